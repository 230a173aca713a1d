//! One float RGB plane per component layer; the composite is their sum.

use crate::image::components::Components;
use crate::image::data::PixelData;
use crate::image::window::PixelWindow;
use glam::Vec3;

/// The component layers, in the order they are stored and written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layer {
    Emission,
    Direct,
    Specular,
    Indirect,
}

impl Layer {
    pub const ALL: [Layer; 4] = [Layer::Emission, Layer::Direct, Layer::Specular, Layer::Indirect];

    /// The EXR layer name (channels are `name.R`, `name.G`, `name.B`).
    pub fn name(self) -> &'static str {
        match self {
            Layer::Emission => "emission",
            Layer::Direct => "direct",
            Layer::Specular => "specular",
            Layer::Indirect => "indirect",
        }
    }

    pub fn index(self) -> usize {
        self as usize
    }
}

/// The pixels of a window of the image (`image::window`): the whole image, or a region task's
/// region. Pixels are named in the full image's coordinates; the planes hold the window's
/// pixels only, row-major.
#[derive(Clone, Debug)]
pub struct FrameBuffer {
    /// The pixels held: the window's width and height.
    pub width: u32,
    pub height: u32,
    window: PixelWindow,
    layers: [Vec<Vec3>; 4],
    /// Records of the irradiance cache made while rendering each pixel (debug layer).
    records: Vec<f32>,
    /// The data layers and Cryptomatte ranks of each pixel (`image::data`).
    data: Vec<PixelData>,
}

impl FrameBuffer {
    /// A frame of the whole `width` x `height` image.
    pub fn new(width: u32, height: u32) -> FrameBuffer {
        FrameBuffer::windowed(PixelWindow::whole(width, height))
    }

    /// A frame holding the pixels of `window` only.
    pub fn windowed(window: PixelWindow) -> FrameBuffer {
        let n = window.pixels();
        FrameBuffer {
            width: window.width(),
            height: window.height(),
            window,
            layers: std::array::from_fn(|_| vec![Vec3::ZERO; n]),
            records: vec![0.0; n],
            data: vec![PixelData::default(); n],
        }
    }

    /// Where the frame's pixels lie in the full image.
    pub fn window(&self) -> PixelWindow {
        self.window
    }

    /// The planes' index of the full image's pixel (x, y). A pixel outside the window is a bug
    /// of the caller (tiles and restored tiles lie inside the area rendered).
    fn at(&self, x: u32, y: u32) -> usize {
        self.window.index(x, y).unwrap_or_else(|| {
            panic!(
                "pixel ({x}, {y}) is outside the frame's window {}",
                self.window.area.text()
            )
        })
    }

    /// The window's planes, row-major.
    pub fn layer(&self, layer: Layer) -> &[Vec3] {
        &self.layers[layer.index()]
    }

    pub fn set(&mut self, x: u32, y: u32, value: &Components) {
        let i = self.at(x, y);
        for (plane, v) in self.layers.iter_mut().zip(value.as_array()) {
            plane[i] = v;
        }
    }

    pub fn add_at(&mut self, x: u32, y: u32, value: &Components) {
        let i = self.at(x, y);
        for (plane, v) in self.layers.iter_mut().zip(value.as_array()) {
            plane[i] += v;
        }
    }

    pub fn set_records(&mut self, x: u32, y: u32, count: f32) {
        let i = self.at(x, y);
        self.records[i] = count;
    }

    /// Adds `count` records to pixel (x, y)'s count.
    pub fn add_records(&mut self, x: u32, y: u32, count: f32) {
        let i = self.at(x, y);
        self.records[i] += count;
    }

    pub fn records(&self) -> &[f32] {
        &self.records
    }

    pub fn set_data(&mut self, x: u32, y: u32, data: &PixelData) {
        let i = self.at(x, y);
        self.data[i] = *data;
    }

    pub fn data(&self) -> &[PixelData] {
        &self.data
    }

    /// Adds light to one layer of one pixel (the full image's pixel number y * full width + x,
    /// as the protocol and the journal name it); pixels outside the window are ignored (the
    /// caller validated them).
    pub fn add(&mut self, pixel: usize, layer: Layer, value: Vec3) {
        if let Some(i) = self.window.index_of_pixel(pixel) {
            self.layers[layer.index()][i] += value;
        }
    }

    /// Adds another frame's layers (and record counts) to this one's, pixel by pixel, and
    /// merges its data layers (`PixelData::merge`: a frame that rendered no pixel changes none).
    pub fn accumulate(&mut self, other: &FrameBuffer) {
        assert_eq!(self.window, other.window, "frames of different windows summed");
        for (mine, theirs) in self.layers.iter_mut().zip(&other.layers) {
            mine.iter_mut().zip(theirs).for_each(|(a, b)| *a += *b);
        }
        self.records.iter_mut().zip(&other.records).for_each(|(a, b)| *a += *b);
        self.data.iter_mut().zip(&other.data).for_each(|(a, b)| *a = a.merge(b));
    }

    /// Multiplies the pixels of `tile` (inside the window) as `scale` does the whole frame's.
    pub fn scale_tile(&mut self, tile: &crate::tiles::Tile, factor: f32) {
        for y in tile.y0..tile.y1 {
            for x in tile.x0..tile.x1 {
                let i = self.at(x, y);
                self.layers.iter_mut().for_each(|plane| plane[i] *= factor);
                self.data[i].scale(factor);
            }
        }
    }

    /// Multiplies every layer, and the averaged data layers, by `factor`.
    pub fn scale(&mut self, factor: f32) {
        self.layers.iter_mut().flatten().for_each(|v| *v *= factor);
        self.data.iter_mut().for_each(|d| d.scale(factor));
    }

    /// The pixels of `tile` (inside the window) as a rendered tile's values, row-major: what
    /// `tiles::store_tile` stored there, with any light added since.
    pub fn tile_values(&self, tile: &crate::tiles::Tile) -> Vec<PixelValue> {
        let mut values = Vec::with_capacity(((tile.x1 - tile.x0) * (tile.y1 - tile.y0)) as usize);
        for y in tile.y0..tile.y1 {
            for x in tile.x0..tile.x1 {
                let i = self.at(x, y);
                values.push(PixelValue {
                    components: Components {
                        emission: self.layers[Layer::Emission.index()][i],
                        direct: self.layers[Layer::Direct.index()][i],
                        specular: self.layers[Layer::Specular.index()][i],
                        indirect: self.layers[Layer::Indirect.index()][i],
                    },
                    records: self.records[i],
                    data: self.data[i],
                });
            }
        }
        values
    }

    /// Sum of all layers at the window's pixel `i` (row-major).
    pub fn composite_at(&self, i: usize) -> Vec3 {
        self.layers.iter().map(|l| l[i]).sum()
    }

    /// Sum of all layers, pixel by pixel.
    pub fn composite(&self) -> Vec<Vec3> {
        (0..self.layers[0].len())
            .map(|i| self.layers.iter().map(|l| l[i]).sum())
            .collect()
    }
}

/// One rendered pixel: its components, the records of the cache it made at level 0, and its
/// data layers.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PixelValue {
    pub components: Components,
    pub records: f32,
    pub data: PixelData,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::region::Region;

    /// A windowed frame holds its window's pixels only, at the places a whole frame's crop to
    /// the window would have them, whether named by (x, y) or by the full image's pixel number.
    #[test]
    fn a_windowed_frame_holds_the_window_of_a_whole_one() {
        let (w, h) = (9u32, 7u32);
        let area = Region {
            x0: 2,
            y0: 3,
            x1: 6,
            y1: 7,
        };
        let mut whole = FrameBuffer::new(w, h);
        let mut part = FrameBuffer::windowed(PixelWindow::new(area, w, h));
        assert_eq!((part.width, part.height, part.layer(Layer::Direct).len()), (4, 4, 16));
        assert_eq!((part.records().len(), part.data().len()), (16, 16));
        let value = |x: u32, y: u32| Vec3::new(x as f32, y as f32, (x * 100 + y) as f32);
        for y in area.y0..area.y1 {
            for x in area.x0..area.x1 {
                let c = Components {
                    direct: value(x, y),
                    ..Default::default()
                };
                let data = PixelData {
                    depth: (y * w + x) as f32,
                    ..Default::default()
                };
                for f in [&mut whole, &mut part] {
                    f.set(x, y, &c);
                    f.set_records(x, y, 1.0);
                    f.add_records(x, y, x as f32);
                    f.set_data(x, y, &data);
                    f.add((y * w + x) as usize, Layer::Indirect, value(y, x));
                }
            }
        }
        // A pixel number outside the window changes nothing.
        part.add(0, Layer::Indirect, Vec3::ONE);
        part.add((w * h) as usize, Layer::Indirect, Vec3::ONE);
        let mut i = 0;
        for y in area.y0..area.y1 {
            for x in area.x0..area.x1 {
                let full = (y * w + x) as usize;
                for layer in Layer::ALL {
                    assert_eq!(part.layer(layer)[i], whole.layer(layer)[full], "{layer:?} ({x}, {y})");
                }
                assert_eq!(part.layer(Layer::Direct)[i], value(x, y));
                assert_eq!(part.layer(Layer::Indirect)[i], value(y, x));
                assert_eq!(part.records()[i], 1.0 + x as f32);
                assert_eq!(part.data()[i].depth, full as f32);
                i += 1;
            }
        }
        assert_eq!(part.window().area, area);
        assert!(whole.window().is_whole());
    }

    #[test]
    #[should_panic(expected = "outside the frame's window")]
    fn a_pixel_outside_the_window_is_a_bug() {
        let window = PixelWindow::new(
            Region {
                x0: 2,
                y0: 3,
                x1: 6,
                y1: 7,
            },
            9,
            7,
        );
        FrameBuffer::windowed(window).set_records(1, 3, 1.0);
    }
}

//! One float RGB plane per component layer; the composite is their sum.

use crate::image::components::Components;
use crate::image::data::{DATA_VALUES, PixelData};
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

#[derive(Clone, Debug)]
pub struct FrameBuffer {
    pub width: u32,
    pub height: u32,
    layers: [Vec<Vec3>; 4],
    /// Records of the irradiance cache made while rendering each pixel (debug layer).
    records: Vec<f32>,
    /// The data layers and Cryptomatte ranks of each pixel (`image::data`).
    data: Vec<PixelData>,
}

/// Floats of one pixel in `to_floats`: four RGB layers, then the data (IDs as their bits).
const FRAME_FLOATS: usize = 12 + DATA_VALUES;

impl FrameBuffer {
    pub fn new(width: u32, height: u32) -> FrameBuffer {
        let n = width as usize * height as usize;
        FrameBuffer {
            width,
            height,
            layers: std::array::from_fn(|_| vec![Vec3::ZERO; n]),
            records: vec![0.0; n],
            data: vec![PixelData::default(); n],
        }
    }

    pub fn layer(&self, layer: Layer) -> &[Vec3] {
        &self.layers[layer.index()]
    }

    pub fn set(&mut self, x: u32, y: u32, value: &Components) {
        let i = y as usize * self.width as usize + x as usize;
        for (plane, v) in self.layers.iter_mut().zip(value.as_array()) {
            plane[i] = v;
        }
    }

    pub fn set_records(&mut self, x: u32, y: u32, count: f32) {
        let i = y as usize * self.width as usize + x as usize;
        self.records[i] = count;
    }

    pub fn records(&self) -> &[f32] {
        &self.records
    }

    pub fn set_data(&mut self, x: u32, y: u32, data: &PixelData) {
        let i = y as usize * self.width as usize + x as usize;
        self.data[i] = *data;
    }

    pub fn data(&self) -> &[PixelData] {
        &self.data
    }

    /// Adds light to one layer of one pixel (index y * width + x); out-of-range pixels are
    /// ignored (the caller validated them).
    pub fn add(&mut self, pixel: usize, layer: Layer, value: Vec3) {
        if let Some(v) = self.layers[layer.index()].get_mut(pixel) {
            *v += value;
        }
    }

    /// Every layer's values and the data layers, pixel after pixel (`FRAME_FLOATS` a pixel;
    /// Cryptomatte IDs as the floats they are), for sending between ranks.
    pub fn to_floats(&self) -> Vec<f32> {
        let n = self.layers[0].len();
        let mut out = Vec::with_capacity(n * FRAME_FLOATS);
        for i in 0..n {
            for layer in &self.layers {
                out.extend_from_slice(&layer[i].to_array());
            }
            out.extend(self.data[i].to_words().map(f32::from_bits));
        }
        out
    }

    /// The inverse of `to_floats`; None when the count does not fit the size.
    pub fn from_floats(width: u32, height: u32, floats: &[f32]) -> Option<FrameBuffer> {
        let n = width as usize * height as usize;
        if floats.len() != n * FRAME_FLOATS {
            return None;
        }
        let mut frame = FrameBuffer::new(width, height);
        for (i, px) in floats.chunks_exact(FRAME_FLOATS).enumerate() {
            for (l, layer) in frame.layers.iter_mut().enumerate() {
                layer[i] = Vec3::new(px[3 * l], px[3 * l + 1], px[3 * l + 2]);
            }
            let words: [u32; DATA_VALUES] = std::array::from_fn(|k| px[12 + k].to_bits());
            frame.data[i] = PixelData::from_words(&words);
            if !frame.data[i].healthy() {
                return None;
            }
        }
        Some(frame)
    }

    /// Adds another frame's layers (and record counts) to this one's, pixel by pixel, and
    /// merges its data layers (`PixelData::merge`: a frame that rendered no pixel changes none).
    pub fn accumulate(&mut self, other: &FrameBuffer) {
        for (mine, theirs) in self.layers.iter_mut().zip(&other.layers) {
            mine.iter_mut().zip(theirs).for_each(|(a, b)| *a += *b);
        }
        self.records.iter_mut().zip(&other.records).for_each(|(a, b)| *a += *b);
        self.data.iter_mut().zip(&other.data).for_each(|(a, b)| *a = a.merge(b));
    }

    /// Multiplies every layer, and the averaged data layers, by `factor`.
    pub fn scale(&mut self, factor: f32) {
        self.layers.iter_mut().flatten().for_each(|v| *v *= factor);
        self.data.iter_mut().for_each(|d| d.scale(factor));
    }

    /// The pixels of `region` as a frame of their own (every layer, the records and the data).
    pub fn crop(&self, region: crate::image::region::Region) -> FrameBuffer {
        FrameBuffer {
            width: region.width(),
            height: region.height(),
            layers: std::array::from_fn(|l| region.crop(&self.layers[l], self.width)),
            records: region.crop(&self.records, self.width),
            data: region.crop(&self.data, self.width),
        }
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

//! Where the pixels a buffer holds lie in the full image. A region task (`render --region`)
//! keeps only its region's pixels, so its memory grows with the region and not with the frame
//! (a 1/64th part of an 8K frame holds 1/64th of its buffers), while everything that names a
//! pixel keeps the full image's terms: the camera, the per-pixel seeds and streams, the tiles,
//! the journal and the wire protocol (`y * full_width + x`). A whole-image buffer's window is
//! the whole image, and there the conversions are the identity.

use super::region::Region;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelWindow {
    /// The pixels held, in the full image's coordinates.
    pub area: Region,
    pub full_width: u32,
    pub full_height: u32,
}

impl PixelWindow {
    /// Every pixel of a `width` x `height` image.
    pub fn whole(width: u32, height: u32) -> PixelWindow {
        PixelWindow {
            area: Region::whole(width, height),
            full_width: width,
            full_height: height,
        }
    }

    /// `area` of a `full_width` x `full_height` image (an area reaching outside it is a bug of
    /// the caller: `Region::from_option` checks what users give).
    pub fn new(area: Region, full_width: u32, full_height: u32) -> PixelWindow {
        assert!(
            area.x1 <= full_width && area.y1 <= full_height,
            "region {} outside the {full_width}x{full_height} image",
            area.text()
        );
        PixelWindow {
            area,
            full_width,
            full_height,
        }
    }

    pub fn width(&self) -> u32 {
        self.area.width()
    }

    pub fn height(&self) -> u32 {
        self.area.height()
    }

    /// Pixels held.
    pub fn pixels(&self) -> usize {
        self.area.pixels()
    }

    pub fn is_whole(&self) -> bool {
        self.area == Region::whole(self.full_width, self.full_height)
    }

    /// Where the full image's pixel (x, y) is in the window's row-major planes; None outside
    /// the window.
    pub fn index(&self, x: u32, y: u32) -> Option<usize> {
        let a = &self.area;
        ((a.x0..a.x1).contains(&x) && (a.y0..a.y1).contains(&y))
            .then(|| (y - a.y0) as usize * a.width() as usize + (x - a.x0) as usize)
    }

    /// As `index`, for the full image's pixel number `y * full_width + x` (how the protocol
    /// and the journal name a pixel).
    pub fn index_of_pixel(&self, pixel: usize) -> Option<usize> {
        if self.is_whole() {
            return (pixel < self.pixels()).then_some(pixel);
        }
        let width = self.full_width.max(1) as usize;
        let (x, y) = (pixel % width, pixel / width);
        self.index(x as u32, u32::try_from(y).ok()?)
    }

    /// The full image's coordinates of the window's pixel `index` (row-major).
    pub fn position(&self, index: usize) -> (u32, u32) {
        let width = self.width().max(1) as usize;
        (
            self.area.x0 + (index % width) as u32,
            self.area.y0 + (index / width) as u32,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn full_image_coordinates_map_into_the_window_and_back() {
        // 10x7 image, window x 3..8, y 2..6 (5 wide, 4 high).
        let area = Region {
            x0: 3,
            y0: 2,
            x1: 8,
            y1: 6,
        };
        let w = PixelWindow::new(area, 10, 7);
        assert_eq!((w.width(), w.height(), w.pixels()), (5, 4, 20));
        assert!(!w.is_whole());
        // Brute force over the whole image: inside pixels get consecutive row-major indices,
        // outside ones none, and the pixel number gives the same answer as (x, y).
        let mut expected = 0;
        for y in 0..7u32 {
            for x in 0..10u32 {
                let inside = (3..8).contains(&x) && (2..6).contains(&y);
                let got = w.index(x, y);
                assert_eq!(got, inside.then_some(expected), "({x}, {y})");
                assert_eq!(w.index_of_pixel((y * 10 + x) as usize), got, "pixel ({x}, {y})");
                if let Some(i) = got {
                    assert_eq!(w.position(i), (x, y));
                    expected += 1;
                }
            }
        }
        assert_eq!(expected, 20);
        // Past the image's last row, and the corners just outside the window.
        assert_eq!(w.index_of_pixel(70), None);
        assert_eq!(w.index(8, 2), None);
        assert_eq!(w.index(3, 6), None);
        assert_eq!(w.index(2, 5), None);
    }

    #[test]
    fn a_whole_window_is_the_identity() {
        let w = PixelWindow::whole(6, 4);
        assert!(w.is_whole());
        assert_eq!(PixelWindow::new(Region::whole(6, 4), 6, 4), w);
        for pixel in 0..24 {
            let (x, y) = w.position(pixel);
            assert_eq!((x, y), ((pixel % 6) as u32, (pixel / 6) as u32));
            assert_eq!(w.index(x, y), Some(pixel));
            assert_eq!(w.index_of_pixel(pixel), Some(pixel));
        }
        assert_eq!(w.index_of_pixel(24), None);
        assert_eq!(w.index(6, 0), None);
    }

    #[test]
    #[should_panic(expected = "outside the 10x7 image")]
    fn a_window_outside_the_image_is_a_bug() {
        PixelWindow::new(
            Region {
                x0: 0,
                y0: 0,
                x1: 11,
                y1: 7,
            },
            10,
            7,
        );
    }
}

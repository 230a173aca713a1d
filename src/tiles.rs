//! The image's tiles: their layout, and where a rendered tile's pixels go in the frame.

use crate::image::framebuffer::{FrameBuffer, PixelValue};

#[derive(Clone, Copy, Debug)]
pub struct Tile {
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
}

/// Tiles in scanline order covering the image exactly once.
pub fn tiles(width: u32, height: u32, tile_width: u32, tile_height: u32) -> Vec<Tile> {
    let (tw, th) = (tile_width.max(1), tile_height.max(1));
    let mut out = Vec::new();
    for y0 in (0..height).step_by(th as usize) {
        for x0 in (0..width).step_by(tw as usize) {
            out.push(Tile {
                x0,
                y0,
                x1: (x0 + tw).min(width),
                y1: (y0 + th).min(height),
            });
        }
    }
    out
}

/// Stores a rendered tile's pixels in the frame.
pub fn store_tile(frame: &mut FrameBuffer, tile: &Tile, values: &[PixelValue]) {
    let mut it = values.iter();
    for y in tile.y0..tile.y1 {
        for x in tile.x0..tile.x1 {
            if let Some(v) = it.next() {
                frame.set(x, y, &v.components);
                frame.set_records(x, y, v.records);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_cover_every_pixel_once() {
        let (w, h) = (67, 45);
        let mut seen = vec![0u8; (w * h) as usize];
        for t in tiles(w, h, 16, 8) {
            for y in t.y0..t.y1 {
                for x in t.x0..t.x1 {
                    seen[(y * w + x) as usize] += 1;
                }
            }
        }
        assert!(seen.iter().all(|&c| c == 1));
    }
}

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

/// The tiles of the whole image's grid cut to `region` (those outside it dropped), so that a
/// region's tile borders fall where the whole image's do. Only the grid's rows and columns that
/// reach the region are visited: a small region of a huge image lists a few tiles, not the
/// image's.
pub fn tiles_in(
    width: u32,
    height: u32,
    tile_width: u32,
    tile_height: u32,
    region: Option<crate::image::region::Region>,
) -> Vec<Tile> {
    let Some(r) = region else {
        return tiles(width, height, tile_width, tile_height);
    };
    let (tw, th) = (tile_width.max(1), tile_height.max(1));
    let (x1, y1) = (r.x1.min(width), r.y1.min(height));
    let mut out = Vec::new();
    // The grid's lines at or before the region's corner, stepping by whole tiles.
    for gy in (r.y0 - r.y0 % th..y1).step_by(th as usize) {
        for gx in (r.x0 - r.x0 % tw..x1).step_by(tw as usize) {
            out.push(Tile {
                x0: gx.max(r.x0),
                y0: gy.max(r.y0),
                x1: (gx + tw).min(x1),
                y1: (gy + th).min(y1),
            });
        }
    }
    out
}

/// Stores a rendered tile's pixels in the frame: their data as they are, their light added to
/// what the frame holds there (nothing, or in component mode the indirect light PAs computed
/// for the pixels, which may reach the master before the tile does).
pub fn store_tile(frame: &mut FrameBuffer, tile: &Tile, values: &[PixelValue]) {
    let mut it = values.iter();
    for y in tile.y0..tile.y1 {
        for x in tile.x0..tile.x1 {
            if let Some(v) = it.next() {
                frame.add_at(x, y, &v.components);
                frame.set_records(x, y, v.records);
                frame.set_data(x, y, &v.data);
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

    /// The region's tiles are exactly the whole grid's tiles cut to it, in the same order
    /// (brute force over many regions and tile sizes).
    #[test]
    fn a_region_s_tiles_are_the_whole_grid_s_cut_to_it() {
        let (w, h) = (23u32, 17u32);
        for (tw, th) in [(4, 4), (5, 3), (1, 1), (23, 17), (64, 64)] {
            for (x0, y0, x1, y1) in [
                (0, 0, 23, 17),
                (3, 2, 9, 6),
                (4, 3, 5, 4),
                (7, 0, 23, 1),
                (22, 16, 23, 17),
            ] {
                let r = crate::image::region::Region { x0, y0, x1, y1 };
                let expected: Vec<(u32, u32, u32, u32)> = tiles(w, h, tw, th)
                    .into_iter()
                    .map(|t| (t.x0.max(x0), t.y0.max(y0), t.x1.min(x1), t.y1.min(y1)))
                    .filter(|&(a, b, c, d)| a < c && b < d)
                    .collect();
                let got: Vec<(u32, u32, u32, u32)> = tiles_in(w, h, tw, th, Some(r))
                    .into_iter()
                    .map(|t| (t.x0, t.y0, t.x1, t.y1))
                    .collect();
                assert_eq!(got, expected, "{tw}x{th} tiles, region {r:?}");
            }
        }
    }

    #[test]
    fn a_region_s_tiles_cover_it_once_on_the_image_s_grid() {
        let (w, h) = (67, 45);
        let region = crate::image::region::Region {
            x0: 10,
            y0: 7,
            x1: 40,
            y1: 45,
        };
        let mut seen = vec![0u8; (w * h) as usize];
        for t in tiles_in(w, h, 16, 8, Some(region)) {
            // Borders inside the region are the whole grid's.
            assert!(t.x0 == region.x0 || t.x0 % 16 == 0);
            assert!(t.y0 == region.y0 || t.y0 % 8 == 0);
            for y in t.y0..t.y1 {
                for x in t.x0..t.x1 {
                    seen[(y * w + x) as usize] += 1;
                }
            }
        }
        for y in 0..h {
            for x in 0..w {
                let inside = (10..40).contains(&x) && (7..45).contains(&y);
                assert_eq!(seen[(y * w + x) as usize], inside as u8, "({x}, {y})");
            }
        }
    }
}

/// The one tile scheduler: hands out the tiles still to render, in order, one at a time, to
/// whoever asks first (a rendering thread of the one-process renderer, or a worker through the
/// master). Tiles an earlier run finished (--checkpoint) are not in it.
#[derive(Debug)]
pub struct TileQueue {
    todo: Vec<usize>,
    next: std::sync::atomic::AtomicUsize,
}

impl TileQueue {
    /// The tiles whose indices are in `todo`, in that order.
    pub fn new(todo: Vec<usize>) -> Self {
        TileQueue {
            todo,
            next: std::sync::atomic::AtomicUsize::new(0),
        }
    }

    /// The next tile's index, or None once every tile has been handed out.
    pub fn next(&self) -> Option<usize> {
        let i = self.next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.todo.get(i).copied()
    }

    /// Tiles in the queue from the start.
    pub fn len(&self) -> usize {
        self.todo.len()
    }

    pub fn is_empty(&self) -> bool {
        self.todo.is_empty()
    }

    /// How many tiles have been handed out.
    pub fn handed_out(&self) -> usize {
        self.next
            .load(std::sync::atomic::Ordering::Relaxed)
            .min(self.todo.len())
    }

    /// Every tile has been handed out.
    pub fn all_out(&self) -> bool {
        self.handed_out() == self.todo.len()
    }
}

#[cfg(test)]
mod queue_tests {
    use super::*;

    #[test]
    fn every_tile_is_handed_out_once_across_threads() {
        let queue = TileQueue::new((0..1000).rev().collect());
        let taken: Vec<Vec<usize>> = std::thread::scope(|s| {
            let workers: Vec<_> = (0..4)
                .map(|_| s.spawn(|| std::iter::from_fn(|| queue.next()).collect::<Vec<_>>()))
                .collect();
            workers.into_iter().map(|w| w.join().unwrap()).collect()
        });
        let mut all: Vec<usize> = taken.concat();
        all.sort();
        assert_eq!(all, (0..1000).collect::<Vec<_>>());
        assert!(queue.all_out());
        assert_eq!(queue.next(), None);
        // Each thread got its tiles in the queue's order.
        assert!(taken.iter().all(|t| t.windows(2).all(|w| w[0] > w[1])));
    }
}

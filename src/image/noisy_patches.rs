//! Where in an image a layer's Monte Carlo noise is: the rectangles (`Patch`es) the denoiser
//! runs its filter on, so that the clean rest of the image costs nothing.
//!
//! The filter's time grows with the pixels it sees (OIDN 2.5.1, fast, 2 cores: 45-50 ms for
//! 256x256), whatever they hold. Where the pixels measured their own noise, the filter's
//! output is weighed against the raw layer by it (`denoise::blend_by_noise`), and where a pixel
//! has next to none the raw value is kept: the filter's work there is thrown away. On the
//! Cornell box at one sample a pixel with 16 shadow rays the direct light's noise is in the
//! penumbrae, 99 % of it in 34 of the 256 blocks of 16x16 pixels; filtered on two patches that
//! see 40 % of the image, the denoiser took 28-38 ms where it took 56-62 ms on the whole image,
//! for the same error (the peers bench's Cornell settings, both views, two seeds: relMSE of
//! the denoised composite within 0.8 % of the whole image's, 4x4 relMSE within 0.2 %).

/// A rectangle of pixels, `[x0, x1) x [y0, y1)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rect {
    pub x0: usize,
    pub y0: usize,
    pub x1: usize,
    pub y1: usize,
}

impl Rect {
    pub fn width(&self) -> usize {
        self.x1 - self.x0
    }

    pub fn height(&self) -> usize {
        self.y1 - self.y0
    }

    pub fn area(&self) -> usize {
        self.width() * self.height()
    }

    fn union(&self, other: &Rect) -> Rect {
        Rect {
            x0: self.x0.min(other.x0),
            y0: self.y0.min(other.y0),
            x1: self.x1.max(other.x1),
            y1: self.y1.max(other.y1),
        }
    }

    #[cfg(test)]
    fn overlaps(&self, other: &Rect) -> bool {
        self.x0 < other.x1 && other.x0 < self.x1 && self.y0 < other.y1 && other.y0 < self.y1
    }

    /// Grown by `margin` on every side, clipped to a `width` x `height` image.
    fn grown(&self, margin: usize, width: usize, height: usize) -> Rect {
        Rect {
            x0: self.x0.saturating_sub(margin),
            y0: self.y0.saturating_sub(margin),
            x1: (self.x1 + margin).min(width),
            y1: (self.y1 + margin).min(height),
        }
    }
}

/// One run of the filter: it sees `seen` (the noisy pixels and a margin of context around
/// them) and its output is kept on `kept` (the noisy pixels' rectangle). Two patches of one
/// image may see the same pixels in their margins, never keep the same ones.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Patch {
    pub seen: Rect,
    pub kept: Rect,
}

/// Side of the square blocks the noise is summed over (OIDN's network works in blocks of 16).
pub const BLOCK: usize = 16;

/// Pixels of context the filter sees around the pixels whose output is kept. Measured on the
/// Cornell box (four of the peers bench's settings, both views, two seeds; 4x4 relMSE of the
/// denoised composite over the raw one, the whole image filtered 0.928-1.002): a margin of 8
/// 0.929-1.008 (the patches' borders show in the 4x4 error), 16 0.928-1.002, 32 0.928-1.003
/// for 15-25 % more of the denoiser's time than 16.
pub const MARGIN: usize = 16;

/// One run of the filter's own set-up (a filter committed for the patch's size), in pixels
/// filtered in the same time: about 1.5 ms at 0.7 microseconds a pixel.
pub const RUN_SET_UP_PIXELS: usize = 2048;

/// The blocks holding all but this share of a layer's noise are filtered; the rest is left raw
/// (the same bar as a whole layer's negligible share, `denoise::NEGLIGIBLE_NOISE_SHARE`).
/// Leaving 5 % raw saved the Cornell box a sixth of the filtered pixels but hardly any time,
/// and raised the denoised relMSE by up to 3 %.
pub const LEFT_RAW_SHARE: f64 = 0.01;

/// Patches that together see less than this share of the image are run as patches; more, and
/// the whole image is filtered at once (each run of the filter has its own set-up, about 1-2 ms,
/// and a patch's margin is filtered twice over where patches come close).
pub const MOST_OF_THE_IMAGE: f64 = 0.6;

/// The patches covering the blocks that hold all but `LEFT_RAW_SHARE` of `noise` (a
/// `width` x `height` image of each pixel's relative variance, >= 0), or None where they would
/// see most of the image (the whole image is filtered) or no noise was measured at all.
pub fn noisy_patches(noise: &[f32], width: usize, height: usize) -> Option<Vec<Patch>> {
    let grid = noisy_blocks(noise, width, height)?;
    let patches = partition(&grid, width, height);
    let seen: usize = patches.iter().map(|p| p.seen.area()).sum();
    if seen as f64 >= MOST_OF_THE_IMAGE * (width * height) as f64 {
        return None;
    }
    Some(patches)
}

/// The blocks that hold all but `LEFT_RAW_SHARE` of the noise (the noisiest taken first); None
/// where there is no noise.
fn noisy_blocks(noise: &[f32], width: usize, height: usize) -> Option<BlockGrid> {
    let (columns, rows) = (width.div_ceil(BLOCK), height.div_ceil(BLOCK));
    let mut sums = vec![0.0f64; columns * rows];
    for (i, v) in noise.iter().enumerate() {
        let (x, y) = (i % width, i / width);
        sums[(y / BLOCK) * columns + x / BLOCK] += *v as f64;
    }
    let total: f64 = sums.iter().sum();
    if total <= 0.0 || !total.is_finite() {
        return None;
    }
    let mut order: Vec<usize> = (0..sums.len()).collect();
    order.sort_by(|a, b| sums[*b].total_cmp(&sums[*a]));
    let mut covered = 0.0;
    let mut noisy = vec![false; columns * rows];
    for i in order {
        if covered >= (1.0 - LEFT_RAW_SHARE) * total {
            break;
        }
        covered += sums[i];
        noisy[i] = true;
    }
    Some(BlockGrid { noisy, columns, rows })
}

/// The noisy blocks, as a grid of `columns` x `rows` flags.
struct BlockGrid {
    noisy: Vec<bool>,
    columns: usize,
    rows: usize,
}

/// A rectangle of blocks, `[x0, x1) x [y0, y1)` in block units.
type Blocks = Rect;

impl BlockGrid {
    /// The smallest rectangle holding every noisy block of `within`, if it holds any.
    fn bounds(&self, within: Blocks) -> Option<Blocks> {
        let mut bounds: Option<Blocks> = None;
        for y in within.y0..within.y1 {
            for x in within.x0..within.x1 {
                if self.noisy[y * self.columns + x] {
                    let block = Rect {
                        x0: x,
                        y0: y,
                        x1: x + 1,
                        y1: y + 1,
                    };
                    bounds = Some(bounds.map_or(block, |b| b.union(&block)));
                }
            }
        }
        bounds
    }
}

/// The noisy blocks split into patches: the bounding rectangle of them all, cut in two along
/// a row or column of blocks where the two parts' bounding rectangles cost the filter less
/// than the whole (`cost`: the pixels each patch sees plus a run's set-up), the cheapest cut
/// first, and each part cut again the same way. So a penumbra along a box's base and one on
/// the far side of the image are filtered apart, and the clean image between them is not.
/// Patches may see the same pixels in their margins, never keep the same ones.
fn partition(grid: &BlockGrid, width: usize, height: usize) -> Vec<Patch> {
    let in_pixels = |b: Blocks| Rect {
        x0: b.x0 * BLOCK,
        y0: b.y0 * BLOCK,
        x1: (b.x1 * BLOCK).min(width),
        y1: (b.y1 * BLOCK).min(height),
    };
    let cost = |b: Blocks| in_pixels(b).grown(MARGIN, width, height).area() + RUN_SET_UP_PIXELS;
    let mut patches = Vec::new();
    let whole = Rect {
        x0: 0,
        y0: 0,
        x1: grid.columns,
        y1: grid.rows,
    };
    let mut pending: Vec<Blocks> = grid.bounds(whole).into_iter().collect();
    while let Some(region) = pending.pop() {
        let mut best: Option<(usize, Blocks, Blocks)> = None;
        let cuts = (region.x0 + 1..region.x1)
            .map(|x| (Rect { x1: x, ..region }, Rect { x0: x, ..region }))
            .chain((region.y0 + 1..region.y1).map(|y| (Rect { y1: y, ..region }, Rect { y0: y, ..region })));
        for (a, b) in cuts {
            // A cut through a bounding rectangle leaves noisy blocks on both sides.
            let (a, b) = (grid.bounds(a).unwrap(), grid.bounds(b).unwrap());
            let split = cost(a) + cost(b);
            if split < cost(region) && best.is_none_or(|(c, _, _)| split < c) {
                best = Some((split, a, b));
            }
        }
        match best {
            Some((_, a, b)) => pending.extend([a, b]),
            None => {
                let kept = in_pixels(region);
                patches.push(Patch {
                    seen: kept.grown(MARGIN, width, height),
                    kept,
                });
            }
        }
    }
    patches.sort_by_key(|p| (p.kept.y0, p.kept.x0));
    patches
}

/// `rect`'s pixels of `plane` (a row-major image `width` wide, `per_pixel` values a pixel), row
/// by row: the input a patch's filter run sees.
pub fn crop<T: Copy>(plane: &[T], width: usize, per_pixel: usize, rect: Rect) -> Vec<T> {
    let mut out = Vec::with_capacity(rect.area() * per_pixel);
    for y in rect.y0..rect.y1 {
        let row = (y * width + rect.x0) * per_pixel;
        out.extend_from_slice(&plane[row..row + rect.width() * per_pixel]);
    }
    out
}

/// Writes a patch's filtered pixels (`filtered`, its `seen` rectangle's, one a pixel) into
/// `plane` (a row-major image `width` wide) on its `kept` rectangle.
pub fn paste<T: Copy>(plane: &mut [T], width: usize, patch: &Patch, filtered: &[T]) {
    let (seen, kept) = (patch.seen, patch.kept);
    for y in kept.y0..kept.y1 {
        let from = (y - seen.y0) * seen.width() + (kept.x0 - seen.x0);
        let to = y * width + kept.x0;
        plane[to..to + kept.width()].copy_from_slice(&filtered[from..from + kept.width()]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rect(x0: usize, y0: usize, x1: usize, y1: usize) -> Rect {
        Rect { x0, y0, x1, y1 }
    }

    fn noise_at(width: usize, height: usize, spots: &[(usize, usize, f32)]) -> Vec<f32> {
        let mut noise = vec![0.0; width * height];
        for &(x, y, v) in spots {
            noise[y * width + x] = v;
        }
        noise
    }

    #[test]
    fn no_noise_needs_no_patch() {
        assert_eq!(noisy_patches(&vec![0.0; 64 * 64], 64, 64), None);
    }

    #[test]
    fn noise_everywhere_filters_the_whole_image() {
        assert_eq!(noisy_patches(&vec![1.0; 128 * 96], 128, 96), None);
    }

    #[test]
    fn two_distant_spots_make_two_patches_with_their_margins() {
        let (w, h) = (256, 256);
        let noise = noise_at(w, h, &[(20, 20, 1.0), (200, 180, 1.0)]);
        let patches = noisy_patches(&noise, w, h).unwrap();
        assert_eq!(patches.len(), 2);
        assert_eq!(patches[0].kept, rect(16, 16, 32, 32));
        assert_eq!(patches[0].seen, rect(0, 0, 48, 48));
        assert_eq!(patches[1].kept, rect(192, 176, 208, 192));
        assert_eq!(patches[1].seen, rect(176, 160, 224, 208));
    }

    #[test]
    fn a_cut_pays_only_where_the_parts_see_fewer_pixels() {
        let (w, h) = (256, 256);
        // Blocks (1, 1) and (3, 1), one block apart: one patch of 3 blocks sees 80x48 pixels,
        // two would see 2 x 48x48 and set the filter up twice.
        let noise = noise_at(w, h, &[(20, 20, 1.0), (52, 20, 1.0)]);
        let patches = noisy_patches(&noise, w, h).unwrap();
        assert_eq!(patches.len(), 1);
        assert_eq!(patches[0].kept, rect(16, 16, 64, 32));
        // An L of noise along two sides of a square: two strips, not the square.
        let mut spots = Vec::new();
        for i in 0..8 {
            spots.push((40 + 16 * i, 40, 1.0));
            spots.push((40, 56 + 16 * i, 1.0));
        }
        let patches = noisy_patches(&noise_at(w, h, &spots), w, h).unwrap();
        assert_eq!(patches.len(), 2);
        let kept: usize = patches.iter().map(|p| p.kept.area()).sum();
        assert_eq!(kept, 16 * 16 * 16, "{patches:?}");
        // Patches may share margin pixels, never kept ones.
        for (i, a) in patches.iter().enumerate() {
            for b in &patches[i + 1..] {
                assert!(!a.kept.overlaps(&b.kept), "{a:?} {b:?}");
            }
        }
    }

    #[test]
    fn a_negligible_share_of_the_noise_is_left_out() {
        let (w, h) = (256, 256);
        // 0.5 % of the noise far from the rest: not worth a run of the filter.
        let noise = noise_at(w, h, &[(20, 20, 199.0), (200, 200, 1.0)]);
        let patches = noisy_patches(&noise, w, h).unwrap();
        assert_eq!(patches.len(), 1);
        assert_eq!(patches[0].kept, rect(16, 16, 32, 32));
    }

    #[test]
    fn partial_blocks_at_the_borders_stay_inside_the_image() {
        // 200x150: the last column and row of blocks are 8 and 6 pixels wide.
        let (w, h) = (200, 150);
        let noise = noise_at(w, h, &[(199, 149, 1.0), (2, 3, 1.0)]);
        let patches = noisy_patches(&noise, w, h).unwrap();
        assert_eq!(patches.len(), 2);
        assert_eq!(patches[0].kept, rect(0, 0, 16, 16));
        assert_eq!(patches[0].seen, rect(0, 0, 32, 32));
        assert_eq!(patches[1].kept, rect(192, 144, 200, 150));
        assert_eq!(patches[1].seen, rect(176, 128, 200, 150));
        // Cropped and pasted back whole.
        let plane: Vec<u32> = (0..(w * h) as u32).collect();
        let mut out = plane.clone();
        for p in &patches {
            let seen = crop(&plane, w, 1, p.seen);
            assert_eq!(seen.len(), p.seen.area());
            paste(&mut out, w, p, &seen);
        }
        assert_eq!(out, plane);
    }

    #[test]
    fn crop_and_paste_put_the_kept_pixels_back_where_they_were() {
        let (w, h) = (40, 30);
        let plane: Vec<u32> = (0..(w * h) as u32).collect();
        let patch = Patch {
            seen: Rect {
                x0: 3,
                y0: 5,
                x1: 30,
                y1: 25,
            },
            kept: Rect {
                x0: 10,
                y0: 9,
                x1: 20,
                y1: 21,
            },
        };
        let seen = crop(&plane, w, 1, patch.seen);
        assert_eq!(seen.len(), patch.seen.area());
        let mut out = vec![u32::MAX; w * h];
        paste(&mut out, w, &patch, &seen);
        for (i, v) in out.iter().enumerate() {
            let (x, y) = (i % w, i / w);
            let inside = (10..20).contains(&x) && (9..21).contains(&y);
            assert_eq!(*v, if inside { i as u32 } else { u32::MAX }, "pixel {x},{y}");
        }
        // Three values a pixel (a guide as the filter takes it).
        let floats: Vec<u32> = (0..(3 * w * h) as u32).collect();
        let seen = crop(&floats, w, 3, patch.seen);
        assert_eq!(&seen[..3], &floats[3 * (5 * w + 3)..3 * (5 * w + 3) + 3]);
    }
}

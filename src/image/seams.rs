//! Tile seams: how much more an image steps between neighbouring pixels across tile borders
//! than within tiles. A cache whose records depend on the order tiles render in leaves blocks
//! that follow the tile grid; a seamless image steps alike everywhere (ratio about 1; noise and
//! geometric edges fall on both sides of a border alike).
//!
//! The step of a pair of neighbouring pixels is |ln a - ln b| of their luminances; pairs with
//! a pixel at zero (or not finite) are left out, so black background and unlit pixels do not
//! count.

use glam::Vec3;

/// A rectangle of pixels, `x0 <= x < x1`, `y0 <= y < y1`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Region {
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
}

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct SeamReport {
    /// Mean step across tile borders over the mean step within tiles.
    pub ratio: f64,
    pub across: f64,
    pub within: f64,
    pub pairs_across: usize,
    pub pairs_within: usize,
}

fn luminance(v: Vec3) -> f32 {
    0.2126 * v.x + 0.7152 * v.y + 0.0722 * v.z
}

/// The seam ratio of `pixels` (row-major, `width` wide) for tiles of `tile` = (w, h) pixels
/// counted from the image's corner, over `region` (the whole image if None). None when either
/// kind of pair is missing (a region inside one tile, or nothing lit).
pub fn tile_seams(pixels: &[Vec3], width: u32, tile: (u32, u32), region: Option<Region>) -> Option<SeamReport> {
    let height = pixels.len() as u32 / width.max(1);
    let r = region.unwrap_or(Region {
        x0: 0,
        y0: 0,
        x1: width,
        y1: height,
    });
    let (x1, y1) = (r.x1.min(width), r.y1.min(height));
    let (tw, th) = (tile.0.max(1), tile.1.max(1));
    let log_of = |x: u32, y: u32| {
        let l = luminance(pixels[(y * width + x) as usize]);
        (l.is_finite() && l > 0.0).then(|| (l as f64).ln())
    };
    let (mut across, mut within, mut n_across, mut n_within) = (0.0f64, 0.0f64, 0usize, 0usize);
    let mut add = |a: Option<f64>, b: Option<f64>, border: bool| {
        if let (Some(a), Some(b)) = (a, b) {
            if border {
                across += (a - b).abs();
                n_across += 1;
            } else {
                within += (a - b).abs();
                n_within += 1;
            }
        }
    };
    for y in r.y0..y1 {
        for x in r.x0..x1 {
            let here = log_of(x, y);
            if x + 1 < x1 {
                add(here, log_of(x + 1, y), (x + 1) % tw == 0);
            }
            if y + 1 < y1 {
                add(here, log_of(x, y + 1), (y + 1) % th == 0);
            }
        }
    }
    if n_across == 0 || n_within == 0 {
        return None;
    }
    let (across, within) = (across / n_across as f64, within / n_within as f64);
    Some(SeamReport {
        ratio: if within > 0.0 { across / within } else { f64::INFINITY },
        across,
        within,
        pairs_across: n_across,
        pairs_within: n_within,
    })
}

/// Parses a region written `x0,y0,x1,y1`.
pub fn parse_region(text: &str) -> Result<Region, String> {
    let v: Vec<u32> = text
        .split(',')
        .map(|p| p.trim().parse::<u32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("region '{text}': expected x0,y0,x1,y1 (pixels)"))?;
    match v[..] {
        [x0, y0, x1, y1] if x0 < x1 && y0 < y1 => Ok(Region { x0, y0, x1, y1 }),
        _ => Err(format!(
            "region '{text}': expected x0,y0,x1,y1 with x0 < x1 and y0 < y1"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Rng;

    fn image(width: u32, height: u32, value: impl Fn(u32, u32) -> f32) -> Vec<Vec3> {
        (0..height)
            .flat_map(|y| (0..width).map(move |x| (x, y)))
            .map(|(x, y)| Vec3::splat(value(x, y)))
            .collect()
    }

    #[test]
    fn blocks_on_the_tile_grid_are_seams_and_noise_is_not() {
        let (w, h) = (64, 64);
        // Noise alone: the same steps everywhere, ratio about 1.
        let mut rng = Rng::new(1, 2);
        let noise: Vec<f32> = (0..w * h).map(|_| 1.0 + 0.2 * rng.next_f32()).collect();
        let noisy = image(w, h, |x, y| noise[(y * w + x) as usize]);
        let r = tile_seams(&noisy, w, (16, 16), None).unwrap();
        assert!((r.ratio - 1.0).abs() < 0.1, "{r:?}");
        // The same noise with each 16x16 tile scaled by its own factor: steps at the borders.
        let blocky = image(w, h, |x, y| {
            noise[(y * w + x) as usize] * (1.0 + 0.3 * ((x / 16 + 3 * (y / 16)) % 3) as f32)
        });
        let r = tile_seams(&blocky, w, (16, 16), None).unwrap();
        assert!(r.ratio > 2.0, "{r:?}");
        // Measured against another tile grid the blocks' edges fall mostly within its tiles.
        let other = tile_seams(&blocky, w, (12, 12), None).unwrap();
        assert!(other.ratio < r.ratio, "{other:?} against {r:?}");
    }

    #[test]
    fn a_smooth_gradient_has_no_seams_and_black_pixels_do_not_count() {
        let (w, h) = (48, 40);
        let smooth = image(w, h, |x, y| if x < 4 { 0.0 } else { 1.0 + 0.01 * (x + y) as f32 });
        let r = tile_seams(&smooth, w, (8, 8), None).unwrap();
        assert!((r.ratio - 1.0).abs() < 0.05, "{r:?}");
        // A region inside one tile has no border pairs.
        let inside = Region {
            x0: 9,
            y0: 9,
            x1: 15,
            y1: 15,
        };
        assert!(tile_seams(&smooth, w, (8, 8), Some(inside)).is_none());
    }

    #[test]
    fn regions_parse() {
        assert_eq!(
            parse_region("1,2,30,40").unwrap(),
            Region {
                x0: 1,
                y0: 2,
                x1: 30,
                y1: 40
            }
        );
        assert!(parse_region("1,2,3").is_err());
        assert!(parse_region("5,2,3,4").is_err());
    }
}

//! Which sites each round of the prepass visits: a lattice over the image, coarse to fine, each
//! level split into rounds whose sites lie apart (see the module above), then the sample
//! positions of the pixels that need them. A pure function of the image's size (and of which
//! pixels need samples): every process computes the same rounds.

use super::{PixelSample, Site};
use crate::image::region::Region;
use crate::image::window::PixelWindow;

/// Spacing in pixels of the first round's lattice (smaller for small images).
const COARSEST_STRIDE: u32 = 32;

/// The coarsest stride for an image: `COARSEST_STRIDE`, or less so that the first lattice
/// still has a few points along the shorter side.
fn coarsest_stride(width: u32, height: u32) -> u32 {
    let side = width.min(height).max(1);
    let mut stride = COARSEST_STRIDE;
    while stride > 1 && stride * 2 > side {
        stride /= 2;
    }
    stride
}

/// The pixel a level's cell (i, j) is visited at: a fixed pseudo-random one in the cell (cells
/// `stride` pixels wide, cut by the image's edge), so that the records of no level line up
/// with a grid of the image. Records made at the corners of a regular lattice do: the
/// interpolated light then varies with the lattice's period, and a tile grid of the same
/// period shows it at its borders (ceiling room, 32-pixel tiles: seam ratio 1.35).
fn cell_site(i: u32, j: u32, stride: u32, width: u32, height: u32) -> Site {
    let mut h = (u64::from(i) << 32 | u64::from(j)) ^ u64::from(stride).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    h = (h ^ (h >> 31)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    h = (h ^ (h >> 29)).wrapping_mul(0x94d0_49bb_1331_11eb);
    h ^= h >> 32;
    let x = (i * stride + (h as u32) % stride).min(width - 1);
    let y = (j * stride + ((h >> 32) as u32) % stride).min(height - 1);
    Site { x, y, sample: None }
}

/// The prepass's rounds of pixel centres, coarse to fine: one site in every cell of a grid of
/// `coarsest_stride` pixels, then of half that, down to 2, then every pixel. Each level is split
/// into 9 rounds by the cells' positions modulo 3, so that a round's sites lie at least two
/// cells apart: neighbouring sites that both lack a record would each make one, where in
/// successive rounds the first one's record covers the other (Cornell box 128x128: 97
/// duplicates of 791 records with sites 2 strides apart, 10 with 4). Every pixel centre is a
/// site at least once.
///
/// A round's sites are made when it comes (`sites`): all of them at once would be 1.3 sites a
/// pixel, 230 MB at 4K, for a round that needs at most a ninth of the pixels' worth.
#[derive(Clone, Debug)]
pub struct Lattice {
    region: Region,
    /// Each round's cell size and the class (cell position modulo 3) it visits.
    rounds: Vec<(u32, u32, u32)>,
}

impl Lattice {
    /// The rounds of the pixels of `region` (the whole image, a `render --region` part or an
    /// `icrender cache --region`): its own lattice, placed at the region's corner.
    pub fn of(region: Region) -> Lattice {
        let (width, height) = (region.width(), region.height());
        let mut rounds = Vec::new();
        if width > 0 && height > 0 {
            let mut stride = coarsest_stride(width, height);
            loop {
                let (columns, rows) = (width.div_ceil(stride), height.div_ceil(stride));
                for k in 0..9 {
                    let (ci, cj) = (k % 3, k / 3);
                    if ci < columns && cj < rows {
                        rounds.push((stride, ci, cj));
                    }
                }
                if stride == 1 {
                    break;
                }
                stride /= 2;
            }
        }
        Lattice { region, rounds }
    }

    pub fn len(&self) -> usize {
        self.rounds.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rounds.is_empty()
    }

    /// Round `k`'s sites, in the full image's coordinates.
    pub fn sites(&self, k: usize) -> Vec<Site> {
        let (stride, ci, cj) = self.rounds[k];
        let (width, height) = (self.region.width(), self.region.height());
        let (columns, rows) = (width.div_ceil(stride), height.div_ceil(stride));
        let mut sites = Vec::new();
        for j in (cj..rows).step_by(3) {
            for i in (ci..columns).step_by(3) {
                let site = if stride == 1 {
                    Site {
                        x: i,
                        y: j,
                        sample: None,
                    }
                } else {
                    cell_site(i, j, stride, width, height)
                };
                sites.push(Site {
                    x: site.x + self.region.x0,
                    y: site.y + self.region.y0,
                    ..site
                });
            }
        }
        sites
    }
}

/// Every round of the `width` x `height` image's lattice, made at once (tests).
#[cfg(test)]
pub fn rounds(width: u32, height: u32) -> Vec<Vec<Site>> {
    let lattice = Lattice::of(Region::whole(width, height));
    (0..lattice.len()).map(|k| lattice.sites(k)).collect()
}

/// How many of `rounds(width, height)`'s rounds are its finest level's (every pixel).
pub(super) fn finest_rounds(width: u32, height: u32) -> usize {
    (width.min(3) * height.min(3)) as usize
}

/// Rounds of the sample positions of the pixels of `window` (`needs`: how many samples each
/// pixel takes whose positions need sites, row-major; 0: none), after the centres: one round
/// per sample number and pixel parity (the parity of the full image's coordinates).
/// Neighbouring samples (of one pixel, or of adjacent pixels along an edge) would otherwise all
/// lack a record at once and each make one (conference room 320x240 at 16 samples: 16,780
/// duplicates of 20,450 records in one round; records made as pixels render: 4,800).
///
/// A round's sites are made when it comes (`sites`), as the lattice's are: all the samples'
/// sites at once would hold 20 bytes a sample of every pixel that needs them.
pub struct SampleRounds<'a> {
    window: PixelWindow,
    count: &'a (dyn Fn(usize) -> u32 + Sync),
    /// Each round's sample number and pixel parity, the empty ones left out.
    rounds: Vec<(u32, u32, u32)>,
}

/// The parities in the order their rounds come.
const PARITIES: [(u32, u32); 4] = [(0, 0), (1, 1), (1, 0), (0, 1)];

impl<'a> SampleRounds<'a> {
    /// The rounds of the pixels of `window`, pixel `i` (row-major in the window) taking
    /// `count(i)` samples whose positions need sites.
    pub fn new(window: PixelWindow, count: &'a (dyn Fn(usize) -> u32 + Sync)) -> SampleRounds<'a> {
        // The most samples a pixel of each parity takes: the rounds beyond are empty.
        let mut most = [0u32; 4];
        for i in 0..window.pixels() {
            let (x, y) = window.position(i);
            let parity = PARITIES.iter().position(|&p| p == (x % 2, y % 2)).unwrap_or(0);
            most[parity] = most[parity].max(count(i));
        }
        let mut rounds = Vec::new();
        for s in 0..most.iter().copied().max().unwrap_or(0) {
            for (k, &(px, py)) in PARITIES.iter().enumerate() {
                if s < most[k] {
                    rounds.push((s, px, py));
                }
            }
        }
        SampleRounds { window, count, rounds }
    }

    pub fn len(&self) -> usize {
        self.rounds.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rounds.is_empty()
    }

    /// Round `k`'s sites, in the full image's coordinates.
    pub fn sites(&self, k: usize) -> Vec<Site> {
        let (s, px, py) = self.rounds[k];
        let a = self.window.area;
        // The first coordinate at or after `from` whose parity is `parity`.
        let first = |from: u32, parity: u32| from + (from % 2 != parity) as u32;
        let mut sites = Vec::new();
        for y in (first(a.y0, py)..a.y1).step_by(2) {
            for x in (first(a.x0, px)..a.x1).step_by(2) {
                let count = self.window.index(x, y).map_or(0, |i| (self.count)(i));
                if s < count {
                    let sample = Some(PixelSample { index: s, count });
                    sites.push(Site { x, y, sample });
                }
            }
        }
        sites
    }
}

/// Every round of `SampleRounds`, made at once (tests).
#[cfg(test)]
pub fn sample_rounds(window: PixelWindow, needs: &[u32]) -> Vec<Vec<Site>> {
    let count = |i: usize| needs.get(i).copied().unwrap_or(0);
    let rounds = SampleRounds::new(window, &count);
    (0..rounds.len()).map(|k| rounds.sites(k)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_region_s_lattice_is_the_lattice_of_its_size_at_its_corner() {
        let region = Region {
            x0: 7,
            y0: 40,
            x1: 90,
            y1: 101,
        };
        let lattice = Lattice::of(region);
        let plain = rounds(region.width(), region.height());
        assert_eq!(lattice.len(), plain.len());
        for (k, sites) in plain.iter().enumerate() {
            let shifted: Vec<(u32, u32)> = sites.iter().map(|s| (s.x + 7, s.y + 40)).collect();
            let placed: Vec<(u32, u32)> = lattice.sites(k).iter().map(|s| (s.x, s.y)).collect();
            assert_eq!(placed, shifted, "round {k}");
        }
        assert!(Lattice::of(Region::whole(0, 5)).is_empty());
    }

    #[test]
    fn every_pixel_centre_is_visited_coarse_to_fine() {
        for (w, h) in [(67, 45), (256, 256), (1, 1), (3, 200), (100, 2)] {
            let rounds = rounds(w, h);
            let mut seen = vec![0u32; (w * h) as usize];
            for site in rounds.iter().flatten() {
                assert_eq!(site.sample, None);
                assert!(site.x < w && site.y < h);
                seen[(site.y * w + site.x) as usize] += 1;
            }
            // Every pixel at full resolution, some again on coarser levels.
            assert!(seen.iter().all(|&c| c >= 1), "{w}x{h}");
            let coarse: usize = rounds.iter().map(|r| r.len()).sum::<usize>() - (w * h) as usize;
            assert!(coarse * 2 <= (w * h) as usize + 9, "{w}x{h}: {coarse} coarse sites");
        }
    }

    #[test]
    fn each_level_fills_the_gaps_of_the_levels_before_and_no_grid_lines_up() {
        let (w, h) = (64u32, 64u32);
        let rounds = rounds(w, h);
        let mut visited: Vec<Site> = Vec::new();
        let mut stride = coarsest_stride(w, h);
        // Nine rounds a level: after each level every pixel is within 2 strides of a site.
        for (k, round) in rounds.iter().enumerate() {
            visited.extend(round);
            if (k + 1) % 9 != 0 {
                continue;
            }
            for y in 0..h {
                for x in 0..w {
                    let nearest = visited
                        .iter()
                        .map(|s| s.x.abs_diff(x).max(s.y.abs_diff(y)))
                        .min()
                        .unwrap();
                    assert!(nearest < 2 * stride, "round {k}: ({x}, {y}) is {nearest} from a site");
                }
            }
            // Within a round, sites lie at least two cells apart.
            for r in &rounds[k + 1 - 9..=k] {
                for (i, a) in r.iter().enumerate() {
                    for b in &r[i + 1..] {
                        assert!(a.x.abs_diff(b.x).max(a.y.abs_diff(b.y)) > stride, "{a:?} {b:?}");
                    }
                }
            }
            // The coarse levels' sites are not on the multiples of any power of two.
            if stride >= 4 {
                let level = &visited[visited.len() - (w.div_ceil(stride) * h.div_ceil(stride)) as usize..];
                for period in [2u32, 4, 8, 16, 32] {
                    let on_grid = level.iter().filter(|s| s.x % period == 0 && s.y % period == 0).count();
                    assert!(
                        on_grid * 2 < level.len().max(2),
                        "stride {stride}: {on_grid} sites on the {period}-grid"
                    );
                }
            }
            if stride > 1 {
                stride /= 2;
            }
        }
    }

    /// A window's rounds, with its own mask, are the whole image's rounds with the same pixels
    /// marked in a whole-image mask: the same sites in the same order (parities of the full
    /// image's coordinates), for windows at even and odd corners.
    #[test]
    fn a_window_s_sample_rounds_are_the_whole_image_s_for_its_pixels() {
        let (w, h, samples) = (11u32, 9u32, 3u32);
        let marked = |x: u32, y: u32| !(x * 7 + y * 3).is_multiple_of(5);
        for (x0, y0, x1, y1) in [(0, 0, 11, 9), (3, 2, 8, 9), (2, 1, 7, 6), (5, 5, 6, 6)] {
            let area = Region { x0, y0, x1, y1 };
            let window = PixelWindow::new(area, w, h);
            let whole: Vec<bool> = (0..w * h)
                .map(|i| {
                    let (x, y) = (i % w, i / w);
                    (x0..x1).contains(&x) && (y0..y1).contains(&y) && marked(x, y)
                })
                .collect();
            let own: Vec<bool> = (0..window.pixels())
                .map(|i| {
                    let (x, y) = window.position(i);
                    marked(x, y)
                })
                .collect();
            let counts = |marks: Vec<bool>| marks.iter().map(|&m| samples * m as u32).collect::<Vec<_>>();
            assert_eq!(
                sample_rounds(window, &counts(own)),
                sample_rounds(PixelWindow::whole(w, h), &counts(whole)),
                "{area:?}"
            );
        }
    }

    #[test]
    fn the_samples_of_marked_pixels_get_rounds_of_their_own() {
        let (w, h) = (5u32, 4u32);
        // Most marked pixels take 4 samples, some (as edge pixels do) 9, the rest none.
        let needs: Vec<u32> = (0..w * h)
            .map(|i| match (i % 3, i % 5) {
                (0, _) => 0,
                (_, 0) => 9,
                _ => 4,
            })
            .collect();
        let rounds = sample_rounds(PixelWindow::whole(w, h), &needs);
        // Every sample of every marked pixel once, placed among its own count, and nothing else.
        assert_eq!(
            rounds.iter().map(|r| r.len()).sum::<usize>(),
            needs.iter().sum::<u32>() as usize
        );
        assert!(rounds.iter().flatten().all(|s| {
            let count = needs[(s.y * w + s.x) as usize];
            s.sample.is_some_and(|p| p.count == count && p.index < count)
        }));
        let index = |s: &Site| s.sample.map(|p| p.index);
        // Within a round, one sample number and no two neighbouring pixels.
        for round in &rounds {
            assert!(round.iter().all(|s| index(s) == index(&round[0])));
            for (i, a) in round.iter().enumerate() {
                for b in &round[i + 1..] {
                    assert!(a.x.abs_diff(b.x).max(a.y.abs_diff(b.y)) >= 2, "{a:?} {b:?}");
                }
            }
        }
    }
}

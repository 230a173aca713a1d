//! An estimate of a render's error against the converged image, made without one: the relMSE
//! `icrender compare` would report (the mean over pixels and channels of (x - r)^2 / (r^2 +
//! 0.01)), from the two kinds of error an irradiance-cache render has.
//!
//! - **Noise of the sampled layers**, and the aliasing of edges and textures that the pixel's
//!   few samples leave: about one pixel in 64 (at least 1,024 where the image has room) is
//!   rendered a second time from independent samples (the same count, other seeds). The
//!   cache's light is the same in both (it is read, not sampled), so the two estimates differ
//!   by their sampling alone: E[(p1 - p2)^2] = 2 var(p). A pixel's noise is independent of its
//!   neighbours', so the error of 4x4-averaged pixels keeps a sixteenth of it.
//! - **The cache's own error**: its interpolation's bias and its records' noise, which do not
//!   average away over a pixel's samples or its neighbours. About one pixel in 1,024 (at least
//!   256), held out, has at its first diffuse surface two fresh records
//!   are computed from independent hemisphere samples, as the prepass makes them, and set
//!   against the value the cache gave the pixel. With c the cache's value, f1 and f2 the fresh
//!   ones and t the truth, E[(c - (f1 + f2) / 2)^2] = E[(c - t)^2] + var(f) / 2 and
//!   E[(f1 - f2)^2] / 4 = var(f) / 2: their difference is the cache's mean squared error, with
//!   no reference. Its error is correlated over many pixels, so 4x4 averaging keeps all of it.
//!
//! Both are relative to a proxy of the converged value where the definition has the
//! reference's: the noise to the two renders' mean, the cache's error to the pixel's value. What
//! neither sees: the bias the deeper bounces share with a fresh record (the last bounce's grid,
//! the records of level 1 and beyond).

use super::pixel::{RenderSettings, render_pixel};
use crate::image::components::Components;
use crate::image::framebuffer::PixelValue;
use crate::image::metrics::REL_EPSILON;
use crate::sampling::Rng;
use crate::scene::view::Camera;
use crate::shading::{Holdout, Integrator, RayCounts, Work};
use crate::tiles::Tile;
use glam::Vec3;
use serde::{Deserialize, Serialize};

/// About one pixel in this many is held out for the cache (two records each).
const HOLDOUT_SHARE: f64 = 1.0 / 1024.0;
/// At least this many held-out pixels, where a quarter of the image's pixels allows.
const MIN_HOLDOUTS: f64 = 256.0;
/// About one pixel in this many is rendered twice (a pixel's cost each): more than are held out,
/// as a few pixels (edges, thin highlights) hold most of a frame's noise.
const PROBE_SHARE: f64 = 1.0 / 64.0;
/// At least this many pixels rendered twice, where a quarter of the image's pixels allows.
const MIN_PROBES: f64 = 1024.0;
/// The streams of a held-out pixel's two fresh records, after every stream its samples use.
const HOLDOUT_STREAMS: [u64; 2] = [u32::MAX as u64 + 3, u32::MAX as u64 + 4];
/// The seed of a held-out pixel's second render is the image's with these bits flipped.
const PROBE_SEED: u64 = 0x7072_6f62_655f_7365;

/// What the estimate is summed from, tile by tile, thread by thread, rank by rank.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ErrorTally {
    pub pixels: u64,
    /// Pixels rendered twice, and over them, relative to the pixel's value (as relMSE weighs an
    /// error): half the squared difference of the two renders, of the composite and of each
    /// light layer (emission, direct, specular, indirect).
    pub probes: u64,
    pub noise: f64,
    pub noise_by_layer: [f64; 4],
    pub holdouts: u64,
    /// Over the held-out pixels, relative to the pixel's value: the squared difference of the
    /// cache's light from the fresh records' mean, and a quarter of the fresh records' squared
    /// difference (their mean's variance).
    pub cache_difference: f64,
    pub fresh_noise: f64,
    /// Seconds the threads spent on it (rendering pixels twice, computing fresh records), and
    /// the rays it traced (not in the render's own counts).
    pub seconds: f64,
    pub rays: u64,
}

/// The estimate a render reports (`--stats` `error_estimate`, the EXR header, the summary).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ErrorEstimate {
    pub relmse: f64,
    /// Of pixels averaged 4x4, as the peers bench measures.
    pub relmse_4x4: f64,
    /// Each light layer's share of `relmse` (the cache's error is the indirect layer's).
    pub by_layer: ByLayer,
    /// The sampled layers' noise (`relmse` less the cache's).
    pub noise: f64,
    /// Of the indirect layer's share, the cache's own error.
    pub cache: f64,
    /// One record's noise (its variance, relative as relMSE weighs it), from the held-out
    /// pixels' two fresh records: what more hemisphere samples (-ad) would lower, where the
    /// cache's error is its records' noise rather than its interpolation's.
    pub record_noise: f64,
    pub pixels: u64,
    /// Pixels rendered twice, and held out for the cache.
    pub probes: u64,
    pub holdouts: u64,
    /// The threads' seconds making the estimate (summed over threads and ranks), and its rays
    /// (not in the render's `rays`).
    pub seconds: f64,
    pub rays: u64,
}

impl ErrorEstimate {
    /// For a summary line: "estimated relMSE 1.23e-3 (4x4 2.10e-4)".
    pub fn summary(&self) -> String {
        format!("estimated relMSE {:.2e} (4x4 {:.2e})", self.relmse, self.relmse_4x4)
    }
}

#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ByLayer {
    pub emission: f64,
    pub direct: f64,
    pub specular: f64,
    pub indirect: f64,
}

/// The shares of an image's pixels rendered twice and held out for the cache.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shares {
    pub probes: f64,
    pub holdouts: f64,
}

impl Shares {
    /// For an image of `pixels`: one in 64 rendered twice (at least 1,024) and one in 1,024 held
    /// out (at least 256), a quarter of the pixels at most.
    pub fn of(pixels: u64) -> Shares {
        let at_least = |count: f64| (count / pixels.max(1) as f64).min(0.25);
        Shares {
            probes: PROBE_SHARE.max(at_least(MIN_PROBES)),
            holdouts: HOLDOUT_SHARE.max(at_least(MIN_HOLDOUTS)),
        }
    }

    /// Pixel `index` (y * width + x) for `seed`: whether it is rendered twice, and whether
    /// held out. One draw for both: the held-out pixels are among those rendered twice.
    pub fn pick(&self, seed: u64, index: u64) -> (bool, bool) {
        let mut rng = Rng::for_sample(seed ^ 0x0068_6f6c_646f_7574, index, 0);
        let u = rng.next_f32() as f64;
        (u < self.probes, u < self.holdouts)
    }
}

/// What measures a render's error as its tiles finish: its integrator, camera and settings,
/// and the settings of a pixel's second render (other seeds).
pub struct ErrorProbe<'a> {
    /// The render's integrator, reading the cache only: a pixel rendered again or held out
    /// adds no record to it, so the image is the one rendered without the estimate. None where
    /// the integrator leaves the indirect light to others (component mode's PRs with PAs): its
    /// pixels lack the light a second render would have; and under --trace-cache.
    integrator: Option<Integrator<'a>>,
    camera: &'a Camera,
    settings: &'a RenderSettings,
    again: RenderSettings,
    shares: Shares,
}

impl<'a> ErrorProbe<'a> {
    pub fn new(integrator: &Integrator<'a>, camera: &'a Camera, settings: &'a RenderSettings) -> ErrorProbe<'a> {
        ErrorProbe {
            // Nor under --trace-cache, whose trace lists the image's lookups and records.
            integrator: (integrator.defer.is_none() && !integrator.cache.is_some_and(|c| c.tracing())).then_some(
                Integrator {
                    frozen: true,
                    // Its misses' records are not the image's (nor kept for the next pass).
                    keeps_gaps: false,
                    ..*integrator
                },
            ),
            camera,
            settings,
            again: RenderSettings {
                seed: settings.seed ^ PROBE_SEED,
                ..settings.clone()
            },
            shares: Shares::of(settings.window(camera).pixels() as u64),
        }
    }

    /// Adds a finished tile (`values`, row by row) to `tally`: some of its pixels rendered
    /// again, fewer measured against fresh records. Their rays, lookups and records are not the
    /// image's: they are left out of its counts, and the tally keeps their rays and time.
    pub fn tile(&self, tally: &mut ErrorTally, tile: &Tile, values: &[PixelValue]) {
        let Some(integrator) = &self.integrator else {
            return;
        };
        let started = std::time::Instant::now();
        let mut own = RayCounts::default();
        let counts = &mut own;
        let (camera, settings) = (self.camera, self.settings);
        tally.pixels += values.len() as u64;
        let seed = settings.seed;
        let window = settings.window(camera);
        let positions = (tile.y0..tile.y1).flat_map(|y| (tile.x0..tile.x1).map(move |x| (x, y)));
        for (value, (x, y)) in values.iter().zip(positions) {
            let index = y as u64 * camera.width as u64 + x as u64;
            let (probe, holdout) = self.shares.pick(seed, index);
            if !probe {
                continue;
            }
            // As many samples as the image's pixel took (an edge's more, where the prepass
            // found the edges).
            let edge = settings.edge_samples > settings.spp
                && settings
                    .edge_map
                    .as_ref()
                    .is_some_and(|map| window.index(x, y).is_some_and(|i| map.get(i)));
            let samples = if edge {
                settings.edge_samples
            } else {
                settings.spp.max(1)
            };
            let (second, _) = render_pixel(integrator, camera, &self.again, (x, y), samples, counts);
            tally.add_probe(&value.components, &second);
            if !holdout {
                continue;
            }
            let (origin, dir) = camera.ray(x as f32 + 0.5, y as f32 + 0.5);
            let [mut a, mut b] = HOLDOUT_STREAMS.map(|stream| Rng::for_sample(seed, index, stream));
            let mut work = Work::new(counts);
            work.sample.pixel = index as u32;
            if let Some(holdout) = integrator.holdout(origin, dir, [&mut a, &mut b], &mut work) {
                tally.add_holdout(&holdout, value.components.total());
            }
        }
        tally.rays += own.total();
        tally.seconds += started.elapsed().as_secs_f64();
    }
}

/// `error` (a pixel's error in each channel, squared, or a variance) relative to `value`, the
/// pixel's light, averaged over the channels.
fn relative(error: Vec3, value: Vec3) -> f64 {
    let v = value.as_dvec3();
    let e = error.as_dvec3();
    (e.x / (v.x * v.x + REL_EPSILON) + e.y / (v.y * v.y + REL_EPSILON) + e.z / (v.z * v.z + REL_EPSILON)) / 3.0
}

impl ErrorTally {
    pub fn merge(&mut self, other: &ErrorTally) {
        self.pixels += other.pixels;
        self.probes += other.probes;
        self.noise += other.noise;
        for (n, o) in self.noise_by_layer.iter_mut().zip(other.noise_by_layer) {
            *n += o;
        }
        self.holdouts += other.holdouts;
        self.cache_difference += other.cache_difference;
        self.fresh_noise += other.fresh_noise;
        self.seconds += other.seconds;
        self.rays += other.rays;
    }

    /// A pixel rendered twice: `first` is the image's, `second` from independent samples.
    ///
    /// The error is relative to the two renders' mean, the nearer proxy of the converged value
    /// that relMSE divides by: relative to the image's own value, a pixel whose render missed a
    /// small bright light that the other render hit (a light's edge) counted as if the pixel
    /// were dark, thousands of times a typical pixel's share (Cornell box 64x64 with one shadow
    /// ray a sample: one such probe of 4,096 took the estimate from 3.8e-3 to 2.6e-2).
    pub fn add_probe(&mut self, first: &Components, second: &Components) {
        let (light, again) = (first.total(), second.total());
        let converged = (light + again) * 0.5;
        let half_squared = |a: Vec3, b: Vec3| (a - b) * (a - b) * 0.5;
        self.probes += 1;
        self.noise += relative(half_squared(light, again), converged);
        for (sum, (a, b)) in self
            .noise_by_layer
            .iter_mut()
            .zip(first.as_array().into_iter().zip(second.as_array()))
        {
            *sum += relative(half_squared(a, b), converged);
        }
    }

    /// A held-out pixel whose light is `light`.
    pub fn add_holdout(&mut self, holdout: &Holdout, light: Vec3) {
        let [a, b] = holdout.fresh;
        let difference = holdout.diffuse * (holdout.cached - (a + b) * 0.5);
        let spread = holdout.diffuse * (a - b);
        self.holdouts += 1;
        self.cache_difference += relative(difference * difference, light);
        self.fresh_noise += relative(spread * spread * 0.25, light);
    }

    /// The estimate from what was summed (None before any pixel).
    pub fn estimate(&self) -> Option<ErrorEstimate> {
        if self.pixels == 0 {
            return None;
        }
        let per_probe = |sum: f64| if self.probes > 0 { sum / self.probes as f64 } else { 0.0 };
        let [emission, direct, specular, indirect] = self.noise_by_layer.map(per_probe);
        let noise = per_probe(self.noise);
        let cache = if self.holdouts > 0 {
            ((self.cache_difference - self.fresh_noise) / self.holdouts as f64).max(0.0)
        } else {
            0.0
        };
        Some(ErrorEstimate {
            relmse: noise + cache,
            relmse_4x4: noise / 16.0 + cache,
            by_layer: ByLayer {
                emission,
                direct,
                specular,
                indirect: indirect + cache,
            },
            noise,
            cache,
            record_noise: if self.holdouts > 0 {
                2.0 * self.fresh_noise / self.holdouts as f64
            } else {
                0.0
            },
            pixels: self.pixels,
            probes: self.probes,
            holdouts: self.holdouts,
            seconds: self.seconds,
            rays: self.rays,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_pixel_in_64_is_rendered_twice_and_one_in_1024_held_out() {
        let hd = Shares::of(1920 * 1080);
        assert_eq!((hd.probes, hd.holdouts), (1.0 / 64.0, 1.0 / 1024.0));
        let small = Shares::of(256 * 256);
        assert!((small.holdouts - 256.0 / 65536.0).abs() < 1e-12);
        assert_eq!(Shares::of(100).probes, 0.25);
        let picked: Vec<_> = (0..65536u64).map(|i| small.pick(7, i)).collect();
        let probes = picked.iter().filter(|p| p.0).count();
        let held = picked.iter().filter(|p| p.1).count();
        assert!(
            (900..1150).contains(&probes) && (200..320).contains(&held),
            "{probes} and {held} of 65536"
        );
        assert!(
            picked.iter().all(|&(probe, held)| probe || !held),
            "the held out are rendered twice"
        );
    }

    /// Fresh records scattered about the truth, a cache off it by a known bias with noise of
    /// its own: the estimate is the cache's mean squared error, the fresh records' noise taken
    /// out.
    #[test]
    fn the_cache_error_is_the_difference_less_the_fresh_records_noise() {
        let mut rng = Rng::new(3, 0);
        let truth = Vec3::new(0.5, 0.4, 0.3);
        let (bias, cache_noise, fresh_noise) = (0.05f32, 0.03f32, 0.08f32);
        let mut gauss = || {
            // Box-Muller, one of the two.
            let (u, v) = (rng.next_f32().max(1e-7), rng.next_f32());
            (-2.0 * u.ln()).sqrt() * (std::f32::consts::TAU * v).cos()
        };
        let mut tally = ErrorTally::default();
        let light = Vec3::splat(1.0);
        for _ in 0..40_000 {
            let cached = truth + Vec3::splat(bias + cache_noise * gauss());
            let fresh = [0, 1].map(|_| truth + Vec3::splat(fresh_noise * gauss()));
            let holdout = Holdout {
                diffuse: Vec3::ONE,
                cached,
                fresh,
            };
            tally.add_holdout(&holdout, light);
            tally.pixels += 1;
        }
        let expected = (bias * bias + cache_noise * cache_noise) as f64 / (1.0 + REL_EPSILON);
        let cache = tally.estimate().unwrap().cache;
        assert!((cache / expected - 1.0).abs() < 0.1, "{cache} against {expected}");
    }

    #[test]
    fn noise_is_half_the_squared_difference_of_two_renders_and_a_sixteenth_stays_over_4x4() {
        let mut tally = ErrorTally {
            pixels: 1,
            ..Default::default()
        };
        let first = Components {
            direct: Vec3::splat(2.0),
            ..Default::default()
        };
        let second = Components {
            direct: Vec3::splat(1.8),
            ..Default::default()
        };
        tally.add_probe(&first, &second);
        let estimate = tally.estimate().unwrap();
        // Relative to the two renders' mean, 1.9.
        let expected = 0.5 * 0.2f64.powi(2) / (1.9f64.powi(2) + REL_EPSILON);
        assert!((estimate.relmse - expected).abs() < 1e-6, "{estimate:?}");
        assert!((estimate.relmse_4x4 - expected / 16.0).abs() < 1e-6);
        // A pixel that missed a light the other render hit counts as a pixel half as bright as
        // the light, not as a dark one: (1 - 0)^2 / 2 over 0.5^2.
        let mut edge = ErrorTally::default();
        let light = Components {
            emission: Vec3::ONE,
            ..Default::default()
        };
        edge.add_probe(&Components::default(), &light);
        let expected_edge = 0.5 / (0.25 + REL_EPSILON);
        assert!((edge.noise - expected_edge).abs() < 1e-6, "{edge:?}");
        assert!((estimate.by_layer.direct - expected).abs() < 1e-6);
        assert_eq!(estimate.by_layer.specular, 0.0);
    }
}

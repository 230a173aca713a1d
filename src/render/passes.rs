//! Progressive passes (`--target-error`, `--time-limit`): the image is rendered again and
//! again from independent samples over one record set, the passes averaged, until the error
//! estimate (`render::error_estimate`) reaches a target or the time runs out. Where the cache's
//! own error dominates, more passes cannot help (it is the same in every pass): the record set
//! is built again, finer (-aa smaller), and the passes start over on it.
//!
//! This module decides what comes next from what the passes measured; the command renders
//! them (`commands::render::passes`).

use super::error_estimate::{ErrorEstimate, ErrorTally};
use crate::image::framebuffer::FrameBuffer;
use crate::tiles::Tile;

/// A finer record set has its accuracy (-aa) and its view's radius floor (--ic-min-pixels)
/// divided by this: about twice the records where the accuracy binds, and half the cache's
/// interpolation error (which grows with the accuracy squared).
pub const REFINE_FACTOR: f32 = std::f32::consts::SQRT_2;

/// No record set is made finer past this accuracy: its records, about 1 / aa^2, would outgrow
/// the passes' worth (25 times the default's at 0.02 where the accuracy binds).
pub const FINEST_ACCURACY: f32 = 0.02;

/// Nor smoother past this many hemisphere samples a record (-ad): 16 times the default.
pub const MOST_DIVISIONS: u32 = 8192;

/// A refinement that left the cache's error above this share of what it was has not helped
/// (it should halve it): it is not tried again.
const HELPED: f64 = 0.8;

/// What a refinement of the record set changes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RecordTuning {
    /// -aa, --ic-min-pixels, -ad and -as.
    pub accuracy: f32,
    pub min_pixels: f32,
    pub divisions: u32,
    pub supersamples: u32,
}

/// The two ways a record set is remade to lower the cache's error.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refinement {
    /// Denser records (-aa and the radius floor over `REFINE_FACTOR`): for the interpolation's
    /// error.
    Finer,
    /// Records of twice the hemisphere samples (-ad): for the records' own noise.
    Smoother,
}

impl RecordTuning {
    /// The tuning after `refinement`, None past its limit.
    pub fn refined(self, refinement: Refinement) -> Option<RecordTuning> {
        match refinement {
            Refinement::Finer => (self.accuracy / REFINE_FACTOR >= FINEST_ACCURACY).then(|| RecordTuning {
                accuracy: self.accuracy / REFINE_FACTOR,
                min_pixels: self.min_pixels / REFINE_FACTOR,
                ..self
            }),
            Refinement::Smoother => (self.divisions * 2 <= MOST_DIVISIONS).then(|| RecordTuning {
                divisions: self.divisions * 2,
                supersamples: self.supersamples * 2,
                ..self
            }),
        }
    }
}

/// Passes reach a target only where the cache's error is at most this share of it.
const WITHIN_REACH: f64 = 0.8;

/// What a refinement is expected to leave of the cache's error before it has been tried: half.
const FIRST_GAIN: f64 = 0.5;

/// Which refinements may still help, and by how much, learnt from those tried.
#[derive(Clone, Debug, Default)]
pub struct Refinements {
    useless: Vec<Refinement>,
    /// The share of the cache's error each kind left the last time it was tried.
    gains: Vec<(Refinement, f64)>,
}

impl Refinements {
    /// The refinement the cache's error calls for, and the tuning it makes; None where none
    /// may help or every one is at its limit. A lookup averages a few records (about three,
    /// where they overlap as the prepass places them), so their noise, `record_noise` (one
    /// record's variance), is about a third of it in the interpolated value: where that is
    /// at least half the cache's error `cache`, the records are made smoother, else finer.
    pub fn next(&self, tuning: RecordTuning, cache: f64, record_noise: f64) -> Option<Refined> {
        let wanted = if record_noise / 3.0 >= cache / 2.0 {
            [Refinement::Smoother, Refinement::Finer]
        } else {
            [Refinement::Finer, Refinement::Smoother]
        };
        wanted.into_iter().filter(|r| !self.useless.contains(r)).find_map(|r| {
            tuning.refined(r).map(|t| Refined {
                refinement: r,
                tuning: t,
                gain: self.gain(r),
            })
        })
    }

    /// The share of the cache's error `refinement` is expected to leave.
    fn gain(&self, refinement: Refinement) -> f64 {
        self.gains
            .iter()
            .rev()
            .find(|(r, _)| *r == refinement)
            .map_or(FIRST_GAIN, |(_, g)| *g)
    }

    /// `refinement` took the cache's error from `before` to `after`.
    pub fn judge(&mut self, refinement: Refinement, before: f64, after: f64) {
        if after > HELPED * before && !self.useless.contains(&refinement) {
            self.useless.push(refinement);
        }
        if before > 0.0 {
            self.gains.push((refinement, after / before));
        }
    }
}

/// A refinement to make next: its kind, the settings it makes and the share of the cache's
/// error it is expected to leave.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Refined {
    pub refinement: Refinement,
    pub tuning: RecordTuning,
    pub gain: f64,
}

/// What the user asked for: stop at this estimated relMSE, or after this many seconds of
/// rendering, whichever comes first (at least one is set).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StopRule {
    pub target_error: Option<f64>,
    pub time_limit_s: Option<f64>,
}

/// What the passes over the current record set have measured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measured {
    /// Passes rendered over this record set.
    pub passes: u32,
    /// One pass's noise and the cache's error, as relMSE (`ErrorEstimate::noise`, `cache`).
    pub noise_per_pass: f64,
    pub cache: f64,
    /// Seconds the record set took to build, and one pass to render and write.
    pub build_s: f64,
    pub pass_s: f64,
    /// Seconds since the render began.
    pub elapsed_s: f64,
    /// The share of the cache's error a refined record set is expected to leave (`Refined::
    /// gain`); None where none may help.
    pub refine_gain: Option<f64>,
}

impl Measured {
    /// The estimated relMSE of the passes' mean.
    pub fn error(&self) -> f64 {
        self.noise_per_pass / self.passes.max(1) as f64 + self.cache
    }

    /// What a refined record set would cost before its first image: about twice the records'
    /// work (twice the records, or twice the samples of each).
    fn refine_s(&self) -> f64 {
        2.0 * self.build_s + self.pass_s
    }

    /// Seconds of passes to bring the estimate to `target` over a record set whose cache error
    /// is `cache`, `done` passes in; None where passes alone cannot: the cache's error is above
    /// `WITHIN_REACH` of the target, which would leave the passes' noise less than a fifth
    /// (their count grows without bound as the cache's error nears the target).
    fn passes_s(&self, cache: f64, done: u32, target: f64) -> Option<f64> {
        if cache > WITHIN_REACH * target {
            return None;
        }
        let needed = (self.noise_per_pass / (target - cache)).ceil().max(1.0);
        Some((needed - done as f64).max(0.0) * self.pass_s)
    }

    /// The estimate reached after `seconds` more of passes over this record set.
    fn error_after(&self, seconds: f64) -> f64 {
        let more = (seconds / self.pass_s.max(1e-9)).floor().max(0.0);
        self.noise_per_pass / (self.passes as f64 + more).max(1.0) + self.cache
    }

    /// The estimate reached after `seconds` if a finer record set is built first (None if it
    /// cannot be built in time).
    fn refined_error_after(&self, seconds: f64) -> Option<f64> {
        let left = seconds - self.refine_s();
        let gain = self.refine_gain.filter(|_| left >= 0.0)?;
        let passes = 1.0 + (left / self.pass_s.max(1e-9)).floor();
        Some(self.noise_per_pass / passes + self.cache * gain)
    }
}

/// What to do next.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Step {
    /// Render one more pass over the record set.
    Pass,
    /// Build a refined record set (`Refinements::next`) and start the passes over on it.
    Refine,
    Stop(Stopped),
}

/// Why the passes stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stopped {
    /// The estimate is at the target.
    Reached,
    /// The next pass would end past the time limit.
    TimeUp,
    /// The target is out of reach: the cache's error is above it and no refinement may help
    /// (the passes went on until their noise was a fifth of the estimate).
    CacheBound,
}

impl Stopped {
    pub fn text(self) -> &'static str {
        match self {
            Stopped::Reached => "target reached",
            Stopped::TimeUp => "time limit",
            Stopped::CacheBound => "the cache's error is above the target, and no refinement lowers it",
        }
    }
}

/// The next step after the passes measured `m`: toward the target by the fastest way the
/// measurements predict (more passes, or a finer record set and passes on it), and within the
/// time left, where there is a limit, the way that leaves the lowest estimate at its end.
pub fn next_step(rule: StopRule, m: &Measured) -> Step {
    if rule.target_error.is_some_and(|target| m.error() <= target) {
        return Step::Stop(Stopped::Reached);
    }
    let left = rule.time_limit_s.map_or(f64::INFINITY, |limit| limit - m.elapsed_s);
    if let Some(target) = rule.target_error {
        let by_passes = m.passes_s(m.cache, m.passes, target);
        let by_refining = m
            .refine_gain
            .and_then(|gain| m.passes_s(m.cache * gain, 1, target).map(|s| m.refine_s() + s));
        let fastest = match (by_passes, by_refining) {
            (Some(p), Some(r)) if r < p => Some((Step::Refine, r)),
            (Some(p), _) => Some((Step::Pass, p)),
            (None, Some(r)) => Some((Step::Refine, r)),
            // Beyond one refinement: refine while it may, the next one will plan again.
            (None, None) if m.refine_gain.is_some() => Some((Step::Refine, m.refine_s())),
            (None, None) => None,
        };
        match fastest {
            Some((step, seconds)) if seconds <= left => return step,
            // Out of time before the target: the lowest estimate the limit allows, below.
            Some(_) if rule.time_limit_s.is_some() => {}
            Some((step, _)) => return step,
            None if rule.time_limit_s.is_some() => {}
            // Out of reach: as near as passes bring it, until their noise is a fifth of the
            // estimate (the cache's error a floor they cannot pass).
            None if m.noise_per_pass / m.passes.max(1) as f64 > m.cache / 4.0 => return Step::Pass,
            None => return Step::Stop(Stopped::CacheBound),
        }
    }
    let by_passes = (m.pass_s <= left).then(|| m.error_after(left));
    let by_refining = m.refined_error_after(left);
    match (by_passes, by_refining) {
        (Some(p), Some(r)) if r < p => Step::Refine,
        (Some(_), _) => Step::Pass,
        (None, Some(_)) => Step::Refine,
        (None, None) => Step::Stop(Stopped::TimeUp),
    }
}

/// Each tile's error tally of one pass, filled by the threads as they finish tiles.
pub struct TileTallies(Vec<std::sync::Mutex<ErrorTally>>);

impl TileTallies {
    pub fn new(tiles: usize) -> TileTallies {
        TileTallies((0..tiles).map(|_| Default::default()).collect())
    }

    pub fn add(&self, tile: usize, tally: &ErrorTally) {
        if let Some(t) = self.0.get(tile) {
            t.lock().unwrap_or_else(|e| e.into_inner()).merge(tally);
        }
    }

    fn into_inner(self) -> Vec<ErrorTally> {
        self.0
            .into_iter()
            .map(|t| t.into_inner().unwrap_or_else(|e| e.into_inner()))
            .collect()
    }
}

/// Every tile takes at least this share of the passes the noisiest tile takes: a tile whose
/// few probes happened to miss its noise is rendered again, and measured again.
const LEAST_SHARE: f64 = 0.25;

/// The passes over one record set: their sum, how many passes each tile took (the passes after
/// the first go to the tiles where the estimate says the noise is) and what the estimates were
/// summed from, overall and tile by tile.
pub struct Accumulated {
    tiles: Vec<Tile>,
    sum: Option<FrameBuffer>,
    /// Passes over the set (each rendering the tiles `next_tiles` chose), and each tile's.
    pub passes: u32,
    counts: Vec<u32>,
    tally: ErrorTally,
    by_tile: Vec<ErrorTally>,
}

impl Accumulated {
    pub fn new(tiles: &[Tile]) -> Accumulated {
        Accumulated {
            tiles: tiles.to_vec(),
            sum: None,
            passes: 0,
            counts: vec![0; tiles.len()],
            tally: ErrorTally::default(),
            by_tile: vec![ErrorTally::default(); tiles.len()],
        }
    }

    /// Adds a pass that rendered `rendered` (indices into the tiles) into `frame`, with their
    /// tallies.
    pub fn add(&mut self, frame: FrameBuffer, rendered: &[usize], tallies: TileTallies) {
        match &mut self.sum {
            Some(sum) => sum.accumulate(&frame),
            None => self.sum = Some(frame),
        }
        self.passes += 1;
        for &t in rendered {
            self.counts[t] += 1;
        }
        for (mine, pass) in self.by_tile.iter_mut().zip(tallies.into_inner()) {
            self.tally.merge(&pass);
            mine.merge(&pass);
        }
    }

    /// The tiles' pixel shares (of the area the tiles cover).
    fn shares(&self) -> Vec<f64> {
        let pixels = |t: &Tile| ((t.x1 - t.x0) * (t.y1 - t.y0)) as f64;
        let total: f64 = self.tiles.iter().map(pixels).sum::<f64>().max(1.0);
        self.tiles.iter().map(|t| pixels(t) / total).collect()
    }

    /// One pass's noise in tile t (relative, as relMSE weighs it), and by layer: its probes'
    /// (the whole image's where it has none yet).
    fn tile_noise(&self, t: usize) -> (f64, [f64; 4]) {
        let tally = if self.by_tile[t].probes > 0 {
            &self.by_tile[t]
        } else {
            &self.tally
        };
        let per = |sum: f64| sum / tally.probes.max(1) as f64;
        (per(tally.noise), tally.noise_by_layer.map(per))
    }

    /// The tiles the next pass renders: each until its passes reach its share of the noisiest
    /// tile's, in proportion to its noise's square root (what spends a given time where it
    /// lowers the image's mean noise the most: n_t proportional to sqrt(v_t), for tiles of
    /// like cost), and no fewer than `LEAST_SHARE` of them.
    pub fn next_tiles(&self) -> Vec<usize> {
        let roots: Vec<f64> = (0..self.tiles.len()).map(|t| self.tile_noise(t).0.sqrt()).collect();
        let loudest = roots.iter().cloned().fold(0.0f64, f64::max);
        let next = (self.passes + 1) as f64;
        (0..self.tiles.len())
            .filter(|&t| {
                let share = if loudest > 0.0 { roots[t] / loudest } else { 1.0 };
                (self.counts[t] as f64) < (next * share.max(LEAST_SHARE)).ceil()
            })
            .collect()
    }

    /// The passes a pixel took on average.
    pub fn mean_passes(&self) -> f64 {
        self.shares().iter().zip(&self.counts).map(|(w, n)| w * *n as f64).sum()
    }

    /// The image: each tile's sum over its passes (None before the first pass).
    pub fn mean(&self) -> Option<FrameBuffer> {
        let mut mean = self.sum.clone()?;
        for (tile, &n) in self.tiles.iter().zip(&self.counts) {
            if n > 1 {
                mean.scale_tile(tile, 1.0 / n as f32);
            }
        }
        Some(mean)
    }

    /// The estimate of the image's error: each tile's noise (a pass's, pooled over its passes'
    /// probes) over its passes, weighed by its pixels; the cache's, pooled over every pass's
    /// held-out pixels (it is the same in each).
    pub fn estimate(&self) -> Option<ErrorEstimate> {
        let mut estimate = self.tally.estimate()?;
        let (mut noise, mut layers) = (0.0, [0.0; 4]);
        for (t, w) in self.shares().into_iter().enumerate() {
            let n = self.counts[t].max(1) as f64;
            let (v, by_layer) = self.tile_noise(t);
            noise += w * v / n;
            for (sum, l) in layers.iter_mut().zip(by_layer) {
                *sum += w * l / n;
            }
        }
        let cache = estimate.cache;
        estimate.noise = noise;
        estimate.relmse = noise + cache;
        estimate.relmse_4x4 = noise / 16.0 + cache;
        estimate.by_layer.emission = layers[0];
        estimate.by_layer.direct = layers[1];
        estimate.by_layer.specular = layers[2];
        estimate.by_layer.indirect = layers[3] + cache;
        Some(estimate)
    }
}

/// What the passes did, for `--stats` and the EXR header.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct PassesReport {
    pub target_error: Option<f64>,
    pub time_limit_s: Option<f64>,
    /// The passes averaged in the image written, over its record set's accuracy (-aa).
    pub passes: u32,
    pub accuracy: f32,
    pub min_pixels: f32,
    pub divisions: u32,
    /// Record sets built (1 + the refinements).
    pub record_sets: u32,
    /// Why the passes ended (`Stopped::text`); None for a fixed --passes.
    pub stopped: Option<&'static str>,
    pub log: Vec<PassLog>,
}

/// One pass: when it ended and the estimate of the passes' mean then.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct PassLog {
    /// 1, 2, ... over the whole render, and over its record set.
    pub pass: u32,
    pub pass_of_set: u32,
    /// Tiles it rendered (the first pass of a set all, the next ones the noisiest).
    pub tiles: u32,
    pub accuracy: f32,
    pub divisions: u32,
    pub records: u64,
    /// Seconds since the render began (the scene loaded), when the pass's image was ready.
    pub elapsed_s: f64,
    pub relmse: f64,
    pub relmse_4x4: f64,
    pub noise: f64,
    pub cache: f64,
    pub record_noise: f64,
    /// Whether this pass's image was written (it lowered the estimate).
    pub written: bool,
}

/// The seed of pass `pass` (0 the first: the image's own seed, so that a first pass is the image
/// rendered without passes).
pub fn pass_seed(seed: u64, pass: u32) -> u64 {
    if pass == 0 {
        return seed;
    }
    // splitmix64 of (seed, pass): no two passes' streams overlap in practice.
    let mut z = seed ^ (pass as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn measured(passes: u32, noise: f64, cache: f64) -> Measured {
        Measured {
            passes,
            noise_per_pass: noise,
            cache,
            build_s: 2.0,
            pass_s: 1.0,
            elapsed_s: 3.0,
            refine_gain: Some(0.5),
        }
    }

    fn target(e: f64) -> StopRule {
        StopRule {
            target_error: Some(e),
            time_limit_s: None,
        }
    }

    #[test]
    fn the_passes_stop_at_the_target() {
        assert_eq!(
            next_step(target(0.011), &measured(1, 0.01, 0.001)),
            Step::Stop(Stopped::Reached)
        );
        // Noise 0.01 a pass and cache 0.001: 0.002 needs ten passes' mean.
        assert_eq!(next_step(target(0.002), &measured(9, 0.01, 0.001)), Step::Pass);
        assert_eq!(
            next_step(target(0.002), &measured(10, 0.01, 0.001)),
            Step::Stop(Stopped::Reached)
        );
    }

    #[test]
    fn a_cache_above_the_target_is_refined_and_at_the_finest_accuracy_stops() {
        let m = measured(1, 0.001, 0.004);
        assert_eq!(next_step(target(0.003), &m), Step::Refine);
        // Beyond one refinement's reach: refine, and plan again after.
        assert_eq!(next_step(target(0.001), &m), Step::Refine);
        // No refinement left: passes until their noise is a fifth of the estimate, then stop.
        assert_eq!(
            next_step(
                target(0.003),
                &Measured {
                    refine_gain: None,
                    ..measured(1, 0.001, 0.0025)
                }
            ),
            Step::Pass,
            "the cache's error is 0.83 of the target: out of reach, the passes' noise is above a fifth"
        );
        let finest = Measured { refine_gain: None, ..m };
        assert_eq!(next_step(target(0.003), &finest), Step::Stop(Stopped::CacheBound));
        let noisy = Measured {
            refine_gain: None,
            ..measured(2, 0.004, 0.004)
        };
        assert_eq!(next_step(target(0.003), &noisy), Step::Pass);
        let converged = Measured { passes: 4, ..noisy };
        assert_eq!(next_step(target(0.003), &converged), Step::Stop(Stopped::CacheBound));
    }

    /// Passes alone would take 1/(E - c) of them; a finer set costs 5 s, then halves c.
    #[test]
    fn the_faster_way_to_the_target_is_taken() {
        // c = 0.0009 of E = 0.001: 20 passes (19 s more), or 5 s and 4 passes (8 s).
        assert_eq!(next_step(target(0.001), &measured(1, 0.002, 0.0009)), Step::Refine);
        // c small: passes.
        assert_eq!(next_step(target(0.001), &measured(1, 0.002, 0.0001)), Step::Pass);
    }

    #[test]
    fn nothing_starts_that_would_end_past_the_time_limit() {
        let rule = StopRule {
            target_error: None,
            time_limit_s: Some(10.0),
        };
        assert_eq!(next_step(rule, &measured(1, 0.01, 0.0)), Step::Pass);
        let late = Measured {
            elapsed_s: 9.5,
            ..measured(5, 0.01, 0.0)
        };
        assert_eq!(next_step(rule, &late), Step::Stop(Stopped::TimeUp));
        // With the cache's error the larger part and time for a finer set and passes: refine.
        assert_eq!(next_step(rule, &measured(1, 0.001, 0.01)), Step::Refine);
        // Not time enough for a finer set (5 s) and the cache large: passes.
        let tight = Measured {
            elapsed_s: 6.0,
            ..measured(1, 0.001, 0.01)
        };
        assert_eq!(next_step(rule, &tight), Step::Pass);
    }

    #[test]
    fn with_both_the_target_ends_it_first_or_the_time() {
        let rule = StopRule {
            target_error: Some(0.001),
            time_limit_s: Some(4.5),
        };
        // The target needs 10 passes (10 s): the limit leaves one more pass, which is taken.
        assert_eq!(next_step(rule, &measured(1, 0.01, 0.0)), Step::Pass);
        let end = Measured {
            elapsed_s: 4.0,
            ..measured(2, 0.01, 0.0)
        };
        assert_eq!(next_step(rule, &end), Step::Stop(Stopped::TimeUp));
        assert_eq!(next_step(rule, &measured(1, 0.0005, 0.0)), Step::Stop(Stopped::Reached));
    }

    #[test]
    fn the_records_noise_makes_them_smoother_else_finer_and_a_useless_one_is_dropped() {
        let tuning = RecordTuning {
            accuracy: 0.2,
            min_pixels: 3.0,
            divisions: 512,
            supersamples: 128,
        };
        let mut tried = Refinements::default();
        let finer = tried.next(tuning, 1e-4, 1e-5).unwrap();
        assert_eq!((finer.refinement, finer.gain), (Refinement::Finer, FIRST_GAIN));
        assert!((finer.tuning.accuracy - 0.2 / REFINE_FACTOR).abs() < 1e-6 && finer.tuning.divisions == 512);
        let smoother = tried.next(tuning, 1e-4, 1e-3).unwrap();
        assert_eq!(
            (smoother.refinement, smoother.tuning.divisions),
            (Refinement::Smoother, 1024)
        );
        tried.judge(Refinement::Finer, 1e-4, 0.6e-4);
        let learnt = tried.next(tuning, 1e-4, 1e-5).unwrap();
        assert_eq!(learnt.refinement, Refinement::Finer);
        assert!((learnt.gain - 0.6).abs() < 1e-9);
        tried.judge(Refinement::Finer, 1e-4, 0.9e-4);
        assert_eq!(tried.next(tuning, 1e-4, 1e-5).unwrap().refinement, Refinement::Smoother);
        tried.judge(Refinement::Smoother, 1e-4, 1e-4);
        assert_eq!(tried.next(tuning, 1e-4, 1e-5), None);
        let limits = RecordTuning {
            accuracy: 0.025,
            min_pixels: 1.0,
            divisions: 8192,
            supersamples: 2048,
        };
        assert_eq!(Refinements::default().next(limits, 1e-4, 1e-5), None);
    }

    fn tile(x0: u32) -> Tile {
        Tile {
            x0,
            y0: 0,
            x1: x0 + 2,
            y1: 2,
        }
    }

    /// A tile's tally of `probes` probes whose noise sums to `noise` (all of it direct light).
    fn tally(probes: u64, noise: f64) -> ErrorTally {
        ErrorTally {
            pixels: 4,
            probes,
            noise,
            noise_by_layer: [0.0, noise, 0.0, 0.0],
            ..Default::default()
        }
    }

    /// Two tiles, one with 16 times the other's noise: after the first pass (both), the loud
    /// one takes every pass and the quiet one a quarter of them (the square roots' ratio); the
    /// estimate weighs each tile's noise by its pixels over its passes, and the image is each
    /// tile's sum over its own passes.
    #[test]
    fn the_passes_go_where_the_noise_is() {
        let tiles = [tile(0), tile(2)];
        let mut passes = Accumulated::new(&tiles);
        let mut rendered = vec![0, 1];
        for pass in 0..8 {
            let tallies = TileTallies::new(2);
            let mut frame = FrameBuffer::new(4, 2);
            for &t in &rendered {
                tallies.add(t, &tally(1, if t == 0 { 1.6e-3 } else { 1e-4 }));
                for x in tiles[t].x0..tiles[t].x1 {
                    for y in 0..2 {
                        let light = crate::image::components::Components {
                            direct: glam::Vec3::splat(1.0),
                            ..Default::default()
                        };
                        frame.add_at(x, y, &light);
                    }
                }
            }
            passes.add(frame, &rendered, tallies);
            rendered = passes.next_tiles();
            assert!(rendered.contains(&0), "pass {pass}: the loud tile is always rendered");
        }
        assert_eq!(passes.counts, vec![8, 2]);
        let estimate = passes.estimate().unwrap();
        let expected = 0.5 * 1.6e-3 / 8.0 + 0.5 * 1e-4 / 2.0;
        assert!((estimate.noise - expected).abs() < 1e-12, "{estimate:?}");
        assert!((estimate.by_layer.direct - expected).abs() < 1e-12);
        let mean = passes.mean().unwrap();
        assert!(
            mean.layer(crate::image::framebuffer::Layer::Direct)
                .iter()
                .all(|v| (v.x - 1.0).abs() < 1e-6)
        );
        assert!((passes.mean_passes() - 5.0).abs() < 1e-12);
    }

    #[test]
    fn the_first_pass_has_the_images_seed_and_the_others_differ() {
        assert_eq!(pass_seed(7, 0), 7);
        let seeds: std::collections::HashSet<u64> = (0..100).map(|p| pass_seed(7, p)).collect();
        assert_eq!(seeds.len(), 100);
    }
}

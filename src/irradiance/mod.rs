//! Ward's irradiance cache with Radiance's semantics and option names: records made from a
//! stratified hemisphere (-ad) with extra samples where it varies most (-as), radii from the
//! Hessian bounded by -ar, lookups weighted by -aa, an index shared by every thread, and an
//! optional file (-af) that persists records across runs.

pub mod codec;
pub mod grid_memory;
pub mod hemisphere;
pub mod index;
pub mod last_bounce;
pub mod persist;
pub mod record;
pub mod record_origins;
pub mod temporal;
pub mod trace;
pub mod validation;

use glam::Vec3;
use hemisphere::Hemisphere;
use index::{FrozenIndex, RecordIndex};
use persist::{CacheFile, LoadReport};
use record::{Metric, Record};
use std::ops::ControlFlow;
use std::sync::{Mutex, OnceLock};

/// Largest relative change the translation and rotation gradients may make within a record's
/// reach; together they stay inside the extrapolation clamp of `Record::extrapolate`.
const MAX_TRANSLATION_CHANGE: f32 = 0.35;
const MAX_ROTATION_CHANGE: f32 = 0.15;
/// How far below the smallest radius (-ar's or the view's) a steep gradient may shrink a record.
const STEEP_RADIUS_FRACTION: f32 = 0.5;

/// The total weight of the records at a point below which the prepass makes a record there
/// anyway (a weight falls from 1 at a record's position to 0 at the edge of its reach). A
/// point on the fringe of every record that may serve it is served by the value of records
/// made far from it. Measured on the Cornell box (128x128, -aa 0.2, indirect relMSE against
/// brute force), with the cone weight 1 - t: any weight 1.9e-4 (798 records), 0.1 1.5e-4
/// (952), 0.25 1.2e-4 (1134), where -aa 0.1 bought 1.6e-4 (1022); with today's smooth weight
/// 0.1 gives 1.25e-4 (1073) and 0.25 9.4e-5 (1273), about what the extra records' time would
/// buy by other means, and at 0.25 the cache lost its 5x lead in rays over brute force on the
/// small test render (`tests/irradiance_cache.rs`). A pixel's own lookup takes any weight.
pub const FIRM_COVERAGE: f32 = 0.1;

/// Smallest hemisphere grid side, so deep levels still see their surroundings.
pub const MIN_DIVISIONS: usize = 4;

/// The cache's options (Radiance's meanings) resolved for a scene.
#[derive(Clone, Debug)]
pub struct CacheSettings {
    /// -aa: larger means larger radii and fewer records.
    pub accuracy: f32,
    /// -ad: hemisphere samples of a new level-0 record.
    pub divisions: u32,
    /// -as: extra samples on the cells that differ most.
    pub supersamples: u32,
    /// -ar: minimum radius is the scene's cube size / ar (0: no minimum).
    pub resolution: u32,
    pub metric: Metric,
    pub min_radius: f32,
    pub max_radius: f32,
    /// The scene's size: a headroom ray that meets nothing counts as this long.
    pub headroom_cap: f32,
    /// `--ic-min-pixels`: the smallest radius the image can use, from the view.
    pub view_floor: Option<ViewFloor>,
    /// `--ic-blend`: once the record set is complete (`freeze`), each record is read over this
    /// many times the radii it was placed with (see `DEFAULT_BLEND`).
    pub blend: f32,
}

/// How much wider than they were placed the finished cache reads its records: placement
/// density stays -aa's, but each point blends about `DEFAULT_BLEND^2` as many records, so the
/// records' own Monte Carlo noise, most of the cache's error at the peers bench's settings,
/// averages further. The curvature is fitted over the wider reach, which holds the
/// extrapolation's bias. Measured on the peers bench's settings against its references (4x4
/// relMSE, 1.3 against 1; docs/cache.md, "Blending"): the Cornell box -13 % at the fastest setting,
/// -11 % at -ad 384, -14 % at -ad 1024; Sibenik -13 % at the fastest, -2 % at the slowest
/// (-ad 512); the conference room -5 % to -8 %; for 1.00-1.04x the time. 1.6 gained more at the
/// fast settings and lost at the slowest (Sibenik +6 %, Cornell +17 %), where the records are
/// accurate and the extrapolation's error, which grows with the reach, is what is left.
pub const DEFAULT_BLEND: f32 = 1.3;

/// The smallest record radius worth making at a point: `pixels` pixel widths at the point's
/// depth in the view (`--ic-min-pixels`). -ar's floor is a fraction of the scene's size, blind
/// to where the camera stands: a view close to a wall of a large building (Sibenik's aisle)
/// needs records far smaller than one of the whole nave, and a floor that suits one view
/// spreads a vault's crease light over many facets in the other, or makes records finer than
/// the image can show. Measured on Sibenik, 320x240, -ab 2, 4x4 relMSE against brute force at
/// the peers bench's middle setting: the aisle 1.8e-2 at -ar 32, 3.4e-3 at -ar 256, 2.8e-3 at
/// -ar 512; the nave 1.3e-3 at -ar 32, 8.5e-4 at -ar 256 and 8.0e-4 at -ar 512 for 1.2x the
/// time: about 2 to 3 pixels in both views.
#[derive(Clone, Debug)]
pub struct ViewFloor {
    pub camera: crate::scene::view::Camera,
    pub pixels: f32,
}

impl ViewFloor {
    pub fn at(&self, point: Vec3) -> f32 {
        let floor = self.pixels * self.camera.pixel_width_at(point);
        if floor.is_finite() { floor.max(0.0) } else { 0.0 }
    }
}

impl CacheSettings {
    pub fn new(
        accuracy: f32,
        divisions: u32,
        supersamples: u32,
        resolution: u32,
        metric: Metric,
        scene_size: f32,
    ) -> Self {
        let size = scene_size.max(f32::MIN_POSITIVE);
        let min_radius = if resolution > 0 { size / resolution as f32 } else { 0.0 };
        let max_radius = if resolution > 0 {
            (64.0 * min_radius).min(0.2 * size)
        } else {
            0.2 * size
        };
        CacheSettings {
            accuracy,
            divisions,
            supersamples,
            resolution,
            metric,
            min_radius,
            max_radius: max_radius.max(min_radius),
            headroom_cap: size,
            view_floor: None,
            blend: DEFAULT_BLEND,
        }
    }

    /// Records read over `blend` times their radii once the set is complete (1: as placed,
    /// as Radiance reads them).
    pub fn with_blend(mut self, blend: f32) -> Self {
        self.blend = blend;
        self
    }

    /// Records no smaller than `pixels` pixel widths of `camera`'s image at their depth (as
    /// well as -ar's floor); 0 pixels leaves -ar's alone.
    pub fn with_view_floor(mut self, camera: &crate::scene::view::Camera, pixels: f32) -> Self {
        self.view_floor = (pixels > 0.0).then(|| ViewFloor {
            camera: camera.clone(),
            pixels,
        });
        self
    }

    /// The smallest radius of a record at `point`: -ar's and the view's, the larger.
    pub fn min_radius_at(&self, point: Vec3) -> f32 {
        let view = self.view_floor.as_ref().map_or(0.0, |f| f.at(point));
        self.min_radius.max(view).min(self.max_radius)
    }

    /// Weight of a record made at `level`: halves with every bounce, as Radiance's does.
    pub fn weight(level: u32) -> f32 {
        0.5f32.powi(level.min(60) as i32)
    }

    /// Side of the hemisphere grid for a record at `level`.
    pub fn grid_side(&self, level: u32) -> usize {
        let wanted = (self.divisions as f32 * Self::weight(level)).sqrt().round() as usize;
        wanted.max(MIN_DIVISIONS)
    }

    /// Extra samples for a record at `level`.
    pub fn extra_samples(&self, level: u32) -> usize {
        (self.supersamples as f32 * Self::weight(level)).round() as usize
    }
}

/// What the records near a point make of it: their weighted mean and the smallest radius among
/// them.
struct Interpolation {
    value: Vec3,
    smallest_radius: f32,
}

pub struct IrradianceCache {
    pub settings: CacheSettings,
    index: RecordIndex,
    file: Option<CacheFile>,
    pub load_report: LoadReport,
    /// Records made here and not yet shared with other ranks (None when nothing is shared).
    outbox: Option<Mutex<Vec<Record>>>,
    /// `--trace-cache`: lookups and new records written as text.
    trace: Option<trace::CacheTrace>,
    /// The complete cache's read-only index, once a prepass has made every record (`freeze`).
    frozen: OnceLock<FrozenIndex>,
    /// The last bounce's grid (`--ic-deep grid`), built before the prepass's first round.
    last_bounce: OnceLock<last_bounce::LastBounceGrid>,
    /// Records a frozen cache's misses made for their own use (gaps), kept to join the set
    /// between the passes of a render in passes (`render::passes`).
    gaps: Mutex<Vec<Record>>,
    /// The last-bounce grid's sites kept for the next frame (`remember_grid_sites`).
    grid_memory: Option<grid_memory::GridMemory>,
    /// Where each record was made, to make it again after a move (`remember_origins`).
    origins: Option<record_origins::RecordOrigins>,
}

impl IrradianceCache {
    pub fn new(settings: CacheSettings) -> IrradianceCache {
        let finest = if settings.min_radius > 0.0 {
            settings.min_radius
        } else {
            settings.max_radius * 1e-3
        };
        IrradianceCache {
            index: RecordIndex::new(finest),
            settings,
            file: None,
            load_report: LoadReport::default(),
            outbox: None,
            trace: None,
            frozen: OnceLock::new(),
            last_bounce: OnceLock::new(),
            gaps: Mutex::new(Vec::new()),
            grid_memory: None,
            origins: None,
        }
    }

    /// From now on each prepass record's point and random state are kept, and a record the
    /// moves drop is made again from them (`record_origins`): for frames of scenes whose meshes
    /// or lights move.
    pub fn remember_origins(&mut self) {
        self.origins.get_or_insert_with(Default::default);
    }

    pub fn origins(&self) -> Option<&record_origins::RecordOrigins> {
        self.origins.as_ref()
    }

    /// From now on the last-bounce grid's sites are kept for the next frame, which takes those
    /// the moves did not reach (`grid_memory`): for frames of scenes whose meshes move.
    pub fn remember_grid_sites(&mut self) {
        self.grid_memory.get_or_insert_with(Default::default);
    }

    pub fn grid_memory(&self) -> Option<&grid_memory::GridMemory> {
        self.grid_memory.as_ref()
    }

    /// Keeps a record made at a frozen cache's miss (see `gaps`).
    pub fn keep_gap(&self, record: Record) {
        self.gaps.lock().unwrap_or_else(|e| e.into_inner()).push(record);
    }

    /// Adds the gaps' records kept since the last call to the set, and freezes it again (their
    /// curvatures fitted with the rest).
    pub fn absorb_gaps(&mut self) {
        let mut gaps = std::mem::take(self.gaps.get_mut().unwrap_or_else(|e| e.into_inner()));
        if gaps.is_empty() {
            return;
        }
        // In an order of their own, not the threads' (the set's order is its lookups' sums'
        // order): the next pass is the same whatever the threads.
        let key = |r: &Record| {
            (
                r.position.to_array().map(f32::to_bits),
                r.normal.to_array().map(f32::to_bits),
            )
        };
        gaps.sort_unstable_by_key(key);
        self.frozen = OnceLock::new();
        for record in gaps {
            self.insert(record);
        }
        self.fit_curvatures_and_freeze();
    }

    /// From now on lookups read a lock-free copy of the records (see `RecordIndex::frozen`):
    /// for a cache no record will join any more, after the prepass. Measured on the
    /// conference room (320x240, 16 samples a pixel) the live index's lookups took 41 % of the
    /// render's CPU time.
    /// The frozen copy holds the records widened by `CacheSettings::blend`.
    pub fn freeze(&self) {
        self.frozen
            .get_or_init(|| self.index.frozen_widened(self.settings.blend).1);
    }

    /// Lets records join again after a `freeze`: the next frame of a sequence adds the records
    /// its view needs to those the frames before made (its own prepass freezes it again).
    pub fn thaw(&mut self) {
        self.frozen = OnceLock::new();
        // The next frame's scene may have moved: its prepass builds its own grid.
        self.last_bounce = OnceLock::new();
    }

    /// Drops the records `disturbance` says the last moves changed (a frame of an animation
    /// that moves meshes or lights, `temporal`); the cache is thawed first. A cache with a file
    /// is never given moves (frames of such animations refuse -af).
    pub fn forget_disturbed(&mut self, disturbance: &temporal::Disturbance) -> temporal::Invalidation {
        self.thaw();
        self.gaps.get_mut().unwrap_or_else(|e| e.into_inner()).clear();
        if let Some(memory) = &mut self.grid_memory {
            memory.forget_disturbed(disturbance);
        }
        let before = self.index.len() as u64;
        let mut held = std::collections::HashSet::new();
        let dropped = if disturbance.is_empty() {
            Vec::new()
        } else {
            // As lookups read it: over its radii widened by the blend.
            let (blend, remember) = (self.settings.blend, self.origins.is_some());
            self.index.retain(|r| {
                let keep = !disturbance.disturbs(r, blend);
                if keep && remember {
                    held.insert(r.identity());
                }
                keep
            })
        };
        if let Some(origins) = &mut self.origins
            && !disturbance.is_empty()
        {
            origins.dropped(&dropped, disturbance);
            // And those of records a round made but did not keep (covered by another of its
            // records), which nothing will drop.
            origins.keep_only(&held);
        }
        let invalidated = dropped.len() as u64;
        temporal::Invalidation {
            kept: before - invalidated,
            invalidated,
        }
    }

    /// Adds records made again at their own points after a move (`record_origins`), in an
    /// order of their own (the thread that made each does not matter), and keeps their origins.
    pub fn insert_remade(&self, mut remade: Vec<(Record, record_origins::RecordOrigin)>) {
        remade.sort_by_key(|(r, _)| r.identity());
        for (record, origin) in remade {
            if let Some(origins) = &self.origins {
                origins.keep(&record, origin);
            }
            self.insert(record);
        }
    }

    /// Attaches a persistent file: its records join the cache, new ones are appended to it.
    pub fn with_file(mut self, path: &std::path::Path, settings_line: &str) -> Result<IrradianceCache, String> {
        let (file, records, report) = CacheFile::open(path, settings_line)?;
        for r in records {
            self.index.insert(r);
        }
        self.file = Some(file);
        self.load_report = report;
        Ok(self)
    }

    /// Loads a persistent file's records without attaching it: nothing is ever written to it.
    pub fn with_records_from(mut self, path: &std::path::Path, settings_line: &str) -> Result<IrradianceCache, String> {
        let (records, report) = persist::read_only(path, settings_line)?;
        for r in records {
            self.index.insert(r);
        }
        self.load_report = report;
        Ok(self)
    }

    /// Writes every lookup and new record to a text file (see `trace`).
    pub fn with_trace(mut self, path: &std::path::Path) -> Result<IrradianceCache, String> {
        self.trace = Some(trace::CacheTrace::create(path)?);
        Ok(self)
    }

    /// Whether `--trace-cache` is on.
    pub fn tracing(&self) -> bool {
        self.trace.is_some()
    }

    /// Traces a lookup at `record`'s position and normal, and the record a miss there makes
    /// (after a hit: would make), when tracing is on.
    pub fn trace(&self, pixel: u32, level: u32, hit: bool, record: &Record) {
        if let Some(t) = &self.trace {
            t.write(&trace::lookup_line(pixel, level, hit, record.position, record.normal));
            t.write(&trace::record_line(pixel, record));
        }
    }

    pub fn len(&self) -> usize {
        self.index.len()
    }

    pub fn is_empty(&self) -> bool {
        self.index.is_empty()
    }

    pub fn contention(&self) -> u64 {
        self.index.contention()
    }

    pub fn records(&self) -> Vec<Record> {
        self.index.all()
    }

    /// The cached value (irradiance over pi) at a point with its headroom (see
    /// `Record::headroom`), or None when no record may be used.
    pub fn lookup(&self, point: Vec3, normal: Vec3, headroom: f32, level: u32) -> Option<Vec3> {
        self.interpolate(point, normal, headroom, level).map(|i| i.value)
    }

    /// `lookup`'s value with the smallest radius among the records that gave it: how far from
    /// the point the interpolation may change much.
    pub fn lookup_with_scale(&self, point: Vec3, normal: Vec3, headroom: f32, level: u32) -> Option<(Vec3, f32)> {
        self.interpolate(point, normal, headroom, level)
            .map(|i| (i.value, i.smallest_radius))
    }

    /// A lock-free copy of the records as they are now, for asking `covered_in` many times
    /// while no record joins (a prepass round); `FrozenIndex::push` adds the next ones.
    pub fn snapshot(&self) -> FrozenIndex {
        self.index.snapshot()
    }

    /// Whether the records of `snapshot` cover the point firmly: their weights there add up to
    /// at least `FIRM_COVERAGE`. Only the weights are summed (no record's value is needed to
    /// say so), and only until they reach it: the prepass asks this at every site, most of
    /// them covered.
    pub fn covered_in(&self, snapshot: &FrozenIndex, point: Vec3, normal: Vec3, headroom: f32, level: u32) -> bool {
        self.covered_by(snapshot, |_| true, point, normal, headroom, level)
    }

    /// As [`IrradianceCache::covered_in`], by the records of `snapshot` that `admit` takes (by
    /// their place in it) only.
    pub fn covered_by(
        &self,
        snapshot: &FrozenIndex,
        admit: impl Fn(usize) -> bool,
        point: Vec3,
        normal: Vec3,
        headroom: f32,
        level: u32,
    ) -> bool {
        let mut total = 0.0f32;
        snapshot
            .try_for_each_near_indexed(point, |i, r| {
                if !admit(i) {
                    return ControlFlow::Continue(());
                }
                total += self.lookup_weight(r, point, normal, headroom, level).unwrap_or(0.0);
                if total >= FIRM_COVERAGE {
                    ControlFlow::Break(())
                } else {
                    ControlFlow::Continue(())
                }
            })
            .is_break()
    }

    /// The weight of record `r` in a lookup at the point (None: not used there).
    fn lookup_weight(&self, r: &Record, point: Vec3, normal: Vec3, headroom: f32, level: u32) -> Option<f32> {
        let (reach, distance_squared) = (r.reach(), (r.position - point).length_squared());
        if distance_squared > reach * reach {
            return None;
        }
        r.weight_at(point, normal, level, self.settings.metric, self.settings.accuracy)
            .map(|w| w * record::under_one_roof(r.headroom, headroom, distance_squared.sqrt()))
            .filter(|w| *w > 0.0)
    }

    /// The weighted mean of the records that may be used at the point, from the frozen index
    /// if there is one, else the live one.
    fn interpolate(&self, point: Vec3, normal: Vec3, headroom: f32, level: u32) -> Option<Interpolation> {
        let (mut sum, mut total, mut smallest_radius) = (Vec3::ZERO, 0.0f32, f32::INFINITY);
        let weigh = |r: &Record| {
            self.lookup_weight(r, point, normal, headroom, level)
                .map(|w| (r.extrapolate(point, normal) * w, w))
        };
        let mut add = |r: &Record| {
            if let Some((value, w)) = weigh(r) {
                sum += value;
                total += w;
                smallest_radius = smallest_radius.min(r.radii[0].min(r.radii[1]));
            }
        };
        match self.frozen.get() {
            Some(frozen) => frozen.for_each_near(point, &mut add),
            None => self.index.for_each_near(point, &mut add),
        }
        (total > 0.0)
            .then(|| Interpolation {
                value: sum / total,
                smallest_radius,
            })
            .filter(|i| i.value.is_finite())
    }

    /// Shrinks the records of `snapshot` (which holds every record of this cache's level 0,
    /// the prepass's copy) that `revisable` picks (by their place in it) whose extrapolation
    /// misses a neighbouring record's value (`validation::shrink_factors`), checking only pairs
    /// with a record `fresh` picks; each shrinks in this cache and in `snapshot` alike, and a
    /// shrunk record's new form is appended to the file, where it replaces the old one on
    /// loading. A record's factor is the smallest its neighbours ask
    /// for, whatever their order, so the snapshot's order (not the canonical one) gives the
    /// same records as any process's copy would.
    pub fn shrink_where_neighbours_disagree(
        &self,
        snapshot: &mut FrozenIndex,
        revisable: impl Fn(usize) -> bool,
        fresh: impl Fn(usize) -> bool,
    ) {
        let revisable: Vec<bool> = (0..snapshot.len()).map(&revisable).collect();
        let fresh: Vec<bool> = (0..snapshot.len()).map(&fresh).collect();
        let factors = validation::shrink_factors(
            snapshot,
            self.settings.metric,
            self.settings.accuracy,
            &revisable,
            &fresh,
        );
        for (index, factor) in factors.into_iter().enumerate() {
            if factor >= 1.0 {
                continue;
            }
            let old = &snapshot.records()[index];
            let floor = self.settings.min_radius_at(old.position) * STEEP_RADIUS_FRACTION;
            let mut new = old.clone();
            new.radii = old.radii.map(|r| (r * factor).max(floor).min(r));
            if new.radii == old.radii {
                continue;
            }
            if let Some(file) = &self.file {
                file.append(&new);
            }
            self.index.replace(old, new.clone());
            snapshot.shrink(index, new);
        }
    }

    /// Fits every record's `curvature` from its neighbours (`validation::fit_curvatures`) once
    /// the record set is complete, and freezes the cache (`freeze`). The fit reads the records
    /// as the frozen copy will (widened by `CacheSettings::blend`), so the overshoot is fitted
    /// over the whole reach a lookup extrapolates to, and in the copy's canonical order; a
    /// curvature changes neither that order (a record's identity) nor where the copy lists a
    /// record, so the copy the fit read, with the curvatures written into it, is the frozen
    /// index: it is built once, not twice. The live index keeps the records as placed, with
    /// the curvature per unit of their own `t2` (a sequence's next frame widens them afresh).
    pub fn fit_curvatures_and_freeze(&self) {
        let blend = self.settings.blend;
        let (placed, mut frozen) = self.index.frozen_widened(blend);
        let curvatures = validation::fit_curvatures(&frozen, self.settings.metric, self.settings.accuracy);
        for (i, curvature) in curvatures.into_iter().enumerate() {
            if curvature != frozen.records()[i].curvature {
                frozen.set_curvature(i, curvature);
                let mut new = placed[i].clone();
                new.curvature = curvature / (blend * blend);
                self.index.replace(&placed[i], new);
            }
        }
        self.frozen.get_or_init(|| frozen);
    }

    /// From now on the last diffuse bounce of a path reads `grid` where it has a mean (set
    /// once, before the prepass; a second grid is ignored).
    pub fn set_last_bounce(&self, grid: last_bounce::LastBounceGrid) {
        let _ = self.last_bounce.set(grid);
    }

    /// Takes the last-bounce grid out (for a cache that replaces this one).
    pub fn take_last_bounce(&mut self) -> Option<last_bounce::LastBounceGrid> {
        self.last_bounce.take()
    }

    pub fn last_bounce(&self) -> Option<&last_bounce::LastBounceGrid> {
        self.last_bounce.get()
    }

    /// Adds a record (and appends it to the file, if any).
    pub fn insert(&self, record: Record) {
        debug_assert!(self.frozen.get().is_none(), "a record inserted into a frozen cache");
        if let Some(file) = &self.file {
            file.append(&record);
        }
        if let Some(outbox) = &self.outbox {
            outbox.lock().unwrap_or_else(|e| e.into_inner()).push(record.clone());
        }
        self.index.insert(record);
    }

    /// Adds a record that was made elsewhere (another rank): not written to this process's
    /// file by default and not shared again.
    pub fn insert_shared(&self, record: Record) {
        self.index.insert(record);
    }

    /// From now on, records made here are also kept for `take_outbox`.
    pub fn keep_outbox(&mut self) {
        self.outbox = Some(Mutex::new(Vec::new()));
    }

    /// How many records wait to be shared.
    pub fn outbox_len(&self) -> usize {
        self.outbox
            .as_ref()
            .map_or(0, |o| o.lock().unwrap_or_else(|e| e.into_inner()).len())
    }

    /// The records made here since the last call.
    pub fn take_outbox(&self) -> Vec<Record> {
        self.outbox.as_ref().map_or_else(Vec::new, |o| {
            std::mem::take(&mut *o.lock().unwrap_or_else(|e| e.into_inner()))
        })
    }

    /// Flushes the file; its first write error, if any.
    pub fn finish(&self) -> Result<(), String> {
        if let Some(t) = &self.trace {
            t.finish()?;
        }
        self.file.as_ref().map_or(Ok(()), CacheFile::finish)
    }

    /// Turns a sampled hemisphere into a record: value, gradients, radii, leak horizon.
    pub fn make_record(&self, hemisphere: &Hemisphere, position: Vec3, headroom: f32, level: u32) -> Record {
        let s = &self.settings;
        let value = hemisphere.value();
        let brightness = crate::scene::light::luminance(value) * std::f32::consts::PI;
        let relative = |g: Vec3| if brightness > 0.0 { g / brightness } else { Vec3::ZERO };
        let mut translation_gradient = relative(hemisphere.translation_gradient());
        let mut rotation_gradient = relative(hemisphere.rotation_gradient());
        let min_radius = s.min_radius_at(position);
        let clamp_radius = |r: f32| {
            let r = if r.is_finite() { r } else { s.max_radius };
            r.clamp(min_radius, s.max_radius).max(f32::MIN_POSITIVE)
        };
        let (u_axis, radii) = match s.metric {
            Metric::Hessian => {
                let (axis, [large, small]) = hemisphere.geometric_hessian();
                // Second-order error over radius R along an axis of curvature lambda is about
                // lambda R^2 / 2; keep it under the accuracy times the (unit) irradiance pi.
                let radius = |lambda: f32| (2.0 * s.accuracy * std::f32::consts::PI / lambda).sqrt();
                // The first-order change over R stays well inside the value (see below).
                // Where the light changes fast (a contact, a corner) the gradient may shrink a
                // record below the smallest radius, down to `STEEP_RADIUS_FRACTION` of it:
                // held at the minimum, a record by a corner spread its dark value (its gradient
                // scaled down to fit, see below) over the brighter wall beside it. Corridor,
                // 128x128, against brute force: indirect relMSE 1.5e-4 -> 1.0e-4 with 10 % more
                // records, bias -1.4 % -> +1.1 %.
                let gradient_limit = MAX_TRANSLATION_CHANGE / translation_gradient.length().max(1e-30);
                let steepest = gradient_limit.max(min_radius * STEEP_RADIUS_FRACTION);
                let r0 = clamp_radius(radius(large)).min(steepest);
                let r1 = clamp_radius(radius(small)).min(steepest);
                // At most 2:1 anisotropy.
                (axis, [r0, r1.min(2.0 * r0)])
            }
            Metric::Ward88 => {
                let r = clamp_radius(s.accuracy * hemisphere.harmonic_distance());
                (hemisphere.tangent, [r, r])
            }
        };
        // Ward's metric measures distance in units of the harmonic distance; keep the two
        // consistent with the clamped radius (valid region = accuracy x harmonic distance).
        let harmonic_distance = match s.metric {
            Metric::Ward88 => radii[0] / s.accuracy.max(1e-6),
            Metric::Hessian => clamp_radius(hemisphere.harmonic_distance()),
        };
        // Bound what the gradients may change within the record's reach, so that extrapolated
        // values never meet the extrapolation clamp. Gradients estimated from very close hits
        // (corners) can be huge, and a clamp that cuts large changes more on one side than the
        // other biases the cache (measured: +7 % indirect light on the Cornell box). Where the
        // minimum radius keeps a record larger than its gradient allows, the gradient is
        // scaled down instead.
        let reach = radii[0].max(radii[1]);
        let change = translation_gradient.length() * reach;
        if change > MAX_TRANSLATION_CHANGE {
            translation_gradient *= MAX_TRANSLATION_CHANGE / change;
        }
        let max_angle = record::max_normal_deviation(s.accuracy);
        let turn = rotation_gradient.length() * max_angle;
        if turn > MAX_ROTATION_CHANGE {
            rotation_gradient *= MAX_ROTATION_CHANGE / turn;
        }
        let horizon = hemisphere.horizon(u_axis);
        Record {
            position,
            normal: hemisphere.normal,
            u_axis,
            radii,
            harmonic_distance,
            level,
            weight: CacheSettings::weight(level),
            value,
            translation_gradient,
            rotation_gradient,
            horizon,
            headroom,
            curvature: 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 90-degree view 100 pixels wide down -z: a pixel is 0.02 wide per unit of depth.
    fn camera() -> crate::scene::view::Camera {
        crate::scene::view::tests::view().camera(100, 100)
    }

    /// The smallest radius is -ar's or the view's, whichever is larger, never above the
    /// largest radius; without a view floor it is -ar's everywhere.
    #[test]
    fn the_smallest_radius_follows_the_view_above_ar_s_floor() {
        let near = Vec3::new(0.0, 0.0, -5.0);
        let far = Vec3::new(0.0, 0.0, -500.0);
        // -ar 64 in a scene of size 100: 1.5625; the largest radius 20.
        let ar = CacheSettings::new(0.2, 64, 16, 64, Metric::Hessian, 100.0);
        assert_eq!(ar.min_radius_at(near), 1.5625);
        assert_eq!(ar.clone().with_view_floor(&camera(), 0.0).min_radius_at(far), 1.5625);
        let both = ar.with_view_floor(&camera(), 2.0);
        assert_eq!(both.min_radius_at(near), 1.5625, "two pixels at depth 5 are 0.2");
        assert_eq!(
            both.min_radius_at(far),
            20.0,
            "two pixels at depth 500 are 20: the largest radius"
        );
        let view_only = CacheSettings::new(0.2, 64, 16, 0, Metric::Hessian, 100.0).with_view_floor(&camera(), 2.0);
        assert!((view_only.min_radius_at(near) - 0.2).abs() < 1e-6);
        assert!((view_only.min_radius_at(Vec3::new(0.0, 0.0, -50.0)) - 2.0).abs() < 1e-5);
        assert_eq!(view_only.min_radius_at(Vec3::new(0.0, 0.0, 1.0)), 0.0, "behind the eye");
    }

    /// A lookup's scale is the smallest radius among the records that gave its value, and its
    /// value is `lookup`'s.
    #[test]
    fn a_lookups_scale_is_its_smallest_records_radius() {
        use record::tests::flat_record;
        let cache = IrradianceCache::new(CacheSettings::new(0.2, 64, 16, 64, Metric::Hessian, 100.0));
        cache.insert(flat_record(1.0, 2.0));
        cache.insert(Record {
            position: Vec3::new(0.2, 0.0, 0.0),
            ..flat_record(3.0, 0.5)
        });
        let at = |x: f32| cache.lookup_with_scale(Vec3::new(x, 0.0, 0.0), Vec3::Z, 100.0, 0);
        let (value, scale) = at(0.1).unwrap();
        assert_eq!(scale, 0.5);
        assert!(value.x > 1.0 && value.x < 3.0, "both records weigh in: {value}");
        assert_eq!(Some(value), cache.lookup(Vec3::new(0.1, 0.0, 0.0), Vec3::Z, 100.0, 0));
        // Beyond the small record's reach only the large one answers.
        let (value, scale) = at(1.5).unwrap();
        assert_eq!((value.x, scale), (1.0, 2.0));
    }

    /// A cache of records on a lit bump (values concave around its peak, so most curvatures
    /// are fitted non-zero), read `blend` times as wide as placed.
    fn bump_cache(blend: f32) -> IrradianceCache {
        use record::tests::flat_record;
        let settings = CacheSettings::new(0.2, 64, 16, 64, Metric::Hessian, 100.0).with_blend(blend);
        let cache = IrradianceCache::new(settings);
        let mut rng = crate::sampling::Rng::new(11, 0);
        for _ in 0..600 {
            let (x, y) = (rng.next_f32() * 6.0 - 3.0, rng.next_f32() * 6.0 - 3.0);
            let light = 2.0 - 0.2 * (x * x + y * y);
            cache.insert(Record {
                position: Vec3::new(x, y, 0.0),
                translation_gradient: Vec3::new(-0.4 * x, -0.4 * y, 0.0) / light,
                ..flat_record(light, 0.4 + 0.4 * rng.next_f32())
            });
        }
        cache
    }

    /// The frozen index `fit_curvatures_and_freeze` leaves is the one the fitted records would
    /// freeze into afresh: the same records, curvatures included, in the same order.
    #[test]
    fn fitting_and_freezing_at_once_freezes_the_fitted_records() {
        let cache = bump_cache(1.0);
        cache.fit_curvatures_and_freeze();
        let frozen = cache.frozen.get().expect("frozen");
        let afresh = cache.index.frozen();
        assert_eq!(frozen.records(), afresh.records());
        let fitted = frozen.records().iter().filter(|r| r.curvature != 0.0).count();
        assert!(fitted > 400, "curvatures fitted: {fitted} of 600");
    }

    /// Read wider (`--ic-blend`), the frozen copy holds the records as placed, widened: the
    /// live index keeps the placed radii, and its curvature, per unit of the placed `t2`,
    /// subtracts the overshoot the frozen copy's does at the same point. The fit itself reads
    /// the wider reach: it finds other curvatures than at blend 1.
    #[test]
    fn a_blended_cache_freezes_its_records_widened() {
        let blend = 1.3;
        let cache = bump_cache(blend);
        cache.fit_curvatures_and_freeze();
        let frozen = cache.frozen.get().expect("frozen");
        let placed = cache.index.frozen();
        assert_eq!(frozen.len(), placed.len());
        let narrow = bump_cache(1.0);
        narrow.fit_curvatures_and_freeze();
        let mut differ = 0;
        for ((read, as_placed), unblended) in frozen
            .records()
            .iter()
            .zip(placed.records())
            .zip(narrow.frozen.get().unwrap().records())
        {
            assert_eq!(read.identity(), as_placed.identity());
            assert_eq!(read.radii, as_placed.radii.map(|r| r * blend));
            let at = read.position + read.u_axis * read.radii[0] * 0.9;
            let (a, b) = (
                read.extrapolate(at, read.normal),
                as_placed.widened(blend).extrapolate(at, read.normal),
            );
            assert!((a - b).abs().max_element() <= 1e-5 * a.abs().max_element(), "{a} {b}");
            differ += usize::from((read.curvature - unblended.curvature).abs() > 1e-4);
        }
        assert!(differ > 100, "curvatures refitted over the wider reach: {differ}");
    }

    /// What blending is for: records of a uniformly lit floor, each holding the light with
    /// its own noise (+-20 %), read as placed and 1.3 times as wide. The wider read averages
    /// more records at every point, so its error against the true light is smaller; and
    /// uniform light stays uniform (no bias from the curvature fitted to the noise).
    #[test]
    fn reading_wider_averages_the_records_noise() {
        use record::tests::flat_record;
        let error = |blend: f32| {
            let settings = CacheSettings::new(0.2, 64, 16, 64, Metric::Hessian, 100.0).with_blend(blend);
            let cache = IrradianceCache::new(settings);
            let mut rng = crate::sampling::Rng::new(5, 0);
            // Records about a radius apart, as the prepass places them.
            for i in 0..40 {
                for j in 0..40 {
                    let jitter = (rng.next_f32() - 0.5) * 0.3;
                    cache.insert(Record {
                        position: Vec3::new(i as f32 * 0.5 + jitter, j as f32 * 0.5 - jitter, 0.0),
                        ..flat_record(1.0 + 0.4 * (rng.next_f32() - 0.5), 0.6)
                    });
                }
            }
            cache.fit_curvatures_and_freeze();
            let (mut squared, mut sum, mut n) = (0.0f64, 0.0f64, 0);
            for _ in 0..4000 {
                let p = Vec3::new(2.0 + rng.next_f32() * 15.0, 2.0 + rng.next_f32() * 15.0, 0.0);
                let value = cache.lookup(p, Vec3::Z, 100.0, 0).expect("covered").x as f64;
                squared += (value - 1.0) * (value - 1.0);
                sum += value - 1.0;
                n += 1;
            }
            ((squared / n as f64).sqrt(), sum / n as f64)
        };
        let (placed, placed_bias) = error(1.0);
        let (wide, wide_bias) = error(1.3);
        assert!(
            wide < 0.85 * placed,
            "RMS error read as placed {placed}, 1.3 times as wide {wide}"
        );
        assert!(
            placed_bias.abs() < 0.01 && wide_bias.abs() < 0.01,
            "{placed_bias} {wide_bias}"
        );
    }

    /// `covered_in`, which stops adding weights once they reach `FIRM_COVERAGE`, answers as the
    /// sum over every record does (brute force, not through the index), at points on and off
    /// a floor of records of many sizes and tilts, under different roofs, at both levels.
    #[test]
    fn coverage_stops_early_and_agrees_with_every_records_weight() {
        use record::tests::flat_record;
        let cache = IrradianceCache::new(CacheSettings::new(0.2, 64, 16, 64, Metric::Hessian, 100.0));
        let mut rng = crate::sampling::Rng::new(7, 0);
        for _ in 0..400 {
            let radius = 0.05 + 0.6 * rng.next_f32();
            let tilt = Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, 2.0).normalize();
            cache.insert(Record {
                position: Vec3::new(8.0 * rng.next_f32(), 8.0 * rng.next_f32(), 0.05 * rng.next_f32()),
                normal: tilt,
                u_axis: Vec3::X.reject_from(tilt).normalize(),
                level: (rng.next_f32() < 0.3) as u32,
                headroom: if rng.next_f32() < 0.2 { 0.05 } else { 100.0 },
                ..flat_record(1.0, radius)
            });
        }
        let snapshot = cache.snapshot();
        let (mut covered, mut open) = (0, 0);
        for _ in 0..4000 {
            let point = Vec3::new(
                9.0 * rng.next_f32() - 0.5,
                9.0 * rng.next_f32() - 0.5,
                0.1 * rng.next_f32(),
            );
            let normal = Vec3::new(0.3 * (rng.next_f32() - 0.5), 0.3 * (rng.next_f32() - 0.5), 1.0).normalize();
            let headroom = if rng.next_f32() < 0.2 { 0.05 } else { 100.0 };
            let level = (rng.next_f32() < 0.3) as u32;
            let total: f32 = snapshot
                .records()
                .iter()
                .filter_map(|r| cache.lookup_weight(r, point, normal, headroom, level))
                .sum();
            // Summed in another order than the index's: too close to the bar to tell.
            if (total - FIRM_COVERAGE).abs() < 1e-4 {
                continue;
            }
            let firm = total >= FIRM_COVERAGE;
            assert_eq!(
                cache.covered_in(&snapshot, point, normal, headroom, level),
                firm,
                "{point} {total}"
            );
            if firm { covered += 1 } else { open += 1 }
        }
        assert!(
            covered > 500 && open > 500,
            "both answers occur: {covered} covered, {open} open"
        );
    }
}

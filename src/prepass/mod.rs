//! The cache prepass: every level-0 record the image will look up is placed before any pixel
//! is shaded, so that each pixel interpolates between records on all its sides and no pixel's
//! value depends on which pixels happened to render before it.
//!
//! The prepass visits sites (the first diffuse surface seen through a pixel) coarse to fine
//! over the whole image: a lattice of `COARSEST_STRIDE` pixels, then at each halving of the
//! stride the centres of the previous lattice's squares and then their edges' midpoints (as a
//! diamond-square refinement does), down to every pixel, and, when a pixel takes several
//! samples, every sample's own position. A site that no record covers yet gets one; records
//! are made where the error control asks for them and large ones made early cover most later
//! sites, so the fine rounds are mostly lookups.
//!
//! Each round is one deterministic step: its sites are looked up in the cache as it stood when
//! the round began (records of the round are held back), the records it needs are computed in
//! parallel, and they join the cache in site order. The record set, and so the image, is the
//! same whatever the number of threads and the tile size.
//!
//! Between rounds and at the end the records are checked against their neighbours
//! (`irradiance::validation`): this prepass's own records shrunk where their extrapolation
//! misses a neighbour, and every record's overshoot fitted once the set is complete; both
//! depend on the record set alone.

pub mod pool;
#[cfg(test)]
mod pooled_tests;
pub mod schedule;

use crate::image::pixel_map::PixelMap;
use crate::image::window::PixelWindow;
use crate::irradiance::IrradianceCache;
use crate::irradiance::index::FrozenIndex;
use crate::irradiance::last_bounce::{self, LastBounceGrid};
use crate::irradiance::record::Record;
use crate::irradiance::record_origins::RecordOrigin;
use crate::render::edges;
use crate::render::pixel::{RenderSettings, ThreadClock, ThreadStats, eye_spread, pixel_offset};
use crate::sampling::Rng;
use crate::scene::view::Camera;
use crate::shading::{Integrator, RayCounts, Work};
use crate::tiles::Tile;
use crate::tracer::SurfaceHit;
pub use pool::{Alone, GridRows, PixelRows, Pool, RoundRecords, Share, Timed};
use schedule::finest_rounds;
pub use schedule::{Lattice, SampleRounds};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

/// Random stream of a lattice site's record: after every stream a pixel's samples use (those
/// are numbered from 0, and the pixel's own light strata use u32::MAX + 1).
const LATTICE_STREAM: u64 = u32::MAX as u64 + 2;
/// Streams of the records made at sample positions: this plus the sample's number.
const SAMPLE_STREAM: u64 = u32::MAX as u64 + 3;

/// Where the prepass looks: a pixel, and the sample's position within it (None: its centre).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Site {
    pub x: u32,
    pub y: u32,
    pub sample: Option<PixelSample>,
}

/// Sample `index` of a pixel's `count` (`render::pixel_offset` places it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelSample {
    pub index: u32,
    pub count: u32,
}

/// What the prepass did.
#[derive(Debug, Default)]
pub struct PrepassOutcome {
    /// The pixel (x, y in the full image) of each record made, in the order they were made:
    /// for the `ic_records` layer (a list of the records, not a plane of the image, so that a
    /// region's prepass holds nothing per pixel of the whole frame).
    pub record_pixels: Vec<(u32, u32)>,
    /// Work per thread (thread i of every round adds to entry i).
    pub threads: Vec<ThreadStats>,
    pub rounds: usize,
    pub sites: u64,
    /// Pixels whose samples were visited one by one (see `pixels_needing_samples`).
    pub pixels_sampled: u64,
    pub records: u64,
    pub seconds: f64,
    /// The last bounce's grid (`--ic-deep grid`): cells with a mean, and samples taken.
    pub last_bounce_cells: u64,
    pub last_bounce_samples: u64,
    /// The rays those samples traced (of every kind: their sites' camera rays, their paths'
    /// segments and shadow rays), counted in `threads` too.
    pub last_bounce_rays: RayCounts,
    /// Records a sequence's moves dropped that were made again at their own points
    /// (`remake_records`), counted in `threads`' records too.
    pub records_remade: u64,
    /// The pixels an edge crosses (`edge_map`), when `--edge-samples` asked for them: the final
    /// pass takes them from here (`RenderSettings::edge_map`) instead of tracing the corners
    /// again.
    pub edges: Option<std::sync::Arc<PixelMap>>,
    /// Each round as this process saw it, in order.
    pub round_log: Vec<RoundLog>,
    /// Seconds in the pool (every exchange, rounds and rows: see `pool::Timed`).
    pub pool_s: f64,
    /// Seconds fitting the records' overshoot and freezing the set once it was complete: a
    /// part every rank repeats (what `bench/prepass_sim.py` models as serial).
    pub fit_s: f64,
}

/// One round of the prepass as one process saw it: the whole round's sites and records, and
/// this process's seconds computing its share, in the pool (handing its records over and
/// waiting for the others'), and in all (with putting the records in the cache), and the bytes
/// it took in from the other processes.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RoundLog {
    pub sites: u64,
    pub records: u64,
    pub compute_s: f64,
    pub pool_s: f64,
    pub seconds: f64,
    #[serde(default)]
    pub bytes: u64,
}

impl PrepassOutcome {
    /// Each pixel a record was made for, with how many, in scanline order.
    pub fn records_per_pixel(&self) -> Vec<((u32, u32), u32)> {
        let mut pixels = self.record_pixels.clone();
        pixels.sort_unstable_by_key(|&(x, y)| (y, x));
        let mut out: Vec<((u32, u32), u32)> = Vec::new();
        for pixel in pixels {
            match out.last_mut() {
                Some((last, count)) if *last == pixel => *count += 1,
                _ => out.push((pixel, 1)),
            }
        }
        out
    }
}

/// Runs `work` on one thread per entry of `stats` and adds each thread's rays, counters and
/// times to its entry (thread i of every round or pass to entry i).
fn on_threads(stats: &mut [ThreadStats], work: impl Fn(&mut RayCounts) + Sync) {
    std::thread::scope(|scope| {
        for thread_stats in stats.iter_mut() {
            let work = &work;
            scope.spawn(move || {
                let clock = ThreadClock::start();
                let mut mine = ThreadStats::default();
                work(&mut mine.rays);
                clock.stop(&mut mine);
                thread_stats.absorb(&mine);
            });
        }
    });
}

/// The last bounce's grid from sites over the whole image (the same grid for every region,
/// rank and thread count: each row's samples are computed alike wherever it is computed, and
/// the rows join in order). Every pixel starts sites up to `last_bounce::MAX_SITE_PIXELS`
/// pixels; a larger image takes every s-th pixel of every s-th row, so that a region task of a
/// large frame does not trace the whole frame's sites again. The pool's processes share the
/// rows.
fn last_bounce_grid<P: Pool>(
    pass: Pass<'_, '_>,
    pool: &mut P,
    stats: &mut [ThreadStats],
) -> Result<LastBounceGrid, P::Error> {
    let Pass { integrator, camera, .. } = pass;
    let stride = last_bounce::site_stride(camera.width, camera.height);
    let mine = pool.share().indices(camera.height.div_ceil(stride) as usize);
    let next = AtomicUsize::new(0);
    let rows = Mutex::new(Vec::new());
    on_threads(stats, |counts| {
        let mut work = Work::new(counts);
        while let Some(&k) = mine.get(next.fetch_add(1, Ordering::Relaxed)) {
            let y = k * stride;
            let mut row = Vec::new();
            for x in (0..camera.width).step_by(stride as usize) {
                integrator.last_bounce_samples(camera, (x, y), pass.settings.seed, &mut row, &mut work);
            }
            rows.lock().unwrap_or_else(|e| e.into_inner()).push((y, row));
        }
    });
    let mut rows = pool.grid_rows(rows.into_inner().unwrap_or_else(|e| e.into_inner()))?;
    rows.sort_unstable_by_key(|(y, _)| *y);
    let positions = rows
        .iter()
        .flat_map(|(_, row)| row.iter().map(|sample| sample.position));
    let cell = last_bounce::cell_side(integrator.scene.size(), positions);
    Ok(LastBounceGrid::from_samples(
        cell,
        rows.into_iter().flat_map(|(_, row)| row),
        integrator.last_bounce_reads(),
    ))
}

/// A pixel map of the area rendered, row-major, from its rows (or strips of rows) as the
/// pool's processes computed them.
fn pixel_map(window: PixelWindow, rows: PixelRows) -> PixelMap {
    let mut map = PixelMap::new(window.pixels());
    for (y, flags) in rows {
        let start = window.index(window.area.x0, y).expect("a row of the area");
        map.set_run(start, &flags);
    }
    map
}

/// The pixels whose samples may need records the centres' did not make, once every centre
/// has its records: those with a corner whose eye path reaches a diffuse surface no record
/// covers yet (between centres, or seen in a mirror from farther apart), or reaches other
/// planes than the centre's (a silhouette, a crease, a small object within the pixel). Inside
/// a covered surface a pixel's samples land between its covered corners, where the records
/// serve them. A row's answer follows from the geometry and the cache alone (five eye paths a
/// pixel, a lookup at each corner), so the pool's processes share the rows.
/// The answer holds the pixels of the area rendered (`RenderSettings::window`), row-major.
fn pixels_needing_samples<P: Pool>(
    pass: Pass<'_, '_>,
    snapshot: &FrozenIndex,
    pool: &mut P,
    stats: &mut [ThreadStats],
) -> Result<PixelMap, P::Error> {
    let Pass {
        integrator,
        cache,
        camera,
        ..
    } = pass;
    let window = pass.settings.window(camera);
    let area = window.area;
    let sites_at = |x: f32, y: f32, counts: &mut RayCounts| {
        let (origin, dir) = camera.ray(x, y);
        // Glossy directions from a fixed stream: the same rays on every process.
        let mut rng = Rng::new(0, ((y as u64) << 32) | x.to_bits() as u64);
        let spread = eye_spread(camera, pass.settings, dir, 1);
        integrator.record_sites(origin, dir, spread, &mut rng, &mut Work::new(counts))
    };
    let covered = |hits: &[SurfaceHit], counts: &mut RayCounts| {
        hits.iter().all(|h| {
            let headroom = integrator.headroom(cache, h, &mut Work::new(counts));
            cache.covered_in(snapshot, h.position, h.normal, headroom, 0)
        })
    };
    let mine = pool.share().indices(area.height() as usize);
    let next = AtomicUsize::new(0);
    let rows = Mutex::new(Vec::new());
    on_threads(stats, |counts| {
        while let Some(&k) = mine.get(next.fetch_add(1, Ordering::Relaxed)) {
            let y = area.y0 + k;
            // Each corner's hits, and whether records cover them all.
            let corners = |y: u32, counts: &mut RayCounts| -> Vec<(Vec<SurfaceHit>, bool)> {
                (area.x0..=area.x1)
                    .map(|x| {
                        let hits = sites_at(x as f32, y as f32, counts);
                        let ok = covered(&hits, counts);
                        (hits, ok)
                    })
                    .collect()
            };
            let (top, bottom) = (corners(y, counts), corners(y + 1, counts));
            let row: Vec<bool> = (area.x0..area.x1)
                .map(|x| {
                    let centre = sites_at(x as f32 + 0.5, y as f32 + 0.5, counts);
                    // The corners of the area's pixel x, counted from the area's left edge.
                    let (x, i) = ((x - area.x0) as usize, (x - area.x0) as usize + 1);
                    [&top[x], &top[i], &bottom[x], &bottom[i]].iter().any(|(corner, ok)| {
                        !ok || corner.len() != centre.len()
                            || corner.iter().zip(&centre).any(|(a, b)| !b.on_plane_of(a))
                    })
                })
                .collect();
            rows.lock().unwrap_or_else(|e| e.into_inner()).push((y, row));
        }
    });
    let rows = pool.pixel_rows(rows.into_inner().unwrap_or_else(|e| e.into_inner()))?;
    Ok(pixel_map(window, rows))
}

/// Rows of pixels an edge map's strip holds (a strip's pixels share their corner rays).
const EDGE_STRIP: u32 = 8;

/// The pixels of the area rendered an edge crosses (`render::edges::edge_pixels`), row-major
/// as `RenderSettings::window`'s: the same corner rays as the final pass's tiles, so the same
/// answer for every pixel. Strips of rows on every thread, shared by the pool's processes.
fn edge_map<P: Pool>(pass: Pass<'_, '_>, pool: &mut P, stats: &mut [ThreadStats]) -> Result<PixelMap, P::Error> {
    let Pass { integrator, camera, .. } = pass;
    let window = pass.settings.window(camera);
    let area = window.area;
    let mine = pool.share().indices(area.height().div_ceil(EDGE_STRIP) as usize);
    let next = AtomicUsize::new(0);
    let strips = Mutex::new(Vec::new());
    on_threads(stats, |counts| {
        while let Some(&k) = mine.get(next.fetch_add(1, Ordering::Relaxed)) {
            let y0 = area.y0 + k * EDGE_STRIP;
            let strip = Tile {
                x0: area.x0,
                y0,
                x1: area.x1,
                y1: (y0 + EDGE_STRIP).min(area.y1),
            };
            let found = edges::edge_pixels(integrator, camera, &strip, &mut Work::new(counts));
            strips.lock().unwrap_or_else(|e| e.into_inner()).push((y0, found));
        }
    });
    let strips = pool.pixel_rows(strips.into_inner().unwrap_or_else(|e| e.into_inner()))?;
    Ok(pixel_map(window, strips))
}

/// The primary ray through a site: the pixel's centre, or exactly the ray its sample takes
/// in `render::render_pixel` (same stream, same jitter).
fn site_ray(camera: &Camera, settings: &RenderSettings, site: Site) -> (glam::Vec3, glam::Vec3) {
    match site.sample {
        None => camera.ray(site.x as f32 + 0.5, site.y as f32 + 0.5),
        Some(PixelSample { index, count }) => {
            let pixel = site.y as u64 * camera.width as u64 + site.x as u64;
            let mut rng = Rng::for_sample(settings.seed, pixel, index as u64);
            let (jx, jy) = pixel_offset(index, count, settings.jitter, &mut rng);
            camera.ray(site.x as f32 + jx, site.y as f32 + jy)
        }
    }
}

/// Sites handed to a thread at a time.
const CHUNK: usize = 16;

/// What the work at every site needs.
#[derive(Clone, Copy)]
struct Pass<'a, 'b> {
    integrator: &'a Integrator<'b>,
    cache: &'a IrradianceCache,
    camera: &'a Camera,
    settings: &'a RenderSettings,
}

/// Runs one round's `mine` sites on one thread per entry of `stats`, looking records up in
/// `snapshot` (the cache as the round began). `counted`: the sites' lookups were counted
/// already (by `find_misses`).
fn run_round(
    pass: Pass<'_, '_>,
    sites: &[Site],
    mine: &[u32],
    snapshot: &FrozenIndex,
    counted: bool,
    stats: &mut [ThreadStats],
) -> RoundRecords {
    let mut made = on_sites(mine, stats, |index, counts, records: &mut RoundRecords| {
        let visit = Visit::Make {
            records,
            count_lookups: !counted,
        };
        site_visit(pass, snapshot, (index, sites[index as usize]), counts, visit);
    });
    made.sort_by_key(|(index, _)| *index);
    made
}

/// Of a round's `mine` sites, those whose eye path reaches a point no record in `snapshot`
/// covers: the sites that will make records (`run_round` then makes them), in site order.
fn find_misses(
    pass: Pass<'_, '_>,
    sites: &[Site],
    mine: &[u32],
    snapshot: &FrozenIndex,
    stats: &mut [ThreadStats],
) -> Vec<u32> {
    let mut found = on_sites(mine, stats, |index, counts, misses: &mut Vec<u32>| {
        if site_visit(pass, snapshot, (index, sites[index as usize]), counts, Visit::Find) {
            misses.push(index);
        }
    });
    found.sort_unstable();
    found
}

/// Runs `visit` on each of `mine` sites, `CHUNK` at a time, on one thread per entry of `stats`;
/// each thread gathers what its visits add to a list of its own, and the lists join (in no
/// particular order: the caller sorts).
fn on_sites<T: Send>(
    mine: &[u32],
    stats: &mut [ThreadStats],
    visit: impl Fn(u32, &mut RayCounts, &mut Vec<T>) + Sync,
) -> Vec<T> {
    let next = AtomicUsize::new(0);
    let all = Mutex::new(Vec::new());
    on_threads(stats, |counts| {
        let mut own = Vec::new();
        loop {
            let first = next.fetch_add(CHUNK, Ordering::Relaxed);
            if first >= mine.len() {
                break;
            }
            for &index in &mine[first..(first + CHUNK).min(mine.len())] {
                visit(index, counts, &mut own);
            }
        }
        all.lock().unwrap_or_else(|e| e.into_inner()).extend(own);
    });
    all.into_inner().unwrap_or_else(|e| e.into_inner())
}

/// Makes again, on one thread per entry of `stats`, the records a sequence's moves dropped
/// whose points still stand (`record_origins`), each at its point from its random state, and
/// adds them to the cache: before a frame's rounds, which then find them. How many were made.
fn remake_records(integrator: &Integrator<'_>, cache: &IrradianceCache, stats: &mut [ThreadStats]) -> u64 {
    let Some(origins) = cache.origins() else {
        return 0;
    };
    let queue = origins.take_to_remake();
    let indices: Vec<u32> = (0..queue.len() as u32).collect();
    let remade = on_sites(&indices, stats, |i, counts, out: &mut Vec<(Record, RecordOrigin)>| {
        let origin = &queue[i as usize];
        let mut rng = origin.rng.clone();
        let mut work = Work::new(counts);
        let record = integrator.eye_record(cache, &origin.hit, &mut rng, &mut work);
        out.push((record, origin.clone()));
    });
    let made = remade.len() as u64;
    cache.insert_remade(remade);
    made
}

/// What a site's visit does with the points on its eye path that no record covers.
enum Visit<'r> {
    /// Only finds whether there is one (counting every lookup on the path).
    Find,
    /// Makes their records (`count_lookups`: false where `Find` counted them already).
    Make {
        records: &'r mut RoundRecords,
        count_lookups: bool,
    },
}

/// Visits a site: follows its eye path to the diffuse points it reaches and looks each up;
/// answers whether any lacks a record, and with `Visit::Make` adds the records they need to
/// `records`, in the order the path reaches them. The site's random stream is its own, so a
/// site's records are the same whichever process visits it, and however often.
fn site_visit(
    pass: Pass<'_, '_>,
    snapshot: &FrozenIndex,
    (index, site): (u32, Site),
    counts: &mut RayCounts,
    mut visit: Visit<'_>,
) -> bool {
    let Pass {
        integrator,
        cache,
        camera,
        settings,
    } = pass;
    let pixel = site.y as u64 * camera.width as u64 + site.x as u64;
    let stream = match site.sample {
        None => LATTICE_STREAM,
        Some(s) => SAMPLE_STREAM + s.index as u64,
    };
    let mut rng = Rng::for_sample(settings.seed, pixel, stream);
    let (origin, dir) = site_ray(camera, settings, site);
    // The footprint the pixel's sample reads textures over (a lattice site: the centre's ray
    // of a pixel's one sample).
    let spread = eye_spread(camera, settings, dir, site.sample.map_or(1, |s| s.count));
    let mut work = Work::new(counts);
    work.sample.pixel = pixel as u32;
    let count = !matches!(
        visit,
        Visit::Make {
            count_lookups: false,
            ..
        }
    );
    let mut missed = false;
    for hit in integrator.record_sites(origin, dir, spread, &mut rng, &mut work) {
        work.lookups += count as u64;
        let headroom = integrator.headroom(cache, &hit, &mut work);
        if cache.covered_in(snapshot, hit.position, hit.normal, headroom, 0) {
            work.hits += count as u64;
            continue;
        }
        missed = true;
        // `Find` looks on to the path's end, so that it counts every lookup the site makes.
        if let Visit::Make { records, .. } = &mut visit {
            // Its origin, where a sequence will make it again after a move (`record_origins`).
            let origins = cache.origins();
            let start = origins.map(|_| rng.clone());
            let record = integrator.eye_record(cache, &hit, &mut rng, &mut work);
            if let (Some(origins), Some(rng)) = (origins, start) {
                origins.keep(&record, RecordOrigin { hit, rng });
            }
            records.push((index, record));
        }
    }
    missed
}

/// The record set as the rounds add to it, the same in every process that keeps it: each
/// round's records join the cache in site order, and after every round but the finest level's
/// this prepass's records shrink where their neighbours disagree (`irradiance::validation`);
/// the finest rounds fill the gaps shrinking opens. Only this prepass's records shrink: those
/// it found (a cache file's, an earlier frame's) are final, so the views they were made for
/// stay covered.
pub struct RecordSet<'c> {
    cache: &'c IrradianceCache,
    /// The rounds look records up in this lock-free copy of the cache, which grows with it
    /// and keeps its order (records shrink in place), so this prepass's records are those past
    /// the `found` ones.
    snapshot: FrozenIndex,
    found: usize,
    /// Rounds after which records shrink: the lattice's but its finest level's.
    coarse: usize,
    rounds: usize,
}

impl<'c> RecordSet<'c> {
    /// The set for a prepass over `area`, from what `cache` holds.
    pub fn new(cache: &'c IrradianceCache, area: crate::image::region::Region) -> Self {
        let snapshot = cache.snapshot();
        let lattice = Lattice::of(area).len();
        RecordSet {
            cache,
            found: snapshot.len(),
            coarse: lattice.saturating_sub(finest_rounds(area.width(), area.height())),
            rounds: 0,
            snapshot,
        }
    }

    pub fn snapshot(&self) -> &FrozenIndex {
        &self.snapshot
    }

    /// Adds the next round's records, in order; answers how many another of them, placed
    /// before, already covered (duplicates).
    pub fn add_round(&mut self, records: Vec<Record>) -> u64 {
        let before = self.snapshot.len();
        for record in records {
            self.snapshot.push(record.clone());
            self.cache.insert(record);
        }
        // The rounds before covered none of these (each was a site they missed, by the same
        // test): only the round's own records placed before one can have served it. Looked up
        // among the round's few alone, not the whole set (a fifth of what every rank repeats
        // per record: the rounds' serial share, `bench/prepass_sim.py`).
        let fresh: Vec<usize> = (before..self.snapshot.len()).collect();
        let round = self.snapshot.subset(&fresh);
        let duplicates = round
            .records()
            .iter()
            .enumerate()
            .filter(|(j, r)| {
                self.cache
                    .covered_by(&round, |k| k < *j, r.position, r.normal, r.headroom, 0)
            })
            .count() as u64;
        if self.rounds < self.coarse && self.snapshot.len() > before {
            let (found, cache) = (self.found, self.cache);
            cache.shrink_where_neighbours_disagree(&mut self.snapshot, |i| i >= found, |i| i >= before);
        }
        self.rounds += 1;
        duplicates
    }
}

/// What a process that keeps the records without taking part in the rounds hears next.
#[derive(Clone, Debug, PartialEq)]
pub enum Kept {
    /// A round: its log and its records in order, each with its site's pixel (y * width + x).
    Round(RoundLog, Vec<(u32, Record)>),
    /// The rounds are over: the pixels whose samples were visited one by one.
    End(u64),
}

/// Keeps the record set the rounds make elsewhere (an MPI master: `parallel::prepass`) in
/// `cache`, round by round as `next` hands them over, exactly as the processes that make them
/// keep it: its file gets the same records, in the same order, and the same shrunk ones. An
/// error of `next` ends it.
pub fn keep_rounds<E>(
    cache: &IrradianceCache,
    camera: &Camera,
    settings: &RenderSettings,
    mut next: impl FnMut() -> Result<Kept, E>,
) -> Result<PrepassOutcome, E> {
    let start = Instant::now();
    let mut outcome = PrepassOutcome::default();
    let mut set = RecordSet::new(cache, settings.area(camera));
    loop {
        match next()? {
            Kept::Round(log, records) => {
                let width = camera.width;
                outcome
                    .record_pixels
                    .extend(records.iter().map(|(pixel, _)| (pixel % width, pixel / width)));
                outcome.records += records.len() as u64;
                set.add_round(records.into_iter().map(|(_, record)| record).collect());
                outcome.sites += log.sites;
                outcome.rounds += 1;
                outcome.round_log.push(log);
            }
            Kept::End(pixels_sampled) => {
                outcome.pixels_sampled = pixels_sampled;
                break;
            }
        }
    }
    // Nothing reads this copy (the master renders nothing): it is frozen without the fit.
    cache.freeze();
    outcome.seconds = start.elapsed().as_secs_f64();
    Ok(outcome)
}

/// Runs the whole prepass in this process into `integrator`'s cache (nothing to do without one).
/// `watch` hears of each round as it ends, with the rounds done and the rounds in all, and
/// answers whether to go on (a render stopped by a signal ends after the round it is in, every
/// record so far in the cache).
pub fn run(
    integrator: &Integrator<'_>,
    camera: &Camera,
    settings: &RenderSettings,
    watch: &dyn Fn(usize, usize) -> bool,
) -> PrepassOutcome {
    let Ok(outcome) = run_watched(integrator, camera, settings, &mut Alone, watch);
    outcome
}

/// Runs the prepass as one of several processes pooled by `pool`: each list's items (rows,
/// sites) are computed by the process whose share holds them, the pool hands every process
/// all of the results, and each round's records join the cache in site order, so every process
/// ends each round with the same cache as one process alone would. An error of the pool ends it.
pub fn run_shared<P: Pool>(
    integrator: &Integrator<'_>,
    camera: &Camera,
    settings: &RenderSettings,
    pool: &mut P,
) -> Result<PrepassOutcome, P::Error> {
    run_watched(integrator, camera, settings, pool, &|_, _| true)
}

fn run_watched<P: Pool>(
    integrator: &Integrator<'_>,
    camera: &Camera,
    settings: &RenderSettings,
    pool: &mut P,
    watch: &dyn Fn(usize, usize) -> bool,
) -> Result<PrepassOutcome, P::Error> {
    // Every exchange is timed, for the report (under mpirun: the rounds' barriers).
    let mut timed = Timed::new(pool);
    let pool = &mut timed;
    let start = Instant::now();
    let mut outcome = PrepassOutcome {
        threads: vec![ThreadStats::default(); settings.threads.max(1)],
        ..Default::default()
    };
    let Some(cache) = integrator.cache else {
        return Ok(outcome);
    };
    if integrator.options.ambient_bounces == 0 {
        return Ok(outcome);
    }
    let pass = Pass {
        integrator,
        cache,
        camera,
        settings,
    };
    let grid_level = integrator
        .last_bounce_level()
        .filter(|_| integrator.options.last_bounce_grid);
    // Only a process that renders reads the grid (a master keeping the records does not).
    if grid_level.is_some() && cache.last_bounce().is_none() && pool.share().renders() {
        let mut sampling = vec![ThreadStats::default(); outcome.threads.len()];
        let grid = last_bounce_grid(pass, pool, &mut sampling)?;
        for (thread, part) in outcome.threads.iter_mut().zip(&sampling) {
            thread.absorb(part);
            outcome.last_bounce_rays.add(&part.rays);
        }
        outcome.last_bounce_cells = grid.cells() as u64;
        outcome.last_bounce_samples = grid.samples();
        cache.set_last_bounce(grid);
    }
    // A sequence's records that the moves dropped, made again where they were (with the grid
    // of this frame), before the rounds look for what is missing.
    outcome.records_remade = remake_records(integrator, cache, &mut outcome.threads);
    // Only the region's pixels (the whole image without --region) will be shaded.
    let area = settings.area(camera);
    let mut set = RecordSet::new(cache, area);
    let run = |sites: Vec<Site>,
               set: &mut RecordSet<'_>,
               outcome: &mut PrepassOutcome,
               pool: &mut Timed<'_, P>|
     -> Result<(), P::Error> {
        let began = Instant::now();
        let bytes_before = pool.bytes_received();
        let mut pooled = 0.0;
        let mine = pool.share().indices(sites.len());
        let snapshot = set.snapshot();
        // Processes sharing a round first find which of their sites lack records, and then
        // share those sites out evenly: a round's time is its slowest process's, and the
        // records are nearly all of it (a site's lookup is about 1.5 us, a record at -ab 2
        // about 0.8 ms: conference room), so the records, not the sites, must be spread.
        let made = if pool.share() == Share::All {
            run_round(pass, &sites, &mine, snapshot, false, &mut outcome.threads)
        } else {
            let misses = find_misses(pass, &sites, &mine, snapshot, &mut outcome.threads);
            let pooling = Instant::now();
            let mut all = pool.sites(misses)?;
            pooled += pooling.elapsed().as_secs_f64();
            all.sort_unstable();
            let share: Vec<u32> = pool
                .share()
                .indices(all.len())
                .into_iter()
                .map(|k| all[k as usize])
                .collect();
            run_round(pass, &sites, &share, snapshot, true, &mut outcome.threads)
        };
        let computed = Instant::now();
        let compute_s = (computed - began).as_secs_f64() - pooled;
        let mut made = pool.round(made)?;
        pooled += computed.elapsed().as_secs_f64();
        made.sort_by_key(|(index, _)| *index);
        let records = made.len();
        let keeps = pool.keeps();
        let mut kept = Vec::new();
        let mut round = Vec::with_capacity(made.len());
        for (index, record) in made {
            let Some(&site) = sites.get(index as usize) else {
                continue;
            };
            outcome.record_pixels.push((site.x, site.y));
            if keeps {
                kept.push((site.y * camera.width + site.x, record.clone()));
            }
            round.push(record);
        }
        outcome.records += round.len() as u64;
        // A record another of this round's sites made first would have served this one:
        // the price of computing a round's records side by side.
        outcome.threads[0].rays.duplicates += set.add_round(round);
        outcome.sites += sites.len() as u64;
        outcome.rounds += 1;
        let log = RoundLog {
            sites: sites.len() as u64,
            records: records as u64,
            compute_s,
            pool_s: pooled,
            bytes: pool.bytes_received() - bytes_before,
            seconds: began.elapsed().as_secs_f64(),
        };
        outcome.round_log.push(log);
        pool.kept(log, &kept)
    };
    let lattice = Lattice::of(area);
    let mut total = lattice.len();
    let mut go_on = true;
    for k in 0..lattice.len() {
        run(lattice.sites(k), &mut set, &mut outcome, pool)?;
        go_on = watch(outcome.rounds, total);
        if !go_on {
            break;
        }
    }
    // The pixels an edge crosses take more samples (`render::edges`), each a site: the final
    // pass finds the same pixels from the same rays.
    let spp = settings.spp.max(1);
    let edges = match go_on && settings.edge_samples > spp {
        true => Some(edge_map(pass, pool, &mut outcome.threads)?),
        false => None,
    };
    if go_on && (spp > 1 || settings.jitter || edges.is_some()) {
        let needs = if spp > 1 || settings.jitter {
            pixels_needing_samples(pass, set.snapshot(), pool, &mut outcome.threads)?
        } else {
            PixelMap::new(settings.window(camera).pixels())
        };
        let edge = |i: usize| edges.as_ref().is_some_and(|e| e.get(i));
        // How many samples of pixel i need sites: made from the two maps when asked, not kept
        // (4 bytes a pixel).
        let count = |i: usize| {
            if edge(i) {
                settings.edge_samples
            } else {
                spp * needs.get(i) as u32
            }
        };
        outcome.pixels_sampled = (0..needs.len()).filter(|&i| count(i) > 0).count() as u64;
        let more = SampleRounds::new(settings.window(camera), &count);
        total += more.len();
        for k in 0..more.len() {
            run(more.sites(k), &mut set, &mut outcome, pool)?;
            if !watch(outcome.rounds, total) {
                break;
            }
        }
    }
    pool.ended(outcome.pixels_sampled)?;
    // The record set is complete: each record's overshoot is fitted from its neighbours, and
    // from now on lookups read the cache's lock-free copy.
    let fitting = Instant::now();
    if go_on {
        cache.fit_curvatures_and_freeze();
    } else {
        cache.freeze();
    }
    outcome.fit_s = fitting.elapsed().as_secs_f64();
    outcome.edges = edges.map(std::sync::Arc::new);
    outcome.seconds = start.elapsed().as_secs_f64();
    outcome.pool_s = timed.seconds;
    Ok(outcome)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_are_counted_per_pixel_in_scanline_order() {
        let outcome = PrepassOutcome {
            record_pixels: vec![(5, 2), (1, 3), (5, 2), (0, 2), (5, 2), (1, 3)],
            ..Default::default()
        };
        assert_eq!(outcome.records_per_pixel(), vec![((0, 2), 1), ((5, 2), 3), ((1, 3), 2)]);
    }
}

//! Component mode's pipeline under a prepass: a worker fills its waits at the prepass's round
//! barriers by tracing the tiles it will render (`render::ahead`): their emission, direct and
//! specular light, which need no record, while the other workers finish the round's indirect
//! diffuse work. After the prepass the ranks exchange which tiles each has begun (`claims`);
//! the master hands each worker its own first, and the worker finishes them from their traces.
//!
//! Worker k of W takes tiles k, k + W, k + 2W, ... in order, so no two claim a tile, and traces
//! a few pixels at a time, so that a round's collective, tested between the steps, is never
//! held up by more than a step (about 0.1-0.3 ms).

use crate::render::ahead::{TileTrace, TileTracer};
use crate::render::pixel::RenderSettings;
use crate::scene::view::Camera;
use crate::shading::Integrator;
use crate::tiles::Tile;
use std::collections::HashMap;
use std::time::{Duration, Instant};

/// Pixels traced between two looks at the collective.
const PIXELS_A_STEP: usize = 16;

/// The most bytes of traces a rank holds: about 400 bytes a pixel of one sample, so about
/// 170,000 pixels (a quarter of a 1280x720 frame per worker at 2 workers; a 4K frame's workers
/// each trace that many at most, and shade the rest after the prepass).
pub const TRACE_BYTES_LIMIT: usize = 64 << 20;

/// A worker's tracing ahead, stepped by its waits.
pub struct TracingAhead<'a> {
    integrator: Integrator<'a>,
    camera: &'a Camera,
    settings: &'a RenderSettings,
    tiles: &'a [Tile],
    /// This worker's tiles, in the order it traces them.
    mine: Vec<u32>,
    next: usize,
    current: Option<(u32, TileTracer)>,
    traced: Vec<(u32, TileTrace)>,
    bytes: usize,
    limit: usize,
    /// Time spent tracing, and pixels traced.
    pub busy: Duration,
    pub pixels: u64,
}

impl<'a> TracingAhead<'a> {
    /// Worker `index` of `workers` (counted from 0), over the job's `tiles`.
    pub fn new(
        integrator: Integrator<'a>,
        camera: &'a Camera,
        settings: &'a RenderSettings,
        tiles: &'a [Tile],
        (index, workers): (usize, usize),
        limit: usize,
    ) -> Self {
        TracingAhead {
            integrator,
            camera,
            settings,
            tiles,
            mine: (index..tiles.len()).step_by(workers.max(1)).map(|t| t as u32).collect(),
            next: 0,
            current: None,
            traced: Vec::new(),
            bytes: 0,
            limit,
            busy: Duration::ZERO,
            pixels: 0,
        }
    }

    /// Traces a few more pixels; answers whether there was anything left to trace.
    pub fn step(&mut self) -> bool {
        if self.bytes >= self.limit {
            return false;
        }
        let started = Instant::now();
        let (index, tracer) = match &mut self.current {
            Some(current) => current,
            None => {
                let Some(&index) = self.mine.get(self.next) else {
                    return false;
                };
                self.next += 1;
                let tile = self.tiles[index as usize];
                let tracer = TileTracer::new(&self.integrator, self.camera, self.settings, tile);
                self.current.insert((index, tracer))
            }
        };
        let before = (tracer.len(), tracer.bytes());
        let done = tracer.step(&self.integrator, self.camera, self.settings, PIXELS_A_STEP);
        self.pixels += (tracer.len() - before.0) as u64;
        self.bytes += tracer.bytes() - before.1;
        if done {
            let index = *index;
            if let Some((_, tracer)) = self.current.take() {
                self.traced.push((index, tracer.into_trace()));
            }
        }
        self.busy += started.elapsed();
        true
    }

    /// The tiles begun, each with the traces of its first pixels, and what that took.
    pub fn finish(mut self) -> (TracedTiles, AheadReport) {
        if let Some((index, tracer)) = self.current.take()
            && !tracer.is_empty()
        {
            self.traced.push((index, tracer.into_trace()));
        }
        let report = AheadReport {
            pixels: self.pixels,
            tiles: self.traced.len() as u64,
            seconds: self.busy.as_secs_f64(),
        };
        let traced = TracedTiles {
            tiles: self.traced.into_iter().collect(),
        };
        (traced, report)
    }
}

/// What a worker traced ahead: pixels, tiles begun, and the seconds of waits it filled.
#[derive(Clone, Copy, Debug, Default)]
pub struct AheadReport {
    pub pixels: u64,
    pub tiles: u64,
    pub seconds: f64,
}

/// A worker's tiles traced ahead, by tile index, until it renders them.
#[derive(Debug, Default)]
pub struct TracedTiles {
    tiles: HashMap<u32, TileTrace>,
}

impl TracedTiles {
    /// The indices of the tiles begun, in order (this worker's claims).
    pub fn claims(&self) -> Vec<u32> {
        let mut claims: Vec<u32> = self.tiles.keys().copied().collect();
        claims.sort_unstable();
        claims
    }

    /// The traces of tile `index`, if it was begun here (each is taken once).
    pub fn take(&mut self, index: u32) -> Option<TileTrace> {
        self.tiles.remove(&index)
    }
}

//! The single-process renderer: the image is cut into tiles, threads take tiles from a shared
//! counter until none are left, and each pixel averages `spp` stratified (jittered) samples over
//! its area, which is the box filter a converged reference integrates.

pub mod ahead;
pub mod edges;
pub mod error_estimate;
pub mod noise;
pub mod passes;
pub mod pixel;
pub mod sink;

pub use pixel::{RenderSettings, ThreadClock, ThreadStats, pixel_offset, pixel_strata, render_pixel, render_tile};

use crate::checkpoint::{Checkpoint, Restored};
use crate::image::framebuffer::FrameBuffer;
use crate::image::layered_exr::StreamedExr;
use crate::prepass::{self, PrepassOutcome};
use crate::progress::Progress;
use crate::scene::view::Camera;
use crate::shading::Integrator;
use crate::tiles::{TileQueue, tiles_in};
use sink::TileSink;

/// What a one-process render made: the image, each thread's work (the prepass's included)
/// and the prepass's own account, when there was one.
pub struct Rendered {
    /// The frame, when it was held whole (not streamed).
    pub frame: Option<FrameBuffer>,
    pub threads: Vec<ThreadStats>,
    pub prepass: Option<PrepassOutcome>,
}

/// Renders the whole image on `settings.threads` threads in one process.
pub fn render(
    integrator: &Integrator<'_>,
    camera: &Camera,
    settings: &RenderSettings,
    progress: &Progress,
) -> Rendered {
    render_resumable(integrator, camera, settings, progress, None, None)
}

/// As [`render`], but with a checkpoint: the tiles an earlier run finished are taken from it
/// and every tile finished now is journalled; and with `streamed`, each finished tile goes to
/// the EXR's stream instead of a frame held whole (`Rendered::frame` is then None).
pub fn render_resumable(
    integrator: &Integrator<'_>,
    camera: &Camera,
    settings: &RenderSettings,
    progress: &Progress,
    checkpoint: Option<(&Checkpoint, Restored)>,
    streamed: Option<&StreamedExr>,
) -> Rendered {
    // A render stopped by SIGTERM or SIGINT (caught only in one-process renders, see
    // sys::signals) ends after the round or the tiles in progress. One whose stream cannot be
    // written (a full disk) ends too, as its file cannot be finished, unless a checkpoint keeps
    // the tiles: then it renders on, so that a rerun with room to write renders nothing again.
    let keeps_tiles = checkpoint.is_some();
    let stopped =
        || crate::sys::signals::received().is_some() || (!keeps_tiles && streamed.is_some_and(StreamedExr::failed));
    let prepared = prepare(integrator, camera, settings, progress);
    let (settings, prepass) = (&prepared.settings, prepared.prepass);
    let reading = prepared_reader(integrator, prepass.is_some());
    let all = tiles_in(
        camera.width,
        camera.height,
        settings.tile_width,
        settings.tile_height,
        settings.region,
    );
    // The pixels rendered: the whole image, or a region task's region.
    let window = settings.window(camera);
    // What an earlier run finished: the journal's tiles, in a frame of the area rendered.
    let (journal, todo, restored) = match checkpoint {
        Some((journal, restored)) => {
            assert_eq!(
                restored.frame.window(),
                window,
                "the journal was opened for another area"
            );
            (Some(journal), restored.unfinished(), Some(restored))
        }
        None => (None, (0..all.len()).collect(), None),
    };
    progress.advance(all.len() - todo.len());
    let sink = match streamed {
        Some(stream) => TileSink::streamed(stream, prepass.as_ref(), restored.as_ref().map(|r| (&all[..], r))),
        // The frame holds the area rendered only: a region task's memory grows with its region.
        None => TileSink::held(restored.map_or_else(|| FrameBuffer::windowed(window), |r| r.frame)),
    };
    let todo = if stopped() { Vec::new() } else { todo };
    let mut stats = trace_tiles(
        &reading,
        camera,
        settings,
        (&all, todo),
        &sink,
        (journal, None),
        progress,
        &stopped,
    );
    progress.finish();
    let frame = sink.into_frame(prepass.as_ref());
    if let Some(prepass) = &prepass {
        add_prepass_work(&mut stats, &prepass.threads);
    }
    Rendered {
        frame,
        threads: stats,
        prepass,
    }
}

/// What the pixels of a render start from: the prepass's account (when the settings ask for
/// one and there is a cache) and the settings they take, with the edges it found.
pub struct Prepared {
    pub prepass: Option<PrepassOutcome>,
    pub settings: RenderSettings,
}

/// Runs the prepass, if any: after it the record set is complete and frozen.
pub fn prepare(
    integrator: &Integrator<'_>,
    camera: &Camera,
    settings: &RenderSettings,
    progress: &Progress,
) -> Prepared {
    let watch = watch_prepass(progress);
    let prepass =
        (settings.prepass && integrator.cache.is_some()).then(|| prepass::run(integrator, camera, settings, &watch));
    // The pixels an edge crosses, as the prepass found them.
    let settings = match prepass.as_ref().and_then(|p| p.edges.clone()) {
        Some(map) => RenderSettings {
            edge_map: Some(map),
            ..settings.clone()
        },
        None => settings.clone(),
    };
    Prepared { prepass, settings }
}

/// The integrator the pixels take: after a prepass they only read the cache (see
/// `Integrator::frozen`).
pub fn prepared_reader<'a>(integrator: &Integrator<'a>, prepassed: bool) -> Integrator<'a> {
    Integrator {
        frozen: prepassed,
        ..*integrator
    }
}

/// Renders tiles `todo` of `all` into `sink` on `settings.threads` threads, each taking the next
/// tile until none is left or `stopped` says so; every tile is measured for the error estimate
/// (into `tallies` too, tile by tile, where given) and journalled when there is a journal.
/// Each thread's work.
#[allow(clippy::too_many_arguments)]
pub fn trace_tiles(
    integrator: &Integrator<'_>,
    camera: &Camera,
    settings: &RenderSettings,
    (all, todo): (&[crate::tiles::Tile], Vec<usize>),
    sink: &TileSink<'_>,
    (journal, tallies): (Option<&Checkpoint>, Option<&passes::TileTallies>),
    progress: &Progress,
    stopped: &(dyn Fn() -> bool + Sync),
) -> Vec<ThreadStats> {
    let queue = TileQueue::new(todo);
    let probe = error_estimate::ErrorProbe::new(integrator, camera, settings);
    let threads = settings.threads.max(1).min(queue.len().max(1));
    std::thread::scope(|scope| {
        let workers: Vec<_> = (0..threads)
            .map(|_| {
                scope.spawn(|| {
                    let mut stats = ThreadStats::default();
                    let clock = ThreadClock::start();
                    while !stopped()
                        && let Some(index) = queue.next()
                    {
                        let tile = &all[index];
                        let values = render_tile(integrator, camera, settings, tile, &mut stats.rays, |_| {});
                        let mut tally = error_estimate::ErrorTally::default();
                        probe.tile(&mut tally, tile, &values);
                        if let Some(tallies) = tallies {
                            tallies.add(index, &tally);
                        }
                        stats.error.merge(&tally);
                        if let Some(journal) = journal {
                            journal.tile(index as u32, 0, &values);
                        }
                        sink.store(tile, values);
                        stats.tiles += 1;
                        progress.advance(1);
                    }
                    clock.stop(&mut stats);
                    stats
                })
            })
            .collect();
        workers.into_iter().map(|w| w.join().unwrap_or_default()).collect()
    })
}

/// What the prepass hears after each of its rounds (`prepass::run`'s `watch`): the progress
/// is told, and the prepass goes on unless a SIGTERM or SIGINT asked to stop (sys::signals).
pub fn watch_prepass(progress: &Progress) -> impl Fn(usize, usize) -> bool + '_ {
    move |done, total| {
        debug_assert!(done <= total);
        progress.prepass_rounds(total);
        progress.prepass_round_done();
        crate::sys::signals::received().is_none()
    }
}

/// Adds the prepass's work, thread by thread, to the threads that rendered afterwards.
pub fn add_prepass_work(threads: &mut Vec<ThreadStats>, prepass: &[ThreadStats]) {
    if threads.len() < prepass.len() {
        threads.resize(prepass.len(), ThreadStats::default());
    }
    for (thread, before) in threads.iter_mut().zip(prepass) {
        thread.absorb(before);
    }
}

//! `icrender render`: prepare the job, trace, write the layered EXR, the preview and the
//! statistics, and report the error against a reference if one is given.

mod header;
mod outputs;
mod passes;

pub use header::{data_attributes, options_line, part_settings, rerun_command};
pub use outputs::{Outputs, check_new_output, job_stats, one_process_stats, output_name, producible_layers};

use super::{CommandError, CommandResult, warn};
use crate::checkpoint::{self, Checkpoint, Restored};
use crate::cli::RenderArgs;
use crate::cli::{DenoiseQualityArg, ModeArg, ProgressArg};
use crate::image::denoise;
use crate::image::denoise::Quality;
use crate::image::framebuffer::FrameBuffer;
use crate::image::layered_exr::ExrLayout;
use crate::image::layered_exr::StreamedExr;
use crate::image::metrics;
use crate::image::region::Region;
use crate::image::window::PixelWindow;
use crate::job::{Job, validate};
use crate::parallel::{JobHost, Mode, ParallelJob, under_mpirun};
use crate::progress::{self, Progress};
use crate::render::render_resumable;
use crate::shading::Integrator;
use crate::stats::RenderStats;
use crate::sys::image_io;
use crate::tiles::{Tile, tiles_in};
use std::path::Path;
use std::time::Instant;

fn denoise_quality(args: &RenderArgs) -> Quality {
    match args.denoise_quality {
        DenoiseQualityArg::Fast => Quality::Fast,
        DenoiseQualityArg::Balanced => Quality::Balanced,
        DenoiseQualityArg::High => Quality::High,
    }
}

/// `--denoise` needs the library and a working device: checked before anything is rendered
/// or written, so a render never runs for minutes only to fail at the end.
pub(crate) fn check_denoiser(args: &RenderArgs) -> Result<(), CommandError> {
    denoise::Denoiser::new(denoise_quality(args), args.threads)
        .map(|_| ())
        .map_err(|e| CommandError::input(format!("--denoise: {e}")))
}

/// With --checkpoint, the cache goes to the checkpoint directory (which `open_checkpoint` has
/// made) unless -af names a file, so a resumed render starts with the records the killed one
/// wrote.
pub fn with_checkpoint_cache(args: &RenderArgs) -> RenderArgs {
    let mut args = args.clone();
    if let Some(dir) = &args.checkpoint
        && args.ambient_file.is_none()
    {
        args.ambient_file = Some(checkpoint::cache_file(dir));
    }
    args
}

/// What identifies a job to its checkpoint: everything that changes the image or the tiles.
/// (The mode, ranks, threads and output names do not: a render may resume in another mode.)
pub fn checkpoint_key(args: &RenderArgs) -> String {
    let scene = std::fs::canonicalize(&args.scene).unwrap_or_else(|_| args.scene.clone());
    let key = format!(
        "scene {}; {}; tile {}; view {:?}",
        scene.display(),
        options_line(args),
        args.tile,
        args.view
    );
    // A part journals its own tiles (keys of whole renders stay as they were).
    match &args.region {
        Some(r) => format!("{key}; region {r:?}"),
        None => key,
    }
}

/// The --region option's rectangle, if given.
fn region_of(args: &RenderArgs) -> Result<Option<Region>, CommandError> {
    args.region
        .as_deref()
        .map(|v| Region::from_option(v, args.width, args.height))
        .transpose()
        .map_err(CommandError::input)
}

/// The tiles this render makes: the whole image's, or those of its --region.
pub fn render_tiles(args: &RenderArgs) -> Result<Vec<Tile>, CommandError> {
    let (tile_width, tile_height) = crate::cli::parse_tile(&args.tile).map_err(CommandError::input)?;
    Ok(tiles_in(
        args.width,
        args.height,
        tile_width,
        tile_height,
        region_of(args)?,
    ))
}

/// The pixels this render's frame holds: its --region, or the whole image.
pub fn render_window(args: &RenderArgs) -> Result<PixelWindow, CommandError> {
    let area = region_of(args)?.unwrap_or_else(|| Region::whole(args.width, args.height));
    Ok(PixelWindow::new(area, args.width, args.height))
}

/// Opens the --checkpoint journal (if asked for) and says what an earlier run left.
/// Opened before the scene is loaded, so another job's checkpoint is refused at once.
pub fn open_checkpoint(args: &RenderArgs, all_tiles: &[Tile]) -> Result<Option<(Checkpoint, Restored)>, CommandError> {
    let Some(dir) = &args.checkpoint else {
        return Ok(None);
    };
    let (journal, restored) =
        Checkpoint::open(dir, &checkpoint_key(args), all_tiles, render_window(args)?).map_err(CommandError::input)?;
    if restored.torn_bytes > 0 {
        warn(&format!(
            "{}: dropped {} bytes of a torn last journal entry",
            dir.display(),
            restored.torn_bytes
        ));
    }
    if !args.quiet && restored.count() > 0 {
        eprintln!(
            "icrender: resuming from {}: {} of {} tiles are already finished",
            dir.display(),
            restored.count(),
            all_tiles.len()
        );
    }
    Ok(Some((journal, restored)))
}

/// Prints the error of the written image against the reference, next to the run time.
pub fn report_error(
    exr: &Path,
    reference: &image_io::ImageData,
    reference_path: &Path,
    seconds: f64,
) -> Result<(), CommandError> {
    let written = image_io::read_image(exr, &[]).map_err(|e| CommandError::input(format!("{}: {e}", exr.display())))?;
    let errors = metrics::compare(&written, reference)
        .map_err(|e| CommandError::input(format!("{}: {e}", reference_path.display())))?;
    for e in &errors {
        println!(
            "error {:<17} rmse {:.6e}  relmse {:.6e}  time {:.3} s",
            e.layer, e.rmse, e.rel_mse, seconds
        );
    }
    Ok(())
}

fn mode_of(arg: ModeArg) -> Mode {
    match arg {
        ModeArg::Serial => Mode::Serial,
        ModeArg::Noshare => Mode::Noshare,
        ModeArg::Centralised => Mode::Centralised,
        ModeArg::Broadcast => Mode::Broadcast,
        ModeArg::Component => Mode::Component,
    }
}

/// The render command's side of a run under mpirun: its options, outputs and checkpoint.
struct RenderHost<'a> {
    args: &'a RenderArgs,
    /// Rank 0's outputs, once checked.
    outputs: std::sync::OnceLock<Outputs>,
}

impl JobHost for RenderHost<'_> {
    fn validate(&self) -> Result<(), String> {
        validate(self.args)
    }

    fn check_outputs(&self) -> Result<(), String> {
        let outputs = Outputs::check(self.args).map_err(|e| e.message)?;
        let _ = self.outputs.set(outputs);
        Ok(())
    }

    fn open_checkpoint(&self, tiles: &[Tile]) -> Result<Option<(Checkpoint, Restored)>, String> {
        open_checkpoint(self.args, tiles).map_err(|e| e.message)
    }

    fn prepare(&self, master: bool, threads: usize) -> Result<Job, String> {
        // Only the master keeps the cache file (beside the checkpoint with --checkpoint).
        let mut args = if master {
            with_checkpoint_cache(self.args)
        } else {
            self.args.clone()
        };
        args.threads = Some(threads);
        if !master {
            args.ambient_file = None;
        }
        Job::prepare(&args, crate::memory::Role::AnyRank).map_err(|e| e.message)
    }

    fn job_stats(&self, job: &Job, mode: &'static str, ranks: usize, render_s: f64) -> RenderStats {
        job_stats(self.args, job, mode, ranks, render_s)
    }

    fn write(&self, job: &Job, frame: &FrameBuffer, stats: &RenderStats) -> Result<(), String> {
        let outputs = self.outputs.get().ok_or("the outputs were not checked")?;
        outputs.write(self.args, job, frame, stats).map_err(|e| e.message)
    }

    fn tile_layout(&self, job: &Job, ranks: usize) -> Option<ExrLayout> {
        // --denoise holds the frame whole, and --checkpoint journals the tiles' values.
        (!self.args.denoise && self.args.checkpoint.is_none())
            .then(|| Outputs::layout(self.args, job, job.settings.window(&job.camera), &[], ranks))
    }

    fn stream(&self, job: &Job, ranks: usize) -> Result<Option<StreamedExr>, String> {
        let outputs = self.outputs.get().ok_or("the outputs were not checked")?;
        outputs.stream(self.args, job, ranks).map_err(|e| e.message)
    }

    fn finish_stream(&self, job: &Job, streamed: StreamedExr, stats: &RenderStats) -> Result<(), String> {
        let outputs = self.outputs.get().ok_or("the outputs were not checked")?;
        outputs
            .finish_stream(self.args, job, streamed, stats)
            .map_err(|e| e.message)
    }
}

fn run_parallel(args: &RenderArgs, mode: Mode) -> CommandResult {
    if args.progress == ProgressArg::Json {
        warn("--progress json reports one-process renders only: under mpirun the master prints its table at the end");
    }
    let host = RenderHost {
        args,
        outputs: std::sync::OnceLock::new(),
    };
    let tile = crate::cli::parse_tile(&args.tile).map_err(CommandError::input)?;
    crate::parallel::run(&ParallelJob {
        mode,
        width: args.width,
        height: args.height,
        tile,
        threads: args.threads,
        sync: args.sync,
        send: args.send,
        pa: args.pa,
        pa_queue: args.pa_queue,
        pr_waits: args.pr_waits,
        silence_limit: std::time::Duration::from_secs_f64(args.timeout.max(1.0)),
        seed: args.seed,
        cache_file: args.ambient_file.is_some(),
        quiet: args.quiet,
        host: &host,
    })
    .map_err(CommandError::from)
}

/// What a render stopped by `signal` says: nothing was written, and what a rerun resumes.
fn interrupted(args: &RenderArgs, signal: i32) -> CommandError {
    CommandError {
        message: format!(
            "stopped by {}: no image written; {}",
            crate::sys::signals::name(signal),
            kept_after_stop(args)
        ),
        exit: super::Exit::Interrupted(signal),
    }
}

/// What a stopped render leaves for the next run: the checkpoint, or the cache file, or nothing.
pub(crate) fn kept_after_stop(args: &RenderArgs) -> String {
    match (&args.checkpoint, &args.ambient_file) {
        (Some(dir), _) => format!(
            "the finished tiles and the cache are kept in {}: the same command resumes",
            dir.display()
        ),
        (None, Some(file)) => format!("the cache's records are kept in {}", file.display()),
        (None, None) => "nothing is kept (--checkpoint DIR would keep the finished tiles)".into(),
    }
}

/// Renders a frame sequence (`--frames`, `--frame`) once the checks common to every render have
/// passed: `commands::frames::run`, handed in by `main`, so that this module, which
/// the sequence renders each frame through, does not depend on it in turn.
pub type SequenceRenderer = fn(&RenderArgs, crate::frames::Frames) -> CommandResult;

pub fn run(args: &RenderArgs, sequence: SequenceRenderer) -> CommandResult {
    let mode = match args.mode {
        Some(m) => mode_of(m),
        None if under_mpirun() => Mode::Component,
        None => Mode::Serial,
    };
    if mode != Mode::Serial {
        if args.frames.is_some() || args.frame.is_some() {
            return Err(CommandError::input(
                "--frames and --frame render in one process (no mpirun, no --mode): a farm runs one task per \
                 chunk of frames; under mpirun render one image at a time"
                    .into(),
            ));
        }
        if args.region.is_some() {
            return Err(CommandError::input(
                "--region renders in one process (no mpirun, no --mode): run one task per region and \
                 `icrender merge` the parts"
                    .into(),
            ));
        }
        if args.trace_cache.is_some() {
            return Err(CommandError::input("--trace-cache traces the serial mode only".into()));
        }
        if passes::in_passes(args) {
            return Err(CommandError::input(format!(
                "{} renders in one process (no mpirun, no --mode)",
                passes::asked_by(args)
            )));
        }
        return run_parallel(args, mode);
    }
    let wall = Instant::now();
    validate(args)?;
    if args.region.is_some() && args.reference.is_some() {
        return Err(CommandError::input(
            "--reference compares whole images: render the regions, merge them, and `icrender compare` the merged image"
                .into(),
        ));
    }
    if passes::in_passes(args) {
        passes::check(args)?;
    }
    if let Some(frames) = args.frames()? {
        return sequence(args, frames);
    }
    let outputs = Outputs::check(args)?;
    image_io::open_in_background();
    let reference = match &args.reference {
        Some(path) => {
            Some(image_io::read_image(path, &[]).map_err(|e| CommandError::input(format!("{}: {e}", path.display())))?)
        }
        None => None,
    };
    if passes::in_passes(args) {
        return passes::run(args, &outputs, reference.as_ref(), wall);
    }
    let all_tiles = render_tiles(args)?;
    let (journal, restored) = open_checkpoint(args, &all_tiles)?.map_or((None, None), |(j, r)| (Some(j), Some(r)));
    let job = Job::prepare(&with_checkpoint_cache(args), crate::memory::Role::Single)?;
    let integrator = Integrator::new(&job.scene, &job.tracer, &job.shading, job.cache.as_ref());
    let s = &job.settings;
    let tiles_restored = restored.as_ref().map_or(0, Restored::count);
    let progress = Progress::with_style(
        all_tiles.len(),
        progress::Style::chosen(args.progress == ProgressArg::Json, args.quiet),
    );
    // From here a SIGTERM or SIGINT stops the render cleanly (see sys::signals).
    crate::sys::signals::catch_termination().map_err(CommandError::failed)?;
    let streamed = outputs.stream(args, &job, 1)?;
    let render_start = Instant::now();
    let rendered = render_resumable(
        &integrator,
        &job.camera,
        s,
        &progress,
        journal.as_ref().zip(restored),
        streamed.as_ref(),
    );
    let (frame, thread_stats) = (rendered.frame, rendered.threads);
    let render_s = render_start.elapsed().as_secs_f64();
    if let Some(cache) = &job.cache
        && let Err(e) = cache.finish()
    {
        warn(&format!(
            "{}: cache file not fully written: {e}",
            args.ambient_file.as_deref().unwrap_or(Path::new("")).display()
        ));
    }
    if let Some(signal) = crate::sys::signals::received() {
        return Err(interrupted(args, signal));
    }

    let mut stats = one_process_stats(
        args,
        &job,
        (render_s, wall.elapsed().as_secs_f64()),
        &thread_stats,
        rendered.prepass.as_ref(),
    );
    stats.tiles_restored = tiles_restored as u64;
    if stats.nonfinite_dropped > 0 {
        warn(&format!(
            "{} non-finite contribution(s) were dropped",
            stats.nonfinite_dropped
        ));
    }
    outputs.save(args, &job, frame, streamed, &stats)?;
    progress.done(&outputs.exr, stats.error_estimate.as_ref());
    if !args.quiet {
        eprintln!(
            "icrender: {}{}x{} in {:.2} s ({:.1} Mrays/s, {} threads, {} records, {:.0}% of lookups hit{}) -> {}",
            job.settings
                .region
                .map_or_else(String::new, |r| format!("region {} of ", r.text())),
            args.width,
            args.height,
            render_s,
            stats.mrays_per_s,
            s.threads,
            stats.records_computed,
            100.0 * stats.hits as f64 / stats.lookups.max(1) as f64,
            stats
                .error_estimate
                .as_ref()
                .map_or_else(String::new, |e| format!(", {}", e.summary())),
            outputs.exr.display()
        );
    }
    if let (Some(reference), Some(path)) = (&reference, &args.reference) {
        report_error(&outputs.exr, reference, path, render_s)?;
    }
    Ok(())
}

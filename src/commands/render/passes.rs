//! `icrender render` in passes (`--passes`, `--target-error`, `--time-limit`): the record set
//! is built once, the image rendered over it again and again from independent samples, and the
//! passes averaged; `render::passes` says after each pass whether to render another, build a
//! finer record set, or stop. The image is written after every pass that lowers the error
//! estimate, so the file on disk is always a whole image, the best one so far.

use super::{Outputs, one_process_stats, render_tiles, report_error};
use crate::cli::{
    CacheBuildArg, DEFAULT_ACCURACY, DEFAULT_DIVISIONS, DEFAULT_LIGHT_SAMPLES, DEFAULT_SUPERSAMPLES, ProgressArg,
    RenderArgs,
};
use crate::commands::{CommandError, CommandResult, Exit, warn};
use crate::image::framebuffer::FrameBuffer;
use crate::job::{Job, cache_build};
use crate::progress::{self, Progress};
use crate::render::passes::{
    Accumulated, Measured, PassLog, PassesReport, RecordTuning, Refined, Refinement, Refinements, Step, StopRule,
    Stopped, TileTallies, next_step, pass_seed,
};
use crate::render::sink::TileSink;
use crate::render::{RenderSettings, ThreadStats, add_prepass_work, prepare, prepared_reader, trace_tiles};
use crate::shading::Integrator;
use crate::stats::RenderStats;
use crate::sys::image_io::ImageData;
use std::time::Instant;

/// Whether this render goes in passes.
pub fn in_passes(args: &RenderArgs) -> bool {
    args.passes > 1 || adaptive(args)
}

/// Whether the passes are chosen as they go (a target or a time limit), not fixed.
fn adaptive(args: &RenderArgs) -> bool {
    args.target_error.is_some() || args.time_limit.is_some()
}

/// The option that asked for passes, for messages.
pub fn asked_by(args: &RenderArgs) -> &'static str {
    if args.target_error.is_some() {
        "--target-error"
    } else if args.time_limit.is_some() {
        "--time-limit"
    } else {
        "--passes"
    }
}

/// What a render in passes cannot go with, refused in one line before anything is loaded.
pub fn check(args: &RenderArgs) -> Result<(), CommandError> {
    let name = asked_by(args);
    let refuse = |why: &str| Err(CommandError::input(format!("{name} {why}")));
    if args.checkpoint.is_some() {
        return refuse("renders whole passes: not with --checkpoint, which journals one pass's tiles");
    }
    if args.frames.is_some() || args.frame.is_some() {
        return refuse("renders one image: not with --frames or --frame");
    }
    if args.trace_cache.is_some() {
        return refuse("renders over a prepass's record set: not with --trace-cache");
    }
    if cache_build(args) == CacheBuildArg::Progressive {
        return refuse("renders over a prepass's record set: not with --ic-build progressive");
    }
    if adaptive(args) && args.ambient_file.is_some() {
        return refuse("may build a finer record set than the -af file holds: not with -af");
    }
    if adaptive(args) && args.passes > 1 {
        return refuse("chooses the passes itself: not with --passes");
    }
    Ok(())
}

/// Where a render to a target starts: rough, where the records' and the lights' settings are
/// left at their defaults (the fastest of the peers bench's settings: records of -aa 0.3 -ad 64
/// -as 16, 4 shadow rays a sample), as the passes add the samples and the refinements the
/// records' density and samples where the estimate asks for them; what the user set, as set.
/// A time limit alone, and a fixed --passes, start from the settings given: with time to spare
/// the defaults' records did better (bench/error_estimate.py, Cornell box 128x128 in 2 s: a
/// measured relMSE of 1.3e-4 from the defaults, 2.0e-4 from the rough start).
fn starting_point(args: &RenderArgs) -> RenderArgs {
    let mut start = args.clone();
    if args.target_error.is_none() {
        return start;
    }
    if (args.ambient_accuracy, args.ambient_divisions, args.ambient_supersamples)
        == (DEFAULT_ACCURACY, DEFAULT_DIVISIONS, DEFAULT_SUPERSAMPLES)
    {
        (
            start.ambient_accuracy,
            start.ambient_divisions,
            start.ambient_supersamples,
        ) = ROUGH_RECORDS;
    }
    if args.light_samples == DEFAULT_LIGHT_SAMPLES {
        start.light_samples = ROUGH_LIGHT_SAMPLES;
    }
    start
}

/// The rough start's -aa, -ad and -as, and shadow rays a sample (`starting_point`).
const ROUGH_RECORDS: (f32, u32, u32) = (0.3, 64, 16);
const ROUGH_LIGHT_SAMPLES: u32 = 4;

/// The options as the image written was rendered: its record set's settings and its passes,
/// with no target or limit (the EXR's `icrender/command` reruns exactly this image).
fn as_rendered(args: &RenderArgs, tuning: RecordTuning, passes: u32) -> RenderArgs {
    RenderArgs {
        ambient_accuracy: tuning.accuracy,
        ic_min_pixels: tuning.min_pixels,
        ambient_divisions: tuning.divisions,
        ambient_supersamples: tuning.supersamples,
        passes,
        target_error: None,
        time_limit: None,
        ..args.clone()
    }
}

/// What the render has written so far: the estimate of the image on disk and its statistics.
struct Written {
    relmse: f64,
    stats: RenderStats,
    pass: u32,
    at: Instant,
}

/// Between the passes' ends and changes of record set, the image is written at most this often
/// (seconds), and at most once in `WRITES_APART` times the last write's own time.
const WRITE_EVERY_S: f64 = 10.0;
const WRITES_APART: f64 = 10.0;

/// Renders in passes and writes the best image (see the module's comment). `outputs` were
/// checked writable; `wall` started with the command.
pub fn run(args: &RenderArgs, outputs: &Outputs, reference: Option<&ImageData>, wall: Instant) -> CommandResult {
    let args = &starting_point(args);
    let rule = StopRule {
        target_error: args.target_error,
        time_limit_s: args.time_limit,
    };
    let mut job = Job::prepare(args, crate::memory::Role::Single)?;
    let all = render_tiles(args)?;
    let style = progress::Style::chosen(args.progress == ProgressArg::Json, args.quiet);
    crate::sys::signals::catch_termination().map_err(CommandError::failed)?;
    let stopped = || crate::sys::signals::received().is_some();
    let start = Instant::now();
    let mut tuning = RecordTuning {
        accuracy: args.ambient_accuracy,
        min_pixels: args.ic_min_pixels,
        divisions: args.ambient_divisions,
        supersamples: args.ambient_supersamples,
    };
    let mut refinements = Refinements::default();
    // The refinement that made the current record set, and the cache's error before it.
    let mut last_refinement: Option<(Refinement, f64)> = None;
    let mut report = PassesReport {
        target_error: args.target_error,
        time_limit_s: args.time_limit,
        ..Default::default()
    };
    // Every pass's and prepass's work, for the statistics.
    let mut work: Vec<ThreadStats> = Vec::new();
    let mut written: Option<Written> = None;
    let mut write_every = WRITE_EVERY_S;
    loop {
        report.record_sets += 1;
        let build_start = Instant::now();
        let progress = Progress::with_style(all.len(), style);
        let prepared = {
            let integrator = Integrator::new(&job.scene, &job.tracer, &job.shading, job.cache.as_ref());
            prepare(&integrator, &job.camera, &job.settings, &progress)
        };
        let build_s = build_start.elapsed().as_secs_f64();
        if let Some(prepass) = &prepared.prepass {
            add_prepass_work(&mut work, &prepass.threads);
        }
        let window = prepared.settings.window(&job.camera);
        let mut passes = Accumulated::new(&all);
        let mut passes_s = 0.0;
        // Whether this set's passes are the image on disk.
        let mut set_written = false;
        let (step, cache, refined) = loop {
            let pass_start = Instant::now();
            let settings = RenderSettings {
                seed: pass_seed(args.seed, passes.passes),
                ..prepared.settings.clone()
            };
            // The first pass renders every tile; the next ones, the tiles the estimate says
            // are noisiest, more often than the rest.
            let todo: Vec<usize> = match passes.passes {
                0 => (0..all.len()).collect(),
                _ => passes.next_tiles(),
            };
            let rendered = todo.clone();
            let later;
            let progress = if passes.passes == 0 {
                &progress
            } else {
                later = Progress::with_style(todo.len(), style);
                &later
            };
            let tallies = TileTallies::new(all.len());
            let records = job.cache.as_ref().map_or(0, |c| c.len() as u64);
            let sink = TileSink::held(FrameBuffer::windowed(window));
            let threads = {
                let integrator = Integrator::new(&job.scene, &job.tracer, &job.shading, job.cache.as_ref());
                // The records a pass's samples miss (they fall where no earlier pass's did) join
                // the set before the next pass, instead of being made again in every pass.
                let reader = Integrator {
                    keeps_gaps: true,
                    ..prepared_reader(&integrator, prepared.prepass.is_some())
                };
                trace_tiles(
                    &reader,
                    &job.camera,
                    &settings,
                    (&all, todo),
                    &sink,
                    (None, Some(&tallies)),
                    progress,
                    &stopped,
                )
            };
            progress.finish();
            if let Some(cache) = job.cache.as_mut() {
                cache.absorb_gaps();
            }
            if let Some(signal) = crate::sys::signals::received() {
                return Err(interrupted(signal, written.as_ref(), outputs));
            }
            // The records counted in `ic_records` once, with the first pass.
            let first = passes.passes == 0;
            let frame = sink
                .into_frame(prepared.prepass.as_ref().filter(|_| first))
                .ok_or_else(|| CommandError::failed("a pass held no frame".into()))?;
            add_prepass_work(&mut work, &threads);
            passes.add(frame, &rendered, tallies);
            let estimate = passes.estimate();
            let relmse = estimate.as_ref().map_or(f64::INFINITY, |e| e.relmse);
            let mut log = PassLog {
                pass: report.log.len() as u32 + 1,
                pass_of_set: passes.passes,
                tiles: rendered.len() as u32,
                accuracy: tuning.accuracy,
                divisions: tuning.divisions,
                records,
                elapsed_s: start.elapsed().as_secs_f64(),
                relmse,
                relmse_4x4: estimate.as_ref().map_or(f64::INFINITY, |e| e.relmse_4x4),
                noise: estimate.as_ref().map_or(0.0, |e| e.noise),
                cache: estimate.as_ref().map_or(0.0, |e| e.cache),
                record_noise: estimate.as_ref().map_or(0.0, |e| e.record_noise),
                written: false,
            };
            passes_s += pass_start.elapsed().as_secs_f64();
            let (cache, record_noise) = estimate.as_ref().map_or((0.0, 0.0), |e| (e.cache, e.record_noise));
            // Whether the refinement that made this set lowered the cache's error as it should.
            if let Some((refinement, before)) = last_refinement.take() {
                refinements.judge(refinement, before, cache);
            }
            let refined: Option<Refined> = refinements
                .next(tuning, cache, record_noise)
                .filter(|_| job.cache.is_some());
            let measured = Measured {
                passes: passes.passes,
                // The image's noise as if each pass had rendered every tile (the plan's model:
                // the noise over the passes).
                noise_per_pass: estimate.as_ref().map_or(0.0, |e| e.noise) * passes.passes as f64,
                cache,
                build_s,
                pass_s: passes_s / passes.passes as f64,
                elapsed_s: start.elapsed().as_secs_f64(),
                refine_gain: refined.map(|r| r.gain),
            };
            let step = match adaptive(args) {
                true => next_step(rule, &measured),
                false if passes.passes < args.passes => Step::Pass,
                false => Step::Stop(Stopped::Reached),
            };
            if let Step::Stop(why) = step {
                report.stopped = adaptive(args).then(|| why.text());
            }
            // Every pass of the record set that made the image on disk is better than it: more
            // passes' mean is, whatever the estimate says (a pixel's rare bright sample makes it
            // jump up and down). A refined set takes over once its estimate is lower: its first
            // passes may be noisier than the last set's mean. The better image is written when
            // the passes end or leave this set, and between, once the last write is
            // `WRITE_EVERY` old (a write of a large frame costs a pass's share).
            let better = set_written || written.as_ref().is_none_or(|w| relmse < w.relmse);
            let due = step != Step::Pass
                || written
                    .as_ref()
                    .is_none_or(|w| w.at.elapsed().as_secs_f64() >= write_every);
            report.log.push(log.clone());
            if better && due {
                set_written = true;
                log.written = true;
                report.log.last_mut().expect("just pushed").written = true;
                report.passes = passes.passes;
                (report.accuracy, report.min_pixels, report.divisions) =
                    (tuning.accuracy, tuning.min_pixels, tuning.divisions);
                let rendered = as_rendered(args, tuning, passes.passes);
                let mut stats = one_process_stats(
                    &rendered,
                    &job,
                    (start.elapsed().as_secs_f64(), wall.elapsed().as_secs_f64()),
                    &work,
                    prepared.prepass.as_ref(),
                );
                stats.spp = (args.spp as f64 * passes.mean_passes()).round() as u32;
                stats.error_estimate = estimate.clone();
                stats.passes = Some(report.clone());
                let mean = passes
                    .mean()
                    .ok_or_else(|| CommandError::failed("no pass to average".into()))?;
                let writing = Instant::now();
                outputs.write(&rendered, &job, &mean, &stats)?;
                write_every = WRITE_EVERY_S.max(WRITES_APART * writing.elapsed().as_secs_f64());
                written = Some(Written {
                    relmse,
                    stats,
                    pass: log.pass,
                    at: Instant::now(),
                });
            }
            progress::pass_done(style, &log, &outputs.exr);
            if !args.quiet {
                eprintln!(
                    "icrender: pass {} ({} over {} records, -aa {:.3} -ad {}): estimated relMSE {:.3e} (noise {:.3e}, cache {:.3e}) at {:.2} s{}",
                    log.pass,
                    log.pass_of_set,
                    records,
                    tuning.accuracy,
                    tuning.divisions,
                    log.relmse,
                    log.noise,
                    log.cache,
                    log.elapsed_s,
                    if log.written { ", written" } else { "" }
                );
            }
            if step != Step::Pass {
                break (step, cache, refined);
            }
        };
        match step {
            Step::Refine => {
                let Some(refined) = refined else {
                    unreachable!("a refinement is asked for only where there is one")
                };
                last_refinement = Some((refined.refinement, cache));
                tuning = refined.tuning;
                job.refine_records(&as_rendered(args, tuning, 1));
            }
            Step::Stop(why) => {
                report.stopped = adaptive(args).then(|| why.text());
                break;
            }
            Step::Pass => unreachable!("a pass is rendered in the loop above"),
        }
    }
    let Some(mut written) = written else {
        return Err(CommandError::failed("no pass was rendered".into()));
    };
    // The statistics file gets the whole log and why the passes stopped (the EXR's header has
    // them up to its own pass).
    written.stats.passes = Some(report.clone());
    if let Some(path) = &outputs.stats {
        crate::image::output::write_json(path, &written.stats)
            .map_err(|e| CommandError::failed(format!("{}: {e}", path.display())))?;
    }
    let stats = &written.stats;
    if stats.nonfinite_dropped > 0 {
        warn(&format!(
            "{} non-finite contribution(s) were dropped",
            stats.nonfinite_dropped
        ));
    }
    progress::Progress::with_style(all.len(), style).done(&outputs.exr, stats.error_estimate.as_ref());
    let render_s = start.elapsed().as_secs_f64();
    if !args.quiet {
        eprintln!(
            "icrender: {}x{} in {:.2} s: {} pass{} over {} records at -aa {:.3} -ad {}{}{} -> {}",
            args.width,
            args.height,
            render_s,
            report.passes,
            if report.passes == 1 { "" } else { "es" },
            stats.cache_records,
            report.accuracy,
            report.divisions,
            report.stopped.map_or_else(String::new, |s| format!(" ({s})")),
            stats
                .error_estimate
                .as_ref()
                .map_or_else(String::new, |e| format!(", {}", e.summary())),
            outputs.exr.display()
        );
    }
    if let Some(limit) = args.time_limit
        && render_s > limit * 1.1
        && written.pass == 1
    {
        warn(&format!(
            "--time-limit {limit}: the first pass alone took {render_s:.1} s; a smaller image or cheaper settings fit the limit"
        ));
    }
    if let (Some(reference), Some(path)) = (reference, &args.reference) {
        report_error(&outputs.exr, reference, path, render_s)?;
    }
    Ok(())
}

/// What a render in passes stopped by `signal` says: the image on disk is the last one written.
fn interrupted(signal: i32, written: Option<&Written>, outputs: &Outputs) -> CommandError {
    let kept = match written {
        Some(w) => format!(
            "{} holds the image of pass {} (estimated relMSE {:.3e})",
            outputs.exr.display(),
            w.pass,
            w.relmse
        ),
        None => "no image written".to_string(),
    };
    CommandError {
        message: format!("stopped by {}: {kept}", crate::sys::signals::name(signal)),
        exit: Exit::Interrupted(signal),
    }
}

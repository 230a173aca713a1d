//! `icrender render --frames A-B` (and `--frame N`): a sequence of frames of the scene's camera
//! animation, each written whole to its own EXR before the next begins (a farm may pick frame
//! files up as they appear).
//!
//! The scene, its BVH and the irradiance cache are made once. Where only cameras animate, the
//! indirect light does not change from frame to frame and the cache's records hold for every
//! frame: each frame's prepass finds the records earlier frames made and adds only those its
//! own view needs that are missing. Where meshes or lights move, each frame places them again
//! (`scene::posing`), builds the BVH again, and drops the records the moves changed
//! (`irradiance::temporal`) before its prepass makes what is missing.
//!
//! With `--checkpoint DIR` each frame journals its tiles in `DIR/frame-N/` and, once its files
//! are written, leaves `DIR/frame-N/done`; the cache goes to `DIR/cache.icc` (unless -af names
//! a file) and is shared by all frames. The same command run again skips the finished frames,
//! resumes the first unfinished one from its journal and goes on.

use super::render::{
    Outputs, check_denoiser, checkpoint_key, kept_after_stop, one_process_stats, output_name, render_tiles,
    render_window, with_checkpoint_cache,
};
use super::{CommandError, CommandResult, warn};
use crate::checkpoint::Checkpoint;
use crate::cli::{ProgressArg, RenderArgs};
use crate::frames::{FrameTag, Frames, NamePattern};
use crate::job::Job;
use crate::progress::{self, InSequence, Progress};
use crate::render::render_resumable;
use crate::shading::Integrator;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// A frame's own checkpoint directory.
fn frame_dir(checkpoint: &Path, frame: u32) -> PathBuf {
    checkpoint.join(format!("frame-{frame}"))
}

/// The marker a frame leaves in its checkpoint directory once its outputs are written: the EXR
/// it wrote, so that a rerun naming other outputs renders it again.
fn done_marker(checkpoint: &Path, frame: u32) -> PathBuf {
    frame_dir(checkpoint, frame).join("done")
}

/// Whether an earlier run of this checkpoint finished `frame` into `exr` (and the file is
/// still there).
fn finished_before(checkpoint: Option<&Path>, frame: u32, exr: &Path) -> bool {
    let Some(dir) = checkpoint else {
        return false;
    };
    std::fs::read(done_marker(dir, frame)).is_ok_and(|named| named == exr.as_os_str().as_encoded_bytes())
        && exr.is_file()
}

/// Every frame's outputs, checked before anything is rendered (none may exist unless
/// --overwrite, every folder must be writable); frames a checkpoint says are finished are not
/// checked, they are skipped.
fn frame_outputs(args: &RenderArgs, frames: &Frames) -> Result<Vec<(u32, Option<Outputs>)>, CommandError> {
    if args.denoise {
        check_denoiser(args)?;
    }
    let exr =
        NamePattern::new(&output_name(args), frames.count()).map_err(|e| CommandError::input(format!("-o {e}")))?;
    let stats = args
        .stats
        .as_deref()
        .map(|s| NamePattern::new(s, frames.count()))
        .transpose()
        .map_err(|e| CommandError::input(format!("--stats {e}")))?;
    let mut out = Vec::with_capacity(frames.count());
    for n in frames.numbers() {
        let path = exr.path(n);
        if finished_before(args.checkpoint.as_deref(), n, &path) {
            out.push((n, None));
            continue;
        }
        let tag = FrameTag::of(frames, n);
        let outputs = Outputs::checked(args, path, stats.as_ref().map(|s| s.path(n)), Some(tag))?;
        out.push((n, Some(outputs)));
    }
    Ok(out)
}

/// Renders the frames (one process; `render::run` has checked the options).
pub fn run(args: &RenderArgs, frames: Frames) -> CommandResult {
    let sequence_start = Instant::now();
    if args.reference.is_some() && frames.count() > 1 {
        return Err(CommandError::input(
            "--reference compares one image: give --frame N, or compare each frame with `icrender compare`".into(),
        ));
    }
    let outputs = frame_outputs(args, &frames)?;
    crate::sys::image_io::open_in_background();
    let reference = match &args.reference {
        Some(path) => Some(
            crate::sys::image_io::read_image(path, &[])
                .map_err(|e| CommandError::input(format!("{}: {e}", path.display())))?,
        ),
        None => None,
    };
    let all_tiles = render_tiles(args)?;
    if let Some(dir) = &args.checkpoint {
        // The cache file goes in it (`with_checkpoint_cache`), opened before the first frame.
        std::fs::create_dir_all(dir)
            .map_err(|e| CommandError::input(format!("{}: cannot create the directory: {e}", dir.display())))?;
    }
    let mut job = Job::prepare(&with_checkpoint_cache(args), crate::memory::Role::Single)?;
    let scene_moves = job
        .frames
        .as_ref()
        .is_some_and(|(_, plan)| plan.meshes_animated || plan.lights_animated);
    if scene_moves && let Some(cache) = job.cache.as_mut() {
        cache.remember_grid_sites();
        cache.remember_origins();
    }
    let style = progress::Style::chosen(args.progress == ProgressArg::Json, args.quiet);
    crate::sys::signals::catch_termination().map_err(CommandError::failed)?;
    let mut written = Vec::new();
    let mut cache_warned = false;
    for (index, (n, outputs)) in outputs.into_iter().enumerate() {
        let Some(outputs) = outputs else {
            if !args.quiet {
                eprintln!("icrender: frame {n}: finished by an earlier run of this checkpoint, skipped");
            }
            written.push(n);
            continue;
        };
        let frame_start = Instant::now();
        let time = frames.time(n);
        let pose_start = Instant::now();
        let invalidation = job.at_time(args, time)?;
        let pose_s = pose_start.elapsed().as_secs_f64();
        let records_before = invalidation.map_or(0, |i| i.kept);
        let (journal, restored) = match &args.checkpoint {
            Some(dir) => {
                let key = format!("{}; frame {n} at {time} s", checkpoint_key(args));
                let (journal, restored) = Checkpoint::open(&frame_dir(dir, n), &key, &all_tiles, render_window(args)?)
                    .map_err(CommandError::input)?;
                if !args.quiet && restored.count() > 0 {
                    eprintln!(
                        "icrender: frame {n}: resuming: {} of {} tiles are already finished",
                        restored.count(),
                        all_tiles.len()
                    );
                }
                (Some(journal), Some(restored))
            }
            None => (None, None),
        };
        let tiles_restored = restored.as_ref().map_or(0, |r| r.count());
        let progress = Progress::with_style(all_tiles.len(), style).in_sequence(InSequence {
            frame: n,
            index,
            count: frames.count(),
            start: sequence_start,
        });
        let integrator = Integrator::new(&job.scene, &job.tracer, &job.shading, job.cache.as_ref());
        let streamed = outputs.stream(args, &job, 1)?;
        let render_start = Instant::now();
        let rendered = render_resumable(
            &integrator,
            &job.camera,
            &job.settings,
            &progress,
            journal.as_ref().zip(restored),
            streamed.as_ref(),
        );
        let render_s = render_start.elapsed().as_secs_f64();
        // The frame's records reach the file before the next frame (a killed job keeps them).
        if let Some(cache) = &job.cache
            && let Err(e) = cache.finish()
            && !cache_warned
        {
            cache_warned = true;
            warn(&format!(
                "{}: cache file not fully written: {e}",
                args.ambient_file.as_deref().unwrap_or(Path::new("")).display()
            ));
        }
        if let Some(signal) = crate::sys::signals::received() {
            return Err(CommandError {
                message: format!(
                    "stopped by {} during frame {n}: {}, frame {n} is not; {}",
                    crate::sys::signals::name(signal),
                    frames_written(&written),
                    kept_after_stop(args)
                ),
                exit: super::Exit::Interrupted(signal),
            });
        }
        let mut stats = one_process_stats(
            args,
            &job,
            (render_s, frame_start.elapsed().as_secs_f64()),
            &rendered.threads,
            rendered.prepass.as_ref(),
        );
        stats.tiles_restored = tiles_restored as u64;
        stats.frame = Some(n);
        stats.frame_time_s = Some(time);
        stats.records_before = Some(records_before);
        if scene_moves {
            stats.pose_s = Some(pose_s);
        }
        // What the moves did to the records (nothing to say without a cache).
        if let (true, Some(invalidation)) = (scene_moves, invalidation) {
            stats.records_invalidated = Some(invalidation.invalidated);
            stats.records_remade = Some(rendered.prepass.as_ref().map_or(0, |p| p.records_remade));
            if let Some(memory) = job.cache.as_ref().and_then(|c| c.grid_memory()) {
                let (kept, sampled) = memory.counts();
                stats.last_bounce_sites_kept = Some(kept);
                stats.last_bounce_sites_sampled = Some(sampled);
            }
        }
        if stats.nonfinite_dropped > 0 {
            warn(&format!(
                "frame {n}: {} non-finite contribution(s) were dropped",
                stats.nonfinite_dropped
            ));
        }
        outputs.save(args, &job, rendered.frame, streamed, &stats)?;
        if let Some(dir) = &args.checkpoint {
            // Only after the files: a frame killed while writing them is rendered again.
            std::fs::write(done_marker(dir, n), outputs.exr.as_os_str().as_encoded_bytes())
                .map_err(|e| CommandError::failed(format!("{}: {e}", done_marker(dir, n).display())))?;
        }
        // Where meshes or lights move, what the moves did to the records, for a farm's log.
        let records = stats.records_invalidated.map(|dropped| {
            serde_json::json!({
                "kept": records_before,
                "dropped": dropped,
                "remade": stats.records_remade.unwrap_or(0),
                "made": stats.records_computed - stats.records_remade.unwrap_or(0),
            })
        });
        progress.done_with(&outputs.exr, stats.error_estimate.as_ref(), records);
        written.push(n);
        if !args.quiet {
            eprintln!(
                "icrender: frame {n} ({time:.4} s): {}x{} in {render_s:.2} s ({} records made, {records_before} carried{}, \
                 {:.0}% of lookups hit){} -> {}",
                args.width,
                args.height,
                stats.records_computed,
                match (stats.records_invalidated, stats.records_remade) {
                    (Some(i), Some(r)) =>
                        format!(", {i} dropped where things moved, {r} of them made again where they were"),
                    _ => String::new(),
                },
                100.0 * stats.hits as f64 / stats.lookups.max(1) as f64,
                stats
                    .error_estimate
                    .as_ref()
                    .map_or(String::new(), |e| format!(", estimated relMSE {:.2e}", e.relmse)),
                outputs.exr.display()
            );
        }
        if let (Some(reference), Some(path)) = (&reference, &args.reference) {
            super::render::report_error(&outputs.exr, reference, path, render_s)?;
        }
    }
    let pattern = NamePattern::new(&output_name(args), frames.count()).map_err(CommandError::input)?;
    progress::sequence_done(style, sequence_start, &frames.text(), &pattern.text());
    Ok(())
}

/// "frames 1-4 are written" or "no frame is written", for a stopped sequence.
fn frames_written(written: &[u32]) -> String {
    match (written.first(), written.last()) {
        (Some(a), Some(b)) if a == b => format!("frame {a} is written"),
        (Some(a), Some(b)) => format!("frames {a}-{b} are written"),
        _ => "no frame is written".into(),
    }
}

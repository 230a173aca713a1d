//! `icrender cache`: the irradiance cache prepass alone. It places every record the image
//! the same options would render (or its --region) needs, appends them to the -af file and
//! stops: no final pass, no image. A farm runs it once before its region or frame tasks,
//! which then read the file with --af-read-only (docs/farms.md).

use super::{CommandError, CommandResult, Exit};
use crate::cli::{CacheBuildArg, ModeArg, ProgressArg, RenderArgs};
use crate::job::{Job, cache_build, validate};
use crate::parallel::under_mpirun;
use crate::progress::{InSequence, Progress, Style};
use crate::shading::Integrator;
use std::time::Instant;

/// Options that make no sense for a prepass alone, refused before anything is loaded.
fn check(args: &RenderArgs) -> Result<(), CommandError> {
    let refuse = |m: &str| Err(CommandError::input(m.to_string()));
    if under_mpirun() || args.mode.is_some_and(|m| m != ModeArg::Serial) {
        return refuse("icrender cache runs in one process (no mpirun, no --mode)");
    }
    if args.ambient_file.is_none() {
        return refuse("icrender cache needs -af FILE: the cache file its records go to");
    }
    if args.af_read_only {
        return refuse("icrender cache writes the -af file: --af-read-only is for the tasks that read it");
    }
    if args.output.is_some() {
        return refuse("-o: icrender cache writes no image, only the -af file");
    }
    if cache_build(args) == CacheBuildArg::Progressive {
        return refuse("icrender cache runs the prepass: --ic-build progressive has none");
    }
    if args.checkpoint.is_some() {
        return refuse(
            "--checkpoint: icrender cache keeps its records in the -af file as it goes; run it again to continue",
        );
    }
    validate(args).map_err(CommandError::input)
}

pub fn run(args: &RenderArgs) -> CommandResult {
    check(args)?;
    let file = args.ambient_file.as_deref().expect("checked");
    let frames = args.frames()?;
    let mut job = Job::prepare(args, crate::memory::Role::Single)?;
    let Some(loaded) = job.cache.as_ref().map(|c| c.load_report.loaded) else {
        return Err(CommandError::input(format!(
            "{}: these options keep no irradiance cache (-ab 0, -aa 0, or no diffuse surface): no records to make",
            args.scene.display()
        )));
    };
    let style = Style::chosen(args.progress == ProgressArg::Json, args.quiet);
    crate::sys::signals::catch_termination().map_err(CommandError::failed)?;
    let start = Instant::now();
    // The views to prepare: the image's, or every frame's (each adds what its view lacks).
    let views: Vec<Option<u32>> = match &frames {
        Some(f) => f.numbers().map(Some).collect(),
        None => vec![None],
    };
    let (mut records, mut rounds, mut sites) = (0u64, 0usize, 0u64);
    let mut per_frame = Vec::new();
    let mut last_progress = None;
    for (index, frame) in views.iter().enumerate() {
        if let (Some(n), Some(f)) = (frame, &frames) {
            job.at_time(args, f.time(*n))?;
            if let Some(cache) = job.cache.as_mut() {
                cache.thaw();
            }
        }
        let cache = job.cache.as_ref().expect("checked above");
        let integrator = Integrator::new(&job.scene, &job.tracer, &job.shading, Some(cache));
        let mut progress = Progress::prepass_only(style);
        if let Some(n) = frame {
            progress = progress.in_sequence(InSequence {
                frame: *n,
                index,
                count: views.len(),
                start,
            });
        }
        let frame_start = Instant::now();
        let outcome = {
            let watch = crate::render::watch_prepass(&progress);
            crate::prepass::run(&integrator, &job.camera, &job.settings, &watch)
        };
        progress.finish();
        records += outcome.records;
        rounds += outcome.rounds;
        sites += outcome.sites;
        if let Some(n) = frame {
            per_frame.push(serde_json::json!({
                "frame": n,
                "records_made": outcome.records,
                "seconds": frame_start.elapsed().as_secs_f64(),
            }));
            if !args.quiet {
                eprintln!(
                    "icrender: cache {}: frame {n}: {} records made in {:.2} s",
                    file.display(),
                    outcome.records,
                    frame_start.elapsed().as_secs_f64()
                );
            }
        }
        last_progress = Some(progress);
        if crate::sys::signals::received().is_some() {
            break;
        }
    }
    let cache = job.cache.as_ref().expect("checked above");
    let seconds = start.elapsed().as_secs_f64();
    cache
        .finish()
        .map_err(|e| CommandError::failed(format!("{}: cache file not fully written: {e}", file.display())))?;
    if let Some(signal) = crate::sys::signals::received() {
        return Err(CommandError {
            message: format!(
                "stopped by {}: the {records} records made so far are in {}; the same command goes on from them",
                crate::sys::signals::name(signal),
                file.display()
            ),
            exit: Exit::Interrupted(signal),
        });
    }
    let area = job.settings.area(&job.camera);
    let image = match job.settings.region {
        Some(r) => format!("region {} of the {}x{} image", r.text(), args.width, args.height),
        None => format!("the {}x{} image", args.width, args.height),
    };
    let what = match &frames {
        Some(f) => format!("{image}, frames {}", f.text()),
        None => image,
    };
    if let Some(path) = &args.stats {
        let mut stats = serde_json::json!({
            "cache_file": file.display().to_string(),
            "region": area.text(),
            "records_loaded": loaded,
            "records_made": records,
            "records_total": cache.len(),
            "rounds": rounds,
            "sites": sites,
            "seconds": seconds,
        });
        if frames.is_some() {
            stats["frames"] = per_frame.into();
        }
        crate::image::output::write_json(path, &stats)
            .map_err(|e| CommandError::failed(format!("{}: {e}", path.display())))?;
    }
    match &frames {
        Some(f) => crate::progress::sequence_done(style, start, &f.text(), &file.display().to_string()),
        None => last_progress.iter().for_each(|p| p.done(file, None)),
    }
    if !args.quiet {
        eprintln!(
            "icrender: cache {}: {records} records made in {seconds:.2} s for {what} ({loaded} loaded before, {} in the file)",
            file.display(),
            cache.len()
        );
    }
    Ok(())
}

//! `icrender cache`: the irradiance cache prepass alone. It places every record the image
//! the same options would render (or its --region) needs, appends them to the -af file and
//! stops: no final pass, no image. A farm runs it once before its region or frame tasks,
//! which then read the file with --af-read-only (README, "Render farms").

use super::{CommandError, CommandResult, Exit};
use crate::cli::{CacheBuildArg, ModeArg, ProgressArg, RenderArgs};
use crate::job::{Job, cache_build, validate};
use crate::parallel::under_mpirun;
use crate::progress::{Progress, Style};
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
    let job = Job::prepare(args, crate::memory::Role::Single)?;
    let Some(cache) = &job.cache else {
        return Err(CommandError::input(format!(
            "{}: these options keep no irradiance cache (-ab 0, -aa 0, or no diffuse surface): no records to make",
            args.scene.display()
        )));
    };
    let loaded = cache.load_report.loaded;
    let integrator = Integrator::new(&job.scene, &job.tracer, &job.shading, Some(cache));
    let progress = Progress::prepass_only(Style::chosen(args.progress == ProgressArg::Json, args.quiet));
    crate::sys::signals::catch_termination().map_err(CommandError::failed)?;
    let start = Instant::now();
    let watch = crate::render::watch_prepass(&progress);
    let outcome = crate::prepass::run(&integrator, &job.camera, &job.settings, &watch);
    progress.finish();
    let seconds = start.elapsed().as_secs_f64();
    cache
        .finish()
        .map_err(|e| CommandError::failed(format!("{}: cache file not fully written: {e}", file.display())))?;
    if let Some(signal) = crate::sys::signals::received() {
        return Err(CommandError {
            message: format!(
                "stopped by {}: the {} records made so far are in {}; the same command goes on from them",
                crate::sys::signals::name(signal),
                outcome.records,
                file.display()
            ),
            exit: Exit::Interrupted(signal),
        });
    }
    let area = job.settings.area(&job.camera);
    let what = match job.settings.region {
        Some(r) => format!("region {} of the {}x{} image", r.text(), args.width, args.height),
        None => format!("the {}x{} image", args.width, args.height),
    };
    if let Some(path) = &args.stats {
        let stats = serde_json::json!({
            "cache_file": file.display().to_string(),
            "region": area.text(),
            "records_loaded": loaded,
            "records_made": outcome.records,
            "records_total": cache.len(),
            "rounds": outcome.rounds,
            "sites": outcome.sites,
            "seconds": seconds,
        });
        crate::image::output::write_json(path, &stats)
            .map_err(|e| CommandError::failed(format!("{}: {e}", path.display())))?;
    }
    progress.done(file);
    if !args.quiet {
        eprintln!(
            "icrender: cache {}: {} records made in {:.2} s for {what} ({} loaded before, {} in the file)",
            file.display(),
            outcome.records,
            seconds,
            loaded,
            cache.len()
        );
    }
    Ok(())
}

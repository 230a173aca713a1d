//! `icrender export`: the scene as Radiance input (`oconv scene.rad > scene.oct; rpict ...`),
//! read with the same material options as `render`, so both renderers see the same scene.

use super::{CommandError, CommandResult, warn};
use crate::cli::ExportArgs;
use crate::export::radiance;
use crate::scene::{LoadOptions, Scene};

pub fn run(args: &ExportArgs) -> CommandResult {
    if args.output.exists() && !args.overwrite {
        return Err(CommandError::input(format!(
            "{}: already exists (give --overwrite to replace it)",
            args.output.display()
        )));
    }
    let options = LoadOptions {
        lambertian: args.lambertian,
        allow_outside_refs: args.allow_outside_refs,
        ..LoadOptions::default()
    };
    let scene = Scene::load(&args.scene, &options)?;
    for w in &scene.warnings {
        warn(&format!("{}: {w}", args.scene.display()));
    }
    let summary = radiance::export(&scene, &args.output)
        .map_err(|e| CommandError::input(format!("{}: {e}", args.output.display())))?;
    for note in &summary.notes {
        warn(&format!("{}: {note}", args.scene.display()));
    }
    eprintln!(
        "icrender: {} materials, {} polygons, {} punctual light sources -> {}",
        summary.materials,
        summary.polygons,
        summary.light_sources,
        args.output.display()
    );
    Ok(())
}

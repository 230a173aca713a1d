//! `icrender compare`: error of an image against a reference, per layer.

use super::{CommandError, CommandResult};
use crate::cli::CompareArgs;
use crate::image::metrics;
use crate::sys::image_io;

pub fn run(args: &CompareArgs) -> CommandResult {
    let read = |path: &std::path::Path| {
        image_io::read_image(path, &[]).map_err(|e| CommandError::input(format!("{}: {e}", path.display())))
    };
    let image = read(&args.image)?;
    let reference = read(&args.reference)?;
    let errors = metrics::compare(&image, &reference).map_err(|e| {
        CommandError::input(format!(
            "{} against {}: {e}",
            args.image.display(),
            args.reference.display()
        ))
    })?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&errors)?);
        return Ok(());
    }
    println!(
        "{:<18} {:>14} {:>14} {:>12} {:>12}",
        "layer", "rmse", "relmse", "mean", "ref mean"
    );
    for e in &errors {
        println!(
            "{:<18} {:>14.6e} {:>14.6e} {:>12.6} {:>12.6}",
            e.layer, e.rmse, e.rel_mse, e.mean, e.reference_mean
        );
    }
    Ok(())
}

//! `icrender seams`: how much a layer of an EXR steps at the borders of a tile grid against
//! within its tiles (see `image::seams`).

use super::{CommandError, CommandResult};
use crate::cli::{SeamsArgs, parse_tile};
use crate::image::seams::{parse_region, tile_seams};
use crate::sys::image_io;
use glam::Vec3;

pub fn run(args: &SeamsArgs) -> CommandResult {
    let path = args.image.display();
    let tile = parse_tile(&args.tile).map_err(CommandError::input)?;
    let region = args
        .region
        .as_deref()
        .map(parse_region)
        .transpose()
        .map_err(CommandError::input)?;
    let image = image_io::read_image(&args.image, &[]).map_err(|e| CommandError::input(format!("{path}: {e}")))?;
    let prefix = if args.layer == "composite" {
        String::new()
    } else {
        format!("{}.", args.layer)
    };
    let channel = |c: &str| {
        image
            .channel(&format!("{prefix}{c}"))
            .ok_or_else(|| CommandError::input(format!("{path}: no layer '{}' (no channel {prefix}{c})", args.layer)))
    };
    let (r, g, b) = (channel("R")?, channel("G")?, channel("B")?);
    let pixels: Vec<Vec3> = (0..r.len()).map(|i| Vec3::new(r[i], g[i], b[i])).collect();
    let report = tile_seams(&pixels, image.width, tile, region).ok_or_else(|| {
        CommandError::input(format!(
            "{path}: no lit pixel pairs on both sides of a {} tile border in that region",
            args.tile
        ))
    })?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "seams {} {}: ratio {:.3} (mean log step across borders {:.4} over {} pairs, within tiles {:.4} over {} pairs)",
            args.layer, args.tile, report.ratio, report.across, report.pairs_across, report.within, report.pairs_within
        );
    }
    Ok(())
}

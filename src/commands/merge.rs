//! `icrender merge`: assembles the parts `render --region` wrote into the whole image, every
//! channel and the header. Parts must come from one render's settings, share a display
//! window, and cover it exactly once; anything else is refused with one line naming the
//! part (and the setting, the overlapping part or the uncovered pixels).

use super::{CommandError, CommandResult};
use crate::cli::MergeArgs;
use crate::image::output::{self, is_data_channel};
use crate::image::region::{
    MERGED_ATTRIBUTE, REGION_ATTRIBUTE, Region, SETTINGS_ATTRIBUTE, Tiling, check_tiling, first_difference,
};
use crate::sys::image_io::{self, ChannelPlane, ImageData, Window};
use std::path::{Path, PathBuf};

/// One part as read: its file, pixels and header, and where it lies.
struct Part {
    path: PathBuf,
    image: ImageData,
    region: Region,
    settings: String,
}

/// Header attributes a part carries over to the whole image: icrender's and Cryptomatte's
/// own, and the standard ones icrender writes.
fn carried_over(name: &str) -> bool {
    (name.starts_with("icrender/")
        || name.starts_with("cryptomatte/")
        || name == "Software"
        || name == "PixelAspectRatio")
        && ![
            REGION_ATTRIBUTE,
            "icrender/command",
            "icrender/statistics",
            "icrender/error_estimate",
            "icrender/render_time_s",
            "icrender/denoise_time_s",
        ]
        .contains(&name)
}

fn read_part(path: &Path) -> Result<Part, CommandError> {
    let image =
        image_io::read_image_with_header(path).map_err(|e| CommandError::input(format!("{}: {e}", path.display())))?;
    let settings = image.attribute(SETTINGS_ATTRIBUTE).map(str::to_string).ok_or_else(|| {
        CommandError::input(format!(
            "{}: not a part of an icrender render (no {SETTINGS_ATTRIBUTE} in its header)",
            path.display()
        ))
    })?;
    let w = image.window;
    let region = Region {
        x0: w.x,
        y0: w.y,
        x1: w.x + image.width,
        y1: w.y + image.height,
    };
    // The header's region is what the render was asked for; the data window is what the file holds.
    if let Some(named) = image.attribute(REGION_ATTRIBUTE)
        && Region::parse(named) != Some(region)
    {
        return Err(CommandError::input(format!(
            "{}: its header names the region {named} but its pixels are {}",
            path.display(),
            region.text()
        )));
    }
    Ok(Part {
        path: path.to_path_buf(),
        image,
        region,
        settings,
    })
}

/// Refuses parts that do not make one image together.
fn check_parts(parts: &[Part]) -> Result<(), CommandError> {
    let first = &parts[0];
    let (fw, fh) = (first.image.window.full_width, first.image.window.full_height);
    for part in &parts[1..] {
        let (w, h) = (part.image.window.full_width, part.image.window.full_height);
        if (w, h) != (fw, fh) {
            return Err(CommandError::input(format!(
                "{}: is a part of a {w}x{h} image, {} of a {fw}x{fh} one",
                part.path.display(),
                first.path.display()
            )));
        }
        if let Some((theirs, mine)) = first_difference(&first.settings, &part.settings) {
            return Err(CommandError::input(format!(
                "{}: was made with other settings than {}: {mine} where it has {theirs}",
                part.path.display(),
                first.path.display()
            )));
        }
        let names = |p: &Part| p.image.channels.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>();
        if names(part) != names(first) {
            return Err(CommandError::input(format!(
                "{}: has other channels than {} ({} against {})",
                part.path.display(),
                first.path.display(),
                names(part).join(","),
                names(first).join(",")
            )));
        }
    }
    let regions: Vec<Region> = parts.iter().map(|p| p.region).collect();
    match check_tiling(fw, fh, &regions) {
        Ok(()) => Ok(()),
        Err(Tiling::Overlap(i, j)) => Err(CommandError::input(format!(
            "{} (region {}) and {} (region {}) overlap",
            parts[i].path.display(),
            parts[i].region.text(),
            parts[j].path.display(),
            parts[j].region.text()
        ))),
        Err(Tiling::Uncovered(r)) => Err(CommandError::input(format!(
            "no part covers the pixels {} (x0 y0 x1 y1) of the {fw}x{fh} image: a part is missing",
            r.text()
        ))),
    }
}

/// The whole image's header: the first part's, without what belongs to one part, with the
/// list of parts, each part's own command, times and statistics, and the summed render time.
fn header(parts: &[Part]) -> Result<Vec<(String, String)>, CommandError> {
    let mut attributes: Vec<(String, String)> = parts[0]
        .image
        .attributes
        .iter()
        .filter(|(name, _)| carried_over(name))
        .cloned()
        .collect();
    let command_line: Vec<String> = std::env::args().collect();
    attributes.push(("icrender/command".into(), command_line.join(" ")));
    let list: Vec<String> = parts
        .iter()
        .map(|p| format!("{}: {}", p.path.display(), p.region.text()))
        .collect();
    attributes.push((MERGED_ATTRIBUTE.into(), list.join("; ")));
    let seconds = |p: &Part, name: &str| p.image.attribute(name).and_then(|v| v.parse::<f64>().ok());
    let total: f64 = parts.iter().filter_map(|p| seconds(p, "icrender/render_time_s")).sum();
    attributes.push(("icrender/render_time_s".into(), format!("{total:.3}")));
    let each: Vec<serde_json::Value> = parts
        .iter()
        .map(|p| {
            serde_json::json!({
                "file": p.path.display().to_string(),
                "region": p.region.text(),
                "command": p.image.attribute("icrender/command"),
                "render_time_s": seconds(p, "icrender/render_time_s"),
                "denoise_time_s": seconds(p, "icrender/denoise_time_s"),
                "statistics": p.image.attribute("icrender/statistics")
                    .and_then(|s| serde_json::from_str::<serde_json::Value>(s).ok()),
            })
        })
        .collect();
    attributes.push(("icrender/parts".into(), serde_json::to_string(&each)?));
    Ok(attributes)
}

pub fn run(args: &MergeArgs) -> CommandResult {
    let out = &args.output;
    if out
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .as_deref()
        != Some("exr")
    {
        return Err(CommandError::input(format!(
            "{}: the merged image must end in .exr",
            out.display()
        )));
    }
    super::render::check_new_output(out, args.overwrite)?;
    if let Some(part) = args.parts.iter().find(|p| !p.is_file()) {
        return Err(CommandError::input(format!("{}: no such part", part.display())));
    }
    let parts = args.parts.iter().map(|p| read_part(p)).collect::<Result<Vec<_>, _>>()?;
    check_parts(&parts)?;
    let window = parts[0].image.window;
    let (width, height) = (window.full_width, window.full_height);
    let mut planes: Vec<(String, Vec<f32>)> = parts[0]
        .image
        .channels
        .iter()
        .map(|(n, _)| (n.clone(), vec![0.0; width as usize * height as usize]))
        .collect();
    for part in &parts {
        let r = part.region;
        for ((_, whole), (_, data)) in planes.iter_mut().zip(&part.image.channels) {
            for (row, y) in (r.y0..r.y1).enumerate() {
                let at = y as usize * width as usize + r.x0 as usize;
                let from = row * r.width() as usize;
                whole[at..at + r.width() as usize].copy_from_slice(&data[from..from + r.width() as usize]);
            }
        }
    }
    let attributes = header(&parts)?;
    // The parts' light layers are half floats when they were rendered with --half.
    let half = parts[0].settings.split("; ").any(|item| item == "--half true");
    let compression = output::ExrCompression::from_settings(&parts[0].settings);
    let channels: Vec<ChannelPlane<'_>> = planes
        .iter()
        .map(|(name, data)| ChannelPlane {
            name,
            data,
            full_float: is_data_channel(name),
        })
        .collect();
    output::write_atomically(out, |tmp| {
        image_io::write_exr(
            tmp,
            width,
            height,
            Window::whole(width, height),
            &channels,
            &attributes,
            half,
            compression.name(),
        )
    })
    .map_err(|e| CommandError::failed(format!("{}: {e}", out.display())))?;
    eprintln!(
        "icrender: merged {} parts into {} ({width}x{height}, {} channels)",
        parts.len(),
        out.display(),
        channels.len()
    );
    Ok(())
}

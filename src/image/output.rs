//! Writing results so that a reader never sees a half-written file: everything goes to a
//! temporary file beside the target, then is renamed over it in one step.

use super::cryptomatte::{RANKS, Ranks};
use super::data::{Aov, PixelData};
use super::framebuffer::{FrameBuffer, Layer};
use super::preview::tone_map;
use crate::sys::image_io::{self, ChannelPlane, Window};
use glam::Vec3;
use std::path::{Path, PathBuf};

fn temporary_beside(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    path.with_file_name(format!(".{name}.partial-{}", std::process::id()))
}

/// Runs `write` on a temporary path, then renames it to `path`; on failure removes the
/// temporary file and leaves whatever was at `path` untouched.
pub fn write_atomically(path: &Path, write: impl FnOnce(&Path) -> Result<(), String>) -> Result<(), String> {
    let temporary = temporary_beside(path);
    let result = write(&temporary).and_then(|()| {
        std::fs::rename(&temporary, path).map_err(|e| format!("cannot move the finished file into place: {e}"))
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&temporary);
    }
    result
}

/// Fails early, before any rendering, if `path` could not be written at the end.
pub fn check_writable(path: &Path) -> Result<(), String> {
    if path.is_dir() {
        return Err("is a directory".into());
    }
    let temporary = temporary_beside(path);
    std::fs::File::create(&temporary).map_err(|e| format!("cannot write here: {e}"))?;
    let _ = std::fs::remove_file(&temporary);
    Ok(())
}

/// The Cryptomatte types' layer names (channels `{name}00.R` ...) and what they rank.
pub const CRYPTO_OBJECT: &str = "CryptoObject";
pub const CRYPTO_MATERIAL: &str = "CryptoMaterial";

/// A plane for the file: its channel name, values, and whether it must stay 32-bit float
/// whatever `--half` says (data layers and Cryptomatte: a half float cannot hold an ID's bits,
/// nor a far depth or a world position to the precision a compositor needs).
struct Plane {
    name: String,
    data: Vec<f32>,
    full_float: bool,
}

/// The planes of the data layers in `aovs`, in that order.
fn data_planes(frame: &FrameBuffer, aovs: &[Aov]) -> Vec<Plane> {
    let data = frame.data();
    let plane = |name: String, value: &dyn Fn(&PixelData) -> f32| Plane {
        name,
        data: data.iter().map(value).collect(),
        full_float: true,
    };
    let vector = |layer: &str, channels: [&str; 3], value: &dyn Fn(&PixelData) -> Vec3| -> Vec<Plane> {
        (0..3)
            .map(|c| plane(format!("{layer}.{}", channels[c]), &|d| value(d)[c]))
            .collect()
    };
    let crypto = |layer: &str, ranks: &dyn Fn(&PixelData) -> &Ranks| -> Vec<Plane> {
        let mut out = Vec::new();
        for level in 0..RANKS / 2 {
            for (c, channel) in ["R", "G", "B", "A"].iter().enumerate() {
                let rank = 2 * level + c / 2;
                let id = c % 2 == 0;
                out.push(plane(format!("{layer}{level:02}.{channel}"), &|d| {
                    let e = ranks(d)[rank];
                    if id { f32::from_bits(e.id) } else { e.coverage }
                }));
            }
        }
        out
    };
    let mut planes = Vec::new();
    for aov in aovs {
        match aov {
            Aov::Albedo => planes.extend(vector("albedo", ["R", "G", "B"], &|d| d.albedo)),
            Aov::Normal => planes.extend(vector("normal", ["X", "Y", "Z"], &|d| d.normal)),
            Aov::Depth => planes.push(plane("depth.Z".into(), &|d| d.depth)),
            Aov::Position => planes.extend(vector("position", ["X", "Y", "Z"], &|d| d.position)),
            Aov::CryptoObject => planes.extend(crypto(CRYPTO_OBJECT, &|d| &d.object)),
            Aov::CryptoMaterial => planes.extend(crypto(CRYPTO_MATERIAL, &|d| &d.material)),
        }
    }
    planes
}

/// Writes the composite as R G B A, each given layer as `layer.R/G/B`, then each of
/// `extra_layers` (a name and a plane: the denoised layers) the same way, and the data layers
/// of `aovs` (always 32-bit float, see `Plane`). The frame's pixels lie at `window` in the
/// whole image (a part of a --region render).
#[allow(clippy::too_many_arguments)]
pub fn write_exr(
    path: &Path,
    frame: &FrameBuffer,
    window: Window,
    layers: &[Layer],
    aovs: &[Aov],
    extra_layers: &[(&str, &[Vec3])],
    attributes: &[(String, String)],
    half_float: bool,
    records_layer: bool,
) -> Result<(), String> {
    let composite = frame.composite();
    let split = |pixels: &[Vec3]| -> [Vec<f32>; 3] { std::array::from_fn(|c| pixels.iter().map(|p| p[c]).collect()) };
    let light = |name: String, data: Vec<f32>| Plane {
        name,
        data,
        full_float: false,
    };
    let mut planes: Vec<Plane> = Vec::new();
    for (c, data) in ["R", "G", "B"].into_iter().zip(split(&composite)) {
        planes.push(light(c.into(), data));
    }
    planes.push(light("A".into(), vec![1.0f32; composite.len()]));
    for &l in layers {
        for (c, data) in ["R", "G", "B"].into_iter().zip(split(frame.layer(l))) {
            planes.push(light(format!("{}.{c}", l.name()), data));
        }
    }
    for &(name, plane) in extra_layers {
        for (c, data) in ["R", "G", "B"].into_iter().zip(split(plane)) {
            planes.push(light(format!("{name}.{c}"), data));
        }
    }
    if records_layer {
        planes.push(light("ic_records.Y".into(), frame.records().to_vec()));
    }
    planes.extend(data_planes(frame, aovs));
    let channels: Vec<ChannelPlane<'_>> = planes
        .iter()
        .map(|p| ChannelPlane {
            name: &p.name,
            data: &p.data,
            full_float: p.full_float,
        })
        .collect();
    write_atomically(path, |tmp| {
        image_io::write_exr(
            tmp,
            frame.width,
            frame.height,
            window,
            &channels,
            attributes,
            half_float,
        )
    })
}

/// Whether a channel written by `write_exr` is a data layer or Cryptomatte (always 32-bit
/// float) rather than light (half with --half).
pub fn is_data_channel(name: &str) -> bool {
    [
        "albedo.",
        "normal.",
        "depth.",
        "position.",
        CRYPTO_OBJECT,
        CRYPTO_MATERIAL,
    ]
    .iter()
    .any(|prefix| name.starts_with(prefix))
}

/// Writes `value` as pretty JSON (statistics), atomically.
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<(), String> {
    let text = serde_json::to_string_pretty(value).map_err(|e| e.to_string())? + "\n";
    write_atomically(path, |tmp| std::fs::write(tmp, &text).map_err(|e| e.to_string()))
}

/// Writes a composite, tone-mapped, as an 8-bit PNG.
pub fn write_preview(path: &Path, width: u32, height: u32, composite: &[Vec3]) -> Result<(), String> {
    let rgb = tone_map(composite);
    write_atomically(path, |tmp| image_io::write_png(tmp, width, height, &rgb))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failed_write_leaves_the_old_file_and_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.exr");
        std::fs::write(&target, b"old").unwrap();
        let result = write_atomically(&target, |tmp| {
            std::fs::write(tmp, b"half").unwrap();
            Err("disk full".into())
        });
        assert!(result.is_err());
        assert_eq!(std::fs::read(&target).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn unwritable_directory_is_reported_before_rendering() {
        assert!(check_writable(Path::new("/nonexistent-dir/x.exr")).is_err());
        let dir = tempfile::tempdir().unwrap();
        assert!(check_writable(&dir.path().join("x.exr")).is_ok());
        assert!(check_writable(dir.path()).is_err());
    }
}

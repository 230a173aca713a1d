//! Writing results so that a reader never sees a half-written file: everything goes to a
//! temporary file beside the target, then is renamed over it in one step.

use super::framebuffer::{FrameBuffer, Layer};
use super::preview::tone_map;
use crate::sys::image_io::{self, ChannelPlane};
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

/// Writes the composite as R G B A, each given layer as `layer.R/G/B`, then each of
/// `extra_layers` (a name and a plane: the denoised layers) the same way.
#[allow(clippy::too_many_arguments)]
pub fn write_exr(
    path: &Path,
    frame: &FrameBuffer,
    layers: &[Layer],
    extra_layers: &[(&str, &[Vec3])],
    attributes: &[(String, String)],
    half_float: bool,
    records_layer: bool,
) -> Result<(), String> {
    let composite = frame.composite();
    let split = |pixels: &[Vec3]| -> [Vec<f32>; 3] { std::array::from_fn(|c| pixels.iter().map(|p| p[c]).collect()) };
    let alpha = vec![1.0f32; composite.len()];
    let composite_planes = split(&composite);
    let layer_planes: Vec<(&str, [Vec<f32>; 3])> = layers
        .iter()
        .map(|&l| (l.name(), split(frame.layer(l))))
        .chain(extra_layers.iter().map(|&(name, plane)| (name, split(plane))))
        .collect();
    let layer_names: Vec<[String; 3]> = layer_planes
        .iter()
        .map(|(name, _)| ["R", "G", "B"].map(|c| format!("{name}.{c}")))
        .collect();
    let mut channels = vec![
        ChannelPlane {
            name: "R",
            data: &composite_planes[0],
        },
        ChannelPlane {
            name: "G",
            data: &composite_planes[1],
        },
        ChannelPlane {
            name: "B",
            data: &composite_planes[2],
        },
        ChannelPlane {
            name: "A",
            data: &alpha,
        },
    ];
    for ((_, planes), names) in layer_planes.iter().zip(&layer_names) {
        for c in 0..3 {
            channels.push(ChannelPlane {
                name: &names[c],
                data: &planes[c],
            });
        }
    }
    if records_layer {
        channels.push(ChannelPlane {
            name: "ic_records.Y",
            data: frame.records(),
        });
    }
    write_atomically(path, |tmp| {
        image_io::write_exr(tmp, frame.width, frame.height, &channels, attributes, half_float)
    })
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

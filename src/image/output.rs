//! Writing results so that a reader never sees a half-written file: everything goes to a
//! temporary file beside the target, then is renamed over it in one step.

use super::cryptomatte::{RANKS, Ranks};
use super::data::{Aov, PixelData};
use super::framebuffer::{FrameBuffer, Layer};
use super::preview::tone_map_each;
use crate::sys::image_io::{self, Window};
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
    stage(path, write)?.place()
}

/// Runs `write` on a temporary path beside `path` and keeps the file there, staged: a failed
/// write leaves no temporary file and says so when the file system is full.
pub fn stage(path: &Path, write: impl FnOnce(&Path) -> Result<(), String>) -> Result<StagedFile, String> {
    let staged = StagedFile {
        temporary: temporary_beside(path),
        target: path.to_path_buf(),
        placed: false,
    };
    write(&staged.temporary).map_err(|e| staged.explain(e))?;
    Ok(staged)
}

/// Whether the file system holding `temporary` (a file being written, or its directory) is
/// full, as seen before the partial file is removed: the bytes left if under 1 MiB.
fn full_file_system(temporary: &Path) -> Option<u64> {
    let at = if temporary.exists() {
        temporary.to_path_buf()
    } else {
        temporary.parent().filter(|p| !p.as_os_str().is_empty())?.to_path_buf()
    };
    crate::sys::disk::free_bytes(&at).filter(|&free| free < 1 << 20)
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

/// Where a channel of the file takes its values from, pixel by pixel. Data layers and
/// Cryptomatte stay 32-bit float whatever `--half` says (a half float cannot hold an ID's bits,
/// nor a far depth or a world position to the precision a compositor needs).
#[derive(Clone, Copy)]
enum Source<'a> {
    Composite(usize),
    Alpha,
    /// A light layer (or a denoised one) and its component.
    Light(&'a [Vec3], usize),
    Records,
    Albedo(usize),
    Normal(usize),
    Depth,
    Position(usize),
    /// A Cryptomatte type's rank: its ID's bits or its coverage.
    Crypto {
        object: bool,
        rank: usize,
        id: bool,
    },
}

impl Source<'_> {
    fn full_float(self) -> bool {
        !matches!(
            self,
            Source::Composite(_) | Source::Alpha | Source::Light(..) | Source::Records
        )
    }

    fn value(self, frame: &FrameBuffer, i: usize) -> f32 {
        let data = |i: usize| -> &PixelData { &frame.data()[i] };
        match self {
            Source::Composite(c) => frame.composite_at(i)[c],
            Source::Alpha => 1.0,
            Source::Light(plane, c) => plane[i][c],
            Source::Records => frame.records()[i],
            Source::Albedo(c) => data(i).albedo[c],
            Source::Normal(c) => data(i).normal[c],
            Source::Depth => data(i).depth,
            Source::Position(c) => data(i).position[c],
            Source::Crypto { object, rank, id } => {
                let ranks: &Ranks = if object { &data(i).object } else { &data(i).material };
                let entry = ranks[rank];
                if id { f32::from_bits(entry.id) } else { entry.coverage }
            }
        }
    }
}

const RGB: [&str; 3] = ["R", "G", "B"];
const XYZ: [&str; 3] = ["X", "Y", "Z"];

/// A three-channel layer's channels, `layer.R` ... (or `R` ... for the unnamed layer), each
/// taking its values from `source` of its component.
fn three<'a>(layer: &str, names: [&str; 3], source: impl Fn(usize) -> Source<'a>) -> Vec<(String, Source<'a>)> {
    (0..3)
        .map(|c| match layer {
            "" => (names[c].to_string(), source(c)),
            _ => (format!("{layer}.{}", names[c]), source(c)),
        })
        .collect()
}

/// The channels of the data layers in `aovs`, in that order.
fn data_channels(aovs: &[Aov]) -> Vec<(String, Source<'static>)> {
    let crypto = |layer: &str, object: bool| {
        let mut out = Vec::new();
        for level in 0..RANKS / 2 {
            for (c, channel) in ["R", "G", "B", "A"].iter().enumerate() {
                let source = Source::Crypto {
                    object,
                    rank: 2 * level + c / 2,
                    id: c % 2 == 0,
                };
                out.push((format!("{layer}{level:02}.{channel}"), source));
            }
        }
        out
    };
    let mut channels = Vec::new();
    for aov in aovs {
        match aov {
            Aov::Albedo => channels.extend(three("albedo", RGB, Source::Albedo)),
            Aov::Normal => channels.extend(three("normal", XYZ, Source::Normal)),
            Aov::Depth => channels.push(("depth.Z".to_string(), Source::Depth)),
            Aov::Position => channels.extend(three("position", XYZ, Source::Position)),
            Aov::CryptoObject => channels.extend(crypto(CRYPTO_OBJECT, true)),
            Aov::CryptoMaterial => channels.extend(crypto(CRYPTO_MATERIAL, false)),
        }
    }
    channels
}

/// Writes the composite as R G B A, each given layer as `layer.R/G/B`, then each of
/// `extra_layers` (a name and a plane: the denoised layers) the same way, and the data layers
/// of `aovs` (always 32-bit float, see `Source`). The frame's pixels lie at `window` in the
/// whole image (a part of a --region render). The pixels go to the file a strip of rows at a
/// time, made from the frame as they go: no planar copy of the image is held (at 3840x2160 with
/// every default layer such a copy took 1.5 GB, and making it a pass over the frame per channel).
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
    compression: ExrCompression,
    records_layer: bool,
) -> Result<(), String> {
    let mut channels = three("", RGB, Source::Composite);
    channels.push(("A".to_string(), Source::Alpha));
    for &l in layers {
        let plane = frame.layer(l);
        channels.extend(three(l.name(), RGB, |c| Source::Light(plane, c)));
    }
    for &(name, plane) in extra_layers {
        if plane.len() != frame.width as usize * frame.height as usize {
            return Err(format!(
                "layer {name} has {} pixels for {}x{}",
                plane.len(),
                frame.width,
                frame.height
            ));
        }
        channels.extend(three(name, RGB, |c| Source::Light(plane, c)));
    }
    if records_layer {
        channels.push(("ic_records.Y".to_string(), Source::Records));
    }
    channels.extend(data_channels(aovs));
    let names: Vec<image_io::ChannelName<'_>> = channels
        .iter()
        .map(|(name, source)| image_io::ChannelName {
            name,
            full_float: source.full_float(),
        })
        .collect();
    let sources: Vec<Source<'_>> = channels.iter().map(|(_, s)| *s).collect();
    let width = frame.width as usize;
    let mut fill = |y0: u32, y1: u32, strip: &mut [f32]| {
        let rows = (y0 as usize * width)..(y1 as usize * width);
        for (pixel, values) in rows.zip(strip.chunks_exact_mut(sources.len())) {
            for (value, source) in values.iter_mut().zip(&sources) {
                *value = source.value(frame, pixel);
            }
        }
    };
    write_atomically(path, |tmp| {
        image_io::write_exr_rows(
            tmp,
            frame.width,
            frame.height,
            window,
            &names,
            attributes,
            half_float,
            compression.name(),
            &mut fill,
        )
    })
}

/// The EXR's codec (`--compression`). Zip, lossless, is what Blender and Nuke write float
/// layers with by default; piz, lossless too, packs noisy light tighter but compresses and
/// reads slower; dwaa is lossy on every channel named like colour, whatever its type, so only
/// for light alone (`job::validate` refuses it beside data layers); none writes the bytes as
/// they are.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum ExrCompression {
    #[default]
    Zip,
    Piz,
    Dwaa,
    None,
}

impl ExrCompression {
    /// OpenEXR's name for it (OpenImageIO's `compression` attribute).
    pub fn name(self) -> &'static str {
        match self {
            ExrCompression::Zip => "zip",
            ExrCompression::Piz => "piz",
            ExrCompression::Dwaa => "dwaa",
            ExrCompression::None => "none",
        }
    }

    /// The codec a file's settings line names (`--compression X`), zip where it names none.
    pub fn from_settings(settings: &str) -> Self {
        settings
            .split("; ")
            .find_map(|item| item.strip_prefix("--compression "))
            .and_then(|name| <Self as clap::ValueEnum>::from_str(name, true).ok())
            .unwrap_or_default()
    }
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

/// A finished file under a temporary name beside its target, not yet in place: `place` renames
/// it over the target; dropped unplaced, it is removed. For a file made beside another (the
/// preview while the EXR is written) that must appear only if the other does.
pub struct StagedFile {
    temporary: PathBuf,
    target: PathBuf,
    placed: bool,
}

impl StagedFile {
    /// Renames the file over its target; on failure it is removed (on drop).
    pub fn place(mut self) -> Result<(), String> {
        std::fs::rename(&self.temporary, &self.target)
            .map_err(|e| self.explain(format!("cannot move the finished file into place: {e}")))?;
        self.placed = true;
        Ok(())
    }

    /// A failed write's message, with the file system's state when it is full (seen before
    /// the partial file is removed).
    fn explain(&self, e: String) -> String {
        match full_file_system(&self.temporary) {
            Some(free) => format!("the file system is full ({free} bytes free): {e}"),
            None => e,
        }
    }
}

impl Drop for StagedFile {
    fn drop(&mut self) {
        if !self.placed {
            let _ = std::fs::remove_file(&self.temporary);
        }
    }
}

/// The preview: a composite (`pixel` by index, `width` x `height` of them), tone-mapped, as an
/// 8-bit PNG under a temporary name beside `path`, to be placed later.
pub fn stage_preview(
    path: &Path,
    width: u32,
    height: u32,
    pixel: impl Fn(usize) -> Vec3,
) -> Result<StagedFile, String> {
    let rgb = tone_map_each(width as usize * height as usize, pixel);
    stage(path, |tmp| image_io::write_png(tmp, width, height, &rgb))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_staged_file_appears_only_when_placed() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.png");
        std::fs::write(&target, b"old").unwrap();
        let staged = |dir: &Path| StagedFile {
            temporary: temporary_beside(&dir.join("out.png")),
            target: dir.join("out.png"),
            placed: false,
        };
        let dropped = staged(dir.path());
        std::fs::write(&dropped.temporary, b"new").unwrap();
        drop(dropped);
        assert_eq!(std::fs::read(&target).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "no temporary left");
        let placed = staged(dir.path());
        std::fs::write(&placed.temporary, b"new").unwrap();
        placed.place().unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

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

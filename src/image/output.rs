//! Writing results so that a reader never sees a half-written file: everything goes to a
//! temporary file beside the target, then is renamed over it in one step.

use super::preview::PreviewBuffer;
use crate::sys::image_io;
use crate::sys::unnamed_file::UnnamedFile;
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
///
/// The file has no name while it is written where the file system allows (`UnnamedFile`): a
/// process killed meanwhile, even by SIGKILL, leaves nothing. It takes its temporary name only
/// for the instant before it is renamed over the target.
pub fn stage(path: &Path, write: impl FnOnce(&Path) -> Result<(), String>) -> Result<StagedFile, String> {
    let dir = path.parent().unwrap_or(Path::new(""));
    let staged = StagedFile {
        unnamed: UnnamedFile::create_in(dir).ok(),
        temporary: temporary_beside(path),
        target: path.to_path_buf(),
        placed: false,
    };
    let writing = staged
        .unnamed
        .as_ref()
        .map_or_else(|| staged.temporary.clone(), UnnamedFile::path);
    write(&writing).map_err(|e| staged.explain(e))?;
    Ok(staged)
}

/// A failed write's message for `target`, with the file system's state when it is full.
pub fn explain_failure(target: &Path, e: String) -> String {
    match full_file_system(&temporary_beside(target)) {
        Some(free) => format!("the file system is full ({free} bytes free): {e}"),
        None => e,
    }
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

/// Whether a channel of the layered EXR (`layered_exr`) is a data layer or Cryptomatte (always 32-bit
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
    /// The file, while it has no name (None where the file system cannot make one: then it is
    /// written under `temporary`).
    unnamed: Option<UnnamedFile>,
    temporary: PathBuf,
    target: PathBuf,
    placed: bool,
}

impl StagedFile {
    /// A finished file with no name, to be put in place under `target`.
    pub fn unnamed(file: UnnamedFile, target: &Path) -> StagedFile {
        StagedFile {
            unnamed: Some(file),
            temporary: temporary_beside(target),
            target: target.to_path_buf(),
            placed: false,
        }
    }

    /// A finished file under the temporary name `temporary`, to be renamed to `target`.
    pub fn named(temporary: PathBuf, target: &Path) -> StagedFile {
        StagedFile {
            unnamed: None,
            temporary,
            target: target.to_path_buf(),
            placed: false,
        }
    }

    /// Renames the file over its target; on failure it is removed (on drop).
    pub fn place(mut self) -> Result<(), String> {
        if let Some(file) = &self.unnamed {
            // A name left by an earlier process of this number is stale.
            let _ = std::fs::remove_file(&self.temporary);
            file.link_as(&self.temporary)
                .map_err(|e| self.explain(format!("cannot name the finished file: {e}")))?;
        }
        std::fs::rename(&self.temporary, &self.target)
            .map_err(|e| self.explain(format!("cannot move the finished file into place: {e}")))?;
        self.placed = true;
        Ok(())
    }

    /// A failed write's message, with the file system's state when it is full (seen before
    /// the partial file is removed).
    fn explain(&self, e: String) -> String {
        explain_failure(&self.target, e)
    }
}

impl Drop for StagedFile {
    fn drop(&mut self) {
        if !self.placed {
            let _ = std::fs::remove_file(&self.temporary);
        }
    }
}

/// The preview made from a streamed frame's reduced copy, staged beside `path`.
pub fn stage_kept_preview(path: &Path, kept: &PreviewBuffer) -> Result<StagedFile, String> {
    let rgb = kept.tone_map();
    stage(path, |tmp| image_io::write_png(tmp, kept.width, kept.height, &rgb))
}

/// The preview: a composite (`pixel` by index, `width` x `height` of them), tone-mapped, as an
/// 8-bit PNG under a temporary name beside `path`, to be placed later.
pub fn stage_preview(
    path: &Path,
    width: u32,
    height: u32,
    pixel: impl Fn(usize) -> Vec3,
) -> Result<StagedFile, String> {
    // The same preview a streamed frame keeps (reduced beyond `PREVIEW_MAX_PIXELS`).
    let mut kept = PreviewBuffer::new(width, height);
    (0..width as usize * height as usize).for_each(|i| kept.set(i, pixel(i)));
    stage_kept_preview(path, &kept)
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
            unnamed: None,
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

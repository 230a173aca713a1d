//! Files without a name until they are finished (Linux's O_TMPFILE): a process killed while
//! writing one, even by SIGKILL, leaves nothing behind, where a named temporary file would stay.
//! Libraries that open files by name (OpenImageIO, OpenEXR) reach it through /proc/self/fd.

use std::ffi::CString;
use std::fs::{File, OpenOptions};
use std::io;
use std::os::unix::fs::OpenOptionsExt;
use std::os::unix::io::AsRawFd;
use std::path::{Path, PathBuf};

/// A file open for reading and writing in a directory, with no name there.
pub struct UnnamedFile {
    file: File,
}

impl UnnamedFile {
    /// A new, empty file in `dir` without a name; fails where the file system cannot make one
    /// (O_TMPFILE needs Linux 3.11 and a file system that supports it: ext4, xfs, btrfs, tmpfs).
    pub fn create_in(dir: &Path) -> io::Result<UnnamedFile> {
        let dir = if dir.as_os_str().is_empty() {
            Path::new(".")
        } else {
            dir
        };
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .mode(0o666)
            .custom_flags(libc::O_TMPFILE)
            .open(dir)?;
        Ok(UnnamedFile { file })
    }

    /// A name under which this process (only) can open the file, for libraries that take a
    /// path. Opening it with truncation empties the file.
    pub fn path(&self) -> PathBuf {
        PathBuf::from(format!("/proc/self/fd/{}", self.file.as_raw_fd()))
    }

    /// Gives the file the name `path`, in the directory it was made in; fails if `path` exists.
    pub fn link_as(&self, path: &Path) -> io::Result<()> {
        let from = CString::new(self.path().into_os_string().into_encoded_bytes())?;
        let to = CString::new(path.as_os_str().as_encoded_bytes())?;
        // SAFETY: two NUL-terminated paths alive for the call; linkat reads them only.
        let status = unsafe {
            libc::linkat(
                libc::AT_FDCWD,
                from.as_ptr(),
                libc::AT_FDCWD,
                to.as_ptr(),
                libc::AT_SYMLINK_FOLLOW,
            )
        };
        if status == 0 {
            Ok(())
        } else {
            Err(io::Error::last_os_error())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unnamed_file_is_invisible_until_linked_and_gone_if_dropped() {
        let dir = tempfile::tempdir().unwrap();
        let file = UnnamedFile::create_in(dir.path()).unwrap();
        std::fs::write(file.path(), b"pixels").unwrap();
        assert_eq!(
            std::fs::read_dir(dir.path()).unwrap().count(),
            0,
            "the file has no name yet"
        );
        assert_eq!(std::fs::read(file.path()).unwrap(), b"pixels");
        let named = dir.path().join("done");
        file.link_as(&named).unwrap();
        assert_eq!(std::fs::read(&named).unwrap(), b"pixels");
        assert!(file.link_as(&named).is_err(), "an existing name is not replaced");
        let dropped = UnnamedFile::create_in(dir.path()).unwrap();
        std::fs::write(dropped.path(), b"half").unwrap();
        drop(dropped);
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("done")]);
    }
}

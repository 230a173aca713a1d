//! What the file system holding a path has left: to say "the disk is full" rather than pass on
//! a library's bare "write failed".

use std::ffi::CString;
use std::path::Path;

/// Bytes an unprivileged writer may still use on the file system holding `path` (a file or a
/// directory that exists), or None where the system cannot say.
pub fn free_bytes(path: &Path) -> Option<u64> {
    let path = CString::new(path.as_os_str().as_encoded_bytes()).ok()?;
    let mut stats = std::mem::MaybeUninit::<libc::statvfs>::zeroed();
    // SAFETY: a NUL-terminated path and a buffer of the struct's size, filled by the call.
    let status = unsafe { libc::statvfs(path.as_ptr(), stats.as_mut_ptr()) };
    if status != 0 {
        return None;
    }
    // SAFETY: statvfs succeeded, so it filled the struct.
    let stats = unsafe { stats.assume_init() };
    Some(stats.f_bavail.saturating_mul(stats.f_frsize))
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_directory_that_exists_has_an_answer_and_one_that_does_not_has_none() {
        assert!(super::free_bytes(std::path::Path::new("/")).is_some());
        assert!(super::free_bytes(std::path::Path::new("/no/such/place")).is_none());
    }
}

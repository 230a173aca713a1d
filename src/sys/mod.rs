//! The FFI boundary. Generated bindings and the safe wrappers over them live here, and nowhere
//! else in the crate may say `unsafe`.

/// The code bindgen generated (build.rs), lints off: it is not ours to style.
#[allow(
    non_upper_case_globals,
    non_camel_case_types,
    non_snake_case,
    dead_code,
    clippy::all,
    unsafe_op_in_unsafe_fn
)]
mod generated {
    pub mod embree {
        include!(concat!(env!("OUT_DIR"), "/embree_bindings.rs"));
    }
    pub mod abi {
        include!(concat!(env!("OUT_DIR"), "/abi_bindings.rs"));
    }
    /// The image shim's functions as a table loaded at run time (see image_io.rs).
    pub mod image {
        include!(concat!(env!("OUT_DIR"), "/image_bindings.rs"));
    }
}
use generated::{abi as abi_bindings, embree as embree_bindings, image as image_bindings};

pub mod alloc;
pub mod clock;
pub mod disk;
pub mod embree;
pub mod exr_chunks;
pub mod image_io;
pub mod oidn;
pub mod prefetch;
pub mod process;
pub mod scene_io;
pub mod signals;
pub mod unnamed_file;

use std::ffi::CStr;
use std::os::raw::c_char;

/// Size of the error buffers handed to the C++ side.
const ERR_LEN: usize = 1024;

/// Text of a NUL-terminated error buffer written by C++.
fn buffer_message(buf: &[c_char]) -> String {
    let bytes: Vec<u8> = buf.iter().take_while(|&&c| c != 0).map(|&c| c as u8).collect();
    let text = String::from_utf8_lossy(&bytes).trim().to_string();
    if text.is_empty() {
        "unknown error".to_string()
    } else {
        text
    }
}

/// Copies a C string that may be NULL.
///
/// # Safety
/// `ptr` is NULL or points at a NUL-terminated string that stays valid during the call.
unsafe fn owned_string(ptr: *const c_char) -> String {
    if ptr.is_null() {
        String::new()
    } else {
        // SAFETY: guaranteed by the caller.
        unsafe { CStr::from_ptr(ptr) }.to_string_lossy().into_owned()
    }
}

/// A borrowed slice from C that may be NULL when empty.
///
/// # Safety
/// When `len > 0`, `ptr` points at `len` initialised values that outlive the returned slice.
unsafe fn slice_or_empty<'a, T>(ptr: *const T, len: usize) -> &'a [T] {
    if ptr.is_null() || len == 0 {
        &[]
    } else {
        // SAFETY: guaranteed by the caller.
        unsafe { std::slice::from_raw_parts(ptr, len) }
    }
}

/// Where a library shipped beside the binary may be: the executable's folder, and the one above
/// it (test binaries run from target/<profile>/deps).
fn beside_executable(name: &str) -> Vec<std::path::PathBuf> {
    let mut paths = Vec::new();
    if let Some(dir) = std::env::current_exe()
        .ok()
        .and_then(|e| e.parent().map(std::path::Path::to_path_buf))
    {
        paths.push(dir.join(name));
        if let Some(up) = dir.parent() {
            paths.push(up.join(name));
        }
    }
    paths
}

//! Safe wrapper over the OpenImageIO shim: multi-layer EXR and PNG writing, and reading an
//! image back as named float planes.
//!
//! The shim is a shared library of its own (`libicrender_image.so`, built by build.rs), opened
//! the first time an image is read or written: OpenImageIO drags in about 270 shared libraries
//! whose symbol binding costs a process ~0.3 s of CPU, which worker ranks and commands that
//! never touch an image should not pay.

use super::image_bindings as abi;
use super::{ERR_LEN, buffer_message, owned_string, slice_or_empty};
use std::ffi::CString;
use std::os::raw::c_char;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

const LIBRARY_NAME: &str = "libicrender_image.so";

/// Where the image library may be, in order: $ICRENDER_IMAGE_LIB, beside the executable (and
/// one level up, for test binaries in target/<profile>/deps), and where build.rs made it.
fn library_candidates() -> Vec<PathBuf> {
    let mut paths = Vec::new();
    if let Some(path) = std::env::var_os("ICRENDER_IMAGE_LIB") {
        paths.push(PathBuf::from(path));
    }
    paths.extend(super::beside_executable(LIBRARY_NAME));
    paths.push(Path::new(env!("OUT_DIR")).join(LIBRARY_NAME));
    paths
}

fn open_library() -> Result<abi::ImageLibrary, String> {
    let candidates = library_candidates();
    let mut failures = Vec::new();
    for path in &candidates {
        if !path.is_file() {
            continue;
        }
        // SAFETY: the library is ours (cpp/image_io.cpp); loading it runs only the static
        // constructors of OpenImageIO and its dependencies, and every symbol is checked.
        match unsafe { abi::ImageLibrary::new(path) } {
            Ok(library) => return Ok(library),
            Err(e) => failures.push(format!("{}: {e}", path.display())),
        }
    }
    if failures.is_empty() {
        let looked: Vec<String> = candidates.iter().map(|p| p.display().to_string()).collect();
        Err(format!(
            "the image library {LIBRARY_NAME} was not found (looked in {}; set ICRENDER_IMAGE_LIB)",
            looked.join(", ")
        ))
    } else {
        Err(format!(
            "the image library could not be opened: {}",
            failures.join("; ")
        ))
    }
}

/// Opens the image library on a thread of its own, for a process that will write an image at
/// the end: the opening (~0.3 s of CPU) then overlaps the scene load and the render instead of
/// coming after them. A failure is reported by the first real use. A command that ends before
/// the opening has finished does not wait for it: `process::exit_finished` runs no destructors.
pub fn open_in_background() {
    std::thread::spawn(|| {
        let _ = library();
    });
}

/// The image library, opened on first use and kept for the life of the process.
fn library() -> Result<&'static abi::ImageLibrary, String> {
    static LIBRARY: OnceLock<Result<abi::ImageLibrary, String>> = OnceLock::new();
    LIBRARY.get_or_init(open_library).as_ref().map_err(Clone::clone)
}

fn c_path(path: &Path) -> Result<CString, String> {
    CString::new(path.as_os_str().as_encoded_bytes()).map_err(|_| "path contains a NUL byte".to_string())
}

fn c_text(text: &str) -> CString {
    // Interior NULs cannot travel through C strings; they never occur in our names, and in
    // free text (a command line) dropping them is harmless.
    CString::new(text.replace('\0', "")).expect("NULs removed")
}

/// A named plane of width * height floats, rows top to bottom.
pub struct ChannelPlane<'a> {
    pub name: &'a str,
    pub data: &'a [f32],
    /// Stored as 32-bit float even in a half-float file.
    pub full_float: bool,
}

/// Where an image's pixels (its data window) lie in the whole image (its display window, from
/// (0, 0)): OpenEXR's two windows, for a part of a larger image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Window {
    pub x: u32,
    pub y: u32,
    pub full_width: u32,
    pub full_height: u32,
}

impl Window {
    /// A whole image: the data window is the display window.
    pub fn whole(width: u32, height: u32) -> Window {
        Window {
            x: 0,
            y: 0,
            full_width: width,
            full_height: height,
        }
    }
}

/// Writes an OpenEXR with the given channels (in order) and string attributes to exactly `path`;
/// with `half_float`, every channel not marked `full_float` is stored as half. The channels
/// hold `width` x `height` pixels placed at `window` in the display window, compressed with
/// OpenEXR's codec named `compression`.
#[allow(clippy::too_many_arguments)]
pub fn write_exr(
    path: &Path,
    width: u32,
    height: u32,
    window: Window,
    channels: &[ChannelPlane<'_>],
    attributes: &[(String, String)],
    half_float: bool,
    compression: &str,
) -> Result<(), String> {
    let pixels = width as usize * height as usize;
    if let Some(bad) = channels.iter().find(|c| c.data.len() != pixels) {
        return Err(format!(
            "channel {} has {} values for {} pixels",
            bad.name,
            bad.data.len(),
            pixels
        ));
    }
    let names: Vec<ChannelName<'_>> = channels
        .iter()
        .map(|c| ChannelName {
            name: c.name,
            full_float: c.full_float,
        })
        .collect();
    let width = width as usize;
    let mut fill = |y0: u32, y1: u32, strip: &mut [f32]| {
        let rows = (y0 as usize * width)..(y1 as usize * width);
        for (pixel, values) in rows.zip(strip.chunks_exact_mut(channels.len())) {
            for (value, channel) in values.iter_mut().zip(channels) {
                *value = channel.data[pixel];
            }
        }
    };
    write_exr_rows(
        path,
        width as u32,
        height,
        window,
        &names,
        attributes,
        half_float,
        compression,
        &mut fill,
    )
}

/// A channel of an EXR written row by row: its name, and whether it stays 32-bit float in a
/// half-float file.
pub struct ChannelName<'a> {
    pub name: &'a str,
    pub full_float: bool,
}

/// Makes the pixels of rows `y0..y1` of the data window (0 its top row) into `strip`: row by
/// row, pixel by pixel, every channel in the order given.
pub type FillRows<'a> = dyn FnMut(u32, u32, &mut [f32]) + 'a;

/// What the trampoline needs to hand a strip to the filler.
struct FillContext<'a, 'b> {
    values_per_row: usize,
    fill: &'a mut FillRows<'b>,
    /// Whether `fill` panicked (the write stops; the panic goes on once C++ has returned).
    panic: Option<Box<dyn std::any::Any + Send>>,
}

unsafe extern "C" fn fill_rows(context: *mut std::ffi::c_void, y0: u32, y1: u32, strip: *mut f32) -> i32 {
    // SAFETY: `context` is the FillContext `write_exr_rows` passed, alive for the call; the
    // writer hands a strip of (y1 - y0) rows of values_per_row floats.
    let context = unsafe { &mut *context.cast::<FillContext<'_, '_>>() };
    let strip = unsafe { std::slice::from_raw_parts_mut(strip, (y1 - y0) as usize * context.values_per_row) };
    // A panic must not unwind into C++.
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| (context.fill)(y0, y1, strip))) {
        Ok(()) => 0,
        Err(panic) => {
            context.panic = Some(panic);
            1
        }
    }
}

/// Writes an OpenEXR as `write_exr` does, its pixels made a strip of rows at a time by `fill`
/// (top to bottom) rather than read from planes: the caller need hold no planar copy of the
/// image.
#[allow(clippy::too_many_arguments)]
pub fn write_exr_rows(
    path: &Path,
    width: u32,
    height: u32,
    window: Window,
    channels: &[ChannelName<'_>],
    attributes: &[(String, String)],
    half_float: bool,
    compression: &str,
    fill: &mut FillRows<'_>,
) -> Result<(), String> {
    check_window(width, height, window)?;
    let (_names, planes) = c_channels(channels);
    let (_text, attrs) = c_attributes(attributes);
    let path = c_path(path)?;
    let compression = c_text(compression);
    let lib = library()?;
    let mut err = vec![0 as c_char; ERR_LEN];
    let mut context = FillContext {
        values_per_row: width as usize * channels.len(),
        fill,
        panic: None,
    };
    // SAFETY: every pointer refers to data alive for the call; the writer calls `fill_rows`
    // with `context` only during the call, with strips of whole rows.
    let rc = unsafe {
        lib.icr_exr_write_rows(
            path.as_ptr(),
            width,
            height,
            c_window(window),
            planes.as_ptr(),
            planes.len(),
            attrs.as_ptr(),
            attrs.len(),
            half_float as i32,
            compression.as_ptr(),
            Some(fill_rows),
            (&raw mut context).cast(),
            err.as_mut_ptr(),
            err.len(),
        )
    };
    if let Some(panic) = context.panic.take() {
        std::panic::resume_unwind(panic);
    }
    if rc == 0 { Ok(()) } else { Err(buffer_message(&err)) }
}

/// A tiled EXR written as its tiles finish (any order, any thread), then finished under its
/// final name with the attributes known only at the end (`icr_exr_stream_*` in ffi/image_io.h).
pub struct ExrStream {
    raw: *mut abi::icr_exr_stream,
    lib: &'static abi::ImageLibrary,
    width: u32,
    height: u32,
    tile: (u32, u32),
    channels: usize,
}

// SAFETY: the C++ stream serialises every write behind its own lock, and open, finish and close
// take the stream by value or are called once (Drop).
unsafe impl Send for ExrStream {}
unsafe impl Sync for ExrStream {}

impl ExrStream {
    /// Opens the stream's file at `path` (truncated): `width` x `height` pixels at `window`,
    /// `tile` pixels a tile, the channels in order (half with `half_float` but those marked
    /// `full_float`), OpenEXR's codec `compression`, and `header_room` bytes kept in the header
    /// for the attributes known only at the end (`set_exr_header`).
    #[allow(clippy::too_many_arguments)]
    pub fn open(
        path: &Path,
        width: u32,
        height: u32,
        window: Window,
        channels: &[ChannelName<'_>],
        half_float: bool,
        compression: &str,
        tile: (u32, u32),
        header_room: usize,
    ) -> Result<ExrStream, String> {
        check_window(width, height, window)?;
        let (_names, planes) = c_channels(channels);
        let path = c_path(path)?;
        let compression = c_text(compression);
        let lib = library()?;
        let mut err = vec![0 as c_char; ERR_LEN];
        // SAFETY: every pointer refers to data alive for the call; the stream keeps copies.
        let raw = unsafe {
            lib.icr_exr_stream_open(
                path.as_ptr(),
                width,
                height,
                c_window(window),
                planes.as_ptr(),
                planes.len(),
                half_float as i32,
                compression.as_ptr(),
                tile.0,
                tile.1,
                header_room,
                err.as_mut_ptr(),
                err.len(),
            )
        };
        if raw.is_null() {
            return Err(buffer_message(&err));
        }
        Ok(ExrStream {
            raw,
            lib,
            width,
            height,
            tile,
            channels: channels.len(),
        })
    }

    /// Writes the pixels `x0..x1` x `y0..y1` of the data window (0 its first row and column),
    /// interleaved row by row, every channel in order: whole tiles (the rectangle starts on the
    /// tile grid and ends on it or at the window's edge).
    pub fn write(&self, (x0, y0): (u32, u32), (x1, y1): (u32, u32), pixels: &[f32]) -> Result<(), String> {
        let (tw, th) = self.tile;
        let on_grid = x0 < x1
            && y0 < y1
            && x1 <= self.width
            && y1 <= self.height
            && x0 % tw == 0
            && y0 % th == 0
            && (x1 % tw == 0 || x1 == self.width)
            && (y1 % th == 0 || y1 == self.height);
        if !on_grid {
            return Err(format!(
                "pixels ({x0}, {y0})..({x1}, {y1}) are not whole tiles of the stream"
            ));
        }
        if pixels.len() != (x1 - x0) as usize * (y1 - y0) as usize * self.channels {
            return Err(format!(
                "{} values for the {}x{} pixels of a tile",
                pixels.len(),
                x1 - x0,
                y1 - y0
            ));
        }
        let mut err = vec![0 as c_char; ERR_LEN];
        // SAFETY: the stream is open (finish consumes it); the buffer holds the rectangle's
        // values, checked above.
        let rc = unsafe {
            self.lib
                .icr_exr_stream_write(self.raw, x0, y0, x1, y1, pixels.as_ptr(), err.as_mut_ptr(), err.len())
        };
        if rc == 0 { Ok(()) } else { Err(buffer_message(&err)) }
    }

    /// Ends the stream: its file is complete (its chunk offsets written), under the header
    /// it was opened with.
    pub fn end(mut self) -> Result<(), String> {
        let raw = std::mem::replace(&mut self.raw, std::ptr::null_mut());
        let mut err = vec![0 as c_char; ERR_LEN];
        // SAFETY: `raw` is open and given up here (end frees it, Drop sees null).
        let rc = unsafe { self.lib.icr_exr_stream_end(raw, err.as_mut_ptr(), err.len()) };
        if rc == 0 { Ok(()) } else { Err(buffer_message(&err)) }
    }
}

/// Puts `attributes` into the header of the tiled EXR at `path` (written by a `ChunkFile` or an
/// `ExrStream`)
/// in place, in the room kept for them: false, with nothing changed, if they do not fit.
pub fn set_exr_header(path: &Path, attributes: &[(String, String)]) -> Result<bool, String> {
    let (_text, attrs) = c_attributes(attributes);
    let path = c_path(path)?;
    let lib = library()?;
    let mut err = vec![0 as c_char; ERR_LEN];
    // SAFETY: the path and the attributes live for the call.
    let rc = unsafe { lib.icr_exr_set_header(path.as_ptr(), attrs.as_ptr(), attrs.len(), err.as_mut_ptr(), err.len()) };
    match rc {
        0 => Ok(true),
        2 => Ok(false),
        _ => Err(buffer_message(&err)),
    }
}

/// Writes `to`: the tiled EXR `from` with `attributes` added to its header, its compressed
/// tiles copied as they are.
pub fn copy_exr_with_header(from: &Path, to: &Path, attributes: &[(String, String)]) -> Result<(), String> {
    let (_text, attrs) = c_attributes(attributes);
    let (from, to) = (c_path(from)?, c_path(to)?);
    let lib = library()?;
    let mut err = vec![0 as c_char; ERR_LEN];
    // SAFETY: the paths and the attributes live for the call.
    let rc = unsafe {
        lib.icr_exr_copy_with_header(
            from.as_ptr(),
            to.as_ptr(),
            attrs.as_ptr(),
            attrs.len(),
            err.as_mut_ptr(),
            err.len(),
        )
    };
    if rc == 0 { Ok(()) } else { Err(buffer_message(&err)) }
}

impl Drop for ExrStream {
    fn drop(&mut self) {
        if !self.raw.is_null() {
            // SAFETY: an open stream, closed once.
            unsafe { self.lib.icr_exr_stream_close(self.raw) };
        }
    }
}

/// The C channels of a writer that makes its pixels itself (no planes; the names they point
/// into, to keep alive beside them).
fn c_channels(channels: &[ChannelName<'_>]) -> (Vec<CString>, Vec<abi::icr_channel>) {
    let names: Vec<CString> = channels.iter().map(|c| c_text(c.name)).collect();
    let planes = channels
        .iter()
        .zip(&names)
        .map(|(c, n)| abi::icr_channel {
            name: n.as_ptr(),
            data: std::ptr::null(),
            full_float: c.full_float as i32,
        })
        .collect();
    (names, planes)
}

/// The C attributes (and the strings they point into, to keep alive beside them).
fn c_attributes(attributes: &[(String, String)]) -> (Vec<(CString, CString)>, Vec<abi::icr_attribute>) {
    let text: Vec<(CString, CString)> = attributes.iter().map(|(k, v)| (c_text(k), c_text(v))).collect();
    let attrs = text
        .iter()
        .map(|(k, v)| abi::icr_attribute {
            name: k.as_ptr(),
            value: v.as_ptr(),
        })
        .collect();
    (text, attrs)
}

fn c_window(window: Window) -> abi::icr_window {
    abi::icr_window {
        x: window.x as i32,
        y: window.y as i32,
        full_width: window.full_width,
        full_height: window.full_height,
    }
}

/// The pixels `width` x `height` at `window` lie inside the display window.
fn check_window(width: u32, height: u32, window: Window) -> Result<(), String> {
    if u64::from(window.x) + u64::from(width) > u64::from(window.full_width)
        || u64::from(window.y) + u64::from(height) > u64::from(window.full_height)
        || window.x > i32::MAX as u32
        || window.y > i32::MAX as u32
    {
        return Err(format!(
            "the pixels {width}x{height} at ({}, {}) do not lie inside the image {}x{}",
            window.x, window.y, window.full_width, window.full_height
        ));
    }
    Ok(())
}

/// Writes an 8-bit RGB PNG to exactly `path`.
pub fn write_png(path: &Path, width: u32, height: u32, rgb: &[u8]) -> Result<(), String> {
    if rgb.len() != 3 * width as usize * height as usize {
        return Err("PNG buffer size does not match the image size".into());
    }
    let path = c_path(path)?;
    let lib = library()?;
    let mut err = vec![0 as c_char; ERR_LEN];
    // SAFETY: the buffer holds 3*width*height bytes, checked above.
    let rc = unsafe { lib.icr_png_write(path.as_ptr(), width, height, rgb.as_ptr(), err.as_mut_ptr(), err.len()) };
    if rc == 0 { Ok(()) } else { Err(buffer_message(&err)) }
}

/// An image read back: named float planes and the header's string attributes we asked for.
pub struct ImageData {
    /// The data window's size: the planes hold width * height values.
    pub width: u32,
    pub height: u32,
    /// Where the data window lies in the display window.
    pub window: Window,
    pub channels: Vec<(String, Vec<f32>)>,
    pub attributes: Vec<(String, String)>,
}

impl ImageData {
    pub fn channel(&self, name: &str) -> Option<&[f32]> {
        self.channels.iter().find(|(n, _)| n == name).map(|(_, d)| d.as_slice())
    }
    pub fn attribute(&self, name: &str) -> Option<&str> {
        self.attributes.iter().find(|(n, _)| n == name).map(|(_, v)| v.as_str())
    }
}

struct ImageHandle(&'static abi::ImageLibrary, *mut abi::icr_image);

impl Drop for ImageHandle {
    fn drop(&mut self) {
        // SAFETY: the pointer came from icr_image_read and is freed once.
        unsafe { self.0.icr_image_free(self.1) };
    }
}

/// Which header attributes `read` returns.
enum Wanted<'a> {
    Named(&'a [&'a str]),
    All,
}

/// Reads every channel of an image file, plus the named header attributes where present.
pub fn read_image(path: &Path, attribute_names: &[&str]) -> Result<ImageData, String> {
    read(path, Wanted::Named(attribute_names))
}

/// Reads every channel of an image file and every attribute of its header (as text).
pub fn read_image_with_header(path: &Path) -> Result<ImageData, String> {
    read(path, Wanted::All)
}

fn read(path: &Path, wanted: Wanted<'_>) -> Result<ImageData, String> {
    let cpath = c_path(path)?;
    let lib = library()?;
    let mut err = vec![0 as c_char; ERR_LEN];
    // SAFETY: valid path and error buffer.
    let raw = unsafe { lib.icr_image_read(cpath.as_ptr(), err.as_mut_ptr(), err.len()) };
    if raw.is_null() {
        return Err(buffer_message(&err));
    }
    let handle = ImageHandle(lib, raw);
    // SAFETY: the handle is live; planes hold width*height floats (the shim's contract) and are
    // copied before the handle is dropped.
    unsafe {
        let width = lib.icr_image_width(handle.1);
        let height = lib.icr_image_height(handle.1);
        let w = lib.icr_image_window(handle.1);
        // A display window that does not hold the data window (not one icrender writes) is
        // taken as the data window itself.
        let window = if w.x >= 0
            && w.y >= 0
            && u64::from(w.x as u32) + u64::from(width) <= u64::from(w.full_width)
            && u64::from(w.y as u32) + u64::from(height) <= u64::from(w.full_height)
        {
            Window {
                x: w.x as u32,
                y: w.y as u32,
                full_width: w.full_width,
                full_height: w.full_height,
            }
        } else {
            Window::whole(width, height)
        };
        let pixels = width as usize * height as usize;
        let count = lib.icr_image_channel_count(handle.1);
        let mut channels = Vec::with_capacity(count);
        for i in 0..count {
            let name = owned_string(lib.icr_image_channel_name(handle.1, i));
            let data = slice_or_empty(lib.icr_image_channel_data(handle.1, i), pixels).to_vec();
            channels.push((name, data));
        }
        let mut attributes = Vec::new();
        let all: Vec<String>;
        let attribute_names: Vec<&str> = match wanted {
            Wanted::Named(names) => names.to_vec(),
            Wanted::All => {
                all = (0..lib.icr_image_attribute_count(handle.1))
                    .map(|i| owned_string(lib.icr_image_attribute_name(handle.1, i)))
                    .collect();
                all.iter().map(String::as_str).collect()
            }
        };
        for name in attribute_names {
            let cname = c_text(name);
            let value = lib.icr_image_attribute(handle.1, cname.as_ptr());
            if !value.is_null() {
                attributes.push((name.to_string(), owned_string(value)));
            }
        }
        Ok(ImageData {
            width,
            height,
            window,
            channels,
            attributes,
        })
    }
}

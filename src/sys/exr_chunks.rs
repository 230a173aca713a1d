//! Safe wrapper over cpp/exr_chunks.cpp: a tiled EXR's tiles encoded (compressed) by whoever
//! renders them, and written as encoded bytes by whoever holds the file.

use super::abi_bindings as abi;
use super::{ERR_LEN, buffer_message};
use std::ffi::{CString, c_void};
use std::os::raw::c_char;
use std::path::Path;

/// A tiled EXR's layout: a data window of `width` x `height` pixels at (`x`, `y`) of a display
/// window `full_width` x `full_height`; its channels (name, stored as half); OpenEXR's codec by
/// name; its tile size.
#[derive(Clone, Debug, PartialEq)]
pub struct ExrTiling {
    pub width: u32,
    pub height: u32,
    pub x: u32,
    pub y: u32,
    pub full_width: u32,
    pub full_height: u32,
    pub channels: Vec<(String, bool)>,
    pub compression: String,
    pub tile: (u32, u32),
}

/// The C view of an `ExrTiling`, with the strings it points into.
struct CTiling {
    _names: Vec<CString>,
    channels: Vec<abi::icr_exr_channel>,
    compression: CString,
}

impl CTiling {
    fn new(tiling: &ExrTiling) -> CTiling {
        let names: Vec<CString> = tiling
            .channels
            .iter()
            .map(|(n, _)| CString::new(n.replace('\0', "")).expect("NULs removed"))
            .collect();
        let channels = names
            .iter()
            .zip(&tiling.channels)
            .map(|(n, (_, half))| abi::icr_exr_channel {
                name: n.as_ptr(),
                half: *half as i32,
            })
            .collect();
        CTiling {
            _names: names,
            channels,
            compression: CString::new(tiling.compression.replace('\0', "")).expect("NULs removed"),
        }
    }

    fn raw(&self, tiling: &ExrTiling) -> abi::icr_exr_tiling {
        abi::icr_exr_tiling {
            width: tiling.width,
            height: tiling.height,
            x: tiling.x as i32,
            y: tiling.y as i32,
            full_width: tiling.full_width,
            full_height: tiling.full_height,
            channels: self.channels.as_ptr(),
            channel_count: self.channels.len(),
            compression: self.compression.as_ptr(),
            tile_width: tiling.tile.0,
            tile_height: tiling.tile.1,
        }
    }
}

/// Encodes tiles of one layout, from any thread.
pub struct TileEncoder {
    raw: *mut abi::icr_tile_encoder,
}

// SAFETY: encoding reads the encoder's layout only; each call has its own pipeline and buffers
// (OpenEXR's core library encodes chunks of one part on many threads at once).
unsafe impl Send for TileEncoder {}
unsafe impl Sync for TileEncoder {}

/// Appends a chunk's bytes to the `Vec<u8>` behind `context`.
extern "C" fn append(context: *mut c_void, bytes: *const u8, len: usize) {
    // SAFETY: `context` is the `&mut Vec<u8>` icr_tile_encode was given, alive for the call;
    // `bytes` holds `len` bytes during it.
    let (out, bytes) = unsafe { (&mut *(context as *mut Vec<u8>), super::slice_or_empty(bytes, len)) };
    out.extend_from_slice(bytes);
}

impl TileEncoder {
    pub fn new(tiling: &ExrTiling) -> Result<TileEncoder, String> {
        let c = CTiling::new(tiling);
        let raw_tiling = c.raw(tiling);
        let mut err = vec![0 as c_char; ERR_LEN];
        // SAFETY: the layout and its strings are alive for the call; the encoder copies them.
        let raw = unsafe { abi::icr_tile_encoder_new(&raw_tiling, err.as_mut_ptr(), err.len()) };
        if raw.is_null() {
            return Err(buffer_message(&err));
        }
        Ok(TileEncoder { raw })
    }

    /// The encoded chunk of tile (`column`, `row`) of the grid, from its interleaved values (its
    /// rows cut at the window's edges).
    pub fn encode(&self, tile: (u32, u32), values: &[f32]) -> Result<Vec<u8>, String> {
        let mut out = Vec::new();
        let mut err = vec![0 as c_char; ERR_LEN];
        // SAFETY: `values` and `out` are alive for the call; `append` takes `out` back.
        let status = unsafe {
            abi::icr_tile_encode(
                self.raw,
                tile.0,
                tile.1,
                values.as_ptr(),
                values.len(),
                Some(append),
                &mut out as *mut Vec<u8> as *mut c_void,
                err.as_mut_ptr(),
                err.len(),
            )
        };
        if status != 0 {
            return Err(buffer_message(&err));
        }
        Ok(out)
    }
}

impl Drop for TileEncoder {
    fn drop(&mut self) {
        // SAFETY: made by icr_tile_encoder_new, freed once.
        unsafe { abi::icr_tile_encoder_free(self.raw) };
    }
}

/// A tiled EXR file written from encoded tiles, in any order and from any thread; `end` finishes
/// it, dropping it unfinished abandons it.
pub struct ChunkFile {
    raw: *mut abi::icr_chunk_file,
}

// SAFETY: the C++ file serialises its writes behind its own lock; end and close take it whole.
unsafe impl Send for ChunkFile {}
unsafe impl Sync for ChunkFile {}

impl ChunkFile {
    /// Opens (truncates) `path` for a file laid out as `tiling`, with `header_room` bytes kept
    /// in its header for the attributes known only at the end.
    pub fn open(path: &Path, tiling: &ExrTiling, header_room: usize) -> Result<ChunkFile, String> {
        let path = CString::new(path.as_os_str().as_encoded_bytes()).map_err(|_| "path contains a NUL byte")?;
        let c = CTiling::new(tiling);
        let raw_tiling = c.raw(tiling);
        let mut err = vec![0 as c_char; ERR_LEN];
        // SAFETY: every pointer refers to data alive for the call.
        let raw =
            unsafe { abi::icr_chunk_file_open(path.as_ptr(), &raw_tiling, header_room, err.as_mut_ptr(), err.len()) };
        if raw.is_null() {
            return Err(buffer_message(&err));
        }
        Ok(ChunkFile { raw })
    }

    /// Writes tile (`column`, `row`)'s encoded bytes.
    pub fn write(&self, tile: (u32, u32), bytes: &[u8]) -> Result<(), String> {
        let mut err = vec![0 as c_char; ERR_LEN];
        // SAFETY: `bytes` is alive for the call; the file is open until `end` or drop.
        let status = unsafe {
            abi::icr_chunk_file_write(
                self.raw,
                tile.0,
                tile.1,
                bytes.as_ptr(),
                bytes.len(),
                err.as_mut_ptr(),
                err.len(),
            )
        };
        if status != 0 {
            return Err(buffer_message(&err));
        }
        Ok(())
    }

    /// Finishes the file (every tile written).
    pub fn end(self) -> Result<(), String> {
        let raw = self.raw;
        std::mem::forget(self);
        let mut err = vec![0 as c_char; ERR_LEN];
        // SAFETY: the file is open; icr_chunk_file_end frees it, and Drop will not run.
        let status = unsafe { abi::icr_chunk_file_end(raw, err.as_mut_ptr(), err.len()) };
        if status != 0 {
            return Err(buffer_message(&err));
        }
        Ok(())
    }
}

impl Drop for ChunkFile {
    fn drop(&mut self) {
        // SAFETY: the file is open (end forgets self); closing frees it.
        unsafe { abi::icr_chunk_file_close(self.raw) };
    }
}

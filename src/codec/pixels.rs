//! Pixels and request results as bytes: how a finished tile travels to the master and how the
//! checkpoint journal keeps it, the one layout both read (a journal written by one process is
//! resumed by another, whatever carried the tiles).

use super::DecodeError;
use super::wire::{Put, Reader};
use crate::image::components::Components;
use crate::image::data::{DATA_VALUES, PixelData};
use crate::image::framebuffer::{Layer, PixelValue};
use crate::shading::request::RequestResult;

/// 4-byte values of one pixel on the wire (and in the checkpoint journal): four RGB layers,
/// records, the data layers (`PixelData::to_words`).
pub const PIXEL_FLOATS: usize = 13 + DATA_VALUES;

/// A pixel that is not finite and non-negative (or whose data layers are not what a renderer
/// makes) cannot come from a healthy renderer.
pub fn healthy(p: &PixelValue) -> bool {
    p.components
        .as_array()
        .iter()
        .flat_map(|v| v.to_array())
        .chain([p.records])
        .all(|v| v.is_finite() && v >= 0.0)
        && p.data.healthy()
}

/// Appends pixels as little-endian 4-byte values, PIXEL_FLOATS each.
pub fn encode_pixels(pixels: &[PixelValue], out: &mut Vec<u8>) {
    for p in pixels {
        p.components.as_array().into_iter().for_each(|v| out.put_vec3(v));
        out.put_f32(p.records);
        p.data.to_words().into_iter().for_each(|w| out.put_u32(w));
    }
}

/// The inverse of [`encode_pixels`] for whole pixels (the caller checks the length and values).
pub fn decode_pixels(body: &[u8]) -> Vec<PixelValue> {
    body.chunks_exact(PIXEL_FLOATS * 4)
        .map(|chunk| {
            let mut r = Reader::new(chunk, "pixel");
            let mut v = || r.vec3().expect("a whole pixel");
            let components = Components {
                emission: v(),
                direct: v(),
                specular: v(),
                indirect: v(),
            };
            let records = r.f32().expect("a whole pixel");
            let words: [u32; DATA_VALUES] = std::array::from_fn(|_| r.u32().expect("a whole pixel"));
            PixelValue {
                components,
                records,
                data: PixelData::from_words(&words),
            }
        })
        .collect()
}

/// Bytes of one request's result: pixel, layer, RGB.
pub const RESULT_BYTES: usize = 20;

/// Results as bytes, without a count (the journal's entries and the `Results` message alike).
pub fn put_results(out: &mut Vec<u8>, results: &[RequestResult]) {
    for result in results {
        out.put_u32(result.pixel);
        out.put_u32(result.layer.index() as u32);
        out.put_vec3(result.value);
    }
}

/// The inverse of [`put_results`]: `count` results.
pub fn take_results(r: &mut Reader<'_>, count: usize) -> Result<Vec<RequestResult>, DecodeError> {
    (0..count)
        .map(|_| {
            let (pixel, layer) = (r.u32()?, r.u32()?);
            let layer = Layer::ALL
                .get(layer as usize)
                .copied()
                .ok_or_else(|| r.error(format_args!("layer {layer}")))?;
            let value = r.vec3()?;
            if !value.is_finite() {
                return Err(r.error("a value is not finite"));
            }
            Ok(RequestResult { pixel, layer, value })
        })
        .collect()
}

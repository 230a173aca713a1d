//! The wire form of L_a requests (PR -> PA, PA -> PR when load balancing): a versioned batch
//! of fixed-size little-endian requests. Every request is checked on arrival: a pixel outside
//! the image, a non-finite number or a normal that is not unit length is refused and counted.

use crate::image::framebuffer::Layer;
use crate::shading::request::AmbientRequest;
use glam::Vec3;

const MAGIC: &[u8; 4] = b"ICRQ";
const VERSION: u32 = 1;
pub const REQUEST_BYTES: usize = 100;
/// A batch of no requests (the PRs' delivery markers): magic, version 1, count 0.
pub static EMPTY_BATCH: [u8; 12] = [b'I', b'C', b'R', b'Q', 1, 0, 0, 0, 0, 0, 0, 0];

fn put3(out: &mut Vec<u8>, v: Vec3) {
    for c in v.to_array() {
        out.extend_from_slice(&c.to_le_bytes());
    }
}

pub fn encode(requests: &[AmbientRequest]) -> Vec<u8> {
    let mut out = Vec::with_capacity(12 + requests.len() * REQUEST_BYTES);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&VERSION.to_le_bytes());
    out.extend_from_slice(&(requests.len() as u32).to_le_bytes());
    for r in requests {
        out.extend_from_slice(&r.pixel.to_le_bytes());
        out.extend_from_slice(&(r.layer.index() as u32).to_le_bytes());
        out.extend_from_slice(&r.specular_depth.to_le_bytes());
        for v in [
            r.position,
            r.geometric_normal,
            r.normal,
            r.facing_normal,
            r.coefficient,
            r.direction,
        ] {
            put3(&mut out, v);
        }
        out.extend_from_slice(&r.weight.to_le_bytes());
        out.extend_from_slice(&r.material.to_le_bytes());
        out.extend_from_slice(&r.stream.to_le_bytes());
    }
    out
}

/// Requests that passed the checks, and how many did not.
pub struct Decoded {
    pub requests: Vec<AmbientRequest>,
    pub rejected: usize,
}

fn unit(v: Vec3) -> bool {
    v.is_finite() && (v.length() - 1.0).abs() < 1e-3
}

pub fn decode(bytes: &[u8], pixels: u32) -> Result<Decoded, String> {
    if bytes.get(..4) != Some(MAGIC.as_slice()) {
        return Err("not a request batch".into());
    }
    let word = |o: usize| {
        bytes
            .get(o..o + 4)
            .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")))
    };
    if word(4) != Some(VERSION) {
        return Err(format!("request batch version {:?}, expected {VERSION}", word(4)));
    }
    let count = word(8).ok_or("request batch too short")? as usize;
    let body = &bytes[12..];
    if body.len() != count.saturating_mul(REQUEST_BYTES) {
        return Err(format!(
            "request batch says {count} requests but holds {} bytes",
            body.len()
        ));
    }
    let mut requests = Vec::with_capacity(count);
    let mut rejected = 0;
    for chunk in body.chunks_exact(REQUEST_BYTES) {
        let u = |o: usize| u32::from_le_bytes(chunk[o..o + 4].try_into().expect("4 bytes"));
        let f = |o: usize| f32::from_le_bytes(chunk[o..o + 4].try_into().expect("4 bytes"));
        let v = |o: usize| Vec3::new(f(o), f(o + 4), f(o + 8));
        let layer = match u(4) {
            2 => Some(Layer::Specular),
            3 => Some(Layer::Indirect),
            _ => None,
        };
        let r = AmbientRequest {
            pixel: u(0),
            layer: layer.unwrap_or(Layer::Indirect),
            specular_depth: u(8),
            position: v(12),
            geometric_normal: v(24),
            normal: v(36),
            facing_normal: v(48),
            coefficient: v(60),
            direction: v(72),
            weight: f(84),
            material: u(88),
            stream: 0,
        };
        let stream = u64::from_le_bytes(chunk[REQUEST_BYTES - 8..].try_into().expect("8 bytes"));
        let r = AmbientRequest { stream, ..r };
        let valid = layer.is_some()
            && r.pixel < pixels
            && r.position.is_finite()
            && unit(r.geometric_normal)
            && unit(r.normal)
            && unit(r.facing_normal)
            && r.coefficient.is_finite()
            && r.coefficient.min_element() >= 0.0
            && r.direction.is_finite()
            && r.weight.is_finite();
        if valid {
            requests.push(r);
        } else {
            rejected += 1;
        }
    }
    Ok(Decoded { requests, rejected })
}

/// A request with every field set, for tests of code that moves requests around.
#[cfg(test)]
pub(crate) fn sample_request(pixel: u32) -> AmbientRequest {
    AmbientRequest {
        pixel,
        layer: Layer::Specular,
        specular_depth: 2,
        position: Vec3::new(1.0, 2.0, 3.0),
        geometric_normal: Vec3::Y,
        normal: Vec3::Y,
        facing_normal: -Vec3::Y,
        coefficient: Vec3::new(0.1, 0.2, 0.3),
        weight: 0.5,
        direction: Vec3::X,
        material: 7,
        stream: 0xdead_beef_0000_0001,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use super::sample_request as request;

    #[test]
    fn the_empty_batch_is_an_encoded_batch_of_nothing() {
        assert_eq!(EMPTY_BATCH.as_slice(), encode(&[]).as_slice());
        let decoded = decode(&EMPTY_BATCH, 1).unwrap();
        assert_eq!((decoded.requests.len(), decoded.rejected), (0, 0));
    }

    #[test]
    fn round_trip_and_refusals() {
        let batch = vec![request(5), request(99)];
        let bytes = encode(&batch);
        assert_eq!(bytes.len(), 12 + 2 * REQUEST_BYTES);
        let back = decode(&bytes, 100).unwrap();
        assert_eq!(back.requests, batch);
        // Pixel 99 is outside a 50-pixel image: refused, counted.
        let back = decode(&bytes, 50).unwrap();
        assert_eq!((back.requests.len(), back.rejected), (1, 1));
        let mut bad = bytes.clone();
        bad[12 + 36] = 0xff; // the first request's shading normal becomes NaN
        bad[12 + 37] = 0xff;
        bad[12 + 38] = 0xff;
        bad[12 + 39] = 0xff;
        assert_eq!(decode(&bad, 100).unwrap().rejected, 1);
        assert!(decode(&bytes[..bytes.len() - 1], 100).is_err());
        assert!(decode(b"nope", 100).is_err());
    }
}

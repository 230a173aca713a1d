//! L_a requests on the wire (PR -> PA, and PA -> helper when load balancing): a count, then
//! fixed-size requests. Every request is checked on arrival: a non-finite number, a normal that
//! is not unit length or an unknown layer is refused and counted, not trusted. (Whether its
//! pixel lies in the image is for the receiver, which knows the image.)

use super::ProtocolError;
use super::wire::{Put, Reader};
use crate::image::framebuffer::Layer;
use crate::shading::request::AmbientRequest;
use glam::Vec3;

pub const REQUEST_BYTES: usize = 100;

/// Requests that passed the checks, and how many did not.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Requests {
    pub requests: Vec<AmbientRequest>,
    pub rejected: usize,
}

impl From<Vec<AmbientRequest>> for Requests {
    fn from(requests: Vec<AmbientRequest>) -> Self {
        Requests { requests, rejected: 0 }
    }
}

pub fn put(out: &mut Vec<u8>, requests: &[AmbientRequest]) {
    out.reserve(4 + requests.len() * REQUEST_BYTES);
    out.put_u32(requests.len() as u32);
    for r in requests {
        out.put_u32(r.pixel);
        out.put_u32(r.layer.index() as u32);
        out.put_u32(r.specular_depth);
        for v in [
            r.position,
            r.geometric_normal,
            r.normal,
            r.facing_normal,
            r.coefficient,
            r.direction,
        ] {
            out.put_vec3(v);
        }
        out.put_f32(r.weight);
        out.put_u32(r.material);
        out.put_u64(r.stream);
    }
}

fn unit(v: Vec3) -> bool {
    v.is_finite() && (v.length() - 1.0).abs() < 1e-3
}

pub fn take(reader: &mut Reader<'_>) -> Result<Requests, ProtocolError> {
    let count = reader.count(REQUEST_BYTES)?;
    let mut out = Requests::from(Vec::with_capacity(count));
    for _ in 0..count {
        let pixel = reader.u32()?;
        let layer = match reader.u32()? {
            2 => Some(Layer::Specular),
            3 => Some(Layer::Indirect),
            _ => None,
        };
        let r = AmbientRequest {
            pixel,
            layer: layer.unwrap_or(Layer::Indirect),
            specular_depth: reader.u32()?,
            position: reader.vec3()?,
            geometric_normal: reader.vec3()?,
            normal: reader.vec3()?,
            facing_normal: reader.vec3()?,
            coefficient: reader.vec3()?,
            direction: reader.vec3()?,
            weight: reader.f32()?,
            material: reader.u32()?,
            stream: reader.u64()?,
        };
        let valid = layer.is_some()
            && r.position.is_finite()
            && unit(r.geometric_normal)
            && unit(r.normal)
            && unit(r.facing_normal)
            && r.coefficient.is_finite()
            && r.coefficient.min_element() >= 0.0
            && r.direction.is_finite()
            && r.weight.is_finite();
        if valid {
            out.requests.push(r);
        } else {
            out.rejected += 1;
        }
    }
    Ok(out)
}

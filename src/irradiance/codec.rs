//! The compact, versioned binary form of a record, shared by the cache file and (later) the
//! messages between ranks: 128 bytes of little-endian fields and a 4-byte checksum. A record
//! that fails its checksum or its validation is refused, never trusted.

use super::record::{HORIZON_SECTORS, Record};
use glam::Vec3;

pub const CODEC_VERSION: u32 = 2;
pub const RECORD_BYTES: usize = 132;
const PAYLOAD_BYTES: usize = RECORD_BYTES - 4;
/// Levels beyond this cannot come from any sane -ab.
const MAX_LEVEL: u32 = 1024;

/// FNV-1a, 32 bits: cheap, and enough to tell a torn or corrupted record from a good one.
pub fn checksum(bytes: &[u8]) -> u32 {
    bytes
        .iter()
        .fold(0x811c_9dc5u32, |h, &b| (h ^ b as u32).wrapping_mul(0x0100_0193))
}

pub fn encode(record: &Record, out: &mut Vec<u8>) {
    let start = out.len();
    let mut put = |v: f32| out.extend_from_slice(&v.to_le_bytes());
    for v in [record.position, record.normal, record.u_axis] {
        v.to_array().into_iter().for_each(&mut put);
    }
    record.radii.into_iter().for_each(&mut put);
    put(record.harmonic_distance);
    put(record.weight);
    for v in [record.value, record.translation_gradient, record.rotation_gradient] {
        v.to_array().into_iter().for_each(&mut put);
    }
    record.horizon.into_iter().for_each(&mut put);
    put(record.headroom);
    out.extend_from_slice(&record.level.to_le_bytes());
    let sum = checksum(&out[start..]);
    out.extend_from_slice(&sum.to_le_bytes());
    debug_assert_eq!(out.len() - start, RECORD_BYTES);
}

/// Why a record was refused.
#[derive(Debug, PartialEq, Eq)]
pub enum DecodeError {
    Short,
    Checksum,
    Invalid(&'static str),
}

pub fn decode(bytes: &[u8]) -> Result<Record, DecodeError> {
    if bytes.len() < RECORD_BYTES {
        return Err(DecodeError::Short);
    }
    let (payload, sum) = bytes[..RECORD_BYTES].split_at(PAYLOAD_BYTES);
    if checksum(payload) != u32::from_le_bytes(sum.try_into().expect("4 bytes")) {
        return Err(DecodeError::Checksum);
    }
    let mut floats = payload
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")));
    let mut next = || floats.next().unwrap_or(f32::NAN);
    let mut vec3 = || Vec3::new(next(), next(), next());
    let position = vec3();
    let normal = vec3();
    let u_axis = vec3();
    let mut next = || floats.next().unwrap_or(f32::NAN);
    let radii = [next(), next()];
    let harmonic_distance = next();
    let weight = next();
    let mut vec3 = || {
        Vec3::new(
            floats.next().unwrap_or(f32::NAN),
            floats.next().unwrap_or(f32::NAN),
            floats.next().unwrap_or(f32::NAN),
        )
    };
    let value = vec3();
    let translation_gradient = vec3();
    let rotation_gradient = vec3();
    let mut horizon = [0.0f32; HORIZON_SECTORS];
    for h in &mut horizon {
        *h = floats.next().unwrap_or(f32::NAN);
    }
    let headroom = floats.next().unwrap_or(f32::NAN);
    let level = u32::from_le_bytes(payload[PAYLOAD_BYTES - 4..].try_into().expect("4 bytes"));
    let record = Record {
        position,
        normal,
        u_axis,
        radii,
        harmonic_distance,
        level,
        weight,
        value,
        translation_gradient,
        rotation_gradient,
        horizon,
        headroom,
        curvature: 0.0,
    };
    validate(&record)?;
    Ok(record)
}

/// What any record must satisfy before it is used: finite numbers, unit axes at right angles,
/// positive radii, a non-negative value.
pub fn validate(r: &Record) -> Result<(), DecodeError> {
    let finite = r.position.is_finite()
        && r.normal.is_finite()
        && r.u_axis.is_finite()
        && r.value.is_finite()
        && r.translation_gradient.is_finite()
        && r.rotation_gradient.is_finite()
        && r.weight.is_finite();
    if !finite {
        return Err(DecodeError::Invalid("non-finite field"));
    }
    if (r.normal.length() - 1.0).abs() > 1e-3
        || (r.u_axis.length() - 1.0).abs() > 1e-3
        || r.normal.dot(r.u_axis).abs() > 1e-3
    {
        return Err(DecodeError::Invalid("axes are not unit and perpendicular"));
    }
    if !r.radii.iter().all(|x| x.is_finite() && *x > 0.0) {
        return Err(DecodeError::Invalid("radius not positive"));
    }
    if r.harmonic_distance.is_nan() || r.harmonic_distance <= 0.0 {
        return Err(DecodeError::Invalid("harmonic distance not positive"));
    }
    if r.value.min_element() < 0.0 || r.weight < 0.0 || r.level > MAX_LEVEL {
        return Err(DecodeError::Invalid("negative value or weight, or absurd level"));
    }
    if r.horizon.iter().any(|h| h.is_nan() || *h < 0.0) {
        return Err(DecodeError::Invalid("bad horizon"));
    }
    if !(r.headroom.is_finite() && r.headroom > 0.0) {
        return Err(DecodeError::Invalid("headroom not positive"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::irradiance::record::tests::flat_record;

    #[test]
    fn round_trip_and_corruption() {
        let mut r = flat_record(0.7, 0.3);
        r.level = 2;
        r.horizon[3] = 0.25;
        r.translation_gradient = Vec3::new(0.1, -0.2, 0.0);
        let mut bytes = Vec::new();
        encode(&r, &mut bytes);
        assert_eq!(bytes.len(), RECORD_BYTES);
        assert_eq!(decode(&bytes).unwrap(), r);
        for i in 0..RECORD_BYTES {
            let mut bad = bytes.clone();
            bad[i] ^= 0x40;
            assert!(decode(&bad).is_err(), "flipped byte {i} accepted");
        }
        assert_eq!(decode(&bytes[..100]), Err(DecodeError::Short));
    }

    #[test]
    fn well_formed_but_invalid_records_are_refused() {
        let mut r = flat_record(1.0, 1.0);
        r.radii[0] = -1.0;
        let mut bytes = Vec::new();
        encode(&r, &mut bytes);
        assert!(matches!(decode(&bytes), Err(DecodeError::Invalid(_))));
        let mut r = flat_record(1.0, 1.0);
        r.value.x = f32::NAN;
        let mut bytes = Vec::new();
        encode(&r, &mut bytes);
        assert!(matches!(decode(&bytes), Err(DecodeError::Invalid(_))));
    }
}

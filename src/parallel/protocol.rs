//! What ranks say to each other: message tags and the byte layouts of work assignments, tile
//! results, record batches and statistics. Everything is little-endian, versioned where it
//! carries records, and checked on the way in: nothing a message says is trusted blindly, and
//! nothing in it is a pointer or a process-local id (tiles are indices into the same
//! deterministic tile list every rank computes; records are self-contained values).

use crate::image::components::Components;
use crate::image::framebuffer::PixelValue;
use crate::irradiance::codec::{self, RECORD_BYTES};
use crate::irradiance::record::Record;
use glam::Vec3;
use mpi::Tag;

/// Worker -> MC: "give me a tile", carrying the result of the previous one if any.
pub const TAG_WORK_REQUEST: Tag = 1;
/// Worker -> MC (centralised): new records; the MC answers with those the worker lacks.
pub const TAG_RECORDS_UP: Tag = 2;
/// Worker -> every other rank (broadcast): new records, or the end marker.
pub const TAG_RECORDS_BROADCAST: Tag = 3;
/// MC -> worker at start: the records of the cache file.
pub const TAG_INITIAL_RECORDS: Tag = 4;
/// Worker -> MC at the end: the rank's statistics (JSON).
pub const TAG_STATS: Tag = 5;
/// Worker -> MC at the end (no sharing, with -af): the rank's records, for the file.
pub const TAG_FINAL_RECORDS: Tag = 6;
/// MC -> worker before the prepass: the records every rank starts the prepass from.
pub const TAG_PREPASS_START: Tag = 7;
/// Worker -> MC, each prepass round: the records of the worker's share of the round's sites.
pub const TAG_PREPASS_UP: Tag = 8;
/// MC -> worker, each prepass round: the round's records from every worker, in site order.
pub const TAG_PREPASS_DOWN: Tag = 9;
/// MC -> worker thread t: a tile or "no more work" (tag base + t).
pub const TAG_WORK_BASE: Tag = 1000;
/// MC -> worker thread t: records answering TAG_RECORDS_UP (tag base + t).
pub const TAG_RECORDS_DOWN_BASE: Tag = 2000;

const BATCH_MAGIC: &[u8; 4] = b"ICRB";
const BATCH_VERSION: u32 = 1;
/// Flag of a batch: the sender will send no more records.
pub const BATCH_END: u32 = 1;

#[derive(Debug, PartialEq)]
pub struct ProtocolError(pub String);

fn u32_at(bytes: &[u8], offset: usize) -> Result<u32, ProtocolError> {
    bytes
        .get(offset..offset + 4)
        .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")))
        .ok_or_else(|| ProtocolError(format!("message too short ({} bytes)", bytes.len())))
}

/// A batch of records: magic, version, flags, count, then the records.
pub fn encode_batch(records: &[Record], flags: u32) -> Vec<u8> {
    let mut out = Vec::with_capacity(16 + records.len() * RECORD_BYTES);
    out.extend_from_slice(BATCH_MAGIC);
    out.extend_from_slice(&BATCH_VERSION.to_le_bytes());
    out.extend_from_slice(&flags.to_le_bytes());
    out.extend_from_slice(&(records.len() as u32).to_le_bytes());
    for r in records {
        codec::encode(r, &mut out);
    }
    out
}

/// A decoded batch: the records that passed validation, how many did not, and the flags.
#[derive(Debug)]
pub struct Batch {
    pub records: Vec<Record>,
    pub rejected: usize,
    pub flags: u32,
}

/// A prepass round's records: a count, each record's site index, then the records as a batch.
pub fn encode_round(records: &[(u32, Record)]) -> Vec<u8> {
    let mut out = Vec::with_capacity(4 + records.len() * (4 + RECORD_BYTES) + 16);
    out.extend_from_slice(&(records.len() as u32).to_le_bytes());
    for (index, _) in records {
        out.extend_from_slice(&index.to_le_bytes());
    }
    let batch: Vec<Record> = records.iter().map(|(_, r)| r.clone()).collect();
    out.extend(encode_batch(&batch, 0));
    out
}

/// A prepass round's records. Every rank must insert exactly the same records, so a record
/// that fails validation fails the whole message.
pub fn decode_round(bytes: &[u8]) -> Result<Vec<(u32, Record)>, ProtocolError> {
    let count = u32_at(bytes, 0)? as usize;
    let indices_end = count
        .checked_mul(4)
        .and_then(|n| n.checked_add(4))
        .filter(|&end| end <= bytes.len())
        .ok_or_else(|| {
            ProtocolError(format!(
                "prepass round says {count} records but holds {} bytes",
                bytes.len()
            ))
        })?;
    let indices: Vec<u32> = (0..count).map(|i| u32_at(bytes, 4 + 4 * i)).collect::<Result<_, _>>()?;
    let batch = decode_batch(&bytes[indices_end..])?;
    if batch.rejected > 0 || batch.records.len() != count {
        return Err(ProtocolError(format!(
            "prepass round: {} of {count} records invalid",
            count - batch.records.len().min(count)
        )));
    }
    Ok(indices.into_iter().zip(batch.records).collect())
}

pub fn decode_batch(bytes: &[u8]) -> Result<Batch, ProtocolError> {
    if bytes.get(..4) != Some(BATCH_MAGIC.as_slice()) {
        return Err(ProtocolError("not a record batch".into()));
    }
    let version = u32_at(bytes, 4)?;
    if version != BATCH_VERSION {
        return Err(ProtocolError(format!(
            "record batch version {version}, expected {BATCH_VERSION}"
        )));
    }
    let flags = u32_at(bytes, 8)?;
    let count = u32_at(bytes, 12)? as usize;
    let body = &bytes[16..];
    if body.len() != count.saturating_mul(RECORD_BYTES) {
        return Err(ProtocolError(format!(
            "record batch says {count} records but holds {} bytes",
            body.len()
        )));
    }
    let mut records = Vec::with_capacity(count);
    let mut rejected = 0;
    for chunk in body.chunks_exact(RECORD_BYTES) {
        match codec::decode(chunk) {
            Ok(r) => records.push(r),
            Err(_) => rejected += 1,
        }
    }
    Ok(Batch {
        records,
        rejected,
        flags,
    })
}

/// Worker -> MC work request: the asking thread and, after the first, the finished tile.
pub fn encode_work_request(thread: u32, finished: Option<(u32, &[PixelValue])>) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend_from_slice(&thread.to_le_bytes());
    if let Some((tile, pixels)) = finished {
        out.extend_from_slice(&tile.to_le_bytes());
        out.extend_from_slice(&(pixels.len() as u32).to_le_bytes());
        encode_pixels(pixels, &mut out);
    }
    out
}

/// Floats of one pixel on the wire (and in the checkpoint journal): four RGB layers, records.
pub const PIXEL_FLOATS: usize = 13;

/// Appends pixels as little-endian floats, PIXEL_FLOATS each.
pub fn encode_pixels(pixels: &[PixelValue], out: &mut Vec<u8>) {
    for p in pixels {
        for v in p.components.as_array() {
            for c in v.to_array() {
                out.extend_from_slice(&c.to_le_bytes());
            }
        }
        out.extend_from_slice(&p.records.to_le_bytes());
    }
}

/// The inverse of [`encode_pixels`] for a body of whole pixels (the caller checks the length);
/// the values are not judged here.
pub fn decode_pixels(body: &[u8]) -> Vec<PixelValue> {
    body.chunks_exact(PIXEL_FLOATS * 4)
        .map(|c| {
            let f = |i: usize| f32::from_le_bytes(c[4 * i..4 * i + 4].try_into().expect("4 bytes"));
            let v = |i: usize| Vec3::new(f(3 * i), f(3 * i + 1), f(3 * i + 2));
            PixelValue {
                components: Components {
                    emission: v(0),
                    direct: v(1),
                    specular: v(2),
                    indirect: v(3),
                },
                records: f(12),
            }
        })
        .collect()
}

/// A decoded work request: the thread, and the finished tile with its pixels, if any.
pub type WorkRequest = (u32, Option<(u32, Vec<PixelValue>)>);

pub fn decode_work_request(bytes: &[u8]) -> Result<WorkRequest, ProtocolError> {
    let thread = u32_at(bytes, 0)?;
    if bytes.len() == 4 {
        return Ok((thread, None));
    }
    let tile = u32_at(bytes, 4)?;
    let count = u32_at(bytes, 8)? as usize;
    let body = &bytes[12..];
    if body.len() != count.saturating_mul(PIXEL_FLOATS * 4) {
        return Err(ProtocolError(format!(
            "tile result says {count} pixels but holds {} bytes",
            body.len()
        )));
    }
    let pixels = decode_pixels(body);
    // A pixel that is not finite and non-negative cannot come from a healthy renderer.
    let healthy = |p: &PixelValue| {
        p.components
            .as_array()
            .iter()
            .flat_map(|v| v.to_array())
            .chain([p.records])
            .all(|v| v.is_finite() && v >= 0.0)
    };
    if !pixels.iter().all(healthy) {
        return Err(ProtocolError("tile result holds a negative or non-finite value".into()));
    }
    Ok((thread, Some((tile, pixels))))
}

/// MC -> worker: a tile index, or None for "no more work".
pub fn encode_work(tile: Option<u32>) -> Vec<u8> {
    match tile {
        Some(t) => [&[1u8][..], &t.to_le_bytes()].concat(),
        None => vec![0u8],
    }
}

pub fn decode_work(bytes: &[u8]) -> Result<Option<u32>, ProtocolError> {
    match bytes.first() {
        Some(0) if bytes.len() == 1 => Ok(None),
        Some(1) if bytes.len() == 5 => Ok(Some(u32_at(bytes, 1)?)),
        _ => Err(ProtocolError("malformed work message".into())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::irradiance::record::tests::flat_record;

    #[test]
    fn prepass_rounds_round_trip_and_refuse_damage() {
        let records: Vec<(u32, Record)> = (0..5u32)
            .map(|i| {
                let mut r = flat_record(0.1 + i as f32, 0.5);
                r.position = Vec3::new(i as f32, 2.0, -1.0);
                (i * 7 + 3, r)
            })
            .collect();
        let bytes = encode_round(&records);
        assert_eq!(decode_round(&bytes).unwrap(), records);
        assert_eq!(decode_round(&encode_round(&[])).unwrap(), Vec::new());
        // Cut anywhere: refused, never a shorter list.
        for cut in [0, 3, 4, 10, bytes.len() - 1] {
            assert!(decode_round(&bytes[..cut]).is_err(), "cut at {cut}");
        }
        // A count larger than the message.
        let mut lying = bytes.clone();
        lying[..4].copy_from_slice(&1000u32.to_le_bytes());
        assert!(decode_round(&lying).is_err());
        // A record that fails validation (a non-finite value) fails the round.
        let mut bad = records.clone();
        bad[2].1.value = Vec3::splat(f32::NAN);
        assert!(decode_round(&encode_round(&bad)).is_err());
    }

    #[test]
    fn work_messages_must_have_their_exact_length() {
        assert_eq!(decode_work(&[0]).unwrap(), None);
        assert_eq!(decode_work(&[1, 7, 0, 0, 0]).unwrap(), Some(7));
        assert!(decode_work(&[1, 7, 0, 0, 0, 9]).is_err());
        assert!(decode_work(&[1, 7, 0]).is_err());
        assert!(decode_work(&[0, 0]).is_err());
    }

    #[test]
    fn batches_round_trip_and_bad_records_are_dropped_and_counted() {
        let records = vec![flat_record(1.0, 0.5), flat_record(2.0, 0.25)];
        let mut bytes = encode_batch(&records, BATCH_END);
        let batch = decode_batch(&bytes).unwrap();
        assert_eq!(batch.records, records);
        assert_eq!(batch.flags, BATCH_END);
        // Corrupt the second record: it is refused, the first is kept.
        bytes[16 + RECORD_BYTES + 5] ^= 0xff;
        let batch = decode_batch(&bytes).unwrap();
        assert_eq!((batch.records.len(), batch.rejected), (1, 1));
        // Wrong counts and versions are refused whole.
        assert!(decode_batch(&bytes[..bytes.len() - 1]).is_err());
        let mut other = bytes.clone();
        other[4] = 9;
        assert!(decode_batch(&other).is_err());
        assert!(decode_batch(b"junk").is_err());
    }

    #[test]
    fn work_messages_round_trip() {
        let pixels = vec![PixelValue {
            components: Components {
                emission: Vec3::ONE,
                direct: Vec3::X,
                specular: Vec3::Y,
                indirect: Vec3::Z,
            },
            records: 2.0,
        }];
        let bytes = encode_work_request(3, Some((7, &pixels)));
        let (thread, finished) = decode_work_request(&bytes).unwrap();
        assert_eq!(thread, 3);
        let (tile, back) = finished.unwrap();
        assert_eq!(tile, 7);
        assert_eq!(back[0].components, pixels[0].components);
        let (thread, finished) = decode_work_request(&encode_work_request(1, None)).unwrap();
        assert_eq!(thread, 1);
        assert!(finished.is_none());
        assert_eq!(decode_work(&encode_work(Some(42))).unwrap(), Some(42));
        assert_eq!(decode_work(&encode_work(None)).unwrap(), None);
        assert!(decode_work(&[2]).is_err());
        let mut bad = bytes.clone();
        let n = bad.len();
        bad[n - 8..n - 4].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(decode_work_request(&bad).is_err());
    }
}

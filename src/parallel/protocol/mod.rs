//! What ranks say to each other, every mode's messages in one type. A message travels as one
//! MPI message whose tag names its kind (and, for replies to one rendering thread, the thread);
//! its bytes start with the protocol's version and are little-endian after that. Nothing a
//! message says is trusted blindly: a message is read exactly (too short, too long or a count
//! that does not fit is an error), records and requests are checked one by one (bad ones are
//! dropped and counted), and nothing in it is a pointer or a process-local id (tiles are
//! indices into the tile list every rank computes alike; records are self-contained values).

pub use crate::codec::wire;

use crate::codec::pixels::{
    PIXEL_FLOATS, RESULT_BYTES, decode_pixels, encode_pixels, healthy, put_results, take_results,
};
use crate::image::framebuffer::{Layer, PixelValue};
use crate::image::layered_exr::EncodedTile;
use crate::image::preview::LogLuminance;
use crate::irradiance::codec::{self, RECORD_BYTES};
use crate::irradiance::last_bounce::{GridSample, Received};
use crate::irradiance::record::Record;
use crate::prepass::{GridRows, Kept, PixelRows, RoundLog};
use crate::shading::request::{AmbientRequest, RequestResult};
use crate::stats::RankReport;
use glam::Vec3;
use mpi::Tag;
use std::sync::OnceLock;
use wire::{Put, Reader};

/// The first byte of every message; a rank of another build is refused, not misread.
pub const PROTOCOL_VERSION: u8 = 7;

/// A last bounce's grid sample on the wire: four vectors (position, normal, direct, indirect).
const GRID_SAMPLE_BYTES: usize = 4 * 12;

/// Replies to one rendering thread carry the thread in their tag: base + thread.
const WORK_BASE: Tag = 1000;
const RECORDS_DOWN_BASE: Tag = 2000;
/// The most rendering threads a rank may have (their reply tags must not overlap).
pub const MAX_THREADS: u32 = 999;

/// Declares `Kind`, each the `Message` variant of its name, with its MPI tag and name in errors.
macro_rules! kinds {
    ($($(#[$doc:meta])* $kind:ident = $tag:expr, $name:literal;)*) => {
        /// Every message's kind and its MPI tag, in one place.
        #[derive(Clone, Copy, Debug, PartialEq, Eq)]
        pub enum Kind {
            $($(#[$doc])* $kind = $tag,)*
        }

        impl Kind {
            const ALL: &[Kind] = &[$(Kind::$kind),*];

            fn name(self) -> &'static str {
                match self {
                    $(Kind::$kind => $name,)*
                }
            }
        }

        impl Message {
            pub fn kind(&self) -> Kind {
                match self {
                    $(Message::$kind { .. } => Kind::$kind,)*
                }
            }
        }
    };
}

kinds! {
    Heartbeat = 1, "heartbeat";
    InitialRecords = 2, "initial records";
    PrepassStart = 3, "prepass start";
    PrepassRound = 4, "prepass round";
    WorkRequest = 5, "work request";
    RecordsUp = 6, "records up";
    RecordsBroadcast = 7, "record broadcast";
    FinalRecords = 8, "final records";
    Stats = 9, "statistics";
    Requests = 10, "request buffer";
    Forwarded = 11, "forwarded requests";
    Idle = 12, "idle report";
    PaStatus = 13, "PA status";
    ForwardOrder = 14, "forward order";
    Finish = 15, "finish";
    Results = 17, "results";
    PrepassGrid = 18, "prepass grid rows";
    PrepassPixels = 19, "prepass pixel rows";
    PrepassSites = 20, "prepass sites";
    TileClaims = 21, "tile claims";
    PrepassKept = 22, "prepass records kept";
    /// Tags WORK_BASE + thread.
    Work = WORK_BASE as isize, "work";
    /// Tags RECORDS_DOWN_BASE + thread.
    RecordsDown = RECORDS_DOWN_BASE as isize, "records down";
}

impl Kind {
    /// The tag of this kind (for the per-thread kinds, thread 0's).
    pub fn tag(self) -> Tag {
        self as Tag
    }

    /// The tag of a reply to rendering thread `thread`.
    pub fn for_thread(self, thread: u32) -> Tag {
        debug_assert!(matches!(self, Kind::Work | Kind::RecordsDown));
        self.tag() + thread as Tag
    }

    /// The kind a tag names, and the thread for the per-thread kinds.
    pub fn of_tag(tag: Tag) -> Option<(Kind, u32)> {
        Kind::ALL.iter().find_map(|&kind| {
            let thread = tag - kind.tag();
            let per_thread =
                matches!(kind, Kind::Work | Kind::RecordsDown) && (0..=MAX_THREADS as Tag).contains(&thread);
            (thread == 0 || per_thread).then_some((kind, thread as u32))
        })
    }
}

/// Records that passed validation, and how many did not.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Records {
    pub records: Vec<Record>,
    pub rejected: usize,
}

impl From<Vec<Record>> for Records {
    fn from(records: Vec<Record>) -> Self {
        Records { records, rejected: 0 }
    }
}

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

/// A tile a worker finished, with the requests it sent for it (component mode's PRs; else 0).
#[derive(Clone, Debug, PartialEq)]
pub struct FinishedTile {
    pub tile: u32,
    pub requests: u32,
    pub pixels: TilePixels,
}

/// A finished tile's pixels: their values, or, where the master streams the file, the file's
/// chunks made by the worker (`image::layered_exr::TileChunks`), about a fifth of the bytes
/// and nothing for the master to compress.
#[derive(Clone, Debug, PartialEq)]
pub enum TilePixels {
    Values(Vec<PixelValue>),
    Encoded(EncodedTile),
}

impl TilePixels {
    /// The bytes they take in a message.
    pub fn wire_bytes(&self) -> usize {
        match self {
            TilePixels::Values(pixels) => 4 + pixels.len() * PIXEL_FLOATS * 4,
            TilePixels::Encoded(tile) => {
                let chunks: usize = tile.chunks.iter().map(|(_, bytes)| 12 + bytes.len()).sum();
                4 + chunks + 4 + 4 * tile.preview.len() + 24
            }
        }
    }
}

/// Largest chunk a tile of the file may take: a 4096x4096 tile of 4096 float channels is the
/// most the encoder makes (cpp/exr_chunks.cpp), but a message is checked before any of that.
const MAX_CHUNK_BYTES: usize = i32::MAX as usize;

fn put_encoded(out: &mut Vec<u8>, tile: &EncodedTile) {
    out.put_u32(tile.chunks.len() as u32);
    for ((x, y), bytes) in &tile.chunks {
        out.put_u32(*x);
        out.put_u32(*y);
        out.put_u32(bytes.len() as u32);
        out.extend_from_slice(bytes);
    }
    out.put_u32(tile.preview.len() as u32);
    tile.preview.iter().for_each(|p| out.extend_from_slice(p));
    let (sum, lit) = tile.log.parts();
    out.extend_from_slice(&sum.to_le_bytes());
    out.put_u64(lit);
}

fn take_encoded(r: &mut Reader<'_>) -> Result<EncodedTile, ProtocolError> {
    let count = r.count(12)?;
    let mut chunks = Vec::with_capacity(count);
    for _ in 0..count {
        let (x, y, len) = (r.u32()?, r.u32()?, r.u32()? as usize);
        if len == 0 || len > MAX_CHUNK_BYTES {
            return Err(r.error(format!("a chunk of {len} bytes")));
        }
        chunks.push(((x, y), r.take(len)?.to_vec()));
    }
    let pixels = r.count(4)?;
    let preview = r
        .take(pixels * 4)?
        .chunks_exact(4)
        .map(|p| [p[0], p[1], p[2], p[3]])
        .collect();
    let sum = i128::from_le_bytes(r.take(16)?.try_into().expect("16 bytes"));
    let log = LogLuminance::from_parts(sum, r.u64()?);
    Ok(EncodedTile { chunks, preview, log })
}

/// Every message of every mode. MC: the master (rank 0); worker: any other rank; PR and PA:
/// component mode's workers (paper, section 5).
#[derive(Clone, Debug, PartialEq)]
pub enum Message {
    /// Either way, every few seconds while a job runs: this rank is alive.
    Heartbeat,
    /// MC -> worker at the start: the records of the cache file.
    InitialRecords(Records),
    /// MC -> every rank before the prepass: the records every rank starts the prepass from.
    PrepassStart(Records),
    /// Every rank -> every rank (a collective): the records of its share of a prepass round's
    /// sites. Every rank must insert exactly the same records, so one invalid record fails the
    /// whole message.
    PrepassRound(Vec<(u32, Record)>),
    /// Worker -> every worker (a collective): its rows of the last bounce's grid samples.
    PrepassGrid(GridRows),
    /// Every rank -> every rank (a collective): its rows of a prepass pixel map.
    PrepassPixels(PixelRows),
    /// Every rank -> every rank (a collective): the sites of its share of a prepass round
    /// that lack records (indices into the round's sites).
    PrepassSites(Vec<u32>),
    /// The first worker -> MC: a prepass round as the workers made it (the MC takes no part in
    /// the rounds): its log, and its records in order, each with its site's pixel index
    /// (`y * width + x`), which the MC keeps (the cache file) as every worker does; or the end
    /// of the rounds. One kind for both, so that the end can never be taken before a round
    /// sent ahead of it.
    PrepassKept(Kept),
    /// Every rank -> every rank (a collective, after the prepass): the tiles it has begun
    /// (traced ahead: `parallel::ahead`), which the master hands it first and nobody else.
    TileClaims(Vec<u32>),
    /// Worker -> MC: give me a tile, with the tile finished before, if any.
    WorkRequest {
        thread: u32,
        finished: Option<FinishedTile>,
    },
    /// MC -> the asking thread: a tile or none, and (component mode) the records it lacks.
    Work {
        thread: u32,
        tile: Option<u32>,
        records: Records,
    },
    /// Worker -> MC (centralised mode, helping PRs): new records; answered by `RecordsDown`.
    RecordsUp { thread: u32, records: Records },
    /// MC -> worker thread: the records it lacks (also the answer to a PA's status).
    RecordsDown { thread: u32, records: Records },
    /// Worker -> every other rank (broadcast mode): new records; `last` marks the sender's last.
    RecordsBroadcast { records: Records, last: bool },
    /// Worker -> MC at the end (no sharing, with -af): the rank's records, for the file.
    FinalRecords(Records),
    /// Worker -> MC at the end: the rank's statistics.
    Stats(Box<RankReport>),
    /// PR -> PA: a request buffer.
    Requests(Requests),
    /// PA -> helper (an idle PR, or a PA that ran dry): a share of the PA's queue.
    Forwarded(Requests),
    /// PR -> MC: no tile left; requests sent and computed as a helper so far, new records.
    Idle { sent: u64, helped: u64, records: Records },
    /// PA -> MC: queue length, requests computed, new records; answered by `RecordsDown`.
    PaStatus { queue: u64, done: u64, records: Records },
    /// MC -> PA: hand `count` queued requests to rank `to` (a PA when `to_pa`).
    ForwardOrder { to: u32, count: u32, to_pa: bool },
    /// MC -> every worker (component mode): every request is computed; send your statistics.
    Finish,
    /// PA or helper -> MC (component mode): indirect light computed for requests, which the
    /// master adds to their pixels (and journals, with --checkpoint).
    Results(Vec<RequestResult>),
}

/// A message that cannot be read (the codec's error, named for the protocol).
pub use crate::codec::DecodeError as ProtocolError;

impl Message {
    pub fn tag(&self) -> Tag {
        match self {
            Message::Work { thread, .. } | Message::RecordsDown { thread, .. } => self.kind().for_thread(*thread),
            _ => self.kind().tag(),
        }
    }

    pub fn encode(&self) -> Vec<u8> {
        let mut out = vec![PROTOCOL_VERSION];
        match self {
            Message::Heartbeat | Message::Finish => {}
            Message::InitialRecords(r) | Message::PrepassStart(r) | Message::FinalRecords(r) => {
                put_records(&mut out, r)
            }
            Message::Work { tile, records, .. } => {
                out.put_u8(tile.is_some() as u8);
                out.put_u32(tile.unwrap_or(0));
                put_records(&mut out, records);
            }
            Message::RecordsDown { records, .. } => put_records(&mut out, records),
            Message::PrepassRound(round) => put_indexed_records(&mut out, round),
            Message::PrepassKept(Kept::Round(log, records)) => {
                out.put_u8(0);
                out.put_u64(log.sites);
                out.put_u64(log.records);
                for seconds in [log.compute_s, log.pool_s, log.seconds] {
                    out.put_u64(seconds.to_bits());
                }
                out.put_u64(log.bytes);
                put_indexed_records(&mut out, records);
            }
            Message::PrepassKept(Kept::End(pixels_sampled)) => {
                out.put_u8(1);
                out.put_u64(*pixels_sampled);
            }
            Message::PrepassGrid(rows) => {
                out.put_u32(rows.len() as u32);
                for (y, samples) in rows {
                    out.put_u32(*y);
                    out.put_u32(samples.len() as u32);
                    for s in samples {
                        [s.position, s.normal, s.received.direct, s.received.indirect]
                            .into_iter()
                            .for_each(|v| out.put_vec3(v));
                    }
                }
            }
            Message::PrepassSites(sites) | Message::TileClaims(sites) => {
                out.put_u32(sites.len() as u32);
                sites.iter().for_each(|&s| out.put_u32(s));
            }
            Message::PrepassPixels(rows) => {
                out.put_u32(rows.len() as u32);
                for (y, flags) in rows {
                    out.put_u32(*y);
                    out.put_u32(flags.len() as u32);
                    // Eight flags a byte, lowest bit first: a 4K frame's map is 1 MB, not 8.
                    for chunk in flags.chunks(8) {
                        out.put_u8(chunk.iter().enumerate().fold(0, |b, (i, &f)| b | (f as u8) << i));
                    }
                }
            }
            Message::WorkRequest { thread, finished } => {
                out.put_u32(*thread);
                out.put_u8(finished.is_some() as u8);
                if let Some(f) = finished {
                    out.put_u32(f.tile);
                    out.put_u32(f.requests);
                    match &f.pixels {
                        TilePixels::Values(pixels) => {
                            out.put_u8(0);
                            out.put_u32(pixels.len() as u32);
                            encode_pixels(pixels, &mut out);
                        }
                        TilePixels::Encoded(tile) => {
                            out.put_u8(1);
                            put_encoded(&mut out, tile);
                        }
                    }
                }
            }
            Message::RecordsUp { thread, records } => {
                out.put_u32(*thread);
                put_records(&mut out, records);
            }
            Message::RecordsBroadcast { records, last } => {
                out.put_u8(*last as u8);
                put_records(&mut out, records);
            }
            Message::Stats(report) => out.extend(serde_json::to_vec(report.as_ref()).unwrap_or_default()),
            Message::Requests(r) | Message::Forwarded(r) => put_requests(&mut out, &r.requests),
            Message::Idle { sent, helped, records } => {
                [*sent, *helped].into_iter().for_each(|v| out.put_u64(v));
                put_records(&mut out, records);
            }
            Message::PaStatus { queue, done, records } => {
                [*queue, *done].into_iter().for_each(|v| out.put_u64(v));
                put_records(&mut out, records);
            }
            Message::ForwardOrder { to, count, to_pa } => {
                out.put_u32(*to);
                out.put_u32(*count);
                out.put_u8(*to_pa as u8);
            }
            Message::Results(results) => {
                out.put_u32(results.len() as u32);
                put_results(&mut out, results);
            }
        }
        out
    }

    pub fn decode(tag: Tag, bytes: &[u8]) -> Result<Message, ProtocolError> {
        let (kind, thread) = Kind::of_tag(tag).ok_or_else(|| ProtocolError(format!("unknown message tag {tag}")))?;
        let mut r = Reader::new(bytes, kind.name());
        let version = r.u8()?;
        if version != PROTOCOL_VERSION {
            return Err(r.error(format_args!(
                "protocol version {version}, this build speaks {PROTOCOL_VERSION} (mixed builds?)"
            )));
        }
        let message = match kind {
            Kind::Heartbeat => Message::Heartbeat,
            Kind::Finish => Message::Finish,
            Kind::InitialRecords => Message::InitialRecords(take_records(&mut r)?),
            Kind::PrepassStart => Message::PrepassStart(take_records(&mut r)?),
            Kind::FinalRecords => Message::FinalRecords(take_records(&mut r)?),
            Kind::PrepassRound => Message::PrepassRound(take_indexed_records(&mut r)?),
            // The first byte tells an end (1) from a round (0).
            Kind::PrepassKept if r.u8()? == 1 => Message::PrepassKept(Kept::End(r.u64()?)),
            Kind::PrepassKept => {
                let (sites, records) = (r.u64()?, r.u64()?);
                let mut seconds = [0.0; 3];
                for s in &mut seconds {
                    *s = f64::from_bits(r.u64()?);
                }
                let log = RoundLog {
                    sites,
                    records,
                    compute_s: seconds[0],
                    pool_s: seconds[1],
                    seconds: seconds[2],
                    bytes: r.u64()?,
                };
                Message::PrepassKept(Kept::Round(log, take_indexed_records(&mut r)?))
            }
            Kind::PrepassGrid => {
                let count = r.count(8)?;
                let mut rows = Vec::with_capacity(count);
                for _ in 0..count {
                    let (y, samples) = (r.u32()?, r.count(GRID_SAMPLE_BYTES)?);
                    let mut row = Vec::with_capacity(samples);
                    for _ in 0..samples {
                        let (position, normal) = (r.vec3()?, r.vec3()?);
                        let received = Received {
                            direct: r.vec3()?,
                            indirect: r.vec3()?,
                        };
                        row.push(GridSample {
                            position,
                            normal,
                            received,
                        });
                    }
                    rows.push((y, row));
                }
                Message::PrepassGrid(rows)
            }
            Kind::PrepassSites => {
                let count = r.count(4)?;
                Message::PrepassSites((0..count).map(|_| r.u32()).collect::<Result<_, _>>()?)
            }
            Kind::TileClaims => {
                let count = r.count(4)?;
                Message::TileClaims((0..count).map(|_| r.u32()).collect::<Result<_, _>>()?)
            }
            Kind::PrepassPixels => {
                let count = r.count(8)?;
                let mut rows = Vec::with_capacity(count);
                for _ in 0..count {
                    let (y, pixels) = (r.u32()?, r.u32()? as usize);
                    let bytes = r.take(pixels.div_ceil(8))?;
                    let flags = (0..pixels).map(|i| bytes[i / 8] >> (i % 8) & 1 == 1).collect();
                    rows.push((y, flags));
                }
                Message::PrepassPixels(rows)
            }
            Kind::WorkRequest => {
                let thread = r.u32()?;
                let finished = if r.flag()? {
                    let (tile, requests) = (r.u32()?, r.u32()?);
                    let pixels = if r.flag()? {
                        TilePixels::Encoded(take_encoded(&mut r)?)
                    } else {
                        let count = r.count(PIXEL_FLOATS * 4)?;
                        let pixels = decode_pixels(r.take(count * PIXEL_FLOATS * 4)?);
                        if !pixels.iter().all(healthy) {
                            return Err(r.error("a pixel is negative or not finite"));
                        }
                        TilePixels::Values(pixels)
                    };
                    Some(FinishedTile { tile, requests, pixels })
                } else {
                    None
                };
                Message::WorkRequest { thread, finished }
            }
            Kind::Work => {
                let (tile, records) = (r.flag()?.then_some(r.u32()?), take_records(&mut r)?);
                Message::Work { thread, tile, records }
            }
            Kind::RecordsUp => Message::RecordsUp {
                thread: r.u32()?,
                records: take_records(&mut r)?,
            },
            Kind::RecordsDown => Message::RecordsDown {
                thread,
                records: take_records(&mut r)?,
            },
            Kind::RecordsBroadcast => Message::RecordsBroadcast {
                last: r.flag()?,
                records: take_records(&mut r)?,
            },
            Kind::Stats => {
                let report = serde_json::from_slice(r.rest()).map_err(|e| ProtocolError(format!("statistics: {e}")))?;
                Message::Stats(Box::new(report))
            }
            Kind::Requests => Message::Requests(take_requests(&mut r)?),
            Kind::Forwarded => Message::Forwarded(take_requests(&mut r)?),
            Kind::Idle => {
                let (sent, helped, records) = (r.u64()?, r.u64()?, take_records(&mut r)?);
                Message::Idle { sent, helped, records }
            }
            Kind::PaStatus => {
                let (queue, done, records) = (r.u64()?, r.u64()?, take_records(&mut r)?);
                Message::PaStatus { queue, done, records }
            }
            Kind::ForwardOrder => {
                let (to, count, to_pa) = (r.u32()?, r.u32()?, r.flag()?);
                Message::ForwardOrder { to, count, to_pa }
            }
            Kind::Results => {
                let count = r.count(RESULT_BYTES)?;
                Message::Results(take_results(&mut r, count)?)
            }
        };
        r.finish()?;
        Ok(message)
    }
}

/// The bytes of an empty request buffer, for the PRs' delivery markers (a synchronous send
/// needs bytes that outlive it).
pub fn empty_requests() -> &'static [u8] {
    static EMPTY: OnceLock<Vec<u8>> = OnceLock::new();
    EMPTY.get_or_init(|| Message::Requests(Requests::default()).encode())
}

fn put_records(out: &mut Vec<u8>, records: &Records) {
    out.reserve(4 + records.records.len() * RECORD_BYTES);
    out.put_u32(records.records.len() as u32);
    records.records.iter().for_each(|record| codec::encode(record, out));
}

/// Records each with a number (a site's index, or its pixel): every one must be valid (ranks
/// must keep the same records), so one that is not fails the message.
fn put_indexed_records(out: &mut Vec<u8>, records: &[(u32, Record)]) {
    out.reserve(4 + records.len() * (4 + RECORD_BYTES));
    out.put_u32(records.len() as u32);
    for (index, record) in records {
        out.put_u32(*index);
        codec::encode(record, out);
    }
}

fn take_indexed_records(r: &mut Reader<'_>) -> Result<Vec<(u32, Record)>, ProtocolError> {
    let count = r.count(4 + RECORD_BYTES)?;
    let mut records = Vec::with_capacity(count);
    for _ in 0..count {
        let index = r.u32()?;
        let record = codec::decode(r.take(RECORD_BYTES)?)
            .map_err(|e| r.error(format_args!("record for site {index} refused: {e:?}")))?;
        records.push((index, record));
    }
    Ok(records)
}

fn take_records(r: &mut Reader<'_>) -> Result<Records, ProtocolError> {
    let count = r.count(RECORD_BYTES)?;
    let mut out = Records::from(Vec::with_capacity(count));
    for _ in 0..count {
        match codec::decode(r.take(RECORD_BYTES)?) {
            Ok(record) => out.records.push(record),
            Err(_) => out.rejected += 1,
        }
    }
    Ok(out)
}

pub const REQUEST_BYTES: usize = 132;

/// L_a requests on the wire (PR -> PA, PA -> helper): a count, then fixed-size requests.
fn put_requests(out: &mut Vec<u8>, requests: &[AmbientRequest]) {
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
        // A flag, then the ray (zeros without one), so every request has the same size.
        out.put_u32(u32::from(r.centre_ray.is_some()));
        let (origin, direction) = r.centre_ray.unwrap_or((Vec3::ZERO, Vec3::ZERO));
        out.put_vec3(origin);
        out.put_vec3(direction);
        out.put_f32(r.distance);
    }
}

fn unit(v: Vec3) -> bool {
    v.is_finite() && (v.length() - 1.0).abs() < 1e-3
}

/// Every request is checked on arrival: a non-finite number, a normal that is not unit length or
/// an unknown layer is refused and counted (whether its pixel lies in the image is for the
/// receiver, which knows the image).
fn take_requests(reader: &mut Reader<'_>) -> Result<Requests, ProtocolError> {
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
            centre_ray: None,
            distance: 0.0,
        };
        let (shared, origin, direction) = (reader.u32()?, reader.vec3()?, reader.vec3()?);
        let r = AmbientRequest {
            centre_ray: (shared == 1).then_some((origin, direction)),
            distance: reader.f32()?,
            ..r
        };
        let centre_valid = match (shared, r.centre_ray) {
            (0, None) => true,
            (1, Some((origin, direction))) => origin.is_finite() && unit(direction),
            _ => false,
        };
        let valid = layer.is_some()
            && centre_valid
            && r.distance.is_finite()
            && r.distance >= 0.0
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

#[cfg(test)]
pub(crate) mod tests;

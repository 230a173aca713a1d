//! The master controller (rank 0): hands out tiles on demand, collects their pixels, keeps the
//! records every worker has shared (centralised mode) and what each worker has already seen,
//! owns the -af cache file, and gathers the ranks' statistics. It renders nothing itself.

use super::Mode;
use super::comm::{Comm, Counters};
use super::master_sends::MasterSends;
use super::protocol::*;
use crate::checkpoint::{Checkpoint, Restored};
use crate::image::framebuffer::FrameBuffer;
use crate::irradiance::IrradianceCache;
use crate::irradiance::record::Record;
use crate::stats::RankReport;
use crate::tiles::{Tile, store_tile};
use std::time::{Duration, Instant};

pub struct MasterResult {
    pub frame: FrameBuffer,
    pub ranks: Vec<RankReport>,
    pub render_s: f64,
}

/// Why the master stopped before the end.
#[derive(Debug)]
pub struct MasterError(pub String);

/// What the master controls.
pub struct Plan<'a> {
    pub mode: Mode,
    pub tiles: &'a [Tile],
    pub width: u32,
    pub height: u32,
    pub threads_per_worker: u32,
    /// The cache holding the -af file's records (the master renders nothing with it).
    pub cache: Option<&'a IrradianceCache>,
    /// How long to wait for any message before giving up on the job.
    pub timeout: Duration,
    /// Each rank's host, for messages that name a rank.
    pub hosts: &'a [String],
    /// The --checkpoint journal and what an earlier run finished (those tiles are not handed out).
    pub resume: Option<(&'a Checkpoint, &'a Restored)>,
    /// Every worker already holds the cache's records (the prepass shared them).
    pub workers_have_cache: bool,
}

pub fn run(comm: &Comm<'_>, plan: &Plan<'_>) -> Result<MasterResult, MasterError> {
    let Plan {
        mode,
        tiles,
        width,
        height,
        threads_per_worker,
        cache,
        timeout,
        hosts,
        resume,
        workers_have_cache,
    } = *plan;
    let start = Instant::now();
    let sends = MasterSends {
        comm,
        limit: timeout,
        hosts,
        cache,
    };
    let size = comm.size() as usize;
    let workers = size - 1;
    let (mut frame, mut tiles_done, todo) = match resume {
        Some((_, restored)) => (restored.frame.clone(), restored.done.clone(), restored.unfinished()),
        None => (
            FrameBuffer::new(width, height),
            vec![false; tiles.len()],
            (0..tiles.len()).collect(),
        ),
    };

    // Every worker starts from the records of the cache file (possibly none).
    let initial: Vec<Record> = match cache {
        Some(c) if !workers_have_cache => c.records(),
        _ => Vec::new(),
    };
    let initial_batch = encode_batch(&initial, 0);
    for w in 1..size {
        sends.send(w as i32, TAG_INITIAL_RECORDS, &initial_batch);
    }

    let mut next_tile = 0usize;
    let mut finished_requesters = 0usize;
    let requesters = workers * threads_per_worker as usize;
    // Centralised sharing: every record with the rank it came from, and per rank how far
    // into that list it has been brought up to date.
    let mut store: Vec<(usize, Record)> = Vec::new();
    let mut seen = vec![0usize; size];
    let mut end_markers = 0usize;
    let mut reports: Vec<Option<RankReport>> = vec![None; size];
    let mut records_received = 0u64;
    let mut records_rejected = 0u64;
    let persist = |records: &[Record]| {
        if let Some(cache) = cache {
            records.iter().for_each(|r| cache.insert(r.clone()));
        }
    };
    let done = |finished: usize, reports: &[Option<RankReport>], ends: usize| {
        finished == requesters
            && reports[1..].iter().all(Option::is_some)
            && (mode != Mode::Broadcast || ends == workers)
    };
    while !done(finished_requesters, &reports, end_markers) {
        let Some(msg) = comm.receive(None, None, Some(timeout)) else {
            let silent: Vec<String> = (1..size)
                .filter(|&r| reports[r].is_none())
                .map(|r| format!("{r} (host {})", hosts.get(r).map_or("?", String::as_str)))
                .collect();
            return Err(MasterError(format!(
                "no message from any worker for {:.0} s; still waiting for rank(s) {}",
                timeout.as_secs_f64(),
                silent.join(", ")
            )));
        };
        let source = msg.source as usize;
        let bad = |what: &str, e: ProtocolError| MasterError(format!("rank {source} sent a malformed {what}: {}", e.0));
        match msg.tag {
            TAG_WORK_REQUEST => {
                let (thread, finished) = decode_work_request(&msg.data).map_err(|e| bad("work request", e))?;
                if let Some((index, pixels)) = finished {
                    let tile = tiles
                        .get(index as usize)
                        .filter(|_| !tiles_done[index as usize])
                        .ok_or_else(|| {
                            MasterError(format!("rank {source} returned tile {index}, which it was not given"))
                        })?;
                    if pixels.len() != ((tile.x1 - tile.x0) * (tile.y1 - tile.y0)) as usize {
                        return Err(MasterError(format!(
                            "rank {source} returned tile {index} with the wrong size"
                        )));
                    }
                    if let Some((journal, _)) = resume {
                        journal.tile(index, 0, &pixels);
                    }
                    store_tile(&mut frame, tile, &pixels);
                    tiles_done[index as usize] = true;
                }
                let assignment = todo.get(next_tile).map(|&i| i as u32);
                if assignment.is_some() {
                    next_tile += 1;
                } else {
                    finished_requesters += 1;
                }
                sends.send(msg.source, TAG_WORK_BASE + thread as i32, &encode_work(assignment));
            }
            TAG_RECORDS_UP => {
                let thread = msg
                    .data
                    .get(..4)
                    .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")));
                let thread =
                    thread.ok_or_else(|| MasterError(format!("rank {source} sent an empty record message")))?;
                let batch = decode_batch(&msg.data[4..]).map_err(|e| bad("record batch", e))?;
                records_received += batch.records.len() as u64;
                records_rejected += batch.rejected as u64;
                persist(&batch.records);
                store.extend(batch.records.into_iter().map(|r| (source, r)));
                let missing: Vec<Record> = store[seen[source]..]
                    .iter()
                    .filter(|(from, _)| *from != source)
                    .map(|(_, r)| r.clone())
                    .collect();
                seen[source] = store.len();
                sends.send(
                    msg.source,
                    TAG_RECORDS_DOWN_BASE + thread as i32,
                    &encode_batch(&missing, 0),
                );
            }
            TAG_RECORDS_BROADCAST | TAG_FINAL_RECORDS => {
                let batch = decode_batch(&msg.data).map_err(|e| bad("record batch", e))?;
                records_received += batch.records.len() as u64;
                records_rejected += batch.rejected as u64;
                persist(&batch.records);
                if msg.tag == TAG_RECORDS_BROADCAST && batch.flags & BATCH_END != 0 {
                    end_markers += 1;
                }
            }
            TAG_STATS => {
                let report: RankReport = serde_json::from_slice(&msg.data)
                    .map_err(|e| MasterError(format!("rank {source} sent unreadable statistics: {e}")))?;
                reports[source] = Some(report);
            }
            other => {
                return Err(MasterError(format!(
                    "rank {source} sent a message with unknown tag {other}"
                )));
            }
        }
    }
    if let Some(missing) = tiles_done.iter().position(|d| !d) {
        return Err(MasterError(format!("tile {missing} was never rendered")));
    }
    let render_s = start.elapsed().as_secs_f64();
    let counters: &Counters = comm.counters;
    let mut ranks = vec![RankReport {
        rank: 0,
        role: "mc".into(),
        idle_s: counters.idle_s(),
        messages: counters.messages_sent.load(std::sync::atomic::Ordering::Relaxed),
        bytes: counters.bytes_sent.load(std::sync::atomic::Ordering::Relaxed),
        messages_received: counters.messages_received.load(std::sync::atomic::Ordering::Relaxed),
        bytes_received: counters.bytes_received.load(std::sync::atomic::Ordering::Relaxed),
        records_received,
        records_rejected,
        wall_s: render_s,
        ..Default::default()
    }];
    ranks.extend(reports.into_iter().skip(1).flatten());
    Ok(MasterResult { frame, ranks, render_s })
}

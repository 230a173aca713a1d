//! The master controller (rank 0): hands out tiles on demand, collects their pixels, keeps the
//! records every worker has shared (centralised mode) and what each worker has already seen,
//! owns the -af cache file, and gathers the ranks' statistics. It renders nothing itself.

use super::Mode;
use super::comm::Comm;
use super::liveness::Silence;
use super::master_sends::MasterSends;
use super::protocol::{FinishedTile, Message, Records};
use super::relay::RecordRelay;
use crate::checkpoint::{Checkpoint, Restored};
use crate::image::framebuffer::FrameBuffer;
use crate::irradiance::IrradianceCache;
use crate::irradiance::record::Record;
use crate::stats::RankReport;
use crate::tiles::{Tile, TileQueue, store_tile};
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
    let initial = Message::InitialRecords(Records::from(initial));
    for w in 1..size {
        sends.send(w as i32, &initial);
    }

    let queue = TileQueue::new(todo);
    let mut finished_requesters = 0usize;
    let requesters = workers * threads_per_worker as usize;
    // Centralised sharing goes through the relay (the initial records every worker has).
    let mut relay = RecordRelay::new(size, cache);
    let mut end_markers = 0usize;
    let mut reports: Vec<Option<RankReport>> = vec![None; size];
    let done = |finished: usize, reports: &[Option<RankReport>], ends: usize| {
        finished == requesters
            && reports[1..].iter().all(Option::is_some)
            && (mode != Mode::Broadcast || ends == workers)
    };
    while !done(finished_requesters, &reports, end_markers) {
        let msg = comm
            .receive_live(&[(None, None)], timeout, |r| reports[r as usize].is_none())
            .map_err(|silence| MasterError(lost_rank(&silence, hosts)))?;
        let source = msg.source as usize;
        let message = msg
            .message
            .map_err(|e| MasterError(format!("rank {source} sent a malformed message: {e}")))?;
        match message {
            Message::WorkRequest { thread, finished } => {
                if let Some(FinishedTile {
                    tile: index, pixels, ..
                }) = finished
                {
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
                let assignment = queue.next().map(|i| i as u32);
                finished_requesters += usize::from(assignment.is_none());
                let work = Message::Work {
                    thread,
                    tile: assignment,
                    records: Records::default(),
                };
                sends.send(msg.source, &work);
            }
            Message::RecordsUp { thread, records } => {
                relay.share(source, records);
                let reply = Message::RecordsDown {
                    thread,
                    records: relay.catch_up(source),
                };
                sends.send(msg.source, &reply);
            }
            Message::RecordsBroadcast { records, last } => {
                relay.keep(records);
                end_markers += usize::from(last);
            }
            Message::FinalRecords(records) => {
                relay.keep(records);
            }
            Message::Stats(report) => reports[source] = Some(report),
            other => {
                return Err(MasterError(format!(
                    "rank {source} sent an unexpected message ({:?})",
                    other.kind()
                )));
            }
        }
    }
    if let Some(missing) = tiles_done.iter().position(|d| !d) {
        return Err(MasterError(format!("tile {missing} was never rendered")));
    }
    let render_s = start.elapsed().as_secs_f64();
    let mut ranks = vec![RankReport {
        records_received: relay.received,
        records_rejected: relay.rejected,
        wall_s: render_s,
        ..super::traffic_report(0, "mc", &[comm.counters], comm.counters.idle_s())
    }];
    ranks.extend(reports.into_iter().skip(1).flatten());
    Ok(MasterResult { frame, ranks, render_s })
}

/// The line that ends a job when a rank has fallen silent.
pub fn lost_rank(silence: &Silence, hosts: &[String]) -> String {
    format!(
        "rank {} (host {}) has been silent for {:.0} s: its host or link is gone, or it hangs; the cache \
         file keeps every record synced before",
        silence.rank,
        hosts.get(silence.rank as usize).map_or("?", String::as_str),
        silence.seconds
    )
}

//! A worker rank of the traditional modes (paper, section 4): asks the master for tiles, renders
//! them with its own cache, and shares new records the mode's way: not at all (noshare),
//! through the master (centralised), or with every other rank (broadcast, with a receiving
//! thread that merges incoming records while the rendering threads go on).

use super::comm::{Comm, Counters, kind};
use super::protocol::{FinishedTile, Kind, Message, Records};
use super::sharing::WorkerSharing;
use super::{Intake, SyncThreshold, WorkerSetup, send_report};
use crate::irradiance::IrradianceCache;
use crate::render::{ThreadClock, ThreadStats, render_tile};
use std::sync::Mutex;
use std::time::Instant;

/// How this worker's rendering threads share records: the mode's way, every `sync` new
/// records, one thread at a time; and the records that came back.
struct Sharer<'a> {
    way: WorkerSharing,
    sync: SyncThreshold,
    cache: Option<&'a IrradianceCache>,
    /// Held while a thread shares: the others render on instead of waiting to share too.
    lock: Mutex<()>,
    intake: Intake,
}

impl Sharer<'_> {
    /// After a pixel: shares if the cache has gathered enough and no other thread is sharing.
    fn after_pixel(&self, comm: &Comm<'_>, thread: u32) {
        if let Some(cache) = self.cache
            && self.way != WorkerSharing::Kept
            && self.sync.reached(cache.outbox_len())
            && let Ok(_guard) = self.lock.try_lock()
        {
            self.share(comm, thread, false);
        }
    }

    /// Sends what the cache has gathered since the last share, the mode's way. `thread` is the
    /// calling rendering thread (replies come back on its own tag). The `end` of broadcasting
    /// is marked, records or none (without a cache too): every receiver waits for the marker.
    fn share(&self, comm: &Comm<'_>, thread: u32, end: bool) {
        match (self.way, self.cache) {
            (WorkerSharing::ThroughMaster, Some(cache)) if cache.outbox_len() > 0 => {
                self.intake.sync(comm, thread, cache)
            }
            (WorkerSharing::ToEveryone, cache) if end || cache.is_some_and(|c| c.outbox_len() > 0) => {
                let batch = Message::RecordsBroadcast {
                    records: Records::from(cache.map_or_else(Vec::new, |c| c.take_outbox())),
                    last: end,
                };
                // The master is a recipient too: it keeps the cache file.
                for rank in (0..comm.size()).filter(|&r| r != comm.rank()) {
                    comm.send(rank, &batch);
                }
            }
            _ => {}
        }
    }
}

/// Merges the records other workers broadcast until each of them has sent its end marker.
/// It has counters of its own: its waiting is not the rank's idle time (the rendering threads
/// go on meanwhile).
fn receive_broadcasts(counters: &Counters, cache: &IrradianceCache, peers: usize, intake: &Intake) {
    let comm = Comm::new(counters);
    let mut ends = 0;
    while ends < peers {
        let Some(msg) = comm.receive(&[kind(None, Kind::RecordsBroadcast)], None) else {
            continue;
        };
        match msg.message {
            Ok(Message::RecordsBroadcast { records, last }) => {
                intake.take(cache, records);
                ends += usize::from(last);
            }
            // A broken message cannot be trusted at all; count it and go on.
            _ => intake.reject(1),
        }
    }
}

/// One rendering thread: tiles from the master until there are none left, each finished tile
/// going back with the request for the next.
fn render_tiles(setup: &WorkerSetup<'_>, counters: &Counters, sharer: &Sharer<'_>, thread: u32) -> ThreadStats {
    let comm = Comm::new(counters);
    let integrator = setup.integrator();
    let mut stats = ThreadStats::default();
    let clock = ThreadClock::start();
    let mut finished: Option<FinishedTile> = None;
    loop {
        comm.send(
            0,
            &Message::WorkRequest {
                thread,
                finished: finished.take(),
            },
        );
        let reply = comm.receive(&[(Some(0), Some(Kind::Work.for_thread(thread)))], None);
        let Some(Ok(Message::Work { tile: Some(index), .. })) = reply.map(|r| r.message) else {
            break;
        };
        let tile = &setup.tiles[index as usize];
        let (camera, settings) = (&setup.job.camera, &setup.job.settings);
        let pixels = render_tile(&integrator, camera, settings, tile, &mut stats.rays, |_| {
            sharer.after_pixel(&comm, thread)
        });
        finished = Some(FinishedTile {
            tile: index,
            requests: 0,
            pixels,
        });
        stats.tiles += 1;
    }
    clock.stop(&mut stats);
    stats
}

pub fn run(setup: &WorkerSetup<'_>, way: WorkerSharing, sync: SyncThreshold, persist_local: bool) {
    let counters = Counters::default();
    let listener_counters = Counters::default();
    let comm = Comm::new(&counters);
    let start = Instant::now();
    let cache = setup.cache();
    let initial = comm.receive(&[kind(Some(0), Kind::InitialRecords)], None);
    if let (Some(cache), Some(Ok(Message::InitialRecords(records)))) = (cache, initial.map(|m| m.message)) {
        records.records.into_iter().for_each(|r| cache.insert_shared(r));
    }
    let sharer = Sharer {
        way,
        sync,
        cache,
        lock: Mutex::new(()),
        intake: Intake::default(),
    };
    let threads = setup.job.settings.threads.max(1) as u32;
    let peers = comm.size() as usize - 2;
    let thread_stats: Vec<ThreadStats> = std::thread::scope(|scope| {
        let listener = match (way, cache) {
            (WorkerSharing::ToEveryone, Some(cache)) => {
                Some(scope.spawn(|| receive_broadcasts(&listener_counters, cache, peers, &sharer.intake)))
            }
            _ => None,
        };
        let renderers: Vec<_> = (0..threads)
            .map(|thread| {
                let (counters, sharer) = (&counters, &sharer);
                scope.spawn(move || render_tiles(setup, counters, sharer, thread))
            })
            .collect();
        let stats = renderers.into_iter().map(|r| r.join().unwrap_or_default()).collect();
        // What is left to share goes out now; broadcast ends with the end marker so every
        // receiver knows when it has everything.
        match (way, cache) {
            (WorkerSharing::Kept, Some(cache)) if persist_local => {
                comm.send(0, &Message::FinalRecords(Records::from(cache.take_outbox())));
            }
            (WorkerSharing::Kept, _) => {}
            _ => sharer.share(&comm, 0, true),
        }
        if let Some(listener) = listener {
            let _ = listener.join();
        }
        stats
    });

    let mut report = setup.report(&comm, "worker", thread_stats, &listener_counters);
    (report.records_received, report.records_rejected) = sharer.intake.totals();
    report.wall_s = start.elapsed().as_secs_f64();
    send_report(&comm, report);
}

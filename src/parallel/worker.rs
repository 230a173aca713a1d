//! A worker rank of the traditional modes (paper, section 4): asks the master for tiles, renders
//! them with its own cache, and shares new records the mode's way: not at all (noshare),
//! through the master (centralised), or with every other rank (broadcast, with a receiving
//! thread that merges incoming records while the rendering threads go on).

use super::comm::{Comm, Counters, kind};
use super::protocol::{FinishedTile, Kind, Message, Records};
use super::sharing::WorkerSharing;
use super::{SyncThreshold, WorkerSetup, send_report};
use crate::irradiance::IrradianceCache;
use crate::render::{ThreadClock, ThreadStats, render_tile};
use crate::shading::RayCounts;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// Sends what the cache has gathered since the last share, the mode's way. `thread` is the
/// calling rendering thread (replies come back on its own tag).
fn share(
    comm: &Comm<'_>,
    mode: WorkerSharing,
    cache: &IrradianceCache,
    thread: u32,
    received: &AtomicU64,
    rejected: &AtomicU64,
    end: bool,
) {
    let records = cache.take_outbox();
    let take = |records: Records| {
        received.fetch_add(records.records.len() as u64, Ordering::Relaxed);
        rejected.fetch_add(records.rejected as u64, Ordering::Relaxed);
        records.records.into_iter().for_each(|r| cache.insert_shared(r));
    };
    match mode {
        WorkerSharing::ThroughMaster => {
            if records.is_empty() {
                return;
            }
            let up = Message::RecordsUp {
                thread,
                records: Records::from(records),
            };
            comm.send(0, &up);
            let reply = comm.receive(Some(0), Some(Kind::RecordsDown.for_thread(thread)), None);
            if let Some(Ok(Message::RecordsDown { records, .. })) = reply.map(|r| r.message) {
                take(records);
            }
        }
        WorkerSharing::ToEveryone => {
            if records.is_empty() && !end {
                return;
            }
            let batch = Message::RecordsBroadcast {
                records: Records::from(records),
                last: end,
            };
            // The master is a recipient too: it keeps the cache file.
            for rank in (0..comm.size()).filter(|&r| r != comm.rank()) {
                comm.send(rank, &batch);
            }
        }
        WorkerSharing::Kept => {}
    }
}

/// Merges the records other workers broadcast until each of them has sent its end marker.
/// It has counters of its own: its waiting is not the rank's idle time (the rendering threads
/// go on meanwhile).
fn receive_broadcasts(
    counters: &Counters,
    cache: &IrradianceCache,
    peers: usize,
    received: &AtomicU64,
    rejected: &AtomicU64,
) {
    let comm = Comm::new(counters);
    let mut ends = 0;
    while ends < peers {
        let Some(msg) = comm.receive_one_of(&[kind(None, Kind::RecordsBroadcast)], None) else {
            continue;
        };
        match msg.message {
            Ok(Message::RecordsBroadcast { records, last }) => {
                received.fetch_add(records.records.len() as u64, Ordering::Relaxed);
                rejected.fetch_add(records.rejected as u64, Ordering::Relaxed);
                records.records.into_iter().for_each(|r| cache.insert_shared(r));
                if last {
                    ends += 1;
                }
            }
            // A broken message cannot be trusted at all; count it and go on.
            _ => {
                rejected.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}

pub fn run(setup: &WorkerSetup<'_>, mode: WorkerSharing, sync: SyncThreshold, persist_local: bool) {
    let counters = Counters::default();
    let listener_counters = Counters::default();
    let comm = Comm::new(&counters);
    let start = Instant::now();
    let cache = setup.cache();
    let received = AtomicU64::new(0);
    let rejected = AtomicU64::new(0);

    let initial = comm.receive_one_of(&[kind(Some(0), Kind::InitialRecords)], None);
    if let (Some(cache), Some(Ok(Message::InitialRecords(records)))) = (cache, initial.map(|m| m.message)) {
        records.records.into_iter().for_each(|r| cache.insert_shared(r));
    }
    let share_lock = Mutex::new(());
    let threads = setup.job.settings.threads.max(1) as u32;
    let peers = comm.size() as usize - 2;
    let thread_stats: Vec<ThreadStats> = std::thread::scope(|scope| {
        let listener = (mode == WorkerSharing::ToEveryone && cache.is_some()).then(|| {
            scope.spawn(|| receive_broadcasts(&listener_counters, cache.expect("checked"), peers, &received, &rejected))
        });
        let renderers: Vec<_> = (0..threads)
            .map(|thread| {
                let (counters, received, rejected, share_lock) = (&counters, &received, &rejected, &share_lock);
                scope.spawn(move || {
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
                        let reply = comm.receive(Some(0), Some(Kind::Work.for_thread(thread)), None);
                        let Some(Ok(Message::Work { tile: Some(index), .. })) = reply.map(|r| r.message) else {
                            break;
                        };
                        let tile = &setup.tiles[index as usize];
                        let mut after_pixel = |_: &mut RayCounts| {
                            if let Some(cache) = cache
                                && mode != WorkerSharing::Kept
                                && sync.reached(cache.outbox_len())
                                && let Ok(_guard) = share_lock.try_lock()
                            {
                                share(&comm, mode, cache, thread, received, rejected, false);
                            }
                        };
                        let pixels = render_tile(
                            &integrator,
                            &setup.job.camera,
                            &setup.job.settings,
                            tile,
                            &mut stats.rays,
                            &mut after_pixel,
                        );
                        finished = Some(FinishedTile {
                            tile: index,
                            requests: 0,
                            pixels,
                        });
                        stats.tiles += 1;
                    }
                    clock.stop(&mut stats);
                    stats
                })
            })
            .collect();
        let stats: Vec<ThreadStats> = renderers.into_iter().map(|r| r.join().unwrap_or_default()).collect();
        // What is left to share goes out now; broadcast ends with the end marker so every
        // receiver knows when it has everything.
        if let Some(cache) = cache {
            match mode {
                WorkerSharing::ThroughMaster | WorkerSharing::ToEveryone => {
                    share(&comm, mode, cache, 0, &received, &rejected, true)
                }
                _ if persist_local => {
                    comm.send(0, &Message::FinalRecords(Records::from(cache.take_outbox())));
                }
                _ => {}
            }
        } else if mode == WorkerSharing::ToEveryone {
            // Without a cache there is nothing to share, but peers still wait for the marker.
            let last = Message::RecordsBroadcast {
                records: Records::default(),
                last: true,
            };
            for rank in (0..comm.size()).filter(|&r| r != comm.rank()) {
                comm.send(rank, &last);
            }
        }
        if let Some(listener) = listener {
            let _ = listener.join();
        }
        stats
    });

    let mut report = setup.report(&comm, "worker", thread_stats, &listener_counters);
    report.records_received = received.load(Ordering::Relaxed);
    report.records_rejected = rejected.load(Ordering::Relaxed);
    report.wall_s = start.elapsed().as_secs_f64();
    send_report(&comm, report);
}

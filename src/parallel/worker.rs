//! A worker rank of the traditional modes (paper, section 4): asks the master for tiles, renders
//! them with its own cache, and shares new records the mode's way: not at all (noshare),
//! through the master (centralised), or with every other rank (broadcast, with a receiving
//! thread that merges incoming records while the rendering threads go on).

use super::Mode;
use super::WorkerSetup;
use super::comm::{Comm, Counters};
use super::protocol::*;
use super::{rank_report, send_report};
use crate::irradiance::IrradianceCache;
use crate::irradiance::record::Record;
use crate::render::{ThreadClock, ThreadStats, render_tile};
use crate::shading::{Integrator, RayCounts};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// Sends what the cache has gathered since the last share, the mode's way. `thread` is the
/// calling rendering thread (replies come back on its own tag).
fn share(
    comm: &Comm<'_>,
    mode: Mode,
    cache: &IrradianceCache,
    thread: u32,
    received: &AtomicU64,
    rejected: &AtomicU64,
    end: bool,
) {
    let records = cache.take_outbox();
    match mode {
        Mode::Centralised => {
            if records.is_empty() {
                return;
            }
            let mut message = thread.to_le_bytes().to_vec();
            message.extend(encode_batch(&records, 0));
            comm.send(0, TAG_RECORDS_UP, &message);
            let reply = comm.receive(Some(0), Some(TAG_RECORDS_DOWN_BASE + thread as i32), None);
            if let Some(batch) = reply.and_then(|r| decode_batch(&r.data).ok()) {
                received.fetch_add(batch.records.len() as u64, Ordering::Relaxed);
                rejected.fetch_add(batch.rejected as u64, Ordering::Relaxed);
                batch.records.into_iter().for_each(|r| cache.insert_shared(r));
            }
        }
        Mode::Broadcast => {
            if records.is_empty() && !end {
                return;
            }
            let batch = encode_batch(&records, if end { BATCH_END } else { 0 });
            // The master is a recipient too: it keeps the cache file.
            for rank in (0..comm.size()).filter(|&r| r != comm.rank()) {
                comm.send(rank, TAG_RECORDS_BROADCAST, &batch);
            }
        }
        Mode::Noshare | Mode::Component | Mode::Serial => {}
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
        let Some(msg) = comm.receive(None, Some(TAG_RECORDS_BROADCAST), None) else {
            continue;
        };
        match decode_batch(&msg.data) {
            Ok(batch) => {
                received.fetch_add(batch.records.len() as u64, Ordering::Relaxed);
                rejected.fetch_add(batch.rejected as u64, Ordering::Relaxed);
                batch.records.into_iter().for_each(|r| cache.insert_shared(r));
                if batch.flags & BATCH_END != 0 {
                    ends += 1;
                }
            }
            // A broken message cannot be trusted at all; count it and go on.
            Err(_) => {
                rejected.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}

pub fn run(setup: &WorkerSetup<'_>, mode: Mode, sync: usize, persist_local: bool) {
    let counters = Counters::default();
    let listener_counters = Counters::default();
    let comm = Comm::new(&counters);
    let start = Instant::now();
    let cache = setup.cache;
    let received = AtomicU64::new(0);
    let rejected = AtomicU64::new(0);

    let initial = comm.receive(Some(0), Some(TAG_INITIAL_RECORDS), None);
    if let (Some(cache), Some(batch)) = (cache, initial.and_then(|m| decode_batch(&m.data).ok())) {
        batch.records.into_iter().for_each(|r| cache.insert_shared(r));
    }
    let share_lock = Mutex::new(());
    let threads = setup.settings.threads.max(1) as u32;
    let peers = comm.size() as usize - 2;
    let thread_stats: Vec<ThreadStats> = std::thread::scope(|scope| {
        let listener = (mode == Mode::Broadcast && cache.is_some()).then(|| {
            scope.spawn(|| receive_broadcasts(&listener_counters, cache.expect("checked"), peers, &received, &rejected))
        });
        let renderers: Vec<_> = (0..threads)
            .map(|thread| {
                let (counters, received, rejected, share_lock) = (&counters, &received, &rejected, &share_lock);
                scope.spawn(move || {
                    let comm = Comm::new(counters);
                    let integrator = Integrator::new(setup.scene, setup.tracer, setup.shading, cache)
                        .cache_frozen(setup.settings.prepass);
                    let mut stats = ThreadStats::default();
                    let clock = ThreadClock::start();
                    let mut finished: Option<(u32, Vec<_>)> = None;
                    loop {
                        let request = encode_work_request(thread, finished.as_ref().map(|(t, p)| (*t, p.as_slice())));
                        comm.send(0, TAG_WORK_REQUEST, &request);
                        let reply = comm.receive(Some(0), Some(TAG_WORK_BASE + thread as i32), None);
                        let Some(Ok(Some(index))) = reply.map(|r| decode_work(&r.data)) else {
                            break;
                        };
                        let tile = &setup.tiles[index as usize];
                        let mut after_pixel = |_: &mut RayCounts| {
                            if let Some(cache) = cache
                                && mode != Mode::Noshare
                                && cache.outbox_len() >= sync
                                && let Ok(_guard) = share_lock.try_lock()
                            {
                                share(&comm, mode, cache, thread, received, rejected, false);
                            }
                        };
                        let pixels = render_tile(
                            &integrator,
                            setup.camera,
                            setup.settings,
                            tile,
                            &mut stats.rays,
                            &mut after_pixel,
                        );
                        finished = Some((index, pixels));
                        stats.tiles += 1;
                    }
                    clock.stop(&mut stats);
                    stats
                })
            })
            .collect();
        let mut stats: Vec<ThreadStats> = renderers.into_iter().map(|r| r.join().unwrap_or_default()).collect();
        crate::render::add_prepass_work(&mut stats, setup.prepass);
        // What is left to share goes out now; broadcast ends with the end marker so every
        // receiver knows when it has everything.
        if let Some(cache) = cache {
            match mode {
                Mode::Centralised => share(&comm, mode, cache, 0, &received, &rejected, true),
                Mode::Broadcast => share(&comm, mode, cache, 0, &received, &rejected, true),
                _ if persist_local => {
                    let records: Vec<Record> = cache.take_outbox();
                    comm.send(0, TAG_FINAL_RECORDS, &encode_batch(&records, BATCH_END));
                }
                _ => {}
            }
        } else if mode == Mode::Broadcast {
            // Without a cache there is nothing to share, but peers still wait for the marker.
            let batch = encode_batch(&[], BATCH_END);
            for rank in (0..comm.size()).filter(|&r| r != comm.rank()) {
                comm.send(rank, TAG_RECORDS_BROADCAST, &batch);
            }
        }
        if let Some(listener) = listener {
            let _ = listener.join();
        }
        stats
    });

    let mut report = rank_report(
        comm.rank(),
        "worker",
        &thread_stats,
        &[&counters, &listener_counters, setup.traffic_before],
        counters.idle_s(),
    );
    report.records_received = received.load(Ordering::Relaxed);
    report.records_rejected = rejected.load(Ordering::Relaxed);
    report.wall_s = start.elapsed().as_secs_f64();
    send_report(&comm, report);
}

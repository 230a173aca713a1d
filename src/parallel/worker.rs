//! The traditional modes (paper, section 4): a worker rank asks the master for tiles, renders
//! them with its own cache, and shares new records not at all (noshare; with -af they go to the
//! master at the end), through the master, which answers with those the worker lacks
//! (centralised), or with every other rank (broadcast: a receiving thread merges theirs while
//! the rendering threads go on). `TraditionalSharing` is the master's policy: workers start from
//! the cache file's records, and the render is complete once every rendering thread has been
//! told "no tile left" and every rank has reported (broadcast: and sent its last batch).

use super::comm::{Comm, Counters, kind};
use super::master::{MasterCore, Sharing};
use super::protocol::{FinishedTile, Kind, Message, Records};
use super::{Intake, Mode, Setup, send_report};
use crate::irradiance::IrradianceCache;
use crate::render::error_estimate::ErrorProbe;
use crate::render::{ThreadClock, ThreadStats, render_tile};
use std::sync::Mutex;

/// How this worker's rendering threads share records: every --sync new ones, one at a time.
struct Sharer<'a> {
    setup: &'a Setup<'a>,
    /// Held while a thread shares: the others render on instead of waiting to share too.
    lock: Mutex<()>,
    intake: Intake,
}

impl Sharer<'_> {
    /// After a pixel: shares if the cache has gathered enough and no other thread is sharing.
    fn after_pixel(&self, comm: &Comm<'_>, thread: u32) {
        if let Some(cache) = self.setup.cache()
            && self.setup.job_in.mode != Mode::Noshare
            && cache.outbox_len() >= self.setup.sync
            && let Ok(_guard) = self.lock.try_lock()
        {
            self.share(comm, thread, false);
        }
    }

    /// Sends what the cache has gathered since the last share, the mode's way. `thread` is the
    /// calling rendering thread (replies come back on its own tag). At the `end`, noshare sends
    /// the master its records for the -af file, and broadcast marks its end, records or none
    /// (without a cache too): every receiver waits for the marker.
    fn share(&self, comm: &Comm<'_>, thread: u32, end: bool) {
        let outbox = || Records::from(self.setup.cache().map_or_else(Vec::new, |c| c.take_outbox()));
        match (self.setup.job_in.mode, self.setup.cache()) {
            (Mode::Noshare, Some(_)) if end && self.setup.job_in.cache_file => {
                comm.send(0, &Message::FinalRecords(outbox()));
            }
            (Mode::Centralised, Some(cache)) if cache.outbox_len() > 0 => self.intake.sync(comm, thread, cache),
            (Mode::Broadcast, cache) if end || cache.is_some_and(|c| c.outbox_len() > 0) => {
                let (records, last) = (outbox(), end);
                let batch = Message::RecordsBroadcast { records, last };
                // The master is a recipient too: it keeps the cache file.
                for rank in (0..comm.size()).filter(|&r| r != comm.rank()) {
                    comm.send(rank, &batch);
                }
            }
            _ => {}
        }
    }
}

/// Merges the records other workers broadcast until each has sent its end marker. Its waiting,
/// on counters of its own, is not the rank's idle time (the rendering threads go on meanwhile).
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

/// One rendering thread: tiles until none is left, each going back with the request for the next.
fn render_tiles(setup: &Setup<'_>, counters: &Counters, sharer: &Sharer<'_>, thread: u32) -> ThreadStats {
    let comm = Comm::new(counters);
    let integrator = setup.integrator();
    let probe = ErrorProbe::new(&integrator, &setup.job.camera, &setup.job.settings);
    let mut stats = ThreadStats::default();
    let clock = ThreadClock::start();
    let mut finished: Option<FinishedTile> = None;
    loop {
        comm.send(0, &Message::WorkRequest { thread, finished });
        let reply = comm.receive(&[(Some(0), Some(Kind::Work.for_thread(thread)))], None);
        let Some(Ok(Message::Work { tile: Some(index), .. })) = reply.map(|r| r.message) else {
            break;
        };
        let tile = &setup.tiles[index as usize];
        let (camera, settings) = (&setup.job.camera, &setup.job.settings);
        let pixels = render_tile(&integrator, camera, settings, tile, &mut stats.rays, |_| {
            sharer.after_pixel(&comm, thread)
        });
        probe.tile(&mut stats.error, tile, &pixels);
        finished = Some(setup.finished_tile(index, 0, pixels));
        stats.tiles += 1;
    }
    clock.stop(&mut stats);
    stats
}

pub fn run(setup: &Setup<'_>) {
    let counters = Counters::default();
    let listener_counters = Counters::default();
    let comm = Comm::new(&counters);
    let cache = setup.cache();
    let initial = comm.receive(&[kind(Some(0), Kind::InitialRecords)], None);
    if let (Some(cache), Some(Ok(Message::InitialRecords(records)))) = (cache, initial.map(|m| m.message)) {
        records.records.into_iter().for_each(|r| cache.insert_shared(r));
    }
    let sharer = Sharer {
        setup,
        lock: Mutex::new(()),
        intake: Intake::default(),
    };
    let threads = setup.job.settings.threads.max(1) as u32;
    let peers = comm.size() as usize - 2;
    let thread_stats: Vec<ThreadStats> = std::thread::scope(|scope| {
        let (listening, intake) = (&listener_counters, &sharer.intake);
        let listener = cache
            .filter(|_| setup.job_in.mode == Mode::Broadcast)
            .map(|cache| scope.spawn(move || receive_broadcasts(listening, cache, peers, intake)));
        let renderers: Vec<_> = (0..threads)
            .map(|thread| {
                let (counters, sharer) = (&counters, &sharer);
                scope.spawn(move || render_tiles(setup, counters, sharer, thread))
            })
            .collect();
        let stats = renderers.into_iter().map(|r| r.join().unwrap_or_default()).collect();
        // What is left to share goes out now, with broadcast's end marker.
        sharer.share(&comm, 0, true);
        if let Some(listener) = listener {
            let _ = listener.join();
        }
        stats
    });

    let mut report = setup.report(&comm, "worker", thread_stats, &listener_counters);
    (report.records_received, report.records_rejected) = sharer.intake.totals();
    send_report(&comm, report);
}

/// The master's side of a traditional mode.
#[derive(Default)]
pub struct TraditionalSharing {
    /// Broadcast: workers whose last batch has arrived.
    ended: usize,
}

impl Sharing for TraditionalSharing {
    fn on_message(&mut self, core: &mut MasterCore<'_, '_>, source: i32, message: Message) -> Result<(), String> {
        match (core.setup.job_in.mode, message) {
            (Mode::Noshare, Message::FinalRecords(records)) => {
                core.relay.keep(records);
            }
            (Mode::Centralised, Message::RecordsUp { thread, records }) => core.sync(source, thread, records),
            (Mode::Broadcast, Message::RecordsBroadcast { records, last }) => {
                core.relay.keep(records);
                self.ended += usize::from(last);
            }
            (_, other) => return Err(format!("rank {source} sent an unexpected message ({:?})", other.kind())),
        }
        Ok(())
    }

    fn finished(&self, core: &MasterCore<'_, '_>) -> bool {
        let job_in = core.setup.job_in;
        let all_ended = job_in.mode != Mode::Broadcast || self.ended == core.workers();
        let threads = job_in.threads.unwrap_or(1);
        core.turned_away == core.workers() * threads && core.every_report_in() && all_ended
    }
}

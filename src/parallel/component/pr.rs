//! A PR rank: renders the tiles the master hands out, everything but indirect diffuse light.
//! Indirect diffuse values its local cache (records relayed by the master) can give are used at
//! once; the others become requests, buffered (--send at a time) and sent to the PA of their tile.
//! With no tile left it flushes its buffer and, when the master asks, computes requests
//! forwarded from a loaded PA. Its image goes to the master only at the end.

use super::{Roles, compute_request, send_results};
use crate::checkpoint::RequestResult;
use crate::image::framebuffer::FrameBuffer;
use crate::parallel::comm::kind;
use crate::parallel::comm::{Comm, Counters, Envelope, Marker};
use crate::parallel::protocol::{FinishedTile, Kind, Message, Records, Requests};
use crate::parallel::{SyncThreshold, WorkerSetup, send_report};
use crate::render::{ThreadClock, ThreadStats, render_tile};
use crate::shading::request::RequestBuffer;
use crate::tiles::store_tile;
use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::time::Instant;

/// Request batches wait here for the courier thread; when this many are waiting, the renderer
/// waits too.
const BATCHES_IN_FLIGHT: usize = 16;

/// Hands request batches to the courier. Every request of a tile goes to one PA, the tile's
/// index choosing it (tile i to PA i mod n): a PA then sees a tile's neighbouring points
/// together and reuses its own records, where spreading one tile's batches over every PA had
/// several PAs compute near-identical records for the same spot (measured on the Cornell box at
/// 8 ranks: 934-968 records against 765-772, fewer than centralised or broadcast sharing).
struct Sender<'c> {
    outbox: Option<SyncSender<(i32, Message)>>,
    /// Where the renderer's waits for a full outbox are counted (its idle time).
    idle_ns: &'c AtomicU64,
    pas: &'c [i32],
    /// The PA of the tile being rendered.
    pa: usize,
    sent: u64,
    /// Nanoseconds spent taking, encoding and queueing batches (waits for a full outbox not
    /// included: those are idle time).
    handling_ns: u64,
}

impl Sender<'_> {
    /// Requests from now on belong to this tile.
    fn start_tile(&mut self, index: u32) {
        self.pa = index as usize % self.pas.len().max(1);
    }

    /// Sends the buffered requests to the current tile's PA.
    fn send(&mut self, sink: &RequestBuffer) {
        let handling = Instant::now();
        let batch = sink.take();
        let Some(outbox) = &self.outbox else { return };
        if batch.is_empty() || self.pas.is_empty() {
            return;
        }
        let pa = self.pas[self.pa];
        self.sent += batch.len() as u64;
        let message = (pa, Message::Requests(Requests::from(batch)));
        let queued = outbox.try_send(message);
        self.handling_ns += handling.elapsed().as_nanos() as u64;
        if let Err(TrySendError::Full(message)) = queued {
            let waited = Instant::now();
            let _ = outbox.send(message);
            self.idle_ns
                .fetch_add(waited.elapsed().as_nanos() as u64, Ordering::Relaxed);
        }
    }

    /// No more requests: the courier ends once it has delivered what it holds.
    fn close(&mut self) {
        self.outbox = None;
    }
}

/// Batches sent to one PA between two markers (see `deliver`).
const WINDOW: usize = 16;

/// The courier thread: sends the request batches, and after every WINDOW batches to a PA a
/// marker (an empty batch) as a synchronous send, which completes only once that PA has taken
/// in everything before it. Before it sends the next marker to that PA it waits for the
/// previous one, so at most 2 x WINDOW batches are ever waiting for a PA. A PA with a full
/// queue takes nothing in: the courier waits, the outbox fills and the renderer waits
/// (back-pressure from PA to PR), while a PA that keeps up costs the PR no waiting at all.
/// The courier ends once every marker has been taken in, so nothing of this PR's is still on
/// its way when it reports itself idle.
fn deliver(counters: &Counters, inbox: Receiver<(i32, Message)>) {
    let comm = Comm::new(counters);
    let mut windows: HashMap<i32, (usize, Option<Marker>)> = HashMap::new();
    for (pa, batch) in inbox {
        comm.send(pa, &batch);
        let (since, marker) = windows.entry(pa).or_default();
        *since += 1;
        if *since >= WINDOW {
            if let Some(previous) = marker.take() {
                comm.wait_marker(previous);
            }
            *marker = Some(comm.send_marker(pa));
            *since = 0;
        }
    }
    for (_, (_, marker)) in windows {
        if let Some(marker) = marker {
            comm.wait_marker(marker);
        }
    }
}

/// Sends the records made here and takes in those the master has from others.
fn sync_records(
    comm: &Comm<'_>,
    cache: &crate::irradiance::IrradianceCache,
    up: Vec<crate::irradiance::record::Record>,
    received: &mut u64,
    rejected: &mut u64,
) {
    comm.send(
        0,
        &Message::RecordsUp {
            thread: 0,
            records: Records::from(up),
        },
    );
    if let Some(reply) = comm.receive_one_of(&[kind(Some(0), Kind::RecordsDown)], None)
        && let Ok(Message::RecordsDown { records: batch, .. }) = reply.message
    {
        *received += batch.records.len() as u64;
        *rejected += batch.rejected as u64;
        batch.records.into_iter().for_each(|r| cache.insert_shared(r));
    }
}

/// `journal`: --checkpoint is on, so finished tiles and computed requests are reported to the
/// master as they finish.
pub fn run(setup: &WorkerSetup<'_>, roles: &Roles, send_at: usize, sync: SyncThreshold, seed: u64, journal: bool) {
    let courier_counters = Counters::default();
    let (outbox, inbox) = sync_channel(BATCHES_IN_FLIGHT);
    std::thread::scope(|scope| {
        let courier = scope.spawn(|| deliver(&courier_counters, inbox));
        render_and_help(
            setup,
            roles,
            send_at,
            sync,
            seed,
            journal,
            outbox,
            &courier_counters,
            || {
                let _ = courier.join();
            },
        );
    });
}

#[allow(clippy::too_many_arguments)]
fn render_and_help(
    setup: &WorkerSetup<'_>,
    roles: &Roles,
    send_at: usize,
    sync: SyncThreshold,
    seed: u64,
    journal: bool,
    outbox: SyncSender<(i32, Message)>,
    courier_counters: &Counters,
    join_courier: impl FnOnce(),
) {
    let counters = Counters::default();
    let comm = Comm::new(&counters);
    let start = Instant::now();
    let (width, height) = (setup.job.camera.width, setup.job.camera.height);
    let mut frame = FrameBuffer::new(width, height);
    let sink = RequestBuffer::default();
    let mut integrator = setup.integrator();
    if !roles.pas.is_empty() {
        integrator = integrator.deferring(&sink);
    }
    let mut stats = ThreadStats::default();
    let clock = ThreadClock::start();
    let mut sender = Sender {
        outbox: Some(outbox),
        idle_ns: &counters.idle_ns,
        pas: &roles.pas,
        pa: 0,
        sent: 0,
        handling_ns: 0,
    };
    let (mut received, mut rejected) = (0u64, 0u64);

    // Tiles until the master has none left. A PR asks for its next tile as it starts the
    // current one, so the master's round trip overlaps the rendering instead of idling the PR
    // between tiles (a 16x16 tile is under a millisecond of work, the round trip a few tenths).
    // The request carries the report of the tile finished before (with --checkpoint); the
    // records that come with the next tile are one tile older than they would have been.
    let ask = |finished: Option<FinishedTile>| comm.send(0, &Message::WorkRequest { thread: 0, finished });
    let take = |received: &mut u64, rejected: &mut u64| -> Option<u32> {
        let reply = comm.receive_one_of(&[kind(Some(0), Kind::Work)], None)?;
        let Ok(Message::Work { tile, records, .. }) = reply.message else {
            return None;
        };
        if let Some(cache) = setup.cache() {
            *received += records.records.len() as u64;
            *rejected += records.rejected as u64;
            records.records.into_iter().for_each(|r| cache.insert_shared(r));
        }
        tile
    };
    ask(None);
    let mut next = take(&mut received, &mut rejected);
    let mut finished_tile: Option<FinishedTile> = None;
    loop {
        let Some(index) = next else {
            if finished_tile.is_none() {
                break;
            }
            // The last tile's report still has to reach the master: one more request (its
            // answer is no tile; were it one, the loop renders it).
            ask(finished_tile.take());
            next = take(&mut received, &mut rejected);
            continue;
        };
        ask(finished_tile.take());
        let tile = &setup.tiles[index as usize];
        sender.start_tile(index);
        // The outgoing buffer is empty here (flushed at every tile's end), so what this tile
        // sent is the change in the count sent.
        let sent_before = sender.sent;
        let pixels = render_tile(
            &integrator,
            &setup.job.camera,
            &setup.job.settings,
            tile,
            &mut stats.rays,
            |_| {
                if sink.len() >= send_at {
                    sender.send(&sink);
                }
            },
        );
        // The tile's last requests go to its PA now, not with the next tile's.
        sender.send(&sink);
        if journal {
            let requests = (sender.sent - sent_before) as u32;
            finished_tile = Some(FinishedTile {
                tile: index,
                requests,
                pixels: pixels.clone(),
            });
        }
        store_tile(&mut frame, tile, &pixels);
        stats.tiles += 1;
        next = take(&mut received, &mut rejected);
    }
    sender.send(&sink);
    sender.close();
    // Every batch must have reached its PA before this PR counts as flushed (the master may
    // end the job once the counts close, and a PA stops taking requests then).
    let waited = Instant::now();
    join_courier();
    counters
        .idle_ns
        .fetch_add(waited.elapsed().as_nanos() as u64, Ordering::Relaxed);
    let mut results: Vec<RequestResult> = Vec::new();

    // Helping: compute what the master has a PA forward, until it says everything is done.
    let mut helped = 0u64;
    loop {
        let records = setup.cache().map_or_else(Vec::new, |c| c.take_outbox());
        send_results(&comm, &mut results);
        let idle = Message::Idle {
            sent: sender.sent,
            helped,
            records: Records::from(records),
        };
        comm.send(0, &idle);
        let Some(msg) = wait_for_forward_or_finish(&comm) else {
            break;
        };
        match msg.message {
            Ok(Message::Forwarded(decoded)) => {
                for request in decoded.requests.iter().filter(|r| r.pixel < width * height) {
                    compute_request(
                        &integrator,
                        request,
                        seed,
                        &mut stats.rays,
                        &mut frame,
                        journal.then_some(&mut results),
                    );
                    // A helper shares its records as often as a PA does.
                    if let Some(cache) = setup.cache()
                        && sync.reached(cache.outbox_len())
                    {
                        send_results(&comm, &mut results);
                        sync_records(&comm, cache, cache.take_outbox(), &mut received, &mut rejected);
                    }
                }
                // Refused requests are counted as computed (with nothing added) so the totals
                // still close; the refusal is reported in the statistics.
                let outside = decoded.requests.iter().filter(|r| r.pixel >= width * height).count();
                helped += (decoded.requests.len() + decoded.rejected) as u64;
                rejected += (decoded.rejected + outside) as u64;
            }
            Ok(_) => break,
            Err(_) => rejected += 1,
        }
    }
    clock.stop(&mut stats);

    comm.send(0, &Message::Image(frame.to_floats()));
    let mut report = setup.report(&comm, "pr", vec![stats], courier_counters);
    report.records_received = received;
    report.records_rejected = rejected;
    report.requests_sent = sender.sent;
    report.request_handling_s = sender.handling_ns as f64 * 1e-9;
    report.requests_computed = helped;
    report.wall_s = start.elapsed().as_secs_f64();
    send_report(&comm, report);
}

/// Waits for forwarded requests from any PA or the master's FINISH.
fn wait_for_forward_or_finish(comm: &Comm<'_>) -> Option<Envelope> {
    comm.receive_one_of(&[kind(Some(0), Kind::Finish), kind(None, Kind::Forwarded)], None)
}

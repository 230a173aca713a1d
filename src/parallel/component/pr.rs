//! A PR rank: renders the tiles the master hands out, everything but the indirect diffuse light
//! its cache (records relayed by the master) cannot give: that becomes requests, sent --send at
//! a time to the PA of their tile; a batch that no longer fits its outbox (its PA is behind) it
//! computes itself. With no tile left it flushes its buffer and, when the master asks, computes
//! requests forwarded from a loaded PA. Each finished tile goes to the master with
//! the next tile's request, and what it computes for PAs as results.

use super::order::RequestQueue;
use super::{Roles, compute_request, send_results};
use crate::parallel::comm::{Comm, Counters, Envelope, Marker, kind};
use crate::parallel::protocol::{FinishedTile, Kind, Message, Records, Requests};
use crate::parallel::{Intake, Setup, send_report};
use crate::render::error_estimate::ErrorProbe;
use crate::render::pixel::render_tile_from;
use crate::render::{ThreadClock, ThreadStats};
use crate::shading::Integrator;
use crate::shading::request::{AmbientRequest, RequestBuffer, RequestResult};
use std::cell::RefCell;
use std::collections::HashMap;
use std::sync::atomic::AtomicU64;
use std::sync::atomic::Ordering::Relaxed;
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::time::{Duration, Instant};

/// The fewest request batches the outbox holds for the courier thread (see `outbox_batches`).
const MIN_BATCHES_IN_FLIGHT: usize = 16;
/// The most: a bound on the slots a tiny --send would otherwise ask for.
const MAX_BATCHES_IN_FLIGHT: usize = 1 << 16;

/// How many batches of `send` requests the outbox holds: a PA queue's worth (--pa-queue), so
/// that a PR computes requests itself (or, with --pr-waits, waits) only when a PA is that far
/// behind, as --pa-queue says, and not whenever the courier pauses. With 16 batches (512
/// requests) the courier's pauses between markers filled it: at 5 processes (2 PAs, Cornell
/// box 128x128, -ab 1 -aa 0.2) the PRs computed 2,000-2,200 of their requests themselves and
/// made 715 of 1,238 records, which nobody else had until the PR went idle; the PAs and the
/// other PR made records beside them (centralised: 1,072).
fn outbox_batches(pa_queue: u32, send: u32) -> usize {
    (pa_queue as usize)
        .div_ceil(send.max(1) as usize)
        .clamp(MIN_BATCHES_IN_FLIGHT, MAX_BATCHES_IN_FLIGHT)
}

/// Hands request batches to the courier. Every request of a tile goes to one PA (`pa_of_tiles`),
/// which then reuses its own records for the tile's neighbouring points; spreading a tile over
/// every PA had several compute near-identical records for one spot (Cornell box, 8 ranks:
/// 934-968 records against 765-772, fewer than centralised or broadcast sharing).
struct Sender<'c> {
    outbox: Option<SyncSender<(i32, Message)>>,
    /// Each tile's PA (none without PAs).
    pa_of_tile: Vec<i32>,
    /// The PA of the tile being rendered.
    pa: Option<i32>,
    sent: u64,
    /// Nanoseconds spent taking, encoding and queueing batches (not waiting: that is idle time).
    handling_ns: u64,
    /// --pr-waits: wait for room in a full outbox (the paper's PRs) rather than compute.
    waits: bool,
    /// Where the renderer's waits for a full outbox are counted (its idle time).
    idle_ns: &'c AtomicU64,
    /// The renderer's own link, for taking the master's answer in while it waits.
    comm: Comm<'c>,
    early: &'c EarlyAnswer,
}

impl Sender<'_> {
    /// Sends the buffered requests to the current tile's PA. When the outbox is full (the PA's
    /// queue is: back-pressure) it returns them for the PR to compute itself (`OwnRequests`),
    /// or with --pr-waits waits for room, taking the master's answer in meanwhile
    /// (`EarlyAnswer`).
    fn send(&mut self, sink: &RequestBuffer) -> Vec<AmbientRequest> {
        let handling = Instant::now();
        let batch = sink.take();
        let (Some(outbox), Some(pa), false) = (&self.outbox, self.pa, batch.is_empty()) else {
            return Vec::new();
        };
        let count = batch.len() as u64;
        let queued = outbox.try_send((pa, Message::Requests(Requests::from(batch))));
        self.handling_ns += handling.elapsed().as_nanos() as u64;
        let mut message = match queued {
            Err(TrySendError::Full((_, Message::Requests(back)))) if !self.waits => return back.requests,
            Err(TrySendError::Full(message)) => message,
            // Queued; or the courier is gone, which happens only after the PR's last send.
            _ => {
                self.sent += count;
                return Vec::new();
            }
        };
        self.sent += count;
        let (waited, counted) = (Instant::now(), self.idle_ns.load(Relaxed));
        while let Err(TrySendError::Full(back)) = outbox.try_send(message) {
            message = back;
            if self.early.borrow().is_some() {
                std::thread::sleep(OUTBOX_PAUSE);
            } else if let Some(answer) = self.comm.receive(&[kind(Some(0), Kind::Work)], Some(OUTBOX_PAUSE)) {
                *self.early.borrow_mut() = Some(answer);
            }
        }
        // All of it idle, less what the receives above have counted already.
        let counted = self.idle_ns.load(Relaxed) - counted;
        let idle = (waited.elapsed().as_nanos() as u64).saturating_sub(counted);
        self.idle_ns.fetch_add(idle, Relaxed);
        Vec::new()
    }
}

/// How long a renderer waiting for room in its outbox waits between looks.
const OUTBOX_PAUSE: Duration = Duration::from_millis(1);

/// The master's answer to a PR's `ask` (its next tile and records), taken in while the renderer
/// waits for room in a full outbox (--pr-waits). The master waits for its answer to leave (a
/// standard MPI send of a large message waits for its receiver), and while it waits it takes in
/// no PA's status; a PA whose status is not taken in computes nothing, so its queue stays full,
/// the PR's courier waits for it, and the outbox stays full: a cycle that held until the
/// master's --timeout (conference room, 320x240, -ab 2, 4 ranks, progressive build, the PA's
/// queue at --pa-queue's 65536). Taking the answer in breaks it; `Pr::answer` reads it. Without
/// --pr-waits the PR does not wait at all (`OwnRequests`).
type EarlyAnswer = RefCell<Option<Envelope>>;

/// The requests a PR computed itself, its outbox being full. Their results wait for the help
/// phase (sent before the PR first reports itself idle, while the master sends it nothing), and
/// the records they made go out with that report.
#[derive(Default)]
struct OwnRequests {
    stats: ThreadStats,
    results: Vec<RequestResult>,
    computed: u64,
}

impl OwnRequests {
    fn compute(&mut self, integrator: &Integrator<'_>, batch: Vec<AmbientRequest>, seed: u64) {
        for request in &batch {
            compute_request(integrator, request, seed, &mut self.stats, &mut self.results);
        }
        self.computed += batch.len() as u64;
    }
}

/// Batches sent to one PA between two markers (see `deliver`).
const WINDOW: usize = 16;

/// The courier thread: sends the request batches, and after every WINDOW batches to a PA a
/// marker (an empty batch) as a synchronous send, which completes once that PA has taken in
/// everything before it; it waits for a PA's previous marker before sending the next, so at
/// most 2 x WINDOW batches wait for a PA. A PA with a full queue takes nothing in: the courier
/// waits, the outbox fills and the renderer computes its next batches itself (back-pressure),
/// while a PA that keeps up costs the PR nothing. It ends once every marker is taken in: nothing is still on its way
/// when the PR reports itself idle.
fn deliver(counters: &Counters, inbox: Receiver<(i32, Message)>) {
    let comm = Comm::new(counters);
    let mut windows: HashMap<i32, (usize, Option<Marker>)> = HashMap::new();
    for (pa, batch) in inbox {
        comm.send(pa, &batch);
        let (sent, marker) = windows.entry(pa).or_default();
        *sent += 1;
        if *sent % WINDOW == 0 {
            if let Some(previous) = marker.take() {
                comm.wait_marker(previous);
            }
            *marker = Some(comm.send_marker(pa));
        }
    }
    for marker in windows.into_values().filter_map(|(_, marker)| marker) {
        comm.wait_marker(marker);
    }
}

/// A PR's work and what it has to show for it, rendering tiles, then helping.
struct Pr<'a, 'c> {
    setup: &'a Setup<'a>,
    comm: Comm<'c>,
    early: &'c EarlyAnswer,
    own: OwnRequests,
    integrator: Integrator<'a>,
    stats: ThreadStats,
    intake: Intake,
}

pub fn run(setup: &Setup<'_>, roles: &Roles) {
    let counters = Counters::default();
    let courier_counters = Counters::default();
    let sink = RequestBuffer::default();
    let early = EarlyAnswer::default();
    let mut integrator = setup.integrator();
    if !roles.pas.is_empty() {
        integrator = integrator.deferring(&sink);
    }
    let mut pr = Pr {
        setup,
        comm: Comm::new(&counters),
        early: &early,
        own: OwnRequests::default(),
        integrator,
        stats: ThreadStats::default(),
        intake: Intake::default(),
    };
    let clock = ThreadClock::start();
    let (outbox, inbox) = sync_channel(outbox_batches(setup.job_in.pa_queue, setup.job_in.send));
    let mut sender = Sender {
        outbox: Some(outbox),
        pa_of_tile: pa_of_tiles(&setup.tiles, roles.pas.len())
            .into_iter()
            .filter_map(|i| roles.pas.get(i).copied())
            .collect(),
        pa: None,
        sent: 0,
        handling_ns: 0,
        waits: setup.job_in.pr_waits,
        idle_ns: &counters.idle_ns,
        comm: Comm::new(&counters),
        early: &early,
    };
    std::thread::scope(|scope| {
        let courier = scope.spawn(|| deliver(&courier_counters, inbox));
        pr.render_tiles(&mut sender, &sink);
        let left = sender.send(&sink);
        pr.own.compute(&pr.integrator, left, setup.job_in.seed);
        // No more requests: the courier ends once it has delivered what it holds. Every batch
        // must have reached its PA before this PR counts as flushed (the master may end the job
        // once the counts close, and a PA stops taking requests then).
        sender.outbox = None;
        let waited = Instant::now();
        let _ = courier.join();
        counters.idle_ns.fetch_add(waited.elapsed().as_nanos() as u64, Relaxed);
    });
    let helped = pr.help(sender.sent);
    pr.stats.absorb(&pr.own.stats);
    clock.stop(&mut pr.stats);

    let mut report = setup.report(&pr.comm, "pr", vec![pr.stats], &courier_counters);
    (report.records_received, report.records_rejected) = pr.intake.totals();
    report.requests_sent = sender.sent;
    report.request_handling_s = sender.handling_ns as f64 * 1e-9;
    report.requests_computed = helped;
    report.requests_kept = pr.own.computed;
    send_report(&pr.comm, report);
}

impl Pr<'_, '_> {
    /// Asks the master for a tile, with the report of the tile finished before (if any).
    fn ask(&self, finished: Option<FinishedTile>) {
        self.comm.send(0, &Message::WorkRequest { thread: 0, finished });
    }

    /// The master's answer to `ask`: a tile or none, and the records this PR lacks.
    fn answer(&self) -> Option<u32> {
        let taken_early = self.early.borrow_mut().take();
        let reply = match taken_early {
            Some(reply) => reply,
            None => self.comm.receive(&[kind(Some(0), Kind::Work)], None)?,
        };
        let Ok(Message::Work { tile, records, .. }) = reply.message else {
            return None;
        };
        if let Some(cache) = self.setup.cache() {
            self.intake.take(cache, records);
        }
        tile
    }

    /// Tiles until the master has none left, their requests going out through `sender` every
    /// --send. A PR asks for its next tile as it starts the current one, so the master's round
    /// trip (a few tenths of a millisecond; a 16x16 tile is under one) overlaps the rendering;
    /// the request carries the tile finished before, and the records that
    /// come with the next tile are one tile older.
    fn render_tiles(&mut self, sender: &mut Sender<'_>, sink: &RequestBuffer) {
        let send_at = self.setup.job_in.send.max(1) as usize;
        self.ask(None);
        let mut finished: Option<FinishedTile> = None;
        loop {
            while let Some(index) = self.answer() {
                self.ask(finished.take());
                let tile = &self.setup.tiles[index as usize];
                sender.pa = sender.pa_of_tile.get(index as usize).copied();
                // The outgoing buffer is empty here (flushed at every tile's end), so what this
                // tile sent is the change in the count sent.
                let (sent_before, own_before) = (sender.sent, self.own.computed);
                let (camera, settings) = (&self.setup.job.camera, &self.setup.job.settings);
                let (integrator, own, seed) = (&self.integrator, &mut self.own, self.setup.job_in.seed);
                // A tile this PR began during the prepass is finished from its traces (`ahead`).
                let traced = self.setup.traced.lock().unwrap_or_else(|e| e.into_inner()).take(index);
                let rays = &mut self.stats.rays;
                let pixels = render_tile_from(integrator, camera, settings, tile, traced, rays, |_| {
                    if sink.len() >= send_at {
                        own.compute(integrator, sender.send(sink), seed);
                    }
                });
                // The tile's last requests go to its PA now, not with the next tile's.
                own.compute(integrator, sender.send(sink), seed);
                // Every request of the tile, sent or computed here: the results it awaits.
                let requests = (sender.sent - sent_before + own.computed - own_before) as u32;
                let job = &self.setup.job;
                ErrorProbe::new(&self.integrator, &job.camera, &job.settings).tile(
                    &mut self.stats.error,
                    tile,
                    &pixels,
                );
                finished = Some(self.setup.finished_tile(index, requests, pixels));
                self.stats.tiles += 1;
            }
            // The last tile's report still has to reach the master: one more request (its
            // answer is no tile; were it one, the loop renders it).
            let Some(last) = finished.take() else { break };
            self.ask(Some(last));
        }
    }

    /// Helping: computes what the master has a PA forward until FINISH, reporting itself idle
    /// each time it runs out with the requests it `sent` and helped with (which it returns).
    fn help(&mut self, sent: u64) -> u64 {
        let (setup, comm, intake) = (self.setup, &self.comm, &self.intake);
        let seed = setup.job_in.seed;
        let pixels = setup.job.camera.width * setup.job.camera.height;
        let mut results = std::mem::take(&mut self.own.results);
        let mut helped = 0u64;
        loop {
            send_results(comm, &mut results);
            let records = Records::from(setup.cache().map_or_else(Vec::new, |c| c.take_outbox()));
            comm.send(0, &Message::Idle { sent, helped, records });
            // Forwarded requests from any PA, or the master's FINISH.
            let filters = [kind(Some(0), Kind::Finish), kind(None, Kind::Forwarded)];
            let Some(msg) = comm.receive(&filters, None) else {
                break;
            };
            match msg.message {
                Ok(Message::Forwarded(decoded)) => {
                    // The records made since this PR's last tile or sync first: the share is a
                    // stretch next to what the PAs have been computing, and without their latest
                    // records the helper made them again (the paper's helpers sync as often as
                    // PAs, section 5.3).
                    if let Some(cache) = setup.cache() {
                        send_results(comm, &mut results);
                        intake.sync(comm, 0, cache);
                    }
                    // Grid pixels first, as a PA computes its queue (see `order`).
                    let mut share = RequestQueue::new(setup.job.camera.width, setup.job.settings.overture);
                    share.extend(decoded.requests.iter().filter(|r| r.pixel < pixels).copied());
                    while let Some(request) = share.pop() {
                        compute_request(&self.integrator, &request, seed, &mut self.stats, &mut results);
                        // A helper shares its records as often as a PA does.
                        if let Some(cache) = setup.cache()
                            && cache.outbox_len() >= setup.sync
                        {
                            send_results(comm, &mut results);
                            intake.sync(comm, 0, cache);
                        }
                    }
                    // Refused requests are counted as computed (with nothing added) so the
                    // totals still close; the refusal is reported in the statistics.
                    let outside = decoded.requests.iter().filter(|r| r.pixel >= pixels).count();
                    helped += (decoded.requests.len() + decoded.rejected) as u64;
                    intake.reject(decoded.rejected + outside);
                }
                Ok(_) => break,
                Err(_) => intake.reject(1),
            }
        }
        helped
    }
}

/// Which PA (an index below `pas`) each tile's requests go to: the image cut into as many
/// vertical bands as there are PAs, by a tile's left edge; horizontal bands where there are
/// fewer tile columns than PAs, and tile i to PA i mod n where there are fewer rows too. Only
/// where two bands meet do two PAs make records for neighbouring points without each other's.
/// Tile i to PA i mod n made every tile border such a seam: at 5 processes (two PAs) 770-836
/// records on scenes/cornell.gltf (128x128, -aa 0.2, 32x32 tiles, progressive), one PA 733-774,
/// bands 742-789 (six runs; broadcast 782-812).
fn pa_of_tiles(tiles: &[crate::tiles::Tile], pas: usize) -> Vec<usize> {
    let pas = pas.max(1);
    let distinct = |key: fn(&crate::tiles::Tile) -> u32| {
        let mut keys: Vec<u32> = tiles.iter().map(key).collect();
        keys.sort_unstable();
        keys.dedup();
        keys
    };
    let (columns, rows) = (distinct(|t| t.x0), distinct(|t| t.y0));
    let band = |starts: &[u32], start: u32| {
        let place = starts.partition_point(|&s| s < start);
        place * pas / starts.len()
    };
    tiles
        .iter()
        .enumerate()
        .map(|(i, t)| {
            if columns.len() >= pas {
                band(&columns, t.x0)
            } else if rows.len() >= pas {
                band(&rows, t.y0)
            } else {
                i % pas
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::{MAX_BATCHES_IN_FLIGHT, MIN_BATCHES_IN_FLIGHT, outbox_batches, pa_of_tiles};
    use crate::tiles::tiles;

    #[test]
    fn the_outbox_holds_a_pa_queue_of_requests_within_bounds() {
        // The defaults: 65,536 requests in batches of 32.
        assert_eq!(outbox_batches(65536, 32), 2048);
        // A part batch still needs its slot.
        assert_eq!(outbox_batches(1000, 32), 32);
        // A short --pa-queue keeps the old floor; --send 0 counts as 1.
        assert_eq!(outbox_batches(8, 32), MIN_BATCHES_IN_FLIGHT);
        assert_eq!(outbox_batches(100, 0), 100);
        assert_eq!(outbox_batches(u32::MAX, 1), MAX_BATCHES_IN_FLIGHT);
    }

    #[test]
    fn tiles_go_to_their_pa_in_vertical_bands_else_rows_else_one_by_one() {
        // 8 x 4 tiles, 3 PAs: columns 0-2 to PA 0, 3-5 to PA 1, 6-7 to PA 2, whatever the row.
        let grid = tiles(128, 64, 16, 16);
        let pa = pa_of_tiles(&grid, 3);
        for (t, &p) in grid.iter().zip(&pa) {
            assert_eq!(p, (t.x0 / 16) as usize * 3 / 8, "tile at {},{}", t.x0, t.y0);
        }
        // One column of tiles: bands of rows.
        let column = tiles(16, 64, 16, 16);
        assert_eq!(pa_of_tiles(&column, 2), vec![0, 0, 1, 1]);
        // Two tiles, three PAs: one by one.
        assert_eq!(pa_of_tiles(&tiles(32, 16, 16, 16), 3), vec![0, 1]);
        // Every PA gets tiles wherever there are at least as many columns or rows as PAs.
        for pas in 1..=8 {
            let pa = pa_of_tiles(&grid, pas);
            assert!((0..pas).all(|p| pa.contains(&p)), "{pas} PAs: {pa:?}");
        }
    }
}

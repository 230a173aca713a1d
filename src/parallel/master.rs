//! The one master controller (rank 0) of every mode: hands out tiles on demand, takes finished
//! tiles (into the image, or only into the --checkpoint journal), relays shared records (and
//! keeps the -af file), gathers the ranks' statistics, and ends the job naming a rank that falls
//! silent. It renders nothing. How records are shared, and when the render is complete, is the
//! mode's `Sharing` policy (`worker::TraditionalSharing`, `component::master`).

use super::comm::{Comm, Hosts};
use super::liveness::Silence;
use super::protocol::{FinishedTile, Message, ProtocolError, Records, TilePixels};
use super::relay::RecordRelay;
use super::{ParallelError, ParallelResult};
use super::{Setup, end_job};
use crate::diagnostics::warn;
use crate::image::framebuffer::FrameBuffer;
use crate::image::layered_exr::StreamedExr;
use crate::render::sink::TileSink;
use crate::stats::{RankReport, RenderStats};
use crate::tiles::TileQueue;
use std::collections::{HashSet, VecDeque};
use std::convert::Infallible;
use std::time::Instant;

/// A mode's way of sharing records, as the master sees it.
pub trait Sharing {
    /// Before any tile: what the workers start from (by default, the cache file's records).
    fn start(&mut self, core: &mut MasterCore<'_, '_>) {
        let initial = Message::InitialRecords(core.setup.initial_records());
        (1..core.comm.size()).for_each(|worker| core.send(worker, &initial));
    }
    /// The records that go with a tile (or with "no tile left") to `rank`.
    fn records_with_work(&mut self, _core: &mut MasterCore<'_, '_>, _rank: i32) -> Records {
        Records::default()
    }
    /// A message of the mode's own.
    fn on_message(&mut self, core: &mut MasterCore<'_, '_>, source: i32, message: Message) -> Result<(), String>;
    /// Whether the render is complete.
    fn finished(&self, core: &MasterCore<'_, '_>) -> bool;
    /// The line that ends the job when `silence` holds.
    fn lost(&self, core: &MasterCore<'_, '_>, silence: &Silence) -> String {
        lost_rank(silence, &core.setup.hosts)
    }
    /// After the render is complete: the rest of the job (component mode gathers the images).
    fn gather(&mut self, _core: &mut MasterCore<'_, '_>) -> Result<(), String> {
        Ok(())
    }
}

/// What every mode's master has and does.
pub struct MasterCore<'a, 'c> {
    pub comm: &'a Comm<'c>,
    pub setup: &'a Setup<'a>,
    pub queue: TileQueue,
    /// Tiles each rank began during the prepass (`Setup::claims`) and has not been given yet.
    claimed: Vec<VecDeque<u32>>,
    /// Where finished tiles go: the EXR's stream as they come (the default build: a tile comes
    /// complete), or a frame held whole (--denoise; the progressive modes, whose indirect
    /// light may come after its tile).
    image: TileSink<'a>,
    tiles_done: Vec<bool>,
    pub relay: RecordRelay<'a>,
    pub reports: Vec<Option<RankReport>>,
    /// Work requests answered with "no tile left".
    pub turned_away: usize,
    /// Tiles that came as the file's chunks.
    pub tiles_encoded: u64,
    /// The finished tiles' bytes, and the seconds storing them.
    pub tile_bytes: u64,
    pub tiles_s: f64,
}

impl<'a, 'c> MasterCore<'a, 'c> {
    fn new(comm: &'a Comm<'c>, setup: &'a Setup<'a>, stream: Option<&'a StreamedExr>) -> Self {
        let (size, tiles) = (comm.size() as usize, setup.tiles.len());
        let (tiles_done, todo) = match &setup.checkpoint {
            Some((_, restored)) => (restored.done.clone(), restored.unfinished()),
            None => (vec![false; tiles], (0..tiles).collect()),
        };
        let restored = setup.checkpoint.as_ref().map(|(_, restored)| restored);
        let image = match stream {
            Some(stream) => TileSink::streamed(stream, setup.prepass.as_ref(), restored.map(|r| (&setup.tiles[..], r))),
            None => TileSink::held(restored.map_or_else(
                || FrameBuffer::new(setup.job_in.width, setup.job_in.height),
                |r| r.frame.clone(),
            )),
        };
        // A claimed tile goes to its rank alone; one an earlier run finished (--checkpoint) to nobody.
        let unfinished: HashSet<usize> = todo.iter().copied().collect();
        let claimed: Vec<VecDeque<u32>> = (0..size)
            .map(|rank| {
                let claims = setup.claims.get(rank).map_or(&[][..], Vec::as_slice);
                claims
                    .iter()
                    .copied()
                    .filter(|&t| unfinished.contains(&(t as usize)))
                    .collect()
            })
            .collect();
        let taken: HashSet<usize> = claimed.iter().flatten().map(|&t| t as usize).collect();
        let todo = todo.into_iter().filter(|t| !taken.contains(t)).collect();
        MasterCore {
            comm,
            setup,
            queue: TileQueue::new(todo),
            claimed,
            image,
            tiles_done,
            relay: RecordRelay::new(size, setup.cache()),
            reports: vec![None; size],
            turned_away: 0,
            tiles_encoded: 0,
            tile_bytes: 0,
            tiles_s: 0.0,
        }
    }

    /// Sends to `dest`, waiting at most --timeout for the message to leave: a standard MPI send
    /// of a message too large to go eagerly waits until the receiver takes it, and one whose
    /// host or link is gone never does, so the master, and the job, would hang. Past the timeout
    /// the job ends as on any other failure, naming the rank and host that stopped taking messages.
    pub fn send(&self, dest: i32, message: &Message) {
        let limit = self.setup.job_in.silence_limit;
        self.comm.send_within(dest, message, limit, || -> Infallible {
            let (host, seconds) = (self.setup.hosts.of(dest), limit.as_secs_f64());
            let line = format!(
                "rank {dest} (host {host}) took no message from the master for {seconds:.0} s: its host or link is \
                 gone, or it hangs"
            );
            end_job(self.comm, self.setup.cache(), &line)
        });
    }

    /// Whether every tile has been handed out (claimed ones included).
    pub fn all_out(&self) -> bool {
        self.queue.all_out() && self.claimed.iter().all(VecDeque::is_empty)
    }

    pub fn workers(&self) -> usize {
        self.reports.len() - 1
    }

    pub fn every_report_in(&self) -> bool {
        self.reports[1..].iter().all(Option::is_some)
    }

    /// The next message from any rank; Err once a rank the master still waits for is lost.
    pub fn receive(&self, awaited: impl Fn(i32) -> bool) -> Result<(i32, Result<Message, String>), Silence> {
        let limit = self.setup.job_in.silence_limit;
        let envelope = self.comm.receive_live(&[(None, None)], limit, awaited)?;
        let source = envelope.source;
        let malformed = |e: ProtocolError| format!("rank {source} sent a malformed message: {e}");
        Ok((source, envelope.message.map_err(malformed)))
    }

    /// A sync of `source`'s rendering thread `thread`: its new records for those it lacks.
    pub fn sync(&mut self, source: i32, thread: u32, records: Records) {
        self.relay.share(source as usize, records);
        let records = self.relay.catch_up(source as usize);
        self.send(source, &Message::RecordsDown { thread, records });
    }

    /// A finished tile from `source`: into the journal and the image.
    fn take_tile(&mut self, source: i32, finished: FinishedTile) -> Result<(), String> {
        let index = finished.tile;
        let tile = self
            .setup
            .tiles
            .get(index as usize)
            .filter(|_| !self.tiles_done[index as usize])
            .ok_or_else(|| format!("rank {source} returned tile {index}, which it was not given"))?;
        let pixels_in_tile = ((tile.x1 - tile.x0) * (tile.y1 - tile.y0)) as usize;
        let began = Instant::now();
        self.tile_bytes += finished.pixels.wire_bytes() as u64;
        match finished.pixels {
            TilePixels::Values(pixels) => {
                if pixels.len() != pixels_in_tile {
                    return Err(format!("rank {source} returned tile {index} with the wrong size"));
                }
                if let Some((journal, _)) = &self.setup.checkpoint {
                    journal.tile(index, finished.requests, &pixels);
                }
                self.image.store(tile, pixels);
            }
            // Encoded only where the master streams and journals nothing (`JobHost::tile_layout`).
            TilePixels::Encoded(encoded) => {
                if encoded.preview.len() != pixels_in_tile || self.setup.checkpoint.is_some() {
                    return Err(format!("rank {source} returned tile {index} encoded for another file"));
                }
                self.image
                    .store_encoded(tile, &encoded)
                    .map_err(|e| format!("rank {source} returned tile {index}: {e}"))?;
                self.tiles_encoded += 1;
            }
        }
        self.tiles_s += began.elapsed().as_secs_f64();
        self.tiles_done[index as usize] = true;
        Ok(())
    }

    /// What the core handles in every mode; the rest goes back to the policy.
    pub fn handle(&mut self, sharing: &mut dyn Sharing, source: i32, message: Message) -> Result<(), String> {
        match message {
            Message::WorkRequest { thread, finished } => {
                if let Some(finished) = finished {
                    self.take_tile(source, finished)?;
                }
                let claimed = self.claimed.get_mut(source as usize).and_then(VecDeque::pop_front);
                let tile = claimed.or_else(|| self.queue.next().map(|i| i as u32));
                self.turned_away += usize::from(tile.is_none());
                let records = sharing.records_with_work(self, source);
                self.send(source, &Message::Work { thread, tile, records });
            }
            Message::Stats(report) => self.reports[source as usize] = Some(*report),
            Message::Results(results) => {
                if let Some((journal, _)) = &self.setup.checkpoint {
                    journal.results(&results);
                }
                // Indirect light computed elsewhere for a pixel, before or after its tile came
                // (`tiles::store_tile` adds to what the pixel has).
                let Some(frame) = self.image.held_mut() else {
                    return Err(format!(
                        "rank {source} sent indirect light for pixels whose tiles went to the file as they came"
                    ));
                };
                for r in results {
                    frame.add(r.pixel as usize, r.layer, r.value);
                }
            }
            other => sharing.on_message(self, source, other)?,
        }
        Ok(())
    }
}

/// The master's part: the one master with the mode's policy, then the image, statistics, table.
pub fn run(comm: &Comm<'_>, setup: &Setup<'_>, sharing: &mut dyn Sharing, wall: Instant) -> ParallelResult {
    let (job_in, job) = (setup.job_in, &setup.job);
    // With the prepass every tile comes complete (its indirect light read from the finished
    // record set), so it can go to the file as it comes.
    let streamed = match setup.prepass.is_some() {
        true => job_in
            .host
            .stream(job, comm.size() as usize)
            .unwrap_or_else(|e| end_job(comm, setup.cache(), &e)),
        false => None,
    };
    let MasterOutcome {
        image,
        ranks,
        render_s,
        tiles_encoded,
    } = control(comm, setup, sharing, streamed.as_ref()).unwrap_or_else(|e| end_job(comm, setup.cache(), &e));
    let frame = image.into_frame(setup.prepass.as_ref());
    if let Some(cache) = setup.cache()
        && let Err(e) = cache.finish()
    {
        warn(&format!("cache file not fully written: {e}"));
    }
    let mut stats = job_in
        .host
        .job_stats(job, job_in.mode.name(), comm.size() as usize, render_s);
    stats.threads = job_in.threads.unwrap_or(1);
    stats.tiles_restored = setup.checkpoint.as_ref().map_or(0, |(_, r)| r.count()) as u64;
    stats.tiles_encoded = tiles_encoded;
    stats.add_ranks(ranks);
    if let Some(prepass) = &setup.prepass {
        stats.add_prepass(prepass);
    }
    stats.wall_s = wall.elapsed().as_secs_f64();
    match (streamed, frame) {
        (Some(streamed), _) => job_in.host.finish_stream(job, streamed, &stats),
        (None, Some(frame)) => job_in.host.write(job, &frame, &stats),
        (None, None) => Err("the master held no frame and streamed none".to_string()),
    }
    .map_err(ParallelError::Failed)?;
    if !job_in.quiet {
        print_table(&stats);
    }
    Ok(())
}

/// What the master's part of the render leaves: the image (streamed or held), the workers'
/// reports, the render's seconds and how many tiles came encoded.
struct MasterOutcome<'a> {
    image: TileSink<'a>,
    ranks: Vec<RankReport>,
    render_s: f64,
    tiles_encoded: u64,
}

/// The render under the mode's policy: the image, every rank's report and the render's seconds.
fn control<'a>(
    comm: &'a Comm<'_>,
    setup: &'a Setup<'a>,
    sharing: &mut dyn Sharing,
    stream: Option<&'a StreamedExr>,
) -> Result<MasterOutcome<'a>, String> {
    let start = Instant::now();
    let mut core = MasterCore::new(comm, setup, stream);
    sharing.start(&mut core);
    while !sharing.finished(&core) {
        let reports = &core.reports;
        let (source, message) = core
            .receive(|r| reports[r as usize].is_none())
            .map_err(|silence| sharing.lost(&core, &silence))?;
        core.handle(sharing, source, message?)?;
    }
    if !core.all_out() {
        let left = core.queue.len() - core.queue.handed_out() + core.claimed.iter().map(VecDeque::len).sum::<usize>();
        return Err(format!("{left} tiles were not rendered"));
    }
    let render_s = start.elapsed().as_secs_f64();
    sharing.gather(&mut core)?;
    let mut ranks = vec![RankReport {
        records_received: core.relay.received,
        records_rejected: core.relay.rejected,
        wall_s: start.elapsed().as_secs_f64(),
        prepass_s: setup.prepass.as_ref().map_or(0.0, |p| p.seconds),
        prepass_pool_s: setup.prepass.as_ref().map_or(0.0, |p| p.pool_s),
        prepass_fit_s: setup.prepass.as_ref().map_or(0.0, |p| p.fit_s),
        tile_bytes: core.tile_bytes,
        tiles_s: core.tiles_s,
        ..super::traffic_report(0, "mc", &[comm.counters], comm.counters.idle_s())
    }];
    ranks.extend(core.reports.into_iter().skip(1).flatten());
    Ok(MasterOutcome {
        image: core.image,
        ranks,
        render_s,
        tiles_encoded: core.tiles_encoded,
    })
}

/// The line that ends a job when a rank has fallen silent.
pub fn lost_rank(silence: &Silence, hosts: &Hosts) -> String {
    let (rank, host, seconds) = (silence.rank, hosts.of(silence.rank), silence.seconds);
    format!(
        "rank {rank} (host {host}) has been silent for {seconds:.0} s: its host or link is gone, or it hangs; the \
         cache file keeps every record synced before"
    )
}

/// The per-rank statistics as a table on stderr.
fn print_table(stats: &RenderStats) {
    eprintln!(
        "icrender: {} mode, {} ranks, {}x{} in {:.2} s{}",
        stats.mode,
        stats.ranks,
        stats.width,
        stats.height,
        stats.render_s,
        stats
            .error_estimate
            .as_ref()
            .map_or_else(String::new, |e| format!(", {}", e.summary()))
    );
    eprintln!(
        "{:>4} {:>6} {:>6} {:>9} {:>9} {:>8} {:>9} {:>8} {:>8} {:>11}",
        "rank", "role", "tiles", "records", "lookups", "T_amb", "T_notamb", "idle", "msgs", "bytes"
    );
    let all = RankReport {
        tiles: stats.per_rank.iter().map(|r| r.tiles).sum(),
        records_computed: stats.records_computed,
        lookups: stats.lookups,
        t_amb_s: stats.t_amb_s,
        t_notamb_s: stats.t_notamb_s,
        idle_s: stats.idle_s,
        messages: stats.messages,
        bytes: stats.bytes,
        ..Default::default()
    };
    let rows = stats.per_rank.iter().map(|r| (r.rank.to_string(), r));
    for (rank, r) in rows.chain([("all".to_string(), &all)]) {
        eprintln!(
            "{rank:>4} {:>6} {:>6} {:>9} {:>9} {:>8.2} {:>9.2} {:>8.2} {:>8} {:>11}",
            r.role, r.tiles, r.records_computed, r.lookups, r.t_amb_s, r.t_notamb_s, r.idle_s, r.messages, r.bytes
        );
    }
}

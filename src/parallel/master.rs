//! The one master controller (rank 0), whatever the mode: hands out tiles on demand (the one
//! `TileQueue`), takes finished tiles (into the image, or only into the --checkpoint journal),
//! relays shared records (`RecordRelay`, which also keeps the -af file), gathers the ranks'
//! statistics, and ends the job naming a rank that falls silent. It renders nothing itself.
//! How records are shared, and when the render is complete, is the mode's `Sharing` policy:
//! `sharing.rs` holds the traditional modes' (paper, section 4), `component::master` component
//! mode's (section 5).

use super::comm::{Comm, Hosts};
use super::liveness::Silence;
use super::protocol::{FinishedTile, Message, Records};
use super::relay::RecordRelay;
use crate::checkpoint::{Checkpoint, Restored};
use crate::image::framebuffer::FrameBuffer;
use crate::irradiance::IrradianceCache;
use crate::stats::RankReport;
use crate::tiles::{Tile, TileQueue, store_tile};
use std::convert::Infallible;
use std::time::{Duration, Instant};

pub struct MasterResult {
    pub frame: FrameBuffer,
    pub ranks: Vec<RankReport>,
    pub render_s: f64,
}

/// What the master controls.
pub struct Plan<'a> {
    pub tiles: &'a [Tile],
    pub width: u32,
    pub height: u32,
    /// The cache holding the -af file's records (the master renders nothing with it).
    pub cache: Option<&'a IrradianceCache>,
    /// How long a rank may be silent before it counts as lost.
    pub timeout: Duration,
    /// Each rank's host, for messages that name a rank.
    pub hosts: &'a Hosts,
    /// The --checkpoint journal and what an earlier run finished (those tiles are not handed out).
    pub resume: Option<(&'a Checkpoint, &'a Restored)>,
    /// Every worker already holds the cache's records (the prepass shared them).
    pub workers_have_cache: bool,
}

impl Plan<'_> {
    /// The records of the cache file the workers do not hold yet.
    pub fn initial_records(&self) -> Records {
        match self.cache {
            Some(c) if !self.workers_have_cache => Records::from(c.records()),
            _ => Records::default(),
        }
    }
}

/// A mode's way of sharing records, as the master sees it.
pub trait Sharing {
    /// Before any tile: what the workers start from (by default, every worker the records of
    /// the cache file it lacks).
    fn start(&mut self, core: &mut MasterCore<'_, '_>) {
        let initial = Message::InitialRecords(core.plan.initial_records());
        for worker in 1..core.comm.size() {
            core.send(worker, &initial);
        }
    }
    /// Whether a finished tile's pixels are the image's (they are not when the worker keeps
    /// part of its light to send with its whole image at the end).
    fn keeps_tiles(&self) -> bool {
        true
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
        lost_rank(silence, core.plan.hosts)
    }
    /// After the render is complete: the rest of the job (component mode gathers the images).
    fn gather(&mut self, _core: &mut MasterCore<'_, '_>) -> Result<(), String> {
        Ok(())
    }
}

/// What every mode's master has and does.
pub struct MasterCore<'a, 'c> {
    pub comm: &'a Comm<'c>,
    pub plan: &'a Plan<'a>,
    pub queue: TileQueue,
    pub frame: FrameBuffer,
    tiles_done: Vec<bool>,
    pub relay: RecordRelay<'a>,
    pub reports: Vec<Option<RankReport>>,
    /// Work requests answered with "no tile left".
    pub turned_away: usize,
}

impl<'a, 'c> MasterCore<'a, 'c> {
    fn new(comm: &'a Comm<'c>, plan: &'a Plan<'a>) -> Self {
        let size = comm.size() as usize;
        let (frame, tiles_done, todo) = match plan.resume {
            Some((_, restored)) => (restored.frame.clone(), restored.done.clone(), restored.unfinished()),
            None => (
                FrameBuffer::new(plan.width, plan.height),
                vec![false; plan.tiles.len()],
                (0..plan.tiles.len()).collect(),
            ),
        };
        MasterCore {
            comm,
            plan,
            queue: TileQueue::new(todo),
            frame,
            tiles_done,
            relay: RecordRelay::new(size, plan.cache),
            reports: vec![None; size],
            turned_away: 0,
        }
    }

    /// Sends to `dest`, waiting at most the timeout for the message to leave. The master's
    /// --timeout must hold whatever a worker's host does, but a standard MPI send of a message
    /// too large to go eagerly waits until the receiver takes it, and a receiver whose host or
    /// link is gone never does: the master would hang there, past its timeout, and so would the
    /// job. Past the timeout the job ends as on any other failure (the cache file keeps what it
    /// has), naming the rank and host that stopped taking messages.
    pub fn send(&self, dest: i32, message: &Message) {
        let limit = self.plan.timeout;
        self.comm.send_within(dest, message, limit, || -> Infallible {
            let line = format!(
                "rank {dest} (host {}) took no message from the master for {:.0} s: its host or link is gone, or \
                 it hangs",
                self.plan.hosts.of(dest),
                limit.as_secs_f64()
            );
            super::end_job(self.comm, self.plan.cache, &line)
        });
    }

    pub fn workers(&self) -> usize {
        self.reports.len() - 1
    }

    pub fn every_report_in(&self) -> bool {
        self.reports[1..].iter().all(Option::is_some)
    }

    /// The next message from any rank; Err once a rank the master still waits for is lost.
    pub fn receive(&self, awaited: impl Fn(i32) -> bool) -> Result<(i32, Result<Message, String>), Silence> {
        let envelope = self.comm.receive_live(&[(None, None)], self.plan.timeout, awaited)?;
        let source = envelope.source;
        Ok((
            source,
            envelope
                .message
                .map_err(|e| format!("rank {source} sent a malformed message: {e}")),
        ))
    }

    /// A sync of `source`'s rendering thread `thread`: its new records join the relay, and it
    /// gets those of the others it lacks.
    pub fn sync(&mut self, source: i32, thread: u32, records: Records) {
        self.relay.share(source as usize, records);
        let records = self.relay.catch_up(source as usize);
        self.send(source, &Message::RecordsDown { thread, records });
    }

    /// A finished tile from `source`: into the journal, and into the image if `keep`.
    fn take_tile(&mut self, source: i32, finished: FinishedTile, keep: bool) -> Result<(), String> {
        let (index, pixels) = (finished.tile, finished.pixels);
        let tile = self
            .plan
            .tiles
            .get(index as usize)
            .filter(|_| !self.tiles_done[index as usize])
            .ok_or_else(|| format!("rank {source} returned tile {index}, which it was not given"))?;
        if pixels.len() != ((tile.x1 - tile.x0) * (tile.y1 - tile.y0)) as usize {
            return Err(format!("rank {source} returned tile {index} with the wrong size"));
        }
        if let Some((journal, _)) = self.plan.resume {
            journal.tile(index, finished.requests, &pixels);
        }
        if keep {
            store_tile(&mut self.frame, tile, &pixels);
        }
        self.tiles_done[index as usize] = true;
        Ok(())
    }

    /// What the core handles in every mode; the rest goes back to the policy.
    pub fn handle(&mut self, sharing: &mut dyn Sharing, source: i32, message: Message) -> Result<(), String> {
        match message {
            Message::WorkRequest { thread, finished } => {
                if let Some(finished) = finished {
                    self.take_tile(source, finished, sharing.keeps_tiles())?;
                }
                let tile = self.queue.next().map(|i| i as u32);
                self.turned_away += usize::from(tile.is_none());
                let records = sharing.records_with_work(self, source);
                self.send(source, &Message::Work { thread, tile, records });
            }
            Message::Stats(report) => self.reports[source as usize] = Some(*report),
            Message::Results(results) => {
                if let Some((journal, _)) = self.plan.resume {
                    journal.results(&results);
                }
            }
            other => sharing.on_message(self, source, other)?,
        }
        Ok(())
    }
}

pub fn run(comm: &Comm<'_>, plan: &Plan<'_>, sharing: &mut dyn Sharing) -> Result<MasterResult, String> {
    let start = Instant::now();
    let mut core = MasterCore::new(comm, plan);
    sharing.start(&mut core);
    while !sharing.finished(&core) {
        let reports = &core.reports;
        let (source, message) = match core.receive(|r| reports[r as usize].is_none()) {
            Ok(received) => received,
            Err(silence) => return Err(sharing.lost(&core, &silence)),
        };
        core.handle(sharing, source, message?)?;
    }
    if !core.queue.all_out() {
        return Err(format!(
            "only {} of {} tiles were rendered",
            core.queue.handed_out(),
            core.queue.len()
        ));
    }
    let render_s = start.elapsed().as_secs_f64();
    sharing.gather(&mut core)?;
    let mut ranks = vec![RankReport {
        records_received: core.relay.received,
        records_rejected: core.relay.rejected,
        wall_s: start.elapsed().as_secs_f64(),
        ..super::traffic_report(0, "mc", &[comm.counters], comm.counters.idle_s())
    }];
    ranks.extend(core.reports.into_iter().skip(1).flatten());
    Ok(MasterResult {
        frame: core.frame,
        ranks,
        render_s,
    })
}

/// The line that ends a job when a rank has fallen silent.
pub fn lost_rank(silence: &Silence, hosts: &Hosts) -> String {
    format!(
        "rank {} (host {}) has been silent for {:.0} s: its host or link is gone, or it hangs; the cache \
         file keeps every record synced before",
        silence.rank,
        hosts.of(silence.rank),
        silence.seconds
    )
}

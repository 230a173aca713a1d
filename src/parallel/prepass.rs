//! The cache prepass under mpirun (see `crate::prepass`): the ranks pool their work through
//! MPI's collectives, never through the master. Worker k of W takes items k, k + W, ... of every
//! list (the last bounce's rows, the pixel maps' rows, each round's sites), and an allgather
//! hands every rank every worker's results; the master takes part with nothing of its own and
//! keeps the records (for the cache file and the report), nothing else. Every rank inserts the
//! same records in the same order, so all caches hold the record set one process would have
//! made, and the image is the same for any number of ranks and any mode.
//!
//! A collective cannot notice a rank that never comes. The master therefore looks at the
//! heartbeats (`liveness`) about once a second while it waits, and ends the job naming the rank
//! and host that fell silent; a worker's own pulse ends it when the master is gone.

use super::comm::{Comm, Hosts};
use super::protocol::{Message, ProtocolError, Records};
use crate::irradiance::IrradianceCache;
use crate::job::Job;
use crate::prepass::{GridRows, PixelRows, Pool, PrepassOutcome, RoundRecords, Share, run_shared};
use crate::shading::Integrator;
use std::time::Duration;

/// The ranks of one job as the prepass's pool.
struct Collective<'a, 'c> {
    /// Every rank.
    world: &'a Comm<'c>,
    /// The workers alone (None on the master), for what only rendering ranks need: the grid.
    workers: Option<Comm<'c>>,
    share: Share,
    hosts: &'a Hosts,
    /// How long a rank may be silent before it counts as lost.
    limit: Duration,
    /// The master's cache, kept (its file flushed) when the job ends for a lost rank.
    cache: &'a IrradianceCache,
}

impl Collective<'_, '_> {
    /// Every rank's `message`, decoded, by rank: of the world, or of the workers alone when
    /// `workers` (this rank must be one).
    fn gather(&self, workers: bool, message: Message) -> Result<Vec<Message>, String> {
        let (comm, first) = match &self.workers {
            Some(comm) if workers => (comm, 1),
            _ => (self.world, 0),
        };
        let kind = message.kind();
        let parts = comm.all_gather_bytes(&message.encode(), || self.watch())?;
        (parts.iter().enumerate())
            .map(|(part, bytes)| {
                Message::decode(kind.tag(), bytes).map_err(|ProtocolError(why)| {
                    let rank = first + part as i32;
                    format!(
                        "prepass: rank {rank} on {} sent a bad message: {why}",
                        self.hosts.of(rank)
                    )
                })
            })
            .collect()
    }

    /// Every rank's items of `message`'s kind, joined in rank order (`items` takes them out of
    /// a decoded message, which is always of the kind sent: `Message::decode` reads it as that).
    fn pooled<T>(
        &self,
        workers: bool,
        message: Message,
        items: impl Fn(Message) -> Option<Vec<T>>,
    ) -> Result<Vec<T>, String> {
        let parts = self.gather(workers, message)?;
        Ok(parts.into_iter().filter_map(items).flatten().collect())
    }

    /// Called while a collective waits: the master ends the job if a rank has gone silent
    /// (it can never come to the collective, which would wait for ever).
    fn watch(&self) {
        if self.world.rank() != 0 {
            return;
        }
        if let Some(lost) = super::liveness::lost(self.world.size(), self.limit, |_| true) {
            let (who, host, seconds) = (lost.rank, self.hosts.of(lost.rank), lost.seconds);
            let line = format!(
                "prepass: rank {who} on {host} has been silent for {seconds:.0} s (lost, or stalled); the cache \
                 file keeps every record of the rounds before"
            );
            super::end_job(self.world, Some(self.cache), &line)
        }
    }
}

impl Pool for Collective<'_, '_> {
    type Error = String;

    fn share(&self) -> Share {
        self.share
    }

    fn round(&mut self, mine: RoundRecords) -> Result<RoundRecords, String> {
        self.pooled(false, Message::PrepassRound(mine), |m| match m {
            Message::PrepassRound(records) => Some(records),
            _ => None,
        })
    }

    fn sites(&mut self, mine: Vec<u32>) -> Result<Vec<u32>, String> {
        self.pooled(false, Message::PrepassSites(mine), |m| match m {
            Message::PrepassSites(sites) => Some(sites),
            _ => None,
        })
    }

    fn grid_rows(&mut self, mine: GridRows) -> Result<GridRows, String> {
        debug_assert!(self.workers.is_some(), "only workers build the grid");
        self.pooled(true, Message::PrepassGrid(mine), |m| match m {
            Message::PrepassGrid(rows) => Some(rows),
            _ => None,
        })
    }

    fn pixel_rows(&mut self, mine: PixelRows) -> Result<PixelRows, String> {
        self.pooled(false, Message::PrepassPixels(mine), |m| match m {
            Message::PrepassPixels(rows) => Some(rows),
            _ => None,
        })
    }

    fn bytes_received(&self) -> u64 {
        self.world
            .counters
            .bytes_received
            .load(std::sync::atomic::Ordering::Relaxed)
    }
}

/// Runs this rank's part of the prepass. Err: a rank sent what cannot be trusted (the job cannot
/// go on: ranks would hold different caches); every rank reads the same bytes and so fails alike.
/// A rank that falls silent ends the job from the master (see `Collective::watch`).
pub fn run(comm: &Comm<'_>, job: &Job, limit: Duration, hosts: &Hosts) -> Result<PrepassOutcome, String> {
    let (rank, size) = (comm.rank(), comm.size());
    let Some(cache) = job.cache.as_ref() else {
        return Ok(PrepassOutcome::default());
    };
    let integrator = Integrator::new(&job.scene, &job.tracer, &job.shading, Some(cache));
    let share = match rank {
        0 => Share::Nothing,
        _ => Share::Slice {
            index: (rank - 1) as usize,
            count: (size - 1) as usize,
        },
    };
    let mut pool = Collective {
        world: comm,
        workers: comm.split(rank != 0),
        share,
        hosts,
        limit,
        cache,
    };
    // Every rank starts from the master's records (its cache file): a gather in which only the
    // master has any.
    let start = Records::from(if rank == 0 { cache.records() } else { Vec::new() });
    let parts = pool.gather(false, Message::PrepassStart(start))?;
    if rank != 0
        && let Some(Message::PrepassStart(start)) = parts.into_iter().next()
    {
        start.records.into_iter().for_each(|r| cache.insert_shared(r));
    }
    run_shared(&integrator, &job.camera, &job.settings, &mut pool)
}

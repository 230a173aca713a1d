//! The cache prepass under mpirun (see `crate::prepass`): the workers pool their work through
//! MPI's collectives on a communicator of their own, never through the master. Worker k of W
//! takes items k, k + W, ... of every list (the last bounce's rows, the pixel maps' rows, each
//! round's sites), and an allgather hands every worker every worker's results. Every worker
//! inserts the same records in the same order, so all caches hold the record set one process
//! would have made, and the image is the same for any number of ranks and any mode.
//!
//! The master takes no part in the rounds: it renders nothing, and a rank waiting in a
//! collective must poll it (every 0.2 ms), which on a machine with as many cores as workers took
//! time slices from the workers' rounds. The first worker hands it each round's records as they
//! join the set (`Message::PrepassKept`), point to point from a thread of its own, and the
//! master keeps them as the workers do (`prepass::keep_rounds`): the cache file grows round by
//! round, and the master's bytes grow with the records, not with the workers.
//!
//! In component mode a worker fills its waits in the rounds' collectives by tracing the tiles
//! it will render (`ahead`); after the prepass every rank learns which tiles each has begun.
//!
//! A collective cannot notice a rank that never comes, but the master is in none of the rounds:
//! it looks at the heartbeats (`liveness`) about once a second while it waits for the next
//! round, and ends the job naming the rank and host that fell silent, which ends the workers
//! waiting for that rank too; a worker's own pulse ends it when the master is gone.

use super::ahead::{AheadReport, TracedTiles, TracingAhead};
use super::comm::{Comm, Hosts, kind};
use super::protocol::{Kind, Message, ProtocolError, Records};
use crate::irradiance::IrradianceCache;
use crate::irradiance::record::Record;
use crate::job::Job;
use crate::prepass::{
    GridRows, Kept, PixelRows, Pool, PrepassOutcome, RoundLog, RoundRecords, Share, keep_rounds, run_shared,
};
use crate::shading::Integrator;
use std::cell::RefCell;
use std::sync::mpsc::{Sender, channel};
use std::time::Duration;

/// The workers of one job as the prepass's pool (seen from one of them).
struct Collective<'a, 'c> {
    /// The workers alone.
    workers: Comm<'c>,
    share: Share,
    /// The first worker's way to the master: each round's records as they are kept.
    to_master: Option<Sender<Message>>,
    /// What this worker does while it waits in a round's collectives (component mode).
    ahead: Option<RefCell<TracingAhead<'a>>>,
}

impl Collective<'_, '_> {
    /// Every worker's `message`, decoded, by worker. `fill`: the wait may be filled by tracing
    /// ahead (once the last bounce's grid, which the tracing reads, is built).
    fn gather(&self, message: Message, fill: bool) -> Result<Vec<Message>, String> {
        let kind = message.kind();
        let ahead = self.ahead.as_ref().filter(|_| fill);
        let step = || ahead.is_some_and(|a| a.borrow_mut().step());
        // A lost worker is noticed by the master, which ends the job (see the module's notes).
        let parts = self.workers.all_gather_bytes(&message.encode(), || {}, step)?;
        (parts.iter().enumerate())
            .map(|(part, bytes)| {
                Message::decode(kind.tag(), bytes).map_err(|ProtocolError(why)| {
                    // Worker k of the workers' communicator is rank k + 1.
                    format!("prepass: rank {} sent a bad message: {why}", part + 1)
                })
            })
            .collect()
    }

    /// Every worker's items of `message`'s kind, joined in worker order (`items` takes them out
    /// of a decoded message, which is always of the kind sent: `Message::decode` reads it as that).
    fn pooled<T>(&self, message: Message, items: impl Fn(Message) -> Option<Vec<T>>) -> Result<Vec<T>, String> {
        // Only the grid's rows come before the grid is built.
        let fill = !matches!(message, Message::PrepassGrid(_));
        let parts = self.gather(message, fill)?;
        Ok(parts.into_iter().filter_map(items).flatten().collect())
    }

    /// Hands the master a message (the first worker only), from the sending thread.
    fn tell_master(&self, message: Message) {
        if let Some(to_master) = &self.to_master {
            // The thread ends only after the prepass: the channel is open.
            let _ = to_master.send(message);
        }
    }
}

impl Pool for Collective<'_, '_> {
    type Error = String;

    fn share(&self) -> Share {
        self.share
    }

    fn round(&mut self, mine: RoundRecords) -> Result<RoundRecords, String> {
        self.pooled(Message::PrepassRound(mine), |m| match m {
            Message::PrepassRound(records) => Some(records),
            _ => None,
        })
    }

    fn sites(&mut self, mine: Vec<u32>) -> Result<Vec<u32>, String> {
        self.pooled(Message::PrepassSites(mine), |m| match m {
            Message::PrepassSites(sites) => Some(sites),
            _ => None,
        })
    }

    fn grid_rows(&mut self, mine: GridRows) -> Result<GridRows, String> {
        self.pooled(Message::PrepassGrid(mine), |m| match m {
            Message::PrepassGrid(rows) => Some(rows),
            _ => None,
        })
    }

    fn pixel_rows(&mut self, mine: PixelRows) -> Result<PixelRows, String> {
        self.pooled(Message::PrepassPixels(mine), |m| match m {
            Message::PrepassPixels(rows) => Some(rows),
            _ => None,
        })
    }

    fn bytes_received(&self) -> u64 {
        self.workers
            .counters
            .bytes_received
            .load(std::sync::atomic::Ordering::Relaxed)
    }

    fn kept(&mut self, log: RoundLog, records: &[(u32, Record)]) -> Result<(), String> {
        let records = records.to_vec();
        self.tell_master(Message::PrepassKept(Kept::Round(log, records)));
        Ok(())
    }

    fn ended(&mut self, pixels_sampled: u64) -> Result<(), String> {
        self.tell_master(Message::PrepassKept(Kept::End(pixels_sampled)));
        Ok(())
    }

    fn keeps(&self) -> bool {
        self.to_master.is_some()
    }
}

/// What a rank has when the prepass is done: the outcome, the tiles each rank has begun (by
/// rank: the claims), and this worker's traces of its own.
pub struct Prepassed {
    pub outcome: PrepassOutcome,
    pub claims: Vec<Vec<u32>>,
    pub traced: TracedTiles,
    pub ahead: AheadReport,
}

/// Runs this rank's part of the prepass; a worker given `ahead` fills its waits with it. Err: a
/// rank sent what cannot be trusted (the job cannot go on: ranks would hold different caches);
/// every rank reads the same bytes and so fails alike. A rank that falls silent ends the job
/// from the master (see `keep`).
pub fn run<'a>(
    comm: &'a Comm<'_>,
    job: &'a Job,
    limit: Duration,
    hosts: &'a Hosts,
    ahead: Option<TracingAhead<'a>>,
) -> Result<Prepassed, String> {
    let (rank, size) = (comm.rank(), comm.size());
    let Some(cache) = job.cache.as_ref() else {
        return Ok(Prepassed {
            outcome: PrepassOutcome::default(),
            claims: vec![Vec::new(); size as usize],
            traced: TracedTiles::default(),
            ahead: AheadReport::default(),
        });
    };
    let workers = comm.split(rank != 0);
    // Every rank starts from the master's records (its cache file): a gather in which only the
    // master has any.
    let start = Records::from(if rank == 0 { cache.records() } else { Vec::new() });
    let parts = comm.all_gather_bytes(&Message::PrepassStart(start).encode(), || {}, || false)?;
    if rank != 0 {
        let start = Message::decode(Kind::PrepassStart.tag(), &parts[0])
            .map_err(|ProtocolError(why)| format!("prepass: the master sent a bad message: {why}"))?;
        if let Message::PrepassStart(start) = start {
            start.records.into_iter().for_each(|r| cache.insert_shared(r));
        }
    }
    let (outcome, traced, ahead) = match workers {
        None => (
            keep(comm, job, cache, limit, hosts)?,
            TracedTiles::default(),
            AheadReport::default(),
        ),
        Some(workers) => {
            let integrator = Integrator::new(&job.scene, &job.tracer, &job.shading, Some(cache));
            let index = (rank - 1) as usize;
            std::thread::scope(|scope| {
                // The first worker's records go to the master from a thread of their own: a
                // send of a large round waits for the master to take it, and the master looks
                // for messages only every few milliseconds.
                let to_master = (index == 0).then(|| {
                    let (to_master, outbox) = channel::<Message>();
                    // The rank's own books: what it sends is counted as the rank's.
                    let counters = comm.counters;
                    scope.spawn(move || {
                        let comm = Comm::new(counters);
                        outbox.into_iter().for_each(|message| comm.send(0, &message));
                    });
                    to_master
                });
                let mut pool = Collective {
                    workers,
                    share: Share::Slice {
                        index,
                        count: (size - 1) as usize,
                    },
                    to_master,
                    ahead: ahead.map(RefCell::new),
                };
                let outcome = run_shared(&integrator, &job.camera, &job.settings, &mut pool);
                // Closing the channel ends the sending thread once it has sent everything.
                pool.to_master = None;
                let (traced, ahead) = pool.ahead.take().map(|a| a.into_inner().finish()).unwrap_or_default();
                outcome.map(|outcome| (outcome, traced, ahead))
            })?
        }
    };
    let claims = Message::TileClaims(traced.claims()).encode();
    let claims = (comm.all_gather_bytes(&claims, || {}, || false)?.iter())
        .map(|bytes| match Message::decode(Kind::TileClaims.tag(), bytes) {
            Ok(Message::TileClaims(tiles)) => Ok(tiles),
            _ => Err("prepass: a rank sent a bad list of tiles begun".to_string()),
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Prepassed {
        outcome,
        claims,
        traced,
        ahead,
    })
}

/// The master's part: keeps each round's records as the first worker hands them over, until
/// the rounds end. A rank silent for `limit` ends the job, naming it and its host, the cache
/// file keeping every record of the rounds before.
fn keep(
    comm: &Comm<'_>,
    job: &Job,
    cache: &IrradianceCache,
    limit: Duration,
    hosts: &Hosts,
) -> Result<PrepassOutcome, String> {
    let filters = [kind(Some(1), Kind::PrepassKept)];
    keep_rounds(cache, &job.camera, &job.settings, || {
        let envelope = comm.receive_live(&filters, limit, |_| true).unwrap_or_else(|lost| {
            let (who, host, seconds) = (lost.rank, hosts.of(lost.rank), lost.seconds);
            let line = format!(
                "prepass: rank {who} on {host} has been silent for {seconds:.0} s (lost, or stalled); the cache \
                 file keeps every record of the rounds before"
            );
            super::end_job(comm, Some(cache), &line)
        });
        match envelope.message {
            Ok(Message::PrepassKept(kept)) => Ok(kept),
            Ok(other) => Err(format!(
                "prepass: rank 1 sent an unexpected message ({:?})",
                other.kind()
            )),
            Err(ProtocolError(why)) => Err(format!("prepass: rank 1 on {} sent a bad message: {why}", hosts.of(1))),
        }
    })
}

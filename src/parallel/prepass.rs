//! The cache prepass under mpirun (see `crate::prepass`): before any tile is handed out, the
//! workers share each round's sites (worker k of W takes sites k, k + W, ...), send the
//! records they made to the master, and the master hands every worker the round's records
//! from all of them in site order. Every rank, the master included, inserts the same records
//! in the same order, so all caches hold the record set one process would have made, and the
//! image is the same for any number of ranks and any mode.

use super::comm::{Comm, Hosts, kind};
use super::protocol::{Kind, Message, Records};
use crate::job::Job;
use crate::prepass::{PrepassOutcome, RoundRecords, Share, run_shared};
use crate::shading::Integrator;
use std::time::Duration;

/// Runs this rank's part of the prepass. Err: a rank fell silent for `timeout`, or sent
/// records that cannot be trusted (the job cannot go on: ranks would hold different caches).
pub fn run(comm: &Comm<'_>, job: &Job, timeout: Duration, hosts: &Hosts) -> Result<PrepassOutcome, String> {
    let (rank, size) = (comm.rank(), comm.size());
    let workers = (size - 1).max(1) as usize;
    let Some(cache) = job.cache.as_ref() else {
        return Ok(PrepassOutcome::default());
    };
    let integrator = Integrator::new(&job.scene, &job.tracer, &job.shading, Some(cache));
    let mut failure: Option<String> = None;
    if rank == 0 {
        // Workers start from the master's records (its cache file), as the master does.
        let start = Message::PrepassStart(Records::from(cache.records()));
        for worker in 1..size {
            comm.send(worker, &start);
        }
        let mut gather = |_: RoundRecords| -> RoundRecords {
            if failure.is_some() {
                return Vec::new();
            }
            let mut round = Vec::new();
            for worker in 1..size {
                let message = comm.receive_live(&[kind(Some(worker), Kind::PrepassRound)], timeout, |_| true);
                match message.map(|m| m.message) {
                    Ok(Ok(Message::PrepassRound(records))) => round.extend(records),
                    Ok(other) => {
                        failure = Some(format!(
                            "prepass: rank {worker} on {} sent a bad round: {}",
                            hosts.of(worker),
                            other.err().map_or_else(|| "not a round".into(), |e| e.0)
                        ))
                    }
                    Err(lost) => {
                        failure = Some(format!(
                            "prepass: rank {} on {} has been silent for {:.0} s (lost, or stalled); the cache file keeps \
                             every record of the rounds before",
                            lost.rank,
                            hosts.of(lost.rank),
                            lost.seconds
                        ))
                    }
                }
            }
            round.sort_by_key(|(index, _)| *index);
            let message = Message::PrepassRound(round);
            for worker in 1..size {
                comm.send(worker, &message);
            }
            let Message::PrepassRound(round) = message else {
                unreachable!("built above")
            };
            round
        };
        let outcome = run_shared(&integrator, &job.camera, &job.settings, Share::Nothing, &mut gather);
        return failure.map_or(Ok(outcome), Err);
    }
    match comm
        .receive(&[kind(Some(0), Kind::PrepassStart)], Some(timeout))
        .map(|m| m.message)
    {
        Some(Ok(Message::PrepassStart(start))) => start.records.into_iter().for_each(|r| cache.insert_shared(r)),
        _ => return Err(format!("rank {rank}: prepass: no start from the master")),
    }
    let mut exchange = |mine: RoundRecords| -> RoundRecords {
        if failure.is_some() {
            return Vec::new();
        }
        comm.send(0, &Message::PrepassRound(mine));
        match comm
            .receive(&[kind(Some(0), Kind::PrepassRound)], Some(timeout))
            .map(|m| m.message)
        {
            Some(Ok(Message::PrepassRound(round))) => round,
            Some(other) => {
                failure = Some(format!(
                    "rank {rank}: prepass: bad round from the master: {}",
                    other.err().map_or_else(|| "not a round".into(), |e| e.0)
                ));
                Vec::new()
            }
            None => {
                failure = Some(format!(
                    "rank {rank} on {}: prepass: nothing from the master (rank 0 on {}) for {} s",
                    hosts.of(rank),
                    hosts.of(0),
                    timeout.as_secs()
                ));
                Vec::new()
            }
        }
    };
    let share = Share::Slice {
        index: (rank - 1) as usize,
        count: workers,
    };
    let outcome = run_shared(&integrator, &job.camera, &job.settings, share, &mut exchange);
    failure.map_or(Ok(outcome), Err)
}

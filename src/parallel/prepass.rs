//! The cache prepass under mpirun (see `crate::prepass`): before any tile is handed out, the
//! workers share each round's sites (worker k of W takes sites k, k + W, ...), send the
//! records they made to the master, and the master hands every worker the round's records
//! from all of them in site order. Every rank, the master included, inserts the same records
//! in the same order, so all caches hold the record set one process would have made, and the
//! image is the same for any number of ranks and any mode.

use super::comm::Comm;
use super::protocol::{
    TAG_PREPASS_DOWN, TAG_PREPASS_START, TAG_PREPASS_UP, decode_batch, decode_round, encode_batch, encode_round,
};
use crate::job::Job;
use crate::prepass::{PrepassOutcome, RoundRecords, Share, run_shared};
use crate::shading::Integrator;
use std::time::Duration;

/// Runs this rank's part of the prepass. Err: a rank fell silent for `timeout`, or sent
/// records that cannot be trusted (the job cannot go on: ranks would hold different caches).
pub fn run(comm: &Comm<'_>, job: &Job, timeout: Duration, hosts: &[String]) -> Result<PrepassOutcome, String> {
    let host = |rank: i32| hosts.get(rank as usize).map_or("?", String::as_str).to_string();
    let (rank, size) = (comm.rank(), comm.size());
    let workers = (size - 1).max(1) as usize;
    let Some(cache) = job.cache.as_ref() else {
        return Ok(PrepassOutcome::default());
    };
    let integrator = Integrator::new(&job.scene, &job.tracer, &job.shading, Some(cache));
    let mut failure: Option<String> = None;
    if rank == 0 {
        // Workers start from the master's records (its cache file), as the master does.
        let start = encode_batch(&cache.records(), 0);
        for worker in 1..size {
            comm.send(worker, TAG_PREPASS_START, &start);
        }
        let mut gather = |_: RoundRecords| -> RoundRecords {
            if failure.is_some() {
                return Vec::new();
            }
            let mut round = Vec::new();
            for worker in 1..size {
                let message = comm.receive(Some(worker), Some(TAG_PREPASS_UP), Some(timeout));
                match message.map(|m| decode_round(&m.data)) {
                    Some(Ok(records)) => round.extend(records),
                    Some(Err(e)) => {
                        failure = Some(format!(
                            "prepass: rank {worker} on {} sent a bad round: {}",
                            host(worker),
                            e.0
                        ))
                    }
                    None => {
                        failure = Some(format!(
                            "prepass: rank {worker} on {} sent no records for {} s (lost, or stalled); the cache file keeps \
                             every record of the rounds before",
                            host(worker),
                            timeout.as_secs()
                        ))
                    }
                }
            }
            round.sort_by_key(|(index, _)| *index);
            let message = encode_round(&round);
            for worker in 1..size {
                comm.send(worker, TAG_PREPASS_DOWN, &message);
            }
            round
        };
        let outcome = run_shared(&integrator, &job.camera, &job.settings, Share::Nothing, &mut gather);
        return failure.map_or(Ok(outcome), Err);
    }
    match comm
        .receive(Some(0), Some(TAG_PREPASS_START), Some(timeout))
        .map(|m| decode_batch(&m.data))
    {
        Some(Ok(batch)) => batch.records.into_iter().for_each(|r| cache.insert_shared(r)),
        _ => return Err(format!("rank {rank}: prepass: no start from the master")),
    }
    let mut exchange = |mine: RoundRecords| -> RoundRecords {
        if failure.is_some() {
            return Vec::new();
        }
        comm.send(0, TAG_PREPASS_UP, &encode_round(&mine));
        match comm
            .receive(Some(0), Some(TAG_PREPASS_DOWN), Some(timeout))
            .map(|m| decode_round(&m.data))
        {
            Some(Ok(round)) => round,
            Some(Err(e)) => {
                failure = Some(format!("rank {rank}: prepass: bad round from the master: {}", e.0));
                Vec::new()
            }
            None => {
                failure = Some(format!(
                    "rank {rank} on {}: prepass: nothing from the master (rank 0 on {}) for {} s",
                    host(rank),
                    host(0),
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

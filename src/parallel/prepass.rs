//! The cache prepass under mpirun (see `crate::prepass`): the workers share each round's sites
//! (worker k of W takes sites k, k + W, ...) and send their records to the master, which hands
//! every worker all of them in site order. Every rank, the master included, inserts the same
//! records in the same order, so all caches hold the record set one process would have made,
//! and the image is the same for any number of ranks and any mode.

use super::comm::{Comm, Hosts, kind};
use super::protocol::{Kind, Message, ProtocolError, Records};
use crate::job::Job;
use crate::prepass::{PrepassOutcome, RoundRecords, Share, run_shared};
use crate::shading::Integrator;
use std::time::Duration;

/// Runs this rank's part of the prepass. Err: a rank fell silent for `timeout`, or sent
/// records that cannot be trusted (the job cannot go on: ranks would hold different caches).
pub fn run(comm: &Comm<'_>, job: &Job, timeout: Duration, hosts: &Hosts) -> Result<PrepassOutcome, String> {
    let (rank, size) = (comm.rank(), comm.size());
    let Some(cache) = job.cache.as_ref() else {
        return Ok(PrepassOutcome::default());
    };
    let integrator = Integrator::new(&job.scene, &job.tracer, &job.shading, Some(cache));
    let bad = |other: Result<Message, ProtocolError>| other.err().map_or_else(|| "not a round".into(), |e| e.0);
    if rank == 0 {
        // Workers start from the master's records (its cache file), as the master does. Every
        // send waits at most --timeout (see `MasterCore::send`), or the master would hang on a
        // gone rank while the others time out waiting for it, and nobody would name the lost one.
        let send = |worker: i32, message: &Message| {
            comm.send_within(worker, message, timeout, || -> std::convert::Infallible {
                let (host, seconds) = (hosts.of(worker), timeout.as_secs_f64());
                let line = format!(
                    "prepass: rank {worker} on {host} took no round from the master for {seconds:.0} s: its host or \
                     link is gone, or it hangs; the cache file keeps every record of the rounds before"
                );
                super::end_job(comm, Some(cache), &line)
            })
        };
        let start = Message::PrepassStart(Records::from(cache.records()));
        (1..size).for_each(|worker| send(worker, &start));
        let mut gather = |_: RoundRecords| -> Result<RoundRecords, String> {
            let mut round = Vec::new();
            for worker in 1..size {
                let message = comm.receive_live(&[kind(Some(worker), Kind::PrepassRound)], timeout, |_| true);
                match message.map(|m| m.message) {
                    Ok(Ok(Message::PrepassRound(records))) => round.extend(records),
                    Ok(other) => {
                        let (host, why) = (hosts.of(worker), bad(other));
                        return Err(format!("prepass: rank {worker} on {host} sent a bad round: {why}"));
                    }
                    Err(lost) => {
                        let (who, host, seconds) = (lost.rank, hosts.of(lost.rank), lost.seconds);
                        return Err(format!(
                            "prepass: rank {who} on {host} has been silent for {seconds:.0} s (lost, or stalled); the \
                             cache file keeps every record of the rounds before"
                        ));
                    }
                }
            }
            // Every rank puts the round in site order itself (see `run_shared`).
            let message = Message::PrepassRound(round);
            (1..size).for_each(|worker| send(worker, &message));
            let Message::PrepassRound(round) = message else {
                unreachable!("built above")
            };
            Ok(round)
        };
        return run_shared(&integrator, &job.camera, &job.settings, Share::Nothing, &mut gather);
    }
    // A worker outwaits the master: the master needs up to --timeout to notice a silent rank
    // and up to another to give up sending to one, and only the master can say which rank was
    // lost. A master that is itself gone is noticed sooner by this rank's pulse (`liveness`).
    let patience = 2 * timeout;
    let start = comm.receive(&[kind(Some(0), Kind::PrepassStart)], Some(patience));
    let Some(Ok(Message::PrepassStart(start))) = start.map(|m| m.message) else {
        return Err(format!("rank {rank}: prepass: no start from the master"));
    };
    start.records.into_iter().for_each(|r| cache.insert_shared(r));
    let mut exchange = |mine: RoundRecords| -> Result<RoundRecords, String> {
        comm.send(0, &Message::PrepassRound(mine));
        let round = [kind(Some(0), Kind::PrepassRound)];
        match comm.receive(&round, Some(patience)).map(|m| m.message) {
            Some(Ok(Message::PrepassRound(round))) => Ok(round),
            Some(other) => Err(format!(
                "rank {rank}: prepass: bad round from the master: {}",
                bad(other)
            )),
            None => {
                let (host, master, seconds) = (hosts.of(rank), hosts.of(0), patience.as_secs());
                Err(format!(
                    "rank {rank} on {host}: prepass: nothing from the master (rank 0 on {master}) for {seconds} s"
                ))
            }
        }
    };
    let (index, count) = ((rank - 1) as usize, (size - 1) as usize);
    let share = Share::Slice { index, count };
    run_shared(&integrator, &job.camera, &job.settings, share, &mut exchange)
}

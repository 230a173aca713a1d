//! The component mode's master controller: tiles on demand to PRs (with the records each PR
//! lacks), the record relay for PAs and helpers at their syncs, load balancing
//! (`LoadBalancer`), the termination check (`TerminationLedger`), and the sum of every rank's
//! image.

use super::Roles;
use super::balancer::{LoadBalancer, Share};
use super::ledger::TerminationLedger;
use crate::checkpoint::{Checkpoint, Restored};
use crate::image::framebuffer::FrameBuffer;
use crate::irradiance::IrradianceCache;
use crate::parallel::comm::Comm;
use crate::parallel::liveness::{self, Silence};
use crate::parallel::master::lost_rank;
use crate::parallel::master_sends::MasterSends;
use crate::parallel::protocol::{FinishedTile, Message, Records};
use crate::parallel::relay::RecordRelay;
use crate::stats::RankReport;
use crate::tiles::{Tile, TileQueue};
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

pub struct ComponentResult {
    pub frame: FrameBuffer,
    pub ranks: Vec<RankReport>,
    pub render_s: f64,
}

/// What the master remembers of a PA for its report and for saying what a lost one held.
#[derive(Default)]
struct PaLog {
    done: u64,
    samples: Vec<(f64, u32)>,
}

#[allow(clippy::too_many_arguments)]
pub fn run(
    comm: &Comm<'_>,
    roles: &Roles,
    tiles: &[Tile],
    width: u32,
    height: u32,
    cache: Option<&IrradianceCache>,
    timeout: Duration,
    hosts: &[String],
    resume: Option<(&Checkpoint, &Restored)>,
    workers_have_cache: bool,
) -> Result<ComponentResult, String> {
    let host = |rank: i32| hosts.get(rank as usize).map_or("?", String::as_str).to_string();
    let start = Instant::now();
    let sends = MasterSends {
        comm,
        limit: timeout,
        hosts,
        cache,
    };
    let size = comm.size() as usize;
    // Tiles an earlier run finished (--checkpoint) are not handed out again.
    let queue = TileQueue::new(match resume {
        Some((_, restored)) => restored.unfinished(),
        None => (0..tiles.len()).collect(),
    });
    let journal = resume.map(|(journal, _)| journal);
    // The cache file's records (none to send when the prepass already gave every rank all):
    // PAs get them now, PRs with their first tile.
    let initial = match cache {
        Some(c) if !workers_have_cache => c.records(),
        _ => Vec::new(),
    };
    let mut relay = RecordRelay::new(size, cache);
    relay.preload(initial);
    for &pa in &roles.pas {
        sends.send(pa, &Message::InitialRecords(relay.catch_up(pa as usize)));
    }
    let mut balancer = LoadBalancer::new(&roles.pas);
    let mut ledger = TerminationLedger::new(&roles.pas, &roles.prs);
    let mut pa_logs: BTreeMap<i32, PaLog> = roles.pas.iter().map(|&r| (r, PaLog::default())).collect();
    let order = |share: Share, ledger: &mut TerminationLedger| {
        let message = Message::ForwardOrder {
            to: share.to as u32,
            count: share.count as u32,
            to_pa: share.to_pa,
        };
        sends.send(share.from, &message);
        if !share.to_pa {
            ledger.forward_ordered(share.to);
        }
    };

    while !ledger.complete() {
        let msg = comm
            .receive_live(&[(None, None)], timeout, |_| true)
            .map_err(|lost| silence(&lost, &pa_logs, &balancer, &ledger, &host))?;
        let source = msg.source;
        let message = msg
            .message
            .map_err(|e| format!("rank {source} sent a malformed message: {e}"))?;
        match message {
            Message::WorkRequest { finished, .. } => {
                if let Some(FinishedTile { tile, requests, pixels }) = finished {
                    let fits = tiles
                        .get(tile as usize)
                        .is_some_and(|t| ((t.x1 - t.x0) * (t.y1 - t.y0)) as usize == pixels.len());
                    if !fits {
                        return Err(format!("rank {source} reported tile {tile} with the wrong size"));
                    }
                    if let Some(journal) = journal {
                        journal.tile(tile, requests, &pixels);
                    }
                }
                let tile = queue.next().map(|i| i as u32);
                let work = Message::Work {
                    thread: 0,
                    tile,
                    records: relay.catch_up(source as usize),
                };
                sends.send(source, &work);
            }
            Message::Idle { sent, helped, records } => {
                relay.share(source as usize, records);
                ledger.pr_idle(source, sent, helped)?;
                if let Some(share) = balancer.pr_idle(source) {
                    order(share, &mut ledger);
                }
            }
            Message::Results(results) => {
                if let Some(journal) = journal {
                    journal.results(&results);
                }
            }
            Message::RecordsUp { thread, records } => {
                relay.share(source as usize, records);
                let reply = Message::RecordsDown {
                    thread,
                    records: relay.catch_up(source as usize),
                };
                sends.send(source, &reply);
            }
            Message::PaStatus {
                queue: queue_length,
                done,
                records,
            } => {
                relay.share(source as usize, records);
                let reply = Message::RecordsDown {
                    thread: 0,
                    records: relay.catch_up(source as usize),
                };
                sends.send(source, &reply);
                ledger.pa_done(source, done)?;
                let now = start.elapsed().as_secs_f64();
                let log = pa_logs.get_mut(&source).expect("a PA, or pa_done refused it");
                log.done = done;
                log.samples.push((now, queue_length as u32));
                balancer.report(source, queue_length, queue.all_out());
                for share in balancer.rebalance() {
                    order(share, &mut ledger);
                }
            }
            other => {
                return Err(format!("rank {source} sent an unexpected message ({:?})", other.kind()));
            }
        }
    }
    if !queue.all_out() {
        return Err(format!(
            "only {} of {} tiles were rendered",
            queue.handed_out(),
            queue.len()
        ));
    }
    let render_s = start.elapsed().as_secs_f64();

    // Everything is computed: collect the images and statistics. A PA may still send a status
    // (its last sync) after FINISH; it gets its answer so it can stop.
    for rank in 1..size as i32 {
        sends.send(rank, &Message::Finish);
    }
    let mut frame = match resume {
        Some((_, restored)) => restored.frame.clone(),
        None => FrameBuffer::new(width, height),
    };
    let mut images = 0;
    let mut has_image = vec![false; size];
    let mut reports: Vec<Option<RankReport>> = vec![None; size];
    while images < size - 1 || reports[1..].iter().any(Option::is_none) {
        let awaited = |r: i32| !has_image[r as usize] || reports[r as usize].is_none();
        let msg = comm
            .receive_live(&[(None, None)], timeout, awaited)
            .map_err(|lost| format!("{}; its image is missing", lost_rank(&lost, hosts)))?;
        let source = msg.source;
        match msg.message {
            Ok(Message::Image(floats)) => {
                let part = FrameBuffer::from_floats(width, height, &floats)
                    .ok_or_else(|| format!("rank {source} sent an image of the wrong size"))?;
                frame.accumulate(&part);
                images += 1;
                has_image[source as usize] = true;
            }
            Ok(Message::Stats(mut report)) => {
                if let Some(log) = pa_logs.get(&source)
                    && report.queue_lengths.is_empty()
                {
                    report.queue_lengths = log.samples.clone();
                }
                reports[source as usize] = Some(report);
            }
            Ok(Message::Results(results)) => {
                if let Some(journal) = journal {
                    journal.results(&results);
                }
            }
            Ok(Message::PaStatus { records, .. }) => {
                relay.keep(records);
                let reply = Message::RecordsDown {
                    thread: 0,
                    records: Records::default(),
                };
                sends.send(source, &reply);
            }
            other => {
                return Err(format!(
                    "rank {source} sent an unexpected message at the end: {:?}",
                    other.map(|m| m.kind())
                ));
            }
        }
    }
    let mut ranks = vec![RankReport {
        records_received: relay.received,
        records_rejected: relay.rejected,
        wall_s: start.elapsed().as_secs_f64(),
        ..crate::parallel::traffic_report(0, "mc", &[comm.counters], comm.counters.idle_s())
    }];
    ranks.extend(reports.into_iter().skip(1).flatten());
    Ok(ComponentResult { frame, ranks, render_s })
}

/// Why the job stops when a rank has been silent too long: which rank, who else went quiet,
/// and what is missing (a lost PA takes its queue with it, a PR that never finished leaves its
/// tiles' pixels undelivered).
fn silence(
    lost: &Silence,
    pa_logs: &BTreeMap<i32, PaLog>,
    balancer: &LoadBalancer,
    ledger: &TerminationLedger,
    host: &dyn Fn(i32) -> String,
) -> String {
    let quiet: Vec<String> = pa_logs
        .keys()
        .filter(|&&r| liveness::silent_for(r).as_secs_f64() >= lost.seconds * 0.9)
        .map(|r| {
            format!(
                "PA {r} (rank {r}, host {}, last queue {}, computed {})",
                host(*r),
                balancer.queue(*r),
                pa_logs[r].done
            )
        })
        .collect();
    let unfinished: Vec<String> = ledger
        .unflushed()
        .iter()
        .map(|r| format!("PR {r} (host {})", host(*r)))
        .collect();
    let list = |what: &str, items: &[String]| {
        if items.is_empty() {
            String::new()
        } else {
            format!("{what}: {}; ", items.join(", "))
        }
    };
    format!(
        "rank {} (host {}) has been silent for {:.0} s; {}{}missing: the indirect light of every pixel whose \
         requests those ranks held, and the pixels of unfinished PRs (requests reported sent {}, computed {})",
        lost.rank,
        host(lost.rank),
        lost.seconds,
        list("silent", &quiet),
        list("unfinished", &unfinished),
        ledger.sent(),
        ledger.computed(),
    )
}

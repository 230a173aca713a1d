//! The component mode's master controller: tiles on demand to PRs (with the records each PR
//! lacks), record relay for PAs at their syncs, load balancing, the termination check, and the
//! sum of every rank's image.
//!
//! Termination is counted, not guessed. Every request a PR makes goes to exactly one PA queue;
//! from there it is either computed by that PA or forwarded once to an idle PR, which computes
//! it. PRs report how many they sent once they have no tile left (cumulative, after flushing),
//! PAs report how many they computed whenever they sync or their queue runs dry, helping PRs
//! report how many they computed. When every PR has flushed, no forward order is outstanding,
//! and sent == computed by PAs + computed by helpers, every request has been computed exactly
//! once and nothing is in flight: then, and only then, FINISH goes out.

use super::*;
use crate::checkpoint::{Checkpoint, Restored, decode_results};
use crate::image::framebuffer::FrameBuffer;
use crate::irradiance::IrradianceCache;
use crate::parallel::comm::Comm;
use crate::parallel::master_sends::MasterSends;
use crate::parallel::protocol::{TAG_STATS, encode_work};
use crate::stats::RankReport;
use crate::tiles::Tile;
use std::collections::HashMap;
use std::time::{Duration, Instant};

/// A share smaller than this is not worth forwarding.
const MIN_SHARE: u64 = 2;
/// An idle PR takes this fraction (1/SHARE_DIVISOR) of the longest PA queue. Half, the first
/// choice, left the PA with nothing to do while the PR worked through its half (the simulation,
/// bench/icsim.py, put component mode's idle time on the Cornell box at 29-52 % at 4-16
/// processors with halves, 9-26 % with eighths, which made it the fastest mode there).
const SHARE_DIVISOR: u64 = 8;

pub struct ComponentResult {
    pub frame: FrameBuffer,
    pub ranks: Vec<RankReport>,
    pub render_s: f64,
}

#[derive(Default)]
struct PaState {
    queue: u64,
    done: u64,
    /// Ran dry after the last tile went out, and waits for a share of another PA's queue.
    waiting: bool,
    samples: Vec<(f64, u32)>,
    /// When it last reported (seconds since the start).
    last_report: f64,
}

#[derive(Default)]
struct PrState {
    flushed: bool,
    sent: u64,
    helped: u64,
    /// A forward order for this PR is on its way; the PR will report back.
    awaiting_forward: bool,
    waiting: bool,
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
    let todo: Vec<usize> = match resume {
        Some((_, restored)) => restored.unfinished(),
        None => (0..tiles.len()).collect(),
    };
    let journal = resume.map(|(journal, _)| journal);
    // Indirect light computed for requests, into the journal (--checkpoint only).
    let journal_results = |source: i32, data: &[u8]| -> Result<(), String> {
        let results = decode_results(data).ok_or_else(|| format!("rank {source} sent malformed results"))?;
        if let Some(journal) = journal {
            journal.results(&results);
        }
        Ok(())
    };
    let mut next_tile = 0usize;
    let mut tiles_given = 0usize;
    // The cache file's records (none to send when the prepass already gave every rank all).
    let mut store: Vec<(usize, Record)> = match cache {
        Some(c) if !workers_have_cache => c.records().into_iter().map(|r| (0, r)).collect(),
        _ => Vec::new(),
    };
    let mut seen = vec![0usize; size];
    let mut pas: HashMap<i32, PaState> = roles.pas.iter().map(|&r| (r, PaState::default())).collect();
    let mut prs: HashMap<i32, PrState> = roles.prs.iter().map(|&r| (r, PrState::default())).collect();
    let mut records_received = 0u64;
    let mut records_rejected = 0u64;
    let mut forwarded_orders = 0u64;
    // PAs start from the cache file's records; PRs get them with their first tile.
    let initial = encode_batch(&store.iter().map(|(_, r)| r.clone()).collect::<Vec<_>>(), 0);
    for &pa in &roles.pas {
        sends.send(pa, crate::parallel::protocol::TAG_INITIAL_RECORDS, &initial);
        seen[pa as usize] = store.len();
    }

    let persist = |records: &[Record]| {
        if let Some(cache) = cache {
            records.iter().for_each(|r| cache.insert(r.clone()));
        }
    };
    // Records the rank lacks, from every other rank, since its last sync.
    let catch_up = |store: &[(usize, Record)], seen: &mut [usize], rank: usize| -> Vec<u8> {
        let missing: Vec<Record> = store[seen[rank]..]
            .iter()
            .filter(|(from, _)| *from != rank)
            .map(|(_, r)| r.clone())
            .collect();
        seen[rank] = store.len();
        encode_batch(&missing, 0)
    };
    // Orders the PA with the longest queue (other than `to`) to send a share of it to `to`, an
    // idle PR or a PA that ran dry, if one is worth splitting; the share's size.
    let order_share = |sends: &MasterSends<'_, '_>, pas: &mut HashMap<i32, PaState>, to: i32, orders: &mut u64| {
        let to_a_pa = pas.contains_key(&to);
        let (&pa, longest) = pas.iter_mut().filter(|(r, _)| **r != to).max_by_key(|(_, s)| s.queue)?;
        let share = longest.queue / SHARE_DIVISOR;
        if share < MIN_SHARE {
            return None;
        }
        longest.queue -= share;
        let mut order = (to as u32).to_le_bytes().to_vec();
        order.extend_from_slice(&(share as u32).to_le_bytes());
        if to_a_pa {
            order.extend_from_slice(&FORWARD_TO_PA.to_le_bytes());
        }
        sends.send(pa, TAG_FORWARD_ORDER, &order);
        *orders += 1;
        Some(share)
    };
    // Gives an idle PR a share of the longest PA queue, if one is worth splitting.
    let dispatch = |sends: &MasterSends<'_, '_>,
                    pas: &mut HashMap<i32, PaState>,
                    pr: i32,
                    state: &mut PrState,
                    orders: &mut u64| {
        if order_share(sends, pas, pr, orders).is_none() {
            return false;
        }
        state.awaiting_forward = true;
        state.waiting = false;
        true
    };
    // Gives a PA that ran dry a share of another's queue (not in the paper, where only PRs
    // help): without it, once the tiles were out, PAs whose queues emptied sat idle while the
    // last shares were worked through elsewhere (bench/icsim.py: 7-24 ms of a 74 ms render at 16
    // workers on the Cornell box).
    let feed_pa = |sends: &MasterSends<'_, '_>, pas: &mut HashMap<i32, PaState>, pa: i32, orders: &mut u64| {
        let Some(share) = order_share(sends, pas, pa, orders) else {
            return false;
        };
        let state = pas.get_mut(&pa).expect("a PA");
        state.queue += share;
        state.waiting = false;
        true
    };

    let finished = |prs: &HashMap<i32, PrState>, pas: &HashMap<i32, PaState>| {
        let sent: u64 = prs.values().map(|p| p.sent).sum();
        let computed: u64 = prs.values().map(|p| p.helped).sum::<u64>() + pas.values().map(|p| p.done).sum::<u64>();
        prs.values().all(|p| p.flushed && !p.awaiting_forward) && sent == computed
    };

    while !finished(&prs, &pas) {
        let Some(msg) = comm.receive(None, None, Some(timeout)) else {
            // Say who went quiet and what is missing: a lost PA takes its queue with it, a PR
            // that never finished leaves its tiles' pixels undelivered.
            let now = start.elapsed().as_secs_f64();
            let mut quiet: Vec<(&i32, &PaState)> = pas
                .iter()
                .filter(|(_, p)| now - p.last_report >= timeout.as_secs_f64() * 0.9)
                .collect();
            quiet.sort_by_key(|(r, _)| **r);
            let pa_text: Vec<String> = quiet
                .iter()
                .map(|(r, p)| {
                    format!(
                        "PA {r} (rank {r}, host {}, last queue {}, computed {})",
                        host(**r),
                        p.queue,
                        p.done
                    )
                })
                .collect();
            let mut stuck: Vec<i32> = prs.iter().filter(|(_, p)| !p.flushed).map(|(r, _)| *r).collect();
            stuck.sort();
            let pr_text: Vec<String> = stuck.iter().map(|r| format!("PR {r} (host {})", host(*r))).collect();
            let sent: u64 = prs.values().map(|p| p.sent).sum();
            let computed: u64 = prs.values().map(|p| p.helped).sum::<u64>() + pas.values().map(|p| p.done).sum::<u64>();
            return Err(format!(
                "no message from any rank for {:.0} s; {}{}missing: the indirect light of every pixel whose \
                 requests those ranks held, and the pixels of unfinished PRs (requests reported sent {sent}, computed {computed})",
                timeout.as_secs_f64(),
                if pa_text.is_empty() {
                    String::new()
                } else {
                    format!("silent: {}; ", pa_text.join(", "))
                },
                if pr_text.is_empty() {
                    String::new()
                } else {
                    format!("unfinished: {}; ", pr_text.join(", "))
                },
            ));
        };
        let source = msg.source;
        let malformed = |what: &str, e: ProtocolError| format!("rank {source} sent a malformed {what}: {}", e.0);
        match msg.tag {
            TAG_PR_WORK_REQUEST => {
                if let Some((tile, requests, pixels)) =
                    decode_tile_report(&msg.data).map_err(|e| malformed("tile report", e))?
                {
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
                let assignment = todo.get(next_tile).map(|&i| i as u32);
                if assignment.is_some() {
                    next_tile += 1;
                    tiles_given += 1;
                }
                let work = encode_work(assignment);
                let mut reply = (work.len() as u32).to_le_bytes().to_vec();
                reply.extend(work);
                reply.extend(catch_up(&store, &mut seen, source as usize));
                sends.send(source, TAG_PR_WORK, &reply);
            }
            TAG_PR_IDLE => {
                let (counts, batch) =
                    decode_counts_and_records(&msg.data, 2).map_err(|e| malformed("idle report", e))?;
                records_received += batch.records.len() as u64;
                records_rejected += batch.rejected as u64;
                persist(&batch.records);
                store.extend(batch.records.into_iter().map(|r| (source as usize, r)));
                let state = prs
                    .get_mut(&source)
                    .ok_or_else(|| format!("rank {source} is not a PR but reported as one"))?;
                state.flushed = true;
                state.sent = counts[0];
                state.helped = counts[1];
                state.awaiting_forward = false;
                if !dispatch(&sends, &mut pas, source, state, &mut forwarded_orders) {
                    state.waiting = true;
                }
            }
            TAG_RESULTS => journal_results(source, &msg.data)?,
            TAG_PR_SYNC => {
                let batch = decode_batch(&msg.data).map_err(|e| malformed("record batch", e))?;
                records_received += batch.records.len() as u64;
                records_rejected += batch.rejected as u64;
                persist(&batch.records);
                store.extend(batch.records.into_iter().map(|r| (source as usize, r)));
                sends.send(source, TAG_PR_CATCH_UP, &catch_up(&store, &mut seen, source as usize));
            }
            TAG_PA_STATUS => {
                let (counts, batch) = decode_counts_and_records(&msg.data, 2).map_err(|e| malformed("status", e))?;
                records_received += batch.records.len() as u64;
                records_rejected += batch.rejected as u64;
                persist(&batch.records);
                store.extend(batch.records.into_iter().map(|r| (source as usize, r)));
                let reply = catch_up(&store, &mut seen, source as usize);
                sends.send(source, TAG_PA_STATUS_REPLY, &reply);
                let pa = pas
                    .get_mut(&source)
                    .ok_or_else(|| format!("rank {source} is not a PA but reported as one"))?;
                pa.queue = counts[0];
                pa.done = counts[1];
                pa.last_report = start.elapsed().as_secs_f64();
                pa.samples.push((start.elapsed().as_secs_f64(), counts[0] as u32));
                // A PA reports an empty queue when it runs dry; once every tile is out, no new
                // requests are coming its way but forwarded ones.
                pa.waiting = counts[0] == 0 && next_tile >= todo.len();
                let waiting: Vec<i32> = prs.iter().filter(|(_, p)| p.waiting).map(|(&r, _)| r).collect();
                for pr in waiting {
                    let state = prs.get_mut(&pr).expect("listed");
                    if !dispatch(&sends, &mut pas, pr, state, &mut forwarded_orders) {
                        break;
                    }
                }
                let mut dry: Vec<i32> = pas.iter().filter(|(_, p)| p.waiting).map(|(&r, _)| r).collect();
                dry.sort();
                for pa in dry {
                    if !feed_pa(&sends, &mut pas, pa, &mut forwarded_orders) {
                        break;
                    }
                }
            }
            other => return Err(format!("rank {source} sent an unexpected message (tag {other})")),
        }
    }
    if tiles_given != todo.len() {
        return Err(format!("only {tiles_given} of {} tiles were rendered", todo.len()));
    }
    let render_s = start.elapsed().as_secs_f64();

    // Everything is computed: collect the images and statistics. A PA may still send a status
    // (its last sync) after FINISH; it gets its answer so it can stop.
    for rank in 1..size as i32 {
        sends.send(rank, TAG_FINISH, &[]);
    }
    let mut frame = match resume {
        Some((_, restored)) => restored.frame.clone(),
        None => FrameBuffer::new(width, height),
    };
    let mut images = 0;
    let mut reports: Vec<Option<RankReport>> = vec![None; size];
    while images < size - 1 || reports[1..].iter().any(Option::is_none) {
        let Some(msg) = comm.receive(None, None, Some(timeout)) else {
            return Err(format!(
                "ranks did not send their images within {:.0} s",
                timeout.as_secs_f64()
            ));
        };
        match msg.tag {
            TAG_IMAGE => {
                let floats: Vec<f32> = msg
                    .data
                    .chunks_exact(4)
                    .map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes")))
                    .collect();
                let part = FrameBuffer::from_floats(width, height, &floats)
                    .filter(|_| floats.iter().all(|v| v.is_finite()))
                    .ok_or_else(|| format!("rank {} sent a malformed image", msg.source))?;
                frame.accumulate(&part);
                images += 1;
            }
            TAG_STATS => {
                let mut report: RankReport = serde_json::from_slice(&msg.data)
                    .map_err(|e| format!("rank {} sent unreadable statistics: {e}", msg.source))?;
                if let Some(pa) = pas.get(&msg.source)
                    && report.queue_lengths.is_empty()
                {
                    report.queue_lengths = pa.samples.clone();
                }
                reports[msg.source as usize] = Some(report);
            }
            TAG_RESULTS => journal_results(msg.source, &msg.data)?,
            TAG_PA_STATUS => {
                let (_, batch) = decode_counts_and_records(&msg.data, 2).map_err(|e| e.0)?;
                persist(&batch.records);
                sends.send(msg.source, TAG_PA_STATUS_REPLY, &encode_batch(&[], 0));
            }
            other => {
                return Err(format!(
                    "rank {} sent an unexpected message (tag {other}) at the end",
                    msg.source
                ));
            }
        }
    }
    let counters = comm.counters;
    use std::sync::atomic::Ordering::Relaxed;
    let mut ranks = vec![RankReport {
        rank: 0,
        role: "mc".into(),
        idle_s: counters.idle_s(),
        messages: counters.messages_sent.load(Relaxed),
        bytes: counters.bytes_sent.load(Relaxed),
        messages_received: counters.messages_received.load(Relaxed),
        bytes_received: counters.bytes_received.load(Relaxed),
        records_received,
        records_rejected,
        wall_s: start.elapsed().as_secs_f64(),
        ..Default::default()
    }];
    ranks.extend(reports.into_iter().skip(1).flatten());
    let _ = forwarded_orders;
    Ok(ComponentResult { frame, ranks, render_s })
}

//! Liveness: every rank hears from its master, and the master from every rank, at least every
//! `HEARTBEAT_INTERVAL` while a job runs. A pulse thread on each rank (`pulse`) sends a heartbeat
//! (one byte and MPI's envelope) that often and takes in the ones sent to it; every message a rank
//! receives, heartbeat or not, counts as word from its sender (`Comm` notes it here). So a
//! rank or host that is lost shows as silence, whatever the job is doing: the master ends the
//! job once a rank it still waits for has been silent for `--timeout`, naming it (see
//! `Silence`), and a worker whose master has been silent that long ends itself, for nothing
//! else would tell it that its master is gone (a cut-off host's ranks otherwise ran on after
//! mpirun was killed).

use super::counters::Counters;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// How often a rank says it is alive.
pub const HEARTBEAT_INTERVAL: Duration = Duration::from_secs(2);

/// When each rank of the job was last heard from, for this process.
struct Ledger {
    start: Instant,
    /// Milliseconds since `start` of the last message from each rank.
    heard_ms: Vec<AtomicU64>,
    /// The heartbeats' own traffic, for this rank's report.
    counters: Counters,
}

static LEDGER: OnceLock<Ledger> = OnceLock::new();

/// Starts the record of who was heard when: every rank counts as just heard from.
pub fn begin(ranks: usize) {
    LEDGER.get_or_init(|| Ledger {
        start: Instant::now(),
        heard_ms: (0..ranks).map(|_| AtomicU64::new(0)).collect(),
        counters: Counters::default(),
    });
}

/// A message from `rank` arrived.
pub fn heard(rank: i32) {
    if let Some(ledger) = LEDGER.get()
        && let Some(slot) = ledger.heard_ms.get(rank as usize)
    {
        slot.fetch_max(ledger.start.elapsed().as_millis() as u64, Ordering::Relaxed);
    }
}

/// How long `rank` has been silent (zero before `begin`).
pub fn silent_for(rank: i32) -> Duration {
    LEDGER.get().map_or(Duration::ZERO, |ledger| {
        let heard = ledger
            .heard_ms
            .get(rank as usize)
            .map_or(0, |h| h.load(Ordering::Relaxed));
        ledger.start.elapsed().saturating_sub(Duration::from_millis(heard))
    })
}

/// The heartbeats' traffic on this rank.
pub fn counters() -> Option<&'static Counters> {
    LEDGER.get().map(|ledger| &ledger.counters)
}

/// A rank that has been silent too long.
#[derive(Clone, Debug, PartialEq)]
pub struct Silence {
    pub rank: i32,
    pub seconds: f64,
}

/// Of the ranks `waiting_for` holds true for, the one silent longest, if that is `limit` or more.
pub fn lost(ranks: i32, limit: Duration, waiting_for: impl Fn(i32) -> bool) -> Option<Silence> {
    (1..ranks)
        .filter(|&r| waiting_for(r))
        .map(|r| (r, silent_for(r)))
        .filter(|(_, silent)| *silent >= limit)
        .max_by_key(|(_, silent)| *silent)
        .map(|(rank, silent)| Silence {
            rank,
            seconds: silent.as_secs_f64(),
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_longest_silence_past_the_limit_among_awaited_ranks_is_lost() {
        begin(4);
        heard(1);
        heard(2);
        heard(3);
        // Nobody has been silent for an hour; everybody has been for no time at all.
        assert_eq!(lost(4, Duration::from_secs(3600), |_| true), None);
        let silence = lost(4, Duration::ZERO, |r| r != 2).unwrap();
        assert!(silence.rank == 1 || silence.rank == 3);
        assert_eq!(lost(4, Duration::ZERO, |_| false), None, "only awaited ranks count");
        assert!(silent_for(2) < Duration::from_secs(60));
    }
}

//! The load balancer of component mode's master: an idle PR (the paper's helpers) and a PA that
//! ran dry once every tile is out get 1/SHARE_DIVISOR of the longest queue other than their own
//! (the dry PAs beyond the paper: without it they sat idle while the last shares were worked
//! through elsewhere; bench/icsim.py: 7-24 ms of a 74 ms render, 16 workers, Cornell box).

use std::collections::{BTreeMap, BTreeSet};

/// A share smaller than this is not worth forwarding.
pub const MIN_SHARE: u64 = 2;
/// A helper takes 1/SHARE_DIVISOR of the longest PA queue. Half left the PA with nothing to do
/// while the helper worked through it (simulated idle time, Cornell box, 4-16 processors:
/// 29-52 % with halves, 9-26 % with eighths, which made component mode the fastest there).
pub const SHARE_DIVISOR: u64 = 8;

/// An order for PA `from` to hand `count` of its queued requests to rank `to`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Share {
    pub from: i32,
    pub to: i32,
    pub count: u64,
    pub to_pa: bool,
}

#[derive(Debug, Default)]
pub struct LoadBalancer {
    /// Each PA's queue as last reported, less shares ordered away, plus shares ordered to it.
    queues: BTreeMap<i32, u64>,
    /// Idle PRs no share was found for yet.
    waiting_prs: BTreeSet<i32>,
    /// PAs that ran dry after the last tile went out.
    dry_pas: BTreeSet<i32>,
}

impl LoadBalancer {
    pub fn new(pas: &[i32]) -> Self {
        LoadBalancer {
            queues: pas.iter().map(|&r| (r, 0)).collect(),
            ..Default::default()
        }
    }

    pub fn queue(&self, pa: i32) -> u64 {
        self.queues.get(&pa).copied().unwrap_or(0)
    }

    /// A PA's status: with every tile out, an empty queue gets no new requests but shares.
    pub fn report(&mut self, pa: i32, queue: u64, tiles_all_out: bool) {
        self.queues.insert(pa, queue);
        if queue == 0 && tiles_all_out {
            self.dry_pas.insert(pa);
        } else {
            self.dry_pas.remove(&pa);
        }
    }

    /// The last tile is out: a PA whose last status was an empty queue is dry now. An idle PA
    /// sends no further status, so one that ran dry while tiles were still coming would
    /// otherwise wait for the end while another PA's queue is worked through (seen in
    /// tests/mpi.rs: 1 run in 5 the second PA never got a share).
    pub fn all_tiles_out(&mut self) {
        let empty = self.queues.iter().filter(|(_, q)| **q == 0).map(|(&r, _)| r);
        self.dry_pas.extend(empty);
    }

    /// A share of the longest queue other than `to`'s, if one is worth splitting.
    fn share_for(&mut self, to: i32) -> Option<Share> {
        let to_pa = self.queues.contains_key(&to);
        let (&from, queue) = self
            .queues
            .iter_mut()
            .filter(|(r, _)| **r != to)
            .max_by_key(|(_, q)| **q)?;
        let count = *queue / SHARE_DIVISOR;
        if count < MIN_SHARE {
            return None;
        }
        *queue -= count;
        if to_pa {
            *self.queues.get_mut(&to).expect("a PA") += count;
            self.dry_pas.remove(&to);
        }
        Some(Share { from, to, count, to_pa })
    }

    /// A PR has nothing left to do: a share for it, or it waits for one.
    pub fn pr_idle(&mut self, pr: i32) -> Option<Share> {
        let share = self.share_for(pr);
        if share.is_none() {
            self.waiting_prs.insert(pr);
        } else {
            self.waiting_prs.remove(&pr);
        }
        share
    }

    /// Shares for the waiting PRs, then for the dry PAs, while there are queues to split.
    pub fn rebalance(&mut self) -> Vec<Share> {
        let mut shares = Vec::new();
        for pr in self.waiting_prs.clone() {
            let Some(share) = self.share_for(pr) else { break };
            self.waiting_prs.remove(&pr);
            shares.push(share);
        }
        for pa in self.dry_pas.clone() {
            let Some(share) = self.share_for(pa) else { break };
            shares.push(share);
        }
        shares
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_idle_pr_gets_an_eighth_of_the_longest_queue() {
        let mut b = LoadBalancer::new(&[1, 2]);
        b.report(1, 80, false);
        b.report(2, 160, false);
        let share = b.pr_idle(5).unwrap();
        assert_eq!(
            share,
            Share {
                from: 2,
                to: 5,
                count: 20,
                to_pa: false
            }
        );
        assert_eq!(b.queue(2), 140);
    }

    #[test]
    fn small_queues_are_not_split_and_the_pr_waits_for_the_next_status() {
        let mut b = LoadBalancer::new(&[1]);
        b.report(1, 15, false);
        assert_eq!(b.pr_idle(4), None, "15 / 8 < MIN_SHARE");
        assert!(b.rebalance().is_empty());
        b.report(1, 64, false);
        assert_eq!(
            b.rebalance(),
            vec![Share {
                from: 1,
                to: 4,
                count: 8,
                to_pa: false
            }]
        );
        assert!(b.rebalance().is_empty(), "the PR no longer waits");
    }

    #[test]
    fn a_pa_that_ran_dry_after_the_last_tile_is_fed_from_another() {
        let mut b = LoadBalancer::new(&[1, 2]);
        b.report(1, 0, false);
        b.report(2, 40, false);
        assert!(b.rebalance().is_empty(), "tiles are still coming: not dry");
        b.report(1, 0, true);
        assert_eq!(
            b.rebalance(),
            vec![Share {
                from: 2,
                to: 1,
                count: 5,
                to_pa: true
            }]
        );
        assert_eq!((b.queue(1), b.queue(2)), (5, 35));
        assert!(b.rebalance().is_empty(), "fed: no longer dry");
    }

    #[test]
    fn a_pa_that_ran_dry_before_the_last_tile_is_fed_once_all_are_out() {
        // PA 1 reported an empty queue while tiles were still coming, and, idle, reports no more.
        let mut b = LoadBalancer::new(&[1, 2]);
        b.report(1, 0, false);
        b.report(2, 64, false);
        assert!(b.rebalance().is_empty(), "tiles are still coming: not dry");
        b.all_tiles_out();
        assert_eq!(
            b.rebalance(),
            vec![Share {
                from: 2,
                to: 1,
                count: 8,
                to_pa: true
            }]
        );
        assert_eq!((b.queue(1), b.queue(2)), (8, 56));
        assert!(b.rebalance().is_empty(), "fed: no longer dry");
    }
}

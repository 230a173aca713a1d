//! The termination ledger: when may component mode's master say FINISH? Every request a PR
//! makes goes to one PA queue, and is computed by that PA or forwarded once to a helper (an idle
//! PR, or a PA that ran dry). PRs report how many they sent once they have no tile left (after
//! every batch has reached its PA), PAs and helping PRs how many they computed. When every PR
//! has flushed, no forward order to a PR is outstanding, and sent == computed, every request
//! has been computed exactly once and nothing is in flight.

use std::collections::BTreeMap;

#[derive(Clone, Copy, Debug, Default)]
struct PrAccount {
    flushed: bool,
    sent: u64,
    helped: u64,
    /// A forward order for this PR is on its way; the PR will report back.
    awaiting_forward: bool,
}

#[derive(Debug, Default)]
pub struct TerminationLedger {
    prs: BTreeMap<i32, PrAccount>,
    pa_done: BTreeMap<i32, u64>,
}

impl TerminationLedger {
    pub fn new(pas: &[i32], prs: &[i32]) -> Self {
        TerminationLedger {
            prs: prs.iter().map(|&r| (r, PrAccount::default())).collect(),
            pa_done: pas.iter().map(|&r| (r, 0)).collect(),
        }
    }

    /// A PR has no tile left and has delivered every request: its totals so far.
    pub fn pr_idle(&mut self, pr: i32, sent: u64, helped: u64) -> Result<(), String> {
        let not_pr = || format!("rank {pr} is not a PR but reported as one");
        let account = self.prs.get_mut(&pr).ok_or_else(not_pr)?;
        (account.flushed, account.sent, account.helped, account.awaiting_forward) = (true, sent, helped, false);
        Ok(())
    }

    /// A forward order for `pr` went out: it will report again once it has computed it.
    pub fn forward_ordered(&mut self, pr: i32) {
        if let Some(account) = self.prs.get_mut(&pr) {
            account.awaiting_forward = true;
        }
    }

    /// A PA's count of requests computed (cumulative).
    pub fn pa_done(&mut self, pa: i32, done: u64) -> Result<(), String> {
        let not_pa = || format!("rank {pa} is not a PA but reported as one");
        *self.pa_done.get_mut(&pa).ok_or_else(not_pa)? = done;
        Ok(())
    }

    /// The requests PA `pa` has reported computed.
    pub fn computed_by(&self, pa: i32) -> u64 {
        self.pa_done.get(&pa).copied().unwrap_or(0)
    }

    pub fn sent(&self) -> u64 {
        self.prs.values().map(|p| p.sent).sum()
    }

    pub fn computed(&self) -> u64 {
        self.prs.values().map(|p| p.helped).sum::<u64>() + self.pa_done.values().sum::<u64>()
    }

    /// PRs that have not yet reported themselves out of tiles.
    pub fn unflushed(&self) -> Vec<i32> {
        self.prs.iter().filter(|(_, p)| !p.flushed).map(|(&r, _)| r).collect()
    }

    /// Every request is computed and nothing is in flight.
    pub fn complete(&self) -> bool {
        self.prs.values().all(|p| p.flushed && !p.awaiting_forward) && self.sent() == self.computed()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finish_waits_for_every_pr_every_request_and_every_forward() {
        let mut ledger = TerminationLedger::new(&[1], &[2, 3]);
        assert!(!ledger.complete(), "no PR has flushed yet");
        ledger.pr_idle(2, 10, 0).unwrap();
        ledger.pa_done(1, 10).unwrap();
        assert!(!ledger.complete(), "PR 3 still renders");
        assert_eq!(ledger.unflushed(), vec![3]);
        ledger.pr_idle(3, 5, 0).unwrap();
        assert!(!ledger.complete(), "5 requests not computed");
        // PR 2 is sent a share of the PA's queue: until it reports, nothing ends, even if the
        // counts happen to close meanwhile.
        ledger.forward_ordered(2);
        ledger.pa_done(1, 15).unwrap();
        assert!(!ledger.complete());
        ledger.pr_idle(2, 10, 0).unwrap();
        assert!(ledger.complete());
        assert_eq!((ledger.sent(), ledger.computed()), (15, 15));
    }

    #[test]
    fn helpers_count_as_computing_and_strangers_are_refused() {
        let mut ledger = TerminationLedger::new(&[1], &[2]);
        ledger.pr_idle(2, 8, 3).unwrap();
        ledger.pa_done(1, 5).unwrap();
        assert!(ledger.complete());
        assert!(ledger.pr_idle(1, 0, 0).is_err(), "a PA is not a PR");
        assert!(ledger.pa_done(2, 0).is_err(), "a PR is not a PA");
    }
}

//! Component mode's sharing policy for the one master (`parallel::master`): PRs get the records
//! they lack with every tile, PAs and helpers sync through the record relay, the load balancer
//! sends idle PRs and dry PAs shares of the longest queue, the termination ledger says when every
//! request is computed, and then the last results and every rank's statistics are gathered. A
//! PR's finished tiles and the PAs' results (a pixel's indirect light) make the image as they
//! come (`MasterCore`), so no rank sends a whole image.

use super::Roles;
use super::balancer::{LoadBalancer, Share};
use super::ledger::TerminationLedger;
use crate::parallel::liveness::{self, Silence};
use crate::parallel::master::{MasterCore, Sharing, lost_rank};
use crate::parallel::protocol::{Message, Records};

pub struct ComponentSharing {
    roles: Roles,
    balancer: LoadBalancer,
    ledger: TerminationLedger,
}

impl ComponentSharing {
    pub fn new(roles: Roles) -> Self {
        ComponentSharing {
            balancer: LoadBalancer::new(&roles.pas),
            ledger: TerminationLedger::new(&roles.pas, &roles.prs),
            roles,
        }
    }

    fn order(&mut self, core: &MasterCore<'_, '_>, share: Share) {
        let (to, count, to_pa) = (share.to as u32, share.count as u32, share.to_pa);
        core.send(share.from, &Message::ForwardOrder { to, count, to_pa });
        if !share.to_pa {
            self.ledger.forward_ordered(share.to);
        }
    }
}

impl Sharing for ComponentSharing {
    fn start(&mut self, core: &mut MasterCore<'_, '_>) {
        // The cache file's records: PAs get them now, PRs with their first tile.
        core.relay.preload(core.setup.initial_records().records);
        for &pa in &self.roles.pas {
            let records = core.relay.catch_up(pa as usize);
            core.send(pa, &Message::InitialRecords(records));
        }
    }

    fn records_with_work(&mut self, core: &mut MasterCore<'_, '_>, rank: i32) -> Records {
        core.relay.catch_up(rank as usize)
    }

    fn on_message(&mut self, core: &mut MasterCore<'_, '_>, source: i32, message: Message) -> Result<(), String> {
        match message {
            Message::Idle { sent, helped, records } => {
                core.relay.share(source as usize, records);
                self.ledger.pr_idle(source, sent, helped)?;
                if let Some(share) = self.balancer.pr_idle(source) {
                    self.order(core, share);
                }
                // A PR idles once no tile is left: the PAs that reported an empty queue before
                // are dry now.
                if core.all_out() {
                    self.balancer.all_tiles_out();
                    for share in self.balancer.rebalance() {
                        self.order(core, share);
                    }
                }
            }
            Message::RecordsUp { thread, records } => core.sync(source, thread, records),
            Message::PaStatus { queue, done, records } => {
                core.sync(source, 0, records);
                self.ledger.pa_done(source, done)?;
                self.balancer.report(source, queue, core.all_out());
                for share in self.balancer.rebalance() {
                    self.order(core, share);
                }
            }
            other => return Err(format!("rank {source} sent an unexpected message ({:?})", other.kind())),
        }
        Ok(())
    }

    fn finished(&self, _core: &MasterCore<'_, '_>) -> bool {
        self.ledger.complete()
    }

    /// Which rank, who else went quiet, and what is missing (a lost PA takes its queue with
    /// it, a PR that never finished leaves its tiles' pixels undelivered).
    fn lost(&self, core: &MasterCore<'_, '_>, lost: &Silence) -> String {
        let hosts = &core.setup.hosts;
        let quiet: Vec<String> = self
            .roles
            .pas
            .iter()
            .filter(|&&r| liveness::silent_for(r).as_secs_f64() >= lost.seconds * 0.9)
            .map(|&r| {
                let (host, queue, computed) = (hosts.of(r), self.balancer.queue(r), self.ledger.computed_by(r));
                format!("PA {r} (rank {r}, host {host}, last queue {queue}, computed {computed})")
            })
            .collect();
        let unfinished: Vec<String> = self
            .ledger
            .unflushed()
            .iter()
            .map(|&r| format!("PR {r} (host {})", hosts.of(r)))
            .collect();
        let list = |what: &str, items: &[String]| match items {
            [] => String::new(),
            _ => format!("{what}: {}; ", items.join(", ")),
        };
        let (silent, unfinished) = (list("silent", &quiet), list("unfinished", &unfinished));
        let (rank, host, seconds) = (lost.rank, hosts.of(lost.rank), lost.seconds);
        let (sent, computed) = (self.ledger.sent(), self.ledger.computed());
        format!(
            "rank {rank} (host {host}) has been silent for {seconds:.0} s; {silent}{unfinished}missing: the indirect \
             light of every pixel whose requests those ranks held, and the pixels of unfinished PRs (requests \
             reported sent {sent}, computed {computed})"
        )
    }

    /// Every request is computed: FINISH to every worker, then their statistics (a rank's last
    /// results come before them). A PA may still send a status (its last sync) after FINISH; it
    /// gets its answer so it can stop.
    fn gather(&mut self, core: &mut MasterCore<'_, '_>) -> Result<(), String> {
        (1..core.comm.size()).for_each(|rank| core.send(rank, &Message::Finish));
        while !core.every_report_in() {
            let reports = &core.reports;
            let (source, message) = core
                .receive(|r| reports[r as usize].is_none())
                .map_err(|lost| format!("{}; its statistics are missing", lost_rank(&lost, &core.setup.hosts)))?;
            match message? {
                common @ (Message::Stats(_) | Message::Results(_)) => core.handle(self, source, common)?,
                Message::PaStatus { records, .. } => {
                    core.relay.keep(records);
                    let (thread, records) = (0, Records::default());
                    core.send(source, &Message::RecordsDown { thread, records });
                }
                other => {
                    return Err(format!(
                        "rank {source} sent an unexpected message at the end ({:?})",
                        other.kind()
                    ));
                }
            }
        }
        Ok(())
    }
}

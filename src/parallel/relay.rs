//! The master's record relay (centralised sharing, and component mode's PAs and PRs): each rank
//! gets exactly the records the others shared since it last synced.

use super::protocol::Records;
use crate::irradiance::IrradianceCache;
use crate::irradiance::record::Record;

/// The record relay: every record a worker shares is counted, kept in the cache file and
/// remembered with the rank it came from, so that each rank can be sent exactly those it lacks
/// (the other ranks' since its last sync).
#[derive(Default)]
pub struct RecordRelay<'a> {
    /// Every shared record, with the rank that made it (0: the cache file's).
    store: Vec<(usize, Record)>,
    /// Per rank, how far into `store` it has been brought up to date.
    seen: Vec<usize>,
    /// Where shared records are kept for the -af file.
    cache: Option<&'a IrradianceCache>,
    pub received: u64,
    pub rejected: u64,
}

impl<'a> RecordRelay<'a> {
    pub fn new(ranks: usize, cache: Option<&'a IrradianceCache>) -> Self {
        RecordRelay {
            seen: vec![0; ranks],
            cache,
            ..Default::default()
        }
    }

    /// Records every rank is to be brought (the cache file's, which came from no rank).
    pub fn preload(&mut self, records: Vec<Record>) {
        self.store.extend(records.into_iter().map(|r| (0, r)));
    }

    /// Counts records that arrived and keeps them in the cache file, without relaying them
    /// (broadcast mode's, which their sender sends everyone itself, and the last ones).
    pub fn keep(&mut self, records: Records) -> Vec<Record> {
        self.received += records.records.len() as u64;
        self.rejected += records.rejected as u64;
        if let Some(cache) = self.cache {
            records.records.iter().for_each(|r| cache.insert(r.clone()));
        }
        records.records
    }

    /// Takes records from rank `from` to relay to the others.
    pub fn share(&mut self, from: usize, records: Records) {
        let records = self.keep(records);
        self.store.extend(records.into_iter().map(|r| (from, r)));
    }

    /// The records rank `rank` lacks, which it now has.
    pub fn catch_up(&mut self, rank: usize) -> Records {
        let missing: Vec<Record> = self.store[self.seen[rank]..]
            .iter()
            .filter(|(from, _)| *from != rank)
            .map(|(_, r)| r.clone())
            .collect();
        self.seen[rank] = self.store.len();
        Records::from(missing)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::irradiance::record::tests::flat_record;

    #[test]
    fn each_rank_gets_the_others_records_once() {
        let mut relay = RecordRelay::new(4, None);
        relay.preload(vec![flat_record(9.0, 1.0)]);
        assert_eq!(relay.catch_up(1).records.len(), 1);
        relay.share(1, Records::from(vec![flat_record(1.0, 1.0)]));
        relay.share(2, Records::from(vec![flat_record(2.0, 1.0), flat_record(3.0, 1.0)]));
        let values = |r: Records| r.records.iter().map(|r| r.value.x).collect::<Vec<_>>();
        // Rank 1 has the preloaded record already and made its own.
        assert_eq!(values(relay.catch_up(1)), vec![2.0, 3.0]);
        assert!(relay.catch_up(1).records.is_empty());
        assert_eq!(values(relay.catch_up(3)), vec![9.0, 1.0, 2.0, 3.0]);
        relay.share(3, Records::from(vec![flat_record(4.0, 1.0)]));
        assert_eq!(values(relay.catch_up(1)), vec![4.0]);
        assert_eq!(relay.received, 4);
        let kept = relay.keep(Records {
            records: vec![flat_record(5.0, 1.0)],
            rejected: 2,
        });
        assert_eq!((kept.len(), relay.received, relay.rejected), (1, 5, 2));
        // Rank 2 never synced: every record but its own, and not the kept one.
        assert_eq!(values(relay.catch_up(2)), vec![9.0, 1.0, 4.0]);
    }
}

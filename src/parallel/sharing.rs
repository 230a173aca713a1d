//! The traditional modes' sharing (paper, section 4): not at all (noshare), through the master
//! (centralised), or by every worker to every other (broadcast). `WorkerSharing` names the way,
//! which the workers follow (`worker`) and the master's policy, `TraditionalSharing`, answers.
//! In each, workers start from the cache file's records and the render is complete once every
//! rendering thread has been told "no tile left" and every rank has reported (in broadcast
//! mode, also once every worker's last batch has arrived).

use super::master::{MasterCore, Sharing};
use super::protocol::Message;

/// A traditional mode, as its workers share records.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WorkerSharing {
    /// noshare: each worker keeps its records; with -af they come to the master at the end.
    Kept,
    /// centralised: through the master, which answers with the records the worker lacks.
    ThroughMaster,
    /// broadcast: to every other rank, and a receiving thread merges theirs; the master keeps
    /// them for the file.
    ToEveryone,
}

/// The master's side of a traditional mode.
pub struct TraditionalSharing {
    way: WorkerSharing,
    /// The threads that ask for tiles on each worker.
    threads_per_worker: usize,
    /// Broadcast: workers whose last batch has arrived.
    ended: usize,
}

impl TraditionalSharing {
    pub fn new(way: WorkerSharing, threads_per_worker: usize) -> Self {
        TraditionalSharing {
            way,
            threads_per_worker,
            ended: 0,
        }
    }
}

impl Sharing for TraditionalSharing {
    fn on_message(&mut self, core: &mut MasterCore<'_, '_>, source: i32, message: Message) -> Result<(), String> {
        match (self.way, message) {
            (WorkerSharing::Kept, Message::FinalRecords(records)) => {
                core.relay.keep(records);
            }
            (WorkerSharing::ThroughMaster, Message::RecordsUp { thread, records }) => {
                core.sync(source, thread, records);
            }
            (WorkerSharing::ToEveryone, Message::RecordsBroadcast { records, last }) => {
                core.relay.keep(records);
                self.ended += usize::from(last);
            }
            (_, other) => {
                return Err(format!("rank {source} sent an unexpected message ({:?})", other.kind()));
            }
        }
        Ok(())
    }

    fn finished(&self, core: &MasterCore<'_, '_>) -> bool {
        let all_ended = self.way != WorkerSharing::ToEveryone || self.ended == core.workers();
        core.turned_away == core.workers() * self.threads_per_worker && core.every_report_in() && all_ended
    }
}

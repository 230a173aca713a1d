//! The traditional modes' sharing policies (paper, section 4), as the master sees them: not at
//! all (noshare), through the master (centralised), or by every worker to every other
//! (broadcast). In each, workers start from the cache file's records and the render is complete
//! once every rendering thread has been told "no tile left" and every rank has reported.

use super::master::{MasterCore, Sharing};
use super::protocol::Message;

/// What the three have in common: the threads that ask for tiles.
struct Requesters {
    threads_per_worker: usize,
}

impl Requesters {
    fn done(&self, core: &MasterCore<'_, '_>) -> bool {
        core.turned_away == core.workers() * self.threads_per_worker && core.every_report_in()
    }
}

fn unexpected(source: i32, message: &Message) -> String {
    format!("rank {source} sent an unexpected message ({:?})", message.kind())
}

/// No sharing: each worker keeps its records; with -af they come to the master at the end.
pub struct NoShare(Requesters);

/// Workers send their new records to the master, which answers with those they lack.
pub struct Centralised(Requesters);

/// Workers send their new records to every other rank; the master keeps them for the file.
pub struct Broadcast {
    requesters: Requesters,
    /// Workers whose last batch has arrived.
    ended: usize,
}

impl NoShare {
    pub fn new(threads_per_worker: usize) -> Self {
        NoShare(Requesters { threads_per_worker })
    }
}

impl Centralised {
    pub fn new(threads_per_worker: usize) -> Self {
        Centralised(Requesters { threads_per_worker })
    }
}

impl Broadcast {
    pub fn new(threads_per_worker: usize) -> Self {
        Broadcast {
            requesters: Requesters { threads_per_worker },
            ended: 0,
        }
    }
}

impl Sharing for NoShare {
    fn on_message(&mut self, core: &mut MasterCore<'_, '_>, source: i32, message: Message) -> Result<(), String> {
        match message {
            Message::FinalRecords(records) => {
                core.relay.keep(records);
                Ok(())
            }
            other => Err(unexpected(source, &other)),
        }
    }

    fn finished(&self, core: &MasterCore<'_, '_>) -> bool {
        self.0.done(core)
    }
}

impl Sharing for Centralised {
    fn on_message(&mut self, core: &mut MasterCore<'_, '_>, source: i32, message: Message) -> Result<(), String> {
        match message {
            Message::RecordsUp { thread, records } => {
                core.sync(source, thread, records);
                Ok(())
            }
            other => Err(unexpected(source, &other)),
        }
    }

    fn finished(&self, core: &MasterCore<'_, '_>) -> bool {
        self.0.done(core)
    }
}

impl Sharing for Broadcast {
    fn on_message(&mut self, core: &mut MasterCore<'_, '_>, source: i32, message: Message) -> Result<(), String> {
        match message {
            Message::RecordsBroadcast { records, last } => {
                core.relay.keep(records);
                self.ended += usize::from(last);
                Ok(())
            }
            other => Err(unexpected(source, &other)),
        }
    }

    fn finished(&self, core: &MasterCore<'_, '_>) -> bool {
        self.requesters.done(core) && self.ended == core.workers()
    }
}

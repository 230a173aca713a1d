//! The master's sends. The master's --timeout must hold whatever a worker's host does, but a
//! standard MPI send of a message too large to go eagerly waits until the receiver takes it,
//! and a receiver whose host or link is gone never does: the master would hang there, past its
//! timeout, and so would the job. Every send of the master waits at most the timeout; past it
//! the job ends as on any other failure (the cache file keeps what it has), naming the rank
//! and host that stopped taking messages.

use super::comm::Comm;
use super::protocol::Message;
use crate::irradiance::IrradianceCache;
use std::convert::Infallible;
use std::time::Duration;

pub struct MasterSends<'a, 'c> {
    pub comm: &'a Comm<'c>,
    pub limit: Duration,
    pub hosts: &'a [String],
    pub cache: Option<&'a IrradianceCache>,
}

impl MasterSends<'_, '_> {
    pub fn send(&self, dest: i32, message: &Message) {
        self.comm.send_within(dest, message, self.limit, || -> Infallible {
            let host = self.hosts.get(dest as usize).map_or("?", String::as_str);
            super::end_job(
                self.comm,
                self.cache,
                &format!(
                    "rank {dest} (host {host}) took no message from the master for {:.0} s: its host or \
                     link is gone, or it hangs",
                    self.limit.as_secs_f64()
                ),
            )
        });
    }
}

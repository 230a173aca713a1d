//! What a rank counts of its messages and waiting.

use std::sync::atomic::{AtomicU64, Ordering};

/// Traffic and waiting of one rank; shared by its threads.
#[derive(Default, Debug)]
pub struct Counters {
    pub messages_sent: AtomicU64,
    pub bytes_sent: AtomicU64,
    pub messages_received: AtomicU64,
    pub bytes_received: AtomicU64,
    /// Nanoseconds spent waiting for messages.
    pub idle_ns: AtomicU64,
    /// Nanoseconds of waits for a collective filled with other work (`Comm::all_gather_bytes`):
    /// not idle.
    pub filled_ns: AtomicU64,
}

impl Counters {
    pub fn idle_s(&self) -> f64 {
        self.idle_ns.load(Ordering::Relaxed) as f64 * 1e-9
    }

    pub fn filled_s(&self) -> f64 {
        self.filled_ns.load(Ordering::Relaxed) as f64 * 1e-9
    }
}

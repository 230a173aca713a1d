//! The pulse thread of a rank (see `liveness`).

use super::comm::Comm;
use super::liveness::{HEARTBEAT_INTERVAL, counters, silent_for};
use super::protocol::{Kind, Message};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The pulse thread of a rank: heartbeats out (the master's to every worker, a worker's to the
/// master) and in, until stopped. On a worker, it ends the process when the master has been
/// silent for `master_lost_after`, with `lost_master` as the one line saying why.
pub struct Pulse {
    stop: std::sync::Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Pulse {
    pub fn start(master_lost_after: Duration, lost_master: String) -> Pulse {
        let stop = std::sync::Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let thread = std::thread::spawn(move || {
            let counters = counters().expect("liveness::begin runs first");
            let comm = Comm::new(counters);
            let rank = comm.rank();
            let peers: Vec<i32> = if rank == 0 { (1..comm.size()).collect() } else { vec![0] };
            let mut next_beat = Instant::now();
            while !flag.load(Ordering::Relaxed) {
                if Instant::now() >= next_beat {
                    peers.iter().for_each(|&peer| comm.send(peer, &Message::Heartbeat));
                    next_beat += HEARTBEAT_INTERVAL;
                }
                while comm.try_receive(None, Some(Kind::Heartbeat.tag())).is_some() {}
                if rank != 0 && silent_for(0) >= master_lost_after {
                    crate::diagnostics::error(&lost_master);
                    crate::sys::process::exit_now(1);
                }
                std::thread::sleep(Duration::from_millis(100));
            }
        });
        Pulse {
            stop,
            thread: Some(thread),
        }
    }
}

/// Dropping the pulse stops the heartbeats (before the rank leaves MPI: no thread may use it
/// then; `parallel::run` drops the pulse before MPI's universe).
impl Drop for Pulse {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

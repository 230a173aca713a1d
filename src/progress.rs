//! A progress bar on a terminal; nothing at all when stderr is a pipe or a file (CI logs, MPI).

use std::io::{IsTerminal, Write};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

pub struct Progress {
    total: usize,
    done: AtomicUsize,
    enabled: bool,
    start: Instant,
    last_drawn: Mutex<Option<Instant>>,
}

impl Progress {
    pub fn new(total: usize, quiet: bool) -> Progress {
        Progress {
            total: total.max(1),
            done: AtomicUsize::new(0),
            enabled: !quiet && std::io::stderr().is_terminal(),
            start: Instant::now(),
            last_drawn: Mutex::new(None),
        }
    }

    pub fn advance(&self, n: usize) {
        let done = self.done.fetch_add(n, Ordering::Relaxed) + n;
        if !self.enabled {
            return;
        }
        let mut last = self.last_drawn.lock().unwrap_or_else(|e| e.into_inner());
        if last.is_some_and(|t| t.elapsed().as_millis() < 100) && done < self.total {
            return;
        }
        *last = Some(Instant::now());
        let fraction = done as f64 / self.total as f64;
        let filled = (fraction * 40.0) as usize;
        eprint!(
            "\r[{}{}] {:5.1}%  {:.1}s",
            "#".repeat(filled),
            " ".repeat(40 - filled.min(40)),
            fraction * 100.0,
            self.start.elapsed().as_secs_f64()
        );
        let _ = std::io::stderr().flush();
    }

    pub fn finish(&self) {
        if self.enabled {
            eprintln!();
        }
    }
}

//! A render that a farm manager or a user stops with SIGTERM or SIGINT (Ctrl-C) finishes the
//! tile or prepass round it is in and ends cleanly: the checkpoint journal keeps every finished
//! tile, the cache file every record, and no output is left half-written. A second signal ends
//! the process at once, for a user who does not want to wait.
//!
//! Only the one-process renderer asks for this (`catch_termination`): under mpirun the launcher
//! forwards signals to its ranks and ends them itself.

use std::sync::atomic::{AtomicI32, Ordering};

/// The first termination signal received (0: none yet).
static RECEIVED: AtomicI32 = AtomicI32::new(0);

extern "C" fn on_termination(signal: libc::c_int) {
    // Only async-signal-safe work here: an atomic swap, and _exit for a second signal.
    if RECEIVED.swap(signal, Ordering::SeqCst) != 0 {
        // SAFETY: _exit is async-signal-safe and takes any status.
        unsafe { libc::_exit(128 + signal) }
    }
}

/// From now on SIGTERM and SIGINT set the flag `received` reads instead of ending the process.
pub fn catch_termination() -> Result<(), String> {
    for signal in [libc::SIGTERM, libc::SIGINT] {
        // SAFETY: a zeroed sigaction is a valid starting value; the handler only touches an
        // atomic and calls _exit, both safe in a signal handler; SA_RESTART keeps interrupted
        // system calls (file writes, waits) going.
        let status = unsafe {
            let mut action: libc::sigaction = std::mem::zeroed();
            action.sa_sigaction = on_termination as extern "C" fn(libc::c_int) as libc::sighandler_t;
            action.sa_flags = libc::SA_RESTART;
            libc::sigemptyset(&mut action.sa_mask);
            libc::sigaction(signal, &action, std::ptr::null_mut())
        };
        if status != 0 {
            return Err(format!(
                "cannot catch signal {signal}: {}",
                std::io::Error::last_os_error()
            ));
        }
    }
    Ok(())
}

/// The termination signal received, if any (SIGTERM is 15, SIGINT 2).
pub fn received() -> Option<i32> {
    match RECEIVED.load(Ordering::SeqCst) {
        0 => None,
        signal => Some(signal),
    }
}

/// The signal's name for messages.
pub fn name(signal: i32) -> &'static str {
    match signal {
        libc::SIGTERM => "SIGTERM",
        libc::SIGINT => "SIGINT",
        _ => "a signal",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_caught_sigterm_is_recorded_not_fatal() {
        catch_termination().unwrap();
        assert_eq!(received(), None);
        // SAFETY: raising a signal this process now handles.
        unsafe { libc::raise(libc::SIGTERM) };
        assert_eq!(received(), Some(libc::SIGTERM));
        assert_eq!(name(libc::SIGTERM), "SIGTERM");
    }
}

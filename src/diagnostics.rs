//! How icrender tells the user that something went wrong: one line on stderr, with one prefix,
//! whichever layer notices it (a command, a rank under mpirun, a rank's pulse thread).

/// Says why the program stops (or a rank of it does).
pub fn error(message: &str) {
    eprintln!("icrender: error: {message}");
}

/// Says what went wrong that the program survives.
pub fn warn(message: &str) {
    eprintln!("icrender: warning: {message}");
}

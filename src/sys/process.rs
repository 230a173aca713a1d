//! Process lifetime under a launcher: a rank started by mpirun (or by its remote daemon) must
//! not outlive it. When a scheduler or a user kills mpirun with SIGKILL, it cannot stop its
//! ranks; without this they would render on as orphans, appending to the same checkpoint and
//! cache files as the job started again in their place.

/// Asks the kernel to kill this process when its parent (the launcher) dies. `launcher`, when
/// known, is the launcher's pid: if the parent is no longer that process, the launcher died
/// before the request could take effect, and this returns an error. Linux only; elsewhere it
/// does nothing.
pub fn die_with_parent(launcher: Option<u32>) -> Result<(), String> {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: PR_SET_PDEATHSIG takes a signal number and ignores the other arguments.
        let status = unsafe { libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL as libc::c_ulong, 0, 0, 0) };
        if status != 0 {
            return Err(format!(
                "cannot ask to end with the launcher: {}",
                std::io::Error::last_os_error()
            ));
        }
        // The launcher may have died before the request: then this process was re-parented.
        // SAFETY: getppid has no preconditions.
        let parent = unsafe { libc::getppid() };
        if launcher.is_some_and(|pid| pid as libc::pid_t != parent) {
            return Err("the launcher (mpirun) is gone".into());
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = launcher;
    Ok(())
}

/// Sets an environment variable for libraries this process starts later (MPI reads its
/// parameters from the environment when it is initialised). Only while this process has one
/// thread: `parallel::run` calls it before MPI starts any thread and before the rank's own.
pub fn set_before_threads(name: &str, value: &str) {
    // SAFETY: no other thread exists yet to read or write the environment at the same time
    // (the caller's contract above).
    unsafe { std::env::set_var(name, value) };
}

/// Ends a finished command with `code` once its output is flushed, running no exit handlers.
/// The libraries the image library loads start threads in their static constructors
/// (log4cplus, through OpenImageIO's DICOM reader, starts a pool of four) and tear them down in
/// their static destructors; a process whose `exit` ran them with those threads alive died by
/// SIGSEGV (seen once in CI, after a refused scene had printed its error; not reproduced in
/// 2,400 tries, so the likely cause rather than a proven one), and one exiting while the library
/// was still loading on the background thread died by SIGABRT (OpenImageIO asserts on a lock
/// held). Every file a command writes is closed, and an MPI rank's library finalised,
/// before this is called, so those destructors have nothing left to do.
pub fn exit_finished(code: u8) -> ! {
    use std::io::Write;
    let _ = std::io::stdout().flush();
    // SAFETY: fflush(NULL) flushes every C stdio stream and takes no other argument.
    unsafe { libc::fflush(std::ptr::null_mut()) };
    exit_now(i32::from(code))
}

/// Ends this process at once with `code`, running no exit handlers: a rank that has lost its
/// master must not wait in the MPI library's own teardown, which may wait for the lost peer.
pub fn exit_now(code: i32) -> ! {
    use std::io::Write;
    let _ = std::io::stderr().flush();
    // SAFETY: _exit takes any status and never returns.
    unsafe { libc::_exit(code) }
}

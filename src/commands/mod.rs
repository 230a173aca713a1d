//! One module per subcommand.

pub mod bench;
pub mod cache;
pub mod compare;
pub mod export;
pub mod frames;
pub mod help_reference;
pub mod info;
pub mod merge;
pub mod reference;
pub mod render;
pub mod seams;
pub mod view;

/// How a command ended, as its exit status says it to a farm manager or a script: whether
/// running the same task again can help (docs/farms.md, "Progress, exit status, stopping").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Exit {
    /// The command line, the scene, a reference or a checkpoint is wrong: the same task fails
    /// again until its input changes.
    BadInput,
    /// Something outside the input failed (an output could not be written, MPI, a lost rank):
    /// the same task may succeed on a retry.
    Failed,
    /// The system refused memory (`sys::alloc` ends the process itself with this status).
    OutOfMemory,
    /// A bug: a panic.
    Internal,
    /// Stopped by this signal (SIGTERM, SIGINT) after finishing what it was doing.
    Interrupted(i32),
}

impl Exit {
    /// The process's exit status: 2, 1, 3, 70 (sysexits' EX_SOFTWARE) and 128 + the signal
    /// number, the shell's convention for a process a signal ended.
    pub fn status(self) -> u8 {
        match self {
            Exit::Failed => 1,
            Exit::BadInput => 2,
            Exit::OutOfMemory => crate::sys::alloc::OUT_OF_MEMORY_STATUS,
            Exit::Internal => 70,
            Exit::Interrupted(signal) => (128 + signal.clamp(1, 127)) as u8,
        }
    }
}

/// A failed command: one line for the user, already naming the file when a file is at fault,
/// and what kind of failure it was.
#[derive(Debug)]
pub struct CommandError {
    pub message: String,
    pub exit: Exit,
}

impl CommandError {
    /// Bad input: the command line, the scene, a reference image, a checkpoint.
    pub fn input(message: String) -> CommandError {
        CommandError {
            message,
            exit: Exit::BadInput,
        }
    }

    /// A failure the input did not cause (writing an output, MPI).
    pub fn failed(message: String) -> CommandError {
        CommandError {
            message,
            exit: Exit::Failed,
        }
    }
}

/// Errors passed on with `?` are, in the commands, about their input.
impl<T: std::fmt::Display> From<T> for CommandError {
    fn from(e: T) -> Self {
        CommandError::input(e.to_string())
    }
}

pub type CommandResult = Result<(), CommandError>;

pub use crate::diagnostics::{error, warn};

impl From<crate::parallel::ParallelError> for CommandError {
    fn from(e: crate::parallel::ParallelError) -> CommandError {
        match e {
            crate::parallel::ParallelError::Input(message) => CommandError::input(message),
            crate::parallel::ParallelError::Failed(message) => CommandError::failed(message),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exit_statuses_are_the_documented_ones() {
        assert_eq!(Exit::Failed.status(), 1);
        assert_eq!(Exit::BadInput.status(), 2);
        assert_eq!(Exit::OutOfMemory.status(), 3);
        assert_eq!(Exit::Internal.status(), 70);
        assert_eq!(Exit::Interrupted(15).status(), 143);
        assert_eq!(Exit::Interrupted(2).status(), 130);
        // Errors passed on with `?` are about the input.
        let e: CommandError = "scene.gltf: no such file".into();
        assert_eq!(e.exit, Exit::BadInput);
    }
}

//! One module per subcommand.

pub mod bench;
pub mod compare;
pub mod export;
pub mod info;
pub mod reference;
pub mod render;
pub mod seams;
pub mod view;

/// A failed command: one line for the user, already naming the file when a file is at fault.
#[derive(Debug)]
pub struct CommandError(pub String);

impl<T: std::fmt::Display> From<T> for CommandError {
    fn from(e: T) -> Self {
        CommandError(e.to_string())
    }
}

pub type CommandResult = Result<(), CommandError>;

/// Says why the command failed, on stderr, as the user sees every error.
pub fn error(message: &str) {
    eprintln!("icrender: error: {message}");
}

pub fn warn(message: &str) {
    eprintln!("icrender: warning: {message}");
}

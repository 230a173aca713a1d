//! The `icrender` command: parses arguments and runs one subcommand.

#![deny(unsafe_code)]

use icrender::{cli, commands};

use clap::Parser;
use std::process::ExitCode;

/// Memory the system refuses ends the process with a clear message, not an abort.
#[global_allocator]
static ALLOCATOR: icrender::sys::alloc::ReportingAllocator = icrender::sys::alloc::ReportingAllocator;

fn main() -> ExitCode {
    let args = cli::rewrite_radiance_options(std::env::args());
    let cli = match cli::Cli::try_parse_from(args) {
        Ok(cli) => cli,
        Err(e) => {
            // clap prints help and version to stdout with success, usage errors to stderr.
            let _ = e.print();
            return if e.use_stderr() {
                ExitCode::from(2)
            } else {
                ExitCode::SUCCESS
            };
        }
    };
    // A panic is a bug: it says so with its own message and ends with Exit::Internal's status
    // instead of Rust's default 101.
    let result = std::panic::catch_unwind(|| run(&cli)).unwrap_or_else(|_| {
        Err(commands::CommandError {
            message: "internal error (a bug): please report it with the command line".into(),
            exit: commands::Exit::Internal,
        })
    });
    let status = match result {
        Ok(()) => 0,
        Err(commands::CommandError { message, exit }) => {
            // An empty message: another rank already said why.
            if !message.is_empty() {
                commands::error(&message);
            }
            exit.status()
        }
    };
    icrender::sys::process::exit_finished(status)
}

fn run(cli: &cli::Cli) -> commands::CommandResult {
    match &cli.command {
        // One image, or a frame sequence rendered frame by frame through it.
        cli::Command::Render(args) => commands::render::run(args, commands::frames::run),
        cli::Command::Info(args) => commands::info::run(args),
        cli::Command::Compare(args) => commands::compare::run(args),
        cli::Command::Seams(args) => commands::seams::run(args),
        cli::Command::Bench(args) => commands::bench::run(args),
        cli::Command::Reference(args) => commands::reference::run(args),
        cli::Command::Export(args) => commands::export::run(args),
        cli::Command::Cache(args) => commands::cache::run(args),
        cli::Command::Merge(args) => commands::merge::run(args),
        cli::Command::HelpReference => {
            print!("{}", commands::help_reference::markdown());
            Ok(())
        }
    }
}

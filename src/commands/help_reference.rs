//! The options reference, docs/options.md, made from the command-line definition itself so
//! that it cannot drift from `--help`: each command's help is the text `icrender COMMAND
//! --help` prints, word for word. `tests/options_reference.rs` fails when the checked-in page
//! and this output differ.

use crate::cli::Cli;
use clap::CommandFactory;

/// How to make the page again, said in the page and by the test that checks it.
pub const REGENERATE: &str = "cargo run --release -- help-reference > docs/options.md";

/// The help clap prints for `icrender WORDS... --help`, as plain text.
pub fn help_text(words: &[&str]) -> String {
    let mut argv = vec!["icrender"];
    argv.extend_from_slice(words);
    argv.push("--help");
    match Cli::command().try_get_matches_from(argv) {
        Err(e) => e.render().to_string(),
        // `--help` always ends parsing with clap's help "error".
        Ok(_) => unreachable!("--help parsed as a command"),
    }
}

/// The visible subcommands of `icrender WORDS...`, in the order `--help` lists them.
fn subcommands(words: &[&str]) -> Vec<String> {
    let mut command = Cli::command();
    for word in words {
        command = command
            .find_subcommand(word)
            .cloned()
            .unwrap_or_else(|| panic!("no subcommand {word}"));
    }
    command
        .get_subcommands()
        .filter(|c| !c.is_hide_set())
        .map(|c| c.get_name().to_string())
        .collect()
}

fn section(out: &mut String, words: &[&str]) {
    let title = std::iter::once("icrender")
        .chain(words.iter().copied())
        .collect::<Vec<_>>()
        .join(" ");
    out.push_str(&format!("\n## `{title}`\n\n```text\n"));
    out.push_str(help_text(words).trim_end());
    out.push_str("\n```\n");
    for sub in subcommands(words) {
        let mut deeper: Vec<&str> = words.to_vec();
        deeper.push(&sub);
        section(out, &deeper);
    }
}

/// docs/options.md: every command's and subcommand's `--help`, under a heading of its own.
pub fn markdown() -> String {
    let mut out = String::from(
        "# Options reference\n\n\
         Generated from the command-line definition (`src/cli.rs`); do not edit by hand. Each \
         section is what `icrender ... --help` prints. After changing an option, run\n\n",
    );
    out.push_str(&format!("```sh\n{REGENERATE}\n```\n\n"));
    out.push_str(
        "Radiance's options (`-ab`, `-aa`, `-vp`, ...) are written here with two dashes, as clap \
         lists them; icrender takes them with one dash as well, as rpict does. What the options \
         are for, and which to reach for first: [rendering.md](rendering.md).\n",
    );
    section(&mut out, &[]);
    out
}

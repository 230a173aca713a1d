//! The layers hold: the transport (`src/parallel/`) takes nothing from the command layer and
//! hands back its own error; the checkpoint journal, a one-process feature, takes nothing from
//! the MPI protocol (the codec both use sits below both, in `src/codec/`). Read from the source,
//! so a new import across a layer fails here with the file and line that made it.

use std::path::{Path, PathBuf};

fn sources(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            out.extend(sources(&path));
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
    out
}

/// Every line of the files under `place` (a folder or one file) that names `forbidden`.
fn crossings(place: &str, forbidden: &str) -> Vec<String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let path = root.join(place);
    let files = if path.is_dir() { sources(&path) } else { vec![path] };
    files
        .iter()
        .flat_map(|file| {
            let text = std::fs::read_to_string(file).unwrap();
            let name = file.strip_prefix(root).unwrap().display().to_string();
            text.lines()
                .enumerate()
                .filter(|(_, line)| line.contains(forbidden) && !line.trim_start().starts_with("//"))
                .map(|(n, line)| format!("{name}:{}: {}", n + 1, line.trim()))
                .collect::<Vec<_>>()
        })
        .collect()
}

#[test]
fn the_transport_takes_nothing_from_the_command_layer() {
    let found = crossings("src/parallel", "crate::commands");
    assert!(
        found.is_empty(),
        "src/parallel/ uses the command layer:\n{}",
        found.join("\n")
    );
}

#[test]
fn the_checkpoint_journal_and_the_codec_take_nothing_from_the_transport() {
    for place in ["src/checkpoint.rs", "src/codec"] {
        let found = crossings(place, "crate::parallel");
        assert!(found.is_empty(), "{place} uses the transport:\n{}", found.join("\n"));
    }
}

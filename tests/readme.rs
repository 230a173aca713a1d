//! The README tells the truth where a test can tell: every option `icrender render --help`
//! lists and every subcommand `icrender --help` lists is named in it, and it says that -o is
//! optional.

mod common;
use common::*;

fn readme() -> String {
    std::fs::read_to_string(project_dir().join("README.md")).unwrap()
}

/// (short, long) option names of a help text's option lines, e.g. ("-o", "--output").
fn options(help: &str) -> Vec<(Option<String>, String)> {
    help.lines()
        .filter_map(|line| {
            let line = line.trim_start();
            let (short, rest) = match line.strip_prefix('-') {
                Some(r) if !r.starts_with('-') => {
                    let (s, rest) = line.split_once(", ").unwrap_or((line.split_whitespace().next()?, ""));
                    (Some(s.to_string()), rest)
                }
                _ => (None, line),
            };
            let long = rest.strip_prefix("--")?.split([' ', '=']).next()?.to_string();
            Some((short, format!("--{long}")))
        })
        .collect()
}

/// Whether `token` appears in `text` as a word of its own (`-vu` in "`-vp -vd -vu` (3
/// numbers)", not as the start of `-vuz`).
fn mentions(text: &str, token: &str) -> bool {
    text.match_indices(token).any(|(at, _)| {
        let before = text[..at].chars().next_back();
        let after = text[at + token.len()..].chars().next();
        before.is_none_or(|c| !c.is_alphanumeric() && c != '-')
            && after.is_none_or(|c| !c.is_alphanumeric() && c != '-')
    })
}

#[test]
fn every_render_option_is_in_the_readme() {
    let text = readme();
    let help = stdout(&run_ok(&["render", "--help"]));
    let listed = options(&help);
    assert!(listed.len() > 40, "too few options parsed from --help:\n{help}");
    let mut missing = Vec::new();
    for (short, long) in &listed {
        if long == "--help" {
            continue;
        }
        let name = &long[2..];
        // Radiance's options are written as rpict takes them (`-ab`); others by their long
        // name, or their short one (`-q`) where they have one.
        let found = mentions(&text, long)
            || (icrender::cli::RADIANCE_OPTIONS.contains(&name) && mentions(&text, &format!("-{name}")))
            || short.as_ref().is_some_and(|s| mentions(&text, s));
        if !found {
            missing.push(long.clone());
        }
    }
    assert!(
        missing.is_empty(),
        "render options --help lists but the README does not: {missing:?}"
    );
}

#[test]
fn every_subcommand_is_in_the_readme() {
    let text = readme();
    let help = stdout(&run_ok(&["--help"]));
    let commands: Vec<&str> = help
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help")
        .collect();
    assert!(commands.len() >= 7, "commands parsed from --help: {commands:?}");
    let missing: Vec<&&str> = commands
        .iter()
        .filter(|c| !text.contains(&format!("icrender {c} ")))
        .collect();
    assert!(missing.is_empty(), "subcommands not shown in the README: {missing:?}");
}

#[test]
fn output_is_optional_in_help_usage_and_readme() {
    let help = stdout(&run_ok(&["render", "--help"]));
    let usage = help.lines().find(|l| l.starts_with("Usage:")).unwrap();
    assert!(
        usage.contains("[-o OUT.exr]"),
        "the usage line shows -o as required: {usage}"
    );
    assert!(help.contains("Optional: by default the scene's file name"), "{help}");
    let text = readme();
    assert!(
        text.contains("icrender render SCENE.gltf [-o out.exr]"),
        "README's usage line"
    );
    assert!(text.contains("the scene's file name with `.exr`, in the current directory"));
    // And it is true: without -o the render lands in the current directory under the scene's name.
    let dir = tempfile::tempdir().unwrap();
    let scene = project_dir().join("scenes/cornell.gltf");
    let out = std::process::Command::new(binary())
        .args([
            "render",
            scene.to_str().unwrap(),
            "-x",
            "8",
            "-y",
            "8",
            "-ad",
            "4",
            "-q",
        ])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(dir.path().join("cornell.exr").exists() && dir.path().join("cornell.png").exists());
}

#[test]
fn the_readme_does_not_call_the_parallel_cache_unbuilt() {
    assert!(!readme().contains("is being built on this base"));
}

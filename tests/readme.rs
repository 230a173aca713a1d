//! The README and the manual tell the truth where a test can tell: every command the README
//! shows works as shown (the concrete ones are run, the ones with placeholders name options
//! their command has), a first render makes what the README says it makes, every subcommand
//! `icrender --help` lists is in the README, every option `icrender render --help` lists is in
//! the manual's rendering page, and both say that -o is optional.

mod common;
use common::*;

fn readme() -> String {
    std::fs::read_to_string(project_dir().join("README.md")).unwrap()
}

/// The manual's page on rendering, where every render option is explained.
fn rendering_page() -> String {
    std::fs::read_to_string(project_dir().join("docs/rendering.md")).unwrap()
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
fn every_render_option_is_in_the_manual() {
    let text = rendering_page();
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
        "render options --help lists but docs/rendering.md does not: {missing:?}"
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
    for (name, text) in [("README", readme()), ("docs/rendering.md", rendering_page())] {
        assert!(
            text.contains("icrender render SCENE.gltf [-o out.exr]"),
            "{name}'s usage line"
        );
        assert!(
            text.contains("the scene's file name with `.exr`, in the current directory"),
            "{name}'s -o"
        );
    }
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

/// The commands of the README's `sh` blocks, one per line and `&&`, without their comments.
fn readme_commands() -> Vec<String> {
    let text = readme();
    let mut out = Vec::new();
    let mut in_sh = false;
    for line in text.lines() {
        if line.starts_with("```") {
            in_sh = line == "```sh";
            continue;
        }
        if !in_sh {
            continue;
        }
        let line = line.split(" # ").next().unwrap().trim();
        out.extend(line.split("&&").map(|c| c.trim().to_string()).filter(|c| !c.is_empty()));
    }
    out
}

/// Runs `cargo run --release -- ARGS` as the binary with ARGS, in a fresh folder where the
/// README's relative scene paths lead to the project's scenes, at a tiny size.
fn run_like_cargo_run(args: &[&str], dir: &std::path::Path) -> std::process::Output {
    std::os::unix::fs::symlink(project_dir().join("scenes"), dir.join("scenes")).unwrap();
    let mut full: Vec<&str> = args.to_vec();
    // Smaller and quicker than the README's, the same command otherwise.
    full.extend(["-x", "16", "-y", "16", "-ad", "16", "-q"]);
    std::process::Command::new(binary())
        .args(&full)
        .current_dir(dir)
        .output()
        .unwrap()
}

#[test]
fn every_command_in_the_readme_works() {
    let commands = readme_commands();
    assert!(commands.len() >= 12, "commands found in the README: {commands:?}");
    let mut ran = 0;
    for command in &commands {
        let words: Vec<&str> = command.split_whitespace().collect();
        match words[..] {
            ["bash", "scripts/install-deps.sh"] => {
                let script = project_dir().join("scripts/install-deps.sh");
                let out = std::process::Command::new("bash")
                    .arg("-n")
                    .arg(&script)
                    .output()
                    .unwrap();
                assert!(out.status.success(), "{command}: {}", stderr(&out));
            }
            ["cargo", "test", "--release"] => {
                // The README says this is what CI runs.
                let ci = std::fs::read_to_string(project_dir().join(".ci/run")).unwrap();
                assert!(
                    ci.lines().any(|l| l.trim() == command),
                    ".ci/run does not run `{command}`"
                );
            }
            ["cargo", "run", "--release", "--", ref args @ ..] => {
                let dir = tempfile::tempdir().unwrap();
                let out = run_like_cargo_run(args, dir.path());
                assert!(out.status.success(), "{command}: {}", stderr(&out));
                ran += 1;
            }
            _ => {
                // A usage line with placeholders: its command exists and takes every option shown.
                let words: Vec<&str> = match words[..] {
                    ["mpirun", "-np", _, ref rest @ ..] => rest.to_vec(),
                    _ => words.clone(),
                };
                assert_eq!(words[0], "icrender", "a command the test does not know: {command}");
                let mut path: Vec<&str> = vec![words[1]];
                if words[1] == "bench" {
                    path.push(words[2]);
                }
                let mut help_args = path.clone();
                help_args.push("--help");
                let help = stdout(&run_ok(&help_args));
                for word in &words[1 + path.len()..] {
                    let option = word.trim_matches(['[', ']']);
                    if !option.starts_with('-') || option == "..." {
                        continue;
                    }
                    let long = format!("-{option}");
                    assert!(
                        mentions(&help, option) || mentions(&help, &long),
                        "`{command}`: `icrender {} --help` has no {option}",
                        path.join(" ")
                    );
                }
            }
        }
    }
    assert!(ran >= 2, "no concrete render command was run from the README");
}

#[test]
fn the_first_render_makes_what_the_readme_says() {
    let text = readme();
    let dir = tempfile::tempdir().unwrap();
    let out = run_like_cargo_run(
        &["render", "scenes/cornell.gltf", "-o", "cornell.exr", "--overwrite"],
        dir.path(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    for file in ["cornell.png", "cornell.exr"] {
        assert!(text.contains(&format!("`{file}`")), "the README does not name {file}");
        assert!(dir.path().join(file).exists(), "{file} was not written");
    }
    let image = icrender::sys::image_io::read_image_with_header(&dir.path().join("cornell.exr")).unwrap();
    for (layer, channel) in [
        ("emission", "emission.R"),
        ("direct", "direct.R"),
        ("indirect", "indirect.R"),
        ("albedo", "albedo.R"),
        ("normal", "normal.X"),
        ("depth", "depth.Z"),
    ] {
        assert!(
            text.contains(&format!("`{layer}`")),
            "the README does not name the layer {layer}"
        );
        assert!(image.channel(channel).is_some(), "no {channel} in the first render");
    }
    assert!(image.channel("CryptoObject00.R").is_some() && image.channel("CryptoMaterial00.R").is_some());
    assert!(text.contains("Cryptomatte"));
    assert!(text.contains("`icrender/command`"));
    assert!(image.attributes.iter().any(|(n, _)| n == "icrender/command"));
}

#[test]
fn the_readme_is_a_front_page() {
    let lines = readme().lines().count();
    assert!(
        lines <= 300,
        "README.md has {lines} lines; the manual under docs/ is where detail goes"
    );
}

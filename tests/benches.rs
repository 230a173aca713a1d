//! The benches on a fresh machine: each checks the Python packages and programs it needs before
//! it does any work, and stops with one line saying what is missing and the one command that
//! installs them (bench/requirements.txt, which docs/benchmarks.md gives). Here a package is hidden
//! from the script (as if not installed) and the script must stop at once, having built and
//! rendered nothing.

mod common;
use common::*;
use std::process::Command;
use std::time::{Duration, Instant};

/// Runs `bench/SCRIPT args` under python3 with `hidden` made unimportable.
fn run_without(script: &str, hidden: &str, args: &[&str]) -> (Option<i32>, String, Duration) {
    let runner = format!(
        "import sys, runpy\n\
         sys.modules[{hidden:?}] = None\n\
         sys.argv = [{script:?}] + sys.argv[1:]\n\
         sys.path.insert(0, 'bench')\n\
         runpy.run_path({script:?}, run_name='__main__')\n",
        script = format!("bench/{script}")
    );
    let start = Instant::now();
    let out = Command::new("python3")
        .arg("-c")
        .arg(runner)
        .args(args)
        .current_dir(project_dir())
        .output()
        .expect("python3 runs");
    (out.status.code(), stderr(&out), start.elapsed())
}

#[test]
fn every_bench_says_what_it_needs_before_it_starts() {
    if Command::new("python3").arg("--version").output().is_err() {
        println!("SKIPPED: no python3");
        return;
    }
    let cases: &[(&str, &str, &[&str])] = &[
        ("paper.py", "matplotlib", &[]),
        ("paper.py", "pyradiance", &[]),
        ("peers.py", "numpy", &[]),
        ("peers.py", "OpenEXR", &[]),
        ("peers.py", "matplotlib", &[]),
        ("peers.py", "mitsuba", &[]),
        ("peers.py", "bpy", &[]),
        ("sweep.py", "matplotlib", &[]),
        ("mpi_modes.py", "matplotlib", &[]),
        ("cluster_bench.py", "matplotlib", &[]),
        ("vs_radiance.py", "pyradiance", &["--no-build"]),
        ("bias.py", "numpy", &[]),
        ("bias.py", "OpenEXR", &[]),
        ("error_estimate.py", "matplotlib", &[]),
    ];
    for (script, hidden, args) in cases {
        let (code, err, took) = run_without(script, hidden, args);
        assert!(
            code.is_some_and(|c| c != 0),
            "{script} without {hidden} did not fail:\n{err}"
        );
        let lines: Vec<&str> = err.trim().lines().collect();
        assert_eq!(lines.len(), 1, "{script} without {hidden}: one line expected:\n{err}");
        for word in [*hidden, "pip install -r bench/requirements.txt", "venv"] {
            assert!(
                lines[0].contains(word),
                "{script} without {hidden}: should mention {word:?}: {err}"
            );
        }
        // Before any work: no build, no render (each of those takes seconds at least).
        assert!(took < Duration::from_secs(10), "{script} took {took:?} before stopping");
    }
    // A peer left out by its flag is not required: with --no-cycles, Cycles' package is not
    // among what the bench says it needs (on a machine without the others it still names
    // those; with them it prints its help).
    let (_, err, _) = run_without("peers.py", "bpy", &["--no-cycles", "--help"]);
    assert!(!err.contains("bpy"), "{err}");
    let (_, err, _) = run_without("peers.py", "bpy", &["--help"]);
    assert!(err.contains("needs") && err.contains("bpy"), "{err}");
}

/// bench/requirements.txt pins every package the benches check for.
#[test]
fn requirements_pin_every_checked_package() {
    let text = std::fs::read_to_string(project_dir().join("bench/requirements.txt")).unwrap();
    let pinned: Vec<&str> = text
        .lines()
        .filter(|l| !l.trim_start().starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let (name, version) = l.split_once("==").unwrap_or_else(|| panic!("not pinned: {l}"));
            assert!(!version.trim().is_empty(), "no version: {l}");
            name.trim()
        })
        .collect();
    for package in ["numpy", "matplotlib", "OpenEXR", "mitsuba", "bpy", "pyradiance"] {
        assert!(
            pinned.contains(&package),
            "{package} is not pinned in bench/requirements.txt"
        );
    }
    let page = std::fs::read_to_string(project_dir().join("docs/benchmarks.md")).unwrap();
    assert!(
        page.contains("pip install -r bench/requirements.txt"),
        "docs/benchmarks.md does not give the command that installs the benches' dependencies"
    );
}

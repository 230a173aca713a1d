//! What a render farm's manager sees of a one-process render: JSON progress lines on stdout,
//! errors on stderr, exit statuses that say whether a retry can help, and SIGTERM ending a
//! render cleanly (resumable with --checkpoint, nothing half-written without it).

mod common;
use common::*;
use serde_json::Value;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

fn json_lines(text: &str) -> Vec<Value> {
    text.lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not a JSON line: {l:?}: {e}")))
        .collect()
}

#[test]
fn progress_json_is_one_line_per_step_on_stdout_ending_with_done() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("p.exr");
    let scene = project_dir().join("scenes/cornell.gltf");
    let result = run_ok(&[
        "render",
        scene.to_str().unwrap(),
        "-x",
        "64",
        "-y",
        "64",
        "--tile",
        "16x16",
        "--progress",
        "json",
        "-o",
        out.to_str().unwrap(),
    ]);
    let lines = json_lines(&stdout(&result));
    assert!(lines.len() >= 3, "{lines:?}");
    let (last, steps) = lines.split_last().unwrap();
    assert_eq!(last["event"], "done");
    assert_eq!(last["output"], out.to_str().unwrap());
    let mut previous = 0.0;
    let mut phases = Vec::new();
    for step in steps {
        assert_eq!(step["event"], "progress", "{step}");
        let fraction = step["fraction"].as_f64().unwrap();
        assert!((previous..=1.0).contains(&fraction), "fractions must grow: {lines:?}");
        previous = fraction;
        assert!(step["elapsed_s"].as_f64().unwrap() >= 0.0);
        assert!(step["remaining_s"].as_f64().is_some_and(|r| r >= 0.0), "{step}");
        let phase = step["phase"].as_str().unwrap().to_string();
        if phases.last() != Some(&phase) {
            phases.push(phase);
        }
    }
    assert_eq!(phases, ["prepass", "render"], "the prepass's rounds, then the tiles");
    assert_eq!(previous, 1.0);
    // Errors and the summary stay on stderr: stdout is only the JSON lines.
    assert!(!stderr(&result).contains('{'), "{}", stderr(&result));
    assert!(out.exists());
}

#[test]
fn exit_statuses_separate_bad_input_from_other_failures() {
    let dir = tempfile::tempdir().unwrap();
    let scene = project_dir().join("scenes/cornell.gltf");
    let out = dir.path().join("x.exr");
    let ok = run(&[
        "render",
        scene.to_str().unwrap(),
        "-x",
        "16",
        "-y",
        "16",
        "-q",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(ok.status.code(), Some(0), "{}", stderr(&ok));

    let broken = dir.path().join("broken.gltf");
    std::fs::write(&broken, "{ this is not glTF").unwrap();
    let missing = dir.path().join("missing.gltf");
    let unwritable = dir.path().join("no-such-dir/x.exr");
    let bad_input: [(&str, Vec<&str>); 4] = [
        (
            "an unknown option",
            vec!["render", scene.to_str().unwrap(), "--no-such-option"],
        ),
        (
            "a missing scene",
            vec!["render", missing.to_str().unwrap(), "-o", out.to_str().unwrap()],
        ),
        (
            "a broken scene",
            vec!["render", broken.to_str().unwrap(), "-o", out.to_str().unwrap()],
        ),
        (
            "an output nowhere",
            vec!["render", scene.to_str().unwrap(), "-o", unwritable.to_str().unwrap()],
        ),
    ];
    for (what, args) in bad_input {
        let result = run(&args);
        assert_eq!(result.status.code(), Some(2), "{what}: {}", stderr(&result));
        assert!(stdout(&result).is_empty(), "{what}: errors go to stderr");
    }
}

/// Starts a render that takes a few seconds, with JSON progress piped back (8 samples a pixel:
/// the tiles take most of a second after the prepass, time enough to stop them).
fn start_render(dir: &Path, extra: &[&str]) -> Child {
    let scene = shared_scene("conference_room/conference.gltf");
    let out = dir.join("c.exr");
    Command::new(binary())
        .args([
            "render",
            scene.to_str().unwrap(),
            "-x",
            "160",
            "-y",
            "120",
            "--tile",
            "16x16",
            "--spp",
            "8",
        ])
        .args(["--progress", "json", "--no-preview", "-o", out.to_str().unwrap()])
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("icrender starts")
}

/// Reads progress lines until one in `phase` at `fraction` or more, then sends SIGTERM; returns
/// the exit status, stderr and the time from the signal to the exit.
fn terminate_at(child: Child, phase: &str, fraction: f64) -> (Option<i32>, String, Duration) {
    signal_at(child, phase, fraction, "-TERM")
}

/// As `terminate_at`, with the signal `kill` is given (`-KILL` ...).
fn signal_at(mut child: Child, phase: &str, fraction: f64, signal: &str) -> (Option<i32>, String, Duration) {
    let stdout = child.stdout.take().unwrap();
    let mut seen = false;
    for line in BufReader::new(stdout).lines() {
        let step: Value = serde_json::from_str(&line.unwrap()).unwrap();
        assert_ne!(step["event"], "done", "the render ended before it could be stopped");
        if step["phase"] == phase && step["fraction"].as_f64().unwrap() >= fraction {
            seen = true;
            break;
        }
    }
    assert!(seen, "no progress line in {phase} at {fraction}");
    let signalled = Instant::now();
    let kill = Command::new("kill")
        .args([signal, &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let output = child.wait_with_output().unwrap();
    (
        output.status.code(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
        signalled.elapsed(),
    )
}

fn leftovers(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn sigterm_ends_a_checkpointed_render_cleanly_and_the_same_command_resumes_it() {
    let dir = tempfile::tempdir().unwrap();
    let checkpoint = dir.path().join("ck");
    let options = ["--checkpoint", checkpoint.to_str().unwrap()];
    let (code, err, took) = terminate_at(start_render(dir.path(), &options), "render", 0.5);
    assert_eq!(code, Some(143), "128 + SIGTERM:\n{err}");
    assert!(took < Duration::from_secs(30), "stopping took {took:?}");
    assert!(
        err.contains("stopped by SIGTERM") && err.contains("the same command resumes"),
        "{err}"
    );
    assert_eq!(leftovers(dir.path()), ["ck"], "no image, and nothing half-written");

    // The same command finishes the job from the journal ...
    let stats = dir.path().join("c.json");
    let resumed = start_render(
        dir.path(),
        &[&options[..], &["--stats", stats.to_str().unwrap()]].concat(),
    );
    let output = resumed.wait_with_output().unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let stats: Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    assert!(stats["tiles_restored"].as_u64().unwrap() > 0, "{stats}");
    // ... with the image a render never stopped makes (the prepass's records come back from the
    // checkpoint's cache file, and tiles are the same whoever renders them).
    let whole_dir = tempfile::tempdir().unwrap();
    let whole = start_render(whole_dir.path(), &[]).wait_with_output().unwrap();
    assert!(whole.status.success());
    let (a, b) = (
        read_exr(&dir.path().join("c.exr")),
        read_exr(&whole_dir.path().join("c.exr")),
    );
    assert_eq!(
        rgb(&a, ""),
        rgb(&b, ""),
        "the resumed render differs from an uninterrupted one"
    );
    // Every channel: the restored tiles were streamed into the file before the new ones.
    assert_eq!(a.channels.len(), b.channels.len());
    for (name, values) in &a.channels {
        assert_eq!(
            Some(values.as_slice()),
            b.channel(name),
            "{name} differs after the resume"
        );
    }
}

#[test]
fn sigterm_in_the_prepass_without_a_checkpoint_leaves_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    let (code, err, took) = terminate_at(start_render(dir.path(), &[]), "prepass", 0.1);
    assert_eq!(code, Some(143), "{err}");
    assert!(took < Duration::from_secs(30), "stopping took {took:?}");
    assert!(err.contains("stopped by SIGTERM: no image written"), "{err}");
    assert!(leftovers(dir.path()).is_empty(), "{:?}", leftovers(dir.path()));
}

/// The EXR is written while the tiles render (each one compressed as it finishes) into a file
/// with no name: a render killed outright, with no chance to clean up, leaves the file that was
/// there before and nothing else, whether killed before its first tile or in the middle.
#[test]
fn sigkill_mid_render_leaves_the_previous_file_and_no_temporary() {
    for (phase, fraction) in [("prepass", 0.1), ("render", 0.3), ("render", 0.8)] {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("c.exr"), b"the previous render").unwrap();
        let child = start_render(dir.path(), &["--overwrite"]);
        let (code, err, _) = signal_at(child, phase, fraction, "-KILL");
        assert_eq!(code, None, "killed by a signal: {err}");
        assert_eq!(leftovers(dir.path()), ["c.exr"], "{phase} {fraction}");
        assert_eq!(
            std::fs::read(dir.path().join("c.exr")).unwrap(),
            b"the previous render",
            "{phase} {fraction}"
        );
    }
}

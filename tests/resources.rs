//! Resource limits: --max-memory refuses a job that will not fit, with its estimate, before the
//! work starts (in one process and under mpirun, where rank 0 alone says so); memory the system
//! refuses mid-render ends the process with one clear line, not an abort.

mod common;
use common::*;
use std::process::Command;

fn error_lines(text: &str) -> Vec<&str> {
    text.lines().filter(|l| l.starts_with("icrender: error:")).collect()
}

#[test]
fn a_render_larger_than_max_memory_is_refused_with_its_estimate() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("big.exr");
    let scene = project_dir().join("scenes/cornell.gltf");
    let args = [
        "render",
        scene.to_str().unwrap(),
        "-x",
        "8000",
        "-y",
        "8000",
        "--max-memory",
        "2G",
        "-o",
        out.to_str().unwrap(),
    ];
    let refused = run(&args);
    assert_eq!(refused.status.code(), Some(2));
    let err = stderr(&refused);
    let lines = error_lines(&err);
    assert_eq!(lines.len(), 1, "{err}");
    for word in ["cornell.gltf", "would need about", "images", "--max-memory 2.0 GiB"] {
        assert!(lines[0].contains(word), "should mention {word:?}: {}", lines[0]);
    }
    assert!(!out.exists());
    // The same render at a size that fits goes ahead.
    let small = [
        "render",
        scene.to_str().unwrap(),
        "-x",
        "32",
        "-y",
        "32",
        "-ad",
        "32",
        "--max-memory",
        "2G",
        "-q",
        "-o",
        out.to_str().unwrap(),
    ];
    run_ok(&small);
    assert!(out.exists());
}

#[test]
fn a_scene_larger_than_max_memory_is_refused_while_loading() {
    let scene = shared_scene("conference_room/conference.gltf");
    // It loads without the limit.
    let loads = run(&["info", scene.to_str().unwrap()]);
    assert!(loads.status.success(), "{}", stderr(&loads));
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("c.exr");
    let refused = run(&[
        "render",
        scene.to_str().unwrap(),
        "--max-memory",
        "4M",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(refused.status.code(), Some(2));
    let err = stderr(&refused);
    let lines = error_lines(&err);
    assert_eq!(lines.len(), 1, "{err}");
    assert!(
        lines[0].contains("conference.gltf") && lines[0].contains("--max-memory"),
        "{err}"
    );
}

#[test]
fn under_mpirun_rank_zero_alone_reports_the_refusal() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("big.exr");
    let scene = project_dir().join("scenes/cornell.gltf");
    let output = mpirun_command(
        3,
        &[
            "render",
            scene.to_str().unwrap(),
            "-x",
            "4000",
            "-y",
            "4000",
            "--max-memory",
            "1G",
            "-o",
            out.to_str().unwrap(),
        ],
    )
    .output()
    .unwrap();
    assert!(!output.status.success());
    let all = format!("{}{}", stdout(&output), stderr(&output));
    let lines = error_lines(&all);
    assert_eq!(lines.len(), 1, "one rank speaks:\n{all}");
    assert!(lines[0].contains("would need about"), "{all}");
    assert!(!out.exists());
}

#[test]
fn memory_the_system_refuses_ends_the_render_with_one_clear_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("big.exr");
    let scene = project_dir().join("scenes/cornell.gltf");
    // A 400 MiB data limit (as a batch system's ulimit would set) and a frame held whole of
    // 12 GB: `--denoise` filters every pixel with its neighbours (a streamed frame of this size
    // fits the limit: its tiles leave as they finish and its preview stops at 4.2 megapixels).
    let output = Command::new("prlimit")
        .arg(format!("--data={}", 400u64 << 20))
        .arg(binary())
        .args([
            "render",
            scene.to_str().unwrap(),
            "-x",
            "8000",
            "-y",
            "8000",
            "-ab",
            "0",
            "--denoise",
            "-o",
            out.to_str().unwrap(),
        ])
        .output()
        .expect("prlimit (util-linux) is installed");
    let err = stderr(&output);
    assert_eq!(output.status.code(), Some(3), "exit status, not a signal:\n{err}");
    let lines = error_lines(&err);
    assert_eq!(lines.len(), 1, "{err}");
    assert!(lines[0].contains("out of memory"), "{err}");
    assert!(!out.exists());
}

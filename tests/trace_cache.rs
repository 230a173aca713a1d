//! The hidden `--trace-cache FILE` option: one line per cache lookup and one per record made (or
//! that a miss would make), matching the statistics, in serial mode only; at one sample a pixel
//! the image is the same (the trace looks every sample up on its own, where a pixel's several
//! samples share one lookup otherwise: `--edge-samples 0` here).

mod common;
use common::*;
use serde_json::Value;

#[test]
fn trace_cache_lists_every_lookup_and_record() {
    let dir = tempfile::tempdir().unwrap();
    let scene = project_dir().join("scenes").join("cornell.gltf");
    let (out, stats, trace) = (
        dir.path().join("t.exr"),
        dir.path().join("t.json"),
        dir.path().join("t.txt"),
    );
    run_ok(&[
        "render",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "-x",
        "24",
        "-y",
        "24",
        "-ad",
        "64",
        "-as",
        "16",
        "--threads",
        "1",
        "-q",
        "--no-preview",
        "--stats",
        stats.to_str().unwrap(),
        "--trace-cache",
        trace.to_str().unwrap(),
        "--ic-build",
        "progressive",
        "--edge-samples",
        "0",
    ]);
    let s: Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    let text = std::fs::read_to_string(&trace).unwrap();
    let lookups: Vec<Vec<&str>> = text
        .lines()
        .filter(|l| l.starts_with("L "))
        .map(|l| l.split(' ').collect())
        .collect();
    let records: Vec<Vec<&str>> = text
        .lines()
        .filter(|l| l.starts_with("R "))
        .map(|l| l.split(' ').collect())
        .collect();
    assert_eq!(lookups.len() as u64, s["lookups"].as_u64().unwrap());
    // One record line after every lookup: made (miss) or what a miss would make (hit).
    assert_eq!(records.len(), lookups.len());
    let misses = lookups.iter().filter(|l| l[3] == "0").count() as u64;
    assert_eq!(misses, s["records_computed"].as_u64().unwrap());
    let hits = lookups.iter().filter(|l| l[3] == "1").count() as u64;
    assert_eq!(hits, s["hits"].as_u64().unwrap());
    assert!(!records.is_empty() && lookups.iter().all(|l| l.len() == 10) && records.iter().all(|r| r.len() == 23));
    // Every pixel index is inside the image.
    assert!(lookups.iter().all(|l| l[1].parse::<u32>().unwrap() < 24 * 24));
    // The same render as without the trace.
    let plain = dir.path().join("p.exr");
    run_ok(&[
        "render",
        scene.to_str().unwrap(),
        "-o",
        plain.to_str().unwrap(),
        "-x",
        "24",
        "-y",
        "24",
        "-ad",
        "64",
        "-as",
        "16",
        "--threads",
        "1",
        "-q",
        "--no-preview",
        "--ic-build",
        "progressive",
        "--edge-samples",
        "0",
    ]);
    assert_eq!(rgb(&read_exr(&out), ""), rgb(&read_exr(&plain), ""));
}

#[test]
fn trace_cache_is_refused_under_a_parallel_mode() {
    let dir = tempfile::tempdir().unwrap();
    let scene = project_dir().join("scenes").join("cornell.gltf");
    let (out, trace) = (dir.path().join("t.exr"), dir.path().join("t.txt"));
    let o = run(&[
        "render",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "-x",
        "8",
        "-y",
        "8",
        "--mode",
        "noshare",
        "--trace-cache",
        trace.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--trace-cache"), "{}", stderr(&o));
}

//! The error a render estimates for itself, without a reference, against the error a converged
//! reference measures (`icrender compare`).

mod common;

use common::*;
use serde_json::Value;
use std::path::Path;

fn cornell() -> String {
    project_dir().join("scenes/cornell.gltf").to_string_lossy().into_owned()
}

/// The composite's relMSE of `image` against `reference`, as `icrender compare` reports it.
fn measured(image: &Path, reference: &Path) -> f64 {
    let out = run_ok(&[
        "compare",
        image.to_str().unwrap(),
        reference.to_str().unwrap(),
        "--json",
    ]);
    let layers: Value = serde_json::from_str(&stdout(&out)).unwrap();
    let composite = layers
        .as_array()
        .unwrap()
        .iter()
        .find(|l| l["layer"] == "composite")
        .unwrap();
    composite["rel_mse"].as_f64().unwrap()
}

/// Renders with `extra` and returns the estimate from --stats and the measured error.
fn estimated_and_measured(dir: &Path, name: &str, reference: &Path, extra: &[&str]) -> (Value, f64) {
    let image = dir.join(format!("{name}.exr"));
    let stats = dir.join(format!("{name}.json"));
    let scene = cornell();
    let mut args = vec![
        "render",
        &scene,
        "-o",
        image.to_str().unwrap(),
        "-q",
        "--no-preview",
        "--aovs",
        "none",
        "--stats",
        stats.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    run_ok(&args);
    let stats: Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    (stats["error_estimate"].clone(), measured(&image, reference))
}

/// The header attributes that say how a render ran, and its command (the output names differ):
/// left out where two renders must make the same image.
const HOW_IT_RAN: [&str; 5] = [
    "icrender/statistics",
    "icrender/render_time_s",
    "icrender/error_estimate",
    "DateTime",
    "icrender/command",
];

/// The image every test here renders: the Cornell box at 64x64, -ab 1.
const SIZE: [&str; 6] = ["-x", "64", "-y", "64", "-ab", "1"];

/// Its converged reference, made once for the tests of this file (they run side by side).
fn reference() -> &'static Path {
    static REFERENCE: std::sync::OnceLock<(tempfile::TempDir, std::path::PathBuf)> = std::sync::OnceLock::new();
    &REFERENCE
        .get_or_init(|| {
            let dir = tempfile::tempdir().unwrap();
            let reference = dir.path().join("reference.exr");
            let scene = cornell();
            let mut args = vec!["reference", &scene, "-o", reference.to_str().unwrap()];
            args.extend_from_slice(&SIZE);
            // Its own error, a relMSE of about 3.6e-4, is in each error measured (15 s of 2
            // cores).
            args.extend_from_slice(&["--noise", "0.02", "-q", "--no-preview"]);
            run_ok(&args);
            (dir, reference)
        })
        .1
}

/// The Cornell box at -ab 1 against its converged reference, from a noisy direct light (one
/// shadow ray a sample) through the defaults to 16 samples a pixel: each estimate within a
/// factor of 2 of the error measured, and the estimates fall as the samples rise, as the error
/// does (against a reference of half the noise: 7.7e-3 against 8.5e-3, 1.7e-3 against 2.4e-3,
/// 7.9e-4 against 5.6e-4).
#[test]
fn the_estimate_is_within_a_factor_of_two_of_the_error_and_falls_with_the_samples() {
    let dir = tempfile::tempdir().unwrap();
    let reference = reference();
    let settings: [(&str, &[&str]); 3] = [
        ("noisy", &["--light-samples", "1"]),
        ("default", &[]),
        ("converging", &["--spp", "16"]),
    ];
    let mut estimates = Vec::new();
    for (name, extra) in settings {
        let extra = [&SIZE[..], extra].concat();
        let (estimate, error) = estimated_and_measured(dir.path(), name, reference, &extra);
        let relmse = estimate["relmse"].as_f64().unwrap();
        assert!(
            estimate["holdouts"].as_u64().unwrap() >= 200 && estimate["probes"].as_u64().unwrap() >= 1000,
            "{name}: {estimate}"
        );
        assert!(
            relmse <= 2.0 * error && relmse >= 0.5 * error,
            "{name}: estimated {relmse:.3e}, measured {error:.3e} ({estimate})"
        );
        // The 4x4 error keeps the cache's and a sixteenth of the noise.
        let (noise, cache) = (estimate["noise"].as_f64().unwrap(), estimate["cache"].as_f64().unwrap());
        assert!((estimate["relmse_4x4"].as_f64().unwrap() - (noise / 16.0 + cache)).abs() <= 1e-12);
        estimates.push(relmse);
    }
    assert!(estimates.windows(2).all(|w| w[1] < w[0]), "{estimates:?}");
}

/// Four passes over one record set, from a noisy direct light: the mean's error measured falls
/// to less than half of one pass's, and so does the estimate, which stays within a factor of 2
/// of it; the statistics count the passes, and the header's command names them.
#[test]
fn passes_lower_the_error_as_the_estimate_says() {
    let dir = tempfile::tempdir().unwrap();
    let noisy = [&SIZE[..], &["--light-samples", "1"]].concat();
    let (one, one_error) = estimated_and_measured(dir.path(), "one", reference(), &noisy);
    let four_args = [&noisy[..], &["--passes", "4"]].concat();
    let (four, four_error) = estimated_and_measured(dir.path(), "four", reference(), &four_args);
    let relmse = four["relmse"].as_f64().unwrap();
    assert!(
        relmse <= 2.0 * four_error && relmse >= 0.5 * four_error,
        "four passes: estimated {relmse:.3e}, measured {four_error:.3e} ({four})"
    );
    assert!(
        four_error < 0.5 * one_error,
        "one pass {one_error:.3e}, four {four_error:.3e}"
    );
    assert!(
        relmse < 0.5 * one["relmse"].as_f64().unwrap(),
        "one pass {one}, four {four}"
    );
    let stats: Value = serde_json::from_str(&std::fs::read_to_string(dir.path().join("four.json")).unwrap()).unwrap();
    assert_eq!(stats["passes"]["passes"], 4);
    let log = stats["passes"]["log"].as_array().unwrap();
    assert_eq!(log.len(), 4);
    // The first pass renders every tile (4 of 32x32), the next ones the noisiest; `spp` counts
    // the samples a pixel took on average.
    assert_eq!(log[0]["tiles"], 4);
    let tiles: u64 = log.iter().map(|p| p["tiles"].as_u64().unwrap()).sum();
    assert!((5..=16).contains(&tiles), "{log:?}");
    assert_eq!(stats["spp"].as_u64().unwrap(), (tiles as f64 / 4.0).round() as u64);
    let command = header_attribute(&dir.path().join("four.exr"), "icrender/command");
    assert!(command.contains("--passes 4"), "{command}");
}

/// The header attribute `name` of an EXR (empty when it has none).
fn header_attribute(exr: &Path, name: &str) -> String {
    let image = read_exr(exr);
    image
        .attributes
        .iter()
        .find(|(k, _)| k == name)
        .map(|(_, v)| v.clone())
        .unwrap_or_default()
}

/// `--target-error`: from one noisy pass (about 8e-3) to an estimate at most 3e-3, by passes,
/// and the error measured against the reference at most 1.5 times the target.
#[test]
fn the_target_error_stops_at_the_target() {
    let dir = tempfile::tempdir().unwrap();
    let target = 3e-3;
    let args = [&SIZE[..], &["--light-samples", "1", "--target-error", "3e-3"]].concat();
    let (estimate, error) = estimated_and_measured(dir.path(), "target", reference(), &args);
    let stats: Value = serde_json::from_str(&std::fs::read_to_string(dir.path().join("target.json")).unwrap()).unwrap();
    let passes = &stats["passes"];
    assert_eq!(passes["stopped"], "target reached", "{passes}");
    assert!(passes["passes"].as_u64().unwrap() >= 2, "{passes}");
    let relmse = estimate["relmse"].as_f64().unwrap();
    assert!(relmse <= target, "estimate {relmse:.3e}");
    // The pass before the last was above the target: it stopped at the first pass below.
    let log = passes["log"].as_array().unwrap();
    let before = log[log.len() - 2]["relmse"].as_f64().unwrap();
    assert!(before > target, "{passes}");
    assert!(
        error <= 1.5 * target,
        "measured {error:.3e} for a target of {target:.1e}"
    );
}

/// `--time-limit`: passes until the next would end past the limit. The last pass ends no later
/// than the limit and one pass's time more (the machine may slow down during a pass), and
/// no earlier than the limit less two passes' (it does not stop early); the image written is
/// the last pass's, the mean of every pass.
#[test]
fn the_time_limit_stops_at_the_limit() {
    let dir = tempfile::tempdir().unwrap();
    let limit = 4.0;
    let args = [&SIZE[..], &["--time-limit", "4"]].concat();
    let (_, _) = estimated_and_measured(dir.path(), "limit", reference(), &args);
    let stats: Value = serde_json::from_str(&std::fs::read_to_string(dir.path().join("limit.json")).unwrap()).unwrap();
    let passes = &stats["passes"];
    assert_eq!(passes["stopped"], "time limit", "{passes}");
    let log = passes["log"].as_array().unwrap();
    let ends: Vec<f64> = log.iter().map(|p| p["elapsed_s"].as_f64().unwrap()).collect();
    let longest = ends.windows(2).map(|w| w[1] - w[0]).fold(0.0f64, f64::max);
    let last = *ends.last().unwrap();
    assert!(log.len() >= 3, "{passes}");
    assert!(
        last <= limit + longest,
        "last pass ended at {last:.2} s; the longest took {longest:.2} s"
    );
    assert!(
        last >= limit - 2.0 * longest,
        "stopped at {last:.2} s; the longest pass took {longest:.2} s"
    );
    let final_pass = log.last().unwrap();
    assert_eq!(final_pass["written"], true, "{passes}");
    assert_eq!(passes["passes"], final_pass["pass_of_set"], "{passes}");
}

/// Passes make the same image whatever the threads: the records their samples miss join the
/// set between passes in an order of their own.
#[test]
fn passes_make_the_same_image_whatever_the_threads() {
    let dir = tempfile::tempdir().unwrap();
    let scene = cornell();
    let images: Vec<_> = ["1", "2"]
        .iter()
        .map(|threads| {
            let out = dir.path().join(format!("threads{threads}.exr"));
            let mut args = vec!["render", &scene, "-o", out.to_str().unwrap(), "-q", "--no-preview"];
            args.extend_from_slice(&SIZE);
            args.extend_from_slice(&["--passes", "3", "--spp", "2", "--threads", threads]);
            run_ok(&args);
            read_exr(&out)
        })
        .collect();
    assert_same_image(&images[0], &images[1], &HOW_IT_RAN, "--passes 3 on 1 and 2 threads");
}

/// Whatever way the passes went (more passes, a refined record set, both), the header's command
/// renders the image again, bit for bit: the record set's settings and the passes as rendered
/// (the conference room at -ab 2, whose last-bounce grid takes its sites from -ad).
#[test]
fn the_headers_command_reruns_a_render_in_passes() {
    let dir = tempfile::tempdir().unwrap();
    let scene = shared_scene("conference_room/conference.gltf");
    let scene = scene.to_str().unwrap();
    let first = dir.path().join("first.exr");
    run_ok(&[
        "render",
        scene,
        "-o",
        first.to_str().unwrap(),
        "-x",
        "96",
        "-y",
        "64",
        "-ab",
        "2",
        "--target-error",
        "2e-3",
        "--time-limit",
        "6",
        "-q",
        "--no-preview",
    ]);
    let command = header_attribute(&first, "icrender/command");
    let again = dir.path().join("again.exr");
    let words: Vec<String> = command
        .split_whitespace()
        .skip(1)
        .map(|w| {
            if w == first.to_str().unwrap() {
                again.to_string_lossy().into_owned()
            } else {
                w.to_string()
            }
        })
        .collect();
    assert!(words.iter().any(|w| w == "--passes"), "{command}");
    let mut args: Vec<&str> = words.iter().map(String::as_str).collect();
    args.push("-q");
    run_ok(&args);
    assert_same_image(&read_exr(&first), &read_exr(&again), &HOW_IT_RAN, &command);
}

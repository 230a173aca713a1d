//! Frame sequences through the real binary: a glTF animation of the camera rendered with
//! `--frames` / `--frame`, checked against still renders of a camera placed by hand where the
//! animation puts it; frame file names; the irradiance cache carried from frame to frame; what
//! is refused (mpirun modes); JSON progress per frame; a checkpointed
//! sequence resumed at its first unfinished frame; a farm's prepass over all frames.

mod common;
use common::*;
use serde_json::{Value, json};
use std::path::{Path, PathBuf};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A grey room (4 x 2.5 x 4) lit by a ceiling panel, with a red panel and a white box in it,
/// so that each view of it is a different image.
fn room(b: &mut GltfBuilder) {
    let grey = b.material(lambertian("grey", [0.6, 0.6, 0.6]));
    inward_box(b, [-2.0, 0.0, -2.0], [2.0, 2.5, 2.0], grey);
    let red = b.material(lambertian("red", [0.8, 0.1, 0.1]));
    b.quad(
        facing(
            [
                [-1.5, 0.0, -1.2],
                [-0.2, 0.0, -1.2],
                [-0.2, 1.4, -1.2],
                [-1.5, 1.4, -1.2],
            ],
            [0.0, 1.0, 2.0],
        ),
        Some(red),
    );
    let white = b.material(lambertian("white", [0.9, 0.9, 0.9]));
    inward_box_outside(b, [0.4, 0.0, -1.0], [1.2, 0.8, -0.2], white);
    let lamp = b.material(emissive_lambertian("lamp", [1.0; 3], 6.0));
    b.quad(
        facing(
            [
                [-0.6, 2.45, -0.6],
                [0.6, 2.45, -0.6],
                [0.6, 2.45, 0.6],
                [-0.6, 2.45, 0.6],
            ],
            [0.0, 0.0, 0.0],
        ),
        Some(lamp),
    );
}

/// A closed box seen from outside (fronts facing out).
fn inward_box_outside(b: &mut GltfBuilder, lo: [f32; 3], hi: [f32; 3], material: usize) {
    let [x0, y0, z0] = lo;
    let [x1, y1, z1] = hi;
    let centre = [(x0 + x1) / 2.0, (y0 + y1) / 2.0, (z0 + z1) / 2.0];
    let away = |f: [[f32; 3]; 4]| {
        // Face the point mirrored through the face's centre: outwards.
        let c = [0, 1, 2].map(|k| f.iter().map(|p| p[k]).sum::<f32>() / 4.0);
        facing(f, [0, 1, 2].map(|k| 2.0 * c[k] - centre[k]))
    };
    for f in [
        [[x0, y1, z0], [x1, y1, z0], [x1, y1, z1], [x0, y1, z1]],
        [[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0]],
        [[x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]],
        [[x0, y0, z0], [x0, y1, z0], [x0, y1, z1], [x0, y0, z1]],
        [[x1, y0, z0], [x1, y1, z0], [x1, y1, z1], [x1, y0, z1]],
    ] {
        b.quad(away(f), Some(material));
    }
}

const YFOV: f32 = 1.0;

/// The camera's keys: at t = 0 at (-0.5, 1.2, 1.5) looking down -Z, at t = 1 at
/// (0.5, 1.2, 1.5) turned 60 degrees to the left (about +Y).
const TIMES: [f32; 2] = [0.0, 1.0];
const MOVES: [f32; 6] = [-0.5, 1.2, 1.5, 0.5, 1.2, 1.5];
fn turns() -> [f32; 8] {
    let half = 30f32.to_radians();
    [0.0, 0.0, 0.0, 1.0, 0.0, half.sin(), 0.0, half.cos()]
}

/// The room with a camera node animated by `channels` (node 0 of them is the camera's: its
/// index is filled in), written as `dir/name.gltf`.
fn animated_room(dir: &Path, name: &str, channels: &[(&str, &str, &[f32], &[f32])]) -> PathBuf {
    let mut b = GltfBuilder::new();
    room(&mut b);
    let camera = b.perspective_camera(YFOV);
    let node = b.node(json!({"name": "cam", "camera": camera, "translation": [0.0, 1.2, 1.9]}));
    let channels: Vec<Channel<'_>> = channels.iter().map(|&(p, i, t, v)| (node, p, i, t, v)).collect();
    b.animation("walk", &channels);
    b.write(dir, name)
}

/// The room with a still camera at `translation`, turned by the unit quaternion `rotation`.
fn still_room(dir: &Path, name: &str, translation: [f64; 3], rotation: [f64; 4]) -> PathBuf {
    let mut b = GltfBuilder::new();
    room(&mut b);
    let camera = b.perspective_camera(YFOV);
    b.node(json!({"name": "cam", "camera": camera, "translation": translation, "rotation": rotation}));
    b.write(dir, name)
}

/// Brute force (no cache), small and quick: an image that depends on the view alone.
const BRUTE: [&str; 10] = ["-x", "48", "-y", "36", "-aa", "0", "-ad", "64", "--aovs", "none"];

/// Renders into `dir` with quiet, no preview and `extra`; panics with stderr on failure.
fn render(scene: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["render", s(scene), "-q", "--no-preview"];
    args.extend_from_slice(extra);
    run_ok(&args)
}

/// The numbers of a header's view line (-vp x y z -vd x y z -vu x y z -vh h -vv v).
fn view_numbers(image: &Path) -> Vec<f64> {
    let data = read_image(image, &["icrender/view"]).unwrap();
    let view = data.attribute("icrender/view").unwrap().to_string();
    view.split_whitespace().filter_map(|t| t.parse().ok()).collect()
}

/// The largest difference of any channel of any pixel, relative to the larger value (and an
/// absolute floor for black).
fn largest_difference(a: &ImageData, b: &ImageData) -> f64 {
    let mut worst = 0.0f64;
    for ((name, x), (other, y)) in a.channels.iter().zip(&b.channels) {
        assert_eq!(name, other);
        for (p, q) in x.iter().zip(y) {
            let d = (p - q).abs() as f64 / (p.abs().max(q.abs()) as f64).max(1e-3);
            worst = worst.max(d);
        }
    }
    worst
}

/// The expected still camera of the LINEAR animation at time t (0..1): translation lerped,
/// rotation the key's angle times t about +Y (slerp turns at a constant rate).
fn linear_pose(t: f64) -> ([f64; 3], [f64; 4]) {
    let m = MOVES.map(|v| v as f64);
    let translation = [0, 1, 2].map(|i| m[i] + t * (m[3 + i] - m[i]));
    let q = turns().map(|v| v as f64);
    let key_angle = 2.0 * q[5].atan2(q[7]);
    let half = 0.5 * t * key_angle;
    (translation, [0.0, half.sin(), 0.0, half.cos()])
}

/// Runs a small render of `scene` with `frames` (`--frames A-B` or `--frame N`) to `out`, which
/// must be refused as bad input (exit 2); returns what it said.
fn refused_frames(scene: &Path, frames: &[&str], out: &Path) -> String {
    let mut args = vec!["render", s(scene), "-q"];
    args.extend(frames);
    args.extend(["-x", "8", "-y", "6", "-o", s(out)]);
    let refused = run(&args);
    let e = stderr(&refused);
    assert_eq!(refused.status.code(), Some(2), "{}: {e}", scene.display());
    e
}

#[test]
fn each_frame_is_the_still_render_of_the_camera_where_the_animation_puts_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let turns = turns();
    let scene = animated_room(
        d,
        "walk",
        &[
            ("translation", "LINEAR", &TIMES, &MOVES),
            ("rotation", "LINEAR", &TIMES, &turns),
        ],
    );
    // --fps 4: frames 1..3 are at 0.25, 0.5 and 0.75 s; frame 6 is past the last key.
    let out = d.join("walk.####.exr");
    let mut args = vec!["--frames", "1-3", "--fps", "4", "-o", s(&out)];
    args.extend(BRUTE);
    render(&scene, &args);
    for (frame, t) in [(1, 0.25), (2, 0.5), (3, 0.75)] {
        let (translation, rotation) = linear_pose(t);
        let still = still_room(d, &format!("still{frame}"), translation, rotation);
        let expected = d.join(format!("still{frame}.exr"));
        let mut args = vec!["-o", s(&expected)];
        args.extend(BRUTE);
        render(&still, &args);
        let got = d.join(format!("walk.000{frame}.exr"));
        // The views agree to f32 rounding (the header writes them in world coordinates).
        let (a, b) = (view_numbers(&got), view_numbers(&expected));
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() < 1e-5, "frame {frame}: view {a:?} against {b:?}");
        }
        // The camera really moved: frame 2 stands at x = 0 turned 30 degrees.
        if frame == 2 {
            assert!(a[0].abs() < 1e-6 && (a[3] + 0.5).abs() < 1e-6, "{a:?}");
        }
        // And the images are the still render's: the same rays up to the view's last bits.
        let diff = largest_difference(&read_exr(&got), &read_exr(&expected));
        eprintln!("frame {frame}: largest difference {diff:e}");
        assert!(diff < 1e-3, "frame {frame}: differs by {diff}");
    }
}

#[test]
fn step_keys_hold_until_the_next_key_and_the_ends_hold_the_first_and_last() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = animated_room(d, "step", &[("translation", "STEP", &TIMES, &MOVES)]);
    // At 24 fps frame 23 is still before the second key (t = 1), frame 24 is on it, and
    // frame 30 is past the last key.
    let out = d.join("step.%04d.exr");
    for frame in ["23", "24", "30"] {
        let mut args = vec!["--frame", frame, "-o", s(&out)];
        args.extend(BRUTE);
        render(&scene, &args);
    }
    let first = still_room(d, "first", [-0.5, 1.2f32 as f64, 1.5], [0.0, 0.0, 0.0, 1.0]);
    let last = still_room(d, "last", [0.5, 1.2f32 as f64, 1.5], [0.0, 0.0, 0.0, 1.0]);
    for (still, name) in [(&first, "first"), (&last, "last")] {
        let path = d.join(format!("{name}.exr"));
        let mut args = vec!["-o", s(&path)];
        args.extend(BRUTE);
        render(still, &args);
    }
    let image = |name: &str| read_exr(&d.join(name));
    // A STEP key's value is exact: the same view, so the same image bit for bit.
    assert_eq!(largest_difference(&image("step.0023.exr"), &image("first.exr")), 0.0);
    assert_eq!(largest_difference(&image("step.0024.exr"), &image("last.exr")), 0.0);
    assert_eq!(largest_difference(&image("step.0030.exr"), &image("last.exr")), 0.0);
    assert!(largest_difference(&image("first.exr"), &image("last.exr")) > 0.1);
}

#[test]
fn a_frame_of_a_still_scene_is_the_still_render() {
    // The frames' camera is evaluated from the node tree as the loader places it at rest: a
    // camera nothing animates is exactly where a still render puts it, under a turned and
    // moved parent too.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut b = GltfBuilder::new();
    room(&mut b);
    let camera = b.perspective_camera(YFOV);
    let cam = b.node(json!({"camera": camera, "translation": [0.1, 0.2, 0.3], "rotation": [0.0, 0.2, 0.0, 0.98]}));
    b.node(json!({"children": [cam], "translation": [0.2, 1.0, 1.2], "rotation": [0.05, 0.0, 0.0, 0.999], "scale": [1.0, 1.1, 1.0]}));
    let scene = b.write(d, "parented");
    let (still_exr, frame_exr) = (d.join("still.exr"), d.join("frame.exr"));
    let mut args = vec!["-o", s(&still_exr)];
    args.extend(BRUTE);
    render(&scene, &args);
    let mut args = vec!["--frame", "5", "-o", s(&frame_exr)];
    args.extend(BRUTE);
    let out = render(&scene, &args);
    assert!(stderr(&out).is_empty(), "{}", stderr(&out));
    let (a, b) = (read_exr(&d.join("still.exr")), read_exr(&d.join("frame.exr")));
    assert_eq!(largest_difference(&a, &b), 0.0);
    assert_eq!(view_numbers(&d.join("still.exr")), view_numbers(&d.join("frame.exr")));
}

#[test]
fn frame_numbers_go_into_the_output_names_as_farm_managers_write_them() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = animated_room(d, "names", &[("translation", "LINEAR", &TIMES, &MOVES)]);
    let quick = ["-x", "8", "-y", "6", "-ab", "0"];
    let names = |dir: &Path| {
        let mut n: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        n.sort();
        n
    };
    let cases: [(&str, &[&str], &[&str]); 5] = [
        (
            "a/out.####.exr",
            &["--frames", "1-3"],
            &["out.0001.exr", "out.0002.exr", "out.0003.exr"],
        ),
        (
            "b/out.%04d.exr",
            &["--frames", "9-10"],
            &["out.0009.exr", "out.0010.exr"],
        ),
        // No placeholder and several frames: `.####` goes before the extension.
        ("c/out.exr", &["--frames", "98-99"], &["out.0098.exr", "out.0099.exr"]),
        // One frame and no placeholder: the name as it is.
        ("d/out.exr", &["--frame", "7"], &["out.exr"]),
        ("e/shot_##.exr", &["--frame", "7"], &["shot_07.exr"]),
    ];
    for (pattern, frames, expected) in cases {
        let out = d.join(pattern);
        std::fs::create_dir_all(out.parent().unwrap()).unwrap();
        let mut args = vec!["render", s(&scene), "-q", "-o", s(&out), "--no-preview"];
        args.extend_from_slice(frames);
        args.extend(quick);
        run_ok(&args);
        assert_eq!(names(out.parent().unwrap()), expected, "{pattern} {frames:?}");
    }
    // The preview and the statistics follow the frame's name.
    let out = d.join("f/out.####.exr");
    std::fs::create_dir_all(d.join("f")).unwrap();
    let stats = d.join("f/stats.json");
    let mut args = vec![
        "render",
        s(&scene),
        "-q",
        "-o",
        s(&out),
        "--stats",
        s(&stats),
        "--frames",
        "1-2",
    ];
    args.extend(quick);
    run_ok(&args);
    assert_eq!(
        names(&d.join("f")),
        [
            "out.0001.exr",
            "out.0001.png",
            "out.0002.exr",
            "out.0002.png",
            "stats.0001.json",
            "stats.0002.json"
        ]
    );
    // An existing frame is never replaced without --overwrite: nothing is rendered.
    let again = run(&args);
    assert_eq!(again.status.code(), Some(2));
    assert!(
        stderr(&again).contains("out.0001.exr: already exists"),
        "{}",
        stderr(&again)
    );
    // Two placeholders are refused.
    let bad = d.join("g/o.##.%04d.exr");
    let refused = run(&[
        "render",
        s(&scene),
        "-q",
        "-o",
        s(&bad),
        "--frames",
        "1-2",
        "-x",
        "8",
        "-y",
        "6",
    ]);
    assert_eq!(refused.status.code(), Some(2));
    assert!(
        stderr(&refused).contains("2 frame number placeholders"),
        "{}",
        stderr(&refused)
    );
}

fn stats_of(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn the_cache_is_carried_from_frame_to_frame_and_later_frames_make_few_records() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let turns = turns();
    let scene = animated_room(
        d,
        "walk",
        &[
            ("translation", "LINEAR", &TIMES, &MOVES),
            ("rotation", "LINEAR", &TIMES, &turns),
        ],
    );
    // At 24 fps the camera moves 1/24 of its path (4 cm, 2.5 degrees) a frame.
    let size = ["-x", "64", "-y", "48", "--fps", "24"];
    let out = d.join("seq.####.exr");
    let stats = d.join("seq.json");
    let mut args = vec!["--frames", "2-4", "-o", s(&out), "--stats", s(&stats)];
    args.extend(size);
    render(&scene, &args);
    let frame_stats: Vec<Value> = (2..=4).map(|n| stats_of(&d.join(format!("seq.000{n}.json")))).collect();
    let made = |v: &Value| v["records_computed"].as_u64().unwrap();
    let before = |v: &Value| v["records_before"].as_u64().unwrap();
    assert_eq!(frame_stats[0]["frame"], 2);
    assert_eq!(frame_stats[0]["frame_time_s"], 2.0 / 24.0);
    assert_eq!(before(&frame_stats[0]), 0);
    for k in 1..3 {
        // Each frame starts with every record the frames before made...
        assert_eq!(
            before(&frame_stats[k]),
            frame_stats[k - 1]["cache_records"].as_u64().unwrap(),
            "frame {}",
            k + 2
        );
        // ... and makes far fewer of its own.
        eprintln!(
            "frame {}: {} records made, {} before",
            k + 2,
            made(&frame_stats[k]),
            before(&frame_stats[k])
        );
        assert!(
            made(&frame_stats[k]) * 3 < made(&frame_stats[0]),
            "frame {}: {} records against {} for the first",
            k + 2,
            made(&frame_stats[k]),
            made(&frame_stats[0])
        );
    }
    // Frame 3 alone, and brute force of it: the carried frame is within the cache's error.
    let alone = d.join("alone.exr");
    let alone_stats = d.join("alone.json");
    let mut args = vec!["--frame", "3", "-o", s(&alone), "--stats", s(&alone_stats)];
    args.extend(size);
    render(&scene, &args);
    assert_eq!(stats_of(&alone_stats)["records_before"], 0);
    assert!(made(&stats_of(&alone_stats)) > 2 * made(&frame_stats[1]));
    let brute = d.join("brute.exr");
    let mut args = vec!["--frame", "3", "-o", s(&brute), "-aa", "0", "-ad", "512"];
    args.extend(size);
    render(&scene, &args);
    let (carried, alone, brute) = (read_exr(&d.join("seq.0003.exr")), read_exr(&alone), read_exr(&brute));
    let (e_carried, e_alone) = (relmse(&carried, &brute), relmse(&alone, &brute));
    eprintln!(
        "relmse carried {e_carried:.3e} alone {e_alone:.3e}, first frame {} records",
        made(&frame_stats[0])
    );
    assert!(
        e_carried < 1.5 * e_alone + 1e-4,
        "carried relMSE {e_carried:.3e} against {e_alone:.3e} for the frame alone"
    );
    let indirect = |i: &ImageData| rgb(i, "indirect").iter().map(|c| mean(c)).sum::<f64>();
    let (a, b) = (indirect(&carried), indirect(&alone));
    assert!((a - b).abs() < 0.02 * b, "indirect mean {a} carried against {b} alone");
}

#[test]
fn frames_are_refused_under_the_mpi_modes_with_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let scene = animated_room(dir.path(), "walk", &[("translation", "LINEAR", &TIMES, &MOVES)]);
    for frames in [["--frames", "1-2"], ["--frame", "3"]] {
        let mut args = vec!["render", s(&scene), "--mode", "noshare", "-x", "8", "-y", "6"];
        args.extend(frames);
        let out = run(&args);
        assert_eq!(out.status.code(), Some(2));
        let e = stderr(&out);
        assert!(
            e.contains("one process (no mpirun, no --mode)") && e.lines().count() == 1,
            "{e}"
        );
    }
}

#[test]
fn json_progress_lines_carry_the_frame_and_each_frame_is_announced_when_written() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = animated_room(d, "walk", &[("translation", "LINEAR", &TIMES, &MOVES)]);
    let out = d.join("p.####.exr");
    let result = run_ok(&[
        "render",
        s(&scene),
        "--frames",
        "4-6",
        "-x",
        "32",
        "-y",
        "24",
        "--tile",
        "8x8",
        "--progress",
        "json",
        "-o",
        s(&out),
    ]);
    let lines: Vec<Value> = stdout(&result)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let (last, steps) = lines.split_last().unwrap();
    assert_eq!(last["event"], "done");
    assert_eq!(last["frames"], "4-6");
    assert_eq!(last["output"], s(&d.join("p.####.exr")));
    let mut previous = 0.0;
    let mut written = Vec::new();
    for step in steps {
        let fraction = step["fraction"].as_f64().unwrap();
        assert!(
            fraction >= previous,
            "fractions grow over the whole sequence: {lines:?}"
        );
        previous = fraction;
        let frame = step["frame"].as_u64().unwrap_or_else(|| panic!("no frame in {step}"));
        match step["event"].as_str().unwrap() {
            "progress" => assert_eq!(frame, 4 + written.len() as u64, "{step}"),
            "frame_done" => {
                // Written whole before the next frame begins.
                let path = PathBuf::from(step["output"].as_str().unwrap());
                assert_eq!(path, d.join(format!("p.000{frame}.exr")));
                assert!(path.exists());
                written.push(frame);
            }
            other => panic!("event {other}"),
        }
    }
    assert_eq!(written, [4, 5, 6]);
    assert_eq!(previous, 1.0);
}

#[test]
fn a_checkpointed_sequence_resumes_at_its_first_unfinished_frame() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = animated_room(d, "walk", &[("translation", "LINEAR", &TIMES, &MOVES)]);
    let out = d.join("c.####.exr");
    let checkpoint = d.join("ck");
    let common = [
        "-x",
        "32",
        "-y",
        "24",
        "--fps",
        "8",
        "-o",
        s(&out),
        "--checkpoint",
        s(&checkpoint),
    ];
    let (a_json, b_json) = (d.join("a.json"), d.join("b.json"));
    let mut first = vec!["render", s(&scene), "--frames", "1-2", "--stats", s(&a_json)];
    first.extend(common);
    run_ok(&first);
    let records_after_two = stats_of(&d.join("a.0002.json"))["cache_records"].as_u64().unwrap();
    let written = std::fs::read(d.join("c.0001.exr")).unwrap();
    // The farm runs the task again with a longer range: frames 1 and 2 are finished, frame 3
    // starts from the cache the first run left in the checkpoint.
    let mut again = vec!["render", s(&scene), "--frames", "1-3", "--stats", s(&b_json)];
    again.extend(common);
    let result = run_ok(&again);
    let e = stderr(&result);
    assert!(
        e.contains("frame 1: finished by an earlier run") && e.contains("frame 2: finished"),
        "{e}"
    );
    assert_eq!(
        std::fs::read(d.join("c.0001.exr")).unwrap(),
        written,
        "frame 1 is not touched"
    );
    assert!(!d.join("b.0001.json").exists());
    let third = stats_of(&d.join("b.0003.json"));
    assert_eq!(third["records_before"].as_u64().unwrap(), records_after_two);
    assert_eq!(third["records_loaded"].as_u64().unwrap(), records_after_two);
    assert!(d.join("c.0003.exr").exists());
}

#[test]
fn a_prepass_over_all_frames_serves_frame_tasks_that_make_no_records() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let turns = turns();
    let scene = animated_room(
        d,
        "walk",
        &[
            ("translation", "LINEAR", &TIMES, &MOVES),
            ("rotation", "LINEAR", &TIMES, &turns),
        ],
    );
    let cache = d.join("job.icc");
    let size = ["-x", "48", "-y", "36", "--fps", "4"];
    let prepass_json = d.join("prepass.json");
    let mut args = vec![
        "cache",
        s(&scene),
        "-af",
        s(&cache),
        "--frames",
        "0-4",
        "-q",
        "--stats",
        s(&prepass_json),
    ];
    args.extend(size);
    run_ok(&args);
    let prepass = stats_of(&d.join("prepass.json"));
    let per_frame = prepass["frames"].as_array().unwrap();
    assert_eq!(per_frame.len(), 5);
    let total = prepass["records_total"].as_u64().unwrap();
    // Two chunks of frames, each reading the file only, and all frames in one task.
    for (chunk, frames) in [("a", "0-2"), ("b", "3-4"), ("all", "0-4")] {
        let out = d.join(format!("{chunk}.####.exr"));
        let stats = d.join(format!("{chunk}.json"));
        let mut args = vec![
            "--frames",
            frames,
            "-af",
            s(&cache),
            "--af-read-only",
            "-o",
            s(&out),
            "--stats",
            s(&stats),
        ];
        args.extend(size);
        render(&scene, &args);
    }
    for (chunk, n) in [("a", 0), ("a", 1), ("a", 2), ("b", 3), ("b", 4)] {
        let st = stats_of(&d.join(format!("{chunk}.000{n}.json")));
        assert_eq!(st["prepass_records"], 0, "frame {n}: {st}");
        assert_eq!(st["records_loaded"].as_u64().unwrap(), total);
        // Every frame interpolates the file's records alone: the same image however chunked.
        let (a, b) = (
            read_exr(&d.join(format!("{chunk}.000{n}.exr"))),
            read_exr(&d.join(format!("all.000{n}.exr"))),
        );
        assert_eq!(largest_difference(&a, &b), 0.0, "frame {n}");
    }
}

#[test]
fn a_broken_camera_animation_is_refused_for_frames_and_a_still_render_ignores_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Key times that go back: glTF 2.0 requires them to increase strictly.
    let scene = animated_room(d, "broken", &[("translation", "LINEAR", &[1.0, 0.5], &MOVES)]);
    let e = refused_frames(&scene, &["--frames", "1-2"], &d.join("b.exr"));
    assert!(
        e.contains("broken.gltf") && e.contains("animation 'walk'") && e.contains("key times must increase strictly"),
        "{e}"
    );
    render(&scene, &["-x", "8", "-y", "6", "-o", s(&d.join("still.exr"))]);
}

#[test]
fn sigterm_stops_a_sequence_between_whole_frames_and_the_same_command_goes_on() {
    use std::io::{BufRead, BufReader};
    use std::process::{Command, Stdio};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = animated_room(d, "walk", &[("translation", "LINEAR", &TIMES, &MOVES)]);
    let out = d.join("out").join("s.####.exr");
    std::fs::create_dir_all(d.join("out")).unwrap();
    let checkpoint = d.join("ck");
    let args = [
        "render",
        s(&scene),
        "--frames",
        "1-6",
        "-x",
        "96",
        "-y",
        "72",
        "--spp",
        "4",
        "--tile",
        "16x16",
        "--progress",
        "json",
        "--no-preview",
        "-o",
        s(&out),
        "--checkpoint",
        s(&checkpoint),
    ];
    let mut child = Command::new(binary())
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Stop it once the first frame is written.
    for line in BufReader::new(child.stdout.take().unwrap()).lines() {
        let step: Value = serde_json::from_str(&line.unwrap()).unwrap();
        assert_ne!(step["event"], "done", "the sequence ended before it could be stopped");
        if step["event"] == "frame_done" {
            break;
        }
    }
    let kill = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let output = child.wait_with_output().unwrap();
    let e = String::from_utf8_lossy(&output.stderr).into_owned();
    assert_eq!(output.status.code(), Some(143), "{e}");
    // Only whole frames, from the first on: each written file reads back.
    let mut names: Vec<String> = std::fs::read_dir(d.join("out"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    let k = names.len();
    assert!((1..6).contains(&k), "{names:?}");
    assert_eq!(names, (1..=k).map(|n| format!("s.000{n}.exr")).collect::<Vec<_>>());
    for name in &names {
        read_exr(&d.join("out").join(name));
    }
    let frames_text = if k == 1 {
        "frame 1 is written".to_string()
    } else {
        format!("frames 1-{k} are written")
    };
    assert!(
        e.contains(&format!("stopped by SIGTERM during frame {}: {frames_text}", k + 1))
            && e.contains("the same command resumes"),
        "{e}"
    );
    // The same command skips the written frames and renders the rest.
    let again = run_ok(&args);
    let e = stderr(&again);
    assert!(e.contains(&format!("frame {k}: finished by an earlier run")), "{e}");
    for n in 1..=6 {
        assert!(d.join("out").join(format!("s.000{n}.exr")).exists(), "frame {n}");
    }
}

#[test]
fn animations_breaking_gltf_rules_are_named_when_frames_need_them() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = animated_room(d, "good", &[("translation", "LINEAR", &TIMES, &MOVES)]);
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&scene).unwrap()).unwrap();
    let input = doc["animations"][0]["samplers"][0]["input"].clone();
    type Edit = fn(&mut Value, &Value);
    let cases: [(&str, Edit, &str); 4] = [
        (
            "bezier",
            |a, _| a["samplers"][0]["interpolation"] = json!("BEZIER"),
            "interpolation 'BEZIER' is not LINEAR, STEP or CUBICSPLINE",
        ),
        (
            "sampler",
            |a, _| a["channels"][0]["sampler"] = json!(5),
            "sampler 5 out of range",
        ),
        (
            "scalar",
            |a, input| a["samplers"][0]["output"] = input.clone(),
            "output must be VEC3 float, got float SCALAR",
        ),
        (
            "cubic",
            |a, _| a["samplers"][0]["interpolation"] = json!("CUBICSPLINE"),
            "2 outputs for 2 key times (CUBICSPLINE needs three per key",
        ),
    ];
    for (name, edit, expected) in cases {
        let mut broken = doc.clone();
        edit(&mut broken["animations"][0], &input);
        let path = d.join(format!("{name}.gltf"));
        std::fs::write(&path, serde_json::to_string(&broken).unwrap()).unwrap();
        let out = d.join(format!("{name}.exr"));
        let e = refused_frames(&path, &["--frame", "3"], &out);
        assert!(
            e.contains("animation 'walk': channel 0") && e.contains(expected),
            "{name}: {e}"
        );
        // The still render of the same file does not need the animation.
        render(&path, &["-x", "8", "-y", "6", "-o", s(&out)]);
    }
}

#[test]
fn a_reference_of_one_frame_has_that_frame_s_view() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = animated_room(d, "walk", &[("translation", "LINEAR", &TIMES, &MOVES)]);
    let frame = d.join("f.####.exr");
    let mut args = vec!["--frame", "12", "-o", s(&frame)];
    args.extend(BRUTE);
    render(&scene, &args);
    let reference = d.join("ref.####.exr");
    run_ok(&[
        "reference",
        s(&scene),
        "--frame",
        "12",
        "-x",
        "48",
        "-y",
        "36",
        "-ad",
        "16",
        "--noise",
        "0.5",
        "--max-seconds",
        "5",
        "-q",
        "--no-preview",
        "-o",
        s(&reference),
    ]);
    let written = d.join("ref.0012.exr");
    assert_eq!(view_numbers(&written), view_numbers(&d.join("f.0012.exr")));
    let header = read_image(&written, &["icrender/frame", "icrender/frame_time_s"]).unwrap();
    assert_eq!(header.attribute("icrender/frame"), Some("12"));
    assert_eq!(header.attribute("icrender/frame_time_s"), Some("0.5"));
    let several = run(&["reference", s(&scene), "--frames", "1-2", "-x", "8", "-y", "6", "-q"]);
    assert_eq!(several.status.code(), Some(2));
    assert!(
        stderr(&several).contains("a reference is one image"),
        "{}",
        stderr(&several)
    );
}

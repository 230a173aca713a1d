//! Region renders, their merge and the cache prepass command, through the real binary: a farm's
//! prepass task, region tasks reading its cache file, and the merge task.

mod common;
use common::*;
use icrender::sys::image_io::read_image_with_header;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Output;

/// An uneven 2x2 split of the 128x96 image (70 + 58 columns, 52 + 44 rows): the borders are
/// x = 70 and y = 52, the only borders of a 70x52 tile grid on this image.
const SIZE: [&str; 4] = ["-x", "128", "-y", "96"];
const SPLIT: [[u32; 4]; 4] = [[0, 0, 70, 52], [70, 0, 128, 52], [0, 52, 70, 96], [70, 52, 128, 96]];

fn cornell() -> PathBuf {
    project_dir().join("scenes/cornell.gltf")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Renders `region` of the image to `dir/name.exr` with `extra` options; returns the
/// statistics.
fn render_part(dir: &Path, name: &str, region: [u32; 4], extra: &[&str]) -> Value {
    let r: Vec<String> = region.iter().map(u32::to_string).collect();
    let mut args: Vec<&str> = vec!["--region", &r[0], &r[1], &r[2], &r[3]];
    args.extend_from_slice(extra);
    render_to(dir, &cornell(), name, &args).1
}

/// `icrender merge OUT PARTS...` in `dir`.
fn merge(dir: &Path, out: &str, parts: &[&str]) -> Output {
    let out = dir.join(out);
    let parts: Vec<PathBuf> = parts.iter().map(|p| dir.join(format!("{p}.exr"))).collect();
    let mut args = vec!["merge", s(&out)];
    args.extend(parts.iter().map(|p| s(p)));
    run(&args)
}

/// The mean log step across the 70x52 grid's borders (the region borders) of a layer.
fn step_across(image: &Path) -> f64 {
    let out = run_ok(&["seams", s(image), "--tile", "70x52", "--json"]);
    let report: Value = serde_json::from_str(&stdout(&out)).unwrap();
    report["across"].as_f64().unwrap()
}

fn same_bits(a: &ImageData, b: &ImageData) -> Result<(), String> {
    let names = |i: &ImageData| i.channels.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>();
    if names(a) != names(b) {
        return Err(format!("channels {:?} against {:?}", names(a), names(b)));
    }
    for ((name, x), (_, y)) in a.channels.iter().zip(&b.channels) {
        if let Some(i) = (0..x.len()).find(|&i| x[i].to_bits() != y[i].to_bits()) {
            return Err(format!("{name} differs at pixel {i}: {} against {}", x[i], y[i]));
        }
    }
    Ok(())
}

fn records_in(stats: &Value) -> (u64, u64, u64) {
    (
        stats["prepass_records"].as_u64().unwrap(),
        stats["gap_records"].as_u64().unwrap(),
        stats["records_computed"].as_u64().unwrap(),
    )
}

#[test]
fn regions_with_the_prepass_cache_merge_into_the_full_render_without_seams() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cache = d.join("cache.icc");
    let cache_stats = d.join("cache.json");
    // The prepass task, with more samples where edges cross pixels: its records serve them too,
    // and every region finds the same edge pixels from the same corner rays.
    let scene = cornell();
    let edges = ["--edge-samples", "4"];
    let mut args = vec!["cache", s(&scene), "-af", s(&cache), "--stats", s(&cache_stats)];
    args.extend(SIZE);
    args.extend(edges);
    let out = run_ok(&args);
    assert!(stderr(&out).contains("records made"), "{}", stderr(&out));
    let made: Value = serde_json::from_str(&std::fs::read_to_string(&cache_stats).unwrap()).unwrap();
    let records = made["records_made"].as_u64().unwrap();
    assert!(records > 100, "{made}");
    let bytes_before = std::fs::read(&cache).unwrap();
    let mtime_before = std::fs::metadata(&cache).unwrap().modified().unwrap();

    let shared = [&SIZE[..], &edges, &["-af", s(&cache), "--af-read-only"]].concat();
    let (_, full_stats) = render_to(d, &cornell(), "full", &shared);
    assert_eq!(records_in(&full_stats), (0, 0, 0), "the full render made records");
    let edge_pixels = full_stats["edge_pixels"].as_u64().unwrap();
    assert!(edge_pixels > 0, "{full_stats}");
    let mut parts_edge_pixels = 0;
    let mut names = Vec::new();
    for (k, region) in SPLIT.iter().enumerate() {
        let name = format!("shared{k}");
        let stats = render_part(d, &name, *region, &shared);
        // The region tasks only read the prepass's records: none made in their prepass or final pass.
        assert_eq!(records_in(&stats), (0, 0, 0), "{name} made records");
        assert_eq!(stats["records_loaded"].as_u64(), Some(records), "{name}");
        parts_edge_pixels += stats["edge_pixels"].as_u64().unwrap();
        // The part's data window is its region inside the whole display window.
        let part = read_image_with_header(&d.join(format!("{name}.exr"))).unwrap();
        assert_eq!(
            (part.width, part.height),
            (region[2] - region[0], region[3] - region[1])
        );
        assert_eq!(
            (
                part.window.x,
                part.window.y,
                part.window.full_width,
                part.window.full_height
            ),
            (region[0], region[1], 128, 96)
        );
        let named: Vec<String> = region.iter().map(u32::to_string).collect();
        assert_eq!(part.attribute("icrender/region"), Some(named.join(" ").as_str()));
        names.push(name);
    }
    assert_eq!(parts_edge_pixels, edge_pixels);
    // Read-only: the file is exactly as the prepass left it.
    assert_eq!(std::fs::read(&cache).unwrap(), bytes_before);
    assert_eq!(std::fs::metadata(&cache).unwrap().modified().unwrap(), mtime_before);

    // The merge task, parts in any order.
    let order: Vec<&str> = [2, 0, 3, 1].iter().map(|&k| names[k].as_str()).collect();
    let out = merge(d, "merged.exr", &order);
    assert!(out.status.success(), "{}", stderr(&out));
    let merged = read_image_with_header(&d.join("merged.exr")).unwrap();
    let full = read_image_with_header(&d.join("full.exr")).unwrap();
    // Same camera, seeds and records: every channel of every layer bit for bit.
    same_bits(&merged, &full).unwrap();
    assert_eq!(
        (merged.width, merged.height, merged.window.x, merged.window.y),
        (128, 96, 0, 0)
    );
    assert_eq!(merged.attribute("icrender/region"), None);
    let listed = merged.attribute("icrender/merged_parts").unwrap();
    assert!(names.iter().all(|n| listed.contains(&format!("{n}.exr"))), "{listed}");
    for kept in [
        "icrender/options",
        "icrender/aovs",
        "icrender/part_settings",
        "icrender/view",
    ] {
        assert_eq!(merged.attribute(kept), full.attribute(kept), "{kept}");
    }
    let parts: Value = serde_json::from_str(merged.attribute("icrender/parts").unwrap()).unwrap();
    assert_eq!(parts.as_array().unwrap().len(), 4);

    // Without the shared cache each region builds its own records and the borders step.
    for (k, region) in SPLIT.iter().enumerate() {
        render_part(d, &format!("own{k}"), *region, &SIZE);
    }
    let out = merge(d, "own.exr", &["own0", "own1", "own2", "own3"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let (full_step, shared_step, own_step) = (
        step_across(&d.join("full.exr")),
        step_across(&d.join("merged.exr")),
        step_across(&d.join("own.exr")),
    );
    eprintln!(
        "mean log step across region borders (indirect): full {full_step:.4}, shared cache {shared_step:.4}, own caches {own_step:.4}"
    );
    assert!(
        shared_step <= full_step * 1.02 + 1e-4,
        "{shared_step} against {full_step}"
    );
    assert!(own_step > 1.5 * full_step, "{own_step} against {full_step}");
}

#[test]
fn a_part_s_preview_is_the_part_and_the_region_is_checked() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let exr = d.join("part.exr");
    let scene = cornell();
    let base = [
        "render",
        s(&scene),
        "-x",
        "48",
        "-y",
        "36",
        "-q",
        "-aa",
        "0",
        "-ab",
        "0",
    ];
    fn with<'a>(base: &[&'a str], extra: &[&'a str]) -> Vec<&'a str> {
        [base, extra].concat()
    }
    run_ok(&with(&base, &["-o", s(&exr), "--region", "5", "7", "30", "36"]));
    let preview = read_image(&exr.with_extension("png"), &[]).unwrap();
    assert_eq!((preview.width, preview.height), (25, 29));

    for (region, says) in [
        (["0", "0", "49", "36"], "not inside the 48x36 image"),
        (["0", "30", "48", "37"], "not inside"),
        (["10", "0", "10", "36"], "is empty"),
        (["20", "0", "10", "36"], "is empty"),
    ] {
        let out = run(&with(
            &base,
            &[
                "-o",
                s(&d.join("bad.exr")),
                "--region",
                region[0],
                region[1],
                region[2],
                region[3],
            ],
        ));
        assert_eq!(out.status.code(), Some(2), "{region:?}: {}", stderr(&out));
        assert!(stderr(&out).contains(says), "{region:?}: {}", stderr(&out));
        assert!(!d.join("bad.exr").exists());
    }
    let out = run(&with(
        &base,
        &[
            "-o",
            s(&d.join("bad.exr")),
            "--region",
            "0",
            "0",
            "8",
            "8",
            "--mode",
            "noshare",
        ],
    ));
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("one process"), "{}", stderr(&out));
    // A reference is a whole image: the merged image is what to compare.
    let out = run(&with(
        &base,
        &[
            "-o",
            s(&d.join("bad.exr")),
            "--region",
            "0",
            "0",
            "8",
            "8",
            "--reference",
            s(&exr),
        ],
    ));
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("merge them"), "{}", stderr(&out));
    assert!(!d.join("bad.exr").exists());
}

#[test]
fn merge_refuses_missing_overlapping_and_foreign_parts() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let small = ["-x", "48", "-y", "36"];
    let quads = [[0, 0, 24, 18], [24, 0, 48, 18], [0, 18, 24, 36], [24, 18, 48, 36]];
    for (k, region) in quads.iter().enumerate() {
        render_part(d, &format!("p{k}"), *region, &small);
    }
    let out = merge(d, "ok.exr", &["p0", "p1", "p2", "p3"]);
    assert!(out.status.success(), "{}", stderr(&out));

    let refused = |out: Output, says: &[&str]| {
        let text = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{text}");
        assert_eq!(text.lines().count(), 1, "{text}");
        for s in says {
            assert!(text.contains(s), "{s:?} not in {text}");
        }
        assert!(!d.join("bad.exr").exists());
    };
    // A missing part: the pixels nobody rendered are named.
    refused(
        merge(d, "bad.exr", &["p0", "p1", "p3"]),
        &["no part covers the pixels 0 18 24 36"],
    );
    // Overlapping parts: both are named.
    render_part(d, "wide", [0, 18, 30, 36], &small);
    refused(
        merge(d, "bad.exr", &["p0", "p1", "wide", "p2", "p3"]),
        &["wide.exr", "p2.exr", "overlap"],
    );
    // A part made with other settings: the part and the first setting that differs.
    render_part(d, "other", [24, 18, 48, 36], &[&small[..], &["-aa", "0.3"]].concat());
    refused(
        merge(d, "bad.exr", &["p0", "p1", "p2", "other"]),
        &["other.exr", "other settings", "-aa 0.3", "-aa 0.2"],
    );
    // A part of another image size.
    render_part(d, "bigger", [24, 18, 48, 36], &["-x", "64", "-y", "36"]);
    refused(
        merge(d, "bad.exr", &["p0", "p1", "p2", "bigger"]),
        &["bigger.exr", "64x36", "48x36"],
    );
    // A part that does not exist.
    refused(
        merge(d, "bad.exr", &["p0", "p1", "p2", "nothere"]),
        &["nothere.exr", "no such part"],
    );
}

#[test]
fn the_cache_command_and_read_only_files_check_their_input() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = cornell();
    let cache = d.join("c.icc");
    let small = ["-x", "48", "-y", "36"];
    // No -af, or -af read-only: refused before anything is loaded.
    let out = run(&[&["cache", s(&scene)][..], &small].concat());
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("needs -af FILE"), "{}", stderr(&out));
    let out = run(&[
        &[
            "render",
            s(&scene),
            "-o",
            s(&d.join("x.exr")),
            "-af",
            s(&cache),
            "--af-read-only",
        ][..],
        &small,
    ]
    .concat());
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("no such cache file"), "{}", stderr(&out));
    assert!(!cache.exists(), "a read-only render created the file");

    // A prepass of one region only: that region's task then makes no record, and the file's
    // settings check applies to read-only tasks too.
    let region = ["--region", "0", "0", "20", "36"];
    run_ok(&[&["cache", s(&scene), "-af", s(&cache), "-q"][..], &small, &region].concat());
    let shared = [&small[..], &region, &["-af", s(&cache), "--af-read-only"]].concat();
    let (_, stats) = render_to(d, &scene, "left", &shared);
    assert_eq!(records_in(&stats), (0, 0, 0));
    let out = run(&[
        &[
            "render",
            s(&scene),
            "-o",
            s(&d.join("y.exr")),
            "-af",
            s(&cache),
            "--af-read-only",
            "-aa",
            "0.3",
        ][..],
        &small,
    ]
    .concat());
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("other settings"), "{}", stderr(&out));
    // The rest of the image was not in the prepass: its task computes records (in memory).
    let (_, stats) = render_to(
        d,
        &scene,
        "right",
        &[
            &small[..],
            &["--region", "20", "0", "48", "36", "-af", s(&cache), "--af-read-only"],
        ]
        .concat(),
    );
    assert!(records_in(&stats).0 > 0, "{stats}");
}

/// The peak resident memory a render reports in its statistics (Linux's VmHWM).
fn peak_of(stats: &Value) -> u64 {
    stats["peak_memory_bytes"]
        .as_u64()
        .expect("peak_memory_bytes in the statistics")
}

/// A 32x32 region of a 20000x20000 image costs what a 32x32 image costs. Holding the whole
/// frame's buffers, as region tasks once did, would take 20000 x 20000 pixels at 188 bytes
/// (four RGB float layers, the records plane and the data layers: `memory.rs`) = 75 GB; before
/// this task held only its region, a 6000x6000 image's 32x32 region peaked at 6.6 GB and this
/// one ran out of memory. Run under a 1 GiB data limit (as a farm's task limit would set), so
/// that holding the frame again fails at once instead of filling the machine.
#[test]
fn a_small_region_of_a_huge_image_holds_only_its_own_pixels() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = cornell();
    let low = ["-ab", "1", "-aa", "0.2", "--threads", "2"];
    // The same task's cost for a whole image of the region's size.
    let (_, small) = render_to(d, &scene, "small", &[&["-x", "32", "-y", "32"][..], &low].concat());
    let stats_path = d.join("huge.json");
    let out = d.join("huge.exr");
    let output = std::process::Command::new("prlimit")
        .arg(format!("--data={}", 1u64 << 30))
        .arg(binary())
        .args([
            "render",
            s(&scene),
            "-o",
            s(&out),
            "--stats",
            s(&stats_path),
            "-q",
            "--no-preview",
        ])
        .args([
            "-x", "20000", "-y", "20000", "--region", "9984", "9984", "10016", "10016",
        ])
        // The estimate counts the region's pixels too (the whole frame's would be refused).
        .args(["--max-memory", "1G"])
        .args(low)
        .output()
        .expect("prlimit (util-linux) is installed");
    assert!(output.status.success(), "{}", stderr(&output));
    let huge: Value = serde_json::from_str(&std::fs::read_to_string(&stats_path).unwrap()).unwrap();
    let (part_peak, small_peak) = (peak_of(&huge), peak_of(&small));
    eprintln!(
        "peak resident memory: 32x32 region of 20000x20000 {:.1} MiB, 32x32 image {:.1} MiB",
        part_peak as f64 / 1048576.0,
        small_peak as f64 / 1048576.0
    );
    assert!(
        part_peak < small_peak + (32 << 20),
        "the region task peaked at {part_peak} bytes, a 32x32 image at {small_peak}"
    );
    // It is the region, in the whole image's display window, and it saw the lit room.
    let part = read_image_with_header(&out).unwrap();
    assert_eq!((part.width, part.height), (32, 32));
    assert_eq!(
        (
            part.window.x,
            part.window.y,
            part.window.full_width,
            part.window.full_height
        ),
        (9984, 9984, 20000, 20000)
    );
    let composite = &part.channels.iter().find(|(n, _)| n == "R").unwrap().1;
    assert!(composite.iter().all(|v| v.is_finite()) && composite.iter().any(|&v| v > 0.0));
}

/// A region task killed mid-render and started again with the same command resumes from its
/// checkpoint: the finished tiles come back from the journal into the region's frame, the rest
/// are rendered, and the part is bit for bit the one an uninterrupted task makes (both read the
/// prepass's records only, so nothing depends on when the kill came). The checkpoint is tied to
/// its region: another region's task refuses it.
#[test]
fn a_killed_region_task_resumes_from_its_checkpoint_into_the_same_part() {
    use icrender::image::region::Region;
    use icrender::image::window::PixelWindow;
    use std::process::{Command, Stdio};
    use std::time::{Duration, Instant};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = cornell();
    let cache = d.join("cache.icc");
    let options = [
        "-x", "160", "-y", "120", "-ab", "1", "-aa", "0.2", "--tile", "8x8", "--spp", "32",
    ];
    run_ok(&[&["cache", s(&scene), "-af", s(&cache), "-q"][..], &options].concat());
    let region = Region {
        x0: 20,
        y0: 10,
        x1: 140,
        y1: 110,
    };
    let r: Vec<String> = [region.x0, region.y0, region.x1, region.y1]
        .iter()
        .map(u32::to_string)
        .collect();
    let task = |name: &str, checkpoint: Option<&Path>| -> Vec<String> {
        let mut args: Vec<String> = ["render", s(&scene), "-q", "--no-preview", "--threads", "1"]
            .iter()
            .map(|a| a.to_string())
            .collect();
        args.extend(options.iter().map(|a| a.to_string()));
        args.extend(["--region", &r[0], &r[1], &r[2], &r[3]].iter().map(|a| a.to_string()));
        args.extend(["-af", s(&cache), "--af-read-only"].iter().map(|a| a.to_string()));
        args.extend(["-o".to_string(), s(&d.join(format!("{name}.exr"))).to_string()]);
        args.extend(["--stats".to_string(), s(&d.join(format!("{name}.json"))).to_string()]);
        if let Some(dir) = checkpoint {
            args.extend(["--checkpoint".to_string(), s(dir).to_string()]);
        }
        args
    };
    fn as_str(args: &[String]) -> Vec<&str> {
        args.iter().map(String::as_str).collect()
    }
    run_ok(&as_str(&task("whole", None)));

    let checkpoint = d.join("ck");
    let killed = task("part", Some(&checkpoint));
    let tiles = icrender::tiles::tiles_in(160, 120, 8, 8, Some(region));
    let window = PixelWindow::new(region, 160, 120);
    let mut child = Command::new(binary())
        .args(&killed)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let target = tiles.len() / 4;
    let waiting = Instant::now();
    while icrender::checkpoint::finished_tiles(&checkpoint, &tiles, window) < target {
        assert!(
            waiting.elapsed() < Duration::from_secs(60),
            "the region task does not progress"
        );
        std::thread::sleep(Duration::from_millis(1));
    }
    child.kill().unwrap();
    let status = child.wait().unwrap();
    assert!(
        !status.success(),
        "the task finished before it was killed: make it longer"
    );
    assert!(!d.join("part.exr").exists(), "a killed task left its part");

    run_ok(&as_str(&killed));
    let stats: Value = serde_json::from_str(&std::fs::read_to_string(d.join("part.json")).unwrap()).unwrap();
    let restored = stats["tiles_restored"].as_u64().unwrap();
    let rendered: u64 = stats["per_thread"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["tiles"].as_u64().unwrap())
        .sum();
    assert!(
        restored >= target as u64 && restored < tiles.len() as u64,
        "{restored} of {} restored",
        tiles.len()
    );
    assert_eq!(
        restored + rendered,
        tiles.len() as u64,
        "a tile was rendered twice or missed"
    );
    let (part, whole) = (
        read_image_with_header(&d.join("part.exr")).unwrap(),
        read_image_with_header(&d.join("whole.exr")).unwrap(),
    );
    same_bits(&part, &whole).unwrap();
    assert_eq!(
        (part.width, part.height, part.window.x, part.window.y),
        (120, 100, 20, 10)
    );

    // Another region's task refuses this region's checkpoint.
    let mut other = killed.clone();
    let at = other.iter().position(|a| a == "--region").unwrap();
    other[at + 1] = "0".into();
    let o = other.iter().position(|a| a == "-o").unwrap();
    other[o + 1] = s(&d.join("other.exr")).to_string();
    let j = other.iter().position(|a| a == "--stats").unwrap();
    other[j + 1] = s(&d.join("other.json")).to_string();
    let out = run(&as_str(&other));
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("another job"), "{}", stderr(&out));
    assert!(!d.join("other.exr").exists());
}

/// A region's tiles are streamed into its EXR as they finish; with --denoise the region's frame
/// is held whole and written at the end. The raw channels of both files are the same, bit for
/// bit, at the same place in the display window, for a region whose corner is off the tile grid
/// (its render tiles then straddle the file's, which start at the region's corner), and the
/// held file carries every attribute of the streamed one that does not say how it ran.
#[test]
fn a_streamed_region_equals_the_region_held_whole() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let common_args = ["-x", "61", "-y", "45", "--tile", "16x8"];
    let region = [5, 3, 58, 38];
    render_part(d, "streamed", region, &common_args);
    let held = [&common_args[..], &["--denoise", "--denoise-quality", "fast"]].concat();
    render_part(d, "held", region, &held);
    let [a, b] = ["streamed", "held"].map(|name| read_image_with_header(&d.join(format!("{name}.exr"))).unwrap());
    assert_eq!((a.window.x, a.window.y, a.width, a.height), (5, 3, 53, 35));
    assert!(b.channel("denoised.R").is_some(), "the held file is the denoised one");
    let how_it_ran = [
        "icrender/command",
        "icrender/options",
        "icrender/part_settings",
        "icrender/render_time_s",
        "icrender/statistics",
        "icrender/error_estimate",
        "DateTime",
    ];
    assert_same_image(&a, &b, &how_it_ran, "the region held whole");
}

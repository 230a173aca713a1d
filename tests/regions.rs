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
    // The prepass task.
    let scene = cornell();
    let mut args = vec!["cache", s(&scene), "-af", s(&cache), "--stats", s(&cache_stats)];
    args.extend(SIZE);
    let out = run_ok(&args);
    assert!(stderr(&out).contains("records made"), "{}", stderr(&out));
    let made: Value = serde_json::from_str(&std::fs::read_to_string(&cache_stats).unwrap()).unwrap();
    let records = made["records_made"].as_u64().unwrap();
    assert!(records > 100, "{made}");
    let bytes_before = std::fs::read(&cache).unwrap();
    let mtime_before = std::fs::metadata(&cache).unwrap().modified().unwrap();

    let shared = [&SIZE[..], &["-af", s(&cache), "--af-read-only"]].concat();
    let (_, full_stats) = render_to(d, &cornell(), "full", &shared);
    assert_eq!(records_in(&full_stats), (0, 0, 0), "the full render made records");
    let mut names = Vec::new();
    for (k, region) in SPLIT.iter().enumerate() {
        let name = format!("shared{k}");
        let stats = render_part(d, &name, *region, &shared);
        // The region tasks only read the prepass's records: none made in their prepass or final pass.
        assert_eq!(records_in(&stats), (0, 0, 0), "{name} made records");
        assert_eq!(stats["records_loaded"].as_u64(), Some(records), "{name}");
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

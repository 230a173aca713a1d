//! The default scene end to end: files written, layers that oiiotool and Nuke see, layers that
//! add up to the composite, determinism, header and statistics.

mod common;
use common::*;
use std::process::Command;

fn default_scene() -> String {
    project_dir().join("scenes/cornell.gltf").to_string_lossy().into_owned()
}

fn render_default(dir: &std::path::Path, name: &str, extra: &[&str]) -> std::path::PathBuf {
    render_default_saying(dir, name, extra).0
}

/// `render_default`, with what the render printed on stderr.
fn render_default_saying(dir: &std::path::Path, name: &str, extra: &[&str]) -> (std::path::PathBuf, String) {
    let out = dir.join(format!("{name}.exr"));
    let scene = default_scene();
    let mut args = vec![
        "render",
        scene.as_str(),
        "-o",
        out.to_str().unwrap(),
        "-x",
        "48",
        "-y",
        "48",
        "-ad",
        "16",
        "-q",
    ];
    args.extend_from_slice(extra);
    let output = run_ok(&args);
    (out, stderr(&output))
}

#[test]
fn default_scene_renders_an_exr_and_a_png_preview() {
    let dir = tempfile::tempdir().unwrap();
    let out = render_default(dir.path(), "cornell", &[]);
    assert!(out.exists());
    let png = out.with_extension("png");
    let bytes = std::fs::read(&png).unwrap();
    assert_eq!(&bytes[1..4], b"PNG");
    let preview = read_image(&png, &[]).unwrap();
    assert_eq!((preview.width, preview.height), (48, 48));
    // The preview is a picture, not a black frame.
    assert!(mean(preview.channel("R").unwrap()) > 0.05);
}

/// A frame over the preview's budget (4.2 megapixels) gets a preview box-filtered down by the
/// smallest whole factor that fits, whose pixels are the blocks' means of the frame's.
#[test]
fn a_frame_beyond_the_previews_budget_gets_a_reduced_preview() {
    let dir = tempfile::tempdir().unwrap();
    // 2900 x 1450 = 4,205,000 pixels: just over 2^22, so the preview is 1450 x 725.
    let out = dir.path().join("large.exr");
    let out_text = out.to_str().unwrap();
    let scene = default_scene();
    run_ok(&[
        "render", &scene, "-o", out_text, "-q", "-x", "2900", "-y", "1450", "-ab", "0", "--aovs", "none", "--tile",
        "64x64",
    ]);
    let preview = read_image(&out.with_extension("png"), &[]).unwrap();
    assert_eq!((preview.width, preview.height), (1450, 725));
    // Its brightest tenth of pixels is bright and its darkest dark, as the frame's are: a
    // picture of the frame, not a black or a flat one.
    let mut red = preview.channel("R").unwrap().to_vec();
    red.sort_by(f32::total_cmp);
    assert!(red[red.len() * 9 / 10] > 0.3 && red[red.len() / 10] < red[red.len() * 9 / 10] * 0.8);
}

#[test]
fn oiiotool_lists_the_four_layers() {
    let dir = tempfile::tempdir().unwrap();
    let out = render_default(dir.path(), "layers", &[]);
    let info = Command::new("oiiotool")
        .args(["--info", "-v"])
        .arg(&out)
        .output()
        .expect("oiiotool (openimageio-tools) is installed");
    let text = String::from_utf8_lossy(&info.stdout);
    let channels = text
        .lines()
        .find(|l| l.trim_start().starts_with("channel list"))
        .unwrap_or_else(|| panic!("no channel list in:\n{text}"));
    for name in ["R", "G", "B", "A"] {
        assert!(
            channels.split([',', ':']).any(|c| c.trim() == name),
            "{name} missing: {channels}"
        );
    }
    for layer in ["emission", "direct", "specular", "indirect"] {
        for c in ["R", "G", "B"] {
            let full = format!("{layer}.{c}");
            assert!(channels.contains(&full), "{full} missing: {channels}");
        }
    }
    assert!(
        text.contains("icrender/options"),
        "options missing from the header:\n{text}"
    );
    assert!(
        text.contains("icrender/render_time_s"),
        "timing missing from the header:\n{text}"
    );
}

#[test]
fn composite_is_the_sum_of_the_layers() {
    let dir = tempfile::tempdir().unwrap();
    let out = render_default(dir.path(), "sum", &[]);
    let image = read_exr(&out);
    let composite = rgb(&image, "");
    let layers: Vec<[Vec<f32>; 3]> = ["emission", "direct", "specular", "indirect"]
        .iter()
        .map(|l| rgb(&image, l))
        .collect();
    for c in 0..3 {
        for i in 0..composite[c].len() {
            let sum: f32 = layers.iter().map(|l| l[c][i]).sum();
            let v = composite[c][i];
            assert!(
                (v - sum).abs() <= 1e-5 * v.abs().max(1.0),
                "pixel {i} channel {c}: {v} vs {sum}"
            );
        }
    }
    // Every layer carries light in this scene (mirror box, visible light, diffuse walls).
    for (name, l) in ["emission", "direct", "specular", "indirect"].iter().zip(&layers) {
        assert!(mean(&l[0]) > 0.0, "{name} is black");
    }
    assert!(composite.iter().flatten().all(|v| v.is_finite() && *v >= 0.0));
}

#[test]
fn same_seed_same_image_and_threads_only_move_cache_records() {
    let dir = tempfile::tempdir().unwrap();
    // One thread renders tiles in a fixed order, so the cache fills the same way: bit for bit.
    let a = read_exr(&render_default(dir.path(), "a", &["--threads", "1"]));
    let b = read_exr(&render_default(dir.path(), "b", &["--threads", "1"]));
    assert_eq!(rgb(&a, ""), rgb(&b, ""));
    // Without the cache every pixel depends only on its own samples, whatever the threads.
    let c = read_exr(&render_default(
        dir.path(),
        "c",
        &["--threads", "1", "-aa", "0", "--tile", "7x5"],
    ));
    let d = read_exr(&render_default(dir.path(), "d", &["--threads", "2", "-aa", "0"]));
    assert_eq!(rgb(&c, ""), rgb(&d, ""));
    // A different seed is a different image.
    let e = read_exr(&render_default(dir.path(), "e", &["--threads", "1", "--seed", "2"]));
    assert_ne!(rgb(&a, ""), rgb(&e, ""));
}

#[test]
fn statistics_json_and_header() {
    let dir = tempfile::tempdir().unwrap();
    let stats = dir.path().join("stats.json");
    let out = render_default(dir.path(), "stats", &["--stats", stats.to_str().unwrap()]);
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    for key in [
        "wall_s",
        "render_s",
        "load_s",
        "build_s",
        "rays",
        "threads",
        "per_thread",
        "layers",
    ] {
        assert!(json.get(key).is_some(), "{key} missing from {json}");
    }
    assert!(json["rays"]["primary"].as_u64().unwrap() >= 48 * 48);
    assert_eq!(json["nonfinite_dropped"], 0);
    let image = read_exr(&out);
    let options = image.attribute("icrender/options").unwrap();
    assert!(options.contains("-ab 1") && options.contains("-ad 16"), "{options}");
}

/// A reference renders pass after pass; its statistics list each thread once, with every
/// pass's rays, so they add up to the totals (not once per thread and pass).
#[test]
fn a_references_statistics_list_each_thread_once() {
    let dir = tempfile::tempdir().unwrap();
    let stats = dir.path().join("ref.json");
    let out = dir.path().join("ref.exr");
    run_ok(&[
        "reference",
        &default_scene(),
        "-o",
        out.to_str().unwrap(),
        "-q",
        "--no-preview",
        "-x",
        "32",
        "-y",
        "16",
        "--tile",
        "8x8",
        "-ad",
        "16",
        "--threads",
        "2",
        "--noise",
        "1e-9",
        "--max-seconds",
        "0.5",
        "--stats",
        stats.to_str().unwrap(),
    ]);
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    let passes = json["reference_passes"].as_u64().unwrap();
    assert!(passes >= 3, "passes: {passes}");
    let threads = json["per_thread"].as_array().unwrap();
    assert_eq!(threads.len(), 2, "{}", json["per_thread"]);
    let rays: u64 = threads.iter().map(|t| t["rays"]["total"].as_u64().unwrap()).sum();
    assert_eq!(rays, json["rays"]["total"].as_u64().unwrap());
    // Every pass traces a camera ray a pixel at least.
    assert!(json["rays"]["primary"].as_u64().unwrap() >= passes * 32 * 16);
}

/// Every ray the render traces is in its statistics, the last bounce's grid's too: each of its
/// sites (one a pixel at this size, two from -ad 256 on: `shading::last_bounce::sites_per_pixel`)
/// starts with a camera ray, which a render tracing its last bounce as paths does not make; the
/// rest of the two renders' eye rays are the same.
#[test]
fn the_last_bounce_grids_rays_are_counted() {
    let dir = tempfile::tempdir().unwrap();
    let scene = std::path::PathBuf::from(default_scene());
    for (divisions, sites) in [("16", 1), ("256", 2)] {
        let primary = |deep: &str| {
            let args = ["-x", "40", "-y", "30", "-ab", "2", "-ad", divisions, "--ic-deep", deep];
            let (_, stats) = render_to(dir.path(), &scene, &format!("{deep}-{divisions}"), &args);
            (
                stats["rays"]["primary"].as_u64().unwrap(),
                stats["last_bounce_samples"].as_u64().unwrap(),
            )
        };
        let (with_grid, samples) = primary("grid");
        let (with_paths, none) = primary("paths");
        assert!(
            samples > 0 && none == 0,
            "-ad {divisions}: grid samples {samples}, paths {none}"
        );
        assert_eq!(
            with_grid,
            with_paths + sites * 40 * 30,
            "-ad {divisions}: primary rays: grid {with_grid}, paths {with_paths}"
        );
    }
}

#[test]
fn radiance_view_options_override_the_gltf_camera() {
    let dir = tempfile::tempdir().unwrap();
    // Looking straight up at the light from the floor: the image is dominated by emission.
    let out = render_default(
        dir.path(),
        "up",
        &[
            "-vp", "0", "0.1", "0", "-vd", "0", "1", "0", "-vu", "0", "0", "1", "-vh", "20", "-vv", "20",
        ],
    );
    let image = read_exr(&out);
    let emission = mean(&rgb(&image, "emission")[0]);
    assert!(
        emission > 1.0,
        "the light should fill the view, emission mean {emission}"
    );
}

/// An emitter's straight edge crossing a column of pixels, seen through a parallel view whose
/// pixels are one unit wide: the edge lies at 0.3 of the way across its pixels, so they are
/// 70 % covered. With one sample (the pixel centre) every pixel is wholly lit or dark; with N
/// jittered samples each pixel is a whole number of N-ths, and the edge's pixels take
/// fractional values whose mean converges to the covered area. Returns the emission layer
/// (R) as rows of 8 pixels, in units of the emitter's radiance.
fn edge_pixels(dir: &std::path::Path, spp: &str) -> Vec<Vec<f64>> {
    let radiance = 2.0f32;
    let mut b = GltfBuilder::new();
    let light = b.material(emissive_lambertian("light", [0.0; 3], radiance));
    b.quad(
        facing(
            [
                [0.3, -50.0, 0.0],
                [50.0, -50.0, 0.0],
                [50.0, 50.0, 0.0],
                [0.3, 50.0, 0.0],
            ],
            [0.0, 0.0, 1.0],
        ),
        Some(light),
    );
    let scene = b.write(dir, "edge");
    let name = format!("edge-{spp}");
    let (image, _) = render_to(
        dir,
        &scene,
        &name,
        &[
            "-x",
            "8",
            "-y",
            "32",
            "-ab",
            "0",
            "--edge-samples",
            "0",
            "-vtl",
            "-vp",
            "0",
            "0",
            "5",
            "-vd",
            "0",
            "0",
            "-1",
            "-vu",
            "0",
            "1",
            "0",
            "-vh",
            "8",
            "-vv",
            "32",
            "--spp",
            spp,
            "--emission-samples",
            "0",
        ],
    );
    let [r, _, _] = rgb(&image, "emission");
    r.chunks(8)
        .map(|row| row.iter().map(|&v| v as f64 / radiance as f64).collect())
        .collect()
}

#[test]
fn spp_averages_jittered_samples_over_the_pixel() {
    let dir = tempfile::tempdir().unwrap();
    let covered = 0.7;
    // The column the edge crosses: the one whose pixels are neither dark nor fully lit at high
    // sample counts (which side is which depends on the view's orientation, not on sampling).
    let many = edge_pixels(dir.path(), "64");
    let fractional: Vec<usize> = (0..8)
        .filter(|&i| many.iter().all(|row| row[i] > 0.01 && row[i] < 0.99))
        .collect();
    assert_eq!(fractional.len(), 1, "one column holds the edge: {many:?}");
    let edge = fractional[0];
    for row in &many {
        for (i, &v) in row.iter().enumerate() {
            if i != edge {
                assert!(
                    v.abs() < 1e-6 || (v - 1.0).abs() < 1e-6,
                    "column {i} is off the edge: {v}"
                );
            }
        }
    }
    for (n, strata_wide) in [(1u32, 1.0), (4, 2.0), (64, 8.0)] {
        let pixels = if n == 64 {
            many.clone()
        } else {
            edge_pixels(dir.path(), &n.to_string())
        };
        let values: Vec<f64> = pixels.iter().map(|row| row[edge]).collect();
        for &v in &values {
            // Each sample adds 1/n of the emitter's radiance.
            let samples = v * n as f64;
            assert!(
                (samples - samples.round()).abs() < 1e-3,
                "--spp {n}: {v} is not a whole number of 1/{n}"
            );
            // Stratified: only the samples in the one column of strata the edge crosses can fall
            // on either side, so a pixel is within one stratum's width of the covered area.
            assert!((v - covered).abs() <= 1.0 / strata_wide + 1e-6, "--spp {n}: {v}");
        }
        let average = values.iter().sum::<f64>() / values.len() as f64;
        match n {
            // The pixel centre (0.5) lies on the emitter: every pixel of the column is lit.
            1 => assert!(values.iter().all(|&v| (v - 1.0).abs() < 1e-6), "--spp 1: {values:?}"),
            // 4 samples (2 x 2): 2 certain, 2 each lit with probability 0.4; 32 pixels.
            4 => {
                assert!(
                    values.iter().any(|&v| v < 0.99),
                    "--spp 4 gave no fractional pixel: {values:?}"
                );
                assert!((average - covered).abs() < 0.1, "--spp 4: mean {average}");
            }
            // 64 samples (8 x 8): per pixel 40 certain and 8 lit with probability 0.6, a
            // standard deviation of 0.022; over 32 pixels 0.004. 0.015 is over 3.5 of those.
            _ => assert!((average - covered).abs() < 0.015, "--spp 64: mean {average}"),
        }
    }
}

#[test]
fn corridor_renders() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("corridor.exr");
    let scene = project_dir().join("scenes/corridor.gltf");
    run_ok(&[
        "render",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "-x",
        "32",
        "-y",
        "24",
        "-ad",
        "8",
        "-q",
    ]);
    let image = read_exr(&out);
    assert!(mean(&rgb(&image, "")[0]) > 0.0);
    // Lambertian corridor: no specular layer.
    assert!(image.channel("specular.R").is_none());
}

#[test]
fn info_and_compare_commands() {
    let scene = default_scene();
    let info = stdout(&run_ok(&["info", scene.as_str(), "--json"]));
    let json: serde_json::Value = serde_json::from_str(&info).unwrap();
    assert_eq!(json["triangles"], 36);
    assert_eq!(json["lights"]["emissive_triangles"], 2);
    assert_eq!(json["components"]["specular"], true);
    assert_eq!(json["cameras"], 1);

    let dir = tempfile::tempdir().unwrap();
    // No emission rays of their own and no more samples at edges (both jittered): the pixel
    // centre alone sees emitters.
    let centred = ["--emission-samples", "0", "--edge-samples", "0"];
    let a = render_default(dir.path(), "a", &centred);
    let b = render_default(dir.path(), "b", &[&centred[..], &["--seed", "9", "-aa", "0"]].concat());
    let same = stdout(&run_ok(&[
        "compare",
        a.to_str().unwrap(),
        a.to_str().unwrap(),
        "--json",
    ]));
    let same: serde_json::Value = serde_json::from_str(&same).unwrap();
    assert_eq!(same[0]["layer"], "composite");
    assert_eq!(same[0]["rmse"], 0.0);
    assert_eq!(same.as_array().unwrap().len(), 5);
    let differ: serde_json::Value = serde_json::from_str(&stdout(&run_ok(&[
        "compare",
        a.to_str().unwrap(),
        b.to_str().unwrap(),
        "--json",
    ])))
    .unwrap();
    assert!(differ[0]["rmse"].as_f64().unwrap() > 0.0);
    // The emission layer does not depend on the seed at one centred sample per pixel.
    let emission = differ
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["layer"] == "emission")
        .unwrap();
    assert_eq!(emission["rmse"], 0.0);
    // --reference prints the error after rendering.
    let out = dir.path().join("r.exr");
    let printed = stdout(&run_ok(&[
        "render",
        scene.as_str(),
        "-o",
        out.to_str().unwrap(),
        "-x",
        "48",
        "-y",
        "48",
        "-ad",
        "16",
        "-q",
        "--reference",
        a.to_str().unwrap(),
    ]));
    assert!(printed.contains("composite") && printed.contains("relmse"), "{printed}");
}

/// Both angles given at another aspect than the image's: the pixels are not square, the EXR's
/// PixelAspectRatio says by how much (pixel width over height on the image plane), and the user
/// is told which angle goes with the other; one angle alone keeps them square.
#[test]
fn a_view_with_non_square_pixels_says_so_in_the_exr_and_on_stderr() {
    let dir = tempfile::tempdir().unwrap();
    let aspect_of = |name: &str, view: &[&str]| {
        let (out, said) = render_default_saying(dir.path(), name, view);
        let image = read_image(&out, &["PixelAspectRatio"]).unwrap();
        let ratio: f64 = image.attribute("PixelAspectRatio").unwrap().parse().unwrap();
        (ratio, said)
    };
    // A 48x48 image: tan(37 deg) over tan(30 deg).
    let (stretched, said) = aspect_of("stretched", &["--vh", "74", "--vv", "60"]);
    let expected = 37f64.to_radians().tan() / 30f64.to_radians().tan();
    assert!(
        (stretched - expected).abs() < 1e-4,
        "PixelAspectRatio {stretched}, expected {expected}"
    );
    assert!(
        said.contains("PixelAspectRatio") && said.contains("-vh 60.0000 goes with -vv 60"),
        "{said}"
    );
    let (square, said) = aspect_of("square", &["--vh", "74"]);
    assert_eq!(square, 1.0);
    assert!(!said.contains("PixelAspectRatio"), "{said}");
}

//! Pixel sampling through the real binary: the box filter integrates each pixel's area, and
//! the error against a converged reference falls as samples per pixel grow.

mod common;
use common::*;
use std::path::{Path, PathBuf};

/// An emitter of radiance 1 covering x < -0.7 seen through a parallel view whose pixels are
/// 1 x 1 units: pixel column 3 spans x in [-1, 0), so the edge covers 0.3 of it.
fn edge_scene(dir: &Path) -> std::path::PathBuf {
    let mut b = GltfBuilder::new();
    let light = b.material(emissive_lambertian("light", [0.0; 3], 1.0));
    b.quad(
        facing(
            [
                [-100.0, -200.0, 0.0],
                [-0.7, -200.0, 0.0],
                [-0.7, 200.0, 0.0],
                [-100.0, 200.0, 0.0],
            ],
            [0.0, 0.0, 5.0],
        ),
        Some(light),
    );
    b.write(dir, "edge")
}

/// Column means of the composite's red channel of an 8 x 256 render of the edge scene, every pixel
/// at `spp` samples (no more at the edge: `--edge-samples 0`).
fn edge_columns(dir: &Path, name: &str, spp: &str, emission_samples: &str) -> Vec<f64> {
    let sampling = [
        "--spp",
        spp,
        "--emission-samples",
        emission_samples,
        "--edge-samples",
        "0",
    ];
    edge_columns_with(dir, name, &sampling).0
}

/// `edge_columns` with the sampling options given, and the render's statistics.
fn edge_columns_with(dir: &Path, name: &str, sampling: &[&str]) -> (Vec<f64>, serde_json::Value) {
    let scene = edge_scene(dir);
    let out = dir.join(format!("{name}.exr"));
    let stats = dir.join(format!("{name}.json"));
    let view = "-vtl -vp 0 0 5 -vd 0 0 -1 -vu 0 1 0 -vh 8 -vv 256";
    let mut args = vec![
        "render",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "-q",
        "--no-preview",
        "-x",
        "8",
        "-y",
        "256",
        "-ab",
        "0",
        "--stats",
        stats.to_str().unwrap(),
    ];
    args.extend(sampling);
    args.extend(view.split_whitespace());
    run_ok(&args);
    let [r, _, _] = rgb(&read_exr(&out), "");
    let columns = (0..8)
        .map(|x| (0..256).map(|y| r[y * 8 + x] as f64).sum::<f64>() / 256.0)
        .collect();
    (
        columns,
        serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap(),
    )
}

#[test]
fn edge_samples_integrate_the_pixels_an_edge_crosses_and_only_those() {
    let dir = tempfile::tempdir().unwrap();
    // One sample a pixel, 16 (4 x 4 strata) where the corners see different surfaces: only
    // column 3 (its left corners on the emitter, its right ones on nothing), which then
    // integrates its area (0.3, standard error 0.002 over 256 rows); the others keep their
    // single centre sample and stay exact.
    let (columns, stats) = edge_columns_with(
        dir.path(),
        "edges",
        &["--spp", "1", "--edge-samples", "16", "--emission-samples", "0"],
    );
    eprintln!("1 spp + 16 edge samples: {columns:?}");
    assert!((columns[3] - 0.3).abs() < 0.01, "{columns:?}");
    for (x, expected) in [(0, 1.0), (1, 1.0), (2, 1.0), (4, 0.0), (5, 0.0), (7, 0.0)] {
        assert!(columns[x] == expected, "column {x}: {columns:?}");
    }
    assert_eq!(stats["edge_pixels"], 256, "{stats}");
    // No more samples than --spp: off, and nothing counted.
    let (columns, stats) = edge_columns_with(
        dir.path(),
        "off",
        &["--spp", "4", "--edge-samples", "4", "--emission-samples", "0"],
    );
    assert_eq!(stats["edge_pixels"], 0, "{stats}");
    assert!((columns[3] - 0.3).abs() < 0.03, "4 spp: {columns:?}");
}

#[test]
fn box_filter_integrates_the_pixel_area_at_an_edge() {
    let dir = tempfile::tempdir().unwrap();
    // 8 samples are a 4 x 2 grid of strata; the straddling pixel's mean over 256 rows is
    // 0.3 with a standard error of 0.0044 (each row: 2 of 8 samples in the column of strata
    // [0.25, 0.5), each covered with probability 0.2). A grid with empty cells (8 samples on
    // 3 x 3) would be biased to 0.3375.
    let columns = edge_columns(dir.path(), "eight", "8", "0");
    eprintln!("8 spp column means: {columns:?}");
    for (x, expected) in [(0, 1.0), (1, 1.0), (2, 1.0), (3, 0.3), (4, 0.0), (5, 0.0), (7, 0.0)] {
        assert!(
            (columns[x] - expected).abs() < 0.015,
            "column {x}: {} against {expected} ({columns:?})",
            columns[x]
        );
    }
    // 7 samples (a prime) are strips 1/7 wide: still the pixel's area, no bias.
    let columns = edge_columns(dir.path(), "seven", "7", "0");
    assert!((columns[3] - 0.3).abs() < 0.015, "7 spp: {columns:?}");
    // One sample is the pixel centre, which the emitter does not reach.
    let columns = edge_columns(dir.path(), "one", "1", "0");
    assert!(columns[3] == 0.0 && columns[2] == 1.0, "1 spp: {columns:?}");
    // With one shading sample at the centre, 16 emission rays (4 x 4 strata) still integrate
    // the emitter seen straight on over the pixel's area (standard error 0.002 over 256 rows).
    let columns = edge_columns(dir.path(), "split", "1", "16");
    eprintln!("1 spp + 16 emission samples: {columns:?}");
    assert!(
        (columns[3] - 0.3).abs() < 0.01,
        "1 spp + 16 emission samples: {columns:?}"
    );
    assert!(
        columns[2] == 1.0 && columns[4] == 0.0 && columns[0] == 1.0,
        "{columns:?}"
    );
}

fn composite_rel_mse(image: &Path, reference: &Path) -> f64 {
    let out = run_ok(&[
        "compare",
        image.to_str().unwrap(),
        reference.to_str().unwrap(),
        "--json",
    ]);
    let layers: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    layers
        .as_array()
        .unwrap()
        .iter()
        .find(|l| l["layer"] == "composite")
        .and_then(|l| l["rel_mse"].as_f64())
        .expect("a composite error")
}

/// The test scenes' Cornell box at 32 x 32, direct light only (-ab 0) with `light_samples`
/// shadow rays a sample: the options every run takes, and a converged reference (64 samples a
/// pass, to `noise`) in `dir`.
fn direct_light_cornell(dir: &Path, light_samples: &'static str, noise: &str) -> (String, [&'static str; 10], PathBuf) {
    let scene = project_dir().join("scenes/cornell.gltf").to_str().unwrap().to_string();
    let common = [
        "-q",
        "--no-preview",
        "-x",
        "32",
        "-y",
        "32",
        "-ab",
        "0",
        "--light-samples",
        light_samples,
    ];
    let reference = dir.join("reference.exr");
    let mut args = vec!["reference", &scene, "-o", reference.to_str().unwrap(), "--spp", "64"];
    args.extend(common);
    args.extend(["--noise", noise]);
    run_ok(&args);
    (scene, common, reference)
}

#[test]
fn error_against_the_reference_falls_as_samples_grow() {
    let dir = tempfile::tempdir().unwrap();
    // One shadow ray per sample: pixel edges and penumbrae are the error, both integrated by
    // more samples; the reference is converged far below them.
    let (scene, common, reference) = direct_light_cornell(dir.path(), "1", "0.002");
    let scene = scene.as_str();
    let mut errors = Vec::new();
    for spp in ["1", "4", "16", "64"] {
        let out = dir.path().join(format!("spp{spp}.exr"));
        let mut args = vec![
            "render",
            scene,
            "-o",
            out.to_str().unwrap(),
            "--spp",
            spp,
            "--edge-samples",
            "0",
            "--seed",
            "7",
        ];
        args.extend(common);
        run_ok(&args);
        errors.push(composite_rel_mse(&out, &reference));
    }
    eprintln!("relMSE by spp 1, 4, 16, 64: {errors:?}");
    // Independent noise of variance 1/spp would fall 4x per step; stratification does better
    // on edges. Asking for 2.5x per step leaves room for the reference's own noise.
    for pair in errors.windows(2) {
        assert!(pair[1] < pair[0] / 2.5, "relMSE by spp 1, 4, 16, 64: {errors:?}");
    }
}

#[test]
fn edge_samples_take_most_of_the_error_of_one_sample_a_pixel_away() {
    let dir = tempfile::tempdir().unwrap();
    // 16 shadow rays a sample with the exact unshadowed light: inside a surface a sample is
    // nearly noise-free, and the error of one sample a pixel is the edges' (the boxes'
    // silhouettes and creases, the light's rim, the room's corners).
    let (scene, common, reference) = direct_light_cornell(dir.path(), "16", "0.004");
    let scene = scene.as_str();
    let render = |name: &str, sampling: &[&str]| {
        let out = dir.path().join(format!("{name}.exr"));
        let stats = dir.path().join(format!("{name}.json"));
        let mut args = vec!["render", scene, "-o", out.to_str().unwrap(), "--seed", "7"];
        args.extend(["--stats", stats.to_str().unwrap()]);
        args.extend(sampling);
        args.extend(common);
        run_ok(&args);
        let stats: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
        (composite_rel_mse(&out, &reference), stats)
    };
    let (one, _) = render("one", &["--spp", "1", "--edge-samples", "0"]);
    let (edges, stats) = render("edges", &["--spp", "1", "--edge-samples", "16"]);
    let (sixteen, all) = render("sixteen", &["--spp", "16"]);
    eprintln!("relMSE 1 spp {one:.3e}, 1 spp + 16 at edges {edges:.3e}, 16 spp {sixteen:.3e}; {stats}");
    // Measured: 4.6x lower than one sample (two seeds), for under half the primary rays of 16
    // everywhere (a third of the pixels are edge pixels at this size).
    assert!(edges < one / 3.0, "{one:.3e} -> {edges:.3e}");
    let edge_pixels = stats["edge_pixels"].as_u64().unwrap();
    assert!(edge_pixels > 100 && edge_pixels < 600, "{edge_pixels} of 1024 pixels");
    let primary = |s: &serde_json::Value| s["rays"]["primary"].as_u64().unwrap();
    assert!(primary(&stats) < primary(&all) / 2, "{stats} against {all}");
}

/// A floor of single-texel checks, 0.05 and 0.9 (linear), 512 texels across 4 units, seen
/// from 2 units above through a 60-degree perspective view at 64 x 64: each pixel covers some
/// 4.6 texels across. Lit by -av alone, so the albedo layer and the light are the texture.
fn checker_floor(dir: &Path) -> (PathBuf, f64) {
    let mean_albedo = single_texel_checker(dir) as f64;
    let mut b = GltfBuilder::new();
    let texture = b.texture("checker.png");
    let mut painted = lambertian("checker", [1.0; 3]);
    painted["pbrMetallicRoughness"]["baseColorTexture"] = serde_json::json!({"index": texture});
    let material = b.material(painted);
    let floor = [[-2.0, 0.0, -2.0], [-2.0, 0.0, 2.0], [2.0, 0.0, 2.0], [2.0, 0.0, -2.0]];
    let uv = [[0.0, 0.0], [0.0, 8.0], [8.0, 8.0], [8.0, 0.0]];
    let mesh = b.mesh_with(&floor, None, Some(&uv), &[[0, 1, 2], [0, 2, 3]], Some(material));
    b.node(serde_json::json!({"mesh": mesh}));
    (b.write(dir, "checker_floor"), mean_albedo)
}

/// A camera ray reads textures averaged over its share of the pixel (the texture's mip
/// pyramid), so one sample a pixel gives each pixel the checker's mean, as a converged box
/// filter does, where reading the point would give 0.05 or 0.9: every pixel's albedo within 5 %
/// of the mean, and the composite's relMSE against `icrender reference` (points, many passes)
/// small. (Measured on Sibenik's textured stone, 320x240 at the defaults, against the peers
/// bench's reference: relMSE 3.0e-2 -> 1.35e-2, 4x4 relMSE 3.4e-3 -> 1.9e-3.)
#[test]
fn one_sample_a_pixel_reads_a_fine_texture_averaged_over_the_pixel() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, mean_albedo) = checker_floor(dir.path());
    let view = [
        "--vp", "0", "2", "0", "--vd", "0", "-1", "0", "--vu", "0", "0", "-1", "--vh", "60", "-x", "64", "-y", "64",
        "-ab", "0", "-av", "1", "1", "1",
    ];
    let (image, _) = render_to(dir.path(), &scene, "one", &[&view[..], &["--spp", "1"]].concat());
    let albedo = rgb(&image, "albedo");
    let worst = albedo[1]
        .iter()
        .map(|&a| (a as f64 - mean_albedo).abs() / mean_albedo)
        .fold(0.0, f64::max);
    assert!(
        worst < 0.05,
        "a pixel's albedo is {:.0} % off the checker's mean {mean_albedo:.3}",
        worst * 100.0
    );
    let reference = dir.path().join("reference.exr");
    let mut args = vec![
        "reference",
        scene.to_str().unwrap(),
        "-o",
        reference.to_str().unwrap(),
        "-q",
    ];
    args.extend_from_slice(&["--no-preview", "--noise", "0.01", "--max-seconds", "60"]);
    args.extend_from_slice(&view);
    run_ok(&args);
    let error = relmse(&image, &read_exr(&reference));
    assert!(error < 2e-3, "relMSE {error:.2e} against the reference");
}

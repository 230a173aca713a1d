//! Pixel sampling through the real binary: the box filter integrates each pixel's area, and
//! the error against a converged reference falls as samples per pixel grow.

mod common;
use common::*;
use std::path::Path;

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

/// Column means of the composite's red channel of an 8 x 256 render of the edge scene.
fn edge_columns(dir: &Path, name: &str, spp: &str, emission_samples: &str) -> Vec<f64> {
    let scene = edge_scene(dir);
    let out = dir.join(format!("{name}.exr"));
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
        "--spp",
        spp,
        "--emission-samples",
        emission_samples,
    ];
    args.extend(view.split_whitespace());
    run_ok(&args);
    let [r, _, _] = rgb(&read_exr(&out), "");
    (0..8)
        .map(|x| (0..256).map(|y| r[y * 8 + x] as f64).sum::<f64>() / 256.0)
        .collect()
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

#[test]
fn error_against_the_reference_falls_as_samples_grow() {
    let dir = tempfile::tempdir().unwrap();
    let scene = project_dir().join("scenes/cornell.gltf");
    let scene = scene.to_str().unwrap();
    // Direct light only (-ab 0) with one shadow ray per sample: pixel edges and penumbrae are
    // the error, both integrated by more samples; the reference is converged far below them.
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
        "1",
    ];
    let reference = dir.path().join("reference.exr");
    let mut args = vec!["reference", scene, "-o", reference.to_str().unwrap(), "--spp", "64"];
    args.extend(common);
    args.extend(["--noise", "0.002"]);
    run_ok(&args);
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

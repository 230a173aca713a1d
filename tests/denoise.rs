//! `--denoise` through the real binary, with the Open Image Denoise library that
//! scripts/install-deps.sh unpacks: the denoised direct layer is closer to a converged
//! reference than the raw one, the layers and the header say what was denoised, the
//! denoiser's time is reported, and without the library the render stops before it starts
//! and writes nothing (while everything else still works).

mod common;
use common::*;
use serde_json::Value;
use std::path::Path;
use std::process::Command;

fn cornell() -> String {
    project_dir().join("scenes/cornell.gltf").display().to_string()
}

/// The error of `layer` of `image` against `reference`, from `icrender compare --json`.
fn compared(image: &Path, reference: &Path) -> Vec<Value> {
    let out = run_ok(&[
        "compare",
        image.to_str().unwrap(),
        reference.to_str().unwrap(),
        "--json",
    ]);
    serde_json::from_str::<Value>(&stdout(&out))
        .unwrap()
        .as_array()
        .unwrap()
        .clone()
}

fn layer_error<'a>(errors: &'a [Value], layer: &str) -> &'a Value {
    errors
        .iter()
        .find(|e| e["layer"] == layer)
        .unwrap_or_else(|| panic!("compare lists no layer {layer}: {errors:?}"))
}

#[test]
fn the_denoised_direct_layer_is_closer_to_a_converged_reference_than_the_raw_one() {
    let dir = tempfile::tempdir().unwrap();
    let (reference, image) = (dir.path().join("ref.exr"), dir.path().join("noisy.exr"));
    let stats = dir.path().join("noisy.json");
    // -ab 0 keeps the reference cheap (about a second); its own relative noise, 0.01 RMS, is a
    // relMSE of about 1e-4, a hundredth of the raw layer's error below.
    let size = ["-x", "64", "-y", "64", "--ab", "0"];
    let scene = cornell();
    let mut args = vec!["reference", &scene, "-o", reference.to_str().unwrap()];
    args.extend_from_slice(&size);
    args.extend_from_slice(&["--noise", "0.01", "-q", "--no-preview"]);
    run_ok(&args);
    // One sample and one plainly sampled shadow ray a pixel: a noisy direct layer.
    let mut args = vec!["render", &scene, "-o", image.to_str().unwrap()];
    args.extend_from_slice(&size);
    args.extend_from_slice(&[
        "--spp",
        "1",
        "--light-samples",
        "1",
        "--direct",
        "sampled",
        "--denoise",
        "--stats",
        stats.to_str().unwrap(),
    ]);
    let out = run_ok(&args);

    let errors = compared(&image, &reference);
    let (raw, denoised) = (layer_error(&errors, "direct"), layer_error(&errors, "direct_denoised"));
    let rel = |e: &Value| e["rel_mse"].as_f64().unwrap();
    let rmse = |e: &Value| e["rmse"].as_f64().unwrap();
    // Measured: relMSE 2.2e-2 raw, 9.5e-3 denoised; RMSE 2.3e-2 and 1.4e-2.
    assert!(
        rel(denoised) < 0.6 * rel(raw) && rmse(denoised) < 0.8 * rmse(raw),
        "direct against the reference: raw {raw}, denoised {denoised}"
    );
    assert!(rel(raw) > 1e-3, "the raw layer should be noisy: {raw}");

    // The denoised layers are in the file beside the raw ones; emission is not denoised.
    let info = Command::new("oiiotool")
        .args(["--info", "-v", image.to_str().unwrap()])
        .output()
        .expect("oiiotool (openimageio-tools) is installed");
    let info = String::from_utf8_lossy(&info.stdout);
    for channel in [
        "direct.R",
        "direct_denoised.R",
        "specular_denoised.B",
        "denoised.G",
        "emission.R",
    ] {
        assert!(info.contains(channel), "oiiotool lists no {channel}:\n{info}");
    }
    assert!(!info.contains("emission_denoised"), "{info}");

    // The header says what was denoised, how, and in what time.
    let read = read_image(
        &image,
        &["icrender/denoised", "icrender/denoise", "icrender/denoise_time_s"],
    )
    .unwrap();
    assert_eq!(
        read.attribute("icrender/denoised"),
        Some("direct_denoised specular_denoised denoised")
    );
    let how = read.attribute("icrender/denoise").unwrap();
    assert!(
        how.contains("Open Image Denoise 2.")
            && how.contains("quality fast")
            && how.contains("as rendered")
            && how.contains("raw emission plus")
            && how.contains("one sample a pixel: no noise measured"),
        "{how}"
    );
    let seconds: f64 = read.attribute("icrender/denoise_time_s").unwrap().parse().unwrap();
    assert!(seconds > 0.0);
    let stats: Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    assert!(stats["denoise_s"].as_f64().unwrap() > 0.0, "{stats}");
    assert_eq!(stats["denoised_layers"][0], "direct_denoised");
    // ... and the summary on stderr.
    let said = stderr(&out);
    assert!(
        said.lines()
            .any(|l| l.starts_with("icrender: denoised direct, specular") && l.contains(" s (")),
        "{said}"
    );

    // The denoised composite is the raw emission plus the denoised layers, exactly as written.
    let sum = |layers: &[&str]| -> [Vec<f32>; 3] {
        std::array::from_fn(|c| {
            let planes: Vec<[Vec<f32>; 3]> = layers.iter().map(|l| rgb(&read, l)).collect();
            (0..planes[0][c].len())
                .map(|i| planes.iter().map(|p| p[c][i]).sum())
                .collect()
        })
    };
    let expected = sum(&["emission", "direct_denoised", "specular_denoised"]);
    let written = rgb(&read, "denoised");
    for c in 0..3 {
        for (a, b) in written[c].iter().zip(&expected[c]) {
            assert!(
                (a - b).abs() <= 1e-6 * b.abs().max(1.0),
                "denoised {a} against the sum {b}"
            );
        }
    }
}

/// A render asked to denoise, with the library made unfindable by naming a file that does not
/// exist (the variable, when set, is the only place looked).
fn without_the_library(dir: &Path, extra: &[&str]) -> std::process::Output {
    let out = dir.join("r.exr");
    let stats = dir.join("r.json");
    let checkpoint = dir.join("checkpoint");
    let mut cmd = Command::new(binary());
    cmd.env("ICRENDER_OIDN_LIB", dir.join("missing/libOpenImageDenoise.so.2"))
        .args(["render", &cornell(), "-x", "32", "-y", "32", "-q", "-o"])
        .arg(&out)
        .arg("--stats")
        .arg(&stats)
        .arg("--checkpoint")
        .arg(&checkpoint)
        .args(extra);
    cmd.output().unwrap()
}

#[test]
fn without_the_library_denoise_stops_before_rendering_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = without_the_library(dir.path(), &["--denoise"]);
    assert!(!out.status.success());
    let said = stderr(&out);
    assert_eq!(said.lines().count(), 1, "one line expected:\n{said}");
    assert!(
        said.starts_with("icrender: error: --denoise: the denoiser library libOpenImageDenoise.so.2")
            && said.contains("was not found")
            && said.contains("scripts/install-deps.sh"),
        "{said}"
    );
    // Nothing written: no image, preview, statistics, temporary file or checkpoint (which a
    // render opens before it loads the scene).
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert!(left.is_empty(), "written: {left:?}");

    // Everything else works without it.
    let out = without_the_library(dir.path(), &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(dir.path().join("r.exr").is_file());
}

#[test]
fn a_file_that_is_not_the_denoiser_is_refused_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let fake = dir.path().join("libOpenImageDenoise.so.2");
    std::fs::write(&fake, b"not a shared library").unwrap();
    let out = Command::new(binary())
        .env("ICRENDER_OIDN_LIB", &fake)
        .args(["render", &cornell(), "-x", "8", "-y", "8", "-q", "--denoise", "-o"])
        .arg(dir.path().join("r.exr"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let said = stderr(&out);
    assert_eq!(said.lines().count(), 1, "{said}");
    assert!(
        said.contains("could not be opened") && said.contains(fake.to_str().unwrap()),
        "{said}"
    );
    assert!(!dir.path().join("r.exr").exists());
}

#[test]
fn a_reference_is_not_denoised() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(&[
        "reference",
        &cornell(),
        "-x",
        "8",
        "-y",
        "8",
        "--denoise",
        "-o",
        dir.path().join("ref.exr").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("--denoise: a reference is converged"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn a_clean_direct_layer_is_not_blurred_by_the_filter() {
    // 16 samples a pixel and the default ratio estimate: the direct layer has little noise
    // left but for penumbrae, and the filter alone blurs the box's edges more than it removes
    // (measured: relMSE 4.65e-4 against the raw layer's 2.8e-4); weighed by the pixels' noise
    // the raw layer is kept where it is clean (3.05e-4). Likewise with one sample a pixel and
    // 16 shadow rays, the edges sampled apart, weighed by the noise its shadow rays measured:
    // 3.18e-4 against the raw 3.27e-4 (the filter alone 3.98e-4; seeds 2 and 3 alike).
    let dir = tempfile::tempdir().unwrap();
    let reference = dir.path().join("ref.exr");
    let scene = cornell();
    let size = ["-x", "64", "-y", "64", "--ab", "0", "-q", "--no-preview"];
    let mut args = vec![
        "reference",
        &scene,
        "-o",
        reference.to_str().unwrap(),
        "--noise",
        "0.005",
    ];
    args.extend_from_slice(&size);
    run_ok(&args);
    let one_sample = ["--spp", "1", "--light-samples", "16", "--edge-samples", "16"];
    for (name, sampling, bound) in [
        ("many.exr", &["--spp", "16"][..], 1.2),
        ("one.exr", &one_sample[..], 1.0),
    ] {
        let image = dir.path().join(name);
        let mut args = vec!["render", &scene, "-o", image.to_str().unwrap(), "--denoise"];
        args.extend_from_slice(sampling);
        args.extend_from_slice(&size);
        run_ok(&args);
        let errors = compared(&image, &reference);
        let rel = |layer| layer_error(&errors, layer)["rel_mse"].as_f64().unwrap();
        let (raw, denoised) = (rel("direct"), rel("direct_denoised"));
        assert!(
            denoised < bound * raw,
            "{sampling:?}: direct against the reference: relMSE raw {raw:.3e}, denoised {denoised:.3e}"
        );
        let how = read_image(&image, &["icrender/denoise"]).unwrap();
        let how = how.attribute("icrender/denoise").unwrap();
        let measured_by = if name == "one.exr" {
            "shadow rays measured"
        } else {
            "samples measured"
        };
        assert!(how.contains(measured_by), "{sampling:?}: {how}");
    }
}

#[test]
fn the_indirect_layer_is_denoised_without_the_cache_only() {
    // With the cache (the default -aa) the indirect layer is records interpolated: written
    // raw, and the denoised composite adds it up raw; with -aa 0 it is sampled per pixel and
    // denoised like the direct light.
    let dir = tempfile::tempdir().unwrap();
    let scene = cornell();
    for (accuracy, expected) in [
        ("0.2", "direct_denoised specular_denoised denoised"),
        ("0", "direct_denoised specular_denoised indirect_denoised denoised"),
    ] {
        let image = dir.path().join(format!("aa-{accuracy}.exr"));
        run_ok(&[
            "render",
            &scene,
            "-o",
            image.to_str().unwrap(),
            "-x",
            "32",
            "-y",
            "32",
            "-ab",
            "1",
            "-ad",
            "32",
            "-aa",
            accuracy,
            "--spp",
            "4",
            "--denoise",
            "-q",
            "--no-preview",
        ]);
        let read = read_image(&image, &["icrender/denoised", "icrender/denoise"]).unwrap();
        assert_eq!(read.attribute("icrender/denoised"), Some(expected), "-aa {accuracy}");
        // Four samples a pixel measure their noise.
        assert!(
            read.attribute("icrender/denoise")
                .unwrap()
                .contains("weighed against the raw layer")
        );
        assert!(read.channel("indirect.R").is_some(), "-aa {accuracy}");
        let indirect = if accuracy == "0" {
            "indirect_denoised"
        } else {
            "indirect"
        };
        let planes: Vec<[Vec<f32>; 3]> = ["emission", "direct_denoised", "specular_denoised", indirect]
            .iter()
            .map(|l| rgb(&read, l))
            .collect();
        let denoised = rgb(&read, "denoised");
        for c in 0..3 {
            for (i, b) in denoised[c].iter().enumerate() {
                let a: f32 = planes.iter().map(|p| p[c][i]).sum();
                assert!(
                    (a - b).abs() <= 1e-5 * b.abs().max(1.0),
                    "-aa {accuracy}: {a} against {b}"
                );
            }
        }
    }
}

#[test]
fn denoise_under_mpirun_writes_the_denoised_layers_on_the_master() {
    let dir = tempfile::tempdir().unwrap();
    let image = dir.path().join("mpi.exr");
    let out = mpirun_command(
        3,
        &[
            "render",
            &cornell(),
            "-x",
            "32",
            "-y",
            "32",
            "-ad",
            "64",
            // Brute force: each pixel samples its own hemisphere, so `indirect` is denoised too.
            "-aa",
            "0",
            // Two samples a pixel: the workers' pixels carry their noise to the master.
            "--spp",
            "2",
            "--tile",
            "8x8",
            "--denoise",
            "--denoise-quality",
            "fast",
            "--no-preview",
            "--timeout",
            "60",
            "-o",
            image.to_str().unwrap(),
        ],
    )
    .output()
    .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let read = read_image(&image, &["icrender/denoised", "icrender/denoise"]).unwrap();
    assert_eq!(
        read.attribute("icrender/denoised"),
        Some("direct_denoised specular_denoised indirect_denoised denoised")
    );
    let how = read.attribute("icrender/denoise").unwrap();
    assert!(
        how.contains("quality fast") && how.contains("weighed against the raw layer"),
        "{how}"
    );
    assert!(read.channel("indirect_denoised.R").is_some());
    assert!(stderr(&out).contains("icrender: denoised direct, specular, indirect"));
    // Had the pixels' noise been lost on the way (zero everywhere), the weighing would have
    // kept every raw value: the denoised layers would be the raw ones.
    for layer in ["direct", "indirect"] {
        let (raw, denoised) = (rgb(&read, layer), rgb(&read, &format!("{layer}_denoised")));
        let changed = (0..3).any(|c| raw[c].iter().zip(&denoised[c]).any(|(a, b)| (a - b).abs() > 1e-4));
        assert!(
            changed,
            "{layer}_denoised is the raw {layer}: no noise reached the master"
        );
    }
}

/// A floor, a square blocker above it casting a hard shadow, lit by a point light or (with
/// `area`) by an emitting square of about the same power in the same place.
fn shadowed_floor(dir: &Path, area: bool) -> std::path::PathBuf {
    let mut b = GltfBuilder::new();
    let paint = b.material(lambertian("paint", [0.6, 0.6, 0.6]));
    b.quad(
        [[-4.0, 0.0, -4.0], [-4.0, 0.0, 4.0], [4.0, 0.0, 4.0], [4.0, 0.0, -4.0]],
        Some(paint),
    );
    b.quad(
        [[-1.0, 1.0, -1.0], [-1.0, 1.0, 1.0], [1.0, 1.0, 1.0], [1.0, 1.0, -1.0]],
        Some(paint),
    );
    if area {
        let lamp = b.material(emissive_lambertian("lamp", [0.0; 3], 40.0));
        b.quad(
            [
                [-0.25, 3.0, -0.25],
                [0.25, 3.0, -0.25],
                [0.25, 3.0, 0.25],
                [-0.25, 3.0, 0.25],
            ],
            Some(lamp),
        );
    } else {
        b.point_light([0.3, 3.0, 0.2], 40.0);
    }
    b.write(dir, if area { "area" } else { "point" })
}

#[test]
fn punctual_light_traced_exactly_leaves_nothing_to_denoise() {
    // Four samples a pixel across the blocker's and its shadow's hard edges: their spread is
    // the pixels' content, not noise (each point light has its own shadow ray), so no filter
    // runs and `direct_denoised` is the raw layer; lit by an area light (sampled shadow rays,
    // a penumbra) the same view's direct light is filtered.
    let dir = tempfile::tempdir().unwrap();
    for area in [false, true] {
        let scene = shadowed_floor(dir.path(), area);
        let view = ["--vp", "0", "5", "4", "--vd", "0", "-5", "-4"];
        let mut args = vec!["-x", "48", "-y", "48", "-ab", "0", "--spp", "4", "--denoise"];
        args.extend_from_slice(&view);
        let image = render_file(dir.path(), &scene, &format!("area-{area}"), &args);
        let read = read_image(&image, &["icrender/denoise"]).unwrap();
        let said = read.attribute("icrender/denoise").unwrap().to_string();
        let (raw, denoised) = (rgb(&read, "direct"), rgb(&read, "direct_denoised"));
        if area {
            assert!(said.contains("layers direct each denoised"), "{said}");
            assert_ne!(raw, denoised, "the area light's direct layer is filtered");
        } else {
            assert!(
                said.contains("not started: no layer to filter")
                    && said.contains("direct left as rendered in direct_denoised (no Monte Carlo noise measured)")
                    && !said.contains("guided by")
                    && !said.contains("each denoised"),
                "{said}"
            );
            assert_eq!(raw, denoised);
        }
    }
}

#[test]
fn the_filter_runs_only_where_the_pixels_measured_noise() {
    // 16 samples a pixel, -ab 0: the direct light is noisy in the penumbrae, clean elsewhere;
    // the filter sees the noisy rectangles with their margins, not the whole of each layer.
    let dir = tempfile::tempdir().unwrap();
    let (image, stats) = (dir.path().join("r.exr"), dir.path().join("r.json"));
    let scene = cornell();
    run_ok(&[
        "render",
        &scene,
        "-o",
        image.to_str().unwrap(),
        "-x",
        "128",
        "-y",
        "128",
        "--ab",
        "0",
        "--spp",
        "16",
        "--denoise",
        "-q",
        "--no-preview",
        "--stats",
        stats.to_str().unwrap(),
    ]);
    let stats: Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    let layers = stats["denoised_layers"].as_array().unwrap().len() - 1;
    let filtered = stats["denoise_filtered_pixels"].as_u64().unwrap() as usize;
    assert!(layers >= 1 && filtered > 0, "{stats}");
    assert!(
        filtered < layers * 128 * 128,
        "{filtered} pixels filtered over {layers} layers: {stats}"
    );
    let how = read_image(&image, &["icrender/denoise"]).unwrap();
    let how = how.attribute("icrender/denoise").unwrap();
    assert!(how.contains("the filter ran where the measured noise is"), "{how}");
}

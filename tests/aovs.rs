//! The data layers (albedo, normal, depth, position) and Cryptomatte in the EXR: against
//! analytic scenes (a plane square to the view, a mirror), names hashed back to the IDs in the
//! pixels, coverage on edges, precision under --half, and the same layers in every mode and
//! after a resume.

mod common;
use common::*;
use icrender::image::cryptomatte::{id_of, layer_key};
use serde_json::{Map, Value, json};
use std::path::{Path, PathBuf};

/// Header attributes the tests read.
fn attributes(object: bool) -> Vec<String> {
    let key = layer_key(if object { "CryptoObject" } else { "CryptoMaterial" });
    let mut names: Vec<String> = ["name", "hash", "conversion", "manifest"]
        .iter()
        .map(|a| format!("cryptomatte/{key}/{a}"))
        .collect();
    names.extend(["icrender/aovs".to_string(), "icrender/depth_far".to_string()]);
    names
}

fn render(dir: &Path, scene: &Path, name: &str, extra: &[&str]) -> ImageData {
    read_with_crypto(&render_file(dir, scene, name, extra))
}

fn read_with_crypto(path: &Path) -> ImageData {
    let names: Vec<String> = attributes(true).into_iter().chain(attributes(false)).collect();
    let names: Vec<&str> = names.iter().map(String::as_str).collect();
    read_image(path, &names).unwrap()
}

fn channel<'a>(image: &'a ImageData, name: &str) -> &'a [f32] {
    image.channel(name).unwrap_or_else(|| panic!("no channel {name}"))
}

/// The camera of the analytic scenes: at (0, 0, 5) looking down -Z, 60 degrees square.
const VIEW: [&str; 14] = [
    "-vp", "0", "0", "5", "-vd", "0", "0", "-1", "-vu", "0", "1", "0", "-vh", "60",
];

fn view_args(size: u32) -> Vec<String> {
    let mut v: Vec<String> = VIEW.iter().map(|s| s.to_string()).collect();
    v.extend(["-vv", "60", "-x", &size.to_string(), "-y", &size.to_string()].map(String::from));
    v
}

/// A 40 x 40 plane at z = 0 facing the camera, node `floor`, material `paint` (Lambertian).
fn plane_scene(dir: &Path) -> PathBuf {
    let mut b = GltfBuilder::new();
    let m = b.material(lambertian("paint", [0.6, 0.3, 0.2]));
    let mesh = b.mesh(
        &[
            [-20.0, -20.0, 0.0],
            [20.0, -20.0, 0.0],
            [20.0, 20.0, 0.0],
            [-20.0, 20.0, 0.0],
        ],
        &[[0, 1, 2], [0, 2, 3]],
        Some(m),
    );
    b.node(json!({"mesh": mesh, "name": "floor"}));
    b.point_light([0.0, 0.0, 3.0], 10.0);
    b.write(dir, "plane")
}

#[test]
fn a_plane_square_to_the_view_has_its_depth_normal_albedo_and_position() {
    let dir = tempfile::tempdir().unwrap();
    let scene = plane_scene(dir.path());
    let size = 17u32;
    let mut args: Vec<String> = view_args(size);
    args.extend(["--aovs", "all"].map(String::from));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let image = render(dir.path(), &scene, "plane", &args);
    assert_eq!(
        image.attribute("icrender/aovs"),
        Some("albedo,normal,depth,position,crypto_object,crypto_material")
    );
    let half_side = 5.0 * (30.0f64).to_radians().tan();
    for y in 0..size {
        for x in 0..size {
            let i = (y * size + x) as usize;
            // Along the view axis every point of the plane is 5 away, although the rays to the
            // corners travel 5 / cos: depth is not the ray's length.
            let depth = channel(&image, "depth.Z")[i];
            assert!((depth - 5.0).abs() < 1e-4, "pixel {x},{y}: depth {depth}");
            let n = ["X", "Y", "Z"].map(|c| channel(&image, &format!("normal.{c}"))[i]);
            assert!(
                n[0].abs() < 1e-6 && n[1].abs() < 1e-6 && (n[2] - 1.0).abs() < 1e-6,
                "{n:?}"
            );
            let albedo = ["R", "G", "B"].map(|c| channel(&image, &format!("albedo.{c}"))[i]);
            for (a, e) in albedo.iter().zip([0.6, 0.3, 0.2]) {
                assert!((a - e).abs() < 1e-6, "pixel {x},{y}: albedo {albedo:?}");
            }
            // One sample at the pixel's centre: the point the centre's ray reaches.
            let sx = 2.0 * (x as f64 + 0.5) / size as f64 - 1.0;
            let sy = 1.0 - 2.0 * (y as f64 + 0.5) / size as f64;
            let p = ["X", "Y", "Z"].map(|c| channel(&image, &format!("position.{c}"))[i] as f64);
            let expect = [sx * half_side, sy * half_side, 0.0];
            for (a, e) in p.iter().zip(expect) {
                assert!(
                    (a - e).abs() < 1e-4,
                    "pixel {x},{y}: position {p:?}, expected {expect:?}"
                );
            }
        }
    }
}

#[test]
fn a_mirror_shows_the_albedo_of_what_it_reflects() {
    // The camera looks at a mirror (metallic, roughness 0, reflectance 0.8) square to the view;
    // the mirror shows a wall behind the camera. Normal and depth are the mirror's, the albedo
    // the wall's times the mirror's reflectance.
    let dir = tempfile::tempdir().unwrap();
    let mut b = GltfBuilder::new();
    let mirror = b.material(json!({
        "name": "mirror",
        "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1.0], "metallicFactor": 1.0, "roughnessFactor": 0.0}
    }));
    let wall = b.material(lambertian("wall", [0.2, 0.5, 0.7]));
    let big = 40.0;
    b.quad(
        facing(
            [[-big, -big, 0.0], [big, -big, 0.0], [big, big, 0.0], [-big, big, 0.0]],
            [0.0, 0.0, 5.0],
        ),
        Some(mirror),
    );
    b.quad(
        facing(
            [
                [-big, -big, 10.0],
                [big, -big, 10.0],
                [big, big, 10.0],
                [-big, big, 10.0],
            ],
            [0.0, 0.0, 0.0],
        ),
        Some(wall),
    );
    b.point_light([0.0, 0.0, 3.0], 10.0);
    let scene = b.write(dir.path(), "mirror");
    let size = 9u32;
    let args = view_args(size);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let image = render(dir.path(), &scene, "mirror", &args);
    for i in 0..(size * size) as usize {
        let albedo = ["R", "G", "B"].map(|c| channel(&image, &format!("albedo.{c}"))[i]);
        for (a, e) in albedo.iter().zip([0.8 * 0.2, 0.8 * 0.5, 0.8 * 0.7]) {
            assert!((a - e).abs() < 1e-5, "pixel {i}: albedo {albedo:?}");
        }
        assert!((channel(&image, "depth.Z")[i] - 5.0).abs() < 1e-4);
        assert!((channel(&image, "normal.Z")[i] - 1.0).abs() < 1e-6);
    }
}

/// Two quads side by side meeting at x = 0, square to the view: `left` (material `matA`) and
/// an unnamed node with an unnamed material (fallback names `node1` and `material1`).
fn two_quads(dir: &Path) -> PathBuf {
    let mut b = GltfBuilder::new();
    let a = b.material(lambertian("matA", [0.5, 0.5, 0.5]));
    let mut unnamed = lambertian("", [0.3, 0.3, 0.3]);
    unnamed.as_object_mut().unwrap().remove("name");
    let c = b.material(unnamed);
    let left = b.mesh(
        &[
            [-20.0, -20.0, 0.0],
            [0.0, -20.0, 0.0],
            [0.0, 20.0, 0.0],
            [-20.0, 20.0, 0.0],
        ],
        &[[0, 1, 2], [0, 2, 3]],
        Some(a),
    );
    let right = b.mesh(
        &[
            [0.0, -20.0, 0.0],
            [20.0, -20.0, 0.0],
            [20.0, 20.0, 0.0],
            [0.0, 20.0, 0.0],
        ],
        &[[0, 1, 2], [0, 2, 3]],
        Some(c),
    );
    b.node(json!({"mesh": left, "name": "left"}));
    b.node(json!({"mesh": right}));
    b.point_light([0.0, 0.0, 3.0], 10.0);
    b.write(dir, "two")
}

#[test]
fn cryptomatte_ids_hash_the_manifest_names_and_coverage_splits_at_an_edge() {
    let dir = tempfile::tempdir().unwrap();
    let scene = two_quads(dir.path());
    // 17 pixels: the seam x = 0 runs down the middle of column 8; 16 samples a pixel in a 4 x 4
    // grid put two columns of samples on each side of it.
    let size = 17u32;
    let mut args = view_args(size);
    args.extend(["--spp", "16"].map(String::from));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let image = render(dir.path(), &scene, "crypto", &args);
    for (type_name, names) in [
        ("CryptoObject", ["left", "node1"]),
        ("CryptoMaterial", ["matA", "material1"]),
    ] {
        let key = layer_key(type_name);
        assert_eq!(image.attribute(&format!("cryptomatte/{key}/name")), Some(type_name));
        assert_eq!(
            image.attribute(&format!("cryptomatte/{key}/hash")),
            Some("MurmurHash3_32")
        );
        assert_eq!(
            image.attribute(&format!("cryptomatte/{key}/conversion")),
            Some("uint32_to_float32")
        );
        let manifest: Map<String, Value> = serde_json::from_str(
            image
                .attribute(&format!("cryptomatte/{key}/manifest"))
                .expect("a manifest"),
        )
        .expect("the manifest is JSON");
        let mut listed: Vec<&str> = manifest.keys().map(String::as_str).collect();
        listed.sort();
        assert_eq!(listed, names, "{type_name}");
        // Every name hashes to the ID the manifest gives, and only those IDs are in the pixels.
        let mut ids = Vec::new();
        for (name, hex) in &manifest {
            let id = u32::from_str_radix(hex.as_str().unwrap(), 16).unwrap();
            assert_eq!(id, id_of(name), "{name}");
            ids.push(id);
        }
        let rank = |r: usize, i: usize| -> (u32, f32) {
            let layer = format!("{type_name}{:02}", r / 2);
            let (id, cov) = if r.is_multiple_of(2) { ("R", "G") } else { ("B", "A") };
            (
                channel(&image, &format!("{layer}.{id}"))[i].to_bits(),
                channel(&image, &format!("{layer}.{cov}"))[i],
            )
        };
        for y in 0..size {
            for x in 0..size {
                let i = (y * size + x) as usize;
                let ranks: Vec<(u32, f32)> = (0..6).map(|r| rank(r, i)).collect();
                // Ranked by coverage; used ranks hold a manifest ID, unused ones are empty.
                assert!(ranks.windows(2).all(|w| w[0].1 >= w[1].1), "{x},{y}: {ranks:?}");
                for &(id, coverage) in &ranks {
                    assert!(coverage == 0.0 && id == 0 || coverage > 0.0 && ids.contains(&id));
                }
                let total: f32 = ranks.iter().map(|r| r.1).sum();
                assert!((total - 1.0).abs() < 1e-6, "{x},{y}: coverage {total}");
                let expect_left = id_of(names[0]);
                let expect_right = id_of(names[1]);
                match x {
                    ..=7 => assert_eq!(ranks[0], (expect_left, 1.0), "{x},{y}"),
                    9.. => assert_eq!(ranks[0], (expect_right, 1.0), "{x},{y}"),
                    _ => {
                        // The edge column: half each (ties are ranked by ID).
                        let mut two = [ranks[0], ranks[1]];
                        two.sort_by_key(|r| r.0);
                        let mut expect = [(expect_left, 0.5), (expect_right, 0.5)];
                        expect.sort_by_key(|r| r.0);
                        assert_eq!(two, expect, "{x},{y}: {ranks:?}");
                    }
                }
            }
        }
    }
}

#[test]
fn nothing_hit_is_the_documented_far_depth_and_no_id() {
    let dir = tempfile::tempdir().unwrap();
    let scene = plane_scene(dir.path());
    // Looking away from the plane: nothing is hit.
    let image = render(
        dir.path(),
        &scene,
        "sky",
        &["-vp", "0", "0", "5", "-vd", "0", "0", "1", "-x", "4", "-y", "4"],
    );
    let far: f32 = image.attribute("icrender/depth_far").unwrap().parse().unwrap();
    assert_eq!(far, 1e30);
    assert!(channel(&image, "depth.Z").iter().all(|&d| d == far));
    for c in ["albedo.R", "normal.Z", "CryptoObject00.R", "CryptoObject00.G"] {
        assert!(channel(&image, c).iter().all(|&v| v == 0.0), "{c}");
    }
    // Position is opt-in; the defaults are the others.
    assert!(image.channel("position.X").is_none());
    assert_eq!(
        image.attribute("icrender/aovs"),
        Some("albedo,normal,depth,crypto_object,crypto_material")
    );
}

#[test]
fn aovs_none_writes_the_light_layers_only() {
    let dir = tempfile::tempdir().unwrap();
    let scene = plane_scene(dir.path());
    let image = render(dir.path(), &scene, "none", &["-x", "4", "-y", "4", "--aovs", "none"]);
    assert!(image.channel("albedo.R").is_none() && image.channel("depth.Z").is_none());
    assert!(image.channels.iter().all(|(n, _)| !n.starts_with("Crypto")));
    assert_eq!(image.attribute("icrender/aovs"), Some("none"));
    let bad = run(&["render", scene.to_str().unwrap(), "--aovs", "albedo,colour"]);
    assert!(!bad.status.success());
    assert!(stderr(&bad).contains("colour"), "{}", stderr(&bad));
}

/// `oiiotool --info -v` as a compositor's tools see the file: every layer, and the data layers
/// and Cryptomatte as float even with --half.
#[test]
fn oiiotool_lists_every_layer_and_data_stays_float_under_half() {
    let dir = tempfile::tempdir().unwrap();
    let scene = project_dir().join("scenes/cornell.gltf");
    let out = dir.path().join("half.exr");
    run_ok(&[
        "render",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "-q",
        "--no-preview",
        "-x",
        "16",
        "-y",
        "16",
        "--half",
        "--aovs",
        "all",
    ]);
    let info = std::process::Command::new("oiiotool")
        .args(["--info", "-v", out.to_str().unwrap()])
        .output()
        .expect("oiiotool (openimageio-tools) is installed");
    assert!(info.status.success());
    let text = String::from_utf8_lossy(&info.stdout);
    let list = text
        .lines()
        .find_map(|l| l.trim().strip_prefix("channel list:"))
        .expect("a channel list");
    let channels: Vec<(&str, &str)> = list
        .split(", ")
        .map(|c| {
            let (name, format) = c.trim().split_once(" (").unwrap();
            (name, format.trim_end_matches(')'))
        })
        .collect();
    let format = |name: &str| {
        channels
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, f)| *f)
            .unwrap_or_else(|| panic!("{name} not in {list}"))
    };
    for light in ["R", "G", "B", "A", "direct.R", "indirect.B", "emission.G", "specular.R"] {
        assert_eq!(format(light), "half", "{light}");
    }
    let mut data = vec![
        "albedo.R",
        "albedo.G",
        "albedo.B",
        "normal.X",
        "normal.Y",
        "normal.Z",
        "depth.Z",
        "position.X",
        "position.Y",
        "position.Z",
    ]
    .into_iter()
    .map(String::from)
    .collect::<Vec<_>>();
    for t in ["CryptoObject", "CryptoMaterial"] {
        for level in 0..3 {
            for c in ["R", "G", "B", "A"] {
                data.push(format!("{t}{level:02}.{c}"));
            }
        }
    }
    for name in &data {
        assert_eq!(format(name), "float", "{name}");
    }
    assert_eq!(channels.len(), 4 + 4 * 3 + data.len(), "{list}");
    for key in [layer_key("CryptoObject"), layer_key("CryptoMaterial")] {
        assert!(text.contains(&format!("cryptomatte/{key}/manifest")), "{text}");
    }
}

/// Every `--compression` reads back in oiiotool, which names the codec; the lossless ones give
/// the zip file's pixels bit for bit. dwaa, lossy on every channel named like colour (it blurred
/// Cryptomatte's IDs when tried), is refused beside data layers and keeps light close.
#[test]
fn every_compression_reads_back_in_oiiotool_and_only_dwaa_changes_the_light() {
    let dir = tempfile::tempdir().unwrap();
    let scene = project_dir().join("scenes/cornell.gltf");
    let options = |codec: &'static str, aovs: &'static str| {
        ["-x", "24", "-y", "24", "--half", "--aovs", aovs, "--compression", codec]
    };
    let write = |codec: &'static str, aovs: &'static str| {
        let path = render_file(dir.path(), &scene, codec, &options(codec, aovs));
        let out = path.to_str().unwrap();
        let info = std::process::Command::new("oiiotool")
            .args(["--info", "-v", out])
            .output()
            .expect("oiiotool (openimageio-tools) is installed");
        assert!(info.status.success(), "oiiotool cannot read the {codec} file");
        let text = String::from_utf8_lossy(&info.stdout).to_string();
        let said = text
            .lines()
            .find_map(|l| l.trim().strip_prefix("compression:"))
            .map(|c| c.trim().trim_matches('"').to_string());
        assert_eq!(said.as_deref(), Some(codec), "{text}");
        read_with_crypto(&path)
    };
    let zip = write("zip", "all");
    for codec in ["piz", "none"] {
        let other = write(codec, "all");
        assert_eq!(zip.channels.len(), other.channels.len(), "{codec}");
        for (name, data) in &zip.channels {
            assert_eq!(data.as_slice(), channel(&other, name), "{codec}: {name}");
        }
    }
    let out = dir.path().join("dwaa.exr");
    let mut refused = vec!["render", scene.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q"];
    refused.extend(options("dwaa", "all"));
    let refused = run(&refused);
    assert!(!refused.status.success());
    let said = stderr(&refused);
    assert!(
        said.contains("--compression dwaa") && said.contains("--aovs none"),
        "{said}"
    );
    assert!(!dir.path().join("dwaa.exr").exists());
    let dwaa = write("dwaa", "none");
    let (a, b) = (channel(&zip, "R"), channel(&dwaa, "R"));
    let scale = a.iter().fold(0f32, |m, v| m.max(v.abs())).max(1e-6);
    let worst = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0f32, f32::max);
    assert!(worst <= 0.1 * scale, "dwaa moved R by {worst} of {scale}");
}

/// Every data channel of two images, bit for bit.
fn assert_same_data(a: &ImageData, b: &ImageData, what: &str) {
    let data: Vec<&String> = a
        .channels
        .iter()
        .map(|(n, _)| n)
        .filter(|n| {
            ["albedo.", "normal.", "depth.", "position.", "Crypto"]
                .iter()
                .any(|p| n.starts_with(p))
        })
        .collect();
    assert_eq!(data.len(), 3 + 3 + 1 + 3 + 24, "{what}: {data:?}");
    for name in data {
        let (x, y) = (channel(a, name), channel(b, name));
        let differing = x.iter().zip(y).filter(|(p, q)| p.to_bits() != q.to_bits()).count();
        assert_eq!(differing, 0, "{what}: {differing} values of {name} differ");
    }
}

fn cornell_args(out: &Path) -> Vec<String> {
    [
        "render",
        project_dir().join("scenes/cornell.gltf").to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "-q",
        "--no-preview",
        "--overwrite",
        "-x",
        "24",
        "-y",
        "24",
        "--tile",
        "8x8",
        "--spp",
        "4",
        "-ad",
        "64",
        "--aovs",
        "all",
        "--timeout",
        "60",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

/// Component mode with records made as tiles render: its light differs from one process's
/// within the cache's error, but what the camera rays hit cannot.
#[test]
fn component_mode_writes_the_one_process_data_layers() {
    let dir = tempfile::tempdir().unwrap();
    let serial_out = dir.path().join("serial.exr");
    let mut args = cornell_args(&serial_out);
    args.extend(["--ic-build", "progressive"].map(String::from));
    run_ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let component_out = dir.path().join("component.exr");
    let mut args = cornell_args(&component_out);
    args.extend(["--ic-build", "progressive", "--mode", "component"].map(String::from));
    let output = mpirun_command(4, &args).output().expect("mpirun runs");
    assert!(output.status.success(), "{}{}", stdout(&output), stderr(&output));
    assert_same_data(
        &read_with_crypto(&component_out),
        &read_with_crypto(&serial_out),
        "component mode",
    );
}

#[test]
fn resumed_renders_keep_the_data_layers() {
    let dir = tempfile::tempdir().unwrap();
    let checkpoint = dir.path().join("ckpt");
    let first_out = dir.path().join("first.exr");
    let mut args = cornell_args(&first_out);
    args.extend(["--checkpoint".to_string(), checkpoint.to_str().unwrap().to_string()]);
    run_ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let first = read_with_crypto(&first_out);
    // Cut the journal in the middle of its entries, as a kill would: the tiles before the cut
    // come back from it, the others are rendered again.
    let journal = checkpoint.join("tiles.journal");
    let bytes = std::fs::read(&journal).unwrap();
    std::fs::write(&journal, &bytes[..bytes.len() / 2]).unwrap();
    let second_out = dir.path().join("second.exr");
    let stats = dir.path().join("second.json");
    let mut args = cornell_args(&second_out);
    args.extend([
        "--checkpoint".to_string(),
        checkpoint.to_str().unwrap().to_string(),
        "--stats".to_string(),
        stats.to_str().unwrap().to_string(),
    ]);
    run_ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let stats: Value = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    let restored = stats["tiles_restored"].as_u64().unwrap();
    assert!(restored > 0 && restored < 9, "{restored} of 9 tiles restored");
    assert_same_data(&read_with_crypto(&second_out), &first, "resumed");
}

//! Test support: building small glTF scenes on disk, running the real `icrender` binary, and
//! reading its EXR output back.

#![allow(dead_code)]

use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub use icrender::sys::image_io::{ImageData, read_image};

pub fn binary() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_icrender"))
}

/// The project's root (for `scenes/`) and the shared scenes beside it.
pub fn project_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

pub fn shared_scene(relative: &str) -> PathBuf {
    project_dir().join("../shared/scenes").join(relative)
}

/// Runs icrender with arguments; returns the process output.
pub fn run(args: &[&str]) -> Output {
    Command::new(binary()).args(args).output().expect("icrender runs")
}

pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

pub fn stdout(out: &Output) -> String {
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Runs icrender and fails the test with its stderr if it did not succeed.
pub fn run_ok(args: &[&str]) -> Output {
    let out = run(args);
    assert!(out.status.success(), "icrender {args:?} failed:\n{}", stderr(&out));
    out
}

/// Renders `scene` to `dir/name.exr` with `extra` options (quiet, no preview, overwriting) and
/// returns the EXR's path.
pub fn render_file(dir: &Path, scene: &Path, name: &str, extra: &[&str]) -> PathBuf {
    let out = dir.join(format!("{name}.exr"));
    let mut args = vec![
        "render",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "-q",
        "--no-preview",
        "--overwrite",
    ];
    args.extend_from_slice(extra);
    run_ok(&args);
    out
}

/// Renders `scene` to `dir/name.exr` with `extra` options (quiet, no preview) and returns the
/// image and the statistics JSON.
pub fn render_to(dir: &Path, scene: &Path, name: &str, extra: &[&str]) -> (ImageData, Value) {
    let stats = dir.join(format!("{name}.json"));
    let mut args = vec!["--stats", stats.to_str().unwrap()];
    args.extend_from_slice(extra);
    let out = render_file(dir, scene, name, &args);
    let stats = serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
    (read_exr(&out), stats)
}

/// The same image where it matters to a compositor: `a`'s every channel in `b`, bit for bit,
/// at the same place in the display window, and `a`'s every header attribute in `b` with the
/// same value but those named in `except` (what says how the render ran).
pub fn assert_same_image(a: &ImageData, b: &ImageData, except: &[&str], what: &str) {
    assert_eq!((a.width, a.height, a.window), (b.width, b.height, b.window), "{what}");
    for (name, values) in &a.channels {
        let theirs = b.channel(name).unwrap_or_else(|| panic!("{what}: no {name}"));
        let differing = values
            .iter()
            .zip(theirs)
            .filter(|(x, y)| x.to_bits() != y.to_bits())
            .count();
        assert_eq!(differing, 0, "{what}: {name} differs at {differing} pixels");
    }
    for (name, value) in &a.attributes {
        if !except.contains(&name.as_str()) {
            assert_eq!(b.attribute(name), Some(value.as_str()), "{what}: {name}");
        }
    }
}

pub fn read_exr(path: &Path) -> ImageData {
    read_image(path, &["icrender/options", "icrender/statistics", "icrender/command"])
        .unwrap_or_else(|e| panic!("reading {}: {e}", path.display()))
}

/// R, G, B planes of a layer ("" for the composite).
pub fn rgb(image: &ImageData, layer: &str) -> [Vec<f32>; 3] {
    ["R", "G", "B"].map(|c| {
        let name = if layer.is_empty() {
            c.to_string()
        } else {
            format!("{layer}.{c}")
        };
        image
            .channel(&name)
            .unwrap_or_else(|| panic!("no channel {name}"))
            .to_vec()
    })
}

pub fn mean(values: &[f32]) -> f64 {
    values.iter().map(|&v| v as f64).sum::<f64>() / values.len().max(1) as f64
}

/// A glTF file under construction: geometry goes into one external .bin buffer.
#[derive(Default)]
pub struct GltfBuilder {
    bin: Vec<u8>,
    buffer_views: Vec<Value>,
    accessors: Vec<Value>,
    meshes: Vec<Value>,
    materials: Vec<Value>,
    nodes: Vec<Value>,
    lights: Vec<Value>,
    cameras: Vec<Value>,
    images: Vec<Value>,
    textures: Vec<Value>,
    animations: Vec<Value>,
    pub extensions_used: Vec<String>,
    pub extensions_required: Vec<String>,
}

/// An animation channel for `GltfBuilder::animation`: (node, path "translation" | "rotation" |
/// "scale", interpolation "LINEAR" | "STEP" | "CUBICSPLINE", key times, values: 3 or 4 per key,
/// three times that for CUBICSPLINE).
pub type Channel<'a> = (usize, &'a str, &'a str, &'a [f32], &'a [f32]);

/// A Lambertian material (specularFactor 0, metallic 0) of albedo `rgb`.
pub fn lambertian(name: &str, rgb: [f32; 3]) -> Value {
    json!({
        "name": name,
        "pbrMetallicRoughness": {"baseColorFactor": [rgb[0], rgb[1], rgb[2], 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0},
        "extensions": {"KHR_materials_specular": {"specularFactor": 0.0}}
    })
}

/// A Lambertian material that also emits `radiance` from its front side.
pub fn emissive_lambertian(name: &str, rgb: [f32; 3], radiance: f32) -> Value {
    let mut m = lambertian(name, rgb);
    m["emissiveFactor"] = json!([1.0, 1.0, 1.0]);
    m["extensions"]["KHR_materials_emissive_strength"] = json!({"emissiveStrength": radiance});
    m
}

impl GltfBuilder {
    pub fn new() -> Self {
        Self::default()
    }

    fn push_view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        let mut view = json!({"buffer": 0, "byteOffset": offset, "byteLength": bytes.len()});
        if let Some(t) = target {
            view["target"] = json!(t);
        }
        self.buffer_views.push(view);
        self.buffer_views.len() - 1
    }

    pub fn material(&mut self, material: Value) -> usize {
        self.materials.push(material);
        self.materials.len() - 1
    }

    /// Adds a mesh of triangles (positions, indices) with a material; returns the mesh index.
    pub fn mesh(&mut self, positions: &[[f32; 3]], indices: &[[u32; 3]], material: Option<usize>) -> usize {
        let pos_bytes: Vec<u8> = positions.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
        let idx_bytes: Vec<u8> = indices.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
        let pv = self.push_view(&pos_bytes, Some(34962));
        let iv = self.push_view(&idx_bytes, Some(34963));
        let finite: Vec<&[f32; 3]> = positions.iter().filter(|p| p.iter().all(|v| v.is_finite())).collect();
        let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
        for p in &finite {
            for c in 0..3 {
                lo[c] = lo[c].min(p[c]);
                hi[c] = hi[c].max(p[c]);
            }
        }
        self.accessors.push(json!({"bufferView": pv, "componentType": 5126, "count": positions.len(), "type": "VEC3", "min": lo, "max": hi}));
        let pa = self.accessors.len() - 1;
        self.accessors
            .push(json!({"bufferView": iv, "componentType": 5125, "count": indices.len() * 3, "type": "SCALAR"}));
        let ia = self.accessors.len() - 1;
        let mut primitive = json!({"attributes": {"POSITION": pa}, "indices": ia, "mode": 4});
        if let Some(m) = material {
            primitive["material"] = json!(m);
        }
        self.meshes.push(json!({"primitives": [primitive]}));
        self.meshes.len() - 1
    }

    /// Adds a mesh with optional NORMAL and TEXCOORD_0 attributes; returns the mesh index.
    pub fn mesh_with(
        &mut self,
        positions: &[[f32; 3]],
        normals: Option<&[[f32; 3]]>,
        texcoords: Option<&[[f32; 2]]>,
        indices: &[[u32; 3]],
        material: Option<usize>,
    ) -> usize {
        let mesh = self.mesh(positions, indices, material);
        let mut extra = Vec::new();
        if let Some(n) = normals {
            extra.push(("NORMAL", n.iter().flatten().copied().collect::<Vec<f32>>(), "VEC3"));
        }
        if let Some(t) = texcoords {
            extra.push(("TEXCOORD_0", t.iter().flatten().copied().collect(), "VEC2"));
        }
        for (name, values, kind) in extra {
            let a = self.float_accessor(&values, kind);
            self.meshes[mesh]["primitives"][0]["attributes"][name] = json!(a);
        }
        mesh
    }

    /// A float accessor of `kind` ("SCALAR", "VEC2", "VEC3", "VEC4") over `values`.
    pub fn float_accessor(&mut self, values: &[f32], kind: &str) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.push_view(&bytes, None);
        let per = match kind {
            "SCALAR" => 1,
            "VEC2" => 2,
            "VEC3" => 3,
            _ => 4,
        };
        let mut accessor =
            json!({"bufferView": view, "componentType": 5126, "count": values.len() / per, "type": kind});
        // glTF requires the bounds of an animation's key times (a SCALAR input).
        if per == 1 {
            let lo = values.iter().cloned().fold(f32::INFINITY, f32::min);
            let hi = values.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
            accessor["min"] = json!([lo]);
            accessor["max"] = json!([hi]);
        }
        self.accessors.push(accessor);
        self.accessors.len() - 1
    }

    /// A normalized signed short VEC4 accessor (a quaternion per element, as
    /// EXT_mesh_gpu_instancing allows for ROTATION).
    pub fn normalized_short_vec4(&mut self, values: &[[f32; 4]]) -> usize {
        let bytes: Vec<u8> = (values.iter().flatten())
            .flat_map(|v| ((v * 32767.0).round() as i16).to_le_bytes())
            .collect();
        let view = self.push_view(&bytes, None);
        self.accessors.push(json!({"bufferView": view, "componentType": 5122, "normalized": true, "count": values.len(), "type": "VEC4"}));
        self.accessors.len() - 1
    }

    /// Adds a quad (two triangles, counter-clockwise a-b-c-d seen from its front).
    pub fn quad(&mut self, corners: [[f32; 3]; 4], material: Option<usize>) -> usize {
        let mesh = self.mesh(&corners, &[[0, 1, 2], [0, 2, 3]], material);
        self.node(json!({"mesh": mesh}))
    }

    pub fn node(&mut self, node: Value) -> usize {
        self.nodes.push(node);
        self.nodes.len() - 1
    }

    pub fn point_light(&mut self, position: [f32; 3], intensity: f32) -> usize {
        self.use_extension("KHR_lights_punctual");
        self.lights
            .push(json!({"type": "point", "color": [1.0, 1.0, 1.0], "intensity": intensity}));
        let light = self.lights.len() - 1;
        self.node(json!({"translation": position, "extensions": {"KHR_lights_punctual": {"light": light}}}))
    }

    /// A perspective camera (vertical field of view in radians); place it with a node
    /// `{"camera": index, ...}`.
    pub fn perspective_camera(&mut self, yfov: f32) -> usize {
        self.cameras
            .push(json!({"type": "perspective", "perspective": {"yfov": yfov, "znear": 0.01}}));
        self.cameras.len() - 1
    }

    /// An animation: one channel per entry, each with its own sampler.
    pub fn animation(&mut self, name: &str, channels: &[Channel<'_>]) -> usize {
        let mut samplers = Vec::new();
        let mut out = Vec::new();
        for (i, (node, path, interpolation, times, values)) in channels.iter().enumerate() {
            let kind = if *path == "rotation" { "VEC4" } else { "VEC3" };
            let input = self.float_accessor(times, "SCALAR");
            let output = self.float_accessor(values, kind);
            samplers.push(json!({"input": input, "output": output, "interpolation": interpolation}));
            out.push(json!({"sampler": i, "target": {"node": node, "path": path}}));
        }
        self.animations
            .push(json!({"name": name, "channels": out, "samplers": samplers}));
        self.animations.len() - 1
    }

    pub fn texture(&mut self, uri: &str) -> usize {
        self.images.push(json!({"uri": uri}));
        self.textures.push(json!({"source": self.images.len() - 1}));
        self.textures.len() - 1
    }

    pub fn use_extension(&mut self, name: &str) {
        if !self.extensions_used.iter().any(|e| e == name) {
            self.extensions_used.push(name.to_string());
        }
    }

    pub fn to_json(&self, bin_name: &str) -> Value {
        let mut used = self.extensions_used.clone();
        for m in &self.materials {
            if let Some(ext) = m.get("extensions").and_then(|e| e.as_object()) {
                for k in ext.keys() {
                    if !used.contains(k) {
                        used.push(k.clone());
                    }
                }
            }
        }
        // The scene's roots: the nodes no node has as a child.
        let children: Vec<u64> = (self.nodes.iter())
            .filter_map(|n| n.get("children").and_then(|c| c.as_array()))
            .flatten()
            .filter_map(|c| c.as_u64())
            .collect();
        let roots: Vec<usize> = (0..self.nodes.len())
            .filter(|i| !children.contains(&(*i as u64)))
            .collect();
        let mut doc = json!({
            "asset": {"version": "2.0", "generator": "icrender tests"},
            "scene": 0,
            "scenes": [{"nodes": roots}],
            "nodes": self.nodes,
            "meshes": self.meshes,
            "accessors": self.accessors,
            "bufferViews": self.buffer_views,
            "buffers": [{"uri": bin_name, "byteLength": self.bin.len()}],
        });
        if !self.materials.is_empty() {
            doc["materials"] = json!(self.materials);
        }
        if !self.cameras.is_empty() {
            doc["cameras"] = json!(self.cameras);
        }
        if !self.animations.is_empty() {
            doc["animations"] = json!(self.animations);
        }
        if !self.images.is_empty() {
            doc["images"] = json!(self.images);
            doc["textures"] = json!(self.textures);
        }
        if !self.lights.is_empty() {
            doc["extensions"] = json!({"KHR_lights_punctual": {"lights": self.lights}});
        }
        if !used.is_empty() {
            doc["extensionsUsed"] = json!(used);
        }
        if !self.extensions_required.is_empty() {
            doc["extensionsRequired"] = json!(self.extensions_required);
        }
        doc
    }

    /// Writes `name.gltf` and `name.bin` into `dir`; returns the .gltf path.
    pub fn write(&self, dir: &Path, name: &str) -> PathBuf {
        self.write_edited(dir, name, |_| {})
    }

    /// As `write`, with the glTF JSON changed by `edit` first.
    pub fn write_edited(&self, dir: &Path, name: &str, edit: impl FnOnce(&mut Value)) -> PathBuf {
        let bin_name = format!("{name}.bin");
        std::fs::write(dir.join(&bin_name), &self.bin).unwrap();
        let path = dir.join(format!("{name}.gltf"));
        let mut doc = self.to_json(&bin_name);
        edit(&mut doc);
        std::fs::write(&path, serde_json::to_string_pretty(&doc).unwrap()).unwrap();
        path
    }
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Orders a planar quad's corners so that its front (by winding) faces towards `target`.
pub fn facing(mut corners: [[f32; 3]; 4], target: [f32; 3]) -> [[f32; 3]; 4] {
    let n = cross(sub(corners[1], corners[0]), sub(corners[2], corners[0]));
    let centre = [0, 1, 2].map(|c| corners.iter().map(|p| p[c]).sum::<f32>() / 4.0);
    if dot(n, sub(target, centre)) < 0.0 {
        corners.reverse();
    }
    corners
}

/// The six walls of an axis-aligned box from `lo` to `hi`, fronts facing inwards.
pub fn inward_box(b: &mut GltfBuilder, lo: [f32; 3], hi: [f32; 3], material: usize) {
    let [x0, y0, z0] = lo;
    let [x1, y1, z1] = hi;
    let centre = [(x0 + x1) / 2.0, (y0 + y1) / 2.0, (z0 + z1) / 2.0];
    let faces = [
        [[x0, y0, z0], [x1, y0, z0], [x1, y0, z1], [x0, y0, z1]],
        [[x0, y1, z0], [x1, y1, z0], [x1, y1, z1], [x0, y1, z1]],
        [[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0]],
        [[x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]],
        [[x0, y0, z0], [x0, y1, z0], [x0, y1, z1], [x0, y0, z1]],
        [[x1, y0, z0], [x1, y1, z0], [x1, y1, z1], [x1, y0, z1]],
    ];
    for f in faces {
        b.quad(facing(f, centre), Some(material));
    }
}

/// Relative mean squared error of the composite of `a` against `b` (eps 0.01, as icrender's
/// own metric), over every channel of every pixel.
/// A 64 x 64 checker of single texels, 0.05 and 0.9 in linear light (stored as sRGB bytes), as
/// `dir/checker.png`; and the checker's mean in linear light, as the stored bytes decode.
pub fn single_texel_checker(dir: &Path) -> f32 {
    let encode = |linear: f32| (255.0 * linear.powf(1.0 / 2.2)).round() as u8;
    let decode = |byte: u8| {
        let c = byte as f32 / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    };
    let (dark, bright) = (encode(0.05), encode(0.9));
    let mut texels = Vec::new();
    for y in 0..64 {
        for x in 0..64 {
            let v = if (x + y) % 2 == 0 { dark } else { bright };
            texels.extend_from_slice(&[v, v, v]);
        }
    }
    icrender::sys::image_io::write_png(&dir.join("checker.png"), 64, 64, &texels).unwrap();
    0.5 * (decode(dark) + decode(bright))
}

pub fn relmse(a: &ImageData, b: &ImageData) -> f64 {
    let (x, y) = (rgb(a, ""), rgb(b, ""));
    let mut sum = 0.0;
    let mut n = 0;
    for c in 0..3 {
        for (p, q) in x[c].iter().zip(&y[c]) {
            sum += ((*p - *q) as f64).powi(2) / ((*q as f64).powi(2) + 0.01);
            n += 1;
        }
    }
    sum / n as f64
}

/// `mpirun` for this machine's tests: as root, oversubscribed (2 cores), loopback only (no
/// network probing).
pub fn mpirun_command<S: AsRef<std::ffi::OsStr>>(np: usize, args: &[S]) -> Command {
    let mut cmd = Command::new("mpirun");
    cmd.env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .env("OMPI_MCA_btl_tcp_if_include", "lo")
        .env("OMPI_MCA_oob_tcp_if_include", "lo")
        .args(["--oversubscribe", "-np", &np.to_string()])
        .arg(binary())
        .args(args);
    cmd
}

/// Channels whose values may be negative: directions and points (`normal`, `position`), and
/// Cryptomatte IDs (floats with a hash's sign bit). Every other channel is light, an albedo,
/// a depth or a coverage, none of which is ever negative.
pub fn may_be_negative(channel: &str) -> bool {
    match channel.rsplit_once('.') {
        Some((layer, c)) => {
            layer == "normal" || layer == "position" || (layer.starts_with("Crypto") && (c == "R" || c == "B"))
        }
        None => false,
    }
}

/// Irradiance at `point` (normal +y) from a uniformly emitting polygon of radiance `radiance`
/// that faces it, by Lambert's contour formula: E = L/2 * sum over edges of angle_i * (g_i . n)
/// with g_i the unit normal of the plane through the point and the edge.
pub fn polygon_irradiance(corners: &[[f64; 3]], point: [f64; 3], radiance: f64) -> f64 {
    let v: Vec<[f64; 3]> = (corners.iter())
        .map(|c| {
            let d = [c[0] - point[0], c[1] - point[1], c[2] - point[2]];
            let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            d.map(|x| x / l)
        })
        .collect();
    let mut sum = 0.0;
    for i in 0..v.len() {
        let (a, b) = (v[i], v[(i + 1) % v.len()]);
        let cross = [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ];
        let l = (cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2]).sqrt();
        let angle = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).clamp(-1.0, 1.0).acos();
        sum += angle * cross[1] / l;
    }
    0.5 * sum.abs() * radiance
}

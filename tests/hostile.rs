//! Hostile and malformed scene files (issue 7, item 1). The corpus is generated here, into a
//! temporary folder laid out as
//!
//!     ROOT/secret.bin, ROOT/secret.png      files the scenes must not read
//!     ROOT/scenes/*.gltf, *.glb             the corpus, one problem per file
//!     ROOT/scenes/tri.bin, tex.png, sub/    legitimate neighbours
//!     ROOT/scenes/link.bin -> ../secret.bin and other symbolic links, a FIFO
//!
//! Every file that must fail makes `render` and `info` exit non-zero with exactly one line
//! "icrender: error: FILE: ..." (no panic, no signal, nothing else on stderr, no output file);
//! files with a documented safe behaviour load and render a finite image. THROUGH_THE_BINARY
//! lists the files run through the real binary (31 failing, 2 loading); the other variants are
//! checked on `Scene::load` in this process, the loader behind both commands. No run reads the
//! secrets: their access times are watched, and the test proves it can see a read by loading the
//! outside references with --allow-outside-refs, which must then succeed and touch the secret.
//!
//! `HOSTILE_CORPUS_DIR=DIR cargo test --release --test hostile -- --ignored write_corpus` writes
//! the corpus into DIR (the fuzzing seeds use it; see docs/FUZZING.md).

mod common;
use common::*;
use icrender::scene::{LoadOptions, Scene};
use serde_json::{Value, json};
use std::fs;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::{Duration, SystemTime};

// ---------------------------------------------------------------------------------------------
// Encoders (no compression crate: PNGs use stored deflate blocks)

fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in bytes.chunks(3) {
        let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(ALPHABET[(n >> (18 - 6 * i) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = 0xffff_ffffu32;
    for &b in bytes {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xedb8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// zlib stream of stored (uncompressed) deflate blocks.
fn zlib_stored(data: &[u8]) -> Vec<u8> {
    let mut out = vec![0x78, 0x01];
    let chunks: Vec<&[u8]> = if data.is_empty() {
        vec![&[]]
    } else {
        data.chunks(65535).collect()
    };
    for (i, c) in chunks.iter().enumerate() {
        out.push((i + 1 == chunks.len()) as u8);
        out.extend_from_slice(&(c.len() as u16).to_le_bytes());
        out.extend_from_slice(&(!(c.len() as u16)).to_le_bytes());
        out.extend_from_slice(c);
    }
    let (mut a, mut b) = (1u32, 0u32);
    for &x in data {
        a = (a + x as u32) % 65521;
        b = (b + a) % 65521;
    }
    out.extend_from_slice(&(b << 16 | a).to_be_bytes());
    out
}

fn png_chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    let mut body = kind.to_vec();
    body.extend_from_slice(data);
    out.extend_from_slice(&body);
    out.extend_from_slice(&crc32(&body).to_be_bytes());
}

/// A PNG whose header says `width` x `height` (bit depth, colour type) and whose IDAT holds
/// `idat` as given.
fn png_raw(width: u32, height: u32, depth: u8, color_type: u8, idat: &[u8]) -> Vec<u8> {
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&width.to_be_bytes());
    ihdr.extend_from_slice(&height.to_be_bytes());
    ihdr.extend_from_slice(&[depth, color_type, 0, 0, 0]);
    png_chunk(&mut out, b"IHDR", &ihdr);
    png_chunk(&mut out, b"IDAT", idat);
    png_chunk(&mut out, b"IEND", &[]);
    out
}

/// A valid 8-bit RGBA PNG.
fn png_rgba(width: u32, height: u32, rgba: &[u8]) -> Vec<u8> {
    let row = 4 * width as usize;
    let mut raw = Vec::new();
    for y in 0..height as usize {
        raw.push(0);
        raw.extend_from_slice(&rgba[y * row..(y + 1) * row]);
    }
    png_raw(width, height, 8, 6, &zlib_stored(&raw))
}

fn small_png() -> Vec<u8> {
    png_rgba(
        2,
        2,
        &[255, 0, 0, 255, 0, 255, 0, 255, 0, 0, 255, 255, 255, 255, 255, 255],
    )
}

/// A baseline JPEG header (SOI, SOF0) declaring `width` x `height`, then EOI.
fn jpeg_header(width: u16, height: u16) -> Vec<u8> {
    let mut out = vec![0xFF, 0xD8, 0xFF, 0xC0, 0x00, 0x11, 0x08];
    out.extend_from_slice(&height.to_be_bytes());
    out.extend_from_slice(&width.to_be_bytes());
    out.push(3);
    for id in 1..=3u8 {
        out.extend_from_slice(&[id, 0x11, 0]);
    }
    out.extend_from_slice(&[0xFF, 0xD9]);
    out
}

/// A BMP header (BITMAPINFOHEADER, 24 bits) declaring `width` x `height` and no pixel data.
fn bmp_header(width: i32, height: i32) -> Vec<u8> {
    let mut out = b"BM".to_vec();
    out.extend_from_slice(&54u32.to_le_bytes()); // file size (a lie)
    out.extend_from_slice(&[0; 4]);
    out.extend_from_slice(&54u32.to_le_bytes()); // pixel data offset
    out.extend_from_slice(&40u32.to_le_bytes());
    out.extend_from_slice(&width.to_le_bytes());
    out.extend_from_slice(&height.to_le_bytes());
    out.extend_from_slice(&1u16.to_le_bytes());
    out.extend_from_slice(&24u16.to_le_bytes());
    out.extend_from_slice(&[0; 24]);
    out
}

fn glb(doc: &Value, bin: &[u8]) -> Vec<u8> {
    let mut js = serde_json::to_vec(doc).unwrap();
    while !js.len().is_multiple_of(4) {
        js.push(b' ');
    }
    let mut body = Vec::new();
    body.extend_from_slice(&(js.len() as u32).to_le_bytes());
    body.extend_from_slice(b"JSON");
    body.extend_from_slice(&js);
    if !bin.is_empty() {
        let mut b = bin.to_vec();
        while !b.len().is_multiple_of(4) {
            b.push(0);
        }
        body.extend_from_slice(&(b.len() as u32).to_le_bytes());
        body.extend_from_slice(b"BIN\0");
        body.extend_from_slice(&b);
    }
    let mut out = b"glTF".to_vec();
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(12 + body.len() as u32).to_le_bytes());
    out.extend_from_slice(&body);
    out
}

// ---------------------------------------------------------------------------------------------
// A small valid scene to break in one place at a time

/// One triangle (positions, u16 indices and two bytes of padding): 44 bytes.
fn tri_bin() -> Vec<u8> {
    let mut out = Vec::new();
    for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for i in [0u16, 1, 2, 0] {
        out.extend_from_slice(&i.to_le_bytes());
    }
    out
}

fn data_uri(bytes: &[u8]) -> String {
    format!("data:application/octet-stream;base64,{}", base64(bytes))
}

/// A lit triangle reading its 44-byte buffer from `uri` (None: the GLB's BIN chunk).
fn triangle(uri: Option<&str>) -> Value {
    let mut doc = json!({
        "asset": {"version": "2.0", "generator": "icrender tests/hostile.rs"},
        "extensionsUsed": ["KHR_lights_punctual"],
        "scene": 0,
        "scenes": [{"nodes": [0, 1]}],
        "nodes": [
            {"name": "triangle", "mesh": 0},
            {"name": "lamp", "translation": [0.3, 0.3, 1.0], "extensions": {"KHR_lights_punctual": {"light": 0}}}
        ],
        "extensions": {"KHR_lights_punctual": {"lights": [{"type": "point", "intensity": 5.0}]}},
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
        "materials": [{"name": "grey", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1.0], "metallicFactor": 0.0}}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 6}
        ],
        "buffers": [{"byteLength": 44}]
    });
    if let Some(uri) = uri {
        doc["buffers"][0]["uri"] = json!(uri);
    }
    doc
}

fn embedded_triangle() -> Value {
    triangle(Some(&data_uri(&tri_bin())))
}

/// The embedded triangle with its material textured by an image of the given uri or data.
fn textured(image: Value) -> Value {
    let mut doc = embedded_triangle();
    doc["images"] = json!([image]);
    doc["textures"] = json!([{"source": 0}]);
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
    doc
}

fn image_data_uri(mime: &str, bytes: &[u8]) -> Value {
    json!({"uri": format!("data:{mime};base64,{}", base64(bytes))})
}

/// A chain (or, with `twice`, a binary DAG) of `levels` nodes over the triangle.
fn node_chain(levels: usize, twice: bool) -> Value {
    let mut doc = embedded_triangle();
    let mut nodes: Vec<Value> = (0..levels)
        .map(|i| {
            let next = (i + 2) as u64;
            if twice {
                json!({"children": [next, next]})
            } else {
                json!({"children": [next]})
            }
        })
        .collect();
    nodes[levels - 1] = json!({"mesh": 0});
    // Node 0 is the chain's head, node 1 the lamp; chain nodes are 0, 2, 3, ...
    let mut all = vec![nodes[0].clone(), doc["nodes"][1].clone()];
    all.extend(nodes.into_iter().skip(1));
    if levels == 1 {
        all[0] = json!({"mesh": 0});
    }
    doc["nodes"] = json!(all);
    doc
}

// ---------------------------------------------------------------------------------------------
// The corpus

enum Expect {
    /// Exit non-zero with one error line mentioning each of these (besides the file name).
    Error(&'static [&'static str]),
    /// Loads and renders a finite image (a documented safe behaviour).
    Loads,
}

struct Case {
    file: String,
    expect: Expect,
    /// With --allow-outside-refs the file loads, by reading this secret outside the folder.
    reads_with_flag: Option<&'static str>,
    /// ICRENDER_MAX_SCENE_MEMORY_MB for this case (MiB), instead of the machine's memory.
    memory_limit_mb: Option<&'static str>,
}

struct Corpus {
    _dir: Option<tempfile::TempDir>,
    root: PathBuf,
    cases: Vec<Case>,
}

impl Corpus {
    fn scenes(&self) -> PathBuf {
        self.root.join("scenes")
    }
    fn secret(&self, name: &str) -> PathBuf {
        self.root.join(name)
    }
}

struct Writer {
    scenes: PathBuf,
    cases: Vec<Case>,
}

impl Writer {
    fn bytes(&mut self, file: &str, data: &[u8], expect: Expect) {
        assert!(!self.cases.iter().any(|c| c.file == file), "duplicate case {file}");
        fs::write(self.scenes.join(file), data).unwrap();
        self.cases.push(Case {
            file: file.into(),
            expect,
            reads_with_flag: None,
            memory_limit_mb: None,
        });
    }
    fn json(&mut self, file: &str, doc: &Value, expect: Expect) {
        self.bytes(file, &serde_json::to_vec(doc).unwrap(), expect);
    }
    /// A file whose only fault is a reference outside the folder, to `secret`.
    fn outside(&mut self, file: &str, data: &[u8], secret: &'static str, mention: &'static [&'static str]) {
        self.bytes(file, data, Expect::Error(mention));
        self.cases.last_mut().unwrap().reads_with_flag = Some(secret);
    }
}

fn make_corpus(root: &Path) -> Vec<Case> {
    let scenes = root.join("scenes");
    fs::create_dir_all(scenes.join("sub")).unwrap();
    let tri = tri_bin();
    fs::write(root.join("secret.bin"), &tri).unwrap();
    fs::write(root.join("secret.png"), small_png()).unwrap();
    fs::write(scenes.join("tri.bin"), &tri).unwrap();
    fs::write(scenes.join("tex.png"), small_png()).unwrap();
    std::os::unix::fs::symlink("../secret.bin", scenes.join("link.bin")).unwrap();
    std::os::unix::fs::symlink("../secret.png", scenes.join("link.png")).unwrap();
    std::os::unix::fs::symlink("/dev/zero", scenes.join("zero.bin")).unwrap();
    let fifo = std::process::Command::new("mkfifo")
        .arg(scenes.join("fifo.bin"))
        .status();
    assert!(fifo.is_ok_and(|s| s.success()), "mkfifo failed");
    let abs_bin = fs::canonicalize(root.join("secret.bin")).unwrap();
    let abs_png = fs::canonicalize(root.join("secret.png")).unwrap();
    let (abs_bin, abs_png) = (abs_bin.to_str().unwrap(), abs_png.to_str().unwrap());

    let mut w = Writer {
        scenes: scenes.clone(),
        cases: Vec::new(),
    };
    let j = |doc: Value| serde_json::to_vec(&doc).unwrap();

    // --- references outside the scene's folder
    w.outside(
        "out_buffer_dotdot.gltf",
        &j(triangle(Some("../secret.bin"))),
        "secret.bin",
        &["'../secret.bin'", "climbs out"],
    );
    w.outside(
        "out_buffer_percent_encoded.gltf",
        &j(triangle(Some("%2E%2E/secret.bin"))),
        "secret.bin",
        &["'../secret.bin'"],
    );
    w.outside(
        "out_buffer_subdir_escape.gltf",
        &j(triangle(Some("sub/../../secret.bin"))),
        "secret.bin",
        &["climbs out"],
    );
    w.outside(
        "out_buffer_absolute.gltf",
        &j(triangle(Some(abs_bin))),
        "secret.bin",
        &["absolute path"],
    );
    let file_uri = format!("file://{abs_bin}");
    w.outside(
        "out_buffer_file_uri.gltf",
        &j(triangle(Some(&file_uri))),
        "secret.bin",
        &["file: URI"],
    );
    let localhost = format!("file://localhost{abs_bin}");
    w.outside(
        "out_buffer_file_uri_localhost.gltf",
        &j(triangle(Some(&localhost))),
        "secret.bin",
        &["file: URI"],
    );
    w.outside(
        "out_buffer_symlink.gltf",
        &j(triangle(Some("link.bin"))),
        "secret.bin",
        &["'link.bin'", "symbolic link"],
    );
    w.outside(
        "out_image_dotdot.gltf",
        &j(textured(json!({"uri": "../secret.png"}))),
        "secret.png",
        &["'../secret.png'"],
    );
    w.outside(
        "out_image_absolute.gltf",
        &j(textured(json!({"uri": abs_png}))),
        "secret.png",
        &["absolute path"],
    );
    w.outside(
        "out_image_symlink.gltf",
        &j(textured(json!({"uri": "link.png"}))),
        "secret.png",
        &["'link.png'"],
    );
    // tinygltf reads every image, used or not: an unused one must be refused all the same.
    let mut unused = embedded_triangle();
    unused["images"] = json!([{"uri": "../secret.png"}]);
    w.outside("out_image_unused.gltf", &j(unused), "secret.png", &["'../secret.png'"]);
    let glb_doc = triangle(Some("../secret.bin"));
    w.outside(
        "out_glb_buffer_dotdot.glb",
        &glb(&glb_doc, &[]),
        "secret.bin",
        &["'../secret.bin'"],
    );
    for (file, uri, mention) in [
        (
            "out_buffer_etc_passwd.gltf",
            "../../../../../../../../etc/passwd",
            "climbs out",
        ),
        ("out_buffer_missing_outside.gltf", "../no-such-file.bin", "climbs out"),
        (
            "out_buffer_file_uri_other_host.gltf",
            "file://evil.example/etc/passwd",
            "file: URI",
        ),
        ("out_buffer_dev_zero_symlink.gltf", "zero.bin", "symbolic link"),
        ("out_buffer_nul_byte.gltf", "tri.bin%00../../secret.bin", "NUL byte"),
    ] {
        let words: &'static [&'static str] = match mention {
            "climbs out" => &["climbs out", "refused"],
            "file: URI" => &["file: URI", "refused"],
            "symbolic link" => &["symbolic link", "refused"],
            _ => &["NUL byte"],
        };
        w.json(file, &triangle(Some(uri)), Expect::Error(words));
    }

    // --- special files inside the folder: never opened, never waited on
    w.json(
        "in_buffer_fifo.gltf",
        &triangle(Some("fifo.bin")),
        Expect::Error(&["fifo.bin"]),
    );
    w.json(
        "in_buffer_directory.gltf",
        &triangle(Some("sub")),
        Expect::Error(&["sub"]),
    );
    w.json(
        "in_buffer_the_folder_itself.gltf",
        &triangle(Some(".")),
        Expect::Error(&["File not found"]),
    );
    w.json(
        "in_buffer_missing.gltf",
        &triangle(Some("nothing.bin")),
        Expect::Error(&["nothing.bin"]),
    );

    // --- data URIs that lie
    let mut doc = embedded_triangle();
    doc["buffers"][0]["byteLength"] = json!(1_000_000);
    w.json(
        "data_uri_shorter_than_declared.gltf",
        &doc,
        Expect::Error(&["holds 44 bytes", "1000000"]),
    );
    doc["buffers"][0]["byteLength"] = json!(8);
    w.json(
        "data_uri_longer_than_declared.gltf",
        &doc,
        Expect::Error(&["holds 44 bytes", "byteLength is 8"]),
    );
    let mut doc = embedded_triangle();
    doc["buffers"][0]["uri"] = json!(format!("data:application/x-evil;base64,{}", base64(&tri)));
    w.json(
        "data_uri_unknown_media_type.gltf",
        &doc,
        Expect::Error(&["not base64 data"]),
    );
    doc["buffers"][0]["uri"] = json!("data:application/octet-stream;base64,!!!!not base64!!!!");
    w.json("data_uri_not_base64.gltf", &doc, Expect::Error(&["holds 0 bytes"]));
    // A megabyte-long lying data URI: the message quotes a few dozen bytes of it, not all.
    doc["buffers"][0]["uri"] = json!(data_uri(&vec![7u8; 1 << 20]));
    w.json(
        "data_uri_megabyte_lie.gltf",
        &doc,
        Expect::Error(&["holds 1048576 bytes"]),
    );
    w.json(
        "image_data_uri_garbage.gltf",
        &textured(image_data_uri("image/png", b"this is not a png at all")),
        Expect::Error(&["cannot decode texture image"]),
    );

    // --- accessors and buffer views past their data
    let mut doc = embedded_triangle();
    doc["accessors"][0]["count"] = json!(1000);
    w.json(
        "accessor_past_buffer_view.gltf",
        &doc,
        Expect::Error(&["exceeds its bufferView"]),
    );
    let mut doc = embedded_triangle();
    doc["accessors"][0]["count"] = json!(1_000_000_000_000u64);
    w.json("accessor_count_1e12.gltf", &doc, Expect::Error(&["1000000000000"]));
    let mut doc = embedded_triangle();
    doc["accessors"][1]["count"] = json!(3_000_000_000_000u64);
    w.json("indices_1e12_triangles.gltf", &doc, Expect::Error(&["3000000000000"]));
    let mut doc = embedded_triangle();
    doc["accessors"][0]["byteOffset"] = json!(u64::MAX - 3);
    w.json("accessor_offset_overflow.gltf", &doc, Expect::Error(&["accessor"]));
    let mut doc = embedded_triangle();
    doc["bufferViews"][0]["byteLength"] = json!(4096);
    w.json(
        "buffer_view_past_buffer.gltf",
        &doc,
        Expect::Error(&["exceeds buffer 0"]),
    );
    let mut doc = embedded_triangle();
    doc["bufferViews"][0]["buffer"] = json!(-1);
    w.json("buffer_view_negative_buffer.gltf", &doc, Expect::Error(&["buffer"]));
    // Index values past the vertex count.
    let mut bad = tri.clone();
    bad[38..40].copy_from_slice(&7u16.to_le_bytes());
    w.json(
        "index_past_vertex_count.gltf",
        &triangle(Some(&data_uri(&bad))),
        Expect::Error(&["index 7 out of range"]),
    );
    let mut doc = triangle(Some(&data_uri(
        &[&tri[..36], &[0, 0, 0, 0, 255, 255, 255, 255, 0, 0, 0, 0][..]].concat(),
    )));
    doc["buffers"][0]["byteLength"] = json!(48);
    doc["bufferViews"][1]["byteLength"] = json!(12);
    doc["accessors"][1]["componentType"] = json!(5125);
    w.json(
        "index_u32_max.gltf",
        &doc,
        Expect::Error(&["index 4294967295 out of range"]),
    );
    // byteStride tricks.
    let mut doc = embedded_triangle();
    doc["bufferViews"][0]["byteStride"] = json!(4);
    w.json(
        "stride_smaller_than_element.gltf",
        &doc,
        Expect::Error(&["byteStride 4 is smaller"]),
    );
    doc["bufferViews"][0]["byteStride"] = json!(13);
    w.json("stride_not_multiple_of_4.gltf", &doc, Expect::Error(&["byteStride"]));
    doc["bufferViews"][0]["byteStride"] = json!(1u64 << 40);
    w.json("stride_huge.gltf", &doc, Expect::Error(&["byteStride"]));
    doc["bufferViews"][0]["byteStride"] = json!(252);
    w.json(
        "stride_max_past_view.gltf",
        &doc,
        Expect::Error(&["stride 252", "exceeds its bufferView"]),
    );
    // Accessor shapes the loader does not take.
    let mut doc = embedded_triangle();
    doc["accessors"][0]["sparse"] =
        json!({"count": 1, "indices": {"bufferView": 1, "componentType": 5123}, "values": {"bufferView": 0}});
    w.json("accessor_sparse.gltf", &doc, Expect::Error(&["sparse"]));
    let mut doc = embedded_triangle();
    doc["accessors"][0].as_object_mut().unwrap().remove("bufferView");
    w.json(
        "accessor_without_buffer_view.gltf",
        &doc,
        Expect::Error(&["no bufferView"]),
    );
    let mut doc = embedded_triangle();
    doc["accessors"][0]["type"] = json!("VEC2");
    w.json(
        "position_vec2.gltf",
        &doc,
        Expect::Error(&["POSITION must be float VEC3"]),
    );
    let mut doc = embedded_triangle();
    doc["accessors"][1]["componentType"] = json!(5126);
    doc["accessors"][1]["count"] = json!(1);
    w.json("indices_float.gltf", &doc, Expect::Error(&["indices must be"]));
    let mut doc = embedded_triangle();
    doc["meshes"][0]["primitives"][0]["material"] = json!(99);
    w.json(
        "material_out_of_range.gltf",
        &doc,
        Expect::Error(&["material 99 out of range"]),
    );
    let mut doc = embedded_triangle();
    doc["nodes"][0]["mesh"] = json!(99);
    w.json("mesh_out_of_range.gltf", &doc, Expect::Error(&["mesh 99 out of range"]));
    let mut doc = embedded_triangle();
    doc["nodes"][1]["extensions"]["KHR_lights_punctual"]["light"] = json!(5);
    w.json(
        "light_out_of_range.gltf",
        &doc,
        Expect::Error(&["light 5 out of range"]),
    );
    let mut doc = embedded_triangle();
    doc["scene"] = json!(7);
    w.json("default_scene_out_of_range.gltf", &doc, Expect::Error(&["scene"]));
    let mut doc = embedded_triangle();
    doc["nodes"][0]["matrix"] = json!([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0]);
    w.json("matrix_15_elements.gltf", &doc, Expect::Error(&["matrix"]));
    let mut doc = embedded_triangle();
    doc["nodes"][0]["scale"] = json!([1e300, 1e300, 1e300]);
    w.json(
        "scale_overflows_to_infinity.gltf",
        &doc,
        Expect::Error(&["no valid triangles"]),
    );

    // --- the glTF 2.0 specification's requirements on every asset (docs/GLTF_VALIDATION.md)
    w.bytes(
        "spec_not_json.gltf",
        b"solid cube\n  facet normal 0 0 1\n",
        Expect::Error(&["not a glTF file", "line 1, column 1"]),
    );
    w.bytes(
        "spec_json_not_object.gltf",
        b"[1, 2, 3]",
        Expect::Error(&["not a glTF file", "not an object"]),
    );
    let mut doc = embedded_triangle();
    doc.as_object_mut().unwrap().remove("asset");
    w.json("spec_asset_missing.gltf", &doc, Expect::Error(&["no \"asset\" object"]));
    let mut doc = embedded_triangle();
    doc["asset"] = json!({"generator": "x"});
    w.json(
        "spec_asset_version_missing.gltf",
        &doc,
        Expect::Error(&["no \"version\""]),
    );
    let mut doc = embedded_triangle();
    doc["asset"]["version"] = json!(2.0);
    w.json(
        "spec_asset_version_number.gltf",
        &doc,
        Expect::Error(&["asset.version", "not a version"]),
    );
    let mut doc = embedded_triangle();
    doc["asset"]["version"] = json!("3.0");
    w.json(
        "spec_asset_version_3.gltf",
        &doc,
        Expect::Error(&["asset.version \"3.0\"", "2.x"]),
    );
    let mut doc = embedded_triangle();
    doc["asset"] = json!({"version": "2.1", "minVersion": "2.1"});
    w.json(
        "spec_asset_min_version_2_1.gltf",
        &doc,
        Expect::Error(&["asset.minVersion \"2.1\""]),
    );
    let mut doc = embedded_triangle();
    doc["asset"] = json!({"version": "2.0", "minVersion": "2.0"});
    w.json("spec_asset_min_version_2_0.gltf", &doc, Expect::Loads);
    let mut doc = embedded_triangle();
    doc["asset"]["version"] = json!("2.7");
    w.json("spec_asset_version_2_7.gltf", &doc, Expect::Loads);
    let mut doc = embedded_triangle();
    doc["extensionsRequired"] = json!(["KHR_materials_specular"]);
    w.json(
        "spec_required_not_used.gltf",
        &doc,
        Expect::Error(&["extensionsRequired", "extensionsUsed"]),
    );
    let mut doc = embedded_triangle();
    doc["extensionsRequired"] = json!(["EXT_meshopt_compression"]);
    doc["extensionsUsed"] = json!(["KHR_lights_punctual", "EXT_meshopt_compression"]);
    w.json(
        "spec_required_unsupported.gltf",
        &doc,
        Expect::Error(&["unsupported required extension EXT_meshopt_compression"]),
    );
    let mut version_1 = glb(&triangle(None), &tri);
    version_1[4..8].copy_from_slice(&1u32.to_le_bytes());
    w.bytes("spec_glb_version_1.glb", &version_1, Expect::Error(&["GLB version 1"]));
    let mut doc = embedded_triangle();
    doc["accessors"][1]["byteOffset"] = json!(1);
    doc["bufferViews"][1]["byteLength"] = json!(8);
    w.json(
        "spec_accessor_misaligned.gltf",
        &doc,
        Expect::Error(&["byteOffset 1", "not a multiple of its component size 2"]),
    );
    let mut doc = embedded_triangle();
    doc["accessors"][1]["count"] = json!(0);
    w.json(
        "spec_accessor_count_0.gltf",
        &doc,
        Expect::Error(&["accessor 1", "count is 0"]),
    );
    let mut doc = embedded_triangle();
    doc["accessors"][0]["normalized"] = json!(true);
    w.json(
        "spec_accessor_float_normalized.gltf",
        &doc,
        Expect::Error(&["normalized", "float"]),
    );
    let mut doc = embedded_triangle();
    doc["accessors"][0]["bufferView"] = json!(9);
    w.json(
        "spec_accessor_buffer_view_9.gltf",
        &doc,
        Expect::Error(&["bufferView 9 out of range"]),
    );
    let mut doc = embedded_triangle();
    doc["accessors"][0]["type"] = json!("VEC5");
    w.json("spec_accessor_type_vec5.gltf", &doc, Expect::Error(&["VEC5"]));
    let mut doc = embedded_triangle();
    doc["accessors"]
        .as_array_mut()
        .unwrap()
        .push(json!({"bufferView": 0, "componentType": 5126, "count": 2, "type": "VEC3"}));
    doc["meshes"][0]["primitives"][0]["attributes"]["NORMAL"] = json!(2);
    w.json(
        "spec_attribute_counts_differ.gltf",
        &doc,
        Expect::Error(&["NORMAL count 2 differs from POSITION count 3"]),
    );
    let mut doc = embedded_triangle();
    doc["accessors"][1]["count"] = json!(2);
    w.json(
        "spec_indices_not_triangles.gltf",
        &doc,
        Expect::Error(&["index count 2 is not a multiple of 3"]),
    );
    let mut doc = embedded_triangle();
    doc["meshes"][0]["primitives"][0]["attributes"]
        .as_object_mut()
        .unwrap()
        .remove("POSITION");
    w.json(
        "spec_primitive_without_position.gltf",
        &doc,
        Expect::Error(&["no POSITION attribute"]),
    );
    let mut doc = embedded_triangle();
    doc["meshes"][0]["primitives"][0]["mode"] = json!(9);
    w.json(
        "spec_primitive_mode_9.gltf",
        &doc,
        Expect::Error(&["mode 9 is not a glTF primitive mode"]),
    );
    fs::write(scenes.join("spec_short.bin"), &tri[..20]).unwrap();
    w.json(
        "spec_buffer_file_shorter.gltf",
        &triangle(Some("spec_short.bin")),
        Expect::Error(&["spec_short.bin", "requestedBytes 44, but got 20"]),
    );
    let mut doc = embedded_triangle();
    doc["buffers"][0].as_object_mut().unwrap().remove("byteLength");
    w.json(
        "spec_buffer_without_byte_length.gltf",
        &doc,
        Expect::Error(&["byteLength", "Buffer"]),
    );
    let mut doc = embedded_triangle();
    doc["nodes"][0]["matrix"] = json!([2, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]);
    doc["nodes"][0]["translation"] = json!([1, 0, 0]);
    w.json(
        "spec_node_matrix_and_trs.gltf",
        &doc,
        Expect::Error(&["node 0", "both a matrix"]),
    );
    let mut doc = embedded_triangle();
    doc["nodes"][0]["camera"] = json!(3);
    w.json(
        "spec_node_camera_3.gltf",
        &doc,
        Expect::Error(&["camera 3 out of range"]),
    );
    let mut doc = embedded_triangle();
    doc["nodes"][0]["children"] = json!([9]);
    w.json("spec_node_child_9.gltf", &doc, Expect::Error(&["child 9 out of range"]));
    let mut doc = embedded_triangle();
    doc["scenes"][0]["nodes"] = json!([0, 9]);
    w.json(
        "spec_scene_root_9.gltf",
        &doc,
        Expect::Error(&["scene root node 9 out of range"]),
    );
    let mut doc = embedded_triangle();
    doc["textures"] = json!([{"source": 5}]);
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
    w.json(
        "spec_texture_image_5.gltf",
        &doc,
        Expect::Error(&["image 5 out of range"]),
    );
    let mut doc = embedded_triangle();
    doc["extensions"]["KHR_lights_punctual"]["lights"][0]["intensity"] = json!(-5);
    w.json(
        "spec_light_negative_intensity.gltf",
        &doc,
        Expect::Error(&["light intensity -5 is negative"]),
    );
    let mut doc = embedded_triangle();
    doc["extensions"]["KHR_lights_punctual"]["lights"][0] =
        json!({"type": "spot", "intensity": 5, "spot": {"innerConeAngle": 1.0, "outerConeAngle": 0.5}});
    w.json(
        "spec_spot_inner_above_outer.gltf",
        &doc,
        Expect::Error(&["spot cone angles", "inner < outer"]),
    );
    let mut doc = embedded_triangle();
    doc["extensions"]["KHR_lights_punctual"]["lights"][0]["type"] = json!("area");
    w.json("spec_light_type_area.gltf", &doc, Expect::Error(&["light type 'area'"]));

    // --- node graphs
    let mut doc = embedded_triangle();
    doc["nodes"][0]["children"] = json!([2]);
    doc["nodes"] = json!([doc["nodes"][0], doc["nodes"][1], {"children": [0]}]);
    w.json("cycle.gltf", &doc, Expect::Error(&["cycle"]));
    let mut doc = embedded_triangle();
    doc["nodes"][0]["children"] = json!([0]);
    w.json("cycle_self.gltf", &doc, Expect::Error(&["cycle"]));
    let mut doc = embedded_triangle();
    doc.as_object_mut().unwrap().remove("scenes");
    doc.as_object_mut().unwrap().remove("scene");
    doc["nodes"][0]["children"] = json!([1]);
    doc["nodes"][1]["children"] = json!([0]);
    w.json("cycle_without_roots.gltf", &doc, Expect::Error(&["cycle"]));
    // 64 levels, each node listing the next twice: 2^63 paths to the triangle.
    w.json(
        "dag_exponential.gltf",
        &node_chain(64, true),
        Expect::Error(&["used more than once"]),
    );
    let mut doc = embedded_triangle();
    doc["scenes"][0]["nodes"] = json!([0, 1, 0]);
    w.json("root_listed_twice.gltf", &doc, Expect::Error(&["used more than once"]));
    w.json(
        "nodes_nested_5000_deep.gltf",
        &node_chain(5000, false),
        Expect::Error(&["deeper than 1024"]),
    );
    let mut deep = embedded_triangle();
    let nested = format!("{}{}", "[".repeat(100_000), "]".repeat(100_000));
    deep["extras"] = json!("placeholder");
    let text = serde_json::to_string(&deep)
        .unwrap()
        .replace("\"placeholder\"", &nested);
    w.bytes(
        "json_nested_100000_deep.gltf",
        text.as_bytes(),
        Expect::Error(&["nested deeper than 256"]),
    );
    // 10^12 triangles declared by instancing: one 3-byte index set of 10^4 triangles reused by
    // 10^3 primitives, the mesh placed by 10^5 nodes. The file is half a megabyte; the scene
    // would need terabytes copied, and instanced (each primitive stored once) its 10^8
    // placements still take about 120 GiB, which is found before any of it is allocated (here
    // against a 16 GiB limit, whatever the machine has).
    w.bytes(
        "instancing_1e12_triangles.glb",
        &instancing_bomb(),
        Expect::Error(&["1000000000000 triangles in 100000000 mesh placements", "16.0 GiB"]),
    );
    w.cases.last_mut().unwrap().memory_limit_mb = Some("16384");

    // One big file in the folder named by 2000 image entries: each entry is read on its own,
    // so the total is checked (here against a 64 MiB limit) before every read.
    fs::write(scenes.join("big.bin"), vec![0u8; 1 << 20]).unwrap();
    let mut doc = embedded_triangle();
    doc["images"] = json!((0..2000).map(|_| json!({"uri": "big.bin"})).collect::<Vec<_>>());
    w.json(
        "images_naming_one_file_2000_times.gltf",
        &doc,
        Expect::Error(&["add up to more than", "64.0 MiB"]),
    );
    w.cases.last_mut().unwrap().memory_limit_mb = Some("64");
    // The same limit for what the scene would take once loaded: 5000 placements of the
    // triangle need more than 1 MiB.
    let mut doc = embedded_triangle();
    let mut nodes: Vec<Value> = (0..5000).map(|_| json!({"mesh": 0})).collect();
    nodes.push(doc["nodes"][1].clone());
    doc["nodes"] = json!(nodes);
    doc["scenes"][0]["nodes"] = json!((0..=5000).collect::<Vec<_>>());
    w.json(
        "memory_limit_1_mib.gltf",
        &doc,
        Expect::Error(&["5000 mesh placements", "1.0 MiB"]),
    );
    w.cases.last_mut().unwrap().memory_limit_mb = Some("1");

    // --- images that claim more than they hold
    w.json(
        "image_png_65535x65535.gltf",
        &textured(image_data_uri(
            "image/png",
            &png_raw(65535, 65535, 8, 6, &zlib_stored(&[0; 64])),
        )),
        Expect::Error(&["65535 x 65535", "limit"]),
    );
    w.json(
        "image_png_16000x16000_in_100_bytes.gltf",
        &textured(image_data_uri(
            "image/png",
            &png_raw(16000, 16000, 8, 6, &zlib_stored(&[0; 32])),
        )),
        Expect::Error(&["16000 x 16000", "of PNG data can hold"]),
    );
    fs::write(
        scenes.join("one_bit_huge.png"),
        png_raw(30000, 8000, 1, 0, &zlib_stored(&[0; 200])),
    )
    .unwrap();
    w.json(
        "image_png_1bit_external.gltf",
        &textured(json!({"uri": "one_bit_huge.png"})),
        Expect::Error(&["30000 x 8000", "of PNG data can hold"]),
    );
    w.json(
        "image_jpeg_60000x60000.gltf",
        &textured(image_data_uri("image/jpeg", &jpeg_header(60000, 60000))),
        Expect::Error(&["60000 x 60000", "limit"]),
    );
    w.json(
        "image_jpeg_16000x16000_header_only.gltf",
        &textured(image_data_uri("image/jpeg", &jpeg_header(16000, 16000))),
        Expect::Error(&["16000 x 16000", "of JPEG data can hold"]),
    );
    w.json(
        "image_bmp_header_only.gltf",
        &textured(image_data_uri("image/bmp", &bmp_header(30000, 30000))),
        Expect::Error(&["30000 x 30000"]),
    );
    w.json(
        "image_missing_file.gltf",
        &textured(json!({"uri": "nowhere.png"})),
        Expect::Error(&["missing texture image 'nowhere.png'"]),
    );
    let mut doc = textured(json!({"bufferView": 2, "mimeType": "image/png"}));
    doc["bufferViews"]
        .as_array_mut()
        .unwrap()
        .push(json!({"buffer": 0, "byteOffset": 40, "byteLength": 4096}));
    w.json(
        "image_buffer_view_past_buffer.gltf",
        &doc,
        Expect::Error(&["exceeds buffer 0"]),
    );

    // A PNG whose data stops short of its 2x2 pixels, and one labelled as a JPEG (decoders go by
    // the bytes, not by mimeType: the second one loads).
    let png = small_png();
    w.json(
        "image_png_truncated.gltf",
        &textured(image_data_uri("image/png", &png[..png.len() - 20])),
        Expect::Error(&["cannot decode texture image"]),
    );
    let mut doc = textured(json!({"bufferView": 2, "mimeType": "image/jpeg"}));
    let mut bin = tri.clone();
    bin.extend_from_slice(&png);
    doc["buffers"][0] = json!({"uri": data_uri(&bin), "byteLength": bin.len()});
    doc["bufferViews"]
        .as_array_mut()
        .unwrap()
        .push(json!({"buffer": 0, "byteOffset": 44, "byteLength": png.len()}));
    w.json("image_mime_type_lies.gltf", &doc, Expect::Loads);

    // --- binary container lies
    let mut glb_ok = triangle(None);
    glb_ok["buffers"][0] = json!({"byteLength": 44});
    let good = glb(&glb_ok, &tri);
    let mut bad = good.clone();
    let bin_at = bad.len() - 44 - 8;
    bad[bin_at..bin_at + 4].copy_from_slice(&1_000_000u32.to_le_bytes());
    w.bytes("glb_bin_chunk_past_end.glb", &bad, Expect::Error(&["BIN chunk"]));
    let mut bad = good.clone();
    bad[8..12].copy_from_slice(&1_000_000_000u32.to_le_bytes());
    w.bytes("glb_length_lies.glb", &bad, Expect::Error(&[]));
    let mut bad = good.clone();
    bad[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
    w.bytes("glb_json_chunk_past_end.glb", &bad, Expect::Error(&[]));
    let mut big = glb_ok.clone();
    big["buffers"][0]["byteLength"] = json!(1u64 << 40);
    w.bytes(
        "glb_buffer_byte_length_1tb.glb",
        &glb(&big, &tri),
        Expect::Error(&["byteLength"]),
    );
    w.bytes("glb_truncated_header.glb", &good[..10], Expect::Error(&[]));
    w.bytes(
        "glb_without_magic.glb",
        b"{\"asset\": {\"version\": \"2.0\"}}",
        Expect::Error(&["no glTF magic"]),
    );
    w.bytes("empty.gltf", b"", Expect::Error(&["empty"]));

    // --- names
    let text = serde_json::to_string(&embedded_triangle())
        .unwrap()
        .replace("\"triangle\"", "\"tri@@angle\"");
    let mut raw = text.into_bytes();
    let at = raw.windows(2).position(|b| b == b"@@").unwrap();
    raw.splice(at..at + 2, [0xff, 0xfe, 0xc0, 0x80]);
    w.bytes("name_not_utf8.gltf", &raw, Expect::Error(&["UTF-8"]));
    let text = serde_json::to_string(&embedded_triangle())
        .unwrap()
        .replace("\"triangle\"", "\"tri\\udc00angle\"");
    w.bytes(
        "name_lone_surrogate.gltf",
        text.as_bytes(),
        Expect::Error(&["surrogate"]),
    );
    // A name trying to forge a second error line: the message stays on one line.
    let mut doc = embedded_triangle();
    doc["materials"][0]["name"] = json!("evil\nicrender: error: forged line\r\n");
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 9});
    w.json(
        "name_forging_an_error_line.gltf",
        &doc,
        Expect::Error(&["baseColorTexture 9 out of range"]),
    );
    // Safe behaviour: control characters, escapes, NUL, right-to-left marks and a 100 kB name
    // are only names; the scene loads and renders.
    let mut doc = embedded_triangle();
    doc["nodes"][0]["name"] = json!("nul\u{0}inside \u{1b}[31mred\u{1b}[0m \u{202e}txt.exe");
    doc["materials"][0]["name"] = json!("x".repeat(100_000));
    doc["nodes"][1]["name"] = json!("line\nbreak");
    w.json("names_control_characters.gltf", &doc, Expect::Loads);

    // --- warnings a file can multiply: summarised, the scene still loads
    let mut doc = embedded_triangle();
    let mut prims: Vec<Value> = (0..5000)
        .map(|_| json!({"attributes": {"POSITION": 0}, "mode": 0}))
        .collect();
    prims.push(doc["meshes"][0]["primitives"][0].clone());
    doc["meshes"][0]["primitives"] = json!(prims);
    w.json("warnings_5000_skipped_primitives.gltf", &doc, Expect::Loads);
    // Legitimate relative references inside the folder load.
    w.json(
        "inside_references.gltf",
        &triangle(Some("sub/../tri.bin")),
        Expect::Loads,
    );
    let mut doc = triangle(Some("tri.bin"));
    doc["images"] = json!([{"uri": "tex.png"}]);
    doc["textures"] = json!([{"source": 0}]);
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
    w.json("inside_texture.gltf", &doc, Expect::Loads);

    w.cases
}

/// See "instancing_1e12_triangles.glb" above.
fn instancing_bomb() -> Vec<u8> {
    const TRIANGLES: u64 = 10_000;
    const PRIMITIVES: u64 = 1_000;
    const NODES: u64 = 100_000;
    let mut bin = tri_bin()[..36].to_vec();
    let indices: Vec<u8> = (0..TRIANGLES * 3).map(|i| (i % 3) as u8).collect();
    bin.extend_from_slice(&indices);
    let prims: Vec<Value> = (0..PRIMITIVES)
        .map(|_| json!({"attributes": {"POSITION": 0}, "indices": 1}))
        .collect();
    let mut nodes: Vec<Value> = (0..NODES).map(|_| json!({"mesh": 0})).collect();
    nodes.push(json!({"translation": [0.3, 0.3, 1.0], "extensions": {"KHR_lights_punctual": {"light": 0}}}));
    let doc = json!({
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": [{"type": "point", "intensity": 5.0}]}},
        "scene": 0,
        "scenes": [{"nodes": (0..=NODES).collect::<Vec<_>>()}],
        "nodes": nodes,
        "meshes": [{"primitives": prims}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5121, "count": TRIANGLES * 3, "type": "SCALAR"}
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": TRIANGLES * 3}
        ],
        "buffers": [{"byteLength": bin.len()}]
    });
    glb(&doc, &bin)
}

fn corpus() -> Corpus {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().to_path_buf();
    let cases = make_corpus(&root);
    Corpus {
        _dir: Some(dir),
        root,
        cases,
    }
}

// ---------------------------------------------------------------------------------------------
// Checks

/// Access times of the secrets, set back to an hour before their modification so that any
/// read updates them (relatime does so when atime <= mtime).
fn arm_secrets(c: &Corpus) {
    for name in ["secret.bin", "secret.png"] {
        let path = c.secret(name);
        let mtime = fs::metadata(&path).unwrap().modified().unwrap();
        let file = fs::File::options().write(true).open(&path).unwrap();
        file.set_times(
            fs::FileTimes::new()
                .set_accessed(mtime - Duration::from_secs(3600))
                .set_modified(mtime),
        )
        .unwrap();
    }
}

fn accessed(path: &Path) -> SystemTime {
    fs::metadata(path).unwrap().accessed().unwrap()
}

fn render_args<'a>(scene: &'a str, out: &'a str) -> Vec<&'a str> {
    vec![
        "render",
        scene,
        "-o",
        out,
        "-x",
        "8",
        "-y",
        "8",
        "-ad",
        "16",
        "--no-preview",
    ]
}

/// Checks a run that must fail: its exit, its single error line, and that it wrote nothing.
fn check_failure(what: &str, file: &str, result: &Output, mention: &[&str], out: &Path) {
    let err = stderr(result);
    assert!(
        result.status.code().is_some(),
        "{what}: killed by a signal ({:?})\n{err}",
        result.status
    );
    assert!(!result.status.success(), "{what}: succeeded, expected an error\n{err}");
    assert!(!err.contains("panicked"), "{what}: panic\n{err}");
    let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("icrender: error:")).collect();
    assert_eq!(errors.len(), 1, "{what}: expected exactly one error line, got:\n{err}");
    assert!(
        err.lines().all(|l| l.starts_with("icrender: ")),
        "{what}: stray output on stderr:\n{err}"
    );
    let line = errors[0];
    assert!(line.contains(file), "{what}: the error does not name the file: {line}");
    for word in mention {
        assert!(line.contains(word), "{what}: the error should mention {word:?}: {line}");
    }
    assert!(line.len() < 1200, "{what}: error line of {} bytes", line.len());
    assert!(!out.exists(), "{what}: output written");
    assert!(!out.with_extension("png").exists(), "{what}: preview written");
}

fn check_case(c: &Corpus, case: &Case, work: &Path) -> String {
    let scene = c.scenes().join(&case.file);
    let scene_s = scene.to_str().unwrap();
    let out = work.join(format!("{}.exr", case.file));
    let out_s = out.to_str().unwrap();
    let run = |args: &[&str]| {
        let mut cmd = std::process::Command::new(binary());
        cmd.args(args);
        if let Some(mb) = case.memory_limit_mb {
            cmd.env("ICRENDER_MAX_SCENE_MEMORY_MB", mb);
        }
        cmd.output().expect("icrender runs")
    };
    match case.expect {
        Expect::Error(mention) => {
            let result = run(&render_args(scene_s, out_s));
            check_failure(&format!("render {}", case.file), &case.file, &result, mention, &out);
            let info = run(&["info", scene_s]);
            check_failure(&format!("info {}", case.file), &case.file, &info, mention, &out);
            assert!(
                stdout(&info).is_empty(),
                "info {} printed:\n{}",
                case.file,
                stdout(&info)
            );
            stderr(&result).lines().last().unwrap().to_string()
        }
        Expect::Loads => {
            let result = run(&render_args(scene_s, out_s));
            let err = stderr(&result);
            assert!(
                result.status.success(),
                "render {}: expected to load:\n{err}",
                case.file
            );
            assert!(
                err.lines().count() <= 110,
                "render {}: {} lines on stderr",
                case.file,
                err.lines().count()
            );
            let image = read_exr(&out);
            for (name, data) in &image.channels {
                assert!(data.iter().all(|v| v.is_finite()), "{}: non-finite {name}", case.file);
            }
            let info = run(&["info", scene_s]);
            assert!(info.status.success(), "info {}:\n{}", case.file, stderr(&info));
            format!("{}: loads", case.file)
        }
    }
}

/// The files run through the real binary, `render` and `info` each (at least 25 failing ones,
/// covering every kind of hostile input the issue lists, and two that load). The other
/// variants go through the same loader in this process: an icrender process costs about 0.4 s
/// of CPU time before main() (the dynamic linker resolving 268 shared libraries), which would
/// make this test take minutes on two cores.
const THROUGH_THE_BINARY: &[&str] = &[
    "out_buffer_dotdot.gltf",
    "out_buffer_percent_encoded.gltf",
    "out_buffer_absolute.gltf",
    "out_buffer_file_uri.gltf",
    "out_buffer_symlink.gltf",
    "out_image_dotdot.gltf",
    "out_image_symlink.gltf",
    "out_glb_buffer_dotdot.glb",
    "out_buffer_etc_passwd.gltf",
    "out_buffer_nul_byte.gltf",
    "in_buffer_fifo.gltf",
    "data_uri_shorter_than_declared.gltf",
    "data_uri_megabyte_lie.gltf",
    "accessor_past_buffer_view.gltf",
    "buffer_view_past_buffer.gltf",
    "index_past_vertex_count.gltf",
    "stride_smaller_than_element.gltf",
    "stride_max_past_view.gltf",
    "cycle.gltf",
    "dag_exponential.gltf",
    "accessor_count_1e12.gltf",
    "instancing_1e12_triangles.glb",
    "image_png_65535x65535.gltf",
    "image_jpeg_16000x16000_header_only.gltf",
    "nodes_nested_5000_deep.gltf",
    "json_nested_100000_deep.gltf",
    "name_not_utf8.gltf",
    "name_forging_an_error_line.gltf",
    "glb_bin_chunk_past_end.glb",
    "images_naming_one_file_2000_times.gltf",
    "memory_limit_1_mib.gltf",
    "names_control_characters.gltf",
    "warnings_5000_skipped_primitives.gltf",
];

fn through_the_binary(case: &Case) -> bool {
    THROUGH_THE_BINARY.contains(&case.file.as_str())
}

/// The same expectations, checked on `Scene::load` in this process (the loader behind both
/// commands): the error names the file and is one line.
fn check_in_process(c: &Corpus, case: &Case, _work: &Path) -> String {
    let scene = c.scenes().join(&case.file);
    let result = Scene::load(&scene, &LoadOptions::default());
    match (&case.expect, result) {
        (Expect::Error(mention), Err(e)) => {
            assert_eq!(e.path, scene, "{}: error names another file", case.file);
            assert!(
                !e.message.contains('\n') && !e.message.contains('\r'),
                "{}: message on more than one line: {:?}",
                case.file,
                e.message
            );
            for word in mention.iter() {
                assert!(
                    e.message.contains(word),
                    "{}: should mention {word:?}: {}",
                    case.file,
                    e.message
                );
            }
            format!("{} (in process): {}", case.file, e.message)
        }
        (Expect::Error(_), Ok(_)) => panic!("{}: loaded, expected an error", case.file),
        (Expect::Loads, Ok(loaded)) => {
            assert!(loaded.triangle_count() > 0, "{}: no triangles", case.file);
            format!("{} (in process): loads", case.file)
        }
        (Expect::Loads, Err(e)) => panic!("{}: expected to load: {e}", case.file),
    }
}

fn check_any(c: &Corpus, case: &Case, work: &Path) -> String {
    if through_the_binary(case) {
        check_case(c, case, work)
    } else {
        check_in_process(c, case, work)
    }
}

/// Runs every case on a few threads (each run is a process of its own).
fn run_all(c: &Corpus, work: &Path, cases: &[&Case], check: impl Fn(&Corpus, &Case, &Path) -> String + Sync) {
    let threads = 4;
    let lines: Vec<String> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                let check = &check;
                s.spawn(move || {
                    cases
                        .iter()
                        .skip(t)
                        .step_by(threads)
                        .map(|case| check(c, case, work))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles.into_iter().flat_map(|h| h.join().unwrap()).collect()
    });
    for l in lines {
        eprintln!("{l}");
    }
}

#[test]
fn corpus_is_large_enough() {
    let c = corpus();
    let binary_errors = c
        .cases
        .iter()
        .filter(|k| matches!(k.expect, Expect::Error(_)) && through_the_binary(k))
        .count();
    assert!(
        binary_errors >= 25,
        "only {binary_errors} failing files go through the binary"
    );
    assert!(c.cases.iter().filter(|k| k.reads_with_flag.is_some()).count() >= 10);
    for name in THROUGH_THE_BINARY {
        assert!(c.cases.iter().any(|k| k.file == *name), "{name} is not in the corpus");
    }
    // An environment variable can only be given to a process of its own.
    for k in &c.cases {
        assert!(k.memory_limit_mb.is_none() || through_the_binary(k), "{}", k.file);
    }
}

#[test]
fn hostile_files_fail_cleanly_and_read_nothing_outside() {
    let c = corpus();
    let work = tempfile::tempdir().unwrap();
    arm_secrets(&c);
    let before: Vec<SystemTime> = ["secret.bin", "secret.png"]
        .iter()
        .map(|s| accessed(&c.secret(s)))
        .collect();
    let cases: Vec<&Case> = c.cases.iter().collect();
    run_all(&c, work.path(), &cases, check_any);
    let after: Vec<SystemTime> = ["secret.bin", "secret.png"]
        .iter()
        .map(|s| accessed(&c.secret(s)))
        .collect();
    assert_eq!(before, after, "a secret outside the scene folder was read");
    // Nothing but the expected EXRs of the loading cases was written.
    let written: Vec<String> = fs::read_dir(work.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    let loads = c
        .cases
        .iter()
        .filter(|k| matches!(k.expect, Expect::Loads) && through_the_binary(k))
        .count();
    assert_eq!(written.len(), loads, "unexpected files: {written:?}");
}

/// The same files load with --allow-outside-refs, and the secret's access time shows the read:
/// the check of the other test can see a read when there is one. Two go through the binary (the
/// option's path to the loader), the others through `Scene::load` in this process.
#[test]
fn outside_references_load_with_the_flag_and_the_read_is_seen() {
    let c = corpus();
    let cases: Vec<&Case> = c.cases.iter().filter(|k| k.reads_with_flag.is_some()).collect();
    // Whether this file system records reads (relatime does for an atime older than mtime).
    arm_secrets(&c);
    let probe = c.secret("secret.bin");
    let t0 = accessed(&probe);
    let _ = fs::read(&probe).unwrap();
    let atime_works = accessed(&probe) != t0;
    if !atime_works {
        eprintln!("note: access times are not updated here; only the outcome with the flag is checked");
    }
    let allow = LoadOptions {
        allow_outside_refs: true,
        ..LoadOptions::default()
    };
    for case in cases {
        let secret = c.secret(case.reads_with_flag.unwrap());
        let scene = c.scenes().join(&case.file);
        arm_secrets(&c);
        // (Without the flag every one of these fails without touching the secret: checked by
        // hostile_files_fail_cleanly_and_read_nothing_outside.)
        let t0 = accessed(&secret);
        if ["out_buffer_dotdot.gltf", "out_image_symlink.gltf"].contains(&case.file.as_str()) {
            let allowed = run(&["info", "--json", scene.to_str().unwrap(), "--allow-outside-refs"]);
            assert!(
                allowed.status.success(),
                "{}: with --allow-outside-refs:\n{}",
                case.file,
                stderr(&allowed)
            );
            let info: Value = serde_json::from_str(&stdout(&allowed)).unwrap();
            assert_eq!(info["triangles"], json!(1), "{}", case.file);
        } else {
            let loaded = Scene::load(&scene, &allow).unwrap_or_else(|e| panic!("{}: with the flag: {e}", case.file));
            assert_eq!(loaded.triangle_count(), 1, "{}", case.file);
        }
        if atime_works {
            assert_ne!(
                accessed(&secret),
                t0,
                "{}: read the secret but the test did not see it",
                case.file
            );
        }
    }
}

/// Writes the corpus into $HOSTILE_CORPUS_DIR (for fuzzing seeds; see docs/FUZZING.md).
#[test]
#[ignore]
fn write_corpus() {
    let dir = PathBuf::from(std::env::var("HOSTILE_CORPUS_DIR").expect("set HOSTILE_CORPUS_DIR"));
    fs::create_dir_all(&dir).unwrap();
    let cases = make_corpus(&dir);
    eprintln!("{} files in {}", cases.len(), dir.join("scenes").display());
}

/// A glTF camera with impossible values (zero or infinite field of view, a singular node
/// transform) is refused with one line that names the scene file.
#[test]
fn bad_gltf_cameras_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let cameras = [
        (
            "camera_yfov_zero.gltf",
            json!({"type": "perspective", "perspective": {"yfov": 0.0, "znear": 0.1}}),
            json!({}),
        ),
        (
            "camera_yfov_inf.gltf",
            json!({"type": "perspective", "perspective": {"yfov": 1e300, "znear": 0.1}}),
            json!({}),
        ),
        (
            "camera_ortho_zero.gltf",
            json!({"type": "orthographic", "orthographic": {"xmag": 0.0, "ymag": 0.0, "znear": 0.0, "zfar": 1.0}}),
            json!({}),
        ),
        (
            "camera_singular_node.gltf",
            json!({"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}}),
            json!({"scale": [0, 0, 0]}),
        ),
    ];
    for (file, camera, node) in cameras {
        let mut doc = embedded_triangle();
        doc["cameras"] = json!([camera]);
        let mut node = node;
        node["camera"] = json!(0);
        node["translation"] = json!([0.3, 0.3, 3.0]);
        doc["nodes"].as_array_mut().unwrap().push(node);
        doc["scenes"][0]["nodes"].as_array_mut().unwrap().push(json!(2));
        let scene = dir.path().join(file);
        fs::write(&scene, serde_json::to_vec(&doc).unwrap()).unwrap();
        let out = dir.path().join("out.exr");
        let result = run(&render_args(scene.to_str().unwrap(), out.to_str().unwrap()));
        check_failure(&format!("render {file}"), file, &result, &["camera"], &out);
    }
}

// ---------------------------------------------------------------------------------------------
// Fuzzing regressions: inputs the fuzz targets (fuzz/, docs/FUZZING.md) flagged, kept under
// tests/hostile/ as fuzz-TARGET-*.bin|.gltf|.glb exactly as the fuzzer wrote them.

fn fuzz_inputs(target: &str) -> Vec<(String, Vec<u8>)> {
    let dir = project_dir().join("tests/hostile");
    let mut out: Vec<(String, Vec<u8>)> = fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p.file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with(&format!("fuzz-{target}-"))
        })
        .map(|p| {
            (
                p.file_name().unwrap().to_string_lossy().into_owned(),
                fs::read(&p).unwrap(),
            )
        })
        .collect();
    out.sort();
    out
}

/// Every scene input the loader's fuzzer ever crashed on loads or fails cleanly now.
#[test]
fn fuzz_scene_load_regressions() {
    let dir = tempfile::tempdir().unwrap();
    for (name, bytes) in fuzz_inputs("scene_load") {
        let ext = if bytes.starts_with(b"glTF") { "glb" } else { "gltf" };
        let scene = dir.path().join(format!("input.{ext}"));
        fs::write(&scene, &bytes).unwrap();
        let result = run(&["info", scene.to_str().unwrap()]);
        let err = stderr(&result);
        assert!(result.status.code().is_some(), "{name}: killed by a signal\n{err}");
        assert!(!err.contains("panicked"), "{name}: panic\n{err}");
        if !result.status.success() {
            let errors = err.lines().filter(|l| l.starts_with("icrender: error:")).count();
            assert_eq!(errors, 1, "{name}: expected one error line:\n{err}");
        }
    }
}

/// The records target's first finding (not a crash): the old `decode_work` took [1, tile (4
/// bytes)] followed by anything. Every message is now read exactly: the input's trailing bytes
/// after a valid work message (of today's codec) are refused, as is the old layout itself. The
/// input is the fuzzer's: byte 0 selected decode_work, byte 1 was the target's flag.
#[test]
fn fuzz_records_decode_work_refuses_trailing_bytes() {
    use icrender::parallel::protocol::{Kind, Message, Records};
    for (name, bytes) in fuzz_inputs("records") {
        if name.contains("decode_work") {
            let old = &bytes[2..];
            let tag = Kind::Work.for_thread(0);
            assert!(
                Message::decode(tag, old).is_err(),
                "{name}: the old layout was accepted"
            );
            let trailing = &old[5..];
            assert!(!trailing.is_empty(), "{name}: the input has no trailing bytes");
            let work = Message::Work {
                thread: 0,
                tile: Some(u32::from_le_bytes(old[1..5].try_into().unwrap())),
                records: Records::default(),
            };
            let padded = [work.encode(), trailing.to_vec()].concat();
            assert!(
                Message::decode(tag, &padded).is_err(),
                "{name}: {padded:?} was accepted"
            );
        }
    }
}

/// The cache_file target's finding (not a crash): a damaged record just before a torn tail is
/// kept (counted corrupt) by the first open, then taken for a torn write and cut by the next
/// open, so a file shrinks over two opens and the two reports disagree. No valid record is
/// lost. The input is the fuzzer's: byte 0 is the target's flag, then the file.
#[test]
fn fuzz_cache_file_reopen_cuts_nothing_more() {
    use icrender::irradiance::persist::CacheFile;
    const SETTINGS: &str = "-aa 0.1 -ar 64 -ad 512 -as 0 -ab 1 -lr 8 -lw 0.001 -st 0.15";
    let dir = tempfile::tempdir().unwrap();
    for (name, bytes) in fuzz_inputs("cache_file") {
        let path = dir.path().join("cache.icc");
        fs::write(&path, &bytes[1..]).unwrap();
        let (file, first, report) = CacheFile::open(&path, SETTINGS).unwrap();
        drop(file);
        let (_, second, again) = CacheFile::open(&path, SETTINGS).unwrap();
        assert_eq!(first, second, "{name}");
        assert_eq!(
            again.torn_bytes, 0,
            "{name}: the second open cut more (first: {report:?})"
        );
    }
}

//! The scene loader end to end: bytes -> a .gltf (or .glb, when the bytes start with the GLB
//! magic) in a private folder -> `Scene::load`, which runs the C++ loader (tinygltf, stb_image,
//! cpp/scene_io*.cpp) and the Rust conversion behind it. The folder also holds a small buffer and
//! a small PNG the fuzzer can refer to by name ("tri.bin", "tex.png"); copies of both sit in the
//! parent folder, so that a reference escaping the folder would find a file to read.

#![no_main]

use icrender::scene::{LoadOptions, Scene};
use libfuzzer_sys::fuzz_target;
use std::path::PathBuf;
use std::sync::OnceLock;

/// A 2x2 RGBA PNG.
const PNG_2X2: &[u8] = &[
    0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a, 0x00, 0x00, 0x00, 0x0d, 0x49, 0x48, 0x44, 0x52, 0x00, 0x00, 0x00,
    0x02, 0x00, 0x00, 0x00, 0x02, 0x08, 0x06, 0x00, 0x00, 0x00, 0x72, 0xb6, 0x0d, 0x24, 0x00, 0x00, 0x00, 0x12, 0x49,
    0x44, 0x41, 0x54, 0x78, 0xda, 0x63, 0xf8, 0xcf, 0xc0, 0xf0, 0x1f, 0x0c, 0x81, 0x34, 0x18, 0x00, 0x00, 0x49, 0xc8,
    0x09, 0xf7, 0x03, 0xd9, 0x64, 0xf1, 0x00, 0x00, 0x00, 0x00, 0x49, 0x45, 0x4e, 0x44, 0xae, 0x42, 0x60, 0x82,
];

struct Dirs {
    gltf: PathBuf,
    glb: PathBuf,
}

fn dirs() -> &'static Dirs {
    static DIRS: OnceLock<Dirs> = OnceLock::new();
    DIRS.get_or_init(|| {
        let root = std::env::temp_dir().join(format!("icrender-fuzz-scene-{}", std::process::id()));
        let dir = root.join("scene");
        std::fs::create_dir_all(&dir).expect("temp dir");
        // One triangle (3 float VEC3) and its indices, as "tri.bin"; a texture as "tex.png".
        let mut bin = Vec::new();
        for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
            bin.extend_from_slice(&v.to_le_bytes());
        }
        for i in [0u16, 1, 2, 0] {
            bin.extend_from_slice(&i.to_le_bytes());
        }
        std::fs::write(dir.join("tri.bin"), &bin).expect("write bin");
        std::fs::write(dir.join("tex.png"), PNG_2X2).expect("write png");
        // Outside the folder: same names, so a "../tri.bin" that were followed would load.
        std::fs::write(root.join("tri.bin"), &bin).expect("write outside bin");
        std::fs::write(root.join("tex.png"), PNG_2X2).expect("write outside png");
        Dirs {
            gltf: dir.join("fuzz.gltf"),
            glb: dir.join("fuzz.glb"),
        }
    })
}

fuzz_target!(|data: &[u8]| {
    let d = dirs();
    let path = if data.starts_with(b"glTF") { &d.glb } else { &d.gltf };
    std::fs::write(path, data).expect("write scene");
    let _ = Scene::load(path, &LoadOptions::default());
});

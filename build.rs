//! Build script: finds the system Embree (4 if its headers exist, else 3), generates Rust
//! bindings for it and for our own C ABI in `ffi/`, and compiles the thin C++ layer in `cpp/`
//! against the Debian packages of tinygltf, stb, nlohmann-json and OpenImageIO.

use std::env;
use std::path::{Path, PathBuf};
use std::process::Command;

fn main() {
    for watched in ["ffi", "cpp", "build.rs"] {
        println!("cargo:rerun-if-changed={watched}");
    }
    println!("cargo:rerun-if-env-changed=EMBREE_DIR");
    println!("cargo::rustc-check-cfg=cfg(embree4)");

    let out = PathBuf::from(env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    let embree = find_embree();
    generate_embree_bindings(&embree, &out);
    generate_abi_bindings(&out);
    compile_cpp(&out);
    bake_denoiser_folder();
}

/// The folder scripts/install-deps.sh unpacks Open Image Denoise into. The binary opens the
/// denoiser at run time, only for `--denoise` (src/sys/oidn.rs), so it is not linked: the
/// build only records where the library is, as an absolute path, the way an rpath would, and
/// a build on a machine without it still succeeds (everything but `--denoise` works).
fn bake_denoiser_folder() {
    let manifest = PathBuf::from(env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let folder = manifest.join("third_party").join("oidn").join("lib");
    println!("cargo:rustc-env=ICRENDER_OIDN_DIR={}", folder.display());
}

struct Embree {
    include_dir: PathBuf,
    version4: bool,
}

/// Embree 4 changed the ray query API (no intersect context), so the Rust wrapper needs to know
/// which one it talks to; we prefer 4 where both are installed.
fn find_embree() -> Embree {
    let mut roots: Vec<PathBuf> = Vec::new();
    if let Ok(dir) = env::var("EMBREE_DIR") {
        roots.push(Path::new(&dir).join("include"));
    }
    roots.extend(["/usr/include", "/usr/local/include", "/opt/embree/include"].map(PathBuf::from));
    for version4 in [true, false] {
        let sub = if version4 { "embree4" } else { "embree3" };
        for root in &roots {
            if root.join(sub).join("rtcore.h").is_file() {
                let lib_root = root.parent().unwrap_or(root);
                for lib in ["lib", "lib64", "lib/x86_64-linux-gnu"] {
                    println!("cargo:rustc-link-search=native={}", lib_root.join(lib).display());
                }
                println!("cargo:rustc-link-lib=dylib={sub}");
                if version4 {
                    println!("cargo:rustc-cfg=embree4");
                }
                return Embree {
                    include_dir: root.clone(),
                    version4,
                };
            }
        }
    }
    panic!(
        "Embree headers not found (looked for embree4/rtcore.h and embree3/rtcore.h in {roots:?}); \
         run scripts/install-deps.sh or set EMBREE_DIR"
    );
}

fn generate_embree_bindings(embree: &Embree, out: &Path) {
    let mut builder = bindgen::Builder::default()
        .header("ffi/embree.h")
        .clang_arg(format!("-I{}", embree.include_dir.display()))
        .allowlist_function("rtc.*")
        .allowlist_type("RTC.*")
        .allowlist_var("RTC.*")
        .default_enum_style(bindgen::EnumVariation::Consts)
        .prepend_enum_name(false)
        .derive_default(true)
        .layout_tests(false);
    if embree.version4 {
        builder = builder.clang_arg("-DICR_EMBREE4");
    }
    builder
        .generate()
        .expect("bindgen failed on the Embree header")
        .write_to_file(out.join("embree_bindings.rs"))
        .expect("writing Embree bindings");
}

fn generate_abi_bindings(out: &Path) {
    bindgen::Builder::default()
        .header("ffi/scene_io.h")
        .header("ffi/exr_chunks.h")
        .allowlist_function("icr_.*")
        .allowlist_type("icr_.*")
        .allowlist_var("ICR_.*")
        .default_enum_style(bindgen::EnumVariation::Consts)
        .layout_tests(false)
        .generate()
        .expect("bindgen failed on ffi/scene_io.h")
        .write_to_file(out.join("abi_bindings.rs"))
        .expect("writing ABI bindings");
    // The image shim is a library of its own, opened when an image is first read or written
    // (see compile_image_library): its functions come as a table loaded at run time.
    bindgen::Builder::default()
        .header("ffi/image_io.h")
        .allowlist_function("icr_.*")
        .allowlist_type("icr_.*")
        .dynamic_library_name("ImageLibrary")
        .dynamic_link_require_all(true)
        .layout_tests(false)
        .generate()
        .expect("bindgen failed on ffi/image_io.h")
        .write_to_file(out.join("image_bindings.rs"))
        .expect("writing image ABI bindings");
}

/// What pkg-config says of `package` for `arg` (e.g. `--libs-only-l`), each word without
/// `prefix` (`-l`, `-I`); None where pkg-config or the .pc file is missing.
fn pkg_config(package: &str, arg: &str, prefix: &str) -> Option<Vec<String>> {
    Command::new("pkg-config")
        .args([arg, package])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| {
            String::from_utf8_lossy(&o.stdout)
                .split_whitespace()
                .filter_map(|f| f.strip_prefix(prefix).map(String::from))
                .collect()
        })
}

/// Include directories and libraries of OpenImageIO, and of OpenEXR (whose own API copies a
/// streamed EXR's compressed tiles into the final file, cpp/image_io.cpp), from pkg-config, with
/// the Debian layout as the fallback so a machine without the .pc files still builds.
fn openimageio_flags() -> (Vec<String>, Vec<String>) {
    let mut includes = pkg_config("OpenImageIO", "--cflags-only-I", "-I").unwrap_or_default();
    let mut libs = pkg_config("OpenImageIO", "--libs-only-l", "-l").unwrap_or_else(|| vec!["OpenImageIO".into()]);
    if !libs.iter().any(|l| l == "OpenImageIO_Util") {
        libs.push("OpenImageIO_Util".into());
    }
    includes.extend(
        pkg_config("OpenEXR", "--cflags-only-I", "-I")
            .unwrap_or_else(|| vec!["/usr/include/OpenEXR".into(), "/usr/include/Imath".into()]),
    );
    libs.extend(
        pkg_config("OpenEXR", "--libs-only-l", "-l").unwrap_or_else(|| vec!["OpenEXR-3_1".into(), "Iex-3_1".into()]),
    );
    (includes, libs)
}

/// The glTF loader's translation units, one concern each (see cpp/scene_io_internal.h).
const SCENE_IO_FILES: [&str; 8] = [
    "cpp/scene_io.cpp",
    "cpp/scene_io_validate.cpp",
    "cpp/scene_io_mesh.cpp",
    "cpp/scene_io_materials.cpp",
    "cpp/scene_io_nodes.cpp",
    "cpp/scene_io_cameras.cpp",
    "cpp/scene_io_lights.cpp",
    "cpp/scene_io_animation.cpp",
];

fn compile_cpp(out: &Path) {
    let mut build = cc::Build::new();
    build
        .cpp(true)
        .std("c++17")
        .include("ffi")
        .include("/usr/include/stb")
        .files(SCENE_IO_FILES)
        .flag_if_supported("-Wno-unused-parameter")
        .flag_if_supported("-Wno-missing-field-initializers")
        .opt_level(2);
    build.compile("icrender_cpp");
    println!("cargo:rustc-link-lib=dylib=stdc++");
    compile_exr_chunks();
    compile_image_library(out);
}

/// The EXR tile encoder and chunk writer (cpp/exr_chunks.cpp), linked into the binary: OpenEXR's
/// core library needs only zlib, so every rank can encode the tiles it renders without loading
/// OpenImageIO.
fn compile_exr_chunks() {
    let mut build = cc::Build::new();
    build
        .cpp(true)
        .std("c++17")
        .include("ffi")
        .file("cpp/exr_chunks.cpp")
        .opt_level(2);
    for dir in pkg_config("OpenEXR", "--cflags-only-I", "-I").unwrap_or_else(|| vec!["/usr/include/OpenEXR".into()]) {
        build.include(dir);
    }
    build
        .flag_if_supported("-Wno-missing-field-initializers")
        .compile("icrender_exr_chunks");
    let core = pkg_config("OpenEXR", "--libs-only-l", "-l")
        .and_then(|libs| libs.into_iter().find(|l| l.starts_with("OpenEXRCore")))
        .unwrap_or_else(|| "OpenEXRCore-3_1".into());
    println!("cargo:rustc-link-lib=dylib={core}");
}

/// The OpenImageIO shim as a shared library of its own, `libicrender_image.so`, which the binary
/// opens on first use (src/sys/image_io.rs) instead of linking it. OpenImageIO pulls in about
/// 270 shared libraries (codecs, GDAL, OpenCV, ...) whose symbol binding cost every process
/// about 0.3 s of CPU at start, before main(): now only a process that reads or writes an image
/// pays it (under mpirun, rank 0), not every rank and every command.
/// It is written next to the binaries (target/<profile>/) and in OUT_DIR, where the binary looks.
fn compile_image_library(out: &Path) {
    let (oiio_includes, oiio_libs) = openimageio_flags();
    let compiler = cc::Build::new().cpp(true).get_compiler();
    let library = out.join("libicrender_image.so");
    let mut cmd = compiler.to_command();
    cmd.args(["-std=c++17", "-O2", "-fPIC", "-shared", "-Iffi"])
        .args(oiio_includes.iter().map(|d| format!("-I{d}")))
        .args(["-Wno-unused-parameter", "cpp/image_io.cpp", "-o"])
        .arg(&library)
        .args(oiio_libs.iter().map(|l| format!("-l{l}")))
        .arg("-lstdc++");
    let status = cmd.status().expect("running the C++ compiler for libicrender_image.so");
    assert!(
        status.success(),
        "compiling cpp/image_io.cpp into {} failed",
        library.display()
    );
    // OUT_DIR is target/<profile>/build/<crate>-<hash>/out: three levels up are the binaries.
    if let Some(profile_dir) = out.ancestors().nth(3) {
        let _ = std::fs::copy(&library, profile_dir.join("libicrender_image.so"));
    }
}

//! The EXR header is written for the user who opens the file: `icrender/command` is a command
//! line they can paste into a shell to render the same image again, and no attribute holds
//! Rust's debug text.

mod common;
use common::*;
use std::path::Path;
use std::process::Command;

const OPTIONS: &[&str] = &[
    "-x",
    "24",
    "-y",
    "16",
    "-ab",
    "2",
    "-aa",
    "0.25",
    "-ad",
    "32",
    "--spp",
    "2",
    "--seed",
    "7",
    "--light-samples",
    "4",
    "--direct",
    "sampled",
    "-vh",
    "50",
    "--aovs",
    "albedo,depth,crypto_object",
];

fn header(path: &Path) -> Vec<(String, String)> {
    icrender::sys::image_io::read_image_with_header(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .attributes
}

fn attribute<'a>(attributes: &'a [(String, String)], name: &str) -> &'a str {
    attributes
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, v)| v.as_str())
        .unwrap_or_else(|| panic!("no {name} in {attributes:?}"))
}

#[test]
fn the_headers_command_line_pasted_into_a_shell_renders_the_same_image() {
    let dir = tempfile::tempdir().unwrap();
    // A folder whose name a shell would split: the command must quote the scene's path.
    let scenes = dir.path().join("my scenes");
    std::fs::create_dir(&scenes).unwrap();
    let scene = scenes.join("cornell.gltf");
    std::fs::copy(project_dir().join("scenes/cornell.gltf"), &scene).unwrap();
    let first = dir.path().join("first");
    std::fs::create_dir(&first).unwrap();
    let mut args = vec![
        "render",
        scene.to_str().unwrap(),
        "-o",
        "image.exr",
        "-q",
        "--threads",
        "2",
    ];
    args.extend_from_slice(OPTIONS);
    let out = Command::new(binary()).args(&args).current_dir(&first).output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));

    let attributes = header(&first.join("image.exr"));
    let command = attribute(&attributes, "icrender/command");
    assert!(
        command.starts_with("icrender render '"),
        "the scene's path is not quoted: {command}"
    );
    for option in ["-ab 2", "--seed 7", "--direct sampled", "-vh 50", "--spp 2"] {
        assert!(command.contains(option), "{option} missing from {command}");
    }

    // Pasted as it is into a shell in another folder (where `icrender` is on the PATH), with
    // one thread: the same pixels, every layer to the bit.
    let second = dir.path().join("second");
    std::fs::create_dir(&second).unwrap();
    let path = format!(
        "{}:{}",
        binary().parent().unwrap().display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let out = Command::new("sh")
        .args(["-c", &format!("{command} -q --threads 1")])
        .env("PATH", path)
        .current_dir(&second)
        .output()
        .unwrap();
    assert!(out.status.success(), "rerunning `{command}`:\n{}", stderr(&out));
    let a = read_exr(&first.join("image.exr"));
    let b = read_exr(&second.join("image.exr"));
    assert_eq!((a.width, a.height), (b.width, b.height));
    let names = |i: &ImageData| i.channels.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>();
    assert_eq!(names(&a), names(&b));
    for (name, values) in &a.channels {
        let again = b.channel(name).unwrap();
        let differing = values
            .iter()
            .zip(again)
            .filter(|(x, y)| x.to_bits() != y.to_bits())
            .count();
        assert_eq!(differing, 0, "channel {name}: {differing} pixels differ on the rerun");
    }
    // The rerun's header names the same command (its own -q and --threads do not change the
    // image, so they are not in it).
    assert_eq!(
        attribute(&header(&second.join("image.exr")), "icrender/command"),
        command
    );
}

#[test]
fn no_header_attribute_holds_debug_text() {
    let dir = tempfile::tempdir().unwrap();
    let scene = project_dir().join("scenes/cornell.gltf");
    let mut extra = vec!["-vp", "0", "1", "3.5", "-vd", "0", "0", "-1"];
    extra.extend_from_slice(OPTIONS);
    let out = render_file(dir.path(), &scene, "view", &extra);
    let attributes = header(&out);
    let settings = attribute(&attributes, "icrender/part_settings");
    assert!(settings.contains("view -vp 0 1 3.5 -vd 0 0 -1"), "{settings}");
    for (name, value) in &attributes {
        // Statistics are JSON; every other value is plain text or numbers.
        if name == "icrender/statistics" {
            continue;
        }
        for debug in ["Args {", "Some(", "None", "Hessian", "Analytic"] {
            assert!(!value.contains(debug), "{name} holds debug text `{debug}`: {value}");
        }
    }
}

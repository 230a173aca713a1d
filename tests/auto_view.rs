//! Scenes without a camera: the automatic view stands inside an enclosure when the scene is
//! one (a building of rooms whose bounds' centre line runs through walls and the gaps between
//! rooms, as conference_x32.gltf's does), and says how to give a view when it finds nothing lit.

mod common;
use common::*;
use std::path::{Path, PathBuf};

/// A closed grey room from `lo` to `hi` with a lamp (an emissive square facing down) under
/// its ceiling's centre.
fn room(b: &mut GltfBuilder, lo: [f32; 3], hi: [f32; 3]) {
    let grey = b.material(lambertian("wall", [0.6; 3]));
    let lamp = b.material(emissive_lambertian("lamp", [0.0; 3], 5.0));
    inward_box(b, lo, hi, grey);
    let (cx, cz, y) = ((lo[0] + hi[0]) / 2.0, (lo[2] + hi[2]) / 2.0, hi[1] - 0.05);
    let s = 0.5;
    b.quad(
        facing(
            [
                [cx - s, y, cz - s],
                [cx + s, y, cz - s],
                [cx + s, y, cz + s],
                [cx - s, y, cz + s],
            ],
            [cx, 0.0, cz],
        ),
        Some(lamp),
    );
}

fn render_without_camera(dir: &Path, scene: &Path, name: &str) -> (ImageData, String) {
    let out = dir.join(format!("{name}.exr"));
    let result = run_ok(&[
        "render",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--no-preview",
        "-x",
        "32",
        "-y",
        "32",
        "-ab",
        "0",
        "--emission-samples",
        "0",
    ]);
    (read_exr(&out), stderr(&result))
}

/// Two closed rooms side by side, 2 units apart: the bounds' centre line lies in the gap
/// between them and every eye on it, or outside the building, sees only unlit outer walls.
#[test]
fn a_building_without_a_camera_is_seen_from_inside_a_room() {
    let dir = tempfile::tempdir().unwrap();
    let mut b = GltfBuilder::new();
    room(&mut b, [0.0, 0.0, 0.0], [4.0, 3.0, 10.0]);
    room(&mut b, [6.0, 0.0, 0.0], [10.0, 3.0, 10.0]);
    let scene: PathBuf = b.write(dir.path(), "building");
    let (image, err) = render_without_camera(dir.path(), &scene, "building");
    let composite = rgb(&image, "");
    let lit = composite[1].iter().filter(|&&v| v > 1e-3).count();
    // From inside a room the walls and floor fill the frame and the lamp lights them; only the
    // ceiling (lit by no direct light at -ab 0) stays dark.
    assert!(
        lit as f64 >= 0.5 * composite[1].len() as f64,
        "{lit} of {} pixels lit:\n{err}",
        composite[1].len()
    );
    assert!(!err.contains("little lit surface"), "{err}");
}

/// A room whose only light is sealed in a small closed box: no view sees anything lit, and the
/// warning says so and how to give a view.
#[test]
fn a_dark_automatic_view_is_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    let mut b = GltfBuilder::new();
    let grey = b.material(lambertian("wall", [0.6; 3]));
    inward_box(&mut b, [0.0, 0.0, 0.0], [10.0, 3.0, 10.0], grey);
    room(&mut b, [2.0, 0.1, 2.0], [3.0, 0.6, 3.0]);
    let scene = b.write(dir.path(), "sealed");
    let (image, err) = render_without_camera(dir.path(), &scene, "sealed");
    assert!(mean(&rgb(&image, "")[1]) < 1e-3, "the room should be dark");
    let warning = err
        .lines()
        .find(|l| l.contains("little lit surface"))
        .unwrap_or_else(|| panic!("no warning:\n{err}"));
    for word in ["sealed.gltf", "no camera", "-vp", "bounds"] {
        assert!(warning.contains(word), "the warning should mention {word:?}: {warning}");
    }
}

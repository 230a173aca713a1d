//! The third-party scenes beside the project load and render without NaN or Inf.

mod common;
use common::*;

fn render_shared(relative: &str, extra: &[&str]) -> ImageData {
    let scene = shared_scene(relative);
    assert!(
        scene.exists(),
        "{} is missing (shared/ must sit beside the project)",
        scene.display()
    );
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.exr");
    let mut args = vec![
        "render",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "-q",
        "--no-preview",
    ];
    args.extend_from_slice(extra);
    run_ok(&args);
    let image = read_exr(&out);
    for (name, data) in &image.channels {
        assert!(
            data.iter().all(|v| v.is_finite()),
            "{relative}: non-finite value in {name}"
        );
        assert!(
            data.iter().all(|v| *v >= 0.0 || may_be_negative(name)),
            "{relative}: negative value in {name}"
        );
    }
    image
}

#[test]
fn cornell_box_original() {
    let image = render_shared(
        "cornell_box/CornellBox-Original.gltf",
        &["-x", "32", "-y", "32", "-ad", "16"],
    );
    assert!(mean(&rgb(&image, "")[0]) > 0.0);
    // Lambertian obj2gltf walls: no specular rays, so no specular layer.
    assert!(image.channel("specular.R").is_none());
}

#[test]
fn conference_room_331k_triangles() {
    let image = render_shared("conference_room/conference.gltf", &["-x", "32", "-y", "24", "-ad", "4"]);
    assert!(
        mean(&rgb(&image, "")[0]) > 0.0,
        "the automatic view should see the lit room"
    );
}

#[test]
fn sibenik_with_textures_and_point_lights() {
    let image = render_shared("sibenik_cathedral/sibenik.gltf", &["-x", "32", "-y", "24", "-ad", "4"]);
    assert!(mean(&rgb(&image, "direct")[0]) > 0.0);
    // Point lights only: nothing emissive to see.
    assert!(image.channel("emission.R").is_none());
}

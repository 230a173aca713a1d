//! Animated scenes through the real binary: meshes and lights moved by glTF animations and
//! rendered with `--frames`, each frame against the still render of its pose (a file that
//! places the mesh or light by hand where the animation puts it): the moved mesh leaves no
//! ghost in the indirect light where it was, a moved light's indirect light follows it, where
//! the moves do not reach the frames are the same pixels (the records there are kept), and
//! what cannot be animated is refused with one line.

mod common;
use common::*;
use serde_json::{Value, json};
use std::path::{Path, PathBuf};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A hall (12 x 3 x 12, grey) lit by a ceiling panel over its middle, a camera at the front
/// looking in, and a crate that the animation `push` slides along the floor near the back-left
/// corner, from x = -4.5 at t = 0 to x = -2.5 at t = 1. `crate_at` instead places it still at
/// that x (and no animation).
fn hall(dir: &Path, name: &str, crate_at: Option<f32>) -> PathBuf {
    hall_with(dir, name, crate_at, Crate::SMALL)
}

/// The crate: its side and its albedo.
#[derive(Clone, Copy)]
struct Crate {
    side: f32,
    albedo: f32,
}

impl Crate {
    /// White, half a metre.
    const SMALL: Crate = Crate { side: 0.5, albedo: 0.9 };
    /// Dark and nearly a metre: it darkens the floor round it by more than a fifth (and bounces
    /// little light), an effect well above the records' noise.
    const DARK: Crate = Crate {
        side: 0.9,
        albedo: 0.05,
    };
}

fn hall_with(dir: &Path, name: &str, crate_at: Option<f32>, kind: Crate) -> PathBuf {
    let mut b = GltfBuilder::new();
    let grey = b.material(lambertian("grey", [0.6, 0.6, 0.6]));
    inward_box(&mut b, [-6.0, 0.0, -6.0], [6.0, 3.0, 6.0], grey);
    let lamp = b.material(emissive_lambertian("lamp", [1.0; 3], 8.0));
    b.quad(
        facing(
            [
                [-1.0, 2.95, -1.0],
                [1.0, 2.95, -1.0],
                [1.0, 2.95, 1.0],
                [-1.0, 2.95, 1.0],
            ],
            [0.0, 0.0, 0.0],
        ),
        Some(lamp),
    );
    let camera = b.perspective_camera(1.1);
    b.node(json!({"name": "cam", "camera": camera, "translation": [0.0, 1.6, 5.5]}));
    let paint = b.material(lambertian("paint", [kind.albedo; 3]));
    let cube = crate_mesh(&mut b, paint, kind.side);
    match crate_at {
        Some(x) => {
            b.node(json!({"name": "crate", "mesh": cube, "translation": [x, 0.0, -4.0]}));
        }
        None => {
            let node = b.node(json!({"name": "crate", "mesh": cube, "translation": [-4.5, 0.0, -4.0]}));
            b.animation(
                "push",
                &[(
                    node,
                    "translation",
                    "LINEAR",
                    &[0.0, 1.0],
                    &[-4.5, 0.0, -4.0, -2.5, 0.0, -4.0],
                )],
            );
        }
    }
    b.write(dir, name)
}

/// A closed cube of side `side` standing on y = 0 around the node's origin, faces outwards.
fn crate_mesh(b: &mut GltfBuilder, material: usize, side: f32) -> usize {
    let (h, t) = (side / 2.0, side);
    let p = |x: f32, y: f32, z: f32| [x * h, y * t, z * h];
    let corners = [
        p(-1.0, 0.0, -1.0),
        p(1.0, 0.0, -1.0),
        p(1.0, 1.0, -1.0),
        p(-1.0, 1.0, -1.0),
        p(-1.0, 0.0, 1.0),
        p(1.0, 0.0, 1.0),
        p(1.0, 1.0, 1.0),
        p(-1.0, 1.0, 1.0),
    ];
    // Counter-clockwise seen from outside.
    let faces: [[u32; 4]; 6] = [
        [0, 3, 2, 1],
        [4, 5, 6, 7],
        [0, 4, 7, 3],
        [1, 2, 6, 5],
        [3, 7, 6, 2],
        [0, 1, 5, 4],
    ];
    let indices: Vec<[u32; 3]> = faces
        .iter()
        .flat_map(|f| [[f[0], f[1], f[2]], [f[0], f[2], f[3]]])
        .collect();
    b.mesh(&corners, &indices, Some(material))
}

const SIZE: [&str; 6] = ["-x", "64", "-y", "48", "--aovs", "albedo"];

fn render(scene: &Path, extra: &[&str]) {
    let mut args = vec!["render", s(scene), "-q", "--no-preview"];
    args.extend_from_slice(&SIZE);
    args.extend_from_slice(extra);
    run_ok(&args);
}

fn stats_of(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Per pixel, the luminance-ish sum of a layer's three channels.
fn sums(image: &ImageData, layer: &str) -> Vec<f64> {
    let [r, g, b] = rgb(image, layer);
    (0..r.len()).map(|i| (r[i] + g[i] + b[i]) as f64).collect()
}

#[test]
fn a_moved_mesh_leaves_no_ghost_and_its_frame_is_the_still_render_of_its_pose() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = hall_with(d, "push", None, Crate::DARK);
    // Frames 0-4 at 4 fps: t = 0 to 1, the crate 0.5 further each frame.
    let out = d.join("seq.####.exr");
    let stats = d.join("seq.####.json");
    render(
        &scene,
        &["--frames", "0-4", "--fps", "4", "-o", s(&out), "--stats", s(&stats)],
    );
    let first = still(d, "first", -4.5);
    let last = still(d, "last", -2.5);
    let frame = read_exr(&d.join("seq.0004.exr"));
    // The direct light is computed afresh: the frame's is the still's, pixel for pixel.
    assert_eq!(rgb(&frame, "direct"), rgb(&last, "direct"), "direct light of frame 4");
    // Where the crate was at t = 0 and is not at t = 1, on the floor (same albedo in both
    // stills), the crate darkened the indirect light by more than a fifth: the ghost zone.
    let (a0, a1) = (sums(&first, "albedo"), sums(&last, "albedo"));
    let (i0, i1, i_seq) = (
        sums(&first, "indirect"),
        sums(&last, "indirect"),
        sums(&frame, "indirect"),
    );
    let zone: Vec<usize> = (0..i0.len())
        .filter(|&p| (a0[p] - a1[p]).abs() < 1e-6 && i0[p] < 0.8 * i1[p])
        .collect();
    assert!(zone.len() >= 10, "ghost zone of {} pixels", zone.len());
    let mean_in = |v: &[f64]| zone.iter().map(|&p| v[p]).sum::<f64>() / zone.len() as f64;
    let (ghost, gone, sequence) = (mean_in(&i0), mean_in(&i1), mean_in(&i_seq));
    eprintln!(
        "ghost zone {} pixels: indirect {ghost:.4} with the crate, {gone:.4} without, {sequence:.4} in frame 4",
        zone.len()
    );
    // The frame is the still's light there, not the light with the crate (a ghost would be):
    // at most a quarter of the crate's effect is left, where two stills of the same pose with
    // other seeds (other records) differ by less.
    let other_seed = {
        let out = d.join("still_last_seed2.exr");
        render(&d.join("still_last.gltf"), &["--seed", "2", "-o", s(&out)]);
        mean_in(&sums(&read_exr(&out), "indirect"))
    };
    eprintln!("the still with seed 2: {other_seed:.4} there");
    let effect = (ghost - gone).abs();
    assert!(
        (other_seed - gone).abs() < 0.25 * effect,
        "two stills differ by {:.4}",
        (other_seed - gone).abs()
    );
    assert!(
        (sequence - gone).abs() < 0.25 * effect,
        "frame 4's indirect light {sequence:.4} where the crate was: {gone:.4} without the crate, {ghost:.4} with it"
    );
    // And over the whole image within the cache's error of the still's.
    within_the_cache_s_error(&frame, &last, "frame 4 against its still");
    // Later frames kept records (the hall is large) and dropped some (the crate moved).
    for n in 1..=4 {
        let st = stats_of(&d.join(format!("seq.000{n}.json")));
        let (kept, dropped) = (
            st["records_before"].as_u64().unwrap(),
            st["records_invalidated"].as_u64().unwrap(),
        );
        eprintln!(
            "frame {n}: {kept} kept, {dropped} dropped, {} made",
            st["records_computed"]
        );
        assert!(kept > 0 && dropped > 0, "frame {n}: {kept} kept, {dropped} dropped");
    }
}

/// The still render of the hall with the crate at x (same size and layers as the sequence).
fn still(d: &Path, name: &str, x: f32) -> ImageData {
    let scene = hall_with(d, &format!("still_{name}"), Some(x), Crate::DARK);
    let out = d.join(format!("still_{name}.exr"));
    render(&scene, &["-o", s(&out)]);
    read_exr(&out)
}

#[test]
fn where_the_moves_do_not_reach_frames_are_the_same_pixels() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = hall(d, "push", None);
    let out = d.join("f.####.exr");
    render(&scene, &["--frames", "0-2", "--fps", "8", "-o", s(&out)]);
    let frames: Vec<ImageData> = (0..=2).map(|n| read_exr(&d.join(format!("f.000{n}.exr")))).collect();
    // The right half of the image: the hall's right wall and floor, far from the crate.
    let (w, h) = (64usize, 48usize);
    let right: Vec<usize> = (0..h).flat_map(|y| (w * 3 / 4..w).map(move |x| y * w + x)).collect();
    for k in 1..3 {
        let (a, b) = (sums(&frames[k - 1], "indirect"), sums(&frames[k], "indirect"));
        let same = right.iter().filter(|&&p| a[p] == b[p]).count();
        assert!(
            same * 10 >= right.len() * 9,
            "frames {} and {k}: {same} of {} pixels of the right quarter unchanged",
            k - 1,
            right.len()
        );
    }
}

#[test]
fn at_two_bounces_the_last_bounce_grid_keeps_the_sites_the_move_does_not_reach() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = hall(d, "push", None);
    let out = d.join("g.####.exr");
    let stats = d.join("g.####.json");
    render(
        &scene,
        &[
            "--frames",
            "0-2",
            "--fps",
            "2",
            "-ab",
            "2",
            "-o",
            s(&out),
            "--stats",
            s(&stats),
        ],
    );
    for n in 1..=2 {
        let st = stats_of(&d.join(format!("g.000{n}.json")));
        let (kept, sampled) = (
            st["last_bounce_sites_kept"].as_u64().unwrap(),
            st["last_bounce_sites_sampled"].as_u64().unwrap(),
        );
        eprintln!("frame {n}: grid sites {kept} kept, {sampled} sampled");
        assert!(kept > 0 && sampled > 0, "frame {n}: {kept} kept, {sampled} sampled");
    }
    // The last frame (the crate at x = -2.5) against its still render, which samples every site.
    let still_scene = hall(d, "still_end", Some(-2.5));
    let still = d.join("still_end.exr");
    render(&still_scene, &["-ab", "2", "-o", s(&still)]);
    let (frame, still) = (read_exr(&d.join("g.0002.exr")), read_exr(&still));
    assert_eq!(rgb(&frame, "direct"), rgb(&still, "direct"));
    within_the_cache_s_error(&frame, &still, "frame 2 against its still at -ab 2");
}

#[test]
fn a_region_of_a_moving_scene_s_frames_is_that_region_of_its_frames() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = hall(d, "push", None);
    render(
        &scene,
        &["--frames", "0-2", "--fps", "2", "-o", s(&d.join("w.####.exr"))],
    );
    // The left half's top rows, where the crate slides.
    render(
        &scene,
        &[
            "--frames",
            "0-2",
            "--fps",
            "2",
            "--region",
            "0",
            "8",
            "32",
            "40",
            "-o",
            s(&d.join("r.####.exr")),
        ],
    );
    for n in 0..=2 {
        let (whole, part) = (
            read_exr(&d.join(format!("w.000{n}.exr"))),
            read_exr(&d.join(format!("r.000{n}.exr"))),
        );
        let crop = |image: &ImageData, layer: &str| -> Vec<f32> {
            let [r, _, _] = rgb(image, layer);
            (8..40)
                .flat_map(|y| (0..32).map(move |x| (y, x)))
                .map(|(y, x)| r[y * 64 + x])
                .collect()
        };
        let [part_direct, _, _] = rgb(&part, "direct");
        assert_eq!(
            part_direct,
            crop(&whole, "direct"),
            "frame {n}: the region's direct light"
        );
        // Its records are its own: its indirect light meets the whole frame's within the cache's
        // error.
        let [part_indirect, _, _] = rgb(&part, "indirect");
        let whole_indirect = crop(&whole, "indirect");
        let e = part_indirect
            .iter()
            .zip(&whole_indirect)
            .map(|(a, b)| ((a - b) as f64).powi(2) / ((b * b) as f64 + 0.01))
            .sum::<f64>()
            / part_indirect.len() as f64;
        assert!(
            e < 2e-3,
            "frame {n}: region indirect against the whole frame's: relMSE {e:.2e}"
        );
    }
}

#[test]
fn each_frame_s_lines_say_what_the_moves_did_and_the_estimated_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = hall(d, "push", None);
    let out = d.join("l.####.exr");
    let mut args = vec![
        "render",
        s(&scene),
        "--no-preview",
        "--frames",
        "0-1",
        "--fps",
        "4",
        "-o",
        s(&out),
    ];
    args.extend_from_slice(&SIZE);
    let e = stderr(&run_ok(&args));
    let line = e
        .lines()
        .find(|l| l.starts_with("icrender: frame 1 "))
        .unwrap_or_else(|| panic!("{e}"));
    assert!(
        line.contains("records made")
            && line.contains("carried")
            && line.contains("dropped where things moved")
            && line.contains("made again where they were")
            && line.contains("estimated relMSE"),
        "{line}"
    );
}

#[test]
fn step_and_cubic_spline_keys_place_a_mesh_as_a_still_placed_by_hand() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // The crate held by STEP at its first key until t = 1, and turned by a CUBICSPLINE with zero
    // tangents from no turn to a quarter turn about +Y over t = 0..1 (at t = 0.5: an eighth).
    let keyed = |name: &str, animated: bool| {
        let mut b = small_room();
        b.point_light([0.0, 2.8, 0.0], 20.0);
        let paint = b.material(lambertian("paint", [0.8, 0.3, 0.2]));
        let cube = crate_mesh(&mut b, paint, 0.8);
        let eighth = std::f64::consts::PI / 8.0;
        if animated {
            let node = b.node(json!({"mesh": cube, "translation": [-1.0, 0.0, -1.0]}));
            let h = std::f32::consts::FRAC_PI_4;
            b.animation(
                "keys",
                &[
                    (
                        node,
                        "translation",
                        "STEP",
                        &[0.0, 1.0],
                        &[-1.0, 0.0, -1.0, 1.0, 0.0, 1.0],
                    ),
                    (
                        node,
                        "rotation",
                        "CUBICSPLINE",
                        &[0.0, 1.0],
                        &[
                            0.0,
                            0.0,
                            0.0,
                            0.0,
                            0.0,
                            0.0,
                            0.0,
                            1.0,
                            0.0,
                            0.0,
                            0.0,
                            0.0, // key 0
                            0.0,
                            0.0,
                            0.0,
                            0.0,
                            0.0,
                            h.sin(),
                            0.0,
                            h.cos(),
                            0.0,
                            0.0,
                            0.0,
                            0.0, // key 1
                        ],
                    ),
                ],
            );
        } else {
            b.node(json!({"mesh": cube, "translation": [-1.0, 0.0, -1.0],
                "rotation": [0.0, eighth.sin(), 0.0, eighth.cos()]}));
        }
        b.write(d, name)
    };
    let (animated, by_hand) = (keyed("keys", true), keyed("by_hand", false));
    // Frame 1 at 2 fps: t = 0.5.
    render(&animated, &["--frame", "1", "--fps", "2", "-o", s(&d.join("k.exr"))]);
    render(&by_hand, &["-o", s(&d.join("h.exr"))]);
    let (frame, still) = (read_exr(&d.join("k.exr")), read_exr(&d.join("h.exr")));
    // The spline's rotation and the one written by hand agree to float rounding, not bits.
    let [a, _, _] = rgb(&frame, "direct");
    let [b, _, _] = rgb(&still, "direct");
    let worst = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x - y).abs() / y.abs().max(1e-3))
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-2, "direct light differs by {worst} at worst");
    within_the_cache_s_error(&frame, &still, "frame against the still placed by hand");
}

#[test]
fn frames_of_a_still_scene_are_the_same_image() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = hall(d, "still", Some(-3.0));
    let out = d.join("s.####.exr");
    render(&scene, &["--frames", "1-3", "-o", s(&out)]);
    let first = read_exr(&d.join("s.0001.exr"));
    for n in 2..=3 {
        let other = read_exr(&d.join(format!("s.000{n}.exr")));
        assert_same_image(
            &first,
            &other,
            &["icrender/frame", "icrender/frame_time_s", "icrender/statistics"],
            &format!("frame {n}"),
        );
    }
}

#[test]
fn a_moved_light_s_indirect_light_follows_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // The hall lit by a point light that the animation `carry` moves from the left to the right.
    let lit = |name: &str, x: Option<f32>| {
        let mut b = small_room();
        let bulb = b.point_light([x.unwrap_or(-2.0), 2.0, -1.0], 40.0);
        if x.is_none() {
            b.animation(
                "carry",
                &[(
                    bulb,
                    "translation",
                    "LINEAR",
                    &[0.0, 1.0],
                    &[-2.0, 2.0, -1.0, 2.0, 2.0, -1.0],
                )],
            );
        }
        b.write(d, name)
    };
    let scene = lit("carry", None);
    render(
        &scene,
        &["--frames", "0-2", "--fps", "2", "-o", s(&d.join("l.####.exr"))],
    );
    for (n, x) in [(0, -2.0), (1, 0.0), (2, 2.0)] {
        let still_scene = lit(&format!("lit{n}"), Some(x));
        let out = d.join(format!("lit{n}.exr"));
        render(&still_scene, &["-o", s(&out)]);
        let (frame, still) = (read_exr(&d.join(format!("l.000{n}.exr"))), read_exr(&out));
        // A moved light changes every record: the frame makes each again at its point, where
        // the still places its own; the two meet within the cache's error.
        within_the_cache_s_error(&frame, &still, &format!("frame {n} against its still"));
        assert_eq!(rgb(&frame, "direct"), rgb(&still, "direct"), "frame {n}: direct light");
    }
    // And the light did move: the left half's indirect light falls from frame 0 to frame 2.
    let left_mean = |n: u32| {
        let v = sums(&read_exr(&d.join(format!("l.000{n}.exr"))), "indirect");
        (0..48)
            .flat_map(|y| (0..32).map(move |x| y * 64 + x))
            .map(|p| v[p])
            .sum::<f64>()
    };
    assert!(
        left_mean(2) < 0.8 * left_mean(0),
        "{} then {}",
        left_mean(0),
        left_mean(2)
    );
}

#[test]
fn a_moved_emissive_mesh_is_a_moved_light() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A room lit by a glowing panel that the animation `slide` carries across the ceiling.
    let lit = |name: &str, x: Option<f32>| {
        let mut b = small_room();
        let glow = b.material(emissive_lambertian("glow", [1.0; 3], 10.0));
        let panel = b.mesh(
            &[[-0.4, 2.9, -0.4], [0.4, 2.9, -0.4], [0.4, 2.9, 0.4], [-0.4, 2.9, 0.4]],
            &[[0, 2, 1], [0, 3, 2]],
            Some(glow),
        );
        let node = b.node(json!({"name": "panel", "mesh": panel, "translation": [x.unwrap_or(-2.0), 0.0, 0.0]}));
        if x.is_none() {
            b.animation(
                "slide",
                &[(
                    node,
                    "translation",
                    "LINEAR",
                    &[0.0, 1.0],
                    &[-2.0, 0.0, 0.0, 2.0, 0.0, 0.0],
                )],
            );
        }
        b.write(d, name)
    };
    let scene = lit("slide", None);
    let stats = d.join("e.####.json");
    render(
        &scene,
        &[
            "--frames",
            "0-2",
            "--fps",
            "2",
            "-o",
            s(&d.join("e.####.exr")),
            "--stats",
            s(&stats),
        ],
    );
    for (n, x) in [(1, 0.0), (2, 2.0)] {
        let st = stats_of(&d.join(format!("e.000{n}.json")));
        // Every record is dropped: the light moved.
        assert_eq!(st["records_before"], 0, "frame {n}");
        let still_scene = lit(&format!("panel{n}"), Some(x));
        let out = d.join(format!("panel{n}.exr"));
        render(&still_scene, &["-o", s(&out)]);
        let (frame, still) = (read_exr(&d.join(format!("e.000{n}.exr"))), read_exr(&out));
        assert!(
            mean(&rgb(&frame, "direct")[0]) > 0.01,
            "frame {n}: the panel lights the room"
        );
        assert_eq!(rgb(&frame, "direct"), rgb(&still, "direct"), "frame {n}: direct light");
        assert_eq!(rgb(&frame, "emission"), rgb(&still, "emission"), "frame {n}: emission");
        within_the_cache_s_error(&frame, &still, &format!("frame {n} against its still"));
    }
}

/// A frame of a sequence and the still it is compared with are two renders of one pose with
/// records of their own: they differ within the cache's error (the ghost bench's bound).
fn within_the_cache_s_error(frame: &ImageData, still: &ImageData, what: &str) {
    let e = relmse(frame, still);
    assert!(e < 2e-3, "{what}: relMSE {e:.2e}");
}

/// A grey box lit by a point light, with a card (a quad node, returned) in it: a file to animate
/// in ways that are refused.
fn box_with_a_card() -> (GltfBuilder, usize) {
    let mut b = GltfBuilder::new();
    let grey = b.material(lambertian("grey", [0.6, 0.6, 0.6]));
    inward_box(&mut b, [-2.0, 0.0, -2.0], [2.0, 2.0, 2.0], grey);
    b.point_light([0.0, 1.0, 0.0], 5.0);
    let card = b.quad(
        [[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.3, 0.3, 0.0], [0.0, 0.3, 0.0]],
        Some(grey),
    );
    (b, card)
}

/// A grey room (6 x 3 x 6) with a camera at its front looking in, and no light yet.
fn small_room() -> GltfBuilder {
    let mut b = GltfBuilder::new();
    let grey = b.material(lambertian("grey", [0.6, 0.6, 0.6]));
    inward_box(&mut b, [-3.0, 0.0, -3.0], [3.0, 3.0, 3.0], grey);
    let camera = b.perspective_camera(1.1);
    b.node(json!({"camera": camera, "translation": [0.0, 1.5, 2.8]}));
    b
}

/// Runs a small render with `extra`, which must be refused as bad input (exit 2) with one line
/// and no output written; returns what it said.
fn refused(scene: &Path, out: &Path, extra: &[&str]) -> String {
    let mut args = vec!["render", s(scene), "-q", "-x", "8", "-y", "6", "-o", s(out)];
    args.extend_from_slice(extra);
    let result = run(&args);
    let e = stderr(&result);
    assert_eq!(result.status.code(), Some(2), "{e}");
    // One line of error (the loader's warnings about the file may come before it).
    let errors = e.lines().filter(|l| !l.starts_with("icrender: warning:")).count();
    assert_eq!(errors, 1, "one line: {e}");
    assert!(!out.exists() && !out.with_extension("png").exists());
    e
}

#[test]
fn deforming_animations_and_cache_files_are_refused_for_moving_scenes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = hall(d, "push", None);
    // A cache file holds one still scene's records.
    let e = refused(&scene, &d.join("a.exr"), &["--frame", "1", "-af", s(&d.join("c.icc"))]);
    assert!(e.contains("push.gltf") && e.contains("-af"), "{e}");
    assert!(!d.join("c.icc").exists());
    let e = refused(
        &scene,
        &d.join("b.exr"),
        &["--frames", "1-2", "--checkpoint", s(&d.join("ck"))],
    );
    assert!(e.contains("--checkpoint"), "{e}");
    // Morph target weights of a mesh's node.
    let morph = {
        let (b, crate_node) = box_with_a_card();
        b.write_edited(d, "morph", |doc| {
            doc["nodes"][crate_node]["name"] = json!("face");
            let times = doc["accessors"].as_array().unwrap().len();
            doc["accessors"].as_array_mut().unwrap().push(json!({"bufferView": 0, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0.0], "max": [1.0]}));
            doc["animations"] = json!([{"name": "smile", "samplers": [{"input": times, "output": times}], "channels": [{"sampler": 0, "target": {"node": crate_node, "path": "weights"}}]}]);
        })
    };
    let e = refused(&morph, &d.join("m.exr"), &["--frames", "0-1"]);
    assert!(
        e.contains("animation 'smile'") && e.contains("node 'face'") && e.contains("morph"),
        "{e}"
    );
    // The joints of a skin.
    let skinned = {
        let (mut b, arm) = box_with_a_card();
        let bone = b.node(json!({"name": "elbow"}));
        b.animation(
            "wave",
            &[(
                bone,
                "rotation",
                "LINEAR",
                &[0.0, 1.0],
                &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.6, 0.8],
            )],
        );
        b.write_edited(d, "skinned", |doc| {
            doc["skins"] = json!([{"joints": [bone]}]);
            doc["nodes"][arm]["skin"] = json!(0);
        })
    };
    let e = refused(&skinned, &d.join("k.exr"), &["--frames", "0-1"]);
    assert!(
        e.contains("animation 'wave'") && e.contains("node 'elbow'") && e.contains("skin"),
        "{e}"
    );
    // A still render of either file shows its rest pose.
    for (scene, name) in [(&morph, "m_still.exr"), (&skinned, "k_still.exr")] {
        let out = d.join(name);
        run_ok(&["render", s(scene), "-q", "-x", "8", "-y", "6", "-o", s(&out)]);
        assert!(out.exists());
    }
}

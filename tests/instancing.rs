//! Meshes used by several nodes (and by EXT_mesh_gpu_instancing) are traced as Embree
//! instances: the image is the one `--flatten` (every placement copied) renders, an instanced
//! emitter is one light per placement, and the loader takes the extension's instances.

mod common;
use common::*;
use serde_json::{Value, json};
use std::path::{Path, PathBuf};

/// A box from (-0.5, 0, -0.5) to (0.5, 1, 0.5), outward winding, with smooth normals (each
/// corner's points away from the centre: shading normals differ from the faces') and texture
/// coordinates from x and z.
fn block(b: &mut GltfBuilder, material: usize) -> usize {
    let mut positions: Vec<[f32; 3]> = Vec::new();
    for i in 0..8u32 {
        positions.push([
            if i & 1 == 0 { -0.5 } else { 0.5 },
            if i & 2 == 0 { 0.0 } else { 1.0 },
            if i & 4 == 0 { -0.5 } else { 0.5 },
        ]);
    }
    let normals: Vec<[f32; 3]> = (positions.iter())
        .map(|p| {
            let d = [p[0], p[1] - 0.5, p[2]];
            let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            d.map(|c| c / l)
        })
        .collect();
    let texcoords: Vec<[f32; 2]> = positions.iter().map(|p| [p[0] + 0.5, p[2] + 0.5]).collect();
    // Faces as quads of corner indices, each counter-clockwise seen from outside.
    let faces = [
        [0, 1, 3, 2], // -z
        [4, 6, 7, 5], // +z
        [0, 2, 6, 4], // -x
        [1, 5, 7, 3], // +x
        [0, 4, 5, 1], // -y
        [2, 3, 7, 6], // +y
    ];
    let indices: Vec<[u32; 3]> = faces
        .iter()
        .flat_map(|[a, b, c, d]| [[*a, *b, *c], [*a, *c, *d]])
        .collect();
    b.mesh_with(&positions, Some(&normals), Some(&texcoords), &indices, Some(material))
}

/// A unit quad in the y = 0 plane, centred on the origin, its front facing `up` (+1: +y).
fn flat_quad(b: &mut GltfBuilder, size: f32, up: f32, material: usize) -> usize {
    let h = size / 2.0;
    let corners = facing([[-h, 0.0, -h], [h, 0.0, -h], [h, 0.0, h], [-h, 0.0, h]], [0.0, up, 0.0]);
    b.mesh(&corners, &[[0, 1, 2], [0, 2, 3]], Some(material))
}

/// A quaternion (x, y, z, w) turning by `degrees` about `axis`.
fn rotation(axis: [f32; 3], degrees: f32) -> [f32; 4] {
    let l = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    let (s, c) = (degrees.to_radians() / 2.0).sin_cos();
    [axis[0] / l * s, axis[1] / l * s, axis[2] / l * s, c]
}

/// An 8 x 8 checker of two colours as a PNG beside the scene.
fn checker(dir: &Path) -> &'static str {
    let mut rgb = Vec::new();
    for y in 0..8 {
        for x in 0..8 {
            rgb.extend_from_slice(if (x + y) % 2 == 0 {
                &[230, 200, 60]
            } else {
                &[40, 90, 200]
            });
        }
    }
    icrender::sys::image_io::write_png(&dir.join("checker.png"), 8, 8, &rgb).unwrap();
    "checker.png"
}

/// A floor (used once, so copied) under a textured, smooth-shaded block placed four times
/// (moved; rotated with a non-uniform scale; mirrored by a negative scale; under a scaled
/// parent), a half-transparent pane placed twice and a lamp (an emissive quad facing down)
/// placed three times, once mirrored: every kind of placement, and the only lights are
/// instanced.
fn props_scene(dir: &Path) -> PathBuf {
    props_scene_at(dir, "props", [0.0; 3])
}

/// The props scene with every root node under one node translated by `offset`.
fn props_scene_at(dir: &Path, name: &str, offset: [f64; 3]) -> PathBuf {
    let mut b = GltfBuilder::new();
    let floor = b.material(lambertian("floor", [0.6, 0.6, 0.6]));
    let texture = b.texture(checker(dir));
    let mut painted = lambertian("painted", [1.0, 1.0, 1.0]);
    painted["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": texture});
    let painted = b.material(painted);
    let glass = b.material(json!({
        "name": "glass",
        "alphaMode": "BLEND",
        "pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.9, 0.9, 0.5], "metallicFactor": 0.0, "roughnessFactor": 1.0},
        "extensions": {"KHR_materials_specular": {"specularFactor": 0.0}}
    }));
    let lamp = b.material(emissive_lambertian("lamp", [0.8, 0.8, 0.8], 8.0));
    let floor_mesh = flat_quad(&mut b, 12.0, 1.0, floor);
    b.node(json!({"name": "floor", "mesh": floor_mesh}));
    let block = block(&mut b, painted);
    b.node(json!({"name": "block_moved", "mesh": block, "translation": [-3.0, 0.0, -2.0]}));
    b.node(
        json!({"name": "block_turned", "mesh": block, "translation": [2.0, 0.2, -1.0],
        "rotation": rotation([0.3, 1.0, 0.2], 40.0), "scale": [1.5, 0.6, 1.0]}),
    );
    b.node(
        json!({"name": "block_mirrored", "mesh": block, "translation": [0.0, 0.0, 2.5],
        "rotation": rotation([0.0, 1.0, 0.0], 30.0), "scale": [-1.2, 1.0, 0.8]}),
    );
    let child = b.node(json!({"name": "block_child", "mesh": block, "rotation": rotation([0.0, 0.0, 1.0], 10.0)}));
    b.node(
        json!({"name": "block_parent", "translation": [3.0, 0.0, 2.0], "scale": [0.7, 0.7, 0.7], "children": [child]}),
    );
    let pane = flat_quad(&mut b, 1.5, 1.0, glass);
    b.node(json!({"name": "pane_flat", "mesh": pane, "translation": [-3.0, 2.5, -2.0]}));
    b.node(
        json!({"name": "pane_standing", "mesh": pane, "translation": [1.0, 1.5, 1.0],
        "rotation": rotation([1.0, 0.0, 0.0], 90.0)}),
    );
    let lamp_mesh = flat_quad(&mut b, 1.0, -1.0, lamp);
    b.node(json!({"name": "lamp_a", "mesh": lamp_mesh, "translation": [-2.0, 4.0, 0.0]}));
    b.node(json!({"name": "lamp_b", "mesh": lamp_mesh, "translation": [2.0, 4.0, 1.0]}));
    b.node(
        json!({"name": "lamp_mirrored", "mesh": lamp_mesh, "translation": [0.0, 4.0, -2.5], "scale": [-1.0, 1.0, 1.0]}),
    );
    b.write_edited(dir, name, |doc| {
        roots_only(doc);
        if offset != [0.0; 3] {
            let roots = doc["scenes"][0]["nodes"].clone();
            let nodes = doc["nodes"].as_array_mut().unwrap();
            nodes.push(json!({"name": "far", "translation": offset, "children": roots}));
            doc["scenes"][0]["nodes"] = json!([nodes.len() - 1]);
        }
    })
}

/// The scene lists only the nodes no other node has as a child.
fn roots_only(doc: &mut Value) {
    let nodes = doc["nodes"].as_array().unwrap();
    let children: Vec<u64> = (nodes.iter())
        .filter_map(|n| n["children"].as_array())
        .flatten()
        .filter_map(Value::as_u64)
        .collect();
    let roots: Vec<usize> = (0..nodes.len()).filter(|i| !children.contains(&(*i as u64))).collect();
    doc["scenes"] = json!([{"nodes": roots}]);
}

fn info(scene: &Path, extra: &[&str]) -> Value {
    let mut args = vec!["info", scene.to_str().unwrap(), "--json"];
    args.extend_from_slice(extra);
    serde_json::from_str(&stdout(&run_ok(&args))).unwrap()
}

const VIEW: &str = "-vd 0 -1 -0.8 -vh 60 -vv 45 -x 96 -y 72";

/// The props' view (from (0, 9, 7), moved with the scene by `offset`) and `extra` options.
fn args_at(offset: [f64; 3], extra: &str) -> Vec<String> {
    let vp = [offset[0], 9.0 + offset[1], 7.0 + offset[2]];
    format!("-vp {} {} {} {VIEW} {extra}", vp[0], vp[1], vp[2])
        .split_whitespace()
        .map(String::from)
        .collect()
}

fn args(extra: &str) -> Vec<String> {
    args_at([0.0; 3], extra)
}

/// How two renders of the same scene differ in a layer (channel names as `rgb`, or a data
/// layer's own): the largest relative difference of a value (against `b`'s, floored at 1e-3 so
/// black values do not divide by zero), the share of values differing by more than 1e-4
/// relative, and the relative difference of the layer's means.
struct Difference {
    worst: f64,
    share_above: f64,
    means: f64,
}

/// The share of the values of `channels` differing by more than `bound` relative (floored as
/// in `difference`).
fn difference_above(a: &ImageData, b: &ImageData, channels: &[String], bound: f64) -> f64 {
    let (mut above, mut count) = (0usize, 0usize);
    for c in channels {
        for (p, q) in a.channel(c).unwrap().iter().zip(b.channel(c).unwrap()) {
            above += ((*p as f64 - *q as f64).abs() / (*q as f64).abs().max(1e-3) > bound) as usize;
            count += 1;
        }
    }
    above as f64 / count as f64
}

fn difference(a: &ImageData, b: &ImageData, channels: &[String]) -> Difference {
    let (mut worst, mut above, mut count, mut sum_a, mut sum_b) = (0.0f64, 0usize, 0usize, 0.0f64, 0.0f64);
    for c in channels {
        let (x, y) = (a.channel(c).unwrap(), b.channel(c).unwrap());
        for (p, q) in x.iter().zip(y) {
            let (p, q) = (*p as f64, *q as f64);
            let d = (p - q).abs() / q.abs().max(1e-3);
            worst = worst.max(d);
            above += (d > 1e-4) as usize;
            count += 1;
            sum_a += p;
            sum_b += q;
        }
    }
    Difference {
        worst,
        share_above: above as f64 / count as f64,
        means: (sum_a - sum_b).abs() / sum_b.abs().max(1e-12),
    }
}

fn channels(layer: &str) -> Vec<String> {
    match layer {
        "" => vec!["R".into(), "G".into(), "B".into()],
        "normal" => ["X", "Y", "Z"].map(|c| format!("normal.{c}")).to_vec(),
        "depth" => vec!["depth.Z".into()],
        _ => ["R", "G", "B"].map(|c| format!("{layer}.{c}")).to_vec(),
    }
}

/// What instancing may change in an image, and why. A hit through an instance is intersected
/// by Embree in the instance's own space, so its distance and barycentrics round differently
/// from the copy's (by about 1e-7 of the coordinates); everything computed from them then
/// differs by about as much: 1e-4 relative is a thousand times that. A ray whose fate is
/// decided at the very boundary (a shadow ray ending exactly where it would touch a surface)
/// may go the other way (here a shadow ray that grazes the lamp it aims at: 5 % of a pixel's
/// direct light): such values are rare (below 0.3 % of the values of a layer; 0.16 % at most
/// in this scene, where a wrong transform, normal, winding or texture coordinate would move
/// most of them), and the layers' means agree to 1e-4 (1e-5 here). The irradiance cache places
/// its records at points that moved by rounding and interpolates them with weights that moved
/// as much, so the indirect light differs in more pixels (0.4 % above 1e-4 here), and its
/// prepass makes yes-or-no choices a rounding can tip (whether a record covers a site, whether a
/// neighbouring record counts in the check that shrinks a record, `irradiance::validation`):
/// where one tips, the few pixels that record serves move by up to a few percent (here 7 of
/// 6,912 pixels by more than 0.1 %, at most 1.07 %, far out; before the neighbour checks at
/// most 0.14 %). So the indirect layer may differ by more than 0.1 % in at most 0.5 % of its
/// values, and by at most 3 % anywhere.
fn assert_same_image(instanced: &ImageData, flattened: &ImageData, what: &str) {
    for (layer, d) in same_means_by_layer(instanced, flattened, what) {
        if layer == "indirect" {
            assert!(d.worst < 3e-2, "{what}: indirect differs by {:.2e}", d.worst);
            let loose = difference_above(instanced, flattened, &channels(layer), 1e-3);
            assert!(
                loose < 5e-3,
                "{what}: {:.3} % of the indirect values differ by more than 1e-3",
                100.0 * loose
            );
        } else {
            assert!(
                d.share_above < 3e-3,
                "{what}: layer '{layer}': {:.3} % of values differ by more than 1e-4",
                100.0 * d.share_above
            );
        }
    }
}

#[test]
fn an_instanced_scene_renders_as_its_flattened_copy() {
    let dir = tempfile::tempdir().unwrap();
    let scene = props_scene(dir.path());
    // The test means something only if the props are instanced, and --flatten copies them.
    let shared = info(&scene, &[]);
    assert_eq!(shared["instancing"]["placements"], 9, "{shared}");
    assert_eq!(shared["instancing"]["shared_meshes"], 3, "{shared}");
    assert_eq!(shared["placed_meshes"], 10);
    let copied = info(&scene, &["--flatten"]);
    assert_eq!(copied["instancing"]["placements"], 0, "{copied}");
    for key in ["triangles", "placed_meshes", "dropped_triangles", "bounds", "lights"] {
        assert_eq!(shared[key], copied[key], "{key}");
    }

    let a = args("-ab 1 --aovs all --ic-deep paths");
    let a: Vec<&str> = a.iter().map(String::as_str).collect();
    let (instanced, stats) = render_to(dir.path(), &scene, "instanced", &a);
    let mut f = a.clone();
    f.push("--flatten");
    let (flattened, _) = render_to(dir.path(), &scene, "flattened", &f);
    assert!(stats["records_computed"].as_u64().unwrap() > 0);
    assert!(
        flattened.attribute("icrender/options").unwrap().ends_with(" --flatten"),
        "{:?}",
        flattened.attribute("icrender/options")
    );
    assert_same_image(&instanced, &flattened, "props");
    assert_same_means_with_the_grid(dir.path(), &scene, [0.0; 3], "props");
}

/// The default render (the last bounce's grid answering the records' hits) of `scene`
/// instanced and flattened: every layer's mean within 1e-4. Pixel by pixel the grid spreads
/// what a rounding tips (a grid sample's shadow ray grazing an edge, 1 of the cell's 8 or more
/// samples) over every hit that reads its cell, so more pixels move than `assert_same_image`
/// allows (measured: the props 0.04 % of the indirect values by more than 1e-4, at most 4.3 %;
/// far out 0.07 %, at most 2.9 %; 3,956 grid samples at this size); the images' geometry,
/// normals and materials are what `assert_same_image` checks, with `--ic-deep paths`.
fn assert_same_means_with_the_grid(dir: &Path, scene: &Path, offset: [f64; 3], what: &str) {
    let a = args_at(offset, "-ab 1 --aovs all");
    let a: Vec<&str> = a.iter().map(String::as_str).collect();
    let (instanced, stats) = render_to(dir, scene, &format!("{what}-grid"), &a);
    assert!(
        stats["last_bounce_cells"].as_u64().unwrap() > 0,
        "{what}: the grid was built"
    );
    let f = [&a[..], &["--flatten"]].concat();
    let (flattened, _) = render_to(dir, scene, &format!("{what}-grid-flattened"), &f);
    same_means_by_layer(&instanced, &flattened, &format!("{what} with the grid"));
}

/// Every layer's difference between the two images, printed, each layer's means within 1e-4.
fn same_means_by_layer(instanced: &ImageData, flattened: &ImageData, what: &str) -> Vec<(&'static str, Difference)> {
    let layers = ["emission", "direct", "indirect", "", "albedo", "normal", "depth"];
    layers
        .into_iter()
        .map(|layer| {
            let d = difference(instanced, flattened, &channels(layer));
            println!(
                "{what}, layer '{layer}': worst {:.2e}, {:.3} % above 1e-4, means {:.2e}",
                d.worst,
                100.0 * d.share_above,
                d.means
            );
            assert!(
                d.means < 1e-4,
                "{what}: layer '{layer}' means differ by {:.2e}",
                d.means
            );
            (layer, d)
        })
        .collect()
}

/// Far from glTF's origin (map coordinates) the instances are placed relative to the tracing
/// origin as the copies are: the same triangles, bounds and image.
#[test]
fn instances_far_from_the_origin_render_as_their_copies() {
    let dir = tempfile::tempdir().unwrap();
    let offset = [1.0e6, -2.5e5, 3.0e6];
    let scene = props_scene_at(dir.path(), "far_props", offset);
    let (shared, copied) = (info(&scene, &[]), info(&scene, &["--flatten"]));
    assert_eq!(shared["instancing"]["placements"], 9, "{shared}");
    for key in ["triangles", "placed_meshes", "dropped_triangles", "bounds", "lights"] {
        assert_eq!(shared[key], copied[key], "{key}");
    }
    let a = args_at(offset, "-ab 1 --aovs all --ic-deep paths");
    let a: Vec<&str> = a.iter().map(String::as_str).collect();
    let (instanced, _) = render_to(dir.path(), &scene, "far_instanced", &a);
    let mut f = a.clone();
    f.push("--flatten");
    let (flattened, _) = render_to(dir.path(), &scene, "far_flattened", &f);
    // The view must see the props (not empty space): most pixels are lit.
    let lit = rgb(&instanced, "direct")[0].iter().filter(|&&v| v > 0.0).count();
    assert!(lit > 96 * 72 / 2, "{lit} lit pixels");
    assert_same_image(&instanced, &flattened, "far out");
    assert_same_means_with_the_grid(dir.path(), &scene, offset, "far out");
}

/// Corners of the lamp (a 1 x 1 quad in y = 0, front facing -y) placed by scale, then a turn
/// about y, then a translation (glTF's T * R * S), and the same as node properties.
struct LampPlacement {
    translation: [f32; 3],
    turn_degrees: f32,
    scale: [f32; 3],
}

impl LampPlacement {
    fn node(&self, mesh: usize) -> Value {
        json!({"mesh": mesh, "translation": self.translation,
            "rotation": rotation([0.0, 1.0, 0.0], self.turn_degrees), "scale": self.scale})
    }

    fn place(&self, p: [f32; 3]) -> [f64; 3] {
        let s = [0, 1, 2].map(|i| p[i] as f64 * self.scale[i] as f64);
        let (sin, cos) = (self.turn_degrees as f64).to_radians().sin_cos();
        let r = [cos * s[0] + sin * s[2], s[1], -sin * s[0] + cos * s[2]];
        [0, 1, 2].map(|i| r[i] + self.translation[i] as f64)
    }
}

/// A floor lit only by one lamp mesh placed three times (moved; turned and stretched; mirrored):
/// three lights, two triangles each, each where its node puts it. Its direct light matches
/// Lambert's formula over the three placed quads at every pixel, with the exact (analytic)
/// direct light and, within noise, with plain shadow-ray sampling through the light tree; and
/// both match the flattened scene's.
#[test]
fn an_instanced_emitter_is_one_light_per_placement() {
    let dir = tempfile::tempdir().unwrap();
    let (rho, radiance) = (0.5f64, 6.0f64);
    let mut b = GltfBuilder::new();
    let floor = b.material(lambertian("floor", [rho as f32; 3]));
    let lamp = b.material(emissive_lambertian("lamp", [0.8; 3], radiance as f32));
    let floor_mesh = flat_quad(&mut b, 12.0, 1.0, floor);
    b.node(json!({"name": "floor", "mesh": floor_mesh}));
    let lamp_mesh = flat_quad(&mut b, 1.0, -1.0, lamp);
    let placements = [
        LampPlacement {
            translation: [-1.5, 4.0, 0.0],
            turn_degrees: 0.0,
            scale: [1.0, 1.0, 1.0],
        },
        LampPlacement {
            translation: [1.5, 4.0, 0.5],
            turn_degrees: 30.0,
            scale: [1.6, 1.0, 0.5],
        },
        LampPlacement {
            translation: [0.0, 4.0, -1.5],
            turn_degrees: -20.0,
            scale: [-1.0, 1.0, 1.2],
        },
    ];
    for p in &placements {
        b.node(p.node(lamp_mesh));
    }
    let scene = b.write(dir.path(), "lamps");
    for flatten in [false, true] {
        let extra: &[&str] = if flatten { &["--flatten"] } else { &[] };
        let d = info(&scene, extra);
        assert_eq!(d["lights"]["emissive_triangles"], 6, "{d}");
        assert_eq!(d["instancing"]["placements"], if flatten { 0 } else { 3 });
    }
    // Straight down at the floor's middle from below the lamps, in parallel projection: the
    // lamps (4 above the floor) see
    // every point at least 55 degrees off grazing.
    let view = "-vtl -vp 0 3 0 -vd 0 -1 0 -vu 0 0 -1 -vh 5 -vv 5 -x 24 -y 24 -ab 0 --aovs position";
    let render = |name: &str, extra: &str| {
        let options: Vec<String> = format!("{view} {extra}").split_whitespace().map(String::from).collect();
        let options: Vec<&str> = options.iter().map(String::as_str).collect();
        render_to(dir.path(), &scene, name, &options).0
    };
    let lamp_corners: Vec<[[f64; 3]; 4]> = (placements.iter())
        .map(|p| [[-0.5, 0.0, -0.5], [0.5, 0.0, -0.5], [0.5, 0.0, 0.5], [-0.5, 0.0, 0.5]].map(|c| p.place(c)))
        .collect();
    let expected: Vec<f64> = {
        let image = render("positions", "");
        let position = ["X", "Y", "Z"].map(|c| image.channel(&format!("position.{c}")).unwrap().to_vec());
        (0..position[0].len())
            .map(|i| {
                let point = [0, 1, 2].map(|c| position[c][i] as f64);
                assert!(point[1].abs() < 1e-5, "pixel {i} is not on the floor: {point:?}");
                let e: f64 = lamp_corners
                    .iter()
                    .map(|q| polygon_irradiance(q, point, radiance))
                    .sum();
                rho / std::f64::consts::PI * e
            })
            .collect()
    };
    let exact = render("exact", "--direct analytic --light-samples 16");
    for (i, (&got, &want)) in exact.channel("direct.R").unwrap().iter().zip(&expected).enumerate() {
        assert!(
            (got as f64 - want).abs() <= 1e-4 * want,
            "pixel {i}: direct {got}, Lambert's formula over the placed lamps {want}"
        );
    }
    let sampled = render("sampled", "--direct sampled --light-samples 64");
    let (got, want) = (
        mean(sampled.channel("direct.R").unwrap()),
        expected.iter().sum::<f64>() / expected.len() as f64,
    );
    // 36,864 shadow rays over a smooth field: the mean's noise is well below 1 %.
    assert!(
        (got - want).abs() < 0.01 * want,
        "sampled direct mean {got}, Lambert's formula {want}"
    );
    let flattened = render("sampled_flat", "--direct sampled --light-samples 64 --flatten");
    let d = difference(&sampled, &flattened, &channels("direct"));
    assert!(
        d.worst < 1e-4,
        "sampled direct light, instanced against flattened: {:.2e}",
        d.worst
    );
}

/// The instances of one EXT_mesh_gpu_instancing node, as (translation, rotation, scale).
fn grove() -> Vec<([f32; 3], [f32; 4], [f32; 3])> {
    vec![
        ([-2.0, 0.0, -1.0], rotation([0.0, 1.0, 0.0], 0.0), [1.0, 1.0, 1.0]),
        ([1.5, 0.3, -1.5], rotation([0.2, 1.0, 0.4], 50.0), [1.4, 0.7, 1.0]),
        ([0.0, 0.0, 1.5], rotation([0.0, 1.0, 0.0], -35.0), [-1.0, 1.2, 0.9]),
        ([2.5, 0.0, 1.0], rotation([1.0, 0.0, 0.0], 15.0), [0.6, 0.6, 0.6]),
    ]
}

/// ROTATION as normalized shorts, read back as the loader reads them.
fn dequantized(q: [f32; 4]) -> [f64; 4] {
    q.map(|v| ((v * 32767.0).round() as i16) as f64 / 32767.0)
}

/// The grove scene: a floor, two lamps, and the block placed by one node (itself moved and
/// turned) either with EXT_mesh_gpu_instancing or, with `as_nodes`, by one child node per
/// instance carrying the instance's transform.
fn grove_scene(dir: &Path, as_nodes: bool) -> PathBuf {
    let name = if as_nodes { "grove_nodes" } else { "grove" };
    grove_scene_with(dir, as_nodes, name, [0.5, 0.0, -0.5], None)
}

/// The grove with its node at `translation`, and with `moved_to`, a STEP animation that moves
/// the node there at t = 1.
fn grove_scene_with(
    dir: &Path,
    as_nodes: bool,
    name: &str,
    translation: [f32; 3],
    moved_to: Option<[f32; 3]>,
) -> PathBuf {
    let mut b = GltfBuilder::new();
    let floor = b.material(lambertian("floor", [0.6, 0.6, 0.6]));
    let painted = b.material(lambertian("painted", [0.7, 0.4, 0.2]));
    let lamp = b.material(emissive_lambertian("lamp", [0.8, 0.8, 0.8], 8.0));
    let floor_mesh = flat_quad(&mut b, 12.0, 1.0, floor);
    b.node(json!({"name": "floor", "mesh": floor_mesh}));
    let block = block(&mut b, painted);
    let node_transform = json!({"translation": translation, "rotation": rotation([0.0, 1.0, 0.0], 25.0)});
    let mut grove_node = json!({"name": "grove"});
    for (k, v) in node_transform.as_object().unwrap() {
        grove_node[k] = v.clone();
    }
    if as_nodes {
        let children: Vec<usize> = (grove().into_iter())
            .map(|(t, q, s)| b.node(json!({"mesh": block, "translation": t, "rotation": dequantized(q), "scale": s})))
            .collect();
        grove_node["children"] = json!(children);
    } else {
        let t: Vec<f32> = grove().iter().flat_map(|g| g.0).collect();
        let q: Vec<[f32; 4]> = grove().iter().map(|g| g.1).collect();
        let s: Vec<f32> = grove().iter().flat_map(|g| g.2).collect();
        let translation = b.float_accessor(&t, "VEC3");
        let rotation = b.normalized_short_vec4(&q);
        let scale = b.float_accessor(&s, "VEC3");
        grove_node["mesh"] = json!(block);
        grove_node["extensions"] = json!({"EXT_mesh_gpu_instancing": {"attributes": {
            "TRANSLATION": translation, "ROTATION": rotation, "SCALE": scale}}});
        b.use_extension("EXT_mesh_gpu_instancing");
        b.extensions_required.push("EXT_mesh_gpu_instancing".into());
    }
    let grove = b.node(grove_node);
    if let Some(to) = moved_to {
        let keys: Vec<f32> = translation.into_iter().chain(to).collect();
        b.animation("move", &[(grove, "translation", "STEP", &[0.0, 1.0], &keys)]);
    }
    let lamp_mesh = flat_quad(&mut b, 1.0, -1.0, lamp);
    b.node(json!({"name": "lamp_a", "mesh": lamp_mesh, "translation": [-1.5, 4.0, 0.5]}));
    b.node(json!({"name": "lamp_b", "mesh": lamp_mesh, "translation": [1.5, 4.0, -0.5]}));
    b.write_edited(dir, name, roots_only)
}

/// An animation of an EXT_mesh_gpu_instancing node moves all its instances with it: a frame
/// after the move is the still render of the node placed there, within float rounding (the
/// frame's placements are the node's new world matrix times each instance's transform under
/// the node, recovered from the rest pose's).
#[test]
fn an_animated_gpu_instancing_node_moves_its_instances() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let to = [-0.5f32, 0.0, 0.5];
    let animated = grove_scene_with(d, false, "grove_moving", [0.5, 0.0, -0.5], Some(to));
    let still = grove_scene_with(d, false, "grove_there", to, None);
    let a = args("-ab 1 --aovs albedo");
    let mut a: Vec<&str> = a.iter().map(String::as_str).collect();
    let (placed, _) = render_to(d, &still, "there", &a);
    a.extend(["--frame", "2", "--fps", "1"]);
    let (frame, _) = render_to(d, &animated, "moved", &a);
    let diff = difference(&frame, &placed, &channels("direct"));
    assert!(
        diff.worst < 1e-3,
        "direct light of the moved instances: {:.2e}",
        diff.worst
    );
    let e = relmse(&frame, &placed);
    assert!(e < 2e-3, "the frame against the still: relMSE {e:.2e}");
}

/// EXT_mesh_gpu_instancing places the mesh once per instance at node world * (T * R * S) of
/// the instance, with a rotation stored as normalized shorts: the same placements as one child
/// node per instance, and so, bit for bit, the same image. The extension may be required.
#[test]
fn ext_mesh_gpu_instancing_places_the_mesh_once_per_instance() {
    let dir = tempfile::tempdir().unwrap();
    let gpu = grove_scene(dir.path(), false);
    let nodes = grove_scene(dir.path(), true);
    let described = info(&gpu, &[]);
    assert_eq!(described["instancing"]["placements"], 4 + 2, "{described}");
    assert_eq!(described["placed_meshes"], 1 + 4 + 2);
    assert_eq!(described["triangles"], 2 + 4 * 12 + 2 * 2);
    assert_eq!(described["bounds"], info(&nodes, &[])["bounds"]);
    let a = args("-ab 1 --aovs albedo,normal,depth");
    let a: Vec<&str> = a.iter().map(String::as_str).collect();
    let (from_extension, _) = render_to(dir.path(), &gpu, "gpu", &a);
    let (from_nodes, _) = render_to(dir.path(), &nodes, "nodes", &a);
    for layer in ["", "emission", "direct", "indirect", "albedo", "normal", "depth"] {
        for c in channels(layer) {
            assert_eq!(from_extension.channel(&c), from_nodes.channel(&c), "channel {c}");
        }
    }
    // And the flattened copy of the extension's placements renders the same image.
    let mut f = a.clone();
    f.push("--flatten");
    let (flattened, _) = render_to(dir.path(), &gpu, "gpu_flat", &f);
    assert_same_image(&from_extension, &flattened, "EXT_mesh_gpu_instancing");
}

/// What the extension's attributes may not be: one line naming the file and the problem.
#[test]
fn ext_mesh_gpu_instancing_with_bad_attributes_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    /// A case: its name, the attributes it writes, what the error says.
    type Case = (&'static str, Box<dyn Fn(&mut GltfBuilder) -> Value>, &'static str);
    let cases: Vec<Case> = vec![
        (
            "counts",
            Box::new(|b: &mut GltfBuilder| {
                let t = b.float_accessor(&[0.0; 9], "VEC3");
                let s = b.float_accessor(&[1.0; 6], "VEC3");
                json!({"TRANSLATION": t, "SCALE": s})
            }),
            "SCALE has 2 instances where another attribute has 3",
        ),
        (
            "rotation",
            Box::new(|b: &mut GltfBuilder| {
                let r = b.float_accessor(&[0.0; 9], "VEC3");
                json!({"ROTATION": r})
            }),
            "ROTATION must be VEC4 float, or normalized byte or short, got float VEC3",
        ),
        (
            "index",
            Box::new(|_: &mut GltfBuilder| json!({"TRANSLATION": 99})),
            "TRANSLATION is not an accessor index",
        ),
    ];
    for (name, attributes, message) in cases {
        let mut b = GltfBuilder::new();
        let m = b.material(emissive_lambertian("lamp", [0.8; 3], 1.0));
        let mesh = flat_quad(&mut b, 1.0, 1.0, m);
        let attributes = attributes(&mut b);
        b.node(json!({"name": "many", "mesh": mesh, "extensions": {"EXT_mesh_gpu_instancing": {"attributes": attributes}}}));
        b.use_extension("EXT_mesh_gpu_instancing");
        let scene = b.write(dir.path(), name);
        let out = run(&["info", scene.to_str().unwrap()]);
        assert_eq!(out.status.code(), Some(2), "{name}: {}", stderr(&out));
        let err = stderr(&out);
        assert_eq!(err.trim().lines().count(), 1, "{name}: {err}");
        assert!(
            err.contains(&format!("{name}.gltf"))
                && err.contains("node 'many': EXT_mesh_gpu_instancing")
                && err.contains(message),
            "{name}: {err}"
        );
    }
}

/// Through the tracer itself: random rays in the props scene hit the same object, triangle,
/// material and point through instances as through copies, and shadow segments are blocked
/// alike (but for rays that graze an edge: rounding decides those, at most 1 in 1000 here).
#[test]
fn rays_through_instances_hit_what_rays_through_copies_hit() {
    use icrender::sampling::Rng;
    use icrender::scene::{LoadOptions, Scene};
    use icrender::sys::embree::Coherence;
    use icrender::tracer::Tracer;
    let dir = tempfile::tempdir().unwrap();
    let path = props_scene_at(dir.path(), "far_props", [1.0e6, -2.5e5, 3.0e6]);
    let shared = Scene::load(&path, &LoadOptions::default()).unwrap();
    let copied = Scene::load(
        &path,
        &LoadOptions {
            flatten: true,
            ..LoadOptions::default()
        },
    )
    .unwrap();
    assert_eq!(shared.instancing.placements.len(), 9);
    assert!(copied.instancing.placements.is_empty());
    assert_eq!(shared.origin, copied.origin);
    assert_ne!(
        shared.origin,
        glam::DVec3::ZERO,
        "the scene is far out: coordinates are re-centred"
    );
    let (ts, tc) = (Tracer::new(&shared).unwrap(), Tracer::new(&copied).unwrap());
    let (lo, hi) = (shared.bounds_min, shared.bounds_max);
    let mut rng = Rng::new(17, 0);
    let mut point = || lo + (hi - lo) * glam::Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
    let (mut hits, mut differ, mut blocked, mut blocked_differ) = (0, 0, 0, 0);
    let n = 100_000;
    for _ in 0..n {
        let (a, b) = (point(), point());
        let dir = (b - a).normalize();
        match (
            ts.intersect(&shared, a, dir, Coherence::Incoherent),
            tc.intersect(&copied, a, dir, Coherence::Incoherent),
        ) {
            (Some(s), Some(c)) => {
                hits += 1;
                let same = s.object == c.object
                    && s.prim_id == c.prim_id
                    && s.material == c.material
                    && (s.position - c.position).length() <= 1e-5 * shared.size()
                    && s.geometric_normal.dot(c.geometric_normal) > 0.9999
                    && s.normal.dot(c.normal) > 0.9999;
                differ += !same as usize;
            }
            (None, None) => {}
            _ => differ += 1,
        }
        let length = (b - a).length();
        let (mut s_continued, mut c_continued) = (0, 0);
        let s = ts.transmittance(&shared, a, dir, length, &mut s_continued);
        let c = tc.transmittance(&copied, a, dir, length, &mut c_continued);
        blocked += (c < 1.0) as usize;
        blocked_differ += ((s - c).abs() > 1e-6) as usize;
    }
    println!("{hits} hits, {differ} differ; {blocked} blocked, {blocked_differ} differ");
    assert!(
        hits > n / 5 && blocked > n / 10,
        "{hits} hits, {blocked} blocked: the rays miss the props"
    );
    assert!(differ * 1000 <= n, "{differ} of {n} closest hits differ");
    assert!(
        blocked_differ * 1000 <= n,
        "{blocked_differ} of {n} shadow segments differ"
    );
}

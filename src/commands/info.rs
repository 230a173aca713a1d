//! `icrender info`: what a scene holds and which components it needs.

use super::{CommandResult, warn};
use crate::cli::InfoArgs;
use crate::scene::{LoadOptions, Scene};
use crate::sys::scene_io::LightType;
use serde_json::json;

pub fn run(args: &InfoArgs) -> CommandResult {
    let options = LoadOptions {
        allow_outside_refs: args.allow_outside_refs,
        flatten: args.flatten,
        ..LoadOptions::default()
    };
    let scene = Scene::load(&args.scene, &options)?;
    for w in &scene.warnings {
        warn(&format!("{}: {w}", args.scene.display()));
    }
    let needs = scene.needs();
    let count = |kind: LightType| scene.punctual_lights.iter().filter(|l| l.kind == kind).count();
    let emissive_materials: Vec<&str> = scene
        .materials
        .iter()
        .filter(|m| m.is_emissive())
        .map(|m| m.name.as_str())
        .collect();
    let specular_materials: Vec<&str> = scene
        .materials
        .iter()
        .filter(|m| m.traces_specular)
        .map(|m| m.name.as_str())
        .collect();
    let description = json!({
        "scene": args.scene.display().to_string(),
        "triangles": scene.triangle_count(),
        "dropped_triangles": scene.dropped_triangles,
        "placed_meshes": scene.placed_mesh_count(),
        "instancing": {
            "shared_meshes": scene.instancing.meshes.len(),
            "placements": scene.instancing.placements.len(),
            "prototypes": scene.instancing.prototypes.len(),
            "instances": scene.instancing.instances.len(),
            "stored_triangles": scene.stored_triangle_count(),
        },
        "materials": scene.materials.len() - 1,
        "textures": scene.textures.len(),
        "lights": {
            "emissive_triangles": scene.emitters.triangles.len(),
            "emissive_materials": emissive_materials,
            "point": count(LightType::Point),
            "spot": count(LightType::Spot),
            "directional": count(LightType::Directional),
        },
        "cameras": scene.cameras.len(),
        "bounds": { "min": world_point(&scene, scene.bounds_min), "max": world_point(&scene, scene.bounds_max), "size": scene.size() },
        "specular_materials": specular_materials,
        "components": {
            "emission": needs.emission,
            "direct": needs.direct,
            "specular": needs.specular,
            "indirect_diffuse": needs.diffuse,
            "transparency": needs.transparency,
        },
    });
    if args.json {
        println!("{}", serde_json::to_string_pretty(&description)?);
        return Ok(());
    }
    let d = &description;
    println!("scene        {}", d["scene"].as_str().unwrap_or_default());
    println!(
        "triangles    {} ({} dropped), {} placed meshes",
        d["triangles"], d["dropped_triangles"], d["placed_meshes"]
    );
    let shared = &d["instancing"];
    if shared["placements"].as_u64().is_some_and(|p| p > 0) {
        println!(
            "instancing   {} shared meshes in {} placements, as {} Embree instances of {} prototypes; {} triangles stored",
            shared["shared_meshes"],
            shared["placements"],
            shared["instances"],
            shared["prototypes"],
            shared["stored_triangles"]
        );
    }
    println!("materials    {}, textures {}", d["materials"], d["textures"]);
    println!(
        "lights       {} emissive triangles, {} point, {} spot, {} directional",
        d["lights"]["emissive_triangles"], d["lights"]["point"], d["lights"]["spot"], d["lights"]["directional"]
    );
    println!("cameras      {}", d["cameras"]);
    println!(
        "bounds       min {} max {} (size {:.4})",
        world_text(&scene, scene.bounds_min),
        world_text(&scene, scene.bounds_max),
        scene.size()
    );
    let yes = |b: bool| if b { "yes" } else { "no" };
    println!(
        "components   emission {}, direct {}, specular {}, indirect diffuse {}, transparency {}",
        yes(needs.emission),
        yes(needs.direct),
        yes(needs.specular),
        yes(needs.diffuse),
        yes(needs.transparency)
    );
    Ok(())
}

/// A point of the renderer's in world coordinates, as a JSON array: the f32 values themselves
/// for a scene around glTF's origin (not re-centred), doubles for one far out.
fn world_point(scene: &Scene, p: glam::Vec3) -> serde_json::Value {
    if scene.origin == glam::DVec3::ZERO {
        serde_json::json!(p.to_array())
    } else {
        serde_json::json!(scene.to_world(p).to_array())
    }
}

fn world_text(scene: &Scene, p: glam::Vec3) -> String {
    if scene.origin == glam::DVec3::ZERO {
        format!("{:?}", p.to_array())
    } else {
        format!("{:?}", scene.to_world(p).to_array())
    }
}

//! Placing meshes in the world, in double precision, around a tracing origin.
//!
//! A scene may sit far from glTF's origin (a building in its city's map coordinates, 1e5-1e7
//! units out). In f32 a coordinate of 1e6 has a step of 0.06 and one of 1e7 a step of 1, so
//! positions, ray origins and offsets computed there lose the scene's detail (the Cornell box
//! moved 1e6 units rendered black). Every world position is therefore computed in f64 and the
//! renderer traces in coordinates relative to the centre of the scene's bounds (the tracing
//! origin) when the scene lies away from glTF's origin; there f32 keeps the precision it has
//! for a scene at the origin. Views and outputs
//! given or shown to the user stay in world coordinates (see `Scene::to_world`).
//!
//! Whether a triangle has an area is decided in f64 world space, before any rounding to f32:
//! a small triangle of a mesh placed far out must not become "zero area" in one placement and
//! not in another (conference_x32 dropped 1,216 triangles the single room keeps).

use super::{MAX_COORDINATE, WorldMesh};
use crate::sys::scene_io::{GltfMesh, GltfScene};
use glam::{DMat3, DMat4, DVec3, Vec3};

fn valid_world_point(p: DVec3) -> bool {
    p.is_finite() && p.abs().max_element() <= MAX_COORDINATE as f64
}

fn world_points(source: &GltfMesh, world: &DMat4) -> Vec<DVec3> {
    source
        .positions
        .iter()
        .map(|p| world.transform_point3(DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64)))
        .collect()
}

/// Where the renderer's coordinates start: glTF's origin for a scene around it (its images
/// are then exactly what they were before scenes were re-centred), else the centre of the
/// bounds of every vertex a triangle uses, once that centre is farther from glTF's origin than
/// the scene is large.
pub fn tracing_origin(gltf: &GltfScene) -> DVec3 {
    let (lo, hi) = world_bounds(gltf);
    if lo.x > hi.x {
        return DVec3::ZERO;
    }
    let centre = 0.5 * (lo + hi);
    if centre.abs().max_element() > (hi - lo).max_element() {
        centre
    } else {
        DVec3::ZERO
    }
}

fn world_bounds(gltf: &GltfScene) -> (DVec3, DVec3) {
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for instance in &gltf.instances {
        let source = &gltf.meshes[instance.mesh];
        let world = DMat4::from_cols_array(&instance.world);
        let points = world_points(source, &world);
        for i in source.indices.iter().flatten() {
            let p = points[*i as usize];
            if valid_world_point(p) {
                lo = lo.min(p);
                hi = hi.max(p);
            }
        }
    }
    (lo, hi)
}

/// Transforms a mesh into world space (f64), then to coordinates relative to `origin` (f32),
/// and drops triangles that cannot be traced: non-finite or out-of-range vertices, or zero
/// area in world space. A mirroring transform reverses the winding, so the front side (which
/// emitters use) stays where glTF says it is.
pub fn place_mesh(source: &GltfMesh, world: DMat4, origin: DVec3, material: u32) -> (WorldMesh, usize) {
    let mirrored = world.determinant() < 0.0;
    let points = world_points(source, &world);
    let normal_matrix = DMat3::from_mat4(world).inverse().transpose().as_mat3();
    let normals = source.normals.as_ref().filter(|_| normal_matrix.is_finite()).map(|ns| {
        ns.iter()
            .map(|&n| (normal_matrix * Vec3::from(n)).normalize_or_zero())
            .collect::<Vec<_>>()
    });
    let mut indices = Vec::with_capacity(source.indices.len());
    let mut dropped = 0;
    for &[a, b, c] in &source.indices {
        let (pa, pb, pc) = (points[a as usize], points[b as usize], points[c as usize]);
        let area2 = (pb - pa).cross(pc - pa).length_squared();
        let valid = [pa, pb, pc].into_iter().all(valid_world_point);
        if valid && area2 > 0.0 && area2.is_finite() {
            indices.push(if mirrored { [a, c, b] } else { [a, b, c] });
        } else {
            dropped += 1;
        }
    }
    // Unreferenced vertices may hold NaN; Embree never reads them, but keep the buffer clean.
    let positions = points
        .into_iter()
        .map(|p| {
            let local = (p - origin).as_vec3();
            if valid_world_point(p) && local.is_finite() {
                local.to_array()
            } else {
                [0.0; 3]
            }
        })
        .collect();
    let mesh = WorldMesh {
        positions,
        normals,
        texcoords: source.texcoords.clone(),
        indices,
        material,
    };
    (mesh, dropped)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sys::scene_io::GltfInstance;

    fn triangle(size: f32) -> GltfMesh {
        GltfMesh {
            positions: vec![[0.0, 0.0, 0.0], [size, 0.0, 0.0], [0.0, size, 0.0]],
            normals: None,
            texcoords: None,
            indices: vec![[0, 1, 2]],
            material: None,
        }
    }

    /// Relative to the tracing origin a small triangle 1e7 units out keeps its shape exactly
    /// as it has at glTF's origin (a power-of-two size, so nothing rounds).
    #[test]
    fn far_meshes_are_placed_relative_to_the_tracing_origin() {
        let far = DVec3::new(1e7, -3e6, 5e6);
        let world = DMat4::from_translation(far);
        let (mesh, dropped) = place_mesh(&triangle(0.25), world, far, 0);
        assert_eq!(dropped, 0);
        assert_eq!(
            mesh.positions,
            vec![[0.0, 0.0, 0.0], [0.25, 0.0, 0.0], [0.0, 0.25, 0.0]]
        );
    }

    #[test]
    fn the_origin_moves_only_for_scenes_away_from_it() {
        let scene = |offset: [f64; 3]| GltfScene {
            meshes: vec![triangle(2.0)],
            instances: vec![GltfInstance {
                mesh: 0,
                world: DMat4::from_translation(DVec3::from(offset)).to_cols_array(),
                node: 0,
                node_name: String::new(),
            }],
            ..Default::default()
        };
        // Around glTF's origin: unchanged, so such scenes render exactly as before.
        assert_eq!(tracing_origin(&scene([-1.0, -0.5, 0.0])), DVec3::ZERO);
        // Far out: the bounds' centre.
        assert_eq!(tracing_origin(&scene([1e6, 0.0, 0.0])), DVec3::new(1e6 + 1.0, 1.0, 0.0));
    }
}

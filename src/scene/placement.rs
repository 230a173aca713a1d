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
/// the scene is large. `surveyed[i]`, when there, is glTF instance i's bounds (`Survey::used`)
/// already computed.
pub fn tracing_origin(gltf: &GltfScene, surveyed: &[Option<Bounds>]) -> DVec3 {
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for (i, instance) in gltf.instances.iter().enumerate() {
        let (l, h) = match surveyed.get(i).copied().flatten() {
            Some(b) => b,
            None => {
                let source = &gltf.meshes[instance.mesh];
                used_bounds(source, &world_points(source, &DMat4::from_cols_array(&instance.world)))
            }
        };
        lo = lo.min(l);
        hi = hi.max(h);
    }
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

/// World-space bounds, lowest and highest corner (empty: +inf, -inf).
pub type Bounds = (DVec3, DVec3);

const EMPTY: Bounds = (DVec3::INFINITY, DVec3::NEG_INFINITY);

/// Bounds of the valid points any triangle uses (what the tracing origin is the centre of).
fn used_bounds(source: &GltfMesh, points: &[DVec3]) -> Bounds {
    let (mut lo, mut hi) = EMPTY;
    for i in source.indices.iter().flatten() {
        let p = points[*i as usize];
        if valid_world_point(p) {
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    (lo, hi)
}

/// Whether a placed triangle can be traced: finite, in-range corners and an area in world
/// space (f64, before any rounding to f32).
fn triangle_kept(pa: DVec3, pb: DVec3, pc: DVec3) -> bool {
    let area2 = (pb - pa).cross(pc - pa).length_squared();
    let valid = [pa, pb, pc].into_iter().all(valid_world_point);
    valid && area2 > 0.0 && area2.is_finite()
}

/// A world point in the renderer's coordinates: relative to `origin`, rounded to f32. Zero for
/// a point no kept triangle can use (non-finite or out of range).
pub fn tracing_point(p: DVec3, origin: DVec3) -> [f32; 3] {
    let local = (p - origin).as_vec3();
    if valid_world_point(p) && local.is_finite() {
        local.to_array()
    } else {
        [0.0; 3]
    }
}

/// What placing a mesh by a transform keeps, found without copying it (the survey
/// `instancing` decides by): the bounds of the points its triangles use (for the tracing
/// origin), whether it keeps exactly the triangles the mesh's first placement keeps, and if so
/// the bounds of their corners, from which a copy's f32 bounds follow (`tracing_bounds`). It
/// does not depend on the tracing origin.
#[derive(Clone, Copy, Debug)]
pub struct PlacementSurvey {
    pub used: Bounds,
    /// It keeps the first placement's triangles (the first one always does).
    pub regular: bool,
    /// The bounds of the kept triangles' corners (of a regular placement; else empty).
    pub kept_bounds: Bounds,
}

/// A mesh's first placement, which the others are compared with: the triangles it keeps, the
/// vertices any triangle uses and those its kept triangles use.
pub struct Reference {
    pub kept: Vec<bool>,
    referenced: Vec<bool>,
    corner: Vec<bool>,
}

/// Surveys the first placement of `source`, by `world`.
pub fn survey_first(source: &GltfMesh, world: &DMat4) -> (Reference, PlacementSurvey) {
    let mut points = Vec::new();
    placed_points(source, world, &mut points);
    let kept: Vec<bool> = source.indices.iter().map(|t| area_kept(&points, t)).collect();
    let mut referenced = vec![false; source.positions.len()];
    let mut corner = vec![false; source.positions.len()];
    for (tri, &k) in source.indices.iter().zip(&kept) {
        for &i in tri {
            referenced[i as usize] = true;
            corner[i as usize] |= k;
        }
    }
    let reference = Reference {
        kept,
        referenced,
        corner,
    };
    let survey = bounds_of(&points, &reference, true);
    (reference, survey)
}

/// Surveys a further placement of `source`, by `world`, against the first one's `reference`
/// (`points`: a buffer to reuse). One pass over the vertices and one over the triangles, with
/// the test `place_mesh` makes.
pub fn survey_next(
    source: &GltfMesh,
    world: &DMat4,
    reference: &Reference,
    points: &mut Vec<DVec3>,
) -> PlacementSurvey {
    placed_points(source, world, points);
    let regular = (source.indices.iter().zip(&reference.kept)).all(|(t, &k)| area_kept(points, t) == k);
    bounds_of(points, reference, regular)
}

/// The mesh's points placed in world space (f64). Points no triangle may use become NaN: a
/// triangle with one has a NaN area, and is dropped by the area test alone (`area_kept`), as
/// `triangle_kept` drops it.
fn placed_points(source: &GltfMesh, world: &DMat4, points: &mut Vec<DVec3>) {
    points.clear();
    points.extend(source.positions.iter().map(|p| {
        let w = world.transform_point3(DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64));
        if valid_world_point(w) { w } else { DVec3::NAN }
    }));
}

fn area_kept(points: &[DVec3], &[a, b, c]: &[u32; 3]) -> bool {
    let (pa, pb, pc) = (points[a as usize], points[b as usize], points[c as usize]);
    let area2 = (pb - pa).cross(pc - pa).length_squared();
    area2 > 0.0 && area2.is_finite()
}

fn bounds_of(points: &[DVec3], reference: &Reference, regular: bool) -> PlacementSurvey {
    let (mut used, mut kept_bounds) = (EMPTY, EMPTY);
    for ((p, &r), &c) in points.iter().zip(&reference.referenced).zip(&reference.corner) {
        if r && !p.is_nan() {
            used = (used.0.min(*p), used.1.max(*p));
            if regular && c {
                kept_bounds = (kept_bounds.0.min(*p), kept_bounds.1.max(*p));
            }
        }
    }
    PlacementSurvey {
        used,
        regular,
        kept_bounds,
    }
}

/// The f32 bounds, in tracing coordinates, of points whose world bounds are `bounds`: rounding
/// (p - origin) to f32 never reverses an order, so the rounded bounds are the bounds of the
/// rounded points, exactly as the copy's are computed from its f32 corners.
pub fn tracing_bounds(bounds: Bounds, origin: DVec3) -> (Vec3, Vec3) {
    let round = |p: DVec3| Vec3::from(tracing_point(p, origin));
    if bounds.0.x > bounds.1.x {
        return (Vec3::INFINITY, Vec3::NEG_INFINITY);
    }
    (round(bounds.0), round(bounds.1))
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
        if triangle_kept(points[a as usize], points[b as usize], points[c as usize]) {
            indices.push(if mirrored { [a, c, b] } else { [a, b, c] });
        } else {
            dropped += 1;
        }
    }
    // Unreferenced vertices may hold NaN; Embree never reads them, but keep the buffer clean.
    let positions = points.into_iter().map(|p| tracing_point(p, origin)).collect();
    let mesh = WorldMesh {
        positions,
        normals,
        texcoords: source.texcoords.clone(),
        indices,
        material,
        object: 0,
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
        assert_eq!(tracing_origin(&scene([-1.0, -0.5, 0.0]), &[]), DVec3::ZERO);
        // Far out: the bounds' centre.
        assert_eq!(
            tracing_origin(&scene([1e6, 0.0, 0.0]), &[]),
            DVec3::new(1e6 + 1.0, 1.0, 0.0)
        );
    }
}

//! The scene in Embree, and what a ray query means for shading: hit points with their normals,
//! texture coordinates and material, and shadow tests that let partly transparent surfaces
//! through.

use crate::scene::Scene;
use crate::scene::instancing::{self, HitTriangle};
pub use crate::sys::embree::PACKET;
use crate::sys::embree::{self, Coherence, Device, InstanceData, TriangleMeshData};
use crate::sys::prefetch::prefetch;
use glam::{DVec3, Vec3};
use std::sync::Arc;

pub struct Tracer {
    embree: embree::Scene,
    /// Distance rays start off a surface, relative to the scene's size.
    scale_epsilon: f32,
    shadows: Shadows,
    /// Each world mesh's triangles' `SurfaceHit::uv_per_length` (empty without texture
    /// coordinates or a texture to read them), so that `plain_texcoords` needs no corner of
    /// the triangle.
    uv_per_length: Vec<Box<[f32]>>,
    pub embree_version: String,
}

/// How a shadow ray is tested (`Tracer::transmittance`): a scene pays for see-through
/// surfaces only where it has them.
enum Shadows {
    /// No material can be see-through: one occlusion query, which stops at the first blocker.
    Opaque,
    /// The ray walks its hits through the whole scene, closest first, reading each one's
    /// opacity: where see-through surfaces are in shared (instanced) meshes, or Embree was
    /// built without ray masks.
    Walk,
    /// One occlusion query that sees only the opaque meshes (`OPAQUE_MASK`), then, if nothing
    /// blocked it, a walk through the see-through meshes alone, a scene of their own whose
    /// geometry `k` is the scene's mesh `meshes[k]`. Most shadow rays of a scene with a few
    /// see-through surfaces then stop at their first blocker and read no material, as in an
    /// opaque scene.
    Split {
        see_through: embree::Scene,
        meshes: Vec<u32>,
    },
}

/// Embree masks of the meshes no material makes see-through, and of the others (`Shadows`).
const OPAQUE_MASK: u32 = 1;
const SEE_THROUGH_MASK: u32 = 2;

/// A ray's closest hit, ready for shading.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceHit {
    pub position: Vec3,
    pub distance: f32,
    /// Unit normal of the triangle by its winding (the front side).
    pub geometric_normal: Vec3,
    /// Unit shading normal, turned to the side the ray came from.
    pub normal: Vec3,
    /// The geometric normal turned to the side the ray came from.
    pub facing_normal: Vec3,
    pub uv: Option<[f32; 2]>,
    /// Texture-coordinate units per unit of length on the triangle hit (the square root of
    /// the ratio of its areas in texture and in world space): how wide in the texture a
    /// footprint is. 0 without texture coordinates.
    pub uv_per_length: f32,
    pub material: u32,
    /// The object (placed mesh: `WorldMesh::object`, `Placement::object`) hit.
    pub object: u32,
    pub prim_id: u32,
}

/// What a hit tells without its triangle's corners (`Tracer::plain_hit`): enough to read the
/// last bounce's grid there, for surfaces whose light at that level is their albedo times the
/// grid's (`Material::is_plain_diffuse`).
#[derive(Clone, Copy, Debug)]
pub struct PlainHit {
    /// Along the ray, at Embree's distance (not from the corners by the barycentrics).
    pub position: Vec3,
    pub distance: f32,
    /// The triangle's unit normal (Embree's, not the corners' shading normals), turned to the
    /// side the ray came from.
    pub facing_normal: Vec3,
    /// The shading normal, turned to the side the ray came from, as `SurfaceHit::normal`.
    pub normal: Vec3,
    pub material: u32,
}

/// Texture-coordinate units per unit of length on the triangle of `corners` and `texcoords`
/// (`SurfaceHit::uv_per_length`): the square root of the ratio of its areas in texture and in
/// world space; 0 where that is not finite.
fn uv_per_length(corners: [Vec3; 3], texcoords: [[f32; 2]; 3]) -> f32 {
    let [pa, pb, pc] = corners;
    let [ta, tb, tc] = texcoords;
    let across = (pb - pa).cross(pc - pa);
    let (e1, e2) = ([tb[0] - ta[0], tb[1] - ta[1]], [tc[0] - ta[0], tc[1] - ta[1]]);
    let uv_area = (e1[0] * e2[1] - e1[1] * e2[0]).abs();
    let ratio = (uv_area / across.length()).sqrt();
    if ratio.is_finite() { ratio } else { 0.0 }
}

/// A triangle's unit `normal` turned to the side a ray along `dir` comes from.
fn facing(normal: Vec3, dir: Vec3) -> Vec3 {
    if normal.dot(dir) > 0.0 { -normal } else { normal }
}

/// The texture coordinates at barycentrics (u, v) of a triangle whose corners have `texcoords`.
fn interpolated_uv([ta, tb, tc]: [[f32; 2]; 3], u: f32, v: f32) -> [f32; 2] {
    let w = 1.0 - u - v;
    [w * ta[0] + u * tb[0] + v * tc[0], w * ta[1] + u * tb[1] + v * tc[1]]
}

/// The shading normal at barycentrics (u, v) of a triangle whose corners have `normals`, kept
/// on the side the ray sees (`facing_normal`'s); `facing_normal` itself where the corners have
/// none or they cancel out.
fn shading_normal(normals: Option<[Vec3; 3]>, u: f32, v: f32, facing_normal: Vec3) -> Vec3 {
    let Some([na, nb, nc]) = normals else {
        return facing_normal;
    };
    match ((1.0 - u - v) * na + u * nb + v * nc).try_normalize() {
        Some(n) if n.dot(facing_normal) < 0.0 => -n,
        Some(n) => n,
        None => facing_normal,
    }
}

#[cfg(test)]
impl SurfaceHit {
    /// A test's hit on a floor (normal +y everywhere) at `position`, `distance` from where the
    /// ray left, of material 0 and `object`, without texture coordinates.
    pub fn on_floor(position: Vec3, distance: f32, object: u32) -> SurfaceHit {
        SurfaceHit {
            position,
            distance,
            geometric_normal: Vec3::Y,
            normal: Vec3::Y,
            facing_normal: Vec3::Y,
            uv: None,
            uv_per_length: 0.0,
            material: 0,
            object,
            prim_id: 0,
        }
    }
}

impl SurfaceHit {
    /// Whether two hits lie on one plane (as far as a record or a pixel's corners are
    /// concerned): normals within about 8 degrees, and each within 2 % of their distance from
    /// the other's tangent plane.
    pub fn on_plane_of(&self, other: &SurfaceHit) -> bool {
        let offset = other.position - self.position;
        self.normal.dot(other.normal) > 0.99 && offset.dot(self.normal).abs() <= 0.02 * offset.length()
    }
}

/// Passes through transparent surfaces a single ray may make before we call it blocked;
/// bounds the loop on pathological stacks of coplanar cut-outs.
const MAX_TRANSPARENT_PASSES: u32 = 64;

impl Tracer {
    /// Builds the BVHs: the copied meshes and, per prototype of shared meshes, a scene of its
    /// members placed by an instance per placement (geometry ids: the copied meshes, then the
    /// prototype instances in order).
    pub fn new(scene: &Scene) -> Result<Tracer, embree::EmbreeError> {
        let device = Arc::new(Device::new()?);
        let shared = &scene.instancing;
        let see_through = |material: u32| scene.materials[material as usize].may_be_transparent();
        let shared_see_through = (shared.prototypes.iter()).any(|p| {
            p.members
                .iter()
                .any(|&m| see_through(shared.meshes[m as usize].material))
        });
        let split = scene.needs().transparency
            && !shared_see_through
            && scene.meshes.iter().any(|m| see_through(m.material))
            && device.supports_ray_masks();
        let meshes: Vec<TriangleMeshData<'_>> = scene
            .meshes
            .iter()
            .map(|m| TriangleMeshData {
                positions: &m.positions,
                indices: &m.indices,
                mask: match (split, see_through(m.material)) {
                    (false, _) => embree::ALL_MASKS,
                    (true, false) => OPAQUE_MASK,
                    (true, true) => SEE_THROUGH_MASK,
                },
            })
            .collect();
        let prototypes = (shared.prototypes.iter())
            .map(|proto| {
                // The members' vertices in the prototype's space: Embree's copy, the only one
                // besides the shared mesh itself.
                let positions: Vec<Vec<[f32; 3]>> = (proto.members.iter().zip(&proto.to_prototype))
                    .map(|(&m, to)| {
                        (shared.meshes[m as usize].positions.iter())
                            .map(|p| to.transform_point3(DVec3::from(p.map(f64::from))).as_vec3().to_array())
                            .collect()
                    })
                    .collect();
                let members: Vec<TriangleMeshData<'_>> = (proto.members.iter().zip(&positions))
                    .map(|(&m, positions)| TriangleMeshData {
                        positions,
                        indices: &shared.meshes[m as usize].indices,
                        mask: embree::ALL_MASKS,
                    })
                    .collect();
                embree::Scene::build(&device, &members).map(Arc::new)
            })
            .collect::<Result<Vec<_>, _>>()?;
        let instances: Vec<InstanceData<'_>> = (shared.instances.iter())
            .map(|i| InstanceData {
                prototype: &prototypes[i.prototype as usize],
                transform: instancing::embree_transform(&i.to_tracing),
            })
            .collect();
        let embree_scene = embree::Scene::build_with_instances(&device, &meshes, &instances)?;
        let shadows = if !scene.needs().transparency {
            Shadows::Opaque
        } else if split {
            let chosen: Vec<u32> = (0..meshes.len() as u32)
                .filter(|&i| meshes[i as usize].mask == SEE_THROUGH_MASK)
                .collect();
            let members: Vec<TriangleMeshData<'_>> = (chosen.iter())
                .map(|&i| TriangleMeshData {
                    mask: embree::ALL_MASKS,
                    ..meshes[i as usize]
                })
                .collect();
            Shadows::Split {
                see_through: embree::Scene::build(&device, &members)?,
                meshes: chosen,
            }
        } else {
            Shadows::Walk
        };
        // Only where a texture reads the coordinates (`plain_texcoords`' only callers).
        let textured =
            |mesh: &crate::scene::WorldMesh| scene.materials[mesh.material as usize].base_color_texture.is_some();
        let uv_per_length = (scene.meshes.iter())
            .map(|mesh| match &mesh.texcoords {
                Some(t) if textured(mesh) => (mesh.indices.iter())
                    .map(|&[a, b, c]| {
                        let [a, b, c] = [a, b, c].map(|i| i as usize);
                        let corners = [a, b, c].map(|i| Vec3::from(mesh.positions[i]));
                        uv_per_length(corners, [t[a], t[b], t[c]])
                    })
                    .collect(),
                _ => Box::default(),
            })
            .collect();
        Ok(Tracer {
            embree: embree_scene,
            scale_epsilon: 1e-5 * scene.size(),
            shadows,
            uv_per_length,
            embree_version: device.version(),
        })
    }

    /// Offset from a surface point along a normal so a new ray does not hit its own surface;
    /// proportional to the scene's size and to the point's magnitude (float precision).
    #[inline]
    pub fn epsilon_at(&self, p: Vec3) -> f32 {
        self.scale_epsilon + 4e-6 * p.abs().max_element()
    }

    /// Origin for a ray leaving `hit` towards direction `dir`.
    #[inline]
    pub fn spawn_point(&self, hit: &SurfaceHit, dir: Vec3) -> Vec3 {
        let side = if dir.dot(hit.geometric_normal) >= 0.0 {
            1.0
        } else {
            -1.0
        };
        hit.position + hit.geometric_normal * (side * self.epsilon_at(hit.position))
    }

    /// Embree's hit alone, before the surface point is made from it (`surface_hit`): a batch's
    /// rays are all traced before any of their hits is read.
    pub fn nearest_hit(&self, org: Vec3, dir: Vec3, coherence: Coherence) -> Option<embree::RayHit> {
        self.embree
            .intersect(org.to_array(), dir.to_array(), 0.0, f32::INFINITY, coherence)
    }

    /// Starts loading the corner indices of the triangle `hit` found (`surface_hit`'s first
    /// read), for a batch whose hits are read a little later.
    #[inline]
    pub fn prefetch_triangle(&self, scene: &Scene, hit: &embree::RayHit) {
        if hit.instance.is_none() {
            prefetch(&scene.meshes[hit.geom_id as usize].indices[hit.prim_id as usize]);
        }
    }

    /// Starts loading the corners' positions, normals and texture coordinates of the triangle
    /// `hit` found (reads its indices: best after `prefetch_triangle` had time to bring them).
    #[inline]
    pub fn prefetch_corners(&self, scene: &Scene, hit: &embree::RayHit) {
        if hit.instance.is_none() {
            let mesh = &scene.meshes[hit.geom_id as usize];
            for i in mesh.indices[hit.prim_id as usize] {
                prefetch(&mesh.positions[i as usize]);
                if let Some(normals) = &mesh.normals {
                    prefetch(&normals[i as usize]);
                }
                if let Some(texcoords) = &mesh.texcoords {
                    prefetch(&texcoords[i as usize]);
                }
            }
        }
    }

    pub fn intersect(&self, scene: &Scene, org: Vec3, dir: Vec3, coherence: Coherence) -> Option<SurfaceHit> {
        self.intersect_within(scene, org, dir, f32::INFINITY, coherence)
    }

    fn intersect_within(
        &self,
        scene: &Scene,
        org: Vec3,
        dir: Vec3,
        tfar: f32,
        coherence: Coherence,
    ) -> Option<SurfaceHit> {
        let hit = self
            .embree
            .intersect(org.to_array(), dir.to_array(), 0.0, tfar, coherence)?;
        Some(self.surface_hit(scene, &hit, dir))
    }

    /// The surface point Embree's `hit` along `dir` found: position, normals, texture
    /// coordinates, material and object.
    pub fn surface_hit(&self, scene: &Scene, hit: &embree::RayHit, dir: Vec3) -> SurfaceHit {
        let (triangle, object) = match hit.instance {
            None => {
                let mesh = &scene.meshes[hit.geom_id as usize];
                let [a, b, c] = mesh.indices[hit.prim_id as usize].map(|i| i as usize);
                let triangle = HitTriangle {
                    corners: [a, b, c].map(|i| Vec3::from(mesh.positions[i])),
                    normals: mesh.normals.as_ref().map(|ns| [ns[a], ns[b], ns[c]]),
                    texcoords: mesh.texcoords.as_ref().map(|t| [t[a], t[b], t[c]]),
                    u: hit.u,
                    v: hit.v,
                    material: mesh.material,
                };
                (triangle, mesh.object)
            }
            Some(instance) => {
                let shared = &scene.instancing;
                let p = shared.placement_of(instance - scene.meshes.len() as u32, hit.geom_id);
                let triangle = shared.hit_triangle(p, hit.prim_id, hit.u, hit.v, scene.origin);
                (triangle, shared.placements[p as usize].object)
            }
        };
        let HitTriangle {
            corners: [pa, pb, pc],
            u,
            v,
            ..
        } = triangle;
        let w = 1.0 - u - v;
        let position = w * pa + u * pb + v * pc;
        let across = (pb - pa).cross(pc - pa);
        let geometric_normal = across.try_normalize().unwrap_or(-dir);
        let facing_normal = facing(geometric_normal, dir);
        let normal = shading_normal(triangle.normals, u, v, facing_normal);
        let uv = triangle.texcoords.map(|texcoords| interpolated_uv(texcoords, u, v));
        let uv_per_length = triangle
            .texcoords
            .map_or(0.0, |texcoords| uv_per_length([pa, pb, pc], texcoords));
        SurfaceHit {
            position,
            distance: hit.t,
            geometric_normal,
            normal,
            facing_normal,
            uv,
            uv_per_length,
            material: triangle.material,
            object,
            prim_id: hit.prim_id,
        }
    }

    /// What Embree's `hit` of the ray from `org` along unit `dir` tells without the triangle's
    /// corners: the point along the ray, the triangle's normal from Embree, and the shading
    /// normal. A hit's loads that miss the processor's caches are its corners', normals' and
    /// texture coordinates' (`surface_hit`); this reads the normals alone, `plain_texcoords`
    /// the texture coordinates. None through an instance (whose hits need the placement's
    /// transform) or on a triangle without a normal.
    pub fn plain_hit(&self, scene: &Scene, hit: &embree::RayHit, org: Vec3, dir: Vec3) -> Option<PlainHit> {
        if hit.instance.is_some() {
            return None;
        }
        let facing_normal = facing(Vec3::from(hit.ng).try_normalize()?, dir);
        let mesh = &scene.meshes[hit.geom_id as usize];
        let corners = mesh.indices[hit.prim_id as usize];
        let normals = mesh.normals.as_ref().map(|ns| corners.map(|i| ns[i as usize]));
        Some(PlainHit {
            position: org + dir * hit.t,
            distance: hit.t,
            facing_normal,
            normal: shading_normal(normals, hit.u, hit.v, facing_normal),
            material: mesh.material,
        })
    }

    /// The texture coordinates at a hit `plain_hit` answered for, and the texture's units per
    /// length there (`SurfaceHit::uv_per_length`), as `surface_hit` gives them; None on a mesh
    /// without texture coordinates or whose material reads no texture.
    pub fn plain_texcoords(&self, scene: &Scene, hit: &embree::RayHit) -> Option<([f32; 2], f32)> {
        let mesh = &scene.meshes[hit.geom_id as usize];
        let t = mesh.texcoords.as_ref()?;
        let uv_per_length = *self.uv_per_length[hit.geom_id as usize].get(hit.prim_id as usize)?;
        let texcoords = mesh.indices[hit.prim_id as usize].map(|i| t[i as usize]);
        Some((interpolated_uv(texcoords, hit.u, hit.v), uv_per_length))
    }

    /// Fraction of light that gets from `org` along unit `dir` over `distance` (1 unobstructed,
    /// 0 blocked). Only scenes with transparent materials pay for walking through hits; each
    /// query past the first (the walk's, or the walk after the opaque geometry's test) is
    /// added to `continued`.
    pub fn transmittance(&self, scene: &Scene, org: Vec3, dir: Vec3, distance: f32, continued: &mut u64) -> f32 {
        let Some(mask) = self.opaque_mask() else {
            let (through, queries) = self.walk_through(scene, &self.embree, None, (org, dir, distance));
            *continued += queries - 1;
            return through;
        };
        if self
            .embree
            .occluded_masked(org.to_array(), dir.to_array(), 0.0, distance, mask)
        {
            0.0
        } else {
            self.past_the_opaque(scene, (org, dir, distance), continued)
        }
    }

    /// `transmittance` for up to `PACKET` rays at once (origin, unit direction, distance),
    /// into `through`. A full packet's rays have the opaque geometry's test as one packet
    /// (`embree::Scene::occluded_packet`); fewer go one at a time, as a packet half empty cost
    /// more than it saved (the Cornell box, 8 samples a pixel of 4 shadow rays each: the render
    /// at 1.017x the time with them in packets of 4; 32 rays a point, packets of 8: 0.96x).
    pub fn transmittances(&self, scene: &Scene, rays: &[(Vec3, Vec3, f32)], through: &mut [f32], continued: &mut u64) {
        let mask = match self.opaque_mask() {
            Some(mask) if rays.len() == PACKET => mask,
            _ => {
                for (t, &(o, d, r)) in through.iter_mut().zip(rays) {
                    *t = self.transmittance(scene, o, d, r, continued);
                }
                return;
            }
        };
        let mut packet = [([0.0f32; 3], [0.0f32; 3], 0.0f32); PACKET];
        for (p, &(o, d, t)) in packet.iter_mut().zip(rays) {
            *p = (o.to_array(), d.to_array(), t);
        }
        let mut blocked = [false; PACKET];
        self.embree.occluded_packet(&packet, mask, &mut blocked);
        for ((t, b), &ray) in through.iter_mut().zip(blocked).zip(rays) {
            *t = if b {
                0.0
            } else {
                self.past_the_opaque(scene, ray, continued)
            };
        }
    }

    /// The mask of the geometry a shadow ray's first query tests as blockers (every geometry,
    /// or the opaque ones where the see-through ones are a scene of their own); None where
    /// the ray walks through everything (`Shadows::Walk`).
    fn opaque_mask(&self) -> Option<u32> {
        match &self.shadows {
            Shadows::Opaque => Some(embree::ALL_MASKS),
            Shadows::Split { .. } => Some(OPAQUE_MASK),
            Shadows::Walk => None,
        }
    }

    /// What passes along a shadow ray the opaque geometry did not block: all of it, or what the
    /// see-through surfaces let through (their walk's queries counted in `continued`).
    fn past_the_opaque(&self, scene: &Scene, ray: (Vec3, Vec3, f32), continued: &mut u64) -> f32 {
        match &self.shadows {
            Shadows::Split { see_through, meshes } => {
                let (through, queries) = self.walk_through(scene, see_through, Some(meshes), ray);
                *continued += queries;
                through
            }
            _ => 1.0,
        }
    }

    /// The product of (1 - opacity) over the surfaces of `embree` the ray (origin, unit
    /// direction, distance) passes, closest first, 0 once one blocks it, and the queries it
    /// took (at least one). `meshes` names the scene's mesh of each of `embree`'s geometries
    /// where they are not the scene's own ids.
    fn walk_through(
        &self,
        scene: &Scene,
        embree: &embree::Scene,
        meshes: Option<&[u32]>,
        (org, dir, distance): (Vec3, Vec3, f32),
    ) -> (f32, u64) {
        let mut through = 1.0;
        let mut origin = org;
        let mut left = distance;
        for queries in 1..=MAX_TRANSPARENT_PASSES as u64 {
            let found = embree.intersect(origin.to_array(), dir.to_array(), 0.0, left, Coherence::Incoherent);
            let Some(mut found) = found else {
                return (through, queries);
            };
            if let Some(meshes) = meshes {
                found.geom_id = meshes[found.geom_id as usize];
            }
            let hit = self.surface_hit(scene, &found, dir);
            let material = &scene.materials[hit.material as usize];
            let opacity = material.at(hit.uv, &scene.textures).opacity;
            through *= 1.0 - opacity;
            if through <= 0.0 {
                return (0.0, queries);
            }
            let next = self.spawn_point(&hit, dir);
            left -= (next - origin).dot(dir);
            origin = next;
            if left <= 0.0 {
                return (through, queries);
            }
        }
        (0.0, MAX_TRANSPARENT_PASSES as u64)
    }

    /// Distance to the first surface along a unit direction (for the automatic view).
    pub fn hit_distance(&self, org: Vec3, dir: Vec3) -> Option<f32> {
        self.embree
            .intersect(
                org.to_array(),
                dir.to_array(),
                0.0,
                f32::INFINITY,
                Coherence::Incoherent,
            )
            .map(|h| h.t)
    }

    /// Whether any surface lies on the segment between two points (for the automatic view).
    pub fn segment_blocked(&self, from: Vec3, to: Vec3) -> bool {
        let d = to - from;
        let len = d.length();
        len > 0.0 && self.embree.occluded(from.to_array(), (d / len).to_array(), 0.0, len)
    }

    /// The raw Embree query, for the ray-throughput bench.
    pub fn raw_intersect(&self, org: Vec3, dir: Vec3, coherence: Coherence) -> Option<embree::RayHit> {
        self.embree
            .intersect(org.to_array(), dir.to_array(), 0.0, f32::INFINITY, coherence)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Rng;
    use crate::scene::WorldMesh;
    use crate::scene::material::Material;

    /// A folded sheet of triangles of uneven sizes, with texture coordinates stretched
    /// unevenly over it and bent shading normals, for comparing what a hit reads.
    fn folded_sheet() -> Scene {
        let (columns, rows) = (7u32, 5u32);
        let mut positions = Vec::new();
        let mut texcoords = Vec::new();
        let mut normals = Vec::new();
        for j in 0..=rows {
            for i in 0..=columns {
                let (x, z) = ((i as f32).powf(1.3), j as f32 * 0.8);
                positions.push([x, (x * 0.9).sin() + 0.3 * z, z]);
                texcoords.push([0.37 * x + 0.05 * z, 0.21 * z * z]);
                normals.push(Vec3::new(-0.4 * (x * 0.9).cos(), 1.0, -0.2).normalize());
            }
        }
        let at = |i: u32, j: u32| j * (columns + 1) + i;
        let indices = (0..rows)
            .flat_map(|j| {
                (0..columns).flat_map(move |i| {
                    [
                        [at(i, j), at(i + 1, j), at(i + 1, j + 1)],
                        [at(i, j), at(i + 1, j + 1), at(i, j + 1)],
                    ]
                })
            })
            .collect();
        let mesh = WorldMesh {
            positions,
            normals: Some(normals),
            texcoords: Some(texcoords),
            indices,
            material: 0,
            object: 0,
        };
        // A material that reads a texture there (none is loaded: only the coordinates matter).
        let mut material = Material::gltf_default();
        material.base_color_texture = Some(0);
        Scene::of_parts(vec![material], vec![mesh], Vec::new())
    }

    /// `plain_hit` and `plain_texcoords` read what `surface_hit` gives, but for the point
    /// and the facing normal, taken along the ray and from Embree (a rounding apart).
    #[test]
    fn a_plain_hit_reads_what_the_full_surface_point_gives() {
        let scene = folded_sheet();
        let tracer = Tracer::new(&scene).unwrap();
        let mut rng = Rng::new(3, 9);
        let mut hits = 0;
        for _ in 0..2000 {
            let org = Vec3::new(12.0 * rng.next_f32() - 1.0, 6.0, 5.0 * rng.next_f32() - 0.5);
            let dir = Vec3::new(rng.next_f32() - 0.5, -1.0, rng.next_f32() - 0.5).normalize();
            let Some(found) = tracer.nearest_hit(org, dir, Coherence::Incoherent) else {
                continue;
            };
            hits += 1;
            let full = tracer.surface_hit(&scene, &found, dir);
            let plain = tracer.plain_hit(&scene, &found, org, dir).unwrap();
            let (uv, uv_per_length) = tracer.plain_texcoords(&scene, &found).unwrap();
            assert_eq!(Some(uv), full.uv);
            assert_eq!(uv_per_length, full.uv_per_length);
            assert!(uv_per_length > 0.0);
            assert_eq!(plain.material, full.material);
            assert_eq!(plain.distance, found.t);
            let scale = 1.0 + full.position.abs().max_element();
            assert!(
                (plain.position - full.position).length() < 1e-5 * scale,
                "{plain:?} {full:?}"
            );
            assert!(
                (plain.facing_normal - full.facing_normal).length() < 1e-5,
                "{plain:?} {full:?}"
            );
            assert!((plain.normal - full.normal).length() < 1e-6, "{plain:?} {full:?}");
        }
        assert!(hits > 800, "{hits} hits");
        // Where no texture reads the coordinates, none are read.
        let mut untextured = folded_sheet();
        untextured.materials[0].base_color_texture = None;
        let tracer = Tracer::new(&untextured).unwrap();
        let found = tracer
            .nearest_hit(Vec3::new(3.0, 6.0, 2.0), Vec3::NEG_Y, Coherence::Incoherent)
            .unwrap();
        assert!(tracer.plain_texcoords(&untextured, &found).is_none());
    }
}

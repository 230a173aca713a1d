//! The scene in Embree, and what a ray query means for shading: hit points with their normals,
//! texture coordinates and material, and shadow tests that let partly transparent surfaces
//! through.

use crate::scene::Scene;
use crate::sys::embree::{self, Coherence, Device, TriangleMeshData};
use glam::Vec3;
use std::sync::Arc;

pub struct Tracer {
    embree: embree::Scene,
    /// Distance rays start off a surface, relative to the scene's size.
    scale_epsilon: f32,
    transparency: bool,
    pub embree_version: String,
}

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
    pub material: u32,
    pub geom_id: u32,
    pub prim_id: u32,
}

/// Passes through transparent surfaces a single ray may make before we call it blocked;
/// bounds the loop on pathological stacks of coplanar cut-outs.
const MAX_TRANSPARENT_PASSES: u32 = 64;

impl Tracer {
    pub fn new(scene: &Scene) -> Result<Tracer, embree::EmbreeError> {
        let device = Arc::new(Device::new()?);
        let meshes: Vec<TriangleMeshData<'_>> = scene
            .meshes
            .iter()
            .map(|m| TriangleMeshData {
                positions: &m.positions,
                indices: &m.indices,
            })
            .collect();
        let embree_scene = embree::Scene::build(&device, &meshes)?;
        Ok(Tracer {
            embree: embree_scene,
            scale_epsilon: 1e-5 * scene.size(),
            transparency: scene.needs().transparency,
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
        let mesh = &scene.meshes[hit.geom_id as usize];
        let [a, b, c] = mesh.indices[hit.prim_id as usize];
        let (a, b, c) = (a as usize, b as usize, c as usize);
        let (u, v) = (hit.u, hit.v);
        let w = 1.0 - u - v;
        let p = |i: usize| Vec3::from(mesh.positions[i]);
        let position = w * p(a) + u * p(b) + v * p(c);
        let geometric_normal = (p(b) - p(a)).cross(p(c) - p(a)).try_normalize().unwrap_or(-dir);
        let toward_ray = if geometric_normal.dot(dir) > 0.0 { -1.0 } else { 1.0 };
        let facing_normal = geometric_normal * toward_ray;
        let mut normal = facing_normal;
        if let Some(ns) = &mesh.normals {
            let interpolated = w * ns[a] + u * ns[b] + v * ns[c];
            if let Some(n) = interpolated.try_normalize() {
                // Keep the shading normal on the side the ray sees.
                normal = if n.dot(facing_normal) < 0.0 { -n } else { n };
            }
        }
        let uv = mesh.texcoords.as_ref().map(|t| {
            let (ta, tb, tc) = (t[a], t[b], t[c]);
            [w * ta[0] + u * tb[0] + v * tc[0], w * ta[1] + u * tb[1] + v * tc[1]]
        });
        Some(SurfaceHit {
            position,
            distance: hit.t,
            geometric_normal,
            normal,
            facing_normal,
            uv,
            material: mesh.material,
            geom_id: hit.geom_id,
            prim_id: hit.prim_id,
        })
    }

    /// Fraction of light that gets from `org` along unit `dir` over `distance` (1 unobstructed,
    /// 0 blocked). Only scenes with transparent materials pay for walking through hits.
    pub fn transmittance(&self, scene: &Scene, org: Vec3, dir: Vec3, distance: f32) -> f32 {
        if !self.transparency {
            return if self.embree.occluded(org.to_array(), dir.to_array(), 0.0, distance) {
                0.0
            } else {
                1.0
            };
        }
        let mut through = 1.0;
        let mut origin = org;
        let mut left = distance;
        for _ in 0..MAX_TRANSPARENT_PASSES {
            let Some(hit) = self.intersect_within(scene, origin, dir, left, Coherence::Incoherent) else {
                return through;
            };
            let material = &scene.materials[hit.material as usize];
            let opacity = material.at(hit.uv, &scene.textures).opacity;
            through *= 1.0 - opacity;
            if through <= 0.0 {
                return 0.0;
            }
            let next = self.spawn_point(&hit, dir);
            left -= (next - origin).dot(dir);
            origin = next;
            if left <= 0.0 {
                return through;
            }
        }
        0.0
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

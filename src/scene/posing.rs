//! Frames of animations that move meshes and lights: the file's meshes and lights placed again
//! where the animations put them at a frame's time, and what moved since the last pose (which
//! the irradiance cache needs to know, `irradiance::temporal`).
//!
//! The renderer's coordinates keep the rest pose's origin (the loader's) for the whole sequence
//! (records and views are stored in them), and a node nothing animates keeps the loader's own world matrix,
//! bit for bit: a frame's static meshes are exactly the still render's.

use super::animation::{Mat4, Rig};
use super::{Geometry, Scene, instancing, names, punctual_lights};
use crate::sys::scene_io::{GltfLight, GltfScene};
use glam::{DMat4, DVec3, Vec3};

/// An axis-aligned box in the renderer's coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub lo: Vec3,
    pub hi: Vec3,
}

impl Aabb {
    /// The box of the finite points among `points` (None without one).
    pub fn around(points: impl IntoIterator<Item = Vec3>) -> Option<Aabb> {
        points
            .into_iter()
            .filter(|p| p.is_finite())
            .fold(None, |b: Option<Aabb>, p| {
                let point = Aabb { lo: p, hi: p };
                Some(b.map_or(point, |b| b.union(&point)))
            })
    }

    pub fn centre(&self) -> Vec3 {
        0.5 * (self.lo + self.hi)
    }

    pub fn union(&self, other: &Aabb) -> Aabb {
        Aabb {
            lo: self.lo.min(other.lo),
            hi: self.hi.max(other.hi),
        }
    }

    /// The box grown by `by` on every side.
    pub fn grown(&self, by: f32) -> Aabb {
        Aabb {
            lo: self.lo - Vec3::splat(by),
            hi: self.hi + Vec3::splat(by),
        }
    }

    /// The part of the box inside `to` (None where they do not meet).
    pub fn clipped(&self, to: &Aabb) -> Option<Aabb> {
        let c = Aabb {
            lo: self.lo.max(to.lo),
            hi: self.hi.min(to.hi),
        };
        c.lo.cmple(c.hi).all().then_some(c)
    }

    pub fn contains(&self, p: Vec3) -> bool {
        self.lo.cmple(p).all() && p.cmple(self.hi).all()
    }

    pub fn meets(&self, other: &Aabb) -> bool {
        self.lo.cmple(other.hi).all() && other.lo.cmple(self.hi).all()
    }

    pub fn corners(&self) -> [Vec3; 8] {
        std::array::from_fn(|i| {
            Vec3::new(
                if i & 1 == 0 { self.lo.x } else { self.hi.x },
                if i & 2 == 0 { self.lo.y } else { self.hi.y },
                if i & 4 == 0 { self.lo.z } else { self.hi.z },
            )
        })
    }
}

/// What placing the scene again needs: the loaded file without its textures (the scene keeps
/// them converted), each instance's and light's world matrix at rest, and the pose now placed.
pub struct PoseSource {
    gltf: GltfScene,
    flatten: bool,
    rest_instances: Vec<[f64; 16]>,
    /// Per mesh of the file: its vertices' box in its own space (None: no finite vertex).
    mesh_bounds: Vec<Option<(DVec3, DVec3)>>,
    /// The time the scene is placed at now (None: the rest pose the loader gave).
    placed_at: Option<f64>,
}

/// What moved between two poses.
#[derive(Clone, Debug, Default)]
pub struct PoseChange {
    /// Per placed mesh that moved: its box before and after, in the renderer's coordinates.
    pub moved: Vec<(Aabb, Aabb)>,
    /// Whether a light moved: a punctual light, or a mesh with an emissive material.
    pub lights_moved: bool,
}

impl PoseChange {
    pub fn is_empty(&self) -> bool {
        self.moved.is_empty() && !self.lights_moved
    }
}

impl PoseSource {
    pub fn of(mut gltf: GltfScene, flatten: bool) -> PoseSource {
        gltf.textures = Vec::new();
        let mesh_bounds = gltf
            .meshes
            .iter()
            .map(|m| {
                let finite = m.positions.iter().filter(|p| p.iter().all(|c| c.is_finite()));
                finite.fold(None, |b: Option<(DVec3, DVec3)>, p| {
                    let p = DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                    Some(b.map_or((p, p), |(lo, hi)| (lo.min(p), hi.max(p))))
                })
            })
            .collect();
        PoseSource {
            rest_instances: gltf.instances.iter().map(|i| i.world).collect(),
            gltf,
            flatten,
            mesh_bounds,
            placed_at: None,
        }
    }

    /// Instance `i`'s world matrix at `time`: the rest matrix where nothing animates its node,
    /// else its node's animated world matrix (times the instance's own transform under the node,
    /// for EXT_mesh_gpu_instancing's several placements of one node).
    fn instance_world(&self, rig: &Rig, i: usize, time: f64) -> [f64; 16] {
        let instance = &self.gltf.instances[i];
        let rest = self.rest_instances[i];
        if !rig.moves(instance.node) {
            return rest;
        }
        let node_rest = rig.rest_world(instance.node);
        let node_now = rig.world_at(instance.node, time);
        if node_rest == rest {
            return node_now;
        }
        let under_node = DMat4::from_cols_array(&node_rest).inverse() * DMat4::from_cols_array(&rest);
        (DMat4::from_cols_array(&node_now) * under_node).to_cols_array()
    }

    /// Light `l` placed by its node's world matrix at `time` (position, and the node's -Z).
    fn light_at(rig: &Rig, light: &GltfLight, time: f64) -> GltfLight {
        let mut placed = light.clone();
        if rig.moves(light.node) {
            let world: Mat4 = rig.world_at(light.node, time);
            placed.position = [world[12], world[13], world[14]];
            placed.direction = super::animation::transform_dir(&world, 0.0, 0.0, -1.0);
        }
        placed
    }

    /// The box of instance `i` placed by `world`, in the renderer's coordinates.
    fn instance_box(&self, i: usize, world: &[f64; 16], origin: DVec3) -> Option<Aabb> {
        let (lo, hi) = self.mesh_bounds[self.gltf.instances[i].mesh]?;
        let m = DMat4::from_cols_array(world);
        Aabb::around((0..8).map(|corner| {
            let local = DVec3::new(
                if corner & 1 == 0 { lo.x } else { hi.x },
                if corner & 2 == 0 { lo.y } else { hi.y },
                if corner & 4 == 0 { lo.z } else { hi.z },
            );
            (m.transform_point3(local) - origin).as_vec3()
        }))
    }
}

impl Scene {
    /// Places the meshes and lights where the animations put them at `time`, and says what
    /// moved since the pose placed before. Nothing is done (and nothing said to have moved)
    /// without a pose source, or when nothing the animations move changes.
    pub fn pose_at(&mut self, time: f64) -> PoseChange {
        let Some(mut source) = self.pose_source.take() else {
            return PoseChange::default();
        };
        let change = self.place_pose(&mut source, time);
        self.pose_source = Some(source);
        change
    }

    fn place_pose(&mut self, source: &mut PoseSource, time: f64) -> PoseChange {
        let mut change = PoseChange::default();
        if source.placed_at == Some(time) {
            return change;
        }
        source.placed_at = Some(time);
        for i in 0..source.gltf.instances.len() {
            let world = source.instance_world(&self.rig, i, time);
            let before = source.gltf.instances[i].world;
            if world == before {
                continue;
            }
            if let (Some(a), Some(b)) = (
                source.instance_box(i, &before, self.origin),
                source.instance_box(i, &world, self.origin),
            ) {
                change.moved.push((a, b));
            }
            let material = source.gltf.meshes[source.gltf.instances[i].mesh].material;
            let default_material = self.materials.len() - 1;
            if self.materials[material.unwrap_or(default_material)].is_emissive() {
                change.lights_moved = true;
            }
            source.gltf.instances[i].world = world;
        }
        for l in 0..source.gltf.lights.len() {
            let placed = PoseSource::light_at(&self.rig, &source.gltf.lights[l], time);
            let light = &mut source.gltf.lights[l];
            if placed.position != light.position || placed.direction != light.direction {
                change.lights_moved = true;
                *light = placed;
            }
        }
        if change.is_empty() {
            return change;
        }
        let gltf = &source.gltf;
        let surveys = instancing::Surveys::of(gltf, source.flatten);
        let default_material = self.materials.len() as u32 - 1;
        let geometry = Geometry::place(gltf, surveys, self.origin, &self.materials, default_material);
        self.meshes = geometry.meshes;
        self.instancing = geometry.instancing;
        self.emitters = super::light::EmitterSet::new(geometry.emitter_triangles);
        self.bounds_min = geometry.bounds_min;
        self.bounds_max = geometry.bounds_max;
        self.dropped_triangles = geometry.dropped;
        let materials = std::mem::take(&mut self.names.materials);
        self.names = names::Names::new(geometry.object_names, materials);
        self.punctual_lights = punctual_lights(&gltf.lights, self.origin).0;
        change
    }
}

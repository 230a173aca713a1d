//! The scene as the renderer sees it: world-space triangle meshes (meshes used once) and
//! placements of shared meshes (meshes used more than once, see `instancing`), with their
//! materials, textures, light sources, cameras and bounds, built from a loaded glTF file.

pub mod animation;
pub mod auto_view;
pub mod footprint;
pub mod instancing;
pub mod lambert;
pub mod light;
pub mod light_tree;
pub mod material;
pub mod names;
pub mod placement;
pub mod posing;
pub mod texture;
pub mod view;

use crate::sys::scene_io::{self, GltfCamera, GltfScene};
use glam::{DMat4, DVec3, Vec3};
use light::{EmitterSet, EmitterTriangle, PunctualLight};
use material::Material;
use std::path::{Path, PathBuf};
use texture::Texture;

/// Coordinates beyond this magnitude are treated like NaN: f32 arithmetic on them (squared
/// distances, cross products) overflows, so no ray query could be trusted near them.
pub const MAX_COORDINATE: f32 = 1e15;

#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct SceneError {
    pub path: PathBuf,
    pub message: String,
}

/// How a scene is read.
#[derive(Clone, Debug)]
pub struct LoadOptions {
    /// Radiance's -st: specular reflectance below which no specular ray is traced.
    pub specular_threshold: f32,
    /// Every material becomes a two-sided Lambertian of its base colour.
    pub lambertian: bool,
    /// Let the file refer to buffers and images outside its own folder (refused by default:
    /// a scene from anywhere must not read files anywhere).
    pub allow_outside_refs: bool,
    /// Bytes the loaded scene may take (--max-memory); None: the machine's memory.
    pub max_memory: Option<u64>,
    /// Copy every placement of a mesh used more than once into world space, as meshes used
    /// once are, instead of instancing it (`--flatten`: for comparison).
    pub flatten: bool,
    /// Keep what re-placing the meshes and lights at another time needs (`posing`): for
    /// frames of animations that move them.
    pub keep_pose_source: bool,
}

impl Default for LoadOptions {
    fn default() -> Self {
        LoadOptions {
            specular_threshold: material::DEFAULT_SPECULAR_THRESHOLD,
            lambertian: false,
            allow_outside_refs: false,
            max_memory: None,
            flatten: false,
            keep_pose_source: false,
        }
    }
}

/// One placed mesh in world space; index = Embree geometry id.
#[derive(Clone, Debug)]
pub struct WorldMesh {
    pub positions: Vec<[f32; 3]>,
    pub normals: Option<Vec<Vec3>>,
    pub texcoords: Option<Vec<[f32; 2]>>,
    pub indices: Vec<[u32; 3]>,
    pub material: u32,
    /// The object (Cryptomatte, `SurfaceHit::object`) it is.
    pub object: u32,
}

pub struct Scene {
    pub path: PathBuf,
    /// Meshes copied into world space (every mesh used once; all with `--flatten`).
    pub meshes: Vec<WorldMesh>,
    /// Meshes used more than once, stored once, and their placements.
    pub instancing: instancing::Instancing,
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
    pub punctual_lights: Vec<PunctualLight>,
    pub emitters: EmitterSet,
    /// Cameras as the file places them, in world coordinates (`to_tracing` for the renderer's).
    pub cameras: Vec<GltfCamera>,
    /// The node trees' rest poses and animations (`camera_at` places a camera at a time).
    pub rig: animation::Rig,
    /// The world point the renderer's coordinates are relative to (the bounds' centre; see
    /// `placement`): meshes, lights, bounds and views are all stored relative to it.
    pub origin: DVec3,
    pub bounds_min: Vec3,
    pub bounds_max: Vec3,
    pub dropped_triangles: usize,
    pub warnings: Vec<String>,
    /// Names and Cryptomatte IDs of each mesh's node and of each material.
    pub names: names::Names,
    /// With `LoadOptions::keep_pose_source`, what re-placing the meshes and lights at another
    /// time of the animations needs (`posing`); None otherwise.
    pub pose_source: Option<Box<posing::PoseSource>>,
}

/// What the scene can produce, so no layer, pass or ray is spent on what it cannot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SceneNeeds {
    pub emission: bool,
    pub direct: bool,
    pub specular: bool,
    pub diffuse: bool,
    pub transparency: bool,
}

impl Scene {
    pub fn load(path: &Path, options: &LoadOptions) -> Result<Scene, SceneError> {
        let fail = |message: String| SceneError {
            path: path.to_path_buf(),
            message,
        };
        if !path.exists() {
            return Err(fail("no such file".into()));
        }
        if path.is_dir() {
            return Err(fail("is a directory, not a glTF file".into()));
        }
        let gltf =
            scene_io::load_gltf(path, options.allow_outside_refs, options.max_memory, options.flatten).map_err(fail)?;
        Scene::from_gltf(path, gltf, options).map_err(fail)
    }

    fn from_gltf(path: &Path, gltf: GltfScene, options: &LoadOptions) -> Result<Scene, String> {
        let mut materials: Vec<Material> = gltf
            .materials
            .iter()
            .map(|m| Material::from_gltf(m, options.specular_threshold))
            .collect();
        let default_material = materials.len() as u32;
        materials.push(Material::gltf_default());
        let mut material_names: Vec<String> = (gltf.materials.iter().enumerate())
            .map(|(i, m)| names::material_name(&m.name, i))
            .collect();
        material_names.push(names::DEFAULT_MATERIAL.to_string());
        if options.lambertian {
            materials.iter_mut().for_each(Material::make_lambertian);
        }
        let textures: Vec<Texture> = gltf.textures.iter().map(Texture::from_gltf).collect();
        let mut warnings = gltf.warnings.clone();

        let surveys = instancing::Surveys::of(&gltf, options.flatten);
        let origin = placement::tracing_origin(&gltf, &surveys.used_bounds());
        let geometry = Geometry::place(&gltf, surveys, origin, &materials, default_material);
        if geometry.dropped > 0 {
            warnings.push(format!(
                "dropped {} triangle(s) with zero area or non-finite or out-of-range coordinates",
                geometry.dropped
            ));
        }
        if geometry.meshes.is_empty() && geometry.instancing.is_empty() {
            return Err(if geometry.dropped > 0 {
                format!(
                    "no valid triangles: all {} were degenerate or had non-finite or out-of-range coordinates",
                    geometry.dropped
                )
            } else {
                "the scene has no triangles".into()
            });
        }
        let (punctual_lights, ignored) = punctual_lights(&gltf.lights, origin);
        warnings.extend(ignored);
        let rig = animation::Rig::new(gltf.nodes.clone(), gltf.channels.clone());
        let cameras = gltf.cameras.clone();
        Ok(Scene {
            path: path.to_path_buf(),
            meshes: geometry.meshes,
            instancing: geometry.instancing,
            materials,
            textures,
            punctual_lights,
            emitters: EmitterSet::new(geometry.emitter_triangles),
            cameras,
            rig,
            origin,
            bounds_min: geometry.bounds_min,
            bounds_max: geometry.bounds_max,
            dropped_triangles: geometry.dropped,
            warnings,
            names: names::Names::new(geometry.object_names, material_names),
            pose_source: options
                .keep_pose_source
                .then(|| Box::new(posing::PoseSource::of(gltf, options.flatten))),
        })
    }

    /// Camera `index` as the animations place it at `time` (seconds): its node's world
    /// matrix evaluated as the loader evaluates the rest pose's, so a camera nothing animates
    /// is exactly where the file puts it.
    pub fn camera_at(&self, index: usize, time: f64) -> GltfCamera {
        let mut camera = self.cameras[index].clone();
        let world = self.rig.world_at(camera.node, time);
        camera.position = [world[12], world[13], world[14]];
        camera.forward = animation::transform_dir(&world, 0.0, 0.0, -1.0);
        camera.up = animation::transform_dir(&world, 0.0, 1.0, 0.0);
        camera
    }

    /// Triangles in the scene, each placement of a shared mesh counting its own.
    pub fn triangle_count(&self) -> usize {
        self.meshes.iter().map(|m| m.indices.len()).sum::<usize>() + self.instancing.placed_triangles()
    }

    /// Triangles stored and built into BVHs: a shared mesh's once.
    pub fn stored_triangle_count(&self) -> usize {
        self.meshes.iter().map(|m| m.indices.len()).sum::<usize>() + self.instancing.stored_triangles()
    }

    /// Placed meshes (objects): the copied meshes and the placements of shared ones.
    pub fn placed_mesh_count(&self) -> usize {
        self.meshes.len() + self.instancing.placements.len()
    }

    /// Every placed mesh in world space, in object order: the copied ones as they are, the
    /// placements of shared meshes copied one at a time (for writing the scene out).
    pub fn each_placed_mesh(&self, mut f: impl FnMut(&WorldMesh)) {
        let mut shared = (0..self.instancing.placements.len() as u32).peekable();
        for mesh in &self.meshes {
            while let Some(p) = shared.next_if(|&p| self.instancing.placements[p as usize].object < mesh.object) {
                f(&self.instancing.flattened(p, self.origin));
            }
            f(mesh);
        }
        for p in shared {
            f(&self.instancing.flattened(p, self.origin));
        }
    }

    /// Which materials some placed mesh uses, by material index.
    pub fn used_materials(&self) -> Vec<bool> {
        let mut used = vec![false; self.materials.len()];
        self.meshes.iter().for_each(|m| used[m.material as usize] = true);
        (self.instancing.placements.iter())
            .for_each(|p| used[self.instancing.meshes[p.mesh as usize].material as usize] = true);
        used
    }

    /// Bytes the scene's geometry and textures take in memory.
    pub fn memory_bytes(&self) -> u64 {
        let mesh = |m: &WorldMesh| {
            m.positions.len() * 12
                + m.normals.as_ref().map_or(0, |n| n.len() * std::mem::size_of::<Vec3>())
                + m.texcoords.as_ref().map_or(0, |t| t.len() * 8)
                + m.indices.len() * 12
        };
        self.meshes.iter().map(|m| mesh(m) as u64).sum::<u64>()
            + self.instancing.memory_bytes()
            + self.textures.iter().map(Texture::memory_bytes).sum::<u64>()
    }

    /// Length of the bounding box's diagonal: the scale every tolerance is relative to.
    /// A world point (a camera, a -vp) in the renderer's coordinates.
    pub fn to_tracing(&self, world: DVec3) -> Vec3 {
        (world - self.origin).as_vec3()
    }

    /// A point of the renderer's in world coordinates (what the user gave and sees).
    pub fn to_world(&self, p: Vec3) -> DVec3 {
        self.origin + p.as_dvec3()
    }

    pub fn size(&self) -> f32 {
        (self.bounds_max - self.bounds_min).length().max(f32::MIN_POSITIVE)
    }

    /// Side of the bounding cube (the largest extent), the scene size Radiance's -ar divides:
    /// Radiance takes its octree's cube, which encloses the scene the same way.
    pub fn cube_size(&self) -> f32 {
        (self.bounds_max - self.bounds_min).max_element().max(f32::MIN_POSITIVE)
    }

    pub fn has_lights(&self) -> bool {
        !self.emitters.is_empty() || !self.punctual_lights.is_empty()
    }

    pub fn needs(&self) -> SceneNeeds {
        let used: Vec<&Material> = {
            let seen = self.used_materials();
            self.materials
                .iter()
                .zip(seen)
                .filter(|(_, s)| *s)
                .map(|(m, _)| m)
                .collect()
        };
        SceneNeeds {
            emission: !self.emitters.is_empty(),
            direct: self.has_lights(),
            specular: used
                .iter()
                .any(|m| m.traces_specular || m.alpha_mode == scene_io::AlphaMode::Blend),
            diffuse: used.iter().any(|m| m.max_diffuse() > 0.0),
            transparency: used.iter().any(|m| m.may_be_transparent()),
        }
    }

    pub fn name(&self) -> String {
        self.path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default()
    }
}

/// The punctual lights of the file in the renderer's coordinates, and a warning for each one
/// that cannot be placed.
fn punctual_lights(lights: &[scene_io::GltfLight], origin: DVec3) -> (Vec<PunctualLight>, Vec<String>) {
    let mut placed = Vec::new();
    let mut warnings = Vec::new();
    for l in lights {
        match PunctualLight::from_gltf(l, origin) {
            Some(light) => placed.push(light),
            None => warnings.push(format!("light '{}' ignored: non-finite position or direction", l.name)),
        }
    }
    (placed, warnings)
}

/// The scene's triangles as one pose of the file places them: the meshes copied into the
/// renderer's coordinates, the shared ones' placements, the emitting triangles, the bounds
/// and the objects' names (a frame of an animation re-places them, `posing`).
pub(crate) struct Geometry {
    pub meshes: Vec<WorldMesh>,
    pub instancing: instancing::Instancing,
    pub emitter_triangles: Vec<EmitterTriangle>,
    pub bounds_min: Vec3,
    pub bounds_max: Vec3,
    pub dropped: usize,
    pub object_names: Vec<String>,
}

impl Geometry {
    pub fn place(
        gltf: &GltfScene,
        surveys: instancing::Surveys,
        origin: DVec3,
        materials: &[Material],
        default_material: u32,
    ) -> Geometry {
        let plan = instancing::plan(gltf, &surveys, origin, default_material);
        drop(surveys);
        let mut shared = plan.instancing;
        let mut meshes = Vec::new();
        // What every placement of a shared mesh drops counts once per placement, as copies do.
        let mut dropped = (shared.placements.iter())
            .map(|p| shared.meshes[p.mesh as usize].dropped)
            .sum::<usize>();
        let mut emitter_triangles = Vec::new();
        let mut object_names = Vec::new();
        let mut bounds_min = Vec3::splat(f32::INFINITY);
        let mut bounds_max = Vec3::splat(f32::NEG_INFINITY);
        // Objects, bounds and emitters in the file's order whether a mesh is copied or shared,
        // so that the light tree and the names are those of the flattened scene.
        for (instance, role) in gltf.instances.iter().zip(&plan.roles) {
            let object = object_names.len() as u32;
            let mesh = match *role {
                instancing::Role::Placed(p) => {
                    let placement = &mut shared.placements[p as usize];
                    placement.object = object;
                    let (lo, hi) = plan.bounds[p as usize];
                    bounds_min = bounds_min.min(lo);
                    bounds_max = bounds_max.max(hi);
                    let material = shared.meshes[placement.mesh as usize].material;
                    if materials[material as usize].is_emissive() {
                        // One light per placement: its triangles in world space (few; the
                        // geometry traced is not copied).
                        let copy = shared.flattened(p, origin);
                        collect_emitters(&copy, materials[material as usize].emission, &mut emitter_triangles);
                    }
                    object_names.push(names::node_name(&instance.node_name, instance.node));
                    continue;
                }
                instancing::Role::Flatten => {
                    let source = &gltf.meshes[instance.mesh];
                    let material = source.material.map_or(default_material, |m| m as u32);
                    let world = DMat4::from_cols_array(&instance.world);
                    let (mut mesh, dropped_here) = placement::place_mesh(source, world, origin, material);
                    dropped += dropped_here;
                    mesh.object = object;
                    mesh
                }
            };
            if mesh.indices.is_empty() {
                continue;
            }
            object_names.push(names::node_name(&instance.node_name, instance.node));
            for tri in &mesh.indices {
                for &i in tri {
                    let p = Vec3::from(mesh.positions[i as usize]);
                    bounds_min = bounds_min.min(p);
                    bounds_max = bounds_max.max(p);
                }
            }
            let m = &materials[mesh.material as usize];
            if m.is_emissive() {
                collect_emitters(&mesh, m.emission, &mut emitter_triangles);
            }
            meshes.push(mesh);
        }
        Geometry {
            meshes,
            instancing: shared,
            emitter_triangles,
            bounds_min,
            bounds_max,
            dropped,
            object_names,
        }
    }
}

fn collect_emitters(mesh: &WorldMesh, radiance: Vec3, out: &mut Vec<EmitterTriangle>) {
    for (prim_id, &[a, b, c]) in mesh.indices.iter().enumerate() {
        let p0 = Vec3::from(mesh.positions[a as usize]);
        let e1 = Vec3::from(mesh.positions[b as usize]) - p0;
        let e2 = Vec3::from(mesh.positions[c as usize]) - p0;
        let cross = e1.cross(e2);
        let area = 0.5 * cross.length();
        if let Some(normal) = cross.try_normalize().filter(|_| area > 0.0 && area.is_finite()) {
            out.push(EmitterTriangle {
                p0,
                e1,
                e2,
                normal,
                area,
                radiance,
                object: mesh.object,
                prim_id: prim_id as u32,
            });
        }
    }
}

#[cfg(test)]
impl Scene {
    /// A scene of world-space meshes, materials and punctual lights made in a test, its bounds
    /// those of the meshes; no emitters are sampled and no camera is set.
    pub fn of_parts(materials: Vec<Material>, meshes: Vec<WorldMesh>, lights: Vec<PunctualLight>) -> Scene {
        let points = meshes.iter().flat_map(|m| m.positions.iter().map(|&p| Vec3::from(p)));
        let (lo, hi) = points.fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p), hi.max(p))
        });
        Scene {
            path: "test.gltf".into(),
            meshes,
            instancing: Default::default(),
            materials,
            textures: Vec::new(),
            punctual_lights: lights,
            emitters: EmitterSet::default(),
            cameras: Vec::new(),
            rig: Default::default(),
            origin: DVec3::ZERO,
            bounds_min: lo,
            bounds_max: hi,
            dropped_triangles: 0,
            warnings: Vec::new(),
            names: Default::default(),
            pose_source: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sys::scene_io::GltfMesh;
    use placement::place_mesh;

    fn quad_mesh() -> GltfMesh {
        GltfMesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
                [f32::NAN, 0.0, 0.0],
            ],
            normals: None,
            texcoords: None,
            indices: vec![[0, 1, 2], [0, 2, 3], [0, 0, 1], [0, 1, 4], [1, 2, 2]],
            material: None,
        }
    }

    #[test]
    fn drops_degenerate_and_nan_triangles() {
        let (mesh, dropped) = place_mesh(&quad_mesh(), DMat4::IDENTITY, DVec3::ZERO, 0);
        assert_eq!(mesh.indices.len(), 2);
        assert_eq!(dropped, 3);
        assert!(mesh.positions.iter().flatten().all(|v| v.is_finite()));
    }

    #[test]
    fn mirroring_keeps_the_front_side() {
        let mirror = DMat4::from_scale(DVec3::new(-1.0, 1.0, 1.0));
        let (mesh, _) = place_mesh(&quad_mesh(), mirror, DVec3::ZERO, 0);
        let mut emitters = Vec::new();
        collect_emitters(&mesh, Vec3::ONE, &mut emitters);
        // The unmirrored quad faces +Z by winding; mirroring in X must not turn it to -Z.
        assert!(emitters.iter().all(|e| e.normal.z > 0.99));
    }
}

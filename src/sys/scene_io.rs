//! Safe wrapper over the C++ glTF loader: copies everything the loader hands back into owned
//! Rust values, so no pointer into C++ memory outlives the call.

use super::abi_bindings as abi;
use super::{ERR_LEN, buffer_message, owned_string, slice_or_empty};
use std::ffi::CString;
use std::path::Path;

/// A mesh primitive in object space, exactly as the file describes it.
#[derive(Clone, Debug, Default)]
pub struct GltfMesh {
    pub positions: Vec<[f32; 3]>,
    pub normals: Option<Vec<[f32; 3]>>,
    pub texcoords: Option<Vec<[f32; 2]>>,
    pub indices: Vec<[u32; 3]>,
    pub material: Option<usize>,
}

#[derive(Clone, Debug)]
pub struct GltfInstance {
    pub mesh: usize,
    /// Column-major 4x4 world matrix.
    pub world: [f64; 16],
    /// The glTF node that places it, and its name ("" when unnamed).
    pub node: usize,
    pub node_name: String,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AlphaMode {
    Opaque,
    Mask,
    Blend,
}

#[derive(Clone, Debug)]
pub struct GltfMaterial {
    pub name: String,
    pub base_color: [f32; 4],
    pub base_color_texture: Option<usize>,
    pub metallic: f32,
    pub roughness: f32,
    pub emissive: [f32; 3],
    pub emissive_strength: f32,
    pub specular_factor: f32,
    pub specular_color: [f32; 3],
    pub alpha_mode: AlphaMode,
    pub alpha_cutoff: f32,
    pub double_sided: bool,
}

#[derive(Clone, Debug)]
pub struct GltfTexture {
    pub name: String,
    pub rgba: Vec<u8>,
    pub width: u32,
    pub height: u32,
    pub wrap_s: i32,
    pub wrap_t: i32,
    pub srgb: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LightType {
    Point,
    Spot,
    Directional,
}

#[derive(Clone, Debug)]
pub struct GltfLight {
    pub name: String,
    pub kind: LightType,
    pub color: [f32; 3],
    pub intensity: f32,
    pub range: f32,
    pub inner_cone: f32,
    pub outer_cone: f32,
    pub position: [f64; 3],
    pub direction: [f32; 3],
    /// The glTF node that places it (an index into `GltfScene::nodes`).
    pub node: usize,
}

#[derive(Clone, Debug)]
pub struct GltfCamera {
    pub name: String,
    pub perspective: bool,
    pub yfov: f32,
    pub aspect: f32,
    pub xmag: f32,
    pub ymag: f32,
    pub position: [f64; 3],
    pub forward: [f32; 3],
    pub up: [f32; 3],
    /// The glTF node that places it (an index into `GltfScene::nodes`).
    pub node: usize,
}

/// What a node places itself (not its children).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Places {
    pub mesh: bool,
    pub light: bool,
    pub camera: bool,
    /// A joint of a skin that a placed mesh uses.
    pub joint: bool,
}

/// A node's local transform at rest, as the file gives it.
#[derive(Clone, Debug, PartialEq)]
pub enum LocalPose {
    /// Column-major (such a node may not be animated).
    Matrix([f64; 16]),
    /// Translation, rotation (x y z w, normalised) and scale.
    Trs {
        translation: [f64; 3],
        rotation: [f64; 4],
        scale: [f64; 3],
    },
}

/// A glTF node's rest pose and place in the tree, for evaluating animations.
#[derive(Clone, Debug)]
pub struct GltfNode {
    pub name: String,
    pub parent: Option<usize>,
    /// Whether the scene's node trees reach it (nodes outside place nothing).
    pub in_scene: bool,
    pub places: Places,
    pub pose: LocalPose,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AnimPath {
    Translation,
    Rotation,
    Scale,
    /// Morph target weights: not read (morph targets are not supported).
    Weights,
    /// A path of an extension: not read.
    Other,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interpolation {
    Linear,
    Step,
    CubicSpline,
}

/// One animation channel and its sampler's keys.
#[derive(Clone, Debug)]
pub struct GltfChannel {
    pub animation: usize,
    pub animation_name: String,
    /// The target node; None when the file's index is out of range (`error` says so).
    pub node: Option<usize>,
    pub path: AnimPath,
    pub interpolation: Interpolation,
    /// Key times in seconds, strictly increasing (checked by the loader).
    pub times: Vec<f32>,
    /// Values per key (`components` each; for CUBICSPLINE three per key: in-tangent, value,
    /// out-tangent).
    pub values: Vec<f32>,
    pub components: usize,
    /// Why the channel breaks glTF's rules (then it has no keys).
    pub error: Option<String>,
}

#[derive(Clone, Debug, Default)]
pub struct GltfScene {
    pub meshes: Vec<GltfMesh>,
    pub instances: Vec<GltfInstance>,
    pub materials: Vec<GltfMaterial>,
    pub textures: Vec<GltfTexture>,
    pub lights: Vec<GltfLight>,
    pub cameras: Vec<GltfCamera>,
    /// Every node of the file, in file order.
    pub nodes: Vec<GltfNode>,
    pub channels: Vec<GltfChannel>,
    pub warnings: Vec<String>,
}

/// Owns the C++ scene and frees it on every path out of `load_gltf`.
struct Handle(*mut abi::icr_scene);

impl Drop for Handle {
    fn drop(&mut self) {
        // SAFETY: the pointer came from icr_scene_load and is freed once.
        unsafe { abi::icr_scene_free(self.0) };
    }
}

/// Loads a glTF 2.0 file (.gltf or .glb). The error is the loader's one-line message; the caller
/// adds the file name.
/// `memory_limit`: bytes the loaded scene may take (None: only the machine's memory).
/// `flatten`: the caller will copy every placement of a mesh (the loader's memory estimate).
pub fn load_gltf(
    path: &Path,
    allow_outside_refs: bool,
    memory_limit: Option<u64>,
    flatten: bool,
) -> Result<GltfScene, String> {
    let c_path =
        CString::new(path.as_os_str().as_encoded_bytes()).map_err(|_| "path contains a NUL byte".to_string())?;
    let mut err = vec![0 as std::os::raw::c_char; ERR_LEN];
    let flags = if allow_outside_refs {
        abi::ICR_LOAD_ALLOW_OUTSIDE_REFS
    } else {
        0
    } | if flatten { abi::ICR_LOAD_FLATTEN } else { 0 };
    // SAFETY: valid C string and error buffer of the stated length.
    let raw = unsafe {
        abi::icr_scene_load(
            c_path.as_ptr(),
            flags,
            memory_limit.unwrap_or(0),
            err.as_mut_ptr(),
            err.len(),
        )
    };
    if raw.is_null() {
        return Err(buffer_message(&err));
    }
    let handle = Handle(raw);
    // SAFETY: the view's arrays are owned by `handle` and stay valid while it lives; every
    // array is copied out before it is dropped.
    unsafe { copy_scene(abi::icr_scene_get_view(handle.0)) }
}

/// # Safety
/// Every pointer in `view` is valid for the count beside it (the loader's contract).
unsafe fn copy_scene(view: abi::icr_scene_view) -> Result<GltfScene, String> {
    let mut scene = GltfScene::default();
    // SAFETY (whole block): counts and pointers come from the loader's contract.
    unsafe {
        for m in slice_or_empty(view.meshes, view.mesh_count) {
            let nv = m.vertex_count as usize;
            let nt = m.triangle_count as usize;
            let positions = slice_or_empty(m.positions as *const [f32; 3], nv).to_vec();
            let normals = (!m.normals.is_null()).then(|| slice_or_empty(m.normals as *const [f32; 3], nv).to_vec());
            let texcoords =
                (!m.texcoords.is_null()).then(|| slice_or_empty(m.texcoords as *const [f32; 2], nv).to_vec());
            let indices = slice_or_empty(m.indices as *const [u32; 3], nt).to_vec();
            if indices.iter().flatten().any(|&i| i as usize >= nv) {
                return Err("a triangle index is past the vertex count".into());
            }
            scene.meshes.push(GltfMesh {
                positions,
                normals,
                texcoords,
                indices,
                material: usize::try_from(m.material).ok(),
            });
        }
        for inst in slice_or_empty(view.instances, view.instance_count) {
            if inst.mesh as usize >= scene.meshes.len() {
                return Err(format!(
                    "instance refers to mesh {} of {}",
                    inst.mesh,
                    scene.meshes.len()
                ));
            }
            scene.instances.push(GltfInstance {
                mesh: inst.mesh as usize,
                world: inst.world,
                node: inst.node as usize,
                node_name: owned_string(inst.node_name),
            });
        }
        for t in slice_or_empty(view.textures, view.texture_count) {
            let len = 4 * t.width as usize * t.height as usize;
            scene.textures.push(GltfTexture {
                name: owned_string(t.name),
                rgba: slice_or_empty(t.rgba, len).to_vec(),
                width: t.width,
                height: t.height,
                wrap_s: t.wrap_s,
                wrap_t: t.wrap_t,
                srgb: t.srgb != 0,
            });
        }
        for m in slice_or_empty(view.materials, view.material_count) {
            let texture = usize::try_from(m.base_color_texture).ok();
            if texture.is_some_and(|t| t >= scene.textures.len()) {
                return Err(format!(
                    "material refers to texture {:?} of {}",
                    texture,
                    scene.textures.len()
                ));
            }
            scene.materials.push(GltfMaterial {
                name: owned_string(m.name),
                base_color: m.base_color,
                base_color_texture: texture,
                metallic: m.metallic,
                roughness: m.roughness,
                emissive: m.emissive,
                emissive_strength: m.emissive_strength,
                specular_factor: m.specular_factor,
                specular_color: m.specular_color,
                alpha_mode: match m.alpha_mode as u32 {
                    abi::icr_alpha_mode_ICR_ALPHA_MASK => AlphaMode::Mask,
                    abi::icr_alpha_mode_ICR_ALPHA_BLEND => AlphaMode::Blend,
                    _ => AlphaMode::Opaque,
                },
                alpha_cutoff: m.alpha_cutoff,
                double_sided: m.double_sided != 0,
            });
        }
        for l in slice_or_empty(view.lights, view.light_count) {
            scene.lights.push(GltfLight {
                name: owned_string(l.name),
                kind: match l.type_ as u32 {
                    abi::icr_light_type_ICR_LIGHT_SPOT => LightType::Spot,
                    abi::icr_light_type_ICR_LIGHT_DIRECTIONAL => LightType::Directional,
                    _ => LightType::Point,
                },
                color: l.color,
                intensity: l.intensity,
                range: l.range,
                inner_cone: l.inner_cone,
                outer_cone: l.outer_cone,
                position: l.position,
                direction: l.direction,
                node: l.node as usize,
            });
        }
        for c in slice_or_empty(view.cameras, view.camera_count) {
            scene.cameras.push(GltfCamera {
                name: owned_string(c.name),
                perspective: c.perspective != 0,
                yfov: c.yfov,
                aspect: c.aspect,
                xmag: c.xmag,
                ymag: c.ymag,
                position: c.position,
                forward: c.forward,
                up: c.up,
                node: c.node as usize,
            });
        }
        let node_count = view.node_count;
        for n in slice_or_empty(view.nodes, view.node_count) {
            let parent = usize::try_from(n.parent).ok();
            if parent.is_some_and(|p| p >= node_count) {
                return Err(format!(
                    "a node's parent {parent:?} is past the node count {node_count}"
                ));
            }
            scene.nodes.push(GltfNode {
                name: owned_string(n.name),
                parent,
                in_scene: n.in_scene != 0,
                places: Places {
                    mesh: n.places & abi::ICR_PLACES_MESH != 0,
                    light: n.places & abi::ICR_PLACES_LIGHT != 0,
                    camera: n.places & abi::ICR_PLACES_CAMERA != 0,
                    joint: n.places & abi::ICR_PLACES_JOINT != 0,
                },
                pose: if n.has_matrix != 0 {
                    LocalPose::Matrix(n.matrix)
                } else {
                    LocalPose::Trs {
                        translation: n.translation,
                        rotation: n.rotation,
                        scale: n.scale,
                    }
                },
            });
        }
        for c in slice_or_empty(view.channels, view.channel_count) {
            let node = (c.node != u32::MAX).then_some(c.node as usize);
            if node.is_some_and(|n| n >= node_count) {
                return Err(format!("an animation channel targets node {node:?} of {node_count}"));
            }
            let keys = c.key_count as usize;
            let components = c.components as usize;
            let interpolation = match c.interpolation as u32 {
                abi::icr_interpolation_ICR_INTERP_STEP => Interpolation::Step,
                abi::icr_interpolation_ICR_INTERP_CUBICSPLINE => Interpolation::CubicSpline,
                _ => Interpolation::Linear,
            };
            let per_key = if interpolation == Interpolation::CubicSpline {
                3
            } else {
                1
            };
            let (times, values) = if keys == 0 || c.times.is_null() || c.values.is_null() {
                (Vec::new(), Vec::new())
            } else {
                (
                    slice_or_empty(c.times, keys).to_vec(),
                    slice_or_empty(c.values, keys * per_key * components).to_vec(),
                )
            };
            scene.channels.push(GltfChannel {
                animation: c.animation as usize,
                animation_name: owned_string(c.animation_name),
                node,
                path: match c.path as u32 {
                    abi::icr_anim_path_ICR_ANIM_TRANSLATION => AnimPath::Translation,
                    abi::icr_anim_path_ICR_ANIM_ROTATION => AnimPath::Rotation,
                    abi::icr_anim_path_ICR_ANIM_SCALE => AnimPath::Scale,
                    abi::icr_anim_path_ICR_ANIM_WEIGHTS => AnimPath::Weights,
                    _ => AnimPath::Other,
                },
                interpolation,
                times,
                values,
                components,
                error: (!c.error.is_null()).then(|| owned_string(c.error)),
            });
        }
        let warnings = owned_string(view.warnings);
        scene.warnings = warnings
            .lines()
            .filter(|l| !l.trim().is_empty())
            .map(String::from)
            .collect();
    }
    for (i, m) in scene.meshes.iter().enumerate() {
        if m.material.is_some_and(|k| k >= scene.materials.len()) {
            return Err(format!(
                "mesh {i} refers to material {:?} of {}",
                m.material,
                scene.materials.len()
            ));
        }
    }
    Ok(scene)
}

//! glTF animations of node transforms, for rendering frames: a channel's sampler evaluated at a
//! time (glTF 2.0's LINEAR, with slerp for rotations, STEP and CUBICSPLINE; held at the first
//! and last key outside their range), and a node's world matrix at a time from the rest poses
//! of its ancestors and the channels that drive them.
//!
//! The matrices are computed the way the loader (cpp/scene_io_nodes.cpp) computes the rest pose's, in
//! the same order of operations, so that a node no channel drives gets exactly the world matrix
//! the loader gave it, and a render of frames matches a still render of the same pose.
//!
//! Cameras, meshes and lights move with their nodes (`scene::posing` places the meshes and
//! lights at a frame's time); `Rig::plan_frames` refuses animations that would deform a mesh
//! (morph targets, skins), which the renderer does not do.

use crate::sys::scene_io::{AnimPath, GltfChannel, GltfNode, Interpolation, LocalPose, Places};

/// Column-major 4x4, as glTF and the loader store matrices.
pub type Mat4 = [f64; 16];

const IDENTITY: Mat4 = [
    1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
];

/// a * b, summed in the loader's order.
fn mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut r = [0.0; 16];
    for c in 0..4 {
        for row in 0..4 {
            let mut s = 0.0;
            for k in 0..4 {
                s += a[k * 4 + row] * b[c * 4 + k];
            }
            r[c * 4 + row] = s;
        }
    }
    r
}

/// The unit direction `m` maps (x, y, z) to, as the loader computes a camera's axes (a singular
/// transform's zero or NaN vector is passed on for the view's check to refuse).
pub fn transform_dir(m: &Mat4, x: f64, y: f64, z: f64) -> [f32; 3] {
    let mut v = [0.0f64; 3];
    for (r, out) in v.iter_mut().enumerate() {
        *out = m[r] * x + m[4 + r] * y + m[8 + r] * z;
    }
    let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if len > 0.0 && len.is_finite() {
        v.iter_mut().for_each(|c| *c /= len);
    }
    v.map(|c| c as f32)
}

/// A translation, a unit rotation quaternion (x y z w) and a scale.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trs {
    pub translation: [f64; 3],
    pub rotation: [f64; 4],
    pub scale: [f64; 3],
}

impl Trs {
    /// T * R * S, as the loader builds a node's local matrix.
    pub fn matrix(&self) -> Mat4 {
        let (t, s) = (self.translation, self.scale);
        let [x, y, z, w] = self.rotation;
        let r = [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - z * w),
                2.0 * (x * z + y * w),
            ],
            [
                2.0 * (x * y + z * w),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - x * w),
            ],
            [
                2.0 * (x * z - y * w),
                2.0 * (y * z + x * w),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ];
        let mut m = [0.0; 16];
        for c in 0..3 {
            for row in 0..3 {
                m[c * 4 + row] = r[row][c] * s[c];
            }
        }
        m[12] = t[0];
        m[13] = t[1];
        m[14] = t[2];
        m[15] = 1.0;
        m
    }
}

/// A quaternion scaled to unit length as the loader does (one without length: identity).
fn normalised(q: [f64; 4]) -> [f64; 4] {
    let len = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    if len > 0.0 && len.is_finite() {
        q.map(|c| c / len)
    } else {
        [0.0, 0.0, 0.0, 1.0]
    }
}

/// Spherical linear interpolation from unit quaternion `a` (s = 0) to `b` (s = 1), the short
/// way round: q and -q are one rotation, and the long way would spin the camera through
/// more than half a turn between two keys that differ by a little.
pub fn slerp(a: [f64; 4], b: [f64; 4], s: f64) -> [f64; 4] {
    let mut dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];
    let b = if dot < 0.0 {
        dot = -dot;
        b.map(|c| -c)
    } else {
        b
    };
    // Nearly the same rotation: the sine below would divide by almost 0; a straight line
    // between them is as good (and normalised, a unit quaternion).
    let (wa, wb) = if dot > 1.0 - 1e-9 {
        (1.0 - s, s)
    } else {
        let angle = dot.min(1.0).acos();
        let sin = angle.sin();
        (((1.0 - s) * angle).sin() / sin, (s * angle).sin() / sin)
    };
    normalised([0, 1, 2, 3].map(|i| wa * a[i] + wb * b[i]))
}

/// A channel's value at `time` (seconds): 3 components (translation, scale) or 4 (rotation,
/// normalised). Before the first key the first key's value, after the last the last's.
pub fn sample(channel: &GltfChannel, time: f64) -> [f64; 4] {
    let n = channel.components;
    let cubic = channel.interpolation == Interpolation::CubicSpline;
    let per_key = if cubic { 3 } else { 1 };
    // Element `e` (0: in-tangent, 1: value, 2: out-tangent for CUBICSPLINE) of key `k`.
    let element = |k: usize, e: usize| -> [f64; 4] {
        let start = (k * per_key + if cubic { e } else { 0 }) * n;
        let mut v = [0.0; 4];
        for (i, out) in v.iter_mut().enumerate().take(n) {
            *out = channel.values[start + i] as f64;
        }
        v
    };
    let rotation = channel.path == AnimPath::Rotation;
    let finish = |v: [f64; 4]| if rotation { normalised(v) } else { v };
    let times = &channel.times;
    let last = times.len() - 1;
    // A NaN time is no time: the first key (frame times are checked finite before this).
    if time.is_nan() || time <= times[0] as f64 {
        return finish(element(0, 1));
    }
    if time >= times[last] as f64 {
        return finish(element(last, 1));
    }
    // The key before `time`: times[k] <= time < times[k + 1].
    let k = times.partition_point(|&t| t as f64 <= time) - 1;
    let (t0, t1) = (times[k] as f64, times[k + 1] as f64);
    let span = t1 - t0;
    let s = (time - t0) / span;
    match channel.interpolation {
        Interpolation::Step => finish(element(k, 1)),
        Interpolation::Linear if rotation => slerp(normalised(element(k, 1)), normalised(element(k + 1, 1)), s),
        Interpolation::Linear => {
            let (a, b) = (element(k, 1), element(k + 1, 1));
            [0, 1, 2, 3].map(|i| a[i] + s * (b[i] - a[i]))
        }
        Interpolation::CubicSpline => {
            // glTF 2.0's cubic Hermite spline: the value and out-tangent of key k, the in-tangent
            // and value of key k + 1, the tangents scaled by the keys' distance in time.
            let (v0, b0) = (element(k, 1), element(k, 2));
            let (a1, v1) = (element(k + 1, 0), element(k + 1, 1));
            let (s2, s3) = (s * s, s * s * s);
            let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
            let h10 = span * (s3 - 2.0 * s2 + s);
            let h01 = -2.0 * s3 + 3.0 * s2;
            let h11 = span * (s3 - s2);
            finish([0, 1, 2, 3].map(|i| h00 * v0[i] + h10 * b0[i] + h01 * v1[i] + h11 * a1[i]))
        }
    }
}

/// The animated parts of the scene's node trees.
#[derive(Clone, Debug, Default)]
pub struct Rig {
    nodes: Vec<GltfNode>,
    channels: Vec<GltfChannel>,
    /// Per node and path (translation, rotation, scale): the channel that drives it (the
    /// file's first valid one).
    driver: Vec<[Option<usize>; 3]>,
}

/// What rendering frames with this scene's animations means (see `Rig::plan_frames`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FramesPlan {
    /// Whether any channel moves the camera's node or one of its ancestors.
    pub camera_animated: bool,
    /// The first and last key time of the channels that move the camera, seconds.
    pub keys: Option<(f64, f64)>,
    /// Whether channels move meshes, and lights (punctual ones; an emissive mesh is a mesh).
    pub meshes_animated: bool,
    pub lights_animated: bool,
    /// The first and last key time of the channels that move meshes or lights, seconds.
    pub scene_keys: Option<(f64, f64)>,
    /// Things said once on stderr: channels ignored, and why.
    pub notes: Vec<String>,
}

fn path_slot(path: AnimPath) -> Option<usize> {
    match path {
        AnimPath::Translation => Some(0),
        AnimPath::Rotation => Some(1),
        AnimPath::Scale => Some(2),
        AnimPath::Weights | AnimPath::Other => None,
    }
}

fn path_name(path: AnimPath) -> &'static str {
    match path {
        AnimPath::Translation => "translation",
        AnimPath::Rotation => "rotation",
        AnimPath::Scale => "scale",
        AnimPath::Weights => "weights",
        AnimPath::Other => "an extension's path",
    }
}

impl Rig {
    pub fn new(nodes: Vec<GltfNode>, channels: Vec<GltfChannel>) -> Rig {
        let mut driver = vec![[None; 3]; nodes.len()];
        for (i, c) in channels.iter().enumerate() {
            if let (Some(node), Some(slot), None) = (c.node, path_slot(c.path), &c.error)
                && !c.times.is_empty()
                && driver[node][slot].is_none()
            {
                driver[node][slot] = Some(i);
            }
        }
        Rig {
            nodes,
            channels,
            driver,
        }
    }

    pub fn has_channels(&self) -> bool {
        !self.channels.is_empty()
    }

    fn node_label(&self, node: usize) -> String {
        match self.nodes.get(node).map(|n| n.name.as_str()) {
            Some(name) if !name.is_empty() => format!("node '{name}'"),
            _ => format!("node {node}"),
        }
    }

    fn animation_label(c: &GltfChannel) -> String {
        if c.animation_name.is_empty() {
            format!("animation {}", c.animation)
        } else {
            format!("animation '{}'", c.animation_name)
        }
    }

    /// The node and its ancestors, the node first.
    fn chain(&self, node: usize) -> Vec<usize> {
        let mut chain = vec![node];
        while let Some(parent) = self.nodes.get(*chain.last().expect("not empty")).and_then(|n| n.parent) {
            // The loader refuses cycles; a chain longer than the node count would be one.
            if chain.len() > self.nodes.len() {
                break;
            }
            chain.push(parent);
        }
        chain
    }

    /// What the node's subtree (the node and its descendants) places.
    fn subtree_places(&self) -> Vec<Places> {
        let mut out = vec![Places::default(); self.nodes.len()];
        for (i, n) in self.nodes.iter().enumerate() {
            let p = n.places;
            if !n.in_scene || !(p.mesh || p.light || p.joint) {
                continue;
            }
            for a in self.chain(i) {
                out[a].mesh |= p.mesh;
                out[a].light |= p.light;
                out[a].joint |= p.joint;
            }
        }
        out
    }

    /// Checks the animations frames can render (the node driving the render's camera is
    /// `camera`, None without a glTF camera) and says what frames will show. Meshes, lights and
    /// cameras move with their nodes' translation, rotation and scale. Refused, naming the
    /// animation and the node: a channel that deforms a mesh (morph target weights, or the
    /// joints of a skin), and a channel that breaks glTF's rules and would move something.
    pub fn plan_frames(&self, camera: Option<usize>) -> Result<FramesPlan, String> {
        let places = self.subtree_places();
        let camera_chain = camera.map(|c| self.chain(c)).unwrap_or_default();
        let mut plan = FramesPlan::default();
        let mut duplicates = Vec::new();
        for (i, c) in self.channels.iter().enumerate() {
            let Some(node) = c.node.filter(|&n| self.nodes[n].in_scene) else {
                // A node outside the scene (or none) moves nothing that is rendered.
                continue;
            };
            let below = places[node];
            let Some(slot) = path_slot(c.path) else {
                if c.path == AnimPath::Weights && below.mesh {
                    return Err(format!(
                        "{} animates the morph target weights of {}: icrender does not deform meshes (morph \
                         targets are not supported); render the frames without that animation",
                        Self::animation_label(c),
                        self.node_label(node),
                    ));
                }
                continue;
            };
            if below.joint {
                return Err(format!(
                    "{} moves {} (its {}), a joint of a skin (or a joint's parent): icrender does not deform \
                     meshes (skins are not supported); render the frames without that animation",
                    Self::animation_label(c),
                    self.node_label(node),
                    path_name(c.path),
                ));
            }
            let moves_camera = camera_chain.contains(&node);
            if !(below.mesh || below.light || moves_camera) {
                continue;
            }
            if let Some(error) = &c.error {
                let what = if moves_camera {
                    "the camera's animation"
                } else {
                    "an animation that moves the scene"
                };
                return Err(format!("{what} cannot be used: {error}"));
            }
            if self.driver[node][slot] != Some(i) {
                duplicates.push(format!(
                    "{} ({} of {})",
                    Self::animation_label(c),
                    path_name(c.path),
                    self.node_label(node)
                ));
                continue;
            }
            plan.meshes_animated |= below.mesh;
            plan.lights_animated |= below.light;
            let (first, last) = (c.times[0] as f64, c.times[c.times.len() - 1] as f64);
            let widen =
                |keys: Option<(f64, f64)>| Some(keys.map_or((first, last), |(a, b)| (a.min(first), b.max(last))));
            if moves_camera {
                plan.camera_animated = true;
                plan.keys = widen(plan.keys);
            }
            if below.mesh || below.light {
                plan.scene_keys = widen(plan.scene_keys);
            }
        }
        if !duplicates.is_empty() {
            plan.notes.push(format!(
                "a node is driven twice by the same property: {} ignored, the file's first channel \
                 for each property is used (all animations play together from time 0)",
                duplicates.join(", ")
            ));
        }
        Ok(plan)
    }

    /// Whether a channel drives the node or one of its ancestors (its world matrix moves).
    pub fn moves(&self, node: usize) -> bool {
        node < self.nodes.len()
            && self
                .chain(node)
                .into_iter()
                .any(|n| self.driver[n].iter().any(Option::is_some))
    }

    /// The node's world matrix at rest (no channel applied), as the loader composed it.
    pub fn rest_world(&self, node: usize) -> Mat4 {
        let mut world = IDENTITY;
        for n in self.chain(node).into_iter().rev() {
            world = mul(&world, &self.local_pose(n, None));
        }
        world
    }

    /// The node's local transform at `time`: its rest pose with the driven parts replaced.
    fn local_at(&self, node: usize, time: f64) -> Mat4 {
        self.local_pose(node, Some(time))
    }

    /// The node's local transform, with its channels applied at `time` when there is one.
    fn local_pose(&self, node: usize, time: Option<f64>) -> Mat4 {
        match &self.nodes[node].pose {
            LocalPose::Matrix(m) => *m,
            LocalPose::Trs {
                translation,
                rotation,
                scale,
            } => {
                let mut trs = Trs {
                    translation: *translation,
                    rotation: *rotation,
                    scale: *scale,
                };
                let drive = |slot: usize| {
                    let time = time?;
                    self.driver[node][slot].map(|c| sample(&self.channels[c], time))
                };
                if let Some(v) = drive(0) {
                    trs.translation = [v[0], v[1], v[2]];
                }
                if let Some(v) = drive(1) {
                    trs.rotation = v;
                }
                if let Some(v) = drive(2) {
                    trs.scale = [v[0], v[1], v[2]];
                }
                trs.matrix()
            }
        }
    }

    /// The node's world matrix at `time`, parents first as the loader composes them.
    pub fn world_at(&self, node: usize, time: f64) -> Mat4 {
        let mut world = IDENTITY;
        for n in self.chain(node).into_iter().rev() {
            world = mul(&world, &self.local_at(n, time));
        }
        world
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sys::scene_io::Places;

    fn channel(path: AnimPath, interpolation: Interpolation, times: &[f32], values: &[f32]) -> GltfChannel {
        GltfChannel {
            animation: 0,
            animation_name: "walk".into(),
            node: Some(0),
            path,
            interpolation,
            times: times.to_vec(),
            values: values.to_vec(),
            components: if path == AnimPath::Rotation { 4 } else { 3 },
            error: None,
        }
    }

    fn close(a: [f64; 4], b: [f64; 4], tolerance: f64) -> bool {
        a.iter().zip(&b).all(|(x, y)| (x - y).abs() <= tolerance)
    }

    #[test]
    fn linear_interpolates_between_keys_and_holds_outside_them() {
        let c = channel(
            AnimPath::Translation,
            Interpolation::Linear,
            &[1.0, 2.0, 4.0],
            &[0.0, 0.0, 0.0, 10.0, -2.0, 4.0, 10.0, 0.0, 0.0],
        );
        assert_eq!(sample(&c, 1.5), [5.0, -1.0, 2.0, 0.0]);
        // A quarter of the way from the second key to the third.
        assert_eq!(sample(&c, 2.5), [10.0, -1.5, 3.0, 0.0]);
        assert_eq!(sample(&c, 2.0), [10.0, -2.0, 4.0, 0.0]);
        // Clamped: before the first key and after the last.
        assert_eq!(sample(&c, 0.0), [0.0, 0.0, 0.0, 0.0]);
        assert_eq!(sample(&c, -3.0), [0.0, 0.0, 0.0, 0.0]);
        assert_eq!(sample(&c, 9.0), [10.0, 0.0, 0.0, 0.0]);
    }

    #[test]
    fn step_holds_each_key_until_the_next() {
        let c = channel(
            AnimPath::Scale,
            Interpolation::Step,
            &[0.0, 1.0, 2.0],
            &[1.0, 1.0, 1.0, 2.0, 2.0, 2.0, 3.0, 3.0, 3.0],
        );
        assert_eq!(sample(&c, 0.999), [1.0, 1.0, 1.0, 0.0]);
        assert_eq!(sample(&c, 1.0), [2.0, 2.0, 2.0, 0.0]);
        assert_eq!(sample(&c, 1.7), [2.0, 2.0, 2.0, 0.0]);
        assert_eq!(sample(&c, 5.0), [3.0, 3.0, 3.0, 0.0]);
    }

    #[test]
    fn linear_rotation_is_a_slerp_the_short_way() {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        // Identity to 90 degrees about Y; the second key written as -q (the same rotation).
        let c = channel(
            AnimPath::Rotation,
            Interpolation::Linear,
            &[0.0, 1.0],
            &[0.0, 0.0, 0.0, 1.0, 0.0, -h as f32, 0.0, -h as f32],
        );
        // A third of the way: 30 degrees about Y (the long way would be -150 degrees).
        let q = sample(&c, 1.0 / 3.0);
        let half = 15f64.to_radians();
        assert!(close(q, [0.0, half.sin(), 0.0, half.cos()], 1e-7), "{q:?}");
        // Constant angular speed: the angle grows linearly with time.
        for s in [0.1, 0.5, 0.9] {
            let q = sample(&c, s);
            let angle = 2.0 * q[3].abs().acos();
            assert!((angle - s * std::f64::consts::FRAC_PI_2).abs() < 1e-6, "{s}: {angle}");
        }
    }

    #[test]
    fn cubic_spline_follows_the_hermite_curve_with_tangents_scaled_by_the_key_span() {
        // One component that matters (x): keys at t = 1 and t = 3 (span 2), values 0 and 1,
        // out-tangent of key 0 = 0.5, in-tangent of key 1 = -1, unused tangents 9.
        let c = channel(
            AnimPath::Translation,
            Interpolation::CubicSpline,
            &[1.0, 3.0],
            &[
                9.0, 9.0, 9.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0, // key 0: in, value, out
                -1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 9.0, 9.0, 9.0, // key 1: in, value, out
            ],
        );
        // At s = 0.5 (t = 2): h00 = 0.5, h10 = 0.125, h01 = 0.5, h11 = -0.125, by hand:
        // 0.5 * 0 + 2 * 0.125 * 0.5 + 0.5 * 1 + 2 * (-0.125) * (-1) = 0.875.
        assert!((sample(&c, 2.0)[0] - 0.875).abs() < 1e-12);
        // At s = 0.25 (t = 1.5): h00 = 0.84375, h10 = 0.140625, h01 = 0.15625, h11 = -0.046875:
        // 2 * 0.140625 * 0.5 + 0.15625 + 2 * 0.046875 = 0.390625.
        assert!((sample(&c, 1.5)[0] - 0.390625).abs() < 1e-12);
        // Keys are hit exactly, and the ends hold the values, not the tangents.
        assert_eq!(sample(&c, 1.0)[0], 0.0);
        assert_eq!(sample(&c, 3.0)[0], 1.0);
        assert_eq!(sample(&c, 0.0)[0], 0.0);
        assert_eq!(sample(&c, 7.0)[0], 1.0);
    }

    #[test]
    fn cubic_spline_rotations_come_out_unit_length() {
        let c = channel(
            AnimPath::Rotation,
            Interpolation::CubicSpline,
            &[0.0, 1.0],
            &[
                0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, //
                0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
            ],
        );
        let q = sample(&c, 0.5);
        let len = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!((len - 1.0).abs() < 1e-12);
        // Half way between identity and a half turn about Y, with zero tangents: a quarter turn.
        assert!(close(q, [0.0, 0.5f64.sqrt(), 0.0, 0.5f64.sqrt()], 1e-12), "{q:?}");
    }

    fn node(parent: Option<usize>, places: Places, translation: [f64; 3]) -> GltfNode {
        GltfNode {
            name: String::new(),
            parent,
            in_scene: true,
            places,
            pose: LocalPose::Trs {
                translation,
                rotation: [0.0, 0.0, 0.0, 1.0],
                scale: [1.0; 3],
            },
        }
    }

    const CAMERA: Places = Places {
        mesh: false,
        light: false,
        camera: true,
        joint: false,
    };
    const MESH: Places = Places {
        mesh: true,
        light: false,
        camera: false,
        joint: false,
    };
    const NOTHING: Places = Places {
        mesh: false,
        light: false,
        camera: false,
        joint: false,
    };

    #[test]
    fn a_camera_under_an_animated_parent_moves_with_it() {
        // Parent at (0, 1, 0) animated to (4, 1, 0); the camera 2 along z below it.
        let nodes = vec![
            node(None, NOTHING, [0.0, 1.0, 0.0]),
            node(Some(0), CAMERA, [0.0, 0.0, 2.0]),
        ];
        let walk = channel(
            AnimPath::Translation,
            Interpolation::Linear,
            &[0.0, 2.0],
            &[0.0, 1.0, 0.0, 4.0, 1.0, 0.0],
        );
        let rig = Rig::new(nodes, vec![walk]);
        let plan = rig.plan_frames(Some(1)).unwrap();
        assert!(plan.camera_animated);
        assert_eq!(plan.keys, Some((0.0, 2.0)));
        let world = rig.world_at(1, 1.0);
        assert_eq!(&world[12..15], &[2.0, 1.0, 2.0]);
        assert_eq!(transform_dir(&world, 0.0, 0.0, -1.0), [0.0, 0.0, -1.0]);
    }

    #[test]
    fn a_mesh_under_an_animated_group_moves_and_a_skin_s_joint_is_refused() {
        // A mesh under an animated group: planned, the mesh's node moves, its rest world stays.
        let mut nodes = vec![node(None, NOTHING, [0.0; 3]), node(Some(0), MESH, [1.0, 0.0, 0.0])];
        nodes[0].name = "Trolley".into();
        nodes.push(node(None, CAMERA, [0.0; 3]));
        let moving = channel(
            AnimPath::Translation,
            Interpolation::Linear,
            &[0.0, 1.0],
            &[0.0, 0.0, 0.0, 2.0, 0.0, 0.0],
        );
        let rig = Rig::new(nodes.clone(), vec![moving.clone()]);
        let plan = rig.plan_frames(Some(2)).unwrap();
        assert!(plan.meshes_animated && !plan.lights_animated && !plan.camera_animated);
        assert_eq!(plan.scene_keys, Some((0.0, 1.0)));
        assert!(rig.moves(1) && !rig.moves(2));
        assert_eq!(&rig.rest_world(1)[12..15], &[1.0, 0.0, 0.0]);
        assert_eq!(&rig.world_at(1, 0.5)[12..15], &[2.0, 0.0, 0.0]);
        // The same group as a skin's joint: refused, naming the animation and the node.
        let mut jointed = nodes.clone();
        jointed[0].places.joint = true;
        let e = Rig::new(jointed, vec![moving.clone()])
            .plan_frames(Some(2))
            .unwrap_err();
        assert!(
            e.contains("animation 'walk'") && e.contains("node 'Trolley'") && e.contains("skin"),
            "{e}"
        );
        // The same channel on a node outside the scene moves nothing rendered.
        nodes[0].in_scene = false;
        nodes[1].in_scene = false;
        let rig = Rig::new(nodes, vec![moving]);
        let plan = rig.plan_frames(Some(2)).unwrap();
        assert!(!plan.camera_animated && !plan.meshes_animated);
    }
}

//! Safe wrapper over Embree: a device, a scene of triangle meshes and of instances of other
//! scenes (one level: a prototype scene holds triangle meshes only), closest-hit and occlusion
//! queries. Works with Embree 3 and Embree 4 (the build script sets `cfg(embree4)`); both take
//! instances the same way (an instance geometry naming its scene and a 3x4 transform), and
//! both report the instance a hit went through in `instID[0]`.
//!
//! Errors reported through Embree's error callback are collected per device and returned as
//! Rust errors from the call that caused them.

use super::embree_bindings as rtc;
use std::ffi::c_void;
use std::sync::{Arc, Mutex};

/// Embree's RTC_INVALID_GEOMETRY_ID is a macro with a cast, which bindgen does not evaluate.
const INVALID_GEOMETRY_ID: u32 = u32::MAX;

#[derive(Debug, thiserror::Error)]
#[error("Embree: {0}")]
pub struct EmbreeError(pub String);

/// Where the error callback leaves messages until the wrapper picks them up.
struct ErrorSink {
    messages: Mutex<Vec<String>>,
}

extern "C" fn error_callback(user: *mut c_void, code: rtc::RTCError, text: *const std::os::raw::c_char) {
    if user.is_null() {
        return;
    }
    // SAFETY: `user` is the ErrorSink boxed by Device::new, which outlives the device.
    let sink = unsafe { &*(user as *const ErrorSink) };
    // SAFETY: Embree passes a NUL-terminated message or NULL.
    let message = unsafe { super::owned_string(text) };
    if let Ok(mut messages) = sink.messages.lock() {
        messages.push(format!("error {code}: {message}"));
    }
}

pub struct Device {
    raw: rtc::RTCDevice,
    sink: Box<ErrorSink>,
}

// SAFETY: Embree devices are thread-safe; the error sink is behind a mutex.
unsafe impl Send for Device {}
unsafe impl Sync for Device {}

impl Device {
    pub fn new() -> Result<Device, EmbreeError> {
        // SAFETY: a NULL config string asks for Embree's defaults.
        let raw = unsafe { rtc::rtcNewDevice(std::ptr::null()) };
        if raw.is_null() {
            // SAFETY: rtcGetDeviceError accepts NULL and reports the creation error.
            let code = unsafe { rtc::rtcGetDeviceError(std::ptr::null_mut()) };
            return Err(EmbreeError(format!("could not create a device (error {code})")));
        }
        let sink = Box::new(ErrorSink {
            messages: Mutex::new(Vec::new()),
        });
        let user = &*sink as *const ErrorSink as *mut c_void;
        // SAFETY: the sink lives as long as the device (both dropped together, device first).
        unsafe { rtc::rtcSetDeviceErrorFunction(raw, Some(error_callback), user) };
        Ok(Device { raw, sink })
    }

    /// Turns errors Embree reported since the last check into a Rust error.
    fn check(&self, what: &str) -> Result<(), EmbreeError> {
        let mut messages = self
            .sink
            .messages
            .lock()
            .map_err(|_| EmbreeError("error sink poisoned".into()))?;
        if messages.is_empty() {
            Ok(())
        } else {
            let all = messages.join("; ");
            messages.clear();
            Err(EmbreeError(format!("{what}: {all}")))
        }
    }

    /// Whether rays and geometries carry masks (`TriangleMeshData::mask`,
    /// `Scene::occluded_masked`): an option of Embree's build, on in Debian's.
    pub fn supports_ray_masks(&self) -> bool {
        // SAFETY: querying a property of a live device.
        unsafe { rtc::rtcGetDeviceProperty(self.raw, rtc::RTC_DEVICE_PROPERTY_RAY_MASK_SUPPORTED) != 0 }
    }

    /// Whether packets of `PACKET` rays are traced by kernels of that width (a build for
    /// AVX or later on a processor that has it).
    pub fn native_packets(&self) -> bool {
        // SAFETY: querying a property of a live device.
        unsafe { rtc::rtcGetDeviceProperty(self.raw, rtc::RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED) != 0 }
    }

    /// Version of the library actually loaded, e.g. "3.13.5".
    pub fn version(&self) -> String {
        // SAFETY: querying a property of a live device.
        let v = unsafe { rtc::rtcGetDeviceProperty(self.raw, rtc::RTC_DEVICE_PROPERTY_VERSION) };
        format!("{}.{}.{}", v / 10000, (v / 100) % 100, v % 100)
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        // SAFETY: the device was created by rtcNewDevice and is released once.
        unsafe { rtc::rtcReleaseDevice(self.raw) };
    }
}

/// A triangle mesh ready to hand to Embree: world-space vertices and indices, and the mask a
/// ray's must share a bit with for the ray to see it (`ALL_MASKS`: every ray).
pub struct TriangleMeshData<'a> {
    pub positions: &'a [[f32; 3]],
    pub indices: &'a [[u32; 3]],
    pub mask: u32,
}

/// An instance to place in a scene: a committed prototype scene and the affine transform from
/// its space to the scene's, 3x4 column-major (the images of the x, y and z axes, then the
/// translation).
pub struct InstanceData<'a> {
    pub prototype: &'a Arc<Scene>,
    pub transform: [f32; 12],
}

/// A committed (immutable) scene. Geometry ids equal the order of the meshes given to `build`,
/// then of the instances given to `build_with_instances`.
pub struct Scene {
    device: Arc<Device>,
    raw: rtc::RTCScene,
    /// The prototypes its instances refer to, kept alive as long as it is.
    prototypes: Vec<Arc<Scene>>,
    /// Whether the library traces packets of `PACKET` rays with kernels of that width
    /// (`occluded_packet`); without them it would split a packet up itself.
    packets: bool,
}

// SAFETY: a committed Embree scene may be queried from many threads at once.
unsafe impl Send for Scene {}
unsafe impl Sync for Scene {}

/// A ray hit: distance, geometry (mesh) id, primitive (triangle) id, barycentrics, and the
/// unnormalised geometric normal Embree computed (orientation follows the triangle's winding).
/// A hit through an instance names the instance (its geometry id in the scene queried), and
/// `geom_id` is then the mesh's id in the instance's prototype, `ng` in the prototype's space.
#[derive(Clone, Copy, Debug)]
pub struct RayHit {
    pub t: f32,
    pub instance: Option<u32>,
    pub geom_id: u32,
    pub prim_id: u32,
    pub u: f32,
    pub v: f32,
    pub ng: [f32; 3],
}

/// Whether a batch of rays is coherent (camera rays) or not; Embree picks traversal by it.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Coherence {
    Coherent,
    Incoherent,
}

/// The mask of a geometry every ray sees, and of a ray that sees every geometry.
pub const ALL_MASKS: u32 = u32::MAX;

/// Rays traced together by `Scene::occluded_packet`.
pub const PACKET: usize = 8;

/// A packet's valid mask (-1: the ray is traced), aligned as the packet is: Embree loads it
/// as one vector.
#[repr(C, align(32))]
struct ValidMask([i32; PACKET]);

fn make_ray(org: [f32; 3], dir: [f32; 3], tnear: f32, tfar: f32) -> rtc::RTCRay {
    rtc::RTCRay {
        org_x: org[0],
        org_y: org[1],
        org_z: org[2],
        tnear,
        dir_x: dir[0],
        dir_y: dir[1],
        dir_z: dir[2],
        time: 0.0,
        tfar,
        mask: u32::MAX,
        id: 0,
        flags: 0,
    }
}

impl Scene {
    /// Builds and commits a scene from triangle meshes. Robust traversal is asked for, since
    /// rays start on surfaces and must not slip through shared edges.
    pub fn build(device: &Arc<Device>, meshes: &[TriangleMeshData<'_>]) -> Result<Scene, EmbreeError> {
        Scene::build_with_instances(device, meshes, &[])
    }

    /// Builds and commits a scene of triangle meshes (geometry ids 0..meshes.len()) and
    /// instances of prototype scenes (the ids after them).
    pub fn build_with_instances(
        device: &Arc<Device>,
        meshes: &[TriangleMeshData<'_>],
        instances: &[InstanceData<'_>],
    ) -> Result<Scene, EmbreeError> {
        // SAFETY: creating a scene on a live device.
        let raw = unsafe { rtc::rtcNewScene(device.raw) };
        if raw.is_null() {
            device.check("creating a scene")?;
            return Err(EmbreeError("could not create a scene".into()));
        }
        let mut scene = Scene {
            device: Arc::clone(device),
            raw,
            prototypes: Vec::new(),
            packets: device.native_packets(),
        };
        // Robust mode, for rays that do not slip between triangles: without it, rays from inside
        // the Cornell box's room aimed at points on its walls' triangle edges passed through 7 %
        // of the time (2.4 % in the test below), for rays 1.16-1.22x faster (`bench rays`,
        // Embree 3.13.5: hemisphere, incoherent and primary rays on the conference room and
        // Sibenik) and a conference room render at -ab 2 in 0.885x the time. A light leak at
        // every wall's edges is not a price for that.
        // SAFETY: flags and quality on a scene not yet committed.
        unsafe {
            rtc::rtcSetSceneFlags(raw, rtc::RTC_SCENE_FLAG_ROBUST);
            rtc::rtcSetSceneBuildQuality(raw, rtc::RTC_BUILD_QUALITY_HIGH);
        }
        for (index, mesh) in meshes.iter().enumerate() {
            scene.attach_mesh(index, mesh)?;
        }
        for (k, instance) in instances.iter().enumerate() {
            scene.attach_instance(meshes.len() + k, instance)?;
        }
        // SAFETY: all geometries are committed and attached.
        unsafe { rtc::rtcCommitScene(raw) };
        device.check("committing the scene")?;
        Ok(scene)
    }

    fn attach_mesh(&self, index: usize, mesh: &TriangleMeshData<'_>) -> Result<(), EmbreeError> {
        let device = self.device.raw;
        // SAFETY: new geometry on a live device; buffers are sized by Embree and filled within
        // their bounds below; the geometry is released after attaching (the scene keeps it).
        unsafe {
            let geom = rtc::rtcNewGeometry(device, rtc::RTC_GEOMETRY_TYPE_TRIANGLE);
            if geom.is_null() {
                self.device.check("creating a triangle geometry")?;
                return Err(EmbreeError("could not create a triangle geometry".into()));
            }
            let vcount = mesh.positions.len();
            let tcount = mesh.indices.len();
            let vbuf =
                rtc::rtcSetNewGeometryBuffer(geom, rtc::RTC_BUFFER_TYPE_VERTEX, 0, rtc::RTC_FORMAT_FLOAT3, 12, vcount)
                    as *mut [f32; 3];
            let ibuf =
                rtc::rtcSetNewGeometryBuffer(geom, rtc::RTC_BUFFER_TYPE_INDEX, 0, rtc::RTC_FORMAT_UINT3, 12, tcount)
                    as *mut [u32; 3];
            if (vbuf.is_null() && vcount > 0) || (ibuf.is_null() && tcount > 0) {
                rtc::rtcReleaseGeometry(geom);
                self.device.check("allocating geometry buffers")?;
                return Err(EmbreeError("could not allocate geometry buffers".into()));
            }
            std::ptr::copy_nonoverlapping(mesh.positions.as_ptr(), vbuf, vcount);
            std::ptr::copy_nonoverlapping(mesh.indices.as_ptr(), ibuf, tcount);
            rtc::rtcSetGeometryMask(geom, mesh.mask);
            rtc::rtcCommitGeometry(geom);
            let id = rtc::rtcAttachGeometry(self.raw, geom);
            rtc::rtcReleaseGeometry(geom);
            if id as usize != index {
                return Err(EmbreeError(format!("geometry {index} got id {id}")));
            }
        }
        self.device.check("adding a triangle mesh")
    }

    fn attach_instance(&mut self, index: usize, instance: &InstanceData<'_>) -> Result<(), EmbreeError> {
        if !Arc::ptr_eq(&instance.prototype.device, &self.device) {
            return Err(EmbreeError(format!(
                "instance {index}: its prototype belongs to another device"
            )));
        }
        if !instance.prototype.prototypes.is_empty() {
            return Err(EmbreeError(format!(
                "instance {index}: its prototype holds instances itself (one level only)"
            )));
        }
        if !instance.transform.iter().all(|v| v.is_finite()) {
            return Err(EmbreeError(format!("instance {index}: non-finite transform")));
        }
        // SAFETY: new geometry on a live device; the prototype is a committed scene of the same
        // device, kept alive by `self.prototypes` for as long as this scene lives; the transform
        // is 12 floats, read by Embree during the call.
        unsafe {
            let geom = rtc::rtcNewGeometry(self.device.raw, rtc::RTC_GEOMETRY_TYPE_INSTANCE);
            if geom.is_null() {
                self.device.check("creating an instance geometry")?;
                return Err(EmbreeError("could not create an instance geometry".into()));
            }
            rtc::rtcSetGeometryInstancedScene(geom, instance.prototype.raw);
            rtc::rtcSetGeometryTransform(
                geom,
                0,
                rtc::RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR,
                instance.transform.as_ptr() as *const c_void,
            );
            rtc::rtcCommitGeometry(geom);
            let id = rtc::rtcAttachGeometry(self.raw, geom);
            rtc::rtcReleaseGeometry(geom);
            if id as usize != index {
                return Err(EmbreeError(format!("instance {index} got id {id}")));
            }
        }
        if !self.prototypes.iter().any(|p| Arc::ptr_eq(p, instance.prototype)) {
            self.prototypes.push(Arc::clone(instance.prototype));
        }
        self.device.check("adding an instance")
    }

    /// Closest hit along the ray within (tnear, tfar), or None.
    #[inline]
    pub fn intersect(
        &self,
        org: [f32; 3],
        dir: [f32; 3],
        tnear: f32,
        tfar: f32,
        coherence: Coherence,
    ) -> Option<RayHit> {
        let mut rayhit = rtc::RTCRayHit {
            ray: make_ray(org, dir, tnear, tfar),
            hit: rtc::RTCHit {
                geomID: INVALID_GEOMETRY_ID,
                instID: [INVALID_GEOMETRY_ID; rtc::RTC_MAX_INSTANCE_LEVEL_COUNT as usize],
                ..Default::default()
            },
        };
        self.raw_intersect(&mut rayhit, coherence);
        let hit = &rayhit.hit;
        (hit.geomID != INVALID_GEOMETRY_ID).then_some(RayHit {
            t: rayhit.ray.tfar,
            instance: (hit.instID[0] != INVALID_GEOMETRY_ID).then_some(hit.instID[0]),
            geom_id: hit.geomID,
            prim_id: hit.primID,
            u: hit.u,
            v: hit.v,
            ng: [hit.Ng_x, hit.Ng_y, hit.Ng_z],
        })
    }

    /// True when anything blocks the ray within (tnear, tfar).
    #[inline]
    pub fn occluded(&self, org: [f32; 3], dir: [f32; 3], tnear: f32, tfar: f32) -> bool {
        self.occluded_masked(org, dir, tnear, tfar, ALL_MASKS)
    }

    /// True when a geometry whose mask shares a bit with `mask` blocks the ray within (tnear,
    /// tfar); the others are passed through. Needs `Device::supports_ray_masks` (without it
    /// every geometry blocks).
    #[inline]
    pub fn occluded_masked(&self, org: [f32; 3], dir: [f32; 3], tnear: f32, tfar: f32, mask: u32) -> bool {
        let mut ray = make_ray(org, dir, tnear, tfar);
        ray.mask = mask;
        self.raw_occluded(&mut ray);
        // Embree marks a blocked ray by setting tfar to -inf.
        ray.tfar < 0.0
    }

    /// Whether each of up to `PACKET` rays (origin, unit direction, tfar; tnear 0) is blocked by
    /// a geometry whose mask shares a bit with `mask`, into `blocked[i]` for `rays[i]`. Traced
    /// as one Embree packet where the library has kernels of its width: rays from one point
    /// to one light cross much the same nodes, which the packet's traversal visits once for
    /// all (the conference room at -ab 2, 16 shadow rays a point on the eye path: the whole
    /// render at 1.066x the rays a second of one ray at a time, images identical). Elsewhere
    /// ray by ray.
    pub fn occluded_packet(&self, rays: &[([f32; 3], [f32; 3], f32)], mask: u32, blocked: &mut [bool]) {
        assert!(rays.len() <= PACKET && blocked.len() >= rays.len());
        if !self.packets {
            for (b, &(org, dir, tfar)) in blocked.iter_mut().zip(rays) {
                *b = self.occluded_masked(org, dir, 0.0, tfar, mask);
            }
            return;
        }
        let mut packet = rtc::RTCRay8::default();
        let mut valid = ValidMask([0i32; PACKET]);
        for (i, &(org, dir, tfar)) in rays.iter().enumerate() {
            packet.org_x[i] = org[0];
            packet.org_y[i] = org[1];
            packet.org_z[i] = org[2];
            packet.dir_x[i] = dir[0];
            packet.dir_y[i] = dir[1];
            packet.dir_z[i] = dir[2];
            packet.tfar[i] = tfar;
            packet.mask[i] = mask;
            valid.0[i] = -1;
        }
        self.raw_occluded8(&valid, &mut packet);
        for (i, b) in blocked.iter_mut().take(rays.len()).enumerate() {
            // Embree marks a blocked ray by setting tfar to -inf.
            *b = packet.tfar[i] < 0.0;
        }
    }

    #[cfg(not(embree4))]
    #[inline]
    fn raw_occluded8(&self, valid: &ValidMask, packet: &mut rtc::RTCRay8) {
        let mut context = intersect_context(Coherence::Coherent);
        // SAFETY: committed scene, a valid mask of PACKET ints, a context and a packet on the
        // stack (RTCRay8 is 32-byte aligned as Embree asks).
        unsafe { rtc::rtcOccluded8(valid.0.as_ptr(), self.raw, &mut context, packet) };
    }

    #[cfg(embree4)]
    #[inline]
    fn raw_occluded8(&self, valid: &ValidMask, packet: &mut rtc::RTCRay8) {
        // SAFETY: committed scene, a valid mask of PACKET ints and a 32-byte aligned packet on
        // the stack; NULL arguments select Embree's defaults.
        unsafe { rtc::rtcOccluded8(valid.0.as_ptr(), self.raw, packet, std::ptr::null_mut()) };
    }

    #[cfg(not(embree4))]
    #[inline]
    fn raw_intersect(&self, rayhit: &mut rtc::RTCRayHit, coherence: Coherence) {
        let mut context = intersect_context(coherence);
        // SAFETY: committed scene, valid context and ray structures on the stack.
        unsafe { rtc::rtcIntersect1(self.raw, &mut context, rayhit) };
    }

    #[cfg(not(embree4))]
    #[inline]
    fn raw_occluded(&self, ray: &mut rtc::RTCRay) {
        let mut context = intersect_context(Coherence::Incoherent);
        // SAFETY: committed scene, valid context and ray structures on the stack.
        unsafe { rtc::rtcOccluded1(self.raw, &mut context, ray) };
    }

    #[cfg(embree4)]
    #[inline]
    fn raw_intersect(&self, rayhit: &mut rtc::RTCRayHit, _coherence: Coherence) {
        // SAFETY: committed scene; NULL arguments select Embree's defaults.
        unsafe { rtc::rtcIntersect1(self.raw, rayhit, std::ptr::null_mut()) };
    }

    #[cfg(embree4)]
    #[inline]
    fn raw_occluded(&self, ray: &mut rtc::RTCRay) {
        // SAFETY: committed scene; NULL arguments select Embree's defaults.
        unsafe { rtc::rtcOccluded1(self.raw, ray, std::ptr::null_mut()) };
    }
}

/// Embree 3's rtcInitIntersectContext is an inline C function that bindgen cannot bind, so
/// the same initialisation is done here.
#[cfg(not(embree4))]
#[inline]
fn intersect_context(coherence: Coherence) -> rtc::RTCIntersectContext {
    let mut context = rtc::RTCIntersectContext {
        flags: match coherence {
            Coherence::Coherent => rtc::RTC_INTERSECT_CONTEXT_FLAG_COHERENT,
            Coherence::Incoherent => rtc::RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT,
        },
        ..Default::default()
    };
    context.instID.iter_mut().for_each(|id| *id = INVALID_GEOMETRY_ID);
    context
}

impl Drop for Scene {
    fn drop(&mut self) {
        // SAFETY: the scene was created by rtcNewScene and is released once.
        unsafe { rtc::rtcReleaseScene(self.raw) };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn errors_reported_by_embree_become_rust_errors() {
        let device = Device::new().unwrap();
        assert!(device.check("nothing yet").is_ok());
        // An invalid geometry type makes Embree call the error callback.
        // SAFETY: a live device; Embree validates the type and returns NULL for a bad one.
        let geom = unsafe { rtc::rtcNewGeometry(device.raw, 12345) };
        assert!(geom.is_null());
        let err = device.check("creating a bogus geometry").unwrap_err();
        assert!(err.0.contains("creating a bogus geometry"), "{err}");
        // Reported once, then cleared.
        assert!(device.check("after").is_ok());
    }

    /// A closed room of six walls, each two triangles with corners of its own (as the Cornell
    /// box's glTF has them), walls at uneven coordinates: rays from inside aimed at points on
    /// the triangles' edges (the diagonals, and the walls' borders where two walls meet) must
    /// all stop at a wall. Without `RTC_SCENE_FLAG_ROBUST` 4,846 of these 200,000 passed
    /// through (Embree 3.13.5; 7 % of such rays in the Cornell box's room), with it none.
    #[test]
    fn rays_aimed_at_the_walls_edges_do_not_leak_out_of_a_closed_room() {
        let device = Arc::new(Device::new().unwrap());
        let (lo, hi) = ([-1.02f32, 0.0, -1.04], [1.0f32, 1.99, 0.99]);
        let corner = |i: usize| [0, 1, 2].map(|a| if i >> a & 1 == 1 { hi[a] } else { lo[a] });
        // Each wall: the four corners with axis `a` at side `side`, in order around the wall.
        let walls: Vec<[[f32; 3]; 4]> = (0..3)
            .flat_map(|a| {
                [0usize, 1].map(|side| {
                    let (b, c) = ((a + 1) % 3, (a + 2) % 3);
                    [(0, 0), (1, 0), (1, 1), (0, 1)].map(|(u, v)| corner(side << a | u << b | v << c))
                })
            })
            .collect();
        let indices = [[0u32, 1, 2], [0, 2, 3]];
        let meshes: Vec<TriangleMeshData<'_>> = walls
            .iter()
            .map(|w| TriangleMeshData {
                positions: w,
                indices: &indices,
                mask: ALL_MASKS,
            })
            .collect();
        let scene = Scene::build(&device, &meshes).unwrap();
        let mut rng = crate::sampling::Rng::new(3, 4);
        let (mut leaked, mut leaked_in_packets) = (0, 0);
        let rays = 200_000;
        for _ in 0..rays {
            let wall = &walls[(rng.next_u32() % 6) as usize];
            let edge = [(0, 1), (1, 2), (2, 3), (3, 0), (0, 2)][(rng.next_u32() % 5) as usize];
            let t = rng.next_f32();
            let (a, b) = (Vec3::from(wall[edge.0]), Vec3::from(wall[edge.1]));
            let target = a + (b - a) * t;
            let inside = Vec3::from(lo)
                + (Vec3::from(hi) - Vec3::from(lo))
                    * Vec3::new(
                        0.1 + 0.8 * rng.next_f32(),
                        0.1 + 0.8 * rng.next_f32(),
                        0.1 + 0.8 * rng.next_f32(),
                    );
            let offset = (target - inside) * 1.5;
            let (length, dir) = (offset.length(), offset.normalize());
            let (o, d) = (inside.to_array(), dir.to_array());
            let stopped = scene.occluded(o, d, 0.0, length)
                && scene.intersect(o, d, 0.0, length, Coherence::Incoherent).is_some();
            leaked += u32::from(!stopped);
            // The same ray in a packet, beside rays from the same point aimed a little apart
            // (as a point's shadow rays to one light are traced).
            let mut packet = [(o, d, length); PACKET];
            for (k, ray) in packet.iter_mut().enumerate().skip(1) {
                let aside = (target + (b - a) * (0.01 * k as f32) - inside) * 1.5;
                *ray = (o, aside.normalize().to_array(), aside.length());
            }
            let mut blocked = [false; PACKET];
            scene.occluded_packet(&packet, ALL_MASKS, &mut blocked);
            leaked_in_packets += u32::from(!blocked[0]);
        }
        assert_eq!(leaked, 0, "{leaked} of {rays} rays passed through the walls");
        assert_eq!(
            leaked_in_packets, 0,
            "{leaked_in_packets} of {rays} rays in packets passed through the walls"
        );
    }

    /// A scene of one triangle, (0,0,0) (1,0,0) (0,1,0), with geometry mask `mask`.
    fn unit_triangle(device: &Arc<Device>, mask: u32) -> Scene {
        let positions = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let indices = [[0u32, 1, 2]];
        Scene::build(
            device,
            &[TriangleMeshData {
                positions: &positions,
                indices: &indices,
                mask,
            }],
        )
        .unwrap()
    }

    #[test]
    fn closest_hit_and_occlusion_on_one_triangle() {
        let device = Arc::new(Device::new().unwrap());
        let scene = unit_triangle(&device, ALL_MASKS);
        let hit = scene
            .intersect(
                [0.25, 0.25, 1.0],
                [0.0, 0.0, -1.0],
                0.0,
                f32::INFINITY,
                Coherence::Coherent,
            )
            .unwrap();
        assert!((hit.t - 1.0).abs() < 1e-6);
        assert_eq!((hit.geom_id, hit.prim_id), (0, 0));
        assert!((hit.u - 0.25).abs() < 1e-6 && (hit.v - 0.25).abs() < 1e-6);
        assert!(
            scene
                .intersect(
                    [2.0, 2.0, 1.0],
                    [0.0, 0.0, -1.0],
                    0.0,
                    f32::INFINITY,
                    Coherence::Incoherent
                )
                .is_none()
        );
        assert!(scene.occluded([0.25, 0.25, 1.0], [0.0, 0.0, -1.0], 0.0, 2.0));
        assert!(!scene.occluded([0.25, 0.25, 1.0], [0.0, 0.0, -1.0], 0.0, 0.5));
    }

    #[test]
    fn hits_through_instances_name_the_instance_and_the_prototype_mesh() {
        let device = Arc::new(Device::new().unwrap());
        let positions = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let indices = [[0u32, 1, 2]];
        let mesh = TriangleMeshData {
            positions: &positions,
            indices: &indices,
            mask: ALL_MASKS,
        };
        let prototype = Arc::new(Scene::build(&device, &[mesh]).unwrap());
        // Instance 0 moved by +10 in x; instance 1 mirrored in x (x -> -x) and moved by -10.
        let moved = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 10.0, 0.0, 0.0];
        let mirrored = [-1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, -10.0, 0.0, 0.0];
        let flat_positions = [[0.0, 0.0, 5.0], [1.0, 0.0, 5.0], [0.0, 1.0, 5.0]];
        let flat = TriangleMeshData {
            positions: &flat_positions,
            indices: &indices,
            mask: ALL_MASKS,
        };
        let scene = Scene::build_with_instances(
            &device,
            &[flat],
            &[
                InstanceData {
                    prototype: &prototype,
                    transform: moved,
                },
                InstanceData {
                    prototype: &prototype,
                    transform: mirrored,
                },
            ],
        )
        .unwrap();
        let down = [0.0, 0.0, -1.0];
        let hit = |x: f32, y: f32| scene.intersect([x, y, 1.0], down, 0.0, f32::INFINITY, Coherence::Incoherent);
        let a = hit(10.25, 0.5).unwrap();
        assert_eq!((a.instance, a.geom_id, a.prim_id), (Some(1), 0, 0));
        assert!((a.t - 1.0).abs() < 1e-6);
        // Barycentrics are those of the prototype's triangle.
        assert!((a.u - 0.25).abs() < 1e-6 && (a.v - 0.5).abs() < 1e-6, "{a:?}");
        let b = hit(-10.25, 0.5).unwrap();
        assert_eq!((b.instance, b.geom_id), (Some(2), 0));
        assert!((b.u - 0.25).abs() < 1e-6 && (b.v - 0.5).abs() < 1e-6, "{b:?}");
        // Where the prototype itself lies there is nothing: only its instances are in the scene.
        assert!(hit(0.25, 0.5).is_none());
        // The plain mesh above it: no instance.
        let c = scene
            .intersect([0.25, 0.25, 9.0], down, 0.0, f32::INFINITY, Coherence::Incoherent)
            .unwrap();
        assert_eq!((c.instance, c.geom_id), (None, 0));
        assert!(scene.occluded([10.25, 0.5, 1.0], down, 0.0, 2.0));
        assert!(!scene.occluded([10.25, 0.5, 1.0], down, 0.0, 0.5));
    }

    #[test]
    fn a_masked_occlusion_query_passes_the_geometries_outside_its_mask() {
        let device = Arc::new(Device::new().unwrap());
        if !device.supports_ray_masks() {
            return;
        }
        let indices = [[0u32, 1, 2]];
        let near = [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]];
        let far = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let scene = Scene::build(
            &device,
            &[
                TriangleMeshData {
                    positions: &near,
                    indices: &indices,
                    mask: 2,
                },
                TriangleMeshData {
                    positions: &far,
                    indices: &indices,
                    mask: 1,
                },
            ],
        )
        .unwrap();
        let (from, down) = ([0.25, 0.25, 2.0], [0.0, 0.0, -1.0]);
        // Only the near triangle (mask 2) lies within 1.5 of the origin.
        assert!(scene.occluded(from, down, 0.0, 1.5));
        assert!(scene.occluded_masked(from, down, 0.0, 1.5, 2));
        assert!(!scene.occluded_masked(from, down, 0.0, 1.5, 1));
        assert!(scene.occluded_masked(from, down, 0.0, 3.0, 1));
    }

    /// A packet answers each of its rays as that ray alone does: rays from a few points past a
    /// triangle, beside it and falling short of it, with and without the mask that passes it,
    /// packets full and partial.
    #[test]
    fn a_packet_of_occlusion_rays_answers_each_ray_as_it_alone_is_answered() {
        let device = Arc::new(Device::new().unwrap());
        let scene = unit_triangle(&device, 2);
        let masks = if device.supports_ray_masks() {
            vec![ALL_MASKS, 1]
        } else {
            vec![ALL_MASKS]
        };
        let mut rng = crate::sampling::Rng::new(5, 6);
        let (mut blocked_rays, mut total) = (0, 0);
        for _ in 0..2000 {
            let origin = Vec3::new(rng.next_f32() - 0.2, rng.next_f32() - 0.2, 0.5 + rng.next_f32());
            let count = 1 + (rng.next_u32() as usize % PACKET);
            let rays: Vec<([f32; 3], [f32; 3], f32)> = (0..count)
                .map(|_| {
                    let target = Vec3::new(1.4 * rng.next_f32() - 0.2, 1.4 * rng.next_f32() - 0.2, 0.0);
                    let offset = target - origin;
                    // Past the plane, or stopping short of it.
                    let reach = offset.length() * (0.5 + rng.next_f32());
                    (origin.to_array(), offset.normalize().to_array(), reach)
                })
                .collect();
            for &mask in &masks {
                let mut blocked = [false; PACKET];
                scene.occluded_packet(&rays, mask, &mut blocked);
                for (&(o, d, t), b) in rays.iter().zip(blocked) {
                    assert_eq!(
                        b,
                        scene.occluded_masked(o, d, 0.0, t, mask),
                        "ray {o:?} {d:?} {t} mask {mask}"
                    );
                    blocked_rays += u32::from(b);
                    total += 1;
                }
            }
        }
        // Both answers occur, so the comparison tested something.
        assert!(
            blocked_rays > 500 && total - blocked_rays > 500,
            "{blocked_rays} of {total}"
        );
    }
}

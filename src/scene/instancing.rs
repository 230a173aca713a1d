//! Meshes placed more than once: stored once, traced through Embree instances.
//!
//! glTF instances a mesh in two ways: several nodes naming it, and `EXT_mesh_gpu_instancing`
//! (the loader turns both into placements of one mesh). Copying every placement into world
//! space, as a mesh used once is, made `conference_x32.gltf` (one room placed 32 times) take
//! 1.46 GB and a 3 s BVH build. Here such a mesh keeps its vertices once, in the file's own
//! space, and each placement is a transform.
//!
//! What the renderer sees is the same as if the meshes were copied (`--flatten` copies them,
//! for the comparison), because every per-hit quantity is computed the way the copy computes
//! it: a hit's corners are transformed in f64 and rounded to f32 relative to the tracing
//! origin (`placement::tracing_point`), its shading normals go through the same f32 normal
//! matrix, a mirrored placement's winding is reversed the same way, and a triangle is kept by
//! the same f64 world-space test. A placement whose world-space test keeps other triangles
//! than the mesh's other placements (a triangle too small to survive rounding far from the
//! origin) is copied instead, so the set of triangles never depends on instancing. Only the
//! ray's intersection differs: Embree intersects the instance in its own space, so a hit's
//! distance and barycentrics can differ from the copy's in the last bits.
//!
//! Prototypes: meshes whose placements are related by the same transforms (a room's 42 meshes
//! placed as one by 32 parent nodes) are put in one Embree prototype scene, placed once per
//! transform. A ray then traverses one instance per room, as it traverses one room in the
//! single-room scene; an instance per mesh would overlap 42 instances in every room. The
//! prototype's space is the first placement's world space moved to the members' centre, so
//! its f32 coordinates keep the precision the geometry has near glTF's origin, and an
//! instance's transform is taken relative to the tracing origin.

use super::placement::{self, Bounds};
use crate::sys::scene_io::GltfScene;
use glam::{DMat3, DMat4, DVec3, Mat3, Vec3};

/// A mesh used by several placements, in the file's object space.
#[derive(Clone, Debug)]
pub struct SharedMesh {
    pub positions: Vec<[f32; 3]>,
    pub normals: Option<Vec<[f32; 3]>>,
    pub texcoords: Option<Vec<[f32; 2]>>,
    /// The triangles every placement keeps, in the file's winding (Embree's primitive ids).
    pub indices: Vec<[u32; 3]>,
    pub material: u32,
    /// Triangles of the file's mesh that every placement drops.
    pub dropped: usize,
}

/// One placement of a shared mesh: one object of the scene.
#[derive(Clone, Debug)]
pub struct Placement {
    pub mesh: u32,
    /// The glTF world matrix (object space to glTF world), in f64 as the loader gives it.
    pub world: DMat4,
    /// Shading normals to world space: the flattened mesh's f32 matrix (None when it is not
    /// finite, where the flattened mesh has no shading normals either).
    pub normal_matrix: Option<Mat3>,
    /// The transform reverses orientation: the winding is reversed to keep the front side.
    pub mirrored: bool,
    /// The object (Cryptomatte, `SurfaceHit::object`) it is.
    pub object: u32,
}

/// An Embree prototype scene: shared meshes (their ids in the prototype are their positions
/// here) in a common space.
#[derive(Clone, Debug)]
pub struct Prototype {
    pub members: Vec<u32>,
    /// Per member: its object space to the prototype's space.
    pub to_prototype: Vec<DMat4>,
}

/// One Embree instance of a prototype.
#[derive(Clone, Debug)]
pub struct PrototypeInstance {
    pub prototype: u32,
    /// Member m of this instance is placement `first_placement + m`.
    pub first_placement: u32,
    /// The prototype's space to the renderer's (tracing) coordinates.
    pub to_tracing: DMat4,
}

#[derive(Clone, Debug, Default)]
pub struct Instancing {
    pub meshes: Vec<SharedMesh>,
    pub placements: Vec<Placement>,
    pub prototypes: Vec<Prototype>,
    pub instances: Vec<PrototypeInstance>,
}

/// A hit's triangle as the flattened mesh holds it: corners in tracing coordinates, shading
/// normals in world space, texture coordinates, in the flattened winding, with the hit's
/// barycentrics for that winding (weights of the second and third corner).
#[derive(Clone, Copy, Debug)]
pub struct HitTriangle {
    pub corners: [Vec3; 3],
    pub normals: Option<[Vec3; 3]>,
    pub texcoords: Option<[[f32; 2]; 3]>,
    pub u: f32,
    pub v: f32,
    pub material: u32,
}

impl Instancing {
    pub fn is_empty(&self) -> bool {
        self.placements.is_empty()
    }

    /// Triangle `prim` of placement `p` hit at barycentrics (u, v) of the shared mesh's
    /// winding, as the flattened copy would hold it (see the module's comment).
    pub fn hit_triangle(&self, p: u32, prim: u32, u: f32, v: f32, origin: DVec3) -> HitTriangle {
        let placement = &self.placements[p as usize];
        let mesh = &self.meshes[placement.mesh as usize];
        let [a, b, c] = mesh.indices[prim as usize];
        // The copy's winding: (a, c, b) when mirrored, with the barycentrics swapped to match.
        let (order, u, v) = if placement.mirrored {
            ([a, c, b], v, u)
        } else {
            ([a, b, c], u, v)
        };
        let corner = |i: u32| {
            let [x, y, z] = mesh.positions[i as usize];
            let world = placement
                .world
                .transform_point3(DVec3::new(x as f64, y as f64, z as f64));
            Vec3::from(placement::tracing_point(world, origin))
        };
        let normals = mesh
            .normals
            .as_ref()
            .zip(placement.normal_matrix)
            .map(|(ns, m)| order.map(|i| (m * Vec3::from(ns[i as usize])).normalize_or_zero()));
        HitTriangle {
            corners: order.map(corner),
            normals,
            texcoords: mesh.texcoords.as_ref().map(|t| order.map(|i| t[i as usize])),
            u,
            v,
            material: mesh.material,
        }
    }

    /// The placement a hit through prototype instance `instance` on member `member` is.
    pub fn placement_of(&self, instance: u32, member: u32) -> u32 {
        self.instances[instance as usize].first_placement + member
    }

    /// Placement `p` copied into tracing coordinates, as `--flatten` would hold it.
    pub fn flattened(&self, p: u32, origin: DVec3) -> super::WorldMesh {
        let placement = &self.placements[p as usize];
        let mesh = &self.meshes[placement.mesh as usize];
        let source = crate::sys::scene_io::GltfMesh {
            positions: mesh.positions.clone(),
            normals: mesh.normals.clone(),
            texcoords: mesh.texcoords.clone(),
            indices: mesh.indices.clone(),
            material: None,
        };
        let (mut world, _) = placement::place_mesh(&source, placement.world, origin, mesh.material);
        world.object = placement.object;
        world
    }

    /// Triangles the placements put in the scene (each placement counts its own).
    pub fn placed_triangles(&self) -> usize {
        let per_mesh: Vec<usize> = self.meshes.iter().map(|m| m.indices.len()).collect();
        self.placements.iter().map(|p| per_mesh[p.mesh as usize]).sum()
    }

    /// Triangles stored (and in Embree's prototypes' BVHs): each shared mesh once.
    pub fn stored_triangles(&self) -> usize {
        self.meshes.iter().map(|m| m.indices.len()).sum()
    }

    /// Bytes the shared meshes and the placements take.
    pub fn memory_bytes(&self) -> u64 {
        let mesh = |m: &SharedMesh| {
            m.positions.len() * 12
                + m.normals.as_ref().map_or(0, |n| n.len() * 12)
                + m.texcoords.as_ref().map_or(0, |t| t.len() * 8)
                + m.indices.len() * 12
        };
        (self.meshes.iter().map(mesh).sum::<usize>()
            + self.placements.len() * std::mem::size_of::<Placement>()
            + self.instances.len() * std::mem::size_of::<PrototypeInstance>()) as u64
    }
}

/// What loading does with each glTF instance (placement of a mesh).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// Copied into world space, as every mesh used once is.
    Flatten,
    /// Placement `p` of a shared mesh.
    Placed(u32),
}

/// The world-space survey of every placement of the meshes used more than once, made before
/// the tracing origin is known (the origin is the centre of bounds the survey computes).
pub struct Surveys {
    /// Per glTF instance: its survey, for meshes used more than once.
    per_instance: Vec<Option<Surveyed>>,
    /// Per glTF mesh used more than once: the triangles its first placement keeps.
    reference: Vec<Option<Vec<bool>>>,
}

type Surveyed = placement::PlacementSurvey;

impl Surveys {
    /// Surveys every placement of each mesh used more than once (`flatten`: none).
    pub fn of(gltf: &GltfScene, flatten: bool) -> Surveys {
        let mut per_instance = vec![None; gltf.instances.len()];
        let mut reference = vec![None; gltf.meshes.len()];
        if flatten {
            return Surveys {
                per_instance,
                reference,
            };
        }
        let mut uses: Vec<Vec<usize>> = vec![Vec::new(); gltf.meshes.len()];
        for (i, instance) in gltf.instances.iter().enumerate() {
            uses[instance.mesh].push(i);
        }
        let world = |i: usize| DMat4::from_cols_array(&gltf.instances[i].world);
        // First placements, then the rest on every core: x32's 1,344 placements of 10.6
        // million triangles took 0.15 s on one.
        let mut references: Vec<Option<placement::Reference>> = (0..gltf.meshes.len()).map(|_| None).collect();
        let mut rest = Vec::new();
        for (m, users) in uses.iter().enumerate().filter(|(_, u)| u.len() >= 2) {
            let (r, first) = placement::survey_first(&gltf.meshes[m], &world(users[0]));
            per_instance[users[0]] = Some(first);
            references[m] = Some(r);
            rest.extend(users[1..].iter().map(|&i| (m, i)));
        }
        let next = std::sync::atomic::AtomicUsize::new(0);
        let threads = std::thread::available_parallelism()
            .map_or(1, |n| n.get())
            .min(rest.len().max(1));
        let surveyed: Vec<Vec<(usize, Surveyed)>> = std::thread::scope(|scope| {
            let workers: Vec<_> = (0..threads)
                .map(|_| {
                    scope.spawn(|| {
                        let (mut out, mut points) = (Vec::new(), Vec::new());
                        loop {
                            let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                            let Some(&(m, i)) = rest.get(k) else {
                                return out;
                            };
                            let reference = references[m].as_ref().expect("surveyed first");
                            out.push((
                                i,
                                placement::survey_next(&gltf.meshes[m], &world(i), reference, &mut points),
                            ));
                        }
                    })
                })
                .collect();
            workers
                .into_iter()
                .map(|w| w.join().expect("a survey thread panicked"))
                .collect()
        });
        for (i, s) in surveyed.into_iter().flatten() {
            per_instance[i] = Some(s);
        }
        for (m, r) in references.into_iter().enumerate() {
            reference[m] = r.map(|r| r.kept);
        }
        Surveys {
            per_instance,
            reference,
        }
    }

    /// Per glTF instance, the bounds `placement::tracing_origin` needs, where surveyed.
    pub fn used_bounds(&self) -> Vec<Option<Bounds>> {
        self.per_instance.iter().map(|s| s.map(|s| s.used)).collect()
    }
}

/// The decision for a whole scene: a role per glTF instance, the shared meshes and placements
/// (objects not yet numbered), and each placement's bounds in tracing coordinates.
pub struct Plan {
    pub roles: Vec<Role>,
    pub instancing: Instancing,
    /// Per placement: the bounds of its kept triangles' corners, in tracing coordinates.
    pub bounds: Vec<(Vec3, Vec3)>,
}

/// Relative transforms of two placements lists agree within this fraction of the largest
/// entry: far below f32's resolution, so members sharing a prototype are placed where their
/// own transforms put them (their hits are computed with their own transforms in any case).
const SAME_TRANSFORM: f64 = 1e-12;

/// Decides which glTF instances become placements of shared meshes and which are copied: a
/// mesh's placements that keep the triangles its first one keeps are shared, when there are
/// at least two of them; every other placement is copied.
pub fn plan(gltf: &GltfScene, surveys: &Surveys, origin: DVec3, default_material: u32) -> Plan {
    let mut roles = vec![Role::Flatten; gltf.instances.len()];
    let mut instancing = Instancing::default();
    let mut bounds = Vec::new();
    let mut users: Vec<Vec<usize>> = vec![Vec::new(); gltf.meshes.len()];
    for (i, instance) in gltf.instances.iter().enumerate() {
        if surveys.per_instance[i].is_some_and(|s| s.regular) {
            users[instance.mesh].push(i);
        }
    }
    // Per shared mesh: its id and the glTF instances that are its placements.
    let mut shared: Vec<(u32, Vec<usize>)> = Vec::new();
    for (m, users) in users.into_iter().enumerate() {
        let Some(kept) = surveys.reference[m].as_ref() else {
            continue;
        };
        if users.len() < 2 || !kept.contains(&true) {
            continue;
        }
        let source = &gltf.meshes[m];
        let indices: Vec<[u32; 3]> = (source.indices.iter().zip(kept))
            .filter(|(_, k)| **k)
            .map(|(t, _)| *t)
            .collect();
        let id = instancing.meshes.len() as u32;
        instancing.meshes.push(SharedMesh {
            positions: source.positions.clone(),
            normals: source.normals.clone(),
            texcoords: source.texcoords.clone(),
            dropped: source.indices.len() - indices.len(),
            indices,
            material: source.material.map_or(default_material, |k| k as u32),
        });
        shared.push((id, users));
    }

    // Prototypes: shared meshes whose placements are related by the same transforms.
    let world = |i: usize| DMat4::from_cols_array(&gltf.instances[i].world);
    let relative = |users: &[usize]| -> Option<Vec<DMat4>> {
        let first = world(users[0]).try_inverse()?;
        Some(users.iter().map(|&i| world(i) * first).collect())
    };
    let mut groups: Vec<(Vec<DMat4>, Vec<usize>)> = Vec::new(); // relative transforms, entries of `shared`
    for (entry, (_, users)) in shared.iter().enumerate() {
        let Some(rel) = relative(users) else {
            groups.push((Vec::new(), vec![entry]));
            continue;
        };
        match (groups.iter_mut()).find(|(r, _)| !r.is_empty() && same_transforms(r, &rel)) {
            Some((_, members)) => members.push(entry),
            None => groups.push((rel, vec![entry])),
        }
    }

    let tracing = |i: usize| {
        let s = surveys.per_instance[i].expect("shared placements are surveyed");
        placement::tracing_bounds(s.kept_bounds, origin)
    };
    for (rel, entries) in &groups {
        let prototype = instancing.prototypes.len() as u32;
        // The prototype's space: the first placements' world space, moved to their centre.
        let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        for &e in entries {
            let (l, h) = tracing(shared[e].1[0]);
            lo = lo.min(l);
            hi = hi.max(h);
        }
        let anchor = origin + (0.5 * (lo + hi)).as_dvec3();
        let to_anchor = DMat4::from_translation(-anchor);
        instancing.prototypes.push(Prototype {
            members: entries.iter().map(|&e| shared[e].0).collect(),
            to_prototype: entries.iter().map(|&e| to_anchor * world(shared[e].1[0])).collect(),
        });
        for k in 0..shared[entries[0]].1.len() {
            // Placement k of every member, in member order.
            let relative_k = if rel.is_empty() { DMat4::IDENTITY } else { rel[k] };
            instancing.instances.push(PrototypeInstance {
                prototype,
                first_placement: instancing.placements.len() as u32,
                to_tracing: DMat4::from_translation(-origin) * relative_k * DMat4::from_translation(anchor),
            });
            for &e in entries {
                let (mesh, users) = &shared[e];
                let i = users[k];
                let world = world(i);
                let normal_matrix = DMat3::from_mat4(world).inverse().transpose().as_mat3();
                roles[i] = Role::Placed(instancing.placements.len() as u32);
                bounds.push(tracing(i));
                instancing.placements.push(Placement {
                    mesh: *mesh,
                    world,
                    normal_matrix: normal_matrix.is_finite().then_some(normal_matrix),
                    mirrored: world.determinant() < 0.0,
                    object: 0,
                });
            }
        }
    }
    Plan {
        roles,
        instancing,
        bounds,
    }
}

/// Whether two lists of transforms are the same, entry by entry, within `SAME_TRANSFORM` of
/// each matrix's largest entry.
fn same_transforms(a: &[DMat4], b: &[DMat4]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(x, y)| {
            let (x, y) = (x.to_cols_array(), y.to_cols_array());
            let scale = x.iter().chain(&y).fold(1.0f64, |s, v| s.max(v.abs()));
            x.iter().zip(&y).all(|(p, q)| (p - q).abs() <= SAME_TRANSFORM * scale)
        })
}

/// Embree's 3x4 column-major transform of a prototype instance (f32).
pub fn embree_transform(m: &DMat4) -> [f32; 12] {
    let c = m.to_cols_array();
    [
        c[0], c[1], c[2], c[4], c[5], c[6], c[8], c[9], c[10], c[12], c[13], c[14],
    ]
    .map(|v| v as f32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sys::scene_io::{GltfInstance, GltfMesh};
    use glam::DQuat;

    fn mesh_with_normals() -> GltfMesh {
        GltfMesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.5]],
            normals: Some(vec![[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, 0.6, 0.8], [0.0, 0.0, 1.0]]),
            texcoords: Some(vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]),
            indices: vec![[0, 1, 2], [1, 3, 2]],
            material: None,
        }
    }

    fn scene(meshes: Vec<GltfMesh>, placements: &[(usize, DMat4)]) -> GltfScene {
        GltfScene {
            meshes,
            instances: placements
                .iter()
                .enumerate()
                .map(|(node, (mesh, world))| GltfInstance {
                    mesh: *mesh,
                    world: world.to_cols_array(),
                    node,
                    node_name: String::new(),
                })
                .collect(),
            ..Default::default()
        }
    }

    /// A non-uniform scale, a rotation and a mirror: the transforms the tests place by.
    fn transforms() -> Vec<DMat4> {
        vec![
            DMat4::from_translation(DVec3::new(3.0, 0.0, 0.0)),
            DMat4::from_scale_rotation_translation(
                DVec3::new(2.0, 0.5, 3.0),
                DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -0.7, 1.1),
                DVec3::new(-4.0, 2.0, 1.0),
            ),
            DMat4::from_scale_rotation_translation(
                DVec3::new(-1.5, 1.0, 1.0),
                DQuat::from_rotation_y(0.4),
                DVec3::new(0.0, -5.0, 2.0),
            ),
        ]
    }

    /// Every placement's hit triangle is exactly the flattened copy's: corners, normals,
    /// texture coordinates and winding (and so its geometric normal), bit for bit.
    #[test]
    fn hit_triangles_are_the_flattened_copys() {
        let placements: Vec<(usize, DMat4)> = transforms().into_iter().map(|t| (0, t)).collect();
        let gltf = scene(vec![mesh_with_normals()], &placements);
        let origin = DVec3::new(0.5, -0.25, 0.0);
        let plan = plan(&gltf, &Surveys::of(&gltf, false), origin, 0);
        assert!(plan.roles.iter().all(|r| matches!(r, Role::Placed(_))));
        for (k, (_, world)) in placements.iter().enumerate() {
            let (copy, _) = placement::place_mesh(&gltf.meshes[0], *world, origin, 0);
            let Role::Placed(p) = plan.roles[k] else { unreachable!() };
            for (prim, &[a, b, c]) in copy.indices.iter().enumerate() {
                // Embree's barycentrics refer to the shared mesh's winding.
                let (u, v) = (0.25, 0.5);
                let t = plan.instancing.hit_triangle(p, prim as u32, u, v, origin);
                let expect = [a, b, c].map(|i| Vec3::from(copy.positions[i as usize]));
                assert_eq!(t.corners, expect, "placement {k}, triangle {prim}");
                let normals = copy.normals.as_ref().unwrap();
                assert_eq!(t.normals.unwrap(), [a, b, c].map(|i| normals[i as usize]));
                let uvs = copy.texcoords.as_ref().unwrap();
                assert_eq!(t.texcoords.unwrap(), [a, b, c].map(|i| uvs[i as usize]));
                // The same point of the triangle, whichever winding.
                let point = |c: [Vec3; 3], u: f32, v: f32| (1.0 - u - v) * c[0] + u * c[1] + v * c[2];
                let mirrored = world.determinant() < 0.0;
                assert_eq!(mirrored, (t.u, t.v) == (v, u));
                let shared = plan.instancing.meshes[0].indices[prim];
                let unmirrored = shared.map(|i| {
                    Vec3::from(placement::tracing_point(
                        world.transform_point3(DVec3::from(gltf.meshes[0].positions[i as usize].map(f64::from))),
                        origin,
                    ))
                });
                assert!((point(t.corners, t.u, t.v) - point(unmirrored, u, v)).length() < 1e-5);
            }
        }
    }

    /// Normals go through the inverse transpose: under a non-uniform scale they stay
    /// perpendicular to the placed surface (the transformed normal would not).
    #[test]
    fn normals_stay_perpendicular_under_non_uniform_scale() {
        let tilted = GltfMesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 0.0]],
            normals: Some(vec![
                [
                    -std::f32::consts::FRAC_1_SQRT_2,
                    0.0,
                    std::f32::consts::FRAC_1_SQRT_2
                ];
                3
            ]),
            texcoords: None,
            indices: vec![[0, 1, 2]],
            material: None,
        };
        let squash = DMat4::from_scale(DVec3::new(4.0, 1.0, 0.25));
        let gltf = scene(vec![tilted], &[(0, squash), (0, DMat4::IDENTITY)]);
        let plan = plan(&gltf, &Surveys::of(&gltf, false), DVec3::ZERO, 0);
        let t = plan.instancing.hit_triangle(0, 0, 0.2, 0.2, DVec3::ZERO);
        let [p0, p1, p2] = t.corners;
        let face = (p1 - p0).cross(p2 - p0).normalize();
        for n in t.normals.unwrap() {
            assert!((n.length() - 1.0).abs() < 1e-6);
            assert!((p1 - p0).dot(n).abs() < 1e-6 && (p2 - p0).dot(n).abs() < 1e-6, "{n}");
            assert!(n.dot(face) > 0.999);
        }
        // Transforming the normal like a direction tilts it off the surface.
        let naive = (squash.transform_vector3(DVec3::new(-1.0, 0.0, 1.0)))
            .as_vec3()
            .normalize();
        assert!((p1 - p0).dot(naive).abs() > 0.5);
    }

    #[test]
    fn meshes_used_once_stay_flattened_and_flatten_copies_everything() {
        let gltf = scene(
            vec![mesh_with_normals(), mesh_with_normals()],
            &[(0, DMat4::IDENTITY), (1, transforms()[0]), (1, transforms()[1])],
        );
        let p = plan(&gltf, &Surveys::of(&gltf, false), DVec3::ZERO, 0);
        assert_eq!(p.roles, vec![Role::Flatten, Role::Placed(0), Role::Placed(1)]);
        assert_eq!(p.instancing.meshes.len(), 1);
        let all = plan(&gltf, &Surveys::of(&gltf, true), DVec3::ZERO, 0);
        assert!(all.roles.iter().all(|r| *r == Role::Flatten));
        assert!(all.instancing.is_empty());
    }

    /// Meshes placed together (a room's furniture under 3 parent nodes) share one prototype
    /// with an instance per parent; a mesh placed otherwise gets its own.
    #[test]
    fn meshes_placed_together_share_a_prototype() {
        let rooms = transforms();
        let local = [
            DMat4::IDENTITY,
            DMat4::from_translation(DVec3::new(0.0, 0.0, 2.0)),
            DMat4::from_rotation_z(0.5),
        ];
        let mut placements = Vec::new();
        for room in &rooms {
            for (m, l) in local.iter().enumerate() {
                placements.push((m, *room * *l));
            }
        }
        // Mesh 3: twice, elsewhere.
        placements.push((3, DMat4::from_translation(DVec3::splat(9.0))));
        placements.push((3, DMat4::from_translation(DVec3::splat(-9.0))));
        let gltf = scene(vec![mesh_with_normals(); 4], &placements);
        let p = plan(&gltf, &Surveys::of(&gltf, false), DVec3::ZERO, 0);
        let inst = &p.instancing;
        assert_eq!(inst.prototypes.len(), 2);
        assert_eq!(inst.prototypes[0].members, vec![0, 1, 2]);
        assert_eq!(inst.instances.len(), 3 + 2);
        // Each instance places each member where the member's own transform puts it.
        for instance in &inst.instances {
            let proto = &inst.prototypes[instance.prototype as usize];
            for (m, to_prototype) in proto.to_prototype.iter().enumerate() {
                let placement = &inst.placements[(instance.first_placement as usize) + m];
                assert_eq!(placement.mesh, proto.members[m]);
                let through = instance.to_tracing * *to_prototype;
                for v in [DVec3::ZERO, DVec3::X, DVec3::new(0.3, 0.9, -2.0)] {
                    let d = through.transform_point3(v) - placement.world.transform_point3(v);
                    assert!(d.length() < 1e-12, "{d}");
                }
            }
        }
    }

    /// A placement that keeps other triangles than the rest (here: one whose scale makes a
    /// triangle's area vanish) is copied, so the triangles never depend on instancing.
    #[test]
    fn a_placement_that_drops_other_triangles_is_copied() {
        let flat_in_z = DMat4::from_scale(DVec3::new(1.0, 1.0, 0.0));
        let standing = GltfMesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            normals: None,
            texcoords: None,
            indices: vec![[0, 1, 2], [0, 1, 3]],
            material: None,
        };
        let gltf = scene(
            vec![standing],
            &[(0, DMat4::IDENTITY), (0, flat_in_z), (0, transforms()[1])],
        );
        let p = plan(&gltf, &Surveys::of(&gltf, false), DVec3::ZERO, 0);
        assert_eq!(p.roles, vec![Role::Placed(0), Role::Flatten, Role::Placed(1)]);
        assert_eq!(p.instancing.meshes[0].indices.len(), 2);
    }
}

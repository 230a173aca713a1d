//! The temporal irradiance cache: which records of the last frame still hold once meshes have
//! moved (`scene::posing::PoseChange`), so a sequence keeps the others and its next prepass
//! makes only what the moves left missing.
//!
//! A record's value is the light its hemisphere sees. A moved mesh changes it in three ways,
//! each bounded here by a region of space around the mesh's box before and after the move:
//! - the mesh itself, seen or no longer seen (its box);
//! - the light it bounces onto and takes from the surfaces round it (its box grown by its own
//!   size on every side: the contact shadows and colour bleeding of the next bounce);
//! - its shadows on the surfaces the record sees (per light, the box's shadow volume away from
//!   the light, clipped to the scene's bounds).
//!
//! A region changes a record by at most the share of the record's cosine-weighted hemisphere it
//! covers, times how much the light from it changes. A record is dropped when its regions'
//! shares (each weighted by the change it may bring) add up to more than `TOLERANCE`, or when its
//! disc reaches into one; the rest are kept unchanged, so where no move reaches, frames read the
//! same records and give the same pixels (no flicker). A moved light (a punctual light, or an
//! emissive mesh) changes the direct light on every surface: every record is dropped. A dropped
//! record is made again at its own point (`record_origins`) unless a moved mesh took its place.
//!
//! Each bound holds against the records made for the pose before, so a record kept for many
//! frames is off by at most two regions' shares: the pose it was made for and the current one.

use super::record::Record;
use crate::scene::Scene;
use crate::scene::posing::{Aabb, PoseChange};
use glam::Vec3;

/// Largest weighted share of a record's hemisphere the moves may cover before it is made again:
/// 5 % of its value, within the noise two renders of one frame differ by (relMSE 5e-4 to 3.5e-3
/// on a Cornell box's ceiling, 2-6 % rms). Measured by bench/frames_moving.py (a crate pushed
/// through the conference room, 320x180, 3 frames), when a dropped record was still placed
/// anew by the prepass (not yet made again at its point): at 0.005, 0.02, 0.05 and 0.2 the
/// frames after the first kept 24 %, 71 %, 83 % and 87 % of the records, and their 4x4 relMSE
/// against the frame rendered alone at 4 samples a pixel was 4.9e-4, 5.7e-4, 5.3e-4 and 5.3e-4
/// (the frame alone: 4.8e-4); far from the crate the frames differed by 8e-5, 1.4e-4, 9e-8 and
/// 1e-8 (relMSE). The latest run with this value: docs/FRAMES.md.
pub const TOLERANCE: f32 = 0.05;

/// The near region: the box grown on every side by this many times its largest side.
const NEAR_GROWTH: f32 = 1.0;

/// How much of the light from each region may change, as a share of the light the record sees
/// there: the mesh itself all of it; the near region's surfaces and the shadows' volumes some of
/// it (a shadow darkens the part of its volume's surfaces it falls on, not the whole volume).
const MESH_CHANGE: f32 = 1.0;
const NEAR_CHANGE: f32 = 0.25;
const SHADOW_CHANGE: f32 = 0.5;

/// At most this many lights cast shadows (more emitting triangles are grouped by object).
const MAX_LIGHTS: usize = 64;

/// Where a light is, for the shadows a box casts away from it.
#[derive(Clone, Copy, Debug)]
enum LightPlace {
    /// A point or spot light, or emitting triangles' box (its corners stand for it).
    Box(Aabb),
    /// A directional light: the direction its light travels.
    Direction(Vec3),
}

/// A light, with what it gives a point facing it (for its share of a mesh's light).
#[derive(Clone, Debug)]
struct ShadowCaster {
    place: LightPlace,
    /// The punctual light, or the emitting triangles, that it is.
    source: Caster,
}

#[derive(Clone, Debug)]
enum Caster {
    Punctual(crate::scene::light::PunctualLight),
    Triangles(Vec<crate::scene::light::EmitterTriangle>),
}

impl ShadowCaster {
    /// The luminance of the irradiance it gives a surface at `p` facing it, unshadowed.
    fn irradiance_at(&self, p: Vec3) -> f32 {
        use crate::scene::light::luminance;
        match &self.source {
            Caster::Punctual(light) => light.illuminate(p).map_or(0.0, |s| luminance(s.irradiance)),
            Caster::Triangles(triangles) => triangles
                .iter()
                .map(|t| {
                    let centre = t.p0 + (t.e1 + t.e2) / 3.0;
                    let to = p - centre;
                    let d2 = to.length_squared().max(1e-12);
                    let facing = (t.normal.dot(to) / d2.sqrt()).max(0.0);
                    luminance(t.radiance) * t.area * facing / d2
                })
                .sum(),
        }
    }
}

/// The regions of space whose light the moves may have changed.
#[derive(Clone, Debug, Default)]
pub struct Disturbance {
    /// Every record is affected (a light moved).
    pub everywhere: bool,
    /// Per moved mesh, per pose (before, after): its regions, each with the share of the
    /// light from it that may change.
    moves: Vec<[PoseRegions; 2]>,
    /// The moved meshes' boxes, before and after.
    moved: Vec<Aabb>,
}

/// One pose's regions, and what the faintest of them (left out) may add together: their
/// changes summed, as if each covered the whole hemisphere.
#[derive(Clone, Debug, Default)]
struct PoseRegions {
    regions: Vec<(Aabb, f32)>,
    left_out: f32,
}

/// The faintest regions of a pose are not looked at one by one (a frame's grid sites and
/// records are tested against every region) while their changes add up to at most this share
/// of `TOLERANCE`: counted whole instead.
const LEFT_OUT_SHARE: f32 = 0.25;

impl PoseRegions {
    fn of(mut regions: Vec<(Aabb, f32)>) -> PoseRegions {
        regions.sort_by(|a, b| b.1.total_cmp(&a.1));
        let mut left_out = 0.0;
        while let Some(&(_, change)) = regions.last() {
            if left_out + change > LEFT_OUT_SHARE * TOLERANCE {
                break;
            }
            left_out += change;
            regions.pop();
        }
        PoseRegions { regions, left_out }
    }
}

/// The records a move left and those it took.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Invalidation {
    pub kept: u64,
    pub invalidated: u64,
}

/// How far along `d` from `from` (inside `scene`) the scene's box ends, in units of `d`.
fn exit_along(from: Vec3, d: Vec3, scene: &Aabb) -> f32 {
    let mut t = f32::INFINITY;
    for axis in 0..3 {
        if d[axis] > 0.0 {
            t = t.min((scene.hi[axis] - from[axis]) / d[axis]);
        } else if d[axis] < 0.0 {
            t = t.min((scene.lo[axis] - from[axis]) / d[axis]);
        }
    }
    t.max(0.0)
}

/// The box of the shadow `b` casts away from `light` inside `scene`. A point x is in the shadow
/// of a light point l when x = s + t (s - l) for a point s of `b` and t >= 0, up to where that
/// ray leaves the scene: the box of the mesh's corners and of where the rays from the light's
/// corners through them leave the scene. (A point light's shadow volume is the hull of those
/// points, unless it leaves the scene across one of the box's edges or corners, where the box of
/// them may cut a sliver off; a box of light points projects through each mesh corner onto the
/// walls as its corners do.)
fn shadow_box(b: &Aabb, light: LightPlace, scene: &Aabb) -> Option<Aabb> {
    let mut points: Vec<Vec3> = b.corners().to_vec();
    match light {
        LightPlace::Direction(d) => {
            for s in b.corners() {
                points.push(s + d * exit_along(s, d, scene));
            }
        }
        LightPlace::Box(l) => {
            // The light's box reaching into the mesh's: its shadow may be anywhere.
            if l.meets(b) {
                return Some(*scene);
            }
            for lc in l.corners() {
                for s in b.corners() {
                    let d = s - lc;
                    points.push(s + d * exit_along(s, d, scene));
                }
            }
        }
    }
    Aabb::around(points).and_then(|s| s.clipped(scene))
}

/// The scene's lights as shadow casters: its punctual lights, and its emitting triangles one
/// by one, or grouped by object (a lamp) where there are more than `MAX_LIGHTS`, the dimmest
/// groups merged into one.
fn shadow_casters(scene: &Scene) -> Vec<ShadowCaster> {
    let mut casters: Vec<ShadowCaster> = Vec::new();
    for light in &scene.punctual_lights {
        let place = match light.kind {
            crate::sys::scene_io::LightType::Directional => LightPlace::Direction(light.direction),
            _ => LightPlace::Box(Aabb {
                lo: light.position,
                hi: light.position,
            }),
        };
        casters.push(ShadowCaster {
            place,
            source: Caster::Punctual(light.clone()),
        });
    }
    let triangles = &scene.emitters.triangles;
    let mut groups: Vec<Vec<crate::scene::light::EmitterTriangle>> = if triangles.len() <= MAX_LIGHTS {
        triangles.iter().map(|t| vec![t.clone()]).collect()
    } else {
        let mut by_object: std::collections::BTreeMap<u32, Vec<_>> = std::collections::BTreeMap::new();
        for t in triangles {
            by_object.entry(t.object).or_default().push(t.clone());
        }
        by_object.into_values().collect()
    };
    let room = MAX_LIGHTS.saturating_sub(casters.len()).max(1);
    if groups.len() > room {
        let power = |g: &Vec<crate::scene::light::EmitterTriangle>| {
            g.iter()
                .map(|t| crate::scene::light::luminance(t.radiance) * t.area)
                .sum::<f32>()
        };
        groups.sort_by(|a, b| power(b).total_cmp(&power(a)));
        let rest: Vec<_> = groups.split_off(room - 1).into_iter().flatten().collect();
        groups.push(rest);
    }
    for group in groups {
        let Some(place) = Aabb::around(group.iter().flat_map(|t| [t.p0, t.p0 + t.e1, t.p0 + t.e2])) else {
            continue;
        };
        casters.push(ShadowCaster {
            place: LightPlace::Box(place),
            source: Caster::Triangles(group),
        });
    }
    casters
}

impl Disturbance {
    /// The regions `change` may have changed the light of, in `scene` as now placed (its
    /// lights cast the shadows; its bounds clip them).
    pub fn of(change: &PoseChange, scene: &Scene) -> Disturbance {
        if change.is_empty() {
            // A camera's frame: nothing to look at (not even the lights).
            return Disturbance::default();
        }
        let moved = change.moved.iter().flat_map(|(a, b)| [*a, *b]).collect();
        if change.lights_moved {
            return Disturbance {
                everywhere: true,
                moves: Vec::new(),
                moved,
            };
        }
        let bounds = Aabb {
            lo: scene.bounds_min,
            hi: scene.bounds_max,
        };
        let casters = shadow_casters(scene);
        let regions = |b: &Aabb| {
            let side = (b.hi - b.lo).max_element();
            let mut out = vec![(*b, MESH_CHANGE), (b.grown(NEAR_GROWTH * side), NEAR_CHANGE)];
            // A light's shadow changes the light of the surfaces it falls on by at most that
            // light's share of what reaches them; taken where the mesh is (its shadow's start).
            let given: Vec<f32> = casters.iter().map(|c| c.irradiance_at(b.centre())).collect();
            let total: f32 = given.iter().sum();
            for (caster, given) in casters.iter().zip(given) {
                let share = if total > 0.0 { given / total } else { 1.0 };
                if let Some(shadow) = shadow_box(b, caster.place, &bounds) {
                    out.push((shadow, SHADOW_CHANGE * share));
                }
            }
            out
        };
        Disturbance {
            everywhere: false,
            moved,
            moves: (change.moved.iter())
                .map(|(before, after)| [PoseRegions::of(regions(before)), PoseRegions::of(regions(after))])
                .collect(),
        }
    }

    pub fn is_empty(&self) -> bool {
        !self.everywhere && self.moves.is_empty()
    }

    /// Whether `p` lies on or in a moved mesh, where it was or where it is (its box grown by a
    /// thousandth of its size: a point on its surface is in).
    pub fn on_moved_mesh(&self, p: Vec3) -> bool {
        (self.moved.iter()).any(|b| b.grown(1e-3 * (b.hi - b.lo).max_element()).contains(p))
    }

    /// Whether the moves may have changed `record`'s value by more than `TOLERANCE`. A mesh's
    /// effect on the record is its effect in the pose the record was made for less its effect
    /// now; both darken or both brighten the same surfaces, so the change is at most the larger
    /// of the two, not their sum. Several meshes' changes add.
    /// `record` is read over its radii widened by `blend` (`CacheSettings::blend`).
    pub fn disturbs(&self, record: &Record, blend: f32) -> bool {
        self.disturbs_point(record.position, record.normal, record.reach() * blend)
    }

    /// Whether the moves may have changed by more than `TOLERANCE` the light arriving at
    /// `position` on a surface facing `normal`, read over `reach` around it.
    pub fn disturbs_point(&self, position: Vec3, normal: Vec3, reach: f32) -> bool {
        if self.everywhere {
            return true;
        }
        let mut total = 0.0f32;
        for poses in &self.moves {
            let mut largest = 0.0f32;
            for pose in poses {
                let mut share = pose.left_out;
                for (region, change) in &pose.regions {
                    share += change * seen_share(region, position, normal, reach);
                }
                largest = largest.max(share);
            }
            total += largest;
            if total > TOLERANCE {
                return true;
            }
        }
        false
    }
}

/// The share of the cosine-weighted hemisphere over `p` (facing `normal`) that `region` may
/// cover: its area projected across the direction to it over pi times the squared distance to
/// its nearest point (the solid angle of a far box, over-estimated near it), at most 1; 1 when
/// the disc read around `p` (`reach`) reaches into the region (it is read where the light may
/// change wholly); 0 when the region lies wholly below the surface.
fn seen_share(region: &Aabb, p: Vec3, normal: Vec3, reach: f32) -> f32 {
    let nearest = p.clamp(region.lo, region.hi);
    let distance = (nearest - p).length();
    if distance <= reach {
        return 1.0;
    }
    // The corner highest above the surface's plane: below it, the whole box is.
    let e = region.hi - region.lo;
    let highest = (region.centre() - p).dot(normal) + 0.5 * normal.abs().dot(e);
    if highest < 0.0 {
        return 0.0;
    }
    let u = (region.centre() - p).normalize_or_zero();
    let projected = u.x.abs() * e.y * e.z + u.y.abs() * e.x * e.z + u.z.abs() * e.x * e.y;
    (projected / (std::f32::consts::PI * distance * distance)).min(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube(centre: Vec3, half: f32) -> Aabb {
        Aabb {
            lo: centre - Vec3::splat(half),
            hi: centre + Vec3::splat(half),
        }
    }

    fn record_at(position: Vec3, normal: Vec3) -> Record {
        let mut r = crate::irradiance::record::tests::flat_record(1.0, 0.01);
        r.position = position;
        r.normal = normal;
        r
    }

    #[test]
    fn a_shadow_box_holds_every_shadowed_point_it_was_made_for() {
        let scene = cube(Vec3::ZERO, 10.0);
        let mesh = cube(Vec3::new(1.0, 0.0, 0.5), 0.5);
        let lamp = Aabb {
            lo: Vec3::new(-1.0, 9.0, -1.0),
            hi: Vec3::new(1.0, 9.5, 1.0),
        };
        let shadow = shadow_box(&mesh, LightPlace::Box(lamp), &scene).unwrap();
        // Brute force: rays from points of the lamp through points of the mesh to the floor.
        let mut rng = 12345u64;
        let mut u = || {
            rng = rng.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (rng >> 40) as f32 / (1u64 << 24) as f32
        };
        for _ in 0..2000 {
            let l = lamp.lo + (lamp.hi - lamp.lo) * Vec3::new(u(), u(), u());
            let s = mesh.lo + (mesh.hi - mesh.lo) * Vec3::new(u(), u(), u());
            let d = s - l;
            // Where the ray meets the floor (y = -10), beyond the mesh.
            let t = (-10.0 - l.y) / d.y;
            let x = l + d * t;
            assert!(t >= 1.0);
            assert!(
                (shadow.lo - Vec3::splat(1e-3)).cmple(x).all() && x.cmple(shadow.hi + Vec3::splat(1e-3)).all(),
                "{x} outside {shadow:?}"
            );
        }
        // And the shadow stays below the mesh's top (light from above).
        assert!(shadow.hi.y <= mesh.hi.y + 1e-4, "{shadow:?}");
    }

    #[test]
    fn records_near_a_move_are_dropped_and_far_ones_kept() {
        let mut scene = Scene::of_parts(Vec::new(), Vec::new(), Vec::new());
        scene.bounds_min = Vec3::splat(-50.0);
        scene.bounds_max = Vec3::splat(50.0);
        let change = PoseChange {
            moved: vec![(
                cube(Vec3::new(0.0, -49.0, 0.0), 0.5),
                cube(Vec3::new(1.0, -49.0, 0.0), 0.5),
            )],
            lights_moved: false,
        };
        let d = Disturbance::of(&change, &scene);
        let up = Vec3::Y;
        // On the floor beside the mesh, and on the floor far away.
        assert!(d.disturbs(&record_at(Vec3::new(2.5, -50.0, 0.0), up), 1.0));
        assert!(!d.disturbs(&record_at(Vec3::new(40.0, -50.0, 40.0), up), 1.0));
        // A record facing away from the mesh, close to it, on a wall behind which it is.
        assert!(!d.disturbs(&record_at(Vec3::new(10.0, -45.0, 0.0), Vec3::X), 1.0));
        // Seen from across the room at a distance where it covers more than the tolerance.
        assert!(d.disturbs(&record_at(Vec3::new(5.0, -45.0, 0.0), -Vec3::X), 1.0));
        // A moved light takes every record.
        let lit = PoseChange {
            moved: Vec::new(),
            lights_moved: true,
        };
        assert!(Disturbance::of(&lit, &scene).disturbs(&record_at(Vec3::new(40.0, 40.0, 40.0), up), 1.0));
    }
}

//! A view for scenes that bring no camera and get no -vp, with +Y up (glTF's convention),
//! looking along the longer horizontal axis of the bounds (-Z when they are about equal), as a
//! viewer's "frame all" does. If the bounds are open on the near side (a Cornell box), the
//! whole box is framed from outside. If they are closed (a room, a nave), the eye steps inside
//! and takes the position from which it sees the most lit surface, farthest away (so it is
//! neither behind a wall nor in the dark gap between an outer and an inner wall). When no eye
//! on the bounds' centre line sees much lit surface (a building of many rooms, whose centre
//! line runs through walls and the gaps between rooms), eyes on a grid over the bounds' floor
//! plan, looking each of the four horizontal ways, are tried too: one of them stands in a room.

use super::view::{Projection, View};
use glam::Vec3;

pub const AUTO_VERTICAL_ANGLE: f32 = 45.0;
const INSIDE_VERTICAL_ANGLE: f32 = 60.0;
/// How far into the bounds (fractions of their depth) the eye may step when they are closed.
const INSIDE_CANDIDATES: [f32; 7] = [0.02, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5];
const PROBE_GRID: u32 = 8;
/// Below this share of lit probe rays the centre line is given up for the floor-plan grid.
const POOR_LIT_FRACTION: f32 = 0.25;
/// Eyes per horizontal axis of the floor-plan grid.
const PLAN_GRID: u32 = 8;

/// What a probe ray from the eye finds: the distance to the first surface, and whether a
/// light source shines on that point.
#[derive(Clone, Copy, Debug)]
pub struct Probe {
    pub distance: f32,
    pub lit: bool,
}

/// `probe(origin, unit direction)` reports the first surface along a ray, if any.
pub fn auto_view(bounds_min: Vec3, bounds_max: Vec3, aspect: f32, probe: impl Fn(Vec3, Vec3) -> Option<Probe>) -> View {
    auto_view_scored(bounds_min, bounds_max, aspect, probe).0
}

/// The automatic view and the share of its probe rays that found a lit surface (low: the
/// image will be mostly dark, and the caller says how to give a view).
pub fn auto_view_scored(
    bounds_min: Vec3,
    bounds_max: Vec3,
    aspect: f32,
    probe: impl Fn(Vec3, Vec3) -> Option<Probe>,
) -> (View, f32) {
    let centre = 0.5 * (bounds_min + bounds_max);
    let extent = (bounds_max - bounds_min).max(Vec3::splat(f32::MIN_POSITIVE));
    // Depth axis: Z unless X is clearly longer.
    let (axis, depth, width) = if extent.x > 1.1 * extent.z {
        (Vec3::X, extent.x, extent.z)
    } else {
        (Vec3::Z, extent.z, extent.x)
    };
    let near_face = centre + axis * (0.5 * depth);
    let tan_half = (AUTO_VERTICAL_ANGLE.to_radians() * 0.5).tan();
    let half_height = 0.5 * extent.y.max(width / aspect.max(1e-3));
    let outside = near_face + axis * (half_height / tan_half);
    let make = |position: Vec3, vertical: f32| View {
        projection: Projection::Perspective,
        position,
        direction: -axis,
        up: Vec3::Y,
        horizontal: View::horizontal_for_aspect(Projection::Perspective, vertical, aspect),
        vertical,
    };
    // Score of a view: lit surface it shows, counting farther surfaces a little more.
    let score = |view: &View| {
        let camera = view.camera(PROBE_GRID, PROBE_GRID);
        let mut lit_rays = 0u32;
        let mut seen = 0.0;
        for j in 0..PROBE_GRID {
            for i in 0..PROBE_GRID {
                let (o, d) = camera.ray(i as f32 + 0.5, j as f32 + 0.5);
                if let Some(p) = probe(o, d).filter(|p| p.lit) {
                    lit_rays += 1;
                    seen += 1.0 + p.distance / depth;
                }
            }
        }
        (lit_rays as f32 / (PROBE_GRID * PROBE_GRID) as f32, seen)
    };
    let outside_view = make(outside, AUTO_VERTICAL_ANGLE);
    // Most of the frame lit from outside: the box is open on this side.
    let outside_score = score(&outside_view);
    if outside_score.0 >= 0.5 {
        return (outside_view, outside_score.0);
    }
    let mut best = (outside_score.1, outside_score.0, outside_view);
    for fraction in INSIDE_CANDIDATES {
        let view = make(near_face - axis * (fraction * depth), INSIDE_VERTICAL_ANGLE);
        let (lit, seen) = score(&view);
        if seen > best.0 * 1.05 {
            best = (seen, lit, view);
        }
    }
    if best.1 >= POOR_LIT_FRACTION {
        return (best.2, best.1);
    }
    // The floor-plan grid: eyes at mid-height, each looking along +-X and +-Z.
    let mut plan_best: Option<(f32, f32, View)> = None;
    for i in 0..PLAN_GRID {
        for k in 0..PLAN_GRID {
            let at = |n: u32| (n as f32 + 0.5) / PLAN_GRID as f32;
            let eye = Vec3::new(
                bounds_min.x + at(i) * extent.x,
                centre.y,
                bounds_min.z + at(k) * extent.z,
            );
            for direction in [-Vec3::X, Vec3::X, -Vec3::Z, Vec3::Z] {
                let view = View {
                    direction,
                    ..make(eye, INSIDE_VERTICAL_ANGLE)
                };
                let (lit, seen) = score(&view);
                if plan_best.as_ref().is_none_or(|b| (lit, seen) > (b.0, b.1)) {
                    plan_best = Some((lit, seen, view));
                }
            }
        }
    }
    match plan_best {
        Some((lit, _, view)) if lit > best.1 => (view, lit),
        _ => (best.2, best.1),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn open_box_is_framed_from_outside() {
        // Everything the eye sees from outside is lit: the open side faces the eye.
        let v = auto_view(
            Vec3::new(-1.0, 0.0, -1.0),
            Vec3::new(1.0, 2.0, 1.0),
            1.0,
            |o: Vec3, d: Vec3| {
                let t = (-1.0 - o.z) / d.z;
                (t > 0.0).then_some(Probe { distance: t, lit: true })
            },
        );
        assert!(v.position.z > 1.0);
        assert!((v.position.y - 1.0).abs() < 1e-6);
        assert_eq!(v.direction, -Vec3::Z);
        // The whole 2-unit height fits in the vertical angle at the front face.
        let half = (v.position.z - 1.0) * (v.vertical.to_radians() * 0.5).tan();
        assert!(half >= 1.0 - 1e-4);
    }

    #[test]
    fn closed_room_is_viewed_from_inside_past_a_near_wall() {
        // A closed 10-unit room along X, lit only left of an inner wall at x = 9: from outside,
        // or from the gap between x = 9 and the end wall, the eye sees nothing lit.
        let wall = 9.0;
        let hit = |o: Vec3, d: Vec3| {
            let mut best: Option<f32> = None;
            for plane in [0.0f32, 10.0, wall] {
                if d.x.abs() > 1e-6 {
                    let t = (plane - o.x) / d.x;
                    if t > 1e-4 {
                        best = Some(best.map_or(t, |b| b.min(t)));
                    }
                }
            }
            best.map(|distance| Probe {
                distance,
                lit: o.x > 0.0 && o.x < wall,
            })
        };
        let v = auto_view(Vec3::ZERO, Vec3::new(10.0, 5.0, 5.0), 1.0, hit);
        assert_eq!(v.direction, -Vec3::X);
        assert!(v.position.x > 0.0 && v.position.x < wall, "eye at {}", v.position.x);
    }
}

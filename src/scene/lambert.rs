//! Exact, unshadowed irradiance from uniformly emitting triangles, by Lambert's contour
//! integral: the projected solid angle of a polygon seen from a point is half the sum, over its
//! edges, of the angle each edge subtends times the cosine between the receiver's normal and
//! the normal of the plane through the point and that edge. The polygon is first clipped to
//! the receiver's upper hemisphere, since light from below the surface does not count.
//!
//! The direct component uses it as the deterministic part of a ratio estimator: the shadow rays
//! then only estimate which fraction of this irradiance gets through, so a fully lit point has
//! no noise at all and a fully shadowed one none either.

use glam::DVec3;

/// Below this length (relative to the triangle's distance) a vertex is taken to coincide with
/// the point, where the formula has no meaning.
const COINCIDENT: f64 = 1e-9;
/// A point nearer the triangle's plane than this, relative to the largest coordinate involved,
/// counts as lying in it: well above the rounding of f32 coordinates (6e-8), well below any
/// gap a model leaves on purpose.
const IN_PLANE: f64 = 1e-5;

/// Projected solid angle (cosine-weighted solid angle, 0 ..= pi) of the triangle `a b c`,
/// emitting from the side its `front` normal points to, seen from `point` on a surface with
/// unit normal `normal`. Zero when the point is behind the triangle or the triangle is below
/// the surface's horizon (a point in the triangle's plane, on it or beside it, gets zero: it is
/// lit at grazing incidence). None when rounding puts a corner of the clipped polygon on the
/// point, where the formula has no finite answer; the caller then samples instead.
pub fn projected_solid_angle(point: DVec3, normal: DVec3, [a, b, c]: [DVec3; 3], front: DVec3) -> Option<f64> {
    let corners = [a - point, b - point, c - point];
    // The emitting side must face the point. A point in the triangle's plane (up to the
    // rounding of single-precision coordinates: a hit on the emitter itself, front or back)
    // gets nothing from it; without this margin rounding alone would decide between nothing
    // and the whole hemisphere.
    let magnitude = [point, a, b, c]
        .iter()
        .map(|v| v.abs().max_element())
        .fold(0.0, f64::max);
    if front.dot(-corners[0]) <= IN_PLANE * magnitude {
        return Some(0.0);
    }
    let scale = corners.iter().map(|v| v.length()).fold(0.0, f64::max);
    let mut polygon = [DVec3::ZERO; 4];
    let count = clip_above(corners, normal, &mut polygon);
    if count < 3 {
        return Some(0.0);
    }
    // Unit directions to the corners, each normalised once.
    for corner in &mut polygon[..count] {
        let length = corner.length();
        if length.is_nan() || length <= COINCIDENT * scale {
            return None;
        }
        *corner /= length;
    }
    let mut sum = 0.0;
    for i in 0..count {
        let (u, v) = (polygon[i], polygon[(i + 1) % count]);
        let cross = u.cross(v);
        let sine = cross.length();
        if sine <= 0.0 {
            // Collinear with the point: the edge subtends no angle (a clipped corner on the
            // horizon, or the point on the edge's line, whose plane term vanishes).
            continue;
        }
        let angle = sine.atan2(u.dot(v));
        sum += angle * normal.dot(cross) / sine;
    }
    let result = 0.5 * sum.abs();
    result.is_finite().then_some(result.min(std::f64::consts::PI))
}

/// Sutherland-Hodgman clipping of a triangle (vertices relative to the point) to the half-space
/// `normal . v >= 0`; writes the 0, 3 or 4 corners that remain and returns their count.
pub(crate) fn clip_above(corners: [DVec3; 3], normal: DVec3, out: &mut [DVec3; 4]) -> usize {
    let heights = corners.map(|v| normal.dot(v));
    if heights.iter().all(|&h| h >= 0.0) {
        out[..3].copy_from_slice(&corners);
        return 3;
    }
    let mut count = 0;
    for i in 0..3 {
        let j = (i + 1) % 3;
        let (hi, hj) = (heights[i], heights[j]);
        if hi >= 0.0 {
            out[count] = corners[i];
            count += 1;
        }
        if (hi >= 0.0) != (hj >= 0.0) {
            // The edge crosses the horizon: keep the crossing point.
            let t = hi / (hi - hj);
            out[count] = corners[i] + (corners[j] - corners[i]) * t;
            count += 1;
        }
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Rng;
    use std::f64::consts::PI;

    fn tri(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [DVec3; 3] {
        [DVec3::from(a), DVec3::from(b), DVec3::from(c)]
    }

    /// Projected solid angle (pi times the form factor from a differential area) of a parallel
    /// rectangle of sides x, y at height h with one corner straight above the point: the
    /// classic closed form.
    fn corner_rectangle(x: f64, y: f64, h: f64) -> f64 {
        let (a, b) = (x / h, y / h);
        let (sa, sb) = ((1.0 + a * a).sqrt(), (1.0 + b * b).sqrt());
        0.5 * (a / sa * (b / sa).atan() + b / sb * (a / sb).atan())
    }

    #[test]
    fn rectangle_over_a_corner_matches_the_closed_form() {
        for (x, y, h) in [(1.0, 1.0, 1.0), (0.3, 2.0, 0.5), (5.0, 0.1, 3.0), (1e-3, 1e-3, 1e4)] {
            let down = DVec3::NEG_Z;
            let halves = [
                tri([0.0, 0.0, h], [x, 0.0, h], [x, y, h]),
                tri([0.0, 0.0, h], [x, y, h], [0.0, y, h]),
            ];
            let got: f64 = halves
                .iter()
                .map(|&t| projected_solid_angle(DVec3::ZERO, DVec3::Z, t, down).unwrap())
                .sum();
            let expected = corner_rectangle(x, y, h);
            assert!(
                (got - expected).abs() <= 1e-9 + 1e-6 * expected,
                "{x}x{y} at {h}: {got} vs {expected}"
            );
        }
    }

    #[test]
    fn behind_below_and_on_the_emitter() {
        let t = tri([-1.0, -1.0, 1.0], [1.0, -1.0, 1.0], [0.0, 1.0, 1.0]);
        // Emitting upwards, away from the point: nothing.
        assert_eq!(projected_solid_angle(DVec3::ZERO, DVec3::Z, t, DVec3::Z), Some(0.0));
        // Receiver facing away from the triangle: all of it is below the horizon.
        assert_eq!(
            projected_solid_angle(DVec3::ZERO, DVec3::NEG_Z, t, DVec3::NEG_Z),
            Some(0.0)
        );
        // Receiver in the emitter's plane, facing along it: grazing, nothing arrives.
        let side = projected_solid_angle(DVec3::new(5.0, 0.0, 1.0), DVec3::NEG_X, t, DVec3::NEG_Z).unwrap();
        assert!(side.abs() < 1e-12, "{side}");
        // On the emitter itself, inside it, slightly off its plane either way by rounding:
        // nothing (not the whole hemisphere).
        for offset in [0.0, 1e-7, -1e-7] {
            let on = DVec3::new(0.0, 0.0, 1.0 + offset);
            assert_eq!(projected_solid_angle(on, DVec3::Z, t, DVec3::NEG_Z), Some(0.0));
            assert_eq!(projected_solid_angle(on, DVec3::NEG_Z, t, DVec3::NEG_Z), Some(0.0));
        }
        // A point on a vertex lies in the emitter's plane: grazing, nothing.
        assert_eq!(
            projected_solid_angle(DVec3::new(-1.0, -1.0, 1.0), DVec3::Z, t, DVec3::NEG_Z),
            Some(0.0)
        );
        // Right under a huge triangle the whole hemisphere glows: pi.
        let huge = tri([-1e3, -1e3, 1.0], [1e3, -1e3, 1.0], [0.0, 1e3, 1.0]);
        let all = projected_solid_angle(DVec3::ZERO, DVec3::Z, huge, DVec3::NEG_Z).unwrap();
        assert!((all - PI).abs() < 1e-4, "{all}");
    }

    /// Monte Carlo over the triangle's area: mean of cos_r cos_e / d^2 / pdf, the estimator the
    /// shadow rays use, restricted to the upper hemisphere.
    fn sampled(point: DVec3, normal: DVec3, t: [DVec3; 3], front: DVec3, rng: &mut Rng) -> f64 {
        let (e1, e2) = (t[1] - t[0], t[2] - t[0]);
        let area = 0.5 * e1.cross(e2).length();
        let n = 200_000;
        let mut sum = 0.0;
        for _ in 0..n {
            let su = (rng.next_f32() as f64).sqrt();
            let (b1, b2) = (1.0 - su, rng.next_f32() as f64 * su);
            let q = t[0] + b1 * e1 + b2 * e2;
            let offset = q - point;
            let d2 = offset.length_squared();
            let w = offset / d2.sqrt();
            let (cr, ce) = (normal.dot(w), -front.dot(w));
            if cr > 0.0 && ce > 0.0 {
                sum += cr * ce / d2 * area;
            }
        }
        sum / n as f64
    }

    #[test]
    fn clipped_and_tilted_triangles_match_sampling() {
        let mut rng = Rng::new(3, 7);
        for case in 0..40 {
            let r = |rng: &mut Rng| DVec3::new(rng.next_f32() as f64, rng.next_f32() as f64, rng.next_f32() as f64);
            let t = [
                r(&mut rng) * 4.0 - 2.0,
                r(&mut rng) * 4.0 - 2.0,
                r(&mut rng) * 4.0 - 2.0,
            ];
            let mut front = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
            let point = r(&mut rng) * 2.0 - 1.0;
            if front.dot(point - t[0]) < 0.0 {
                front = -front;
            }
            // Random receiver orientations put many triangles across the horizon.
            let normal = (r(&mut rng) * 2.0 - 1.0).normalize();
            let exact = projected_solid_angle(point, normal, t, front).unwrap();
            let estimate = sampled(point, normal, t, front, &mut rng);
            assert!(
                (exact - estimate).abs() <= 0.02 * estimate + 2e-3,
                "case {case}: exact {exact}, sampled {estimate}"
            );
        }
    }
}

//! One irradiance cache record and the test that decides whether, and how much, it may stand in
//! for the irradiance at another point.

use glam::Vec3;

/// Number of tangent-plane sectors the leak test divides a record's surroundings into.
pub const HORIZON_SECTORS: usize = 8;

/// The share of the way to a sector's obstacle over which a record's weight fades out.
const HORIZON_FADE: f32 = 0.25;

/// Two points whose headrooms differ by up to this factor count as under the same roof.
const SAME_ROOF_RATIO: f32 = 4.0;
/// Beyond it, how far (in the smaller headroom) one may stand in for the other, divided by how
/// much the ratio exceeds `SAME_ROOF_RATIO`.
const ROOF_REACH: f32 = 2.0;

/// A cached indirect diffuse value, as Radiance keeps it: position, normal, the recursion level
/// and path weight it was made at, two radii along the principal directions of the irradiance
/// Hessian, relative gradients for translation and rotation, and the value itself (irradiance
/// over pi, so it is multiplied by the diffuse albedo to give L_a).
#[derive(Clone, Debug, PartialEq)]
pub struct Record {
    pub position: Vec3,
    pub normal: Vec3,
    /// First principal direction (unit, in the tangent plane); the second is normal x u_axis.
    pub u_axis: Vec3,
    /// Validity radii along u_axis and along normal x u_axis.
    pub radii: [f32; 2],
    /// Harmonic mean distance of the hemisphere's hits (Ward's split-sphere radius).
    pub harmonic_distance: f32,
    pub level: u32,
    pub weight: f32,
    pub value: Vec3,
    /// Gradient of the value's luminance over position, divided by that luminance.
    pub translation_gradient: Vec3,
    /// Gradient over the normal's direction, divided by the luminance.
    pub rotation_gradient: Vec3,
    /// Per tangent-plane sector around u_axis, the horizontal distance to the nearest low
    /// obstacle the hemisphere saw: light cannot be extrapolated past it (leak test).
    pub horizon: [f32; HORIZON_SECTORS],
    /// How far the surface is free along its normal (the first surface a ray from the record
    /// along its normal meets, at most the scene's size): what the lookup point's own headroom
    /// is compared with (`under_one_roof`).
    pub headroom: f32,
    /// How far the first-order extrapolation overshoots, relative to the value, per unit of
    /// `t2` (0 at the record, 1 at its edge): fitted from the neighbouring records once the
    /// record set is complete (`validation::fit_curvatures`), 0 until then. Not stored or sent:
    /// every process derives it from the same records.
    pub curvature: f32,
}

/// Which error metric weighs records.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Metric {
    /// Radiance 5+: ellipse of Hessian radii, angle limit, smooth fall-off.
    Hessian,
    /// Ward et al. 1988: the split-sphere error, harmonic mean distance, weight 1 / error.
    Ward88,
}

/// The extrapolation factor of a record's gradients is held within these bounds, so a noisy
/// gradient cannot turn a value negative or blow it up. Symmetric about 1: a clamp that cut
/// one side more than the other would bias the cache.
const MIN_EXTRAPOLATION: f32 = 0.5;
const MAX_EXTRAPOLATION: f32 = 1.5;

fn clamp_extrapolation(factor: f32) -> f32 {
    if factor.is_finite() {
        factor.clamp(MIN_EXTRAPOLATION, MAX_EXTRAPOLATION)
    } else {
        1.0
    }
}

/// How much of a record's weight it keeps at a point `distance` away when the record and the
/// point have headrooms `a` and `b` (see `Record::headroom`): 1 while the two differ by
/// less than a factor of `SAME_ROOF_RATIO`, else fading to 0 (over the last `HORIZON_FADE`, as
/// the leak test does) at a distance that shrinks with the smaller headroom and the more the two differ.
/// A point under a lid (the ceiling above a light panel hanging 5 units below it, the floor
/// under a table) is lit through a gap its neighbours in the open know nothing of: their
/// hemispheres see the thin lid at grazing angles, if at all, so neither the radii nor the leak
/// test keep their light out. The conference room's ceiling strips above the panels read up to
/// 20x too bright, 0.9 of the indirect layer's +0.7 % against brute force.
pub fn under_one_roof(a: f32, b: f32, distance: f32) -> f32 {
    let (low, high) = (a.min(b), a.max(b));
    let excess = high / low - SAME_ROOF_RATIO;
    if excess.is_nan() || excess <= 0.0 || distance <= 0.0 {
        return 1.0;
    }
    let limit = ROOF_REACH * low / excess;
    ((limit - distance) / (HORIZON_FADE * limit)).clamp(0.0, 1.0)
}

/// The sector (of `HORIZON_SECTORS`, counter-clockwise from the u axis) of the tangent-plane
/// direction (u, v): the octant of its angle, found by comparisons instead of an arctangent
/// (every lookup asks it of every record it weighs).
pub fn sector(u: f32, v: f32) -> usize {
    let (au, av) = (u.abs(), v.abs());
    match (v >= 0.0, u > 0.0, u < 0.0) {
        (true, true, _) => usize::from(av >= au),
        (true, false, _) => 2 + usize::from(av <= au),
        (false, _, true) => 4 + usize::from(av >= au),
        (false, _, false) => 6 + usize::from(av <= au),
    }
}

/// Largest angle between a record's normal and a query's under the Hessian metric.
pub fn max_normal_deviation(accuracy: f32) -> f32 {
    (std::f32::consts::SQRT_2 * accuracy).min(std::f32::consts::FRAC_PI_4)
}

/// What tells records apart, and stays when validation revises one's radii or curvature.
pub type RecordIdentity = [[u32; 3]; 3];

impl Record {
    /// The bits of the position, normal and value: no two records made apart share them.
    pub fn identity(&self) -> RecordIdentity {
        [self.position, self.normal, self.value].map(|v| v.to_array().map(f32::to_bits))
    }

    pub fn v_axis(&self) -> Vec3 {
        self.normal.cross(self.u_axis)
    }

    /// The record as a finished cache reads it (`CacheSettings::blend`): its radii, and Ward's
    /// split-sphere distance, `blend` times those it was placed with; its curvature per unit of
    /// the wider `t2`, so that it subtracts the same overshoot at the same point.
    pub fn widened(&self, blend: f32) -> Record {
        Record {
            radii: self.radii.map(|r| r * blend),
            harmonic_distance: self.harmonic_distance * blend,
            curvature: self.curvature * blend * blend,
            ..self.clone()
        }
    }

    /// Largest distance from the record's position at which it can contribute.
    pub fn reach(&self) -> f32 {
        self.radii[0].max(self.radii[1])
    }

    /// The squared distance of a point from the record along its tangent plane, in units of
    /// its radii: 1 on the edge of its ellipse.
    pub fn t2(&self, point: Vec3) -> f32 {
        let offset = point - self.position;
        let tangent = offset - self.normal * offset.dot(self.normal);
        let du = tangent.dot(self.u_axis) / self.radii[0];
        let dv = tangent.dot(self.v_axis()) / self.radii[1];
        du * du + dv * dv
    }

    /// The record's value moved to (point, normal) by its gradients, less its fitted
    /// overshoot (`curvature`).
    pub fn extrapolate(&self, point: Vec3, normal: Vec3) -> Vec3 {
        let mut factor = self.gradient_factor(point, normal);
        if self.curvature != 0.0 {
            factor -= self.curvature * self.t2(point);
        }
        self.value * clamp_extrapolation(factor)
    }

    /// The value moved by the gradients alone (the tangent the curvature corrects).
    pub fn first_order(&self, point: Vec3, normal: Vec3) -> Vec3 {
        self.value * clamp_extrapolation(self.gradient_factor(point, normal))
    }

    fn gradient_factor(&self, point: Vec3, normal: Vec3) -> f32 {
        1.0 + self.translation_gradient.dot(point - self.position) + self.rotation_gradient.dot(normal - self.normal)
    }

    fn sector_of(&self, tangent_offset: Vec3) -> usize {
        sector(tangent_offset.dot(self.u_axis), tangent_offset.dot(self.v_axis()))
    }

    /// Weight of this record at a query point with unit normal `normal` (None when it may not
    /// be used there): the same level, not behind the point, within the metric's bounds, and no
    /// obstacle between them. Only the same level: a record holds the light of exactly the
    /// bounces left at its level, so a shallower one (as Radiance lets serve deeper lookups)
    /// adds a bounce the deeper lookup must not have; in a grey box under -av at -ab 2 it made
    /// the image up to 22 % dark with `--ic-deep records` (`tests/analytic.rs`).
    pub fn weight_at(&self, point: Vec3, normal: Vec3, level: u32, metric: Metric, accuracy: f32) -> Option<f32> {
        if self.level != level {
            return None;
        }
        let offset = point - self.position;
        // Ward's "in front" test: the point may not lie behind the record's surface.
        let average_normal = (normal + self.normal) * 0.5;
        let along = offset.dot(average_normal);
        let tangent_offset = offset - self.normal * offset.dot(self.normal);
        let cos_normals = normal.dot(self.normal).clamp(-1.0, 1.0);
        if along < -0.05 * self.radii[0].min(self.radii[1]) || cos_normals <= 0.0 {
            return None;
        }
        // The leak test last: most records a lookup weighs fail the cheaper bounds first. The
        // weight fades to zero over the last `HORIZON_FADE` of the way to the obstacle instead
        // of stopping there, so no step follows a record's horizon into the image.
        let unblocked = |weight: f32| {
            let horizon = self.horizon[self.sector_of(tangent_offset)];
            let fade = ((horizon - tangent_offset.length()) / (HORIZON_FADE * horizon)).min(1.0);
            (fade > 0.0).then_some(weight * fade)
        };
        match metric {
            Metric::Hessian => {
                // The ellipse first, the angle (an arccosine) only for records inside it.
                // What of the tangent offset is not along u is along v (u, v and the normal are
                // orthonormal): no cross product for v, no square root.
                let along_u = tangent_offset.dot(self.u_axis);
                let along_v2 = (tangent_offset.length_squared() - along_u * along_u).max(0.0);
                let t2 =
                    along_u * along_u / (self.radii[0] * self.radii[0]) + along_v2 / (self.radii[1] * self.radii[1]);
                if t2.is_nan() || t2 >= 1.0 {
                    return None;
                }
                let max_angle = max_normal_deviation(accuracy);
                // Parallel normals (a flat surface) need no arccosine.
                let angle = if cos_normals >= 1.0 { 0.0 } else { cos_normals.acos() };
                if angle >= max_angle {
                    return None;
                }
                // (1 - t^2)^2: 1 at the record, 0 with a zero slope at the ellipse's edge and no
                // kink anywhere, so the interpolated light has no crease along a record's edge
                // or at its centre, as 1 - t has. Cornell box 128x128, -aa 0.2: indirect relMSE
                // against brute force 1.16e-4 -> 9.4e-5, bias +1.2 % -> +0.9 %, records +9 %.
                let kernel = (1.0 - t2) * (1.0 - t2);
                unblocked(kernel * (1.0 - angle / max_angle))
            }
            Metric::Ward88 => {
                let error = offset.length() / self.harmonic_distance + (1.0 - cos_normals).max(0.0).sqrt();
                // Valid where the error stays under the accuracy; weight 1/error, less the
                // threshold so it falls to zero at the edge instead of jumping.
                (error < accuracy)
                    .then(|| 1.0 / error.max(1e-6) - 1.0 / accuracy)
                    .filter(|w| *w > 0.0)
                    .and_then(unblocked)
            }
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    pub fn flat_record(value: f32, radius: f32) -> Record {
        Record {
            position: Vec3::ZERO,
            normal: Vec3::Z,
            u_axis: Vec3::X,
            radii: [radius, radius],
            harmonic_distance: radius / 0.2,
            level: 0,
            weight: 1.0,
            value: Vec3::splat(value),
            translation_gradient: Vec3::ZERO,
            rotation_gradient: Vec3::ZERO,
            horizon: [f32::INFINITY; HORIZON_SECTORS],
            headroom: 100.0,
            curvature: 0.0,
        }
    }

    #[test]
    fn points_under_different_roofs_share_records_only_close_by() {
        // Alike headrooms (up to 4:1): no limit, whatever the distance.
        assert_eq!(under_one_roof(1.0, 3.9, 50.0), 1.0);
        assert_eq!(under_one_roof(3.0, 3.0, 1e6), 1.0);
        // A lid 0.05 above one point, open sky (2) above the other: a hand's breadth at most.
        let lid = |d: f32| under_one_roof(0.05, 2.0, d);
        assert_eq!(lid(0.0), 1.0);
        assert_eq!(lid(0.01), 0.0);
        // Symmetric, and fading continuously to zero instead of stepping.
        let (a, b) = (8.0, 1.0);
        let limit = ROOF_REACH * b / (a / b - SAME_ROOF_RATIO);
        for d in [0.1, 0.5, 0.8, 0.9, 0.95, 1.0, 1.2] {
            assert_eq!(under_one_roof(a, b, d), under_one_roof(b, a, d));
        }
        assert_eq!(under_one_roof(a, b, 0.7 * limit), 1.0);
        let steps: Vec<f32> = (0..=100)
            .map(|i| under_one_roof(a, b, limit * (0.7 + 0.004 * i as f32)))
            .collect();
        assert!(
            steps.windows(2).all(|w| w[1] <= w[0] && w[0] - w[1] < 0.02),
            "{steps:?}"
        );
        assert_eq!(under_one_roof(a, b, limit), 0.0);
    }

    #[test]
    fn weight_falls_to_zero_at_the_radius_and_respects_level_and_side() {
        let r = flat_record(1.0, 1.0);
        let w0 = r.weight_at(Vec3::ZERO, Vec3::Z, 0, Metric::Hessian, 0.2).unwrap();
        let w_half = r
            .weight_at(Vec3::new(0.5, 0.0, 0.0), Vec3::Z, 0, Metric::Hessian, 0.2)
            .unwrap();
        assert!((w0 - 1.0).abs() < 1e-6 && (w_half - 0.5625).abs() < 1e-6);
        // Smooth: no kink at the centre, a zero slope at the edge.
        let at = |x: f32| {
            r.weight_at(Vec3::new(x, 0.0, 0.0), Vec3::Z, 0, Metric::Hessian, 0.2)
                .unwrap_or(0.0)
        };
        assert!((1.0 - at(0.01)) < 1e-3 && at(0.99) < 1e-3);
        assert!(
            r.weight_at(Vec3::new(1.01, 0.0, 0.0), Vec3::Z, 0, Metric::Hessian, 0.2)
                .is_none()
        );
        // A record serves queries of its own level only, deeper or shallower.
        let mut deep = r.clone();
        deep.level = 1;
        assert!(deep.weight_at(Vec3::ZERO, Vec3::Z, 0, Metric::Hessian, 0.2).is_none());
        assert!(r.weight_at(Vec3::ZERO, Vec3::Z, 1, Metric::Hessian, 0.2).is_none());
        assert!(deep.weight_at(Vec3::ZERO, Vec3::Z, 1, Metric::Hessian, 0.2).is_some());
        // Behind the surface, or facing away, is refused.
        assert!(
            r.weight_at(Vec3::new(0.0, 0.0, -0.2), Vec3::Z, 0, Metric::Hessian, 0.2)
                .is_none()
        );
        assert!(r.weight_at(Vec3::ZERO, -Vec3::Z, 0, Metric::Hessian, 0.2).is_none());
        // Tilted normals beyond the angle bound are refused.
        let tilted = Vec3::new(0.5, 0.0, 1.0).normalize();
        assert!(r.weight_at(Vec3::ZERO, tilted, 0, Metric::Hessian, 0.2).is_none());
    }

    #[test]
    fn leak_test_stops_at_an_obstacle() {
        let mut r = flat_record(1.0, 1.0);
        // An obstacle 0.3 away in the +X sector.
        r.horizon[0] = 0.3;
        assert!(
            r.weight_at(Vec3::new(0.2, 0.01, 0.0), Vec3::Z, 0, Metric::Hessian, 0.2)
                .is_some()
        );
        assert!(
            r.weight_at(Vec3::new(0.5, 0.01, 0.0), Vec3::Z, 0, Metric::Hessian, 0.2)
                .is_none()
        );
        assert!(
            r.weight_at(Vec3::new(-0.5, 0.01, 0.0), Vec3::Z, 0, Metric::Hessian, 0.2)
                .is_some()
        );
        // Towards the obstacle the weight fades continuously to zero: no step at the horizon.
        let weight = |x: f32| {
            r.weight_at(Vec3::new(x, 0.001, 0.0), Vec3::Z, 0, Metric::Hessian, 0.2)
                .unwrap_or(0.0)
        };
        let mut previous = weight(0.2);
        for i in 1..=200 {
            let w = weight(0.2 + 0.1 * i as f32 / 200.0);
            assert!(
                (previous - w).abs() < 0.02,
                "step of {} at {}",
                previous - w,
                0.2 + 0.1 * i as f32 / 200.0
            );
            previous = w;
        }
        assert_eq!(previous, 0.0);
    }

    #[test]
    fn sectors_are_the_octants_of_the_angle() {
        let mut rng = crate::sampling::Rng::new(7, 7);
        for _ in 0..100_000 {
            let (u, v) = (rng.next_f32() * 2.0 - 1.0, rng.next_f32() * 2.0 - 1.0);
            let turn = (v.atan2(u) / std::f32::consts::TAU).rem_euclid(1.0);
            let by_angle = ((turn * HORIZON_SECTORS as f32) as usize).min(HORIZON_SECTORS - 1);
            // Away from the boundaries (where rounding may fall either way) they agree.
            let near_boundary = (turn * 8.0 - (turn * 8.0).round()).abs() < 1e-4;
            if !near_boundary {
                assert_eq!(sector(u, v), by_angle, "({u}, {v})");
            }
        }
        assert_eq!(sector(1.0, 0.0), 0);
        assert_eq!(sector(0.0, 1.0), 2);
        assert_eq!(sector(-1.0, 0.0), 3);
        assert_eq!(sector(0.0, -1.0), 6);
    }

    #[test]
    fn extrapolation_follows_the_gradient_and_is_clamped() {
        let mut r = flat_record(1.0, 1.0);
        r.translation_gradient = Vec3::new(0.5, 0.0, 0.0);
        assert!((r.extrapolate(Vec3::new(0.2, 0.0, 0.0), Vec3::Z).x - 1.1).abs() < 1e-6);
        assert_eq!(r.extrapolate(Vec3::new(100.0, 0.0, 0.0), Vec3::Z).x, 1.5);
        assert_eq!(r.extrapolate(Vec3::new(-100.0, 0.0, 0.0), Vec3::Z).x, 0.5);
    }

    #[test]
    fn ward88_weight() {
        let r = flat_record(1.0, 0.2);
        // Harmonic distance 1: at 0.1 away the error is 0.1 < 0.2.
        assert!(
            r.weight_at(Vec3::new(0.1, 0.0, 0.0), Vec3::Z, 0, Metric::Ward88, 0.2)
                .is_some()
        );
        assert!(
            r.weight_at(Vec3::new(0.3, 0.0, 0.0), Vec3::Z, 0, Metric::Ward88, 0.2)
                .is_none()
        );
    }
}

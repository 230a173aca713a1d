//! One cache lookup for a pixel's samples on one surface.
//!
//! At 16 samples a pixel every camera-ray hit used to make its own lookup (and trace its own
//! headroom ray): on the conference room at the peers bench's slowest setting 1.6 M lookups,
//! most of them answering, a fraction of a pixel away, what the pixel's previous sample had
//! just been told. The records' interpolation changes over a record's radius, and the records
//! are never smaller than a few pixels (the view floor), so within a pixel it barely moves:
//! the pixel looks the surface up once, where its centre ray meets the surface's plane, and
//! its samples that land near that point, on the same surface and under the same roof, share
//! the value.
//!
//! Measured (three seeds, against the peers bench's converged references): on the conference
//! room at `-aa 0.1 -ad 512 --spp 16` the lookups fall from 1.60 M to 0.66 M and one thread's
//! render takes 0.95x the time (farm-bench, 8 pairs; 0.97x at `--spp 4`, 10 pairs; Sibenik at
//! `--spp 8` 1.00x, its time all in the records), for relMSE and relMSE of 4x4-averaged pixels
//! within 0.2 %; on the Cornell box at `--spp 16` within 1.1 %. Two things make it so, each
//! measured without it:
//! - the shared value is the pixel centre's, not its first sample's: the first sample always
//!   falls in the same stratum, and sharing its value moved the cached light by a quarter of a
//!   pixel (the Cornell box's 4x4 relMSE +3.8 %);
//! - a sample whose headroom differs from the centre's does its own lookup: where a lid hangs
//!   over part of a pixel (the conference room's ceiling strips above the light panels) the
//!   records on either side differ, and sharing across the lid's edge lit those pixels 30-50 %
//!   too bright (the conference room's relMSE +3 %; +7 % with no limit on the distance either).

use crate::tracer::SurfaceHit;
use glam::Vec3;

/// A sample shares the pixel's value only this far from where it was looked up, in units of
/// the smallest radius among the records that gave it. At 0.5 the conference room's lookups
/// fall a further fifth, for relMSE 1.8 % higher on the Cornell box.
const SHARE_OF_RADIUS: f32 = 0.25;
/// Shading normals this close (cosine) count as the same surface's.
const SAME_SURFACE_COSINE: f32 = 0.9995;
/// A point whose offset leaves the surface's plane by more than this share of its ray's length
/// lies on another surface (a parallel face of the same object).
const SAME_PLANE_TOLERANCE: f32 = 1e-3;
/// Headrooms (`Record::headroom`) within this factor of each other count as under the same
/// roof; the cache's own test (`record::under_one_roof`) allows 4, and sharing needs the
/// records' weights to agree, not only to be nonzero.
const SAME_ROOF_RATIO: f32 = 1.5;

/// The cache's irradiance (over pi) at one point of a pixel's surface, for the pixel's samples.
#[derive(Clone, Copy, Debug)]
pub struct PixelIrradiance {
    position: Vec3,
    normal: Vec3,
    object: u32,
    headroom: f32,
    value: Vec3,
    /// The smallest radius among the records that gave `value`.
    scale: f32,
    /// Whether a sample has taken the value (for the statistics).
    taken: bool,
}

impl PixelIrradiance {
    /// The value `value` looked up at `position` on the surface of `hit` (a sample's hit, with
    /// its `headroom`), from records the smallest of which has radius `scale`.
    pub fn new(position: Vec3, hit: &SurfaceHit, headroom: f32, value: Vec3, scale: f32) -> PixelIrradiance {
        PixelIrradiance {
            position,
            normal: hit.normal,
            object: hit.object,
            headroom,
            value,
            scale,
            taken: false,
        }
    }

    pub fn value(&self) -> Vec3 {
        self.value
    }

    pub fn taken(&self) -> bool {
        self.taken
    }

    pub fn mark_taken(self) -> PixelIrradiance {
        PixelIrradiance { taken: true, ..self }
    }

    /// Whether a sample's hit (with its headroom) may take this value: on the same surface
    /// (`same_surface`) and near enough to where it was looked up.
    pub fn covers(&self, hit: &SurfaceHit, headroom: f32) -> bool {
        self.same_surface(hit, headroom)
            && (hit.position - self.position).length_squared() <= (SHARE_OF_RADIUS * self.scale).powi(2)
    }

    /// Whether a sample's hit (with its headroom) lies on the surface this value was looked up
    /// on: the same object, facing the same way, in the same plane and under the same roof.
    pub fn same_surface(&self, hit: &SurfaceHit, headroom: f32) -> bool {
        hit.object == self.object
            && headroom.max(self.headroom) <= SAME_ROOF_RATIO * headroom.min(self.headroom)
            && hit.normal.dot(self.normal) >= SAME_SURFACE_COSINE
            && (hit.position - self.position).dot(self.normal).abs() <= SAME_PLANE_TOLERANCE * hit.distance
    }
}

/// Where `ray` (origin, unit direction) meets the plane of the triangle `hit` lies on; None
/// for a ray (nearly) along the plane or one that meets it behind its origin.
pub fn on_plane((origin, dir): (Vec3, Vec3), hit: &SurfaceHit) -> Option<Vec3> {
    let n = hit.geometric_normal;
    let along = dir.dot(n);
    let t = (hit.position - origin).dot(n) / along;
    (along.abs() > 1e-3 && t > 0.0 && t.is_finite()).then(|| origin + dir * t)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hit on the floor (y = 0, normal up) of object 1, seen from 5 units away.
    fn floor_hit(x: f32, z: f32) -> SurfaceHit {
        SurfaceHit::on_floor(Vec3::new(x, 0.0, z), 5.0, 1)
    }

    fn shared_at_origin() -> PixelIrradiance {
        PixelIrradiance::new(Vec3::ZERO, &floor_hit(0.0, 0.0), 2.0, Vec3::splat(0.5), 1.0)
    }

    #[test]
    fn a_sample_beside_the_centre_on_the_same_surface_shares_the_value() {
        let shared = shared_at_origin();
        assert!(shared.covers(&floor_hit(0.1, -0.1), 2.0));
        assert!(shared.covers(&floor_hit(0.2, 0.0), 2.5));
        assert_eq!(shared.value(), Vec3::splat(0.5));
    }

    #[test]
    fn a_sample_on_another_surface_or_too_far_looks_up_its_own() {
        let shared = shared_at_origin();
        // Beyond a quarter of the smallest record's radius: the same surface, but too far.
        assert!(!shared.covers(&floor_hit(0.3, 0.0), 2.0));
        assert!(shared.same_surface(&floor_hit(0.3, 0.0), 2.0));
        // Another object.
        assert!(!shared.covers(
            &SurfaceHit {
                object: 2,
                ..floor_hit(0.1, 0.0)
            },
            2.0
        ));
        // A parallel face of the same object 0.1 above (a step): off the plane.
        let step = SurfaceHit {
            position: Vec3::new(0.1, 0.1, 0.0),
            ..floor_hit(0.0, 0.0)
        };
        assert!(!shared.covers(&step, 2.0));
        // A face turned by 3 degrees.
        let tilted = Vec3::new(3f32.to_radians().sin(), 3f32.to_radians().cos(), 0.0);
        assert!(!shared.covers(
            &SurfaceHit {
                normal: tilted,
                ..floor_hit(0.1, 0.0)
            },
            2.0
        ));
        // Under a lid: headroom 1 where the centre had 2.
        assert!(!shared.covers(&floor_hit(0.1, 0.0), 1.0));
    }

    #[test]
    fn the_centre_ray_meets_the_hits_plane() {
        let hit = floor_hit(0.3, 0.2);
        let centre = on_plane((Vec3::new(0.0, 4.0, 0.0), Vec3::new(0.6, -0.8, 0.0)), &hit).unwrap();
        assert!((centre - Vec3::new(3.0, 0.0, 0.0)).length() < 1e-5, "{centre}");
        // Along the plane, or away from it: none.
        assert!(on_plane((Vec3::new(0.0, 4.0, 0.0), Vec3::X), &hit).is_none());
        assert!(on_plane((Vec3::new(0.0, 4.0, 0.0), Vec3::Y), &hit).is_none());
    }
}

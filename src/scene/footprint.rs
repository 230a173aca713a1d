//! Which pixels can see an emitter straight from the eye: those the projection of some
//! emissive triangle may cover. Only there does a pixel's first-hit emission need samples of
//! its own; everywhere else it is exactly zero, whatever the samples.

use super::light::EmitterSet;
use super::view::Camera;

#[derive(Clone, Debug)]
pub struct EmitterFootprint {
    width: u32,
    covered: Vec<bool>,
}

impl EmitterFootprint {
    pub fn new(emitters: &EmitterSet, camera: &Camera) -> EmitterFootprint {
        let (width, height) = (camera.width, camera.height);
        let mut covered = vec![false; width as usize * height as usize];
        for t in &emitters.triangles {
            let corners = [t.p0, t.p0 + t.e1, t.p0 + t.e2].map(|p| camera.project(p));
            let Some(points) = corners.into_iter().collect::<Option<Vec<_>>>() else {
                // Part of the triangle is behind the eye: its projection is unbounded.
                covered.fill(true);
                break;
            };
            let (mut lo, mut hi) = ((f32::INFINITY, f32::INFINITY), (f32::NEG_INFINITY, f32::NEG_INFINITY));
            for (x, y) in points {
                lo = (lo.0.min(x), lo.1.min(y));
                hi = (hi.0.max(x), hi.1.max(y));
            }
            // One pixel of margin for rounding; the projection is convex, so its box holds it.
            let clamp = |v: f32, n: u32| v.clamp(0.0, n as f32) as u32;
            let (x0, x1) = (clamp(lo.0.floor() - 1.0, width), clamp(hi.0.ceil() + 1.0, width));
            let (y0, y1) = (clamp(lo.1.floor() - 1.0, height), clamp(hi.1.ceil() + 1.0, height));
            for y in y0..y1 {
                covered[(y * width) as usize + x0 as usize..(y * width) as usize + x1 as usize].fill(true);
            }
        }
        EmitterFootprint { width, covered }
    }

    pub fn covers(&self, x: u32, y: u32) -> bool {
        self.covered
            .get(y as usize * self.width as usize + x as usize)
            .copied()
            .unwrap_or(false)
    }

    /// How many pixels are covered (for statistics and tests).
    pub fn count(&self) -> usize {
        self.covered.iter().filter(|&&c| c).count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::light::EmitterTriangle;
    use crate::scene::view::{Projection, View};
    use glam::Vec3;

    fn camera() -> Camera {
        View {
            projection: Projection::Perspective,
            position: Vec3::ZERO,
            direction: -Vec3::Z,
            up: Vec3::Y,
            horizontal: 90.0,
            vertical: 90.0,
        }
        .camera(100, 100)
    }

    fn emitter(p0: Vec3, e1: Vec3, e2: Vec3) -> EmitterSet {
        EmitterSet::new(vec![EmitterTriangle {
            p0,
            e1,
            e2,
            normal: Vec3::Z,
            area: 0.5 * e1.cross(e2).length(),
            radiance: Vec3::ONE,
            object: 0,
            prim_id: 0,
        }])
    }

    #[test]
    fn covers_the_pixels_a_primary_ray_can_hit_the_emitter_through() {
        let cam = camera();
        // A small triangle straight ahead, right of centre and above it.
        let set = emitter(
            Vec3::new(0.2, 0.1, -1.0),
            Vec3::new(0.1, 0.0, 0.0),
            Vec3::new(0.0, 0.1, 0.0),
        );
        let footprint = EmitterFootprint::new(&set, &cam);
        // Every pixel whose sampled rays hit the triangle is covered.
        let t = &set.triangles[0];
        for y in 0..100 {
            for x in 0..100 {
                for (jx, jy) in [(0.1, 0.1), (0.5, 0.5), (0.9, 0.9), (0.1, 0.9), (0.9, 0.1)] {
                    let (o, d) = cam.ray(x as f32 + jx, y as f32 + jy);
                    // Ray-plane z = -1, then inside the right triangle's legs.
                    let s = (-1.0 - o.z) / d.z;
                    let p = o + d * s - t.p0;
                    let (a, b) = (p.x / 0.1, p.y / 0.1);
                    if a >= 0.0 && b >= 0.0 && a + b <= 1.0 {
                        assert!(footprint.covers(x, y), "pixel {x} {y} sees the emitter");
                    }
                }
            }
        }
        assert!(
            footprint.count() > 0 && footprint.count() < 100,
            "{} pixels",
            footprint.count()
        );
        assert!(!footprint.covers(10, 90));
    }

    #[test]
    fn an_emitter_reaching_behind_the_eye_covers_everything() {
        let set = emitter(
            Vec3::new(0.0, 1.0, 1.0),
            Vec3::new(0.0, 0.0, -3.0),
            Vec3::new(1.0, 0.0, 0.0),
        );
        assert_eq!(EmitterFootprint::new(&set, &camera()).count(), 100 * 100);
        assert_eq!(EmitterFootprint::new(&EmitterSet::new(vec![]), &camera()).count(), 0);
    }
}

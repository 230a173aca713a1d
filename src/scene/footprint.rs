//! Which pixels can see an emitter straight from the eye: those the projection of some
//! emissive triangle may cover. Only there does a pixel's first-hit emission need samples of
//! its own; everywhere else it is exactly zero, whatever the samples.

use super::light::EmitterSet;
use super::view::Camera;
use crate::image::window::PixelWindow;

#[derive(Clone, Debug)]
pub struct EmitterFootprint {
    /// The pixels asked about (a region task's region, or the whole image).
    window: PixelWindow,
    /// The window's pixels, row-major.
    covered: Vec<bool>,
}

impl EmitterFootprint {
    /// The footprint within `window` of the camera's image (only the pixels rendered are held).
    pub fn new(emitters: &EmitterSet, camera: &Camera, window: PixelWindow) -> EmitterFootprint {
        let area = window.area;
        let mut covered = vec![false; window.pixels()];
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
            let clamp = |v: f32, from: u32, to: u32| (v.clamp(from as f32, to as f32) as u32).clamp(from, to);
            let (x0, x1) = (
                clamp(lo.0.floor() - 1.0, area.x0, area.x1),
                clamp(hi.0.ceil() + 1.0, area.x0, area.x1),
            );
            let (y0, y1) = (
                clamp(lo.1.floor() - 1.0, area.y0, area.y1),
                clamp(hi.1.ceil() + 1.0, area.y0, area.y1),
            );
            if x0 >= x1 {
                continue;
            }
            for y in y0..y1 {
                let start = window.index(x0, y).expect("inside the window");
                covered[start..start + (x1 - x0) as usize].fill(true);
            }
        }
        EmitterFootprint { window, covered }
    }

    pub fn covers(&self, x: u32, y: u32) -> bool {
        self.window.index(x, y).is_some_and(|i| self.covered[i])
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
        let footprint = EmitterFootprint::new(&set, &cam, PixelWindow::whole(100, 100));
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

    /// A window's footprint is the whole image's within the window (brute force, for windows
    /// holding all, part or none of the emitter's box).
    #[test]
    fn a_window_s_footprint_is_the_whole_one_s_within_it() {
        let cam = camera();
        let set = emitter(
            Vec3::new(0.2, 0.1, -1.0),
            Vec3::new(0.1, 0.0, 0.0),
            Vec3::new(0.0, 0.1, 0.0),
        );
        let whole = EmitterFootprint::new(&set, &cam, PixelWindow::whole(100, 100));
        for (x0, y0, x1, y1) in [(0, 0, 100, 100), (55, 30, 70, 45), (60, 0, 100, 40), (0, 60, 30, 100)] {
            let area = crate::image::region::Region { x0, y0, x1, y1 };
            let part = EmitterFootprint::new(&set, &cam, PixelWindow::new(area, 100, 100));
            let mut inside = 0;
            for y in 0..100 {
                for x in 0..100 {
                    let held = (x0..x1).contains(&x) && (y0..y1).contains(&y);
                    assert_eq!(part.covers(x, y), held && whole.covers(x, y), "{area:?}: ({x}, {y})");
                    inside += (held && whole.covers(x, y)) as usize;
                }
            }
            assert_eq!(part.count(), inside, "{area:?}");
        }
        assert!(whole.count() > 0);
    }

    #[test]
    fn an_emitter_reaching_behind_the_eye_covers_everything() {
        let set = emitter(
            Vec3::new(0.0, 1.0, 1.0),
            Vec3::new(0.0, 0.0, -3.0),
            Vec3::new(1.0, 0.0, 0.0),
        );
        assert_eq!(
            EmitterFootprint::new(&set, &camera(), PixelWindow::whole(100, 100)).count(),
            100 * 100
        );
        assert_eq!(
            EmitterFootprint::new(&EmitterSet::new(vec![]), &camera(), PixelWindow::whole(100, 100)).count(),
            0
        );
    }
}

//! The view: Radiance's -vp -vd -vu -vh -vv -vt options, the glTF camera, or an automatic view
//! of the scene's bounds; and primary rays through image positions.

use glam::Vec3;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Projection {
    /// Radiance -vtv.
    Perspective,
    /// Radiance -vtl: vh and vv are the view's width and height in world units.
    Parallel,
}

#[derive(Clone, Debug)]
pub struct View {
    pub projection: Projection,
    pub position: Vec3,
    pub direction: Vec3,
    pub up: Vec3,
    /// Horizontal and vertical full angles in degrees (perspective) or extents (parallel).
    pub horizontal: f32,
    pub vertical: f32,
}

/// The share of a sample's part of the pixel that its camera ray reads textures over: the
/// whole part blurs a little (the samples' mean is then the texture filtered twice, by the
/// part's box and by the pixel's), none leaves one texel a sample. Measured on Sibenik (320x240,
/// -ab 2, --lambertian, against the peers bench's icrender reference), relMSE / 4x4 relMSE at
/// the defaults (1 sample): 0 (points) 3.0e-2 / 3.4e-3, 0.35 1.7e-2 / 2.2e-3, 0.5 1.4e-2 /
/// 2.1e-3, 0.7 1.35e-2 / 1.9e-3, 1.0 1.4e-2 / 1.85e-3; at 4 samples (-aa 0.3 -ad 64): 0 1.1e-2
/// / 1.28e-3, 0.5 9.2e-3 / 1.19e-3, 0.7 8.7e-3 / 1.17e-3, 1.0 8.6e-3 / 1.15e-3.
pub const EYE_FOOTPRINT: f32 = 0.7;

/// A view fully resolved for an image size: an orthonormal frame and half-extents.
#[derive(Clone, Debug)]
pub struct Camera {
    view: View,
    right: Vec3,
    up: Vec3,
    forward: Vec3,
    half_width: f32,
    half_height: f32,
    pub width: u32,
    pub height: u32,
}

impl View {
    /// The horizontal extent that keeps square pixels at the given image aspect.
    pub fn horizontal_for_aspect(projection: Projection, vertical: f32, aspect: f32) -> f32 {
        match projection {
            Projection::Perspective => 2.0 * ((vertical.to_radians() * 0.5).tan() * aspect).atan().to_degrees(),
            Projection::Parallel => vertical * aspect,
        }
    }

    /// Radiance's -vf-style one-line description, usable as rpict options, in world
    /// coordinates: `origin` is the scene's tracing origin, which the view's position is
    /// relative to.
    pub fn radiance_options(&self, origin: glam::DVec3) -> String {
        let t = match self.projection {
            Projection::Perspective => "v",
            Projection::Parallel => "l",
        };
        let (d, u) = (self.direction, self.up);
        let p = origin + self.position.as_dvec3();
        format!(
            "-vt{t} -vp {} {} {} -vd {} {} {} -vu {} {} {} -vh {} -vv {}",
            world_coordinate(p.x),
            world_coordinate(p.y),
            world_coordinate(p.z),
            d.x,
            d.y,
            d.z,
            u.x,
            u.y,
            u.z,
            self.horizontal,
            self.vertical
        )
    }

    pub fn validate(&self) -> Result<(), String> {
        let finite = self.position.is_finite() && self.direction.is_finite() && self.up.is_finite();
        if !finite {
            return Err("view point, direction and up must be finite".into());
        }
        if self.direction.length_squared() == 0.0 {
            return Err("view direction (-vd) is zero".into());
        }
        if self
            .direction
            .normalize()
            .cross(self.up.normalize_or_zero())
            .length_squared()
            < 1e-10
        {
            return Err("view up (-vu) is parallel to the view direction (-vd)".into());
        }
        let angle_ok = |a: f32| match self.projection {
            Projection::Perspective => a > 0.0 && a < 179.0,
            Projection::Parallel => a > 0.0 && a.is_finite(),
        };
        if !angle_ok(self.horizontal) || !angle_ok(self.vertical) {
            return Err(format!(
                "view size -vh {} -vv {} is out of range (perspective angles must be in (0, 179) degrees)",
                self.horizontal, self.vertical
            ));
        }
        Ok(())
    }

    pub fn camera(&self, width: u32, height: u32) -> Camera {
        let forward = self.direction.normalize();
        let right = forward.cross(self.up).normalize();
        let up = right.cross(forward);
        let (half_width, half_height) = match self.projection {
            Projection::Perspective => (
                (self.horizontal.to_radians() * 0.5).tan(),
                (self.vertical.to_radians() * 0.5).tan(),
            ),
            Projection::Parallel => (self.horizontal * 0.5, self.vertical * 0.5),
        };
        Camera {
            view: self.clone(),
            right,
            up,
            forward,
            half_width,
            half_height,
            width,
            height,
        }
    }
}

impl Camera {
    /// A pixel's width over its height on the image plane: 1 unless -vh and -vv were both given
    /// at another aspect than the image's.
    pub fn pixel_aspect(&self) -> f32 {
        let ratio = (self.half_width / self.width.max(1) as f32) / (self.half_height / self.height.max(1) as f32);
        if ratio.is_finite() && ratio > 0.0 { ratio } else { 1.0 }
    }

    /// The width of one pixel at `point`'s depth in the view (the whole image's pixels, in
    /// world units): what the image can tell apart there.
    pub fn pixel_width_at(&self, point: Vec3) -> f32 {
        let plane = self.pixel_side();
        match self.view.projection {
            Projection::Perspective => self.view_depth(point) * plane,
            Projection::Parallel => plane,
        }
    }

    /// A pixel's width on the image plane at unit depth (a parallel view: in world units).
    fn pixel_side(&self) -> f32 {
        2.0 * self.half_width / self.width.max(1) as f32
    }

    /// Distance of `point` from the camera along the view axis (its forward direction; for a
    /// parallel view, from the view's plane), never negative.
    pub fn view_depth(&self, point: Vec3) -> f32 {
        (point - self.view.position).dot(self.forward).max(0.0)
    }

    /// Where `point` appears in the image, in pixels as `ray` takes them; None behind a
    /// perspective camera (at or behind its position's plane).
    pub fn project(&self, point: Vec3) -> Option<(f32, f32)> {
        let v = point - self.view.position;
        let (sx, sy) = match self.view.projection {
            Projection::Perspective => {
                let depth = v.dot(self.forward);
                // NaN as well as behind the eye.
                if depth.is_nan() || depth <= 0.0 {
                    return None;
                }
                (
                    v.dot(self.right) / (depth * self.half_width),
                    v.dot(self.up) / (depth * self.half_height),
                )
            }
            Projection::Parallel => (v.dot(self.right) / self.half_width, v.dot(self.up) / self.half_height),
        };
        let (x, y) = (
            (sx + 1.0) * 0.5 * self.width as f32,
            (1.0 - sy) * 0.5 * self.height as f32,
        );
        (x.is_finite() && y.is_finite()).then_some((x, y))
    }

    /// How wide the footprint of a camera ray along `dir` (unit) grows per unit of distance
    /// when it stands for one of `samples` equal shares of its pixel: the pixel's side on the
    /// image plane at unit depth, shrunk as the ray leaves the axis (the plane lies farther and
    /// slants: by cos^1.5 of the angle, the side of a square of the footprint's area), over
    /// the square root of the samples, times `EYE_FOOTPRINT`. A parallel view's footprint does
    /// not grow with distance: 0, textures read at the point.
    pub fn sample_spread(&self, dir: Vec3, samples: u32) -> f32 {
        match self.view.projection {
            Projection::Perspective => {
                let cos = dir.dot(self.forward).max(0.0);
                EYE_FOOTPRINT * self.pixel_side() * cos * cos.sqrt() / (samples.max(1) as f32).sqrt()
            }
            Projection::Parallel => 0.0,
        }
    }

    /// Primary ray through image position (x, y) in pixels, with (0, 0) at the top-left corner
    /// of the image: origin and unit direction.
    #[inline]
    pub fn ray(&self, x: f32, y: f32) -> (Vec3, Vec3) {
        let sx = 2.0 * x / self.width as f32 - 1.0;
        let sy = 1.0 - 2.0 * y / self.height as f32;
        match self.view.projection {
            Projection::Perspective => {
                let d = self.forward + sx * self.half_width * self.right + sy * self.half_height * self.up;
                (self.view.position, d.normalize())
            }
            Projection::Parallel => {
                let o = self.view.position + sx * self.half_width * self.right + sy * self.half_height * self.up;
                (o, self.forward)
            }
        }
    }
}

/// A world coordinate as text: as the f32 it is when it is one (every scene around glTF's
/// origin, written as before), else in full double precision (a scene far out).
pub fn world_coordinate(v: f64) -> String {
    if (v as f32) as f64 == v {
        (v as f32).to_string()
    } else {
        v.to_string()
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A 90-degree square view from the origin down -z.
    pub(crate) fn view() -> View {
        View {
            projection: Projection::Perspective,
            position: Vec3::ZERO,
            direction: -Vec3::Z,
            up: Vec3::Y,
            horizontal: 90.0,
            vertical: 90.0,
        }
    }

    #[test]
    fn centre_and_corner_rays() {
        let cam = view().camera(100, 100);
        let (_, d) = cam.ray(50.0, 50.0);
        assert!((d - -Vec3::Z).length() < 1e-6);
        let (_, corner) = cam.ray(100.0, 0.0);
        assert!((corner - Vec3::new(1.0, 1.0, -1.0).normalize()).length() < 1e-6);
    }

    /// A camera ray's footprint: the pixel's side over the square root of its samples, times
    /// EYE_FOOTPRINT, on the axis; at the corner of a 90-degree view (cos 1/sqrt 3) cos^1.5 of
    /// that; none in a parallel view.
    #[test]
    fn a_samples_footprint_is_its_share_of_the_pixel() {
        let cam = view().camera(100, 100);
        let side = 2.0 / 100.0;
        assert!((cam.sample_spread(-Vec3::Z, 1) - EYE_FOOTPRINT * side).abs() < 1e-7);
        assert!((cam.sample_spread(-Vec3::Z, 4) - EYE_FOOTPRINT * side / 2.0).abs() < 1e-7);
        let (_, corner) = cam.ray(100.0, 0.0);
        let cos = 1.0 / 3f32.sqrt();
        assert!((cam.sample_spread(corner, 1) - EYE_FOOTPRINT * side * cos.powf(1.5)).abs() < 1e-7);
        let mut parallel = view();
        parallel.projection = Projection::Parallel;
        assert_eq!(parallel.camera(100, 100).sample_spread(-Vec3::Z, 1), 0.0);
    }

    #[test]
    fn rejects_degenerate_views() {
        let mut v = view();
        v.up = -Vec3::Z;
        assert!(v.validate().is_err());
        let mut v = view();
        v.vertical = 180.0;
        assert!(v.validate().is_err());
        assert!(view().validate().is_ok());
    }

    /// A pixel's width grows with the depth along the view axis (not the distance), and is the
    /// same everywhere in a parallel view.
    #[test]
    fn a_pixel_is_wider_the_deeper_it_looks() {
        let cam = view().camera(100, 100);
        assert!((cam.pixel_width_at(Vec3::new(0.0, 0.0, -5.0)) - 0.1).abs() < 1e-6);
        assert!((cam.pixel_width_at(Vec3::new(3.0, -2.0, -5.0)) - 0.1).abs() < 1e-6);
        assert_eq!(cam.pixel_width_at(Vec3::new(0.0, 0.0, 5.0)), 0.0, "behind the eye");
        let mut parallel = view();
        parallel.projection = Projection::Parallel;
        parallel.horizontal = 10.0;
        parallel.vertical = 10.0;
        let cam = parallel.camera(100, 100);
        for z in [-1.0, -50.0] {
            assert!((cam.pixel_width_at(Vec3::new(1.0, 0.0, z)) - 0.1).abs() < 1e-6);
        }
    }

    #[test]
    fn square_pixels_angle() {
        let h = View::horizontal_for_aspect(Projection::Perspective, 90.0, 2.0);
        assert!((h - 2.0 * 2f32.atan().to_degrees()).abs() < 1e-4);
    }
}

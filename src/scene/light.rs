//! Light sources: punctual lights (KHR_lights_punctual) and emissive triangles, with the
//! sampling the direct component needs.

use super::light_tree::{Item, LightTree, Receiver};
use crate::sys::scene_io::{GltfLight, LightType};
use glam::Vec3;

/// A punctual light in world space. Intensity is used as radiometric (W/sr for point and spot,
/// W/m^2 for directional), as renderers of glTF conventionally do.
#[derive(Clone, Debug)]
pub struct PunctualLight {
    pub name: String,
    pub kind: LightType,
    pub intensity: Vec3,
    pub position: Vec3,
    /// Where the light points (unit).
    pub direction: Vec3,
    pub range: f32,
    pub cos_inner: f32,
    pub cos_outer: f32,
}

/// What a light delivers at a point: direction towards the light (unit), distance (infinite
/// for directional) and the irradiance it gives a surface facing it.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    pub to_light: Vec3,
    pub distance: f32,
    pub irradiance: Vec3,
}

fn finite3(v: [f32; 3]) -> Option<Vec3> {
    let v = Vec3::from(v);
    v.is_finite().then_some(v)
}

impl PunctualLight {
    /// None when the file's numbers cannot describe a light (non-finite position, zero
    /// direction); the caller warns.
    /// `origin`: the scene's tracing origin, which the light's position is made relative to.
    pub fn from_gltf(l: &GltfLight, origin: glam::DVec3) -> Option<PunctualLight> {
        let color = finite3(l.color)?.max(Vec3::ZERO);
        let intensity = if l.intensity.is_finite() {
            l.intensity.max(0.0)
        } else {
            return None;
        };
        let direction = finite3(l.direction)?.try_normalize()?;
        let position = (glam::DVec3::from(l.position) - origin).as_vec3();
        let position = position.is_finite().then_some(position)?;
        let outer = l.outer_cone.clamp(0.0, std::f32::consts::FRAC_PI_2);
        let inner = l.inner_cone.clamp(0.0, outer);
        Some(PunctualLight {
            name: l.name.clone(),
            kind: l.kind,
            intensity: color * intensity,
            position,
            direction,
            range: if l.range.is_finite() && l.range > 0.0 {
                l.range
            } else {
                0.0
            },
            cos_inner: inner.cos(),
            cos_outer: outer.cos(),
        })
    }

    /// Irradiance at `point` on a surface facing the light (the caller applies the cosine and
    /// the shadow test). None when the light gives nothing there.
    pub fn illuminate(&self, point: Vec3) -> Option<LightSample> {
        if self.kind == LightType::Directional {
            return Some(LightSample {
                to_light: -self.direction,
                distance: f32::INFINITY,
                irradiance: self.intensity,
            });
        }
        let offset = self.position - point;
        let d2 = offset.length_squared();
        if !(d2 > 0.0 && d2.is_finite()) {
            return None;
        }
        let distance = d2.sqrt();
        let to_light = offset / distance;
        let mut scale = 1.0 / d2;
        if self.range > 0.0 {
            // glTF's recommended window: smooth fall-off to zero at the range.
            let r = (distance / self.range).powi(4);
            scale *= (1.0 - r).clamp(0.0, 1.0).powi(2);
        }
        if self.kind == LightType::Spot {
            let cos = self.direction.dot(-to_light);
            let t = if self.cos_inner > self.cos_outer {
                ((cos - self.cos_outer) / (self.cos_inner - self.cos_outer)).clamp(0.0, 1.0)
            } else if cos >= self.cos_outer {
                1.0
            } else {
                0.0
            };
            scale *= t * t;
        }
        (scale > 0.0).then(|| LightSample {
            to_light,
            distance,
            irradiance: self.intensity * scale,
        })
    }
}

/// One emissive triangle in world space.
#[derive(Clone, Debug)]
pub struct EmitterTriangle {
    pub p0: Vec3,
    pub e1: Vec3,
    pub e2: Vec3,
    /// Unit normal of the emitting (front) side.
    pub normal: Vec3,
    pub area: f32,
    pub radiance: Vec3,
    /// The object (placed mesh) and its triangle that this is.
    pub object: u32,
    pub prim_id: u32,
}

/// All emissive triangles. A shading point picks one through the light tree, by power
/// (area x luminance) over squared distance, so bright, large and near emitters get most of the
/// shadow rays.
#[derive(Clone, Debug, Default)]
pub struct EmitterSet {
    pub triangles: Vec<EmitterTriangle>,
    cdf: Vec<f64>,
    total_power: f64,
    tree: LightTree,
}

/// A point chosen on an emitter, with the area-measure density of having chosen it.
#[derive(Clone, Copy, Debug)]
pub struct EmitterPoint {
    pub position: Vec3,
    pub normal: Vec3,
    pub radiance: Vec3,
    pub pdf_area: f32,
}

pub fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

impl EmitterSet {
    pub fn new(triangles: Vec<EmitterTriangle>) -> EmitterSet {
        let mut cdf = Vec::with_capacity(triangles.len());
        let mut total = 0.0f64;
        for t in &triangles {
            total += t.area as f64 * luminance(t.radiance).max(1e-12) as f64;
            cdf.push(total);
        }
        let items: Vec<Item> = triangles
            .iter()
            .zip(&cdf)
            .scan(0.0, |previous, (t, &c)| {
                let power = c - *previous;
                *previous = c;
                let (a, b, d) = (t.p0, t.p0 + t.e1, t.p0 + t.e2);
                Some(Item {
                    lo: a.min(b).min(d),
                    hi: a.max(b).max(d),
                    power,
                    anchor: t.p0,
                    front: t.normal,
                })
            })
            .collect();
        EmitterSet {
            tree: LightTree::new(&items),
            triangles,
            cdf,
            total_power: total,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    pub fn len(&self) -> usize {
        self.triangles.len()
    }

    /// Irradiance at `point` on a surface with unit normal `normal` from every emitter, as if
    /// nothing were in the way (exact, by Lambert's formula; O(emitters)). None where rounding
    /// leaves the formula no finite answer (see `lambert::projected_solid_angle`).
    pub fn unshadowed_irradiance(&self, point: Vec3, normal: Vec3) -> Option<Vec3> {
        let (p, n) = (point.as_dvec3(), normal.as_dvec3());
        let mut total = glam::DVec3::ZERO;
        for t in &self.triangles {
            let corners = [t.p0, t.p0 + t.e1, t.p0 + t.e2].map(|c| c.as_dvec3());
            let factor = super::lambert::projected_solid_angle(p, n, corners, t.normal.as_dvec3())?;
            total += t.radiance.as_dvec3() * factor;
        }
        let total = total.as_vec3();
        total.is_finite().then_some(total)
    }

    /// Probability of choosing triangle `index` by power alone (what the tree's estimate
    /// becomes far from every emitter).
    pub fn pick_probability(&self, index: usize) -> f64 {
        let lo = if index == 0 { 0.0 } else { self.cdf[index - 1] };
        (self.cdf[index] - lo) / self.total_power
    }

    /// Chooses a triangle for a shading point at `point` with unit shading normal `normal`
    /// through the light tree with `u1`, and a uniform point on the part of it above the point's
    /// tangent plane with `u2`, `u3`. None where no emitter can light the point (all behind its
    /// tangent plane or facing away).
    ///
    /// Only the part above the tangent plane is sampled because a point below it brings nothing:
    /// a ray spent there is wasted in the plain estimate, and in the ratio estimate (the exact
    /// unshadowed irradiance times the share of the rays' light that got through) a pixel whose
    /// few rays all land below has no share to measure and reads black. On the Cornell box the
    /// tall box's front face, whose plane cuts the lamp, read 12 % dark at 4 rays a point and
    /// 38 % at one that way.
    ///
    /// One pick walks the tree alone: a `sampler`'s chooser, which keeps the nodes' weighing for
    /// the picks after it, costs more to set up than it saves a point that takes a single one (a
    /// record's hemisphere rays' hits at -ab 1, one shadow ray each).
    pub fn sample(&self, point: Vec3, normal: Vec3, u1: f32, u2: f32, u3: f32) -> Option<EmitterPoint> {
        if !self.has_power() {
            return None;
        }
        let (index, probability) = self.tree.pick(Receiver { point, normal }, u1 as f64)?;
        self.point_on(index, probability, point, normal, u2, u3)
    }

    /// A sampler for several of `sample`'s points at one shading point, its picks sharing the
    /// light tree's weighing (`LightTree::chooser`). None where the set has no power to sample.
    pub fn sampler(&self, point: Vec3, normal: Vec3) -> Option<EmitterSampler<'_>> {
        self.has_power().then(|| EmitterSampler {
            set: self,
            chooser: self.tree.chooser(Receiver { point, normal }),
        })
    }

    /// Whether there is anything to sample: emitters with a finite, positive total power.
    fn has_power(&self) -> bool {
        !self.triangles.is_empty() && !self.total_power.is_nan() && self.total_power > 0.0
    }

    /// A uniform point with `u`, `v` on the part of triangle `index` (picked with `probability`)
    /// above the tangent plane of `point` with unit normal `normal`.
    fn point_on(
        &self,
        index: usize,
        probability: f64,
        point: Vec3,
        normal: Vec3,
        u: f32,
        v: f32,
    ) -> Option<EmitterPoint> {
        let t = &self.triangles[index];
        let (position, area) = t.sample_above(point, normal, u, v)?;
        let pdf_area = (probability / area as f64) as f32;
        (pdf_area.is_finite() && pdf_area > 0.0).then_some(EmitterPoint {
            position,
            normal: t.normal,
            radiance: t.radiance,
            pdf_area,
        })
    }
}

/// `EmitterSet::sample` at one shading point (the chooser's receiver), as many times as it is
/// asked.
pub struct EmitterSampler<'a> {
    set: &'a EmitterSet,
    chooser: super::light_tree::Chooser<'a>,
}

impl EmitterSampler<'_> {
    /// A point on an emitter for the shading point, as `EmitterSet::sample` gives it.
    pub fn sample(&mut self, u1: f32, u2: f32, u3: f32) -> Option<EmitterPoint> {
        let Receiver { point, normal } = self.chooser.receiver();
        let (index, probability) = self.chooser.pick(u1 as f64)?;
        self.set.point_on(index, probability, point, normal, u2, u3)
    }
}

/// A uniform point on triangle `a b c` by the square-root warp.
fn point_on_triangle(a: Vec3, b: Vec3, c: Vec3, u: f32, v: f32) -> Vec3 {
    let su = u.sqrt();
    a + (1.0 - su) * (b - a) + (v * su) * (c - a)
}

impl EmitterTriangle {
    /// A uniform point on the part of the triangle above the tangent plane of `point` with unit
    /// normal `normal` (the triangle clipped to that half-space: three or four corners), and
    /// that part's area. None where no part of finite, positive area lies above.
    pub fn sample_above(&self, point: Vec3, normal: Vec3, u: f32, v: f32) -> Option<(Vec3, f32)> {
        let corners = [self.p0, self.p0 + self.e1, self.p0 + self.e2];
        let heights = corners.map(|c| normal.dot(c - point));
        if heights.iter().all(|&h| h >= 0.0) {
            return Some((point_on_triangle(corners[0], corners[1], corners[2], u, v), self.area));
        }
        // Clipped to the half-space above the plane (as Lambert's formula clips, in f64 around
        // the point): three or four corners.
        let mut clipped = [glam::DVec3::ZERO; 4];
        let count =
            super::lambert::clip_above(corners.map(|c| (c - point).as_dvec3()), normal.as_dvec3(), &mut clipped);
        let kept = clipped.map(|v| point + v.as_vec3());
        let area_of = |a: Vec3, b: Vec3, c: Vec3| 0.5 * (b - a).cross(c - a).length();
        let first = if count >= 3 {
            area_of(kept[0], kept[1], kept[2])
        } else {
            0.0
        };
        let second = if count == 4 {
            area_of(kept[0], kept[2], kept[3])
        } else {
            0.0
        };
        let area = first + second;
        if !(area.is_finite() && area > 0.0) {
            return None;
        }
        // A quadrilateral is two triangles of the fan from its first corner, chosen in
        // proportion to their areas with `u`, which is then rescaled to stay uniform.
        let share = first / area;
        let position = if u < share || count == 3 {
            point_on_triangle(kept[0], kept[1], kept[2], (u / share).min(1.0), v)
        } else {
            point_on_triangle(
                kept[0],
                kept[2],
                kept[3],
                ((u - share) / (1.0 - share)).clamp(0.0, 1.0),
                v,
            )
        };
        Some((position, area))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(scale: f32, radiance: f32) -> EmitterTriangle {
        EmitterTriangle {
            p0: Vec3::ZERO,
            e1: Vec3::X * scale,
            e2: Vec3::Y * scale,
            normal: Vec3::Z,
            area: 0.5 * scale * scale,
            radiance: Vec3::splat(radiance),
            object: 0,
            prim_id: 0,
        }
    }

    #[test]
    fn picks_by_power_and_density_integrates_to_one() {
        let set = EmitterSet::new(vec![tri(1.0, 1.0), tri(2.0, 1.0), tri(1.0, 4.0)]);
        // Powers 0.5, 2, 2 -> probabilities 1/9, 4/9, 4/9.
        assert!((set.pick_probability(0) - 1.0 / 9.0).abs() < 1e-9);
        assert!((set.pick_probability(2) - 4.0 / 9.0).abs() < 1e-9);
        // Sum over triangles of pdf_area * area equals one.
        let total: f64 = (0..3).map(|i| set.pick_probability(i)).sum();
        assert!((total - 1.0).abs() < 1e-9);
        // Seen from far away the tree's estimate is the power alone.
        let far = Vec3::new(0.0, 0.0, 1e4);
        let facing_down = Receiver {
            point: far,
            normal: -Vec3::Z,
        };
        for i in 0..3 {
            assert!((set.tree.probability(facing_down, i) - set.pick_probability(i)).abs() < 1e-5);
        }
        let p = set.sample(far, -Vec3::Z, 0.05, 0.3, 0.7).unwrap();
        let picked =
            (0..3).find(|&i| (p.pdf_area as f64 * set.triangles[i].area as f64 - set.pick_probability(i)).abs() < 1e-5);
        assert!(picked.is_some(), "pdf_area {} matches no triangle", p.pdf_area);
    }

    /// A lone pick (`EmitterSet::sample`, no chooser) gives the point a sampler's pick gives
    /// for the same numbers: the same emitter, point and density, so a point that takes one
    /// shadow ray gets what a sampler gave it (the images did not change).
    #[test]
    fn a_lone_pick_is_the_samplers_pick() {
        let triangles: Vec<EmitterTriangle> = (0..11)
            .map(|i| {
                let mut t = tri(0.3 + 0.1 * (i % 3) as f32, 1.0 + i as f32);
                t.p0 = Vec3::new(i as f32 * 0.7 - 3.0, (i % 4) as f32 * 0.5, 2.0);
                t.normal = -Vec3::Z;
                t
            })
            .collect();
        let set = EmitterSet::new(triangles);
        let mut rng = crate::sampling::Rng::new(5, 1);
        for _ in 0..500 {
            let point = Vec3::new(rng.next_f32() * 6.0 - 3.0, rng.next_f32() * 2.0, rng.next_f32());
            let normal = Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, 1.0).normalize();
            let u = (rng.next_f32(), rng.next_f32(), rng.next_f32());
            let lone = set.sample(point, normal, u.0, u.1, u.2);
            let shared = set.sampler(point, normal).and_then(|mut s| s.sample(u.0, u.1, u.2));
            match (lone, shared) {
                (Some(a), Some(b)) => {
                    assert_eq!(a.position, b.position);
                    assert_eq!(a.pdf_area, b.pdf_area);
                    assert_eq!(a.radiance, b.radiance);
                }
                (None, None) => {}
                (a, b) => panic!(
                    "lone pick {:?}, sampler's {:?}",
                    a.map(|p| p.position),
                    b.map(|p| p.position)
                ),
            }
        }
    }

    /// A wall at the origin whose plane cuts a ceiling emitter: facing +x it sees one corner of
    /// the triangle (a clipped triangle), facing -x the other two (a quadrilateral). Every point
    /// sampled lies on the wall's side and the estimate is Lambert's exact, clipped value.
    #[test]
    fn samples_only_the_part_above_the_tangent_plane_and_stays_unbiased() {
        let (e1, e2) = (Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 0.0, 2.0));
        let t = EmitterTriangle {
            p0: Vec3::new(-1.0, 2.0, -1.0),
            e1,
            e2,
            normal: e1.cross(e2).normalize(),
            area: 0.5 * e1.cross(e2).length(),
            radiance: Vec3::splat(3.0),
            object: 0,
            prim_id: 0,
        };
        assert!(t.normal.y < -0.99);
        let corners = [t.p0, t.p0 + t.e1, t.p0 + t.e2].map(|c| c.as_dvec3());
        let set = EmitterSet::new(vec![t.clone()]);
        let mut rng = crate::sampling::Rng::new(3, 0);
        for normal in [Vec3::X, -Vec3::X] {
            let point = Vec3::new(0.0, 0.5, 0.0);
            let exact = 3.0
                * super::super::lambert::projected_solid_angle(
                    point.as_dvec3(),
                    normal.as_dvec3(),
                    corners,
                    t.normal.as_dvec3(),
                )
                .unwrap();
            let samples = 200_000;
            let mut sum = 0.0f64;
            for _ in 0..samples {
                let p = set
                    .sample(point, normal, rng.next_f32(), rng.next_f32(), rng.next_f32())
                    .unwrap();
                let offset = p.position - point;
                assert!(offset.dot(normal) >= -1e-6, "sampled below the plane: {offset}");
                let d2 = offset.length_squared();
                let wi = offset / d2.sqrt();
                let geometry = (normal.dot(wi) * -p.normal.dot(wi)).max(0.0) / d2;
                sum += (p.radiance.x * geometry / p.pdf_area) as f64;
            }
            let mean = sum / samples as f64;
            assert!(
                (mean - exact).abs() < 0.005 * exact,
                "normal {normal}: estimate {mean}, exact {exact}"
            );
        }
    }

    #[test]
    fn spot_cone_and_inverse_square() {
        let l = PunctualLight {
            name: "s".into(),
            kind: LightType::Spot,
            intensity: Vec3::splat(4.0),
            position: Vec3::new(0.0, 2.0, 0.0),
            direction: -Vec3::Y,
            range: 0.0,
            cos_inner: 0.9,
            cos_outer: 0.8,
        };
        let below = l.illuminate(Vec3::ZERO).unwrap();
        assert!((below.irradiance.x - 1.0).abs() < 1e-6);
        assert!(l.illuminate(Vec3::new(10.0, 0.0, 0.0)).is_none());
        assert!(l.illuminate(l.position).is_none());
    }

    /// Irradiance at `point` (surface normal `n`) from a uniformly emitting triangle that faces
    /// it, by Lambert's contour formula: E = L/2 * sum over edges of angle_i * (gamma_i . n).
    fn triangle_irradiance(t: &EmitterTriangle, point: Vec3, n: Vec3) -> f64 {
        let v = [t.p0, t.p0 + t.e1, t.p0 + t.e2].map(|p| (p - point).normalize().as_dvec3());
        let n = n.as_dvec3();
        let mut sum = 0.0;
        for i in 0..3 {
            let (a, b) = (v[i], v[(i + 1) % 3]);
            let angle = a.dot(b).clamp(-1.0, 1.0).acos();
            sum += angle * a.cross(b).normalize().dot(n);
        }
        0.5 * sum.abs() * t.radiance.x as f64
    }

    #[test]
    fn many_light_estimate_is_unbiased() {
        // 200 small emitters of varied size and brightness on a ceiling, facing down at a floor
        // point: the mean of radiance * G / pdf over many samples must equal the sum of each
        // triangle's exact irradiance.
        let mut rng = crate::sampling::Rng::new(11, 0);
        let mut triangles = Vec::new();
        for k in 0..200 {
            let centre = Vec3::new(rng.next_f32() * 8.0 - 4.0, rng.next_f32() * 8.0 - 4.0, 3.0);
            let size = 0.05 + 0.3 * rng.next_f32();
            let radiance = 0.5 + 20.0 * rng.next_f32() * rng.next_f32();
            // Wound so that the normal points down (-Z), towards the floor.
            let (e1, e2) = (Vec3::Y * size, Vec3::X * size * (1.0 + (k % 3) as f32));
            triangles.push(EmitterTriangle {
                p0: centre,
                e1,
                e2,
                normal: e1.cross(e2).normalize(),
                area: 0.5 * e1.cross(e2).length(),
                radiance: Vec3::splat(radiance),
                object: 0,
                prim_id: k,
            });
        }
        assert!(triangles.iter().all(|t| t.normal.z < -0.99));
        let (point, n) = (Vec3::new(0.5, -0.25, 0.0), Vec3::Z);
        let exact: f64 = triangles.iter().map(|t| triangle_irradiance(t, point, n)).sum();
        let set = EmitterSet::new(triangles);
        let samples = 400_000;
        let mut sum = 0.0f64;
        for _ in 0..samples {
            let Some(p) = set.sample(point, n, rng.next_f32(), rng.next_f32(), rng.next_f32()) else {
                continue;
            };
            let offset = p.position - point;
            let d2 = offset.length_squared();
            let wi = offset / d2.sqrt();
            let geometry = (n.dot(wi) * -p.normal.dot(wi)).max(0.0) / d2;
            sum += (p.radiance.x * geometry / p.pdf_area) as f64;
        }
        let mean = sum / samples as f64;
        assert!((mean - exact).abs() < 0.01 * exact, "estimate {mean}, exact {exact}");
    }
    #[test]
    fn estimate_stays_unbiased_where_most_emitters_cannot_light_the_point() {
        // Three kinds of emitters around a floor point facing up: on the ceiling facing down
        // (they light it), on the ceiling facing up (the point is behind them) and under the
        // floor (behind the point's tangent plane). The tree gives the dark ones no picks (a pick
        // may end in none at all, where a part of the tree holds only dark ones); the estimate
        // must still be the lit ones' exact irradiance.
        let mut rng = crate::sampling::Rng::new(5, 0);
        let (point, n) = (Vec3::new(0.3, 0.1, 0.0), Vec3::Z);
        let mut triangles = Vec::new();
        let mut exact = 0.0f64;
        for k in 0..150u32 {
            let x = rng.next_f32() * 8.0 - 4.0;
            let y = rng.next_f32() * 8.0 - 4.0;
            let size = 0.1 + 0.3 * rng.next_f32();
            let (z, facing_down) = match k % 3 {
                0 => (3.0, true),
                1 => (3.0, false),
                _ => (-2.0, false),
            };
            let (e1, e2) = if facing_down {
                (Vec3::Y * size, Vec3::X * size)
            } else {
                (Vec3::X * size, Vec3::Y * size)
            };
            let t = EmitterTriangle {
                p0: Vec3::new(x, y, z),
                e1,
                e2,
                normal: e1.cross(e2).normalize(),
                area: 0.5 * size * size,
                radiance: Vec3::splat(1.0 + 4.0 * rng.next_f32()),
                object: 0,
                prim_id: k,
            };
            if k % 3 == 0 {
                exact += triangle_irradiance(&t, point, n);
            }
            triangles.push(t);
        }
        let set = EmitterSet::new(triangles);
        let samples = 300_000;
        let (mut sum, mut none) = (0.0f64, 0);
        for _ in 0..samples {
            let Some(p) = set.sample(point, n, rng.next_f32(), rng.next_f32(), rng.next_f32()) else {
                none += 1;
                continue;
            };
            let offset = p.position - point;
            let d2 = offset.length_squared();
            let wi = offset / d2.sqrt();
            let geometry = n.dot(wi) * -p.normal.dot(wi) / d2;
            assert!(geometry > 0.0, "picked an emitter that cannot light the point");
            sum += (p.radiance.x * geometry / p.pdf_area) as f64;
        }
        let mean = sum / samples as f64;
        assert!((mean - exact).abs() < 0.01 * exact, "estimate {mean}, exact {exact}");
        // By power alone two picks in three would go to dark emitters.
        assert!(none < samples / 2, "{none} of {samples} picks found no emitter");
    }
}

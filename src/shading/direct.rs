//! L_d: light arriving straight from the light sources, by shadow rays. Area emitters are
//! picked through the light tree (power over squared distance) and sampled by area. On the eye
//! path every punctual light gets one ray; elsewhere (a record's hemisphere rays and below) one
//! punctual light is picked by its unshadowed light there. The diffuse part sees all lights;
//! the glossy lobe sees punctual lights here (nothing else can hit them) and area emitters
//! through its own specular rays.
//!
//! The shadow rays of all of a pixel's samples are stratified together (`LightStrata`): with
//! 16 samples of one ray each, the 16 rays take 16 different strata of the emitter choice and
//! 16 different cells of the point on it, rather than 16 independent draws.

use super::{Integrator, RayCounts, glossy};
use crate::sampling::Rng;
use crate::scene::light::{LightSample, PunctualLight, luminance};
use crate::scene::material::SurfacePoint;
use crate::tracer::{PACKET, SurfaceHit};
use glam::Vec3;
use std::f32::consts::PI;

/// Where one shading point's shadow rays fall among all of its pixel's: rays `first ..
/// first + count` of `total`, and the pixel's random offsets. Ray g takes stratum
/// s = (g + offset) mod total of the emitter choice and the cell of the grid over the
/// emitter's surface that the s-th Sobol point falls in, shifted by `cell_offset`
/// (`emitter_cell`): the rays of a pixel all differ in both, those on one emitter spread over
/// its surface, and with the offsets uniform per pixel each ray alone is uniform, so the
/// estimate stays unbiased. (A fixed affine pairing of strata and cells, tried first, put the
/// rays on one emitter into one part of it and raised the noise by 75 %; a random pairing, the
/// one before Sobol's, scattered them at random over the cells: on the Cornell box, relMSE of
/// the composite 14-35 % above today's at the peers bench's settings.)
#[derive(Clone, Copy, Debug)]
pub struct LightStrata {
    pub first: u32,
    pub count: u32,
    pub total: u32,
    pub offset: u32,
    pub cell_offset: u32,
    /// Whether the point is on the eye path (where the analytic estimate pays off; see
    /// `direct_light`).
    pub eye_path: bool,
}

impl LightStrata {
    /// `count` rays stratified among themselves only, with offsets from `rng`.
    pub fn alone(count: u32, rng: &mut Rng) -> LightStrata {
        LightStrata {
            first: 0,
            count,
            total: count,
            offset: rng.next_u32(),
            cell_offset: rng.next_u32(),
            eye_path: false,
        }
    }

    /// The same strata with `offset` reduced below `total` (the same stratum for every ray),
    /// so that `uniforms` need not divide for each ray.
    fn reduced(self) -> LightStrata {
        LightStrata {
            offset: self.offset % self.total.max(1),
            ..self
        }
    }

    /// The uniforms of ray k (of `count`): stratum of the emitter choice, point on the emitter.
    fn uniforms(&self, k: u32, rng: &mut Rng) -> (f32, f32, f32) {
        let (g, total) = ((self.first + k) as u64, self.total as u64);
        let shifted = g + self.offset as u64;
        // (g + offset) mod total, without a division where the offset is reduced (`reduced`).
        let stratum = if self.offset < self.total && g < total {
            if shifted >= total { shifted - total } else { shifted }
        } else {
            shifted % total
        } as u32;
        let (col, row, cols, rows) = emitter_cell(stratum, self.total, self.cell_offset);
        (
            (stratum as f32 + rng.next_f32()) / self.total as f32,
            (col as f32 + rng.next_f32()) / cols as f32,
            (row as f32 + rng.next_f32()) / rows as f32,
        )
    }
}

/// The cell on the emitter's square of the ray in emitter-choice `stratum` of `total`: the
/// stratum-th point of the two-dimensional Sobol sequence, on a grid of `cols x rows` cells
/// (their product the power of two at or above `total`, as square as powers of two go), its
/// column and row each xor-ed with bits of `shift` (the pixel's random digital shift).
///
/// Why by the stratum, and why Sobol: the emitter choice takes consecutive strata to the same
/// emitter (the light tree inverts u1), so the rays on one emitter are a run of consecutive
/// strata, and the points of a run of a (0,2)-sequence are spread over the square, an aligned
/// run of 2^m of them one in each of 2^m cells. Before, cells were a random permutation of
/// the rays, so the rays of the Cornell box's light (two triangles, half the strata each)
/// fell in a random half of the cells each, clustered here and missing there. The first
/// `cols x rows` points take every cell once, so a pixel's rays take distinct cells; over the
/// shift each cell is equally likely for every ray, so each ray alone is uniform.
fn emitter_cell(stratum: u32, total: u32, shift: u32) -> (u32, u32, u32, u32) {
    let bits = total.max(1).next_power_of_two().trailing_zeros();
    let (col_bits, row_bits) = (bits.div_ceil(2), bits / 2);
    let (x, y) = sobol_2d(stratum);
    let high = |v: u32, b: u32| if b == 0 { 0 } else { v >> (32 - b) };
    let mask = |b: u32| (1u32 << b) - 1;
    let col = high(x, col_bits) ^ (shift & mask(col_bits));
    let row = high(y, row_bits) ^ ((shift >> 16) & mask(row_bits));
    (col, row, 1 << col_bits, 1 << row_bits)
}

/// Point `index` of the two-dimensional Sobol sequence, as 32-bit fractions: the first
/// coordinate the base-2 radical inverse, the second by the Pascal matrix mod 2.
fn sobol_2d(index: u32) -> (u32, u32) {
    // The radical inverse is the index's bits reversed.
    let mut y = 0u32;
    let mut column_y = 1u32 << 31;
    let mut i = index;
    while i != 0 {
        if i & 1 != 0 {
            y ^= column_y;
        }
        i >>= 1;
        column_y ^= column_y >> 1;
    }
    (index.reverse_bits(), y)
}

/// The exact unshadowed irradiance replaces the sampled one while the emitters number at most
/// this many per shadow ray of the shading point. Each emitter costs about a third of a shadow
/// ray. Measured at -ab 1 -aa 0.2 with 16 rays a pixel: on the Cornell box (2 emitting
/// triangles) it cut the direct layer's relMSE 3x for 5 % more render time; on the conference
/// room (48) it cut it by a third for 0.35 s more, where 24 plain rays did as well for 0.17 s.
pub const ANALYTIC_EMITTERS_PER_RAY: usize = 2;

/// Channel-wise `passed / unblocked`, 0 where nothing unblocked was seen.
fn ratio(passed: Vec3, unblocked: Vec3) -> Vec3 {
    let share = |p: f32, u: f32| if u > 0.0 { (p / u).clamp(0.0, 1.0) } else { 0.0 };
    Vec3::new(
        share(passed.x, unblocked.x),
        share(passed.y, unblocked.y),
        share(passed.z, unblocked.z),
    )
}

/// The parts of the ratio estimate at one or more points: the exact unshadowed light, and what
/// the shadow rays brought with and without their blockers. The estimate is `exact` times the
/// share `passed / unblocked`. Parts add up, so a pixel can pool its samples' rays into one
/// share: the share of a point's few rays is a ratio of two noisy sums, biased by about the
/// inverse of its ray count where part of the light is hidden (the Cornell box's penumbrae read
/// 6 % dark at 4 rays a point, at any pixel sample count); pooled over a pixel's samples its bias
/// falls with the pixel's rays, and where the light is wholly visible or hidden it stays exact.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ShadowRatio {
    pub exact: Vec3,
    pub passed: Vec3,
    pub unblocked: Vec3,
    /// How the rays behind `passed` and `unblocked` spread, ray by ray: what a pixel of one
    /// sample knows of its estimate's noise (`render::noise`).
    pub rays: RaySpread,
}

/// The second moments of the shadow rays of a ratio estimate, in luminance: each ray's share
/// of `passed` (x, its light if it got through, over the point's ray count) and of `unblocked`
/// (y). With `P` and `U` their sums and `R = P / U`, the estimate's share has the variance
/// `m / (m - 1) * sum (x - R y)^2 / U^2` over `m` rays (the delta method; `sum (x - R y)` is
/// zero). The rays are stratified over the light, so this is an upper bound of their noise.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RaySpread {
    pub rays: f32,
    pub passed_squared: f32,
    pub unblocked_squared: f32,
    pub product: f32,
}

impl RaySpread {
    /// A ray's parts (a ray that brought nothing adds nothing; `rays` counts them all).
    pub fn add(&mut self, passed: f32, unblocked: f32) {
        self.passed_squared += passed * passed;
        self.unblocked_squared += unblocked * unblocked;
        self.product += passed * unblocked;
    }

    /// The variance of the share `passed / unblocked` (luminances, the rays' sums), zero
    /// with fewer than two rays or no light.
    pub fn share_variance(&self, passed: f32, unblocked: f32) -> f64 {
        let (m, p, u) = (self.rays as f64, passed as f64, unblocked as f64);
        if m < 2.0 || u <= 0.0 {
            return 0.0;
        }
        let r = p / u;
        let squares =
            self.passed_squared as f64 - 2.0 * r * self.product as f64 + r * r * self.unblocked_squared as f64;
        m / (m - 1.0) * squares.max(0.0) / (u * u)
    }

    /// The variance of the plain estimate `passed` (the rays' sum, each ray over their
    /// count), zero with fewer than two rays.
    pub fn mean_variance(&self, passed: f32) -> f64 {
        let (m, p) = (self.rays as f64, passed as f64);
        if m < 2.0 {
            return 0.0;
        }
        ((m * self.passed_squared as f64 - p * p) / (m - 1.0)).max(0.0)
    }

    fn is_finite(&self) -> bool {
        self.passed_squared.is_finite() && self.unblocked_squared.is_finite() && self.product.is_finite()
    }
}

impl ShadowRatio {
    pub fn estimate(&self) -> Vec3 {
        self.exact * ratio(self.passed, self.unblocked)
    }

    pub fn scaled(self, k: f32) -> ShadowRatio {
        let k2 = k * k;
        ShadowRatio {
            exact: self.exact * k,
            passed: self.passed * k,
            unblocked: self.unblocked * k,
            rays: RaySpread {
                rays: self.rays.rays,
                passed_squared: self.rays.passed_squared * k2,
                unblocked_squared: self.rays.unblocked_squared * k2,
                product: self.rays.product * k2,
            },
        }
    }

    pub fn is_finite(&self) -> bool {
        self.exact.is_finite() && self.passed.is_finite() && self.unblocked.is_finite() && self.rays.is_finite()
    }
}

impl std::ops::AddAssign for ShadowRatio {
    fn add_assign(&mut self, other: ShadowRatio) {
        self.exact += other.exact;
        self.passed += other.passed;
        self.unblocked += other.unblocked;
        self.rays.rays += other.rays.rays;
        self.rays.passed_squared += other.rays.passed_squared;
        self.rays.unblocked_squared += other.rays.unblocked_squared;
        self.rays.product += other.rays.product;
    }
}

/// L_d at a point: what plain sampling gave, and the ratio estimate's parts where the exact
/// unshadowed light was used (see `ShadowRatio`). The point's light is their sum.
#[derive(Clone, Copy, Debug, Default)]
pub struct DirectLight {
    pub sampled: Vec3,
    pub ratio: Option<ShadowRatio>,
    /// Of `sampled`, the punctual lights' light where each light got its own shadow ray (on
    /// the eye path): exact at the point, no Monte Carlo noise in it. It differs between a
    /// pixel's samples only as the pixel's content does (a hard shadow's edge, a texture), and
    /// the pixel's noise leaves it out (`render::noise`).
    pub exact: Vec3,
    /// The variance (luminance) of the emitters' plainly sampled light in `sampled`, as its
    /// rays spread: what a pixel of one sample knows of that part's noise.
    pub sampled_noise: f32,
}

impl DirectLight {
    pub fn total(&self) -> Vec3 {
        self.sampled + self.ratio.map_or(Vec3::ZERO, |r| r.estimate())
    }
}

pub fn direct_light(
    integrator: &Integrator<'_>,
    hit: &SurfaceHit,
    wo: Vec3,
    surface: &SurfacePoint,
    strata: LightStrata,
    rng: &mut Rng,
    counts: &mut RayCounts,
) -> DirectLight {
    let scene = integrator.scene;
    let tracer = integrator.tracer;
    let diffuse_brdf = surface.diffuse / PI;
    let mut total = Vec3::ZERO;
    let mut shadow_ratio = None;
    let mut sampled_noise = 0.0;

    if surface.diffuse.max_element() > 0.0 && !scene.emitters.is_empty() {
        let emitter_samples = strata.count.max(1);
        // Lambert's formula costs about a third of a shadow ray an emitter: worth it on the eye
        // path, where a pixel's direct light is its few shadow rays, while the emitters are few
        // next to those rays. At the hemisphere's hit points (not on the eye path) hundreds of rays
        // average the noise it would remove.
        let unshadowed = (strata.eye_path
            && integrator.options.analytic_direct
            && scene.emitters.len() <= ANALYTIC_EMITTERS_PER_RAY * emitter_samples as usize)
            .then(|| scene.emitters.unshadowed_irradiance(hit.position, hit.normal))
            .flatten();
        let mut sum = Vec3::ZERO;
        // What the rays would bring if none were blocked, for the ratio estimator.
        let mut sum_unblocked = Vec3::ZERO;
        // Ray by ray, for a single sample's noise (each ray's light over the ray count).
        let mut spread = RaySpread {
            rays: emitter_samples as f32,
            ..RaySpread::default()
        };
        let per_ray = diffuse_brdf / emitter_samples as f32;
        // A lone ray's pick walks the light tree alone (`EmitterSet::sample`).
        let mut sampler = (emitter_samples > 1)
            .then(|| scene.emitters.sampler(hit.position, hit.normal))
            .flatten();
        let strata = strata.reduced();
        let mut pending = PendingShadows::default();
        for k in 0..emitter_samples {
            let (u1, u2, u3) = strata.uniforms(k, rng);
            let light = match sampler.as_mut() {
                Some(sampler) => sampler.sample(u1, u2, u3),
                None if emitter_samples == 1 => scene.emitters.sample(hit.position, hit.normal, u1, u2, u3),
                None => None,
            };
            let Some(light) = light else {
                continue;
            };
            let offset = light.position - hit.position;
            let d2 = offset.length_squared();
            if d2.is_nan() || d2 <= 0.0 {
                continue;
            }
            let d = d2.sqrt();
            let wi = offset / d;
            let cos_surface = hit.normal.dot(wi);
            let cos_light = -light.normal.dot(wi);
            if cos_surface <= 0.0 || cos_light <= 0.0 {
                continue;
            }
            let contribution = light.radiance * (cos_surface * cos_light / (d2 * light.pdf_area));
            sum_unblocked += contribution;
            // Below the geometric surface (a shading normal tilted towards the light): blocked
            // by the surface itself.
            if wi.dot(hit.facing_normal) <= 0.0 {
                continue;
            }
            let origin = tracer.spawn_point(hit, wi);
            // Aimed from the raised origin at the light's point itself: along `wi` from there the
            // ray runs beside the true one, a hair off, and when it meets the emitter at a
            // grazing angle it crosses the emitter's plane before the point, outside the margin
            // below (the emitter shadowed itself for rays within about 66 degrees of grazing,
            // darkening surfaces far from the lamps). Stops short of the emitter so its own
            // surface does not count as a blocker.
            let to_light = light.position - origin;
            let length = to_light.length();
            let reach = length - tracer.epsilon_at(light.position) * 2.0;
            if reach <= 0.0 || !reach.is_finite() {
                continue;
            }
            counts.shadow += 1;
            pending.push(
                contribution,
                luminance(per_ray * contribution),
                (origin, to_light / length, reach),
            );
            if pending.is_full() {
                pending.trace(integrator, counts, &mut sum, &mut spread);
            }
        }
        pending.trace(integrator, counts, &mut sum, &mut spread);
        match unshadowed {
            // Ratio estimator: the exact unblocked irradiance times the share of the rays'
            // unblocked contribution that got through. Exact where the emitters are wholly
            // visible or wholly hidden; in penumbrae consistent (references use the plain
            // estimate). The caller may pool the parts over a pixel (`ShadowRatio`).
            Some(exact) => {
                let n = emitter_samples as f32;
                shadow_ratio = Some(ShadowRatio {
                    exact: diffuse_brdf * exact,
                    passed: diffuse_brdf * sum / n,
                    unblocked: diffuse_brdf * sum_unblocked / n,
                    rays: spread,
                })
            }
            None => {
                let estimate = diffuse_brdf * sum / emitter_samples as f32;
                sampled_noise = spread.mean_variance(luminance(estimate)) as f32;
                total += estimate;
            }
        }
    }

    let lights = &scene.punctual_lights;
    let mut exact = Vec3::ZERO;
    if strata.eye_path || lights.len() < 2 {
        // On the eye path every punctual light gets its ray: a pixel's few samples are its
        // direct light, and a light left out would be noise the image shows.
        // Their rays leave one point, so they go together (`PendingShadows`).
        let mut pending = PendingShadows::default();
        for light in lights {
            if let Some(lit) = PunctualLit::at(light, hit, wo, surface, diffuse_brdf) {
                counts.shadow += 1;
                pending.push(lit.light, 0.0, lit.ray(integrator, hit));
                if pending.is_full() {
                    pending.trace(integrator, counts, &mut exact, &mut RaySpread::default());
                }
            }
        }
        pending.trace(integrator, counts, &mut exact, &mut RaySpread::default());
        total += exact;
    } else if let Some((lit, probability)) = pick_punctual(lights, hit, wo, surface, diffuse_brdf, rng) {
        // Away from the eye path (a record's hemisphere rays, the paths below them) one light
        // is picked in proportion to its unshadowed light and its ray's result divided by that
        // probability: unbiased, and the hundreds of hits a record averages take the noise.
        // On Sibenik (5 point lights, -ab 2, the peers bench's settings 1-3, two views) it
        // cut the shadow rays 2.6-3x and the render time to 0.70-0.87x at equal or lower 4x4
        // error on the time-error curve (10-12 % lower error at equal time on the nave view).
        total += lit.traced(integrator, hit, counts) / probability;
    }
    DirectLight {
        sampled: total,
        ratio: shadow_ratio,
        exact,
        sampled_noise,
    }
}

/// Shadow rays from one point (to emitters, or to punctual lights) waiting to be traced
/// together (`Tracer::transmittances`), with what each brings if it gets through and its
/// luminance for the rays' spread.
#[derive(Default)]
struct PendingShadows {
    len: usize,
    light: [Vec3; PACKET],
    unblocked: [f32; PACKET],
    rays: [(Vec3, Vec3, f32); PACKET],
}

impl PendingShadows {
    fn push(&mut self, light: Vec3, unblocked: f32, ray: (Vec3, Vec3, f32)) {
        self.light[self.len] = light;
        self.unblocked[self.len] = unblocked;
        self.rays[self.len] = ray;
        self.len += 1;
    }

    fn is_full(&self) -> bool {
        self.len == PACKET
    }

    /// Traces the waiting rays and adds what passed to `sum` and `spread`, in the rays' order.
    fn trace(&mut self, integrator: &Integrator<'_>, counts: &mut RayCounts, sum: &mut Vec3, spread: &mut RaySpread) {
        if self.len == 0 {
            return;
        }
        let mut through = [0.0f32; PACKET];
        integrator.tracer.transmittances(
            integrator.scene,
            &self.rays[..self.len],
            &mut through[..self.len],
            &mut counts.continued,
        );
        let waiting = self.light.iter().zip(&self.unblocked).zip(through).take(self.len);
        for ((&light, &unblocked), visible) in waiting {
            if visible > 0.0 {
                *sum += light * visible;
            }
            spread.add(unblocked * visible, unblocked);
        }
        self.len = 0;
    }
}

/// What a punctual light (`source`) would give a point were nothing in the way: the direction
/// to it and the reflected light.
#[derive(Clone, Copy)]
struct PunctualLit<'a> {
    source: &'a PunctualLight,
    sample: LightSample,
    light: Vec3,
}

impl<'a> PunctualLit<'a> {
    fn at(
        source: &'a PunctualLight,
        hit: &SurfaceHit,
        wo: Vec3,
        surface: &SurfacePoint,
        diffuse_brdf: Vec3,
    ) -> Option<PunctualLit<'a>> {
        let sample = source.illuminate(hit.position)?;
        let wi = sample.to_light;
        let cos_surface = hit.normal.dot(wi);
        if cos_surface <= 0.0 || wi.dot(hit.facing_normal) <= 0.0 {
            return None;
        }
        // A Lambertian surface (every one under --lambertian) skips the glossy lobe's
        // evaluation, whose product with a zero reflectance would be zero anyway: it was most of
        // this function's time, five times per hit on Sibenik's five lights.
        let glossy = if surface.specular.max_element() > 0.0 {
            surface.specular * glossy::eval_cos(hit.normal, wo, wi, surface.alpha)
        } else {
            Vec3::ZERO
        };
        let light = (diffuse_brdf * cos_surface + glossy) * sample.irradiance;
        (light.max_element() > 0.0 && light.is_finite()).then_some(PunctualLit { source, sample, light })
    }

    /// The shadow ray to the light: origin, direction and reach.
    fn ray(&self, integrator: &Integrator<'_>, hit: &SurfaceHit) -> (Vec3, Vec3, f32) {
        let wi = self.sample.to_light;
        let origin = integrator.tracer.spawn_point(hit, wi);
        let reach = if self.sample.distance.is_finite() {
            (self.source.position - origin).length()
        } else {
            f32::INFINITY
        };
        (origin, wi, reach)
    }

    /// The light times what passes along the shadow ray to the light.
    fn traced(&self, integrator: &Integrator<'_>, hit: &SurfaceHit, counts: &mut RayCounts) -> Vec3 {
        let (origin, wi, reach) = self.ray(integrator, hit);
        counts.shadow += 1;
        let visible = integrator
            .tracer
            .transmittance(integrator.scene, origin, wi, reach, &mut counts.continued);
        if visible > 0.0 {
            self.light * visible
        } else {
            Vec3::ZERO
        }
    }

    /// The weight of the light in `pick_punctual`.
    fn weight(&self) -> f32 {
        self.light.x + self.light.y + self.light.z
    }
}

/// Up to this many punctual lights, `pick_punctual` evaluates each light once and keeps the
/// results on the stack; past it, each light is evaluated twice (for the total, then for the
/// choice) rather than allocate a list per hit.
const PICK_FROM_STACK: usize = 8;

/// One of `lights` picked with probability in proportion to its unshadowed light at the point:
/// what it gives, and the probability. None where none lights the point.
fn pick_punctual<'a>(
    lights: &'a [PunctualLight],
    hit: &SurfaceHit,
    wo: Vec3,
    surface: &SurfacePoint,
    diffuse_brdf: Vec3,
    rng: &mut Rng,
) -> Option<(PunctualLit<'a>, f32)> {
    let lit = |light| PunctualLit::at(light, hit, wo, surface, diffuse_brdf);
    if lights.len() <= PICK_FROM_STACK {
        let mut evaluated = [None; PICK_FROM_STACK];
        for (slot, light) in evaluated.iter_mut().zip(lights) {
            *slot = lit(light);
        }
        pick_in_proportion(evaluated.iter().flatten().copied(), rng)
    } else {
        pick_in_proportion(lights.iter().filter_map(lit), rng)
    }
}

/// One of the lit lights `lit` yields (it is walked twice: for the total, then for the choice),
/// picked in proportion to its weight, with its probability.
fn pick_in_proportion<'a>(
    lit: impl Iterator<Item = PunctualLit<'a>> + Clone,
    rng: &mut Rng,
) -> Option<(PunctualLit<'a>, f32)> {
    let total: f32 = lit.clone().map(|l| l.weight()).sum();
    if !(total > 0.0 && total.is_finite()) {
        return None;
    }
    // The light whose share of [0, total) holds the target; the last lit one should rounding
    // carry the target past every share.
    let target = rng.next_f32() * total;
    let mut start = 0.0;
    let mut chosen = None;
    for l in lit {
        let w = l.weight();
        let found = target < start + w;
        start += w;
        chosen = Some((l, w));
        if found {
            break;
        }
    }
    chosen.map(|(l, w)| (l, w / total))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Stratum and cell of ray k, read back from its uniforms; and the number of cells.
    fn slots(strata: &LightStrata, k: u32, rng: &mut Rng) -> (u32, u32, u32) {
        let (u1, u2, u3) = strata.uniforms(k, rng);
        let stratum = (u1 * strata.total as f32) as u32;
        let (_, _, cols, rows) = emitter_cell(0, strata.total, 0);
        let cell = (u3 * rows as f32) as u32 * cols + (u2 * cols as f32) as u32;
        (stratum, cell, cols * rows)
    }

    #[test]
    fn a_pixels_rays_take_distinct_strata_and_cells() {
        let mut rng = Rng::new(4, 5);
        for (samples, per_sample) in [(1u32, 1u32), (4, 1), (8, 2), (16, 1), (3, 5), (64, 4), (8, 4), (6, 4)] {
            let total = samples * per_sample;
            let (offset, cell_offset) = (rng.next_u32(), rng.next_u32());
            let mut strata_seen = vec![false; total as usize];
            let mut cells_seen = vec![false; total.next_power_of_two() as usize];
            for s in 0..samples {
                let strata = LightStrata {
                    first: s * per_sample,
                    count: per_sample,
                    total,
                    offset,
                    cell_offset,
                    eye_path: false,
                };
                for k in 0..per_sample {
                    let (stratum, cell, cells) = slots(&strata, k, &mut rng);
                    assert_eq!(cells, total.next_power_of_two());
                    assert!(
                        !strata_seen[stratum as usize],
                        "{samples}x{per_sample}: stratum {stratum} twice"
                    );
                    assert!(!cells_seen[cell as usize], "{samples}x{per_sample}: cell {cell} twice");
                    strata_seen[stratum as usize] = true;
                    cells_seen[cell as usize] = true;
                }
            }
            assert!(strata_seen.iter().all(|&s| s));
        }
    }

    #[test]
    fn the_rays_on_one_of_two_equal_emitters_cover_its_whole_surface() {
        // 64 rays, 8 x 8 cells: the light tree takes strata 0-31 to the first emitter. Those 32
        // rays take one cell in each 2 x 1 pair of the 8 x 8 grid's cells (8 x 4 coarse
        // cells), whatever the pixel's shift; a random pairing of rays and cells leaves about a
        // quarter of those pairs empty and another quarter doubled up.
        for shift in [0u32, 0x0005_0003, 0xdead_beef] {
            let mut coarse = [0u32; 32];
            for stratum in 0..32 {
                let (col, row, cols, rows) = emitter_cell(stratum, 64, shift);
                assert_eq!((cols, rows), (8, 8));
                coarse[(row / 2 * 8 + col) as usize] += 1;
            }
            assert!(coarse.iter().all(|&n| n == 1), "shift {shift:#x}: {coarse:?}");
        }
    }

    #[test]
    fn sobol_points_start_as_the_sequence_does() {
        let points: Vec<(f64, f64)> = (0..4)
            .map(sobol_2d)
            .map(|(x, y)| (x as f64 / 2f64.powi(32), y as f64 / 2f64.powi(32)))
            .collect();
        assert_eq!(points, [(0.0, 0.0), (0.5, 0.5), (0.25, 0.75), (0.75, 0.25)]);
    }

    #[test]
    fn over_the_pixel_offsets_each_ray_is_uniform() {
        // For a fixed ray, every stratum and every cell comes up equally often as the pixel's
        // offsets run over their range: the ray alone is uniform, so no bias.
        let mut rng = Rng::new(8, 9);
        let total = 12u32;
        let ray = 5u32;
        let mut strata_count = vec![0u32; total as usize];
        let mut cell_count = vec![0u32; 16];
        for offset in 0..total {
            // The shift's low bits xor the column (2 bits), bits 16 and up the row (2 bits).
            for shift in 0..16u32 {
                let strata = LightStrata {
                    first: ray,
                    count: 1,
                    total,
                    offset,
                    cell_offset: (shift & 3) | (shift >> 2) << 16,
                    eye_path: false,
                };
                let (stratum, cell, cells) = slots(&strata, 0, &mut rng);
                assert_eq!(cells, 16);
                strata_count[stratum as usize] += 1;
                cell_count[cell as usize] += 1;
            }
        }
        assert!(strata_count.iter().all(|&c| c == 16), "{strata_count:?}");
        assert!(cell_count.iter().all(|&c| c == total), "{cell_count:?}");
    }

    /// `n` point lights of different strengths and places above the origin, some behind the
    /// floor (so unlit), and a hit on the floor at the origin with a grey Lambertian point.
    fn lights_over_a_floor(n: usize) -> (Vec<PunctualLight>, SurfaceHit, SurfacePoint) {
        let lights = (0..n)
            .map(|i| PunctualLight {
                name: format!("l{i}"),
                kind: crate::sys::scene_io::LightType::Point,
                intensity: Vec3::splat(1.0 + i as f32),
                position: Vec3::new(
                    i as f32 - 3.0,
                    if i % 4 == 3 { -1.0 } else { 1.0 + 0.5 * i as f32 },
                    0.5,
                ),
                direction: -Vec3::Y,
                range: 0.0,
                cos_inner: 0.0,
                cos_outer: 0.0,
            })
            .collect();
        let hit = SurfaceHit::on_floor(Vec3::ZERO, 1.0, 0);
        let grey = SurfacePoint {
            diffuse: Vec3::splat(0.5),
            specular: Vec3::ZERO,
            alpha: 0.0,
            opacity: 1.0,
        };
        (lights, hit, grey)
    }

    /// Each light's unshadowed light at the hit, by the definition (irradiance x cosine x
    /// BRDF), and so its share of the pick.
    fn unshadowed(light: &PunctualLight, hit: &SurfaceHit, diffuse_brdf: Vec3) -> f32 {
        let to = light.position - hit.position;
        let cos = hit.normal.dot(to.normalize());
        if cos <= 0.0 {
            return 0.0;
        }
        let light = diffuse_brdf * cos * light.intensity / to.length_squared();
        light.x + light.y + light.z
    }

    #[test]
    fn a_punctual_light_is_picked_in_proportion_to_its_unshadowed_light() {
        // 6 lights: evaluated once, on the stack; 11: evaluated twice (`PICK_FROM_STACK`).
        for n in [6, 11] {
            let (lights, hit, grey) = lights_over_a_floor(n);
            let brdf = grey.diffuse / PI;
            let weights: Vec<f32> = lights.iter().map(|l| unshadowed(l, &hit, brdf)).collect();
            let total: f32 = weights.iter().sum();
            let mut rng = Rng::new(7, n as u64);
            let mut picked = vec![0usize; n];
            let draws = 40_000;
            for _ in 0..draws {
                let (lit, probability) = pick_punctual(&lights, &hit, Vec3::Y, &grey, brdf, &mut rng).unwrap();
                let k = lights.iter().position(|l| std::ptr::eq(l, lit.source)).unwrap();
                assert!((probability - weights[k] / total).abs() < 1e-5, "light {k} of {n}");
                picked[k] += 1;
            }
            for (k, (&count, &w)) in picked.iter().zip(&weights).enumerate() {
                let expected = draws as f32 * w / total;
                // Unlit lights are never picked; the others within four standard deviations.
                assert!(
                    (count as f32 - expected).abs() <= 4.0 * expected.sqrt() + f32::EPSILON,
                    "light {k} of {n}: {count} picks, {expected} expected"
                );
            }
            assert!(picked.iter().zip(&weights).any(|(&c, &w)| c == 0 && w == 0.0));
        }
    }

    #[test]
    fn picking_from_the_stack_picks_what_evaluating_twice_picks() {
        let (lights, hit, grey) = lights_over_a_floor(PICK_FROM_STACK);
        let brdf = grey.diffuse / PI;
        let lit = |light| PunctualLit::at(light, &hit, Vec3::Y, &grey, brdf);
        let (mut a, mut b) = (Rng::new(3, 9), Rng::new(3, 9));
        for _ in 0..1000 {
            let (x, px) = pick_punctual(&lights, &hit, Vec3::Y, &grey, brdf, &mut a).unwrap();
            let (y, py) = pick_in_proportion(lights.iter().filter_map(lit), &mut b).unwrap();
            assert!(std::ptr::eq(x.source, y.source));
            assert_eq!(px, py);
        }
    }
}

//! Shading by components (Radiance style): at every point a path reaches, emission L_e,
//! direct light L_d from the light sources, specular L_s by mirror and glossy rays carrying the
//! rippled coefficient jT (paper, eq. 1), and indirect diffuse L_a by sampling the hemisphere.
//!
//! Light is counted once: direct lighting samples every emitter, so rays gathering indirect
//! diffuse light do not count the emission they hit; specular rays do, since the direct
//! component leaves the specular lobe's view of area emitters to them.
//!
//! This module is the path: a ray's hit shaded into its components, the specular chain, and
//! the eye path's bookkeeping. The indirect diffuse light a hit asks for (the cache, new
//! records, brute force) is `ambient`; the direct light `direct`; a thread's statistics and
//! the sample's context `work`.

mod ambient;
pub mod deferred;
pub mod direct;
pub mod glossy;
mod hemisphere_batch;
pub mod last_bounce;
mod options;
pub mod pixel_irradiance;
pub mod request;
mod work;

pub use ambient::Holdout;
pub use options::ShadingOptions;
pub use work::{RayCounts, SampleContext, SampleData, Work};
use work::{sanitize, sanitize_value, timed_ambient};

use crate::image::components::Components;
use crate::irradiance::IrradianceCache;
use crate::irradiance::last_bounce::Received;
use crate::irradiance::record::Record;
use crate::sampling::Rng;
use crate::scene::Scene;
use crate::scene::material::SurfacePoint;
use crate::sys::embree::Coherence;
use crate::tracer::{SurfaceHit, Tracer};
use direct::LightStrata;
use glam::Vec3;
use request::RequestBuffer;

/// Where on a path a point is: diffuse bounces so far, specular depth, and the weight jT the
/// path carries to the eye.
#[derive(Clone, Copy, Debug)]
pub struct PathState {
    level: u32,
    specular_depth: u32,
    weight: f32,
    /// Whether emission seen at this hit counts (not for rays gathering indirect diffuse).
    count_emission: bool,
    /// The emission seen straight from the eye (first hit of a primary ray) is gathered by
    /// separate rays (`first_emission`), so the primary ray's own hit leaves it out.
    first_emission_elsewhere: bool,
    /// What light leaving this point is multiplied by before it reaches the pixel: the
    /// rippled jT of the specular path and the opacities passed (RGB).
    throughput: Vec3,
    /// This point is on the eye path's chain of mirrors and transparencies (no diffuse or
    /// glossy bounce yet): its reflectance goes to the albedo layer (`SampleData`).
    albedo_chain: bool,
    /// How wide the ray's footprint grows per unit of distance (radians): 0 for a ray that
    /// stands for itself; a ray standing for a whole cell of a hemisphere of n x n cells
    /// covers the cell, sqrt(2 pi) / n (`cell_spread`). Textures are read averaged over it.
    spread: f32,
}

/// The spread of a ray standing for one of `n` x `n` equal cells of the hemisphere (each 2 pi
/// / n^2 steradians): the side of a cell.
fn cell_spread(n: usize) -> f32 {
    (2.0 * std::f32::consts::PI).sqrt() / n.max(1) as f32
}

/// How wide, in texture coordinates, the footprint of a ray along `dir` with `spread` is where
/// it hits: its width across the ray (spread times distance), stretched by the slant to the
/// side of a square of the ellipse's area, in texture units.
fn texture_footprint(hit: &SurfaceHit, dir: Vec3, spread: f32) -> f32 {
    footprint_width(spread, hit.distance, hit.uv_per_length, dir.dot(hit.geometric_normal))
}

/// `texture_footprint` from its parts: the ray's spread, the distance it went, the texture's
/// units per length there, and the cosine between the ray and the surface's normal.
fn footprint_width(spread: f32, distance: f32, uv_per_length: f32, cosine: f32) -> f32 {
    if spread <= 0.0 || uv_per_length <= 0.0 {
        return 0.0;
    }
    let slant = cosine.abs().max(1e-3);
    spread * distance * uv_per_length / slant.sqrt()
}

impl PathState {
    /// Where a primary ray starts: no bounce yet, full weight, emission counted (unless the
    /// caller gathers the first hit's emission with rays of its own).
    fn eye(first_emission_elsewhere: bool) -> PathState {
        PathState {
            level: 0,
            specular_depth: 0,
            weight: 1.0,
            count_emission: true,
            first_emission_elsewhere,
            throughput: Vec3::ONE,
            albedo_chain: true,
            spread: 0.0,
        }
    }
}

pub struct Integrator<'a> {
    pub scene: &'a Scene,
    pub tracer: &'a Tracer,
    pub options: &'a ShadingOptions,
    /// The irradiance cache; None computes L_a by brute force at every point (-aa 0).
    pub cache: Option<&'a IrradianceCache>,
    /// Component mode's PR: indirect diffuse values that the cache cannot give are not
    /// computed here but become requests in this list (left out of the pixel).
    pub defer: Option<&'a RequestBuffer>,
    /// The cache is complete (the prepass made it): a lookup that finds no record makes one
    /// for its own use and does not add it, so no pixel depends on another's timing.
    pub frozen: bool,
    /// Such a record is kept for the next pass of a render in passes (`render::passes`): it
    /// joins the set between passes (`IrradianceCache::absorb_gaps`).
    pub keeps_gaps: bool,
}

/// Passes through fully transparent (alpha-masked) points before a ray gives up.
const MAX_MASKED_PASSES: u32 = 64;

/// Whether a hit's cell of the last bounce's grid was read before its shading (a batch reads
/// its hits' cells together: `hemisphere_batch`), and what it held.
#[derive(Clone, Copy)]
enum GridRead {
    Unread,
    Read(Option<Received>),
}

impl<'a> Integrator<'a> {
    pub fn new(
        scene: &'a Scene,
        tracer: &'a Tracer,
        options: &'a ShadingOptions,
        cache: Option<&'a IrradianceCache>,
    ) -> Self {
        Integrator {
            scene,
            tracer,
            options,
            cache,
            defer: None,
            frozen: false,
            keeps_gaps: false,
        }
    }

    /// Whether this integrator only reads the cache (after a prepass): see `frozen`.
    pub fn cache_frozen(mut self, frozen: bool) -> Self {
        self.frozen = frozen;
        self
    }

    /// This integrator leaves indirect diffuse values the cache cannot give to `sink`.
    pub fn deferring(mut self, sink: &'a RequestBuffer) -> Self {
        self.defer = Some(sink);
        self
    }

    /// The components of light arriving at the eye along a primary ray.
    pub fn primary(&self, origin: Vec3, dir: Vec3, rng: &mut Rng, counts: &mut Work<'_>) -> Components {
        self.primary_ray(origin, dir, false, rng, counts)
    }

    /// As `primary`, less the emission of the first surface hit, which the caller gathers
    /// with `first_emission` (emission seen through transparent surfaces and mirrors stays).
    pub fn primary_without_first_emission(
        &self,
        origin: Vec3,
        dir: Vec3,
        rng: &mut Rng,
        counts: &mut Work<'_>,
    ) -> Components {
        self.primary_ray(origin, dir, true, rng, counts)
    }

    fn primary_ray(
        &self,
        origin: Vec3,
        dir: Vec3,
        first_emission_elsewhere: bool,
        rng: &mut Rng,
        counts: &mut Work<'_>,
    ) -> Components {
        counts.primary += 1;
        let state = PathState {
            spread: counts.sample.eye_spread,
            ..PathState::eye(first_emission_elsewhere)
        };
        self.trace(origin, dir, state, Coherence::Coherent, rng, counts).0
    }

    /// The overture of a tile: makes the records the first diffuse surface along a primary
    /// ray needs, without shading anything. Run on a sparse grid over a tile before its pixels,
    /// it lets every pixel interpolate between records on all its sides instead of
    /// extrapolating from those its predecessors happened to make. Nothing to do without a
    /// local cache (brute force, or a component-mode PR whose misses go to the PAs).
    pub fn prepare_records(&self, origin: Vec3, dir: Vec3, rng: &mut Rng, counts: &mut Work<'_>) {
        if self.cache.is_none() || self.defer.is_some() || self.options.ambient_bounces == 0 {
            return;
        }
        counts.primary += 1;
        if let Some((hit, surface)) = self.first_surface(origin, dir, Coherence::Coherent, 0.0, counts)
            && surface.diffuse.max_element() > 0.0
        {
            self.ambient_radiance(&hit, PathState::eye(false), rng, counts);
        }
    }

    /// Where the eye path of a primary ray would look up level-0 records: every diffuse
    /// surface it reaches straight or along specular reflections and transmissions (one ray
    /// each, glossy directions drawn from `rng`, within -lr and -lw as `trace` keeps them).
    /// Empty without a cache to fill. `spread`: the camera ray's footprint
    /// (`SampleContext::eye_spread`), so that the sites are the surfaces the pixel's sample
    /// stops at, textures read as it reads them.
    pub fn record_sites(
        &self,
        origin: Vec3,
        dir: Vec3,
        spread: f32,
        rng: &mut Rng,
        counts: &mut Work<'_>,
    ) -> Vec<SurfaceHit> {
        let mut sites = Vec::new();
        if self.cache.is_none() || self.options.ambient_bounces == 0 {
            return sites;
        }
        counts.primary += 1;
        // Rays still to follow: origin, direction, specular depth, path weight.
        let mut rays = vec![(origin, dir, 0u32, 1.0f32)];
        while let Some((origin, dir, depth, weight)) = rays.pop() {
            let coherence = if depth == 0 {
                Coherence::Coherent
            } else {
                Coherence::Incoherent
            };
            let Some((hit, surface)) = self.first_surface(origin, dir, coherence, spread, counts) else {
                continue;
            };
            if surface.diffuse.max_element() > 0.0 {
                sites.push(hit);
            }
            if depth >= self.options.max_specular_depth {
                continue;
            }
            let transmitted = weight * (1.0 - surface.opacity);
            if surface.opacity < 1.0 && transmitted >= self.options.min_weight {
                counts.specular += 1;
                rays.push((self.tracer.spawn_point(&hit, dir), dir, depth + 1, transmitted));
            }
            if surface.specular.max_element() > 0.0
                && let Some((wi, lobe)) =
                    glossy::sample(hit.normal, -dir, surface.alpha, rng.next_f32(), rng.next_f32())
                && wi.dot(hit.facing_normal) > 0.0
            {
                let reflected = weight * (surface.specular * lobe).max_element();
                if reflected >= self.options.min_weight {
                    counts.specular += 1;
                    rays.push((self.tracer.spawn_point(&hit, wi), wi, depth + 1, reflected));
                }
            }
        }
        sites
    }

    /// The level-0 record for a site `record_sites` found (not added to the cache), with its
    /// time counted as T_amb.
    pub fn eye_record(
        &self,
        cache: &IrradianceCache,
        hit: &SurfaceHit,
        rng: &mut Rng,
        counts: &mut Work<'_>,
    ) -> Record {
        let record = timed_ambient(counts, |counts| {
            self.compute_record(cache, hit, PathState::eye(false), rng, counts)
        });
        counts.records_computed += 1;
        counts.records_level0 += 1;
        record
    }

    /// The first surface along a ray that is not fully transparent (alpha-masked points are
    /// passed through), with its material there.
    fn first_surface(
        &self,
        origin: Vec3,
        dir: Vec3,
        coherence: Coherence,
        spread: f32,
        counts: &mut RayCounts,
    ) -> Option<(SurfaceHit, crate::scene::material::SurfacePoint)> {
        let found = self.tracer.nearest_hit(origin, dir, coherence)?;
        let hit = self.tracer.surface_hit(self.scene, &found, dir);
        self.first_surface_from(hit, dir, coherence, spread, counts)
    }

    /// `first_surface` from the point Embree's first hit along `dir` made.
    fn first_surface_from(
        &self,
        hit: SurfaceHit,
        dir: Vec3,
        coherence: Coherence,
        spread: f32,
        counts: &mut RayCounts,
    ) -> Option<(SurfaceHit, crate::scene::material::SurfacePoint)> {
        let mut hit = hit;
        for pass in 1..=MAX_MASKED_PASSES {
            let material = &self.scene.materials[hit.material as usize];
            let surface = material.over(hit.uv, texture_footprint(&hit, dir, spread), &self.scene.textures);
            if surface.opacity > 0.0 {
                return Some((hit, surface));
            }
            if pass == MAX_MASKED_PASSES {
                break;
            }
            counts.continued += 1;
            let found = self
                .tracer
                .nearest_hit(self.tracer.spawn_point(&hit, dir), dir, coherence)?;
            hit = self.tracer.surface_hit(self.scene, &found, dir);
        }
        None
    }

    /// The first surface a camera ray stops at (alpha-masked points passed through): one ray,
    /// no shading, counted as a primary ray. What tells the pixels an edge crosses
    /// (`render::edges`).
    pub fn eye_surface(&self, origin: Vec3, dir: Vec3, counts: &mut Work<'_>) -> Option<SurfaceHit> {
        counts.primary += 1;
        self.first_surface(origin, dir, Coherence::Coherent, 0.0, counts)
            .map(|(hit, _)| hit)
    }

    /// The emission of the first surface a primary ray stops at (times its opacity, as
    /// `trace` weighs it): one ray, no shading. What `primary_without_first_emission` leaves out.
    pub fn first_emission(&self, origin: Vec3, dir: Vec3, counts: &mut Work<'_>) -> Vec3 {
        counts.primary += 1;
        let mut origin = origin;
        for pass in 0..MAX_MASKED_PASSES {
            if pass > 0 {
                counts.continued += 1;
            }
            let Some(hit) = self.tracer.intersect(self.scene, origin, dir, Coherence::Coherent) else {
                return Vec3::ZERO;
            };
            let material = &self.scene.materials[hit.material as usize];
            if !material.is_emissive() && !material.may_be_transparent() {
                return Vec3::ZERO;
            }
            let surface = material.at(hit.uv, &self.scene.textures);
            if surface.opacity <= 0.0 {
                origin = self.tracer.spawn_point(&hit, dir);
                continue;
            }
            let front = hit.geometric_normal.dot(-dir) > 0.0;
            let emission = if material.is_emissive() && front {
                material.emission * surface.opacity
            } else {
                Vec3::ZERO
            };
            return if emission.is_finite() { emission } else { Vec3::ZERO };
        }
        Vec3::ZERO
    }

    /// The components along a ray, and how far it went to the first surface that stopped it
    /// (infinite when it left the scene).
    fn trace(
        &self,
        origin: Vec3,
        dir: Vec3,
        state: PathState,
        coherence: Coherence,
        rng: &mut Rng,
        counts: &mut Work<'_>,
    ) -> (Components, f32) {
        let Some((hit, surface)) = self.first_surface(origin, dir, coherence, state.spread, counts) else {
            return (Components::default(), f32::INFINITY);
        };
        if state.level == 0 && state.specular_depth == 0 {
            // The camera ray's own first hit.
            counts.data.first = Some(hit);
        }
        self.light_from(origin, dir, (&hit, &surface), state, GridRead::Unread, rng, counts)
    }

    /// The light that leaves the first surface `found` along -`dir` towards `origin`, and the
    /// distance to it: `trace`'s work after the ray found its surface.
    #[allow(clippy::too_many_arguments)]
    fn light_from(
        &self,
        origin: Vec3,
        dir: Vec3,
        (hit, surface): (&SurfaceHit, &SurfacePoint),
        state: PathState,
        grid: GridRead,
        rng: &mut Rng,
        counts: &mut Work<'_>,
    ) -> (Components, f32) {
        let mut c = self.shade(hit, dir, surface, state, grid, rng, counts) * surface.opacity;
        if surface.opacity < 1.0 {
            c.specular += self.transmit(hit, dir, 1.0 - surface.opacity, state, rng, counts);
        }
        (c, (hit.position - origin).length())
    }

    /// Light behind a partly transparent surface: a specular transmission with jT = 1 - opacity.
    ///
    /// Off the eye path (a record's hemisphere rays and the paths below them) the ray goes on
    /// with probability jT and then brings all the light behind (Russian roulette: the same
    /// mean, jT times it). Hundreds of such hits average into a record, and a ray that goes
    /// on pays a surface, its shading and often a path (Sibenik's red windows, jT 0.2: the
    /// wall outside, which no grid cell covers). Measured at Sibenik's two views (eight seeds,
    /// against the peers bench's references, `-aa 0.2 -ad 128 --spp 8` and `-aa 0.1 -ad 512
    /// --spp 16`): 0.98x the CPU time, relMSE and 4x4 relMSE 0.996-1.02x (within their noise);
    /// on `bench/ray_rate.py`'s render 0.967x the time (4 pairs). On the eye path the
    /// transmission is always traced: a pixel's few samples would show the roulette's noise.
    fn transmit(
        &self,
        hit: &SurfaceHit,
        dir: Vec3,
        jt: f32,
        state: PathState,
        rng: &mut Rng,
        counts: &mut Work<'_>,
    ) -> Vec3 {
        if state.specular_depth >= self.options.max_specular_depth || state.weight * jt < self.options.min_weight {
            return Vec3::ZERO;
        }
        // What a ray that goes on brings is the light behind times this.
        let gain = if state.level > 0 {
            if rng.next_f32() >= jt {
                return Vec3::ZERO;
            }
            1.0
        } else {
            jt
        };
        counts.specular += 1;
        // Seeing an emitter through a transparent surface is seeing it straight: counted where
        // the path would count it anyway (direct lighting's shadow rays pass the same surface).
        let next = PathState {
            specular_depth: state.specular_depth + 1,
            weight: state.weight * jt,
            throughput: state.throughput * jt,
            ..state
        };
        let origin = self.tracer.spawn_point(hit, dir);
        self.trace(origin, dir, next, Coherence::Incoherent, rng, counts)
            .0
            .total()
            * gain
    }

    #[allow(clippy::too_many_arguments)]
    fn shade(
        &self,
        hit: &SurfaceHit,
        dir: Vec3,
        surface: &crate::scene::material::SurfacePoint,
        state: PathState,
        grid: GridRead,
        rng: &mut Rng,
        counts: &mut Work<'_>,
    ) -> Components {
        let material = &self.scene.materials[hit.material as usize];
        let wo = -dir;
        let mut c = Components::default();
        if state.albedo_chain && state.level == 0 && !is_mirror(surface) {
            // Seen through the chain's mirrors and transparencies, weighed as the light is.
            let reflectance = (surface.diffuse + surface.specular).min(Vec3::ONE);
            counts.data.albedo += state.throughput * surface.opacity * reflectance;
        }
        // Emitters shine from their front side only.
        let seen_first = state.first_emission_elsewhere && state.level == 0 && state.specular_depth == 0;
        if state.count_emission && !seen_first && material.is_emissive() && hit.geometric_normal.dot(wo) > 0.0 {
            c.emission = material.emission;
        }
        let has_diffuse = surface.diffuse.max_element() > 0.0;
        let has_specular = surface.specular.max_element() > 0.0;
        // At the grid's level the diffuse part reads the light the surface receives, direct
        // and indirect, from the grid (`irradiance::last_bounce`): no light pick, no shadow
        // ray, no further path.
        let grid = match grid {
            GridRead::Read(received) => received,
            GridRead::Unread => self.last_bounce_received(hit, surface, state),
        };
        if let Some(grid) = grid {
            c.direct = surface.diffuse * grid.direct;
            if has_specular && !self.scene.punctual_lights.is_empty() {
                // The glossy lobe's highlights of punctual lights: nothing else finds them.
                let glossy = SurfacePoint {
                    diffuse: Vec3::ZERO,
                    ..*surface
                };
                let strata = LightStrata::alone(1, rng);
                c.direct += direct::direct_light(self, hit, wo, &glossy, strata, rng, counts).total();
            }
        } else if has_diffuse || (has_specular && !self.scene.punctual_lights.is_empty()) {
            let strata = if state.level > 0 {
                LightStrata::alone(1, rng)
            } else {
                let count = self.options.light_samples.max(1);
                if counts.sample.index < counts.sample.pixel_samples {
                    // Stratified with the shadow rays of the pixel's other samples.
                    LightStrata {
                        first: counts.sample.index * count,
                        count,
                        total: counts.sample.pixel_samples * count,
                        offset: counts.sample.light_offset,
                        cell_offset: counts.sample.light_cell_offset,
                        eye_path: true,
                    }
                } else {
                    LightStrata {
                        eye_path: true,
                        ..LightStrata::alone(count, rng)
                    }
                }
            };
            let light = direct::direct_light(self, hit, wo, surface, strata, rng, counts);
            // The camera ray's own hit in a pixel's sample: its ratio estimate's parts go to the
            // pixel's pool (`render_pixel` adds the pooled estimate; `direct::ShadowRatio`).
            let pooled =
                state.level == 0 && state.specular_depth == 0 && counts.sample.index < counts.sample.pixel_samples;
            if pooled {
                counts.sample_exact_direct += light.exact * surface.opacity;
                counts.sample_sampled_noise += light.sampled_noise * surface.opacity * surface.opacity;
            }
            c.direct = match light.ratio {
                Some(parts) if pooled => {
                    if parts.is_finite() {
                        counts.pixel_shadow_ratio += parts.scaled(surface.opacity);
                    } else {
                        counts.nonfinite += 1;
                    }
                    light.sampled
                }
                _ => light.total(),
            };
        }
        if has_specular {
            c.specular = self.specular(hit, wo, surface, state, rng, counts);
        }
        if let Some(grid) = grid {
            c.indirect = surface.diffuse * grid.indirect;
        } else if has_diffuse {
            c.indirect = match self.defer {
                // After a prepass the PR's cache is complete: a gap's record is made here, from
                // the pixel's own random stream, as every other mode makes it.
                Some(sink) if state.level == 0 && state.level < self.options.ambient_bounces && !self.frozen => {
                    self.cached_or_requested(sink, hit, dir, surface, state, counts)
                }
                // A pixel shaded in two steps (`deferred`): the point is looked up once the
                // eye path is traced.
                _ if state.level == 0 && state.level < self.options.ambient_bounces && self.cache.is_some() => {
                    match counts.deferred_indirect.as_mut() {
                        Some(later) => {
                            let coefficient = state.throughput * surface.opacity * surface.diffuse;
                            later.push(deferred::DeferredIndirect::new(*hit, state, coefficient));
                            Vec3::ZERO
                        }
                        None => surface.diffuse * self.ambient_radiance(hit, state, rng, counts),
                    }
                }
                _ => surface.diffuse * self.ambient_radiance(hit, state, rng, counts),
            };
        }
        sanitize(c, counts)
    }

    /// L_s: one mirror or glossy ray, weighted by jT = reflectance x lobe weight.
    fn specular(
        &self,
        hit: &SurfaceHit,
        wo: Vec3,
        surface: &crate::scene::material::SurfacePoint,
        state: PathState,
        rng: &mut Rng,
        counts: &mut Work<'_>,
    ) -> Vec3 {
        if state.specular_depth >= self.options.max_specular_depth {
            return Vec3::ZERO;
        }
        let (u1, u2) = (rng.next_f32(), rng.next_f32());
        let Some((wi, lobe)) = glossy::sample(hit.normal, wo, surface.alpha, u1, u2) else {
            return Vec3::ZERO;
        };
        // A reflected direction below the true surface would start inside the object.
        if wi.dot(hit.facing_normal) <= 0.0 {
            return Vec3::ZERO;
        }
        let jt = surface.specular * lobe;
        let weight = state.weight * jt.max_element();
        if weight < self.options.min_weight {
            return Vec3::ZERO;
        }
        counts.specular += 1;
        // Emitters seen in a mirror count on eye paths. After a diffuse bounce they do not: such
        // caustic paths (diffuse -> mirror -> light) are what make indirect diffuse values noisy
        // and cached records blotchy, and Radiance leaves them out of its ambient calculation
        // as well.
        let next = PathState {
            specular_depth: state.specular_depth + 1,
            weight,
            count_emission: state.level == 0,
            throughput: state.throughput * surface.opacity * jt,
            // The albedo layer follows perfect mirrors only (a glossy surface is its end).
            albedo_chain: state.albedo_chain && is_mirror(surface),
            ..state
        };
        let origin = self.tracer.spawn_point(hit, wi);
        jt * self
            .trace(origin, wi, next, Coherence::Incoherent, rng, counts)
            .0
            .total()
    }
}

/// A perfect mirror: no diffuse part, and a specular lobe (if any) of zero roughness. The
/// albedo layer looks past such a surface to what it reflects.
fn is_mirror(surface: &crate::scene::material::SurfacePoint) -> bool {
    surface.diffuse.max_element() <= 0.0 && surface.specular.max_element() > 0.0 && surface.alpha <= 0.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hit_at(distance: f32, uv_per_length: f32) -> SurfaceHit {
        SurfaceHit {
            uv: Some([0.5, 0.5]),
            uv_per_length,
            ..SurfaceHit::on_floor(Vec3::ZERO, distance, 0)
        }
    }

    #[test]
    fn a_cell_ray_spreads_by_the_side_of_its_cell() {
        // n x n cells of 2 pi / n^2 steradians each: the side's square is the cell's solid angle.
        for n in [1, 4, 16, 23] {
            let side = cell_spread(n);
            assert!((side * side * (n * n) as f32 - 2.0 * std::f32::consts::PI).abs() < 1e-4);
        }
    }

    #[test]
    fn a_footprint_grows_with_distance_and_slant_and_is_nothing_for_a_thin_ray() {
        let straight = -Vec3::Y;
        // 0.1 rad at 2 units: 0.2 units wide, 3 texture units a unit: 0.6.
        assert!((texture_footprint(&hit_at(2.0, 3.0), straight, 0.1) - 0.6).abs() < 1e-6);
        // At 60 degrees from the normal the ellipse is twice as long: sqrt(2) wider as a square.
        let slanted = Vec3::new(3f32.sqrt() / 2.0, -0.5, 0.0);
        let wide = texture_footprint(&hit_at(2.0, 3.0), slanted, 0.1);
        assert!((wide - 0.6 * 2f32.sqrt()).abs() < 1e-5, "{wide}");
        // A ray that stands for itself, or a surface without texture coordinates: a point.
        assert_eq!(texture_footprint(&hit_at(2.0, 3.0), straight, 0.0), 0.0);
        assert_eq!(texture_footprint(&hit_at(2.0, 0.0), straight, 0.1), 0.0);
        // Grazing: bounded.
        let grazing = texture_footprint(&hit_at(2.0, 3.0), Vec3::X, 0.1);
        assert!(grazing.is_finite() && grazing > 0.6);
    }
}

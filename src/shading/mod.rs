//! Shading by components (Radiance style): at every point a path reaches, emission L_e,
//! direct light L_d from the light sources, specular L_s by mirror and glossy rays carrying the
//! rippled coefficient jT (paper, eq. 1), and indirect diffuse L_a by sampling the hemisphere.
//!
//! Light is counted once: direct lighting samples every emitter, so rays gathering indirect
//! diffuse light do not count the emission they hit; specular rays do, since the direct
//! component leaves the specular lobe's view of area emitters to them.

pub mod direct;
pub mod glossy;
mod hemisphere_batch;
pub mod last_bounce;
pub mod pixel_irradiance;
pub mod request;

use crate::image::components::Components;
use crate::image::framebuffer::Layer;
use crate::irradiance::IrradianceCache;
use crate::irradiance::hemisphere::{CellSample, Frame, Hemisphere, cell_direction};
use crate::irradiance::last_bounce::Received;
use crate::irradiance::record::Record;
use crate::sampling::{Rng, basis, cosine_hemisphere, grid_side};
use crate::scene::Scene;
use crate::scene::material::SurfacePoint;
use crate::sys::embree::Coherence;
use crate::tracer::{SurfaceHit, Tracer};
use direct::LightStrata;
use glam::Vec3;
use pixel_irradiance::{PixelIrradiance, on_plane};
use request::{AmbientRequest, RequestBuffer};
use std::time::Instant;

/// The options that decide how each component is computed (Radiance names where they exist).
#[derive(Clone, Debug)]
pub struct ShadingOptions {
    /// -ab: diffuse bounces.
    pub ambient_bounces: u32,
    /// -ad: hemisphere samples at the first diffuse bounce.
    pub ambient_divisions: u32,
    /// -av: radiance assumed past the last bounce.
    pub ambient_value: Vec3,
    /// -lr: longest specular path.
    pub max_specular_depth: u32,
    /// -lw: a specular path stops when its weight jT falls below this.
    pub min_weight: f32,
    /// Shadow rays to area emitters per shading point on the eye path.
    pub light_samples: u32,
    /// Area lights' unshadowed irradiance computed exactly (Lambert's formula) and the shadow
    /// rays used only for the share that gets through; false: plain sampling (unbiased, for
    /// references).
    pub analytic_direct: bool,
    /// Past a record's bounce (-ab 2 and more), each hemisphere ray continues as one path
    /// instead of looking up records of deeper levels (`--ic-deep paths`).
    pub deep_paths: bool,
    /// Those paths' last bounce reads the last bounce's grid where it has a mean
    /// (`--ic-deep grid`; `irradiance::last_bounce`).
    pub last_bounce_grid: bool,
}

impl Default for ShadingOptions {
    fn default() -> Self {
        ShadingOptions {
            ambient_bounces: 1,
            ambient_divisions: 512,
            ambient_value: Vec3::ZERO,
            max_specular_depth: 8,
            min_weight: 1e-3,
            light_samples: 1,
            analytic_direct: true,
            deep_paths: true,
            last_bounce_grid: false,
        }
    }
}

/// What one thread did: rays by purpose, irradiance cache traffic, time in L_a. Summed at the
/// end.
#[derive(Clone, Copy, Debug, Default)]
pub struct RayCounts {
    pub primary: u64,
    pub shadow: u64,
    pub specular: u64,
    pub ambient: u64,
    /// Rays traced on past a surface the ray passed through (alpha-masked points, the
    /// see-through surfaces a shadow ray walks): each an Embree query of its own, counted apart
    /// from the ray it continues (which counts once as its kind).
    pub continued: u64,
    /// Contributions that came out NaN or infinite and were dropped (should stay 0).
    pub nonfinite: u64,
    /// Cache lookups, and those answered by existing records.
    pub lookups: u64,
    pub hits: u64,
    /// New records computed (cache misses).
    pub records_computed: u64,
    /// New records that another thread's record, made meanwhile, would have made unneeded.
    pub duplicates: u64,
    /// Records computed at level 0 (for the ic_records debug layer).
    pub records_level0: u64,
    /// Level-0 records a pixel had to make after the prepass (a gap it left: surfaces seen
    /// only through mirrors or glass), used for that pixel alone.
    pub gap_records: u64,
    /// Pixels an edge crosses that took `--edge-samples` (`render::edges`).
    pub edge_pixels: u64,
    /// Seconds spent computing L_a (lookups and new records), the paper's T_amb.
    pub t_amb: f64,
    /// Indirect diffuse values left to a PA as requests (component mode's PRs).
    pub deferred: u64,
    /// Nesting of ambient computations, so T_amb counts only the outermost.
    ambient_depth: u32,
}

/// What the sample being rendered is (kept apart from the statistics): its pixel and index,
/// its share of the pixel (what a deferred request needs to find its way back), and the pixel's
/// sample count and random offsets for stratifying the shadow rays of all its samples together
/// (see `direct::LightStrata`; 0 samples: each point on its own).
#[derive(Clone, Copy, Debug, Default)]
pub struct SampleContext {
    pub pixel: u32,
    pub index: u32,
    pub weight: f32,
    pub pixel_samples: u32,
    pub light_offset: u32,
    pub light_cell_offset: u32,
    /// The camera ray through the pixel's centre (origin, direction), where the pixel's
    /// samples share the cache's irradiance (`PixelIrradiance`); None: each looks up its own.
    pub centre_ray: Option<(Vec3, Vec3)>,
    /// How wide the camera ray's footprint grows per unit of distance (`PathState::spread`):
    /// its share of the pixel (`Camera::sample_spread`); 0: textures read at the point.
    pub eye_spread: f32,
}

/// What a camera sample's own rays found for the data layers (`image::data`), noted as the
/// integrator traces them (no ray is traced for it): the first surface hit, and the
/// reflectance seen along the eye path's mirror and transparency chain.
#[derive(Clone, Copy, Debug, Default)]
pub struct SampleData {
    pub first: Option<SurfaceHit>,
    pub albedo: Vec3,
}

/// A thread's work on one sample: the statistics it adds to, the sample's context and what its
/// rays found for the data layers. It reads as the statistics (`Deref`), which every shading
/// function adds to.
pub struct Work<'a> {
    pub counts: &'a mut RayCounts,
    pub sample: SampleContext,
    pub data: SampleData,
    /// The ratio estimates' parts of the direct light at the pixel's camera-ray hits, pooled
    /// over its samples (`direct::ShadowRatio`), scaled by the hits' opacity.
    pub pixel_shadow_ratio: direct::ShadowRatio,
    /// The direct light at the sample's camera-ray hit that is exact at its point (punctual
    /// lights each traced: `direct::DirectLight::exact`), scaled by the hit's opacity: the
    /// pixel's noise leaves it out (`render::noise`).
    pub sample_exact_direct: Vec3,
    /// The variance its rays measured of the plainly sampled emitters' light at the sample's
    /// camera-ray hit (`direct::DirectLight::sampled_noise`), scaled by the hit's opacity
    /// squared: with one sample a pixel, what its noise is known by (`render::noise`).
    pub sample_sampled_noise: f32,
    /// The cache's irradiance at the pixel's centre on the surface its samples last looked up,
    /// for its other samples there (`pixel_irradiance`).
    pub pixel_irradiance: Option<PixelIrradiance>,
}

impl<'a> Work<'a> {
    pub fn new(counts: &'a mut RayCounts) -> Self {
        Work {
            counts,
            sample: SampleContext::default(),
            data: SampleData::default(),
            pixel_shadow_ratio: direct::ShadowRatio::default(),
            sample_exact_direct: Vec3::ZERO,
            sample_sampled_noise: 0.0,
            pixel_irradiance: None,
        }
    }
}

impl std::ops::Deref for Work<'_> {
    type Target = RayCounts;
    fn deref(&self) -> &RayCounts {
        self.counts
    }
}

impl std::ops::DerefMut for Work<'_> {
    fn deref_mut(&mut self) -> &mut RayCounts {
        self.counts
    }
}

impl RayCounts {
    pub fn add(&mut self, o: &RayCounts) {
        self.primary += o.primary;
        self.shadow += o.shadow;
        self.specular += o.specular;
        self.ambient += o.ambient;
        self.continued += o.continued;
        self.nonfinite += o.nonfinite;
        self.lookups += o.lookups;
        self.hits += o.hits;
        self.records_computed += o.records_computed;
        self.duplicates += o.duplicates;
        self.records_level0 += o.records_level0;
        self.gap_records += o.gap_records;
        self.edge_pixels += o.edge_pixels;
        self.t_amb += o.t_amb;
        self.deferred += o.deferred;
    }
    pub fn total(&self) -> u64 {
        self.primary + self.shadow + self.specular + self.ambient + self.continued
    }
}

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

    /// A PR's L_a: the local cache's value if it has one; otherwise a request for a PA, and
    /// nothing in the pixel for now (the PA adds it to its own image, which is summed in).
    fn cached_or_requested(
        &self,
        sink: &RequestBuffer,
        hit: &SurfaceHit,
        dir: Vec3,
        surface: &crate::scene::material::SurfacePoint,
        state: PathState,
        counts: &mut Work<'_>,
    ) -> Vec3 {
        if let Some(cache) = self.cache {
            let headroom = self.headroom(cache, hit, counts);
            if let Some(value) = self.cached_value(cache, hit, headroom, state, counts) {
                return surface.diffuse * value;
            }
        } else {
            counts.lookups += 1;
        }
        let layer = if state.specular_depth == 0 {
            Layer::Indirect
        } else {
            Layer::Specular
        };
        let request = AmbientRequest {
            pixel: counts.sample.pixel,
            layer,
            specular_depth: state.specular_depth,
            position: hit.position,
            geometric_normal: hit.geometric_normal,
            normal: hit.normal,
            facing_normal: hit.facing_normal,
            coefficient: state.throughput * surface.opacity * surface.diffuse * counts.sample.weight,
            weight: state.weight,
            direction: dir,
            material: hit.material,
            stream: (counts.sample.pixel as u64) << 32
                | (counts.sample.index as u64) << 16
                | (counts.deferred & 0xffff),
            // Shared only at a primary hit (see `pixel_shared`).
            centre_ray: counts.sample.centre_ray.filter(|_| state.specular_depth == 0),
            distance: hit.distance,
        };
        counts.deferred += 1;
        sink.push(request);
        Vec3::ZERO
    }

    /// Computes a PA's request: the indirect diffuse value (irradiance over pi) at the point,
    /// through this process's cache, before the request's coefficient.
    pub fn ambient_for_request(&self, request: &AmbientRequest, rng: &mut Rng, counts: &mut Work<'_>) -> Vec3 {
        let hit = SurfaceHit {
            position: request.position,
            distance: request.distance,
            geometric_normal: request.geometric_normal,
            normal: request.normal,
            facing_normal: request.facing_normal,
            uv: None,
            uv_per_length: 0.0,
            material: request.material,
            object: 0,
            prim_id: 0,
        };
        let state = PathState {
            level: 0,
            specular_depth: request.specular_depth,
            weight: request.weight,
            count_emission: false,
            first_emission_elsewhere: false,
            throughput: Vec3::ONE,
            albedo_chain: false,
            spread: 0.0,
        };
        self.ambient_radiance(&hit, state, rng, counts)
    }

    /// Irradiance / pi arriving at a diffuse point from other surfaces (the part of L_a before
    /// the albedo); -av past the last bounce. Timed as T_amb at the outermost call.
    fn ambient_radiance(&self, hit: &SurfaceHit, state: PathState, rng: &mut Rng, counts: &mut Work<'_>) -> Vec3 {
        if state.level >= self.options.ambient_bounces {
            return self.options.ambient_value;
        }
        timed_ambient(counts, |counts| match self.cache {
            Some(cache) if state.level == 0 || !self.options.deep_paths => {
                self.cached_ambient(cache, hit, state, rng, counts)
            }
            _ => self.brute_force_ambient(hit, state, rng, counts),
        })
    }

    /// Brute force (-aa 0): -ad stratified cosine-weighted samples at the first bounce, one per
    /// further bounce (an unbiased path continuation).
    fn brute_force_ambient(&self, hit: &SurfaceHit, state: PathState, rng: &mut Rng, counts: &mut Work<'_>) -> Vec3 {
        // Each ray samples a point, textures included: brute force is the reference the
        // records (whose rays read textures averaged over their cells) are measured against.
        let next = PathState {
            level: state.level + 1,
            count_emission: false,
            spread: 0.0,
            ..state
        };
        let (side, count) = if state.level == 0 {
            let side = grid_side(self.options.ambient_divisions.max(1));
            (side, side * side)
        } else {
            (1, 1)
        };
        let mut sum = Vec3::ZERO;
        for cell in 0..count {
            let (i, j) = (cell % side, cell / side);
            let u1 = (i as f32 + rng.next_f32()) / side as f32;
            let u2 = (j as f32 + rng.next_f32()) / side as f32;
            let wi = cosine_hemisphere(hit.normal, u1, u2);
            if wi.dot(hit.facing_normal) <= 0.0 {
                continue;
            }
            counts.ambient += 1;
            let origin = self.tracer.spawn_point(hit, wi);
            sum += self
                .trace(origin, wi, next, Coherence::Incoherent, rng, counts)
                .0
                .total();
        }
        sum / count as f32
    }

    /// L_a through the cache: existing records if any may be used here, else a new record.
    fn cached_ambient(
        &self,
        cache: &IrradianceCache,
        hit: &SurfaceHit,
        state: PathState,
        rng: &mut Rng,
        counts: &mut Work<'_>,
    ) -> Vec3 {
        let headroom = self.headroom(cache, hit, counts);
        if let Some(value) = self.cached_value(cache, hit, headroom, state, counts) {
            if cache.tracing() {
                // The record a miss here would make (for the trace only: its own random stream
                // and counters, so the render and its statistics stay as without the trace).
                let mut rng = Rng::new(!u64::from(counts.sample.pixel), counts.lookups);
                let shadow =
                    self.compute_record(cache, hit, state, &mut rng, &mut Work::new(&mut RayCounts::default()));
                cache.trace(counts.sample.pixel, state.level, true, &shadow);
            }
            return value;
        }
        let record = self.compute_record(cache, hit, state, rng, counts);
        cache.trace(counts.sample.pixel, state.level, false, &record);
        counts.records_computed += 1;
        if state.level == 0 {
            counts.records_level0 += 1;
        }
        if self.frozen {
            counts.gap_records += 1;
            return record.value;
        }
        // Another thread may have covered this point while we sampled: the work was done twice.
        if cache.lookup(hit.position, hit.normal, headroom, state.level).is_some() {
            counts.duplicates += 1;
        }
        let value = record.value;
        cache.insert(record);
        value
    }

    /// The cache's value at a hit with its `headroom`: the one the pixel's samples share
    /// (`pixel_shared`), else the records' about the hit; None when no record may be used.
    /// Counted as a lookup either way, and as a hit when answered.
    fn cached_value(
        &self,
        cache: &IrradianceCache,
        hit: &SurfaceHit,
        headroom: f32,
        state: PathState,
        counts: &mut Work<'_>,
    ) -> Option<Vec3> {
        if let Some(value) = self.pixel_shared(cache, hit, headroom, state, counts) {
            return Some(value);
        }
        counts.lookups += 1;
        let value = cache.lookup(hit.position, hit.normal, headroom, state.level)?;
        counts.hits += 1;
        Some(value)
    }

    /// The irradiance the pixel's samples share on this surface (`pixel_irradiance`), if this
    /// is a camera ray's hit near enough to the pixel's centre on it; looked up there for the
    /// pixel's first sample on the surface. None: the hit looks up its own.
    fn pixel_shared(
        &self,
        cache: &IrradianceCache,
        hit: &SurfaceHit,
        headroom: f32,
        state: PathState,
        counts: &mut Work<'_>,
    ) -> Option<Vec3> {
        // The cache's trace shows each lookup's would-be record: no sharing under it.
        if state.level > 0 || state.specular_depth > 0 || cache.tracing() {
            return None;
        }
        let shared = match counts.pixel_irradiance {
            Some(shared) if shared.covers(hit, headroom) => shared,
            // The centre's value on this surface is known, and too far from this sample.
            Some(shared) if shared.same_surface(hit, headroom) => return None,
            _ => {
                let centre = counts.sample.centre_ray.and_then(|ray| on_plane(ray, hit))?;
                let (value, scale) = cache.lookup_with_scale(centre, hit.normal, headroom, state.level)?;
                let shared = PixelIrradiance::new(centre, hit, headroom, value, scale);
                counts.pixel_irradiance = Some(shared);
                if !shared.covers(hit, headroom) {
                    return None;
                }
                shared
            }
        };
        // Counted as one lookup that hit when a sample first takes it: a lookup either hits
        // or makes a record, and the centre's value taken by no sample is neither.
        if !shared.taken() {
            counts.lookups += 1;
            counts.hits += 1;
            counts.pixel_irradiance = Some(shared.mark_taken());
        }
        Some(shared.value())
    }

    /// Samples the hemisphere over an n x n cosine-weighted grid (n from -ad and the level's
    /// weight), adds -as samples where neighbouring cells differ most, and makes a record.
    pub fn compute_record(
        &self,
        cache: &IrradianceCache,
        hit: &SurfaceHit,
        state: PathState,
        rng: &mut Rng,
        counts: &mut Work<'_>,
    ) -> Record {
        let n = cache.settings.grid_side(state.level);
        let normal = hit.normal;
        let (tangent, bitangent) = basis(normal);
        let next = PathState {
            level: state.level + 1,
            count_emission: false,
            spread: cell_spread(n),
            ..state
        };
        let sample = |i: usize, j: usize, rng: &mut Rng, counts: &mut Work<'_>| {
            let frame = Frame {
                normal,
                tangent,
                bitangent,
            };
            let wi = cell_direction(frame, n, (i, j), (rng.next_f32(), rng.next_f32()));
            if wi.dot(hit.facing_normal) <= 0.0 {
                // Below the true surface (a bent shading normal): nothing arrives from there.
                return CellSample {
                    radiance: Vec3::ZERO,
                    distance: f32::INFINITY,
                    direction: wi,
                };
            }
            counts.ambient += 1;
            let origin = self.tracer.spawn_point(hit, wi);
            let (c, distance) = self.trace(origin, wi, next, Coherence::Incoherent, rng, counts);
            let floor = self.tracer.epsilon_at(hit.position);
            CellSample {
                radiance: c.total(),
                distance: distance.max(floor),
                direction: wi,
            }
        };
        // Where the hits read the last bounce's grid, the rays go as one batch
        // (`hemisphere_batch`); elsewhere (no grid: `--ic-deep paths`, or not the grid's
        // level) each ray's path is followed as it is traced.
        let has_grid = self.cache.and_then(|c| c.last_bounce()).is_some();
        let batched = has_grid && Some(next.level) == self.last_bounce_level();
        let frame = Frame {
            normal,
            tangent,
            bitangent,
        };
        let sample_cells = |cells: &[(usize, usize)], rng: &mut Rng, counts: &mut Work<'_>| {
            if batched {
                self.grid_level_samples(hit, frame, n, cells, next, rng, counts)
            } else {
                cells.iter().map(|&(i, j)| sample(i, j, rng, counts)).collect()
            }
        };
        let every_cell: Vec<_> = (0..n).flat_map(|i| (0..n).map(move |j| (i, j))).collect();
        let cells = sample_cells(&every_cell, rng, counts);
        let mut hemisphere = Hemisphere {
            n,
            normal,
            tangent,
            bitangent,
            cells,
        };
        let extra = cache.settings.extra_samples(state.level);
        let supersampled = hemisphere.supersampled_cells(extra);
        let again: Vec<_> = supersampled.iter().map(|&cell| (cell / n, cell % n)).collect();
        for (cell, s) in supersampled.into_iter().zip(sample_cells(&again, rng, counts)) {
            let c = &mut hemisphere.cells[cell];
            c.radiance = (c.radiance + s.radiance) * 0.5;
            c.distance = c.distance.min(s.distance);
        }
        let headroom = self.headroom(cache, hit, counts);
        cache.make_record(&hemisphere, hit.position, headroom, state.level)
    }

    /// How far the surface at `hit` is free along its normal (`Record::headroom`): one ray,
    /// traced for every lookup and record, as the cache compares the two.
    pub fn headroom(&self, cache: &IrradianceCache, hit: &SurfaceHit, counts: &mut Work<'_>) -> f32 {
        let up = if hit.normal.dot(hit.facing_normal) > 0.0 {
            hit.normal
        } else {
            hit.facing_normal
        };
        counts.ambient += 1;
        let cap = cache.settings.headroom_cap;
        let origin = self.tracer.spawn_point(hit, up);
        let floor = self.tracer.epsilon_at(hit.position);
        self.tracer
            .hit_distance(origin, up)
            .map_or(cap, |t| t.min(cap))
            .max(floor)
    }
}

/// A perfect mirror: no diffuse part, and a specular lobe (if any) of zero roughness. The
/// albedo layer looks past such a surface to what it reflects.
fn is_mirror(surface: &crate::scene::material::SurfacePoint) -> bool {
    surface.diffuse.max_element() <= 0.0 && surface.specular.max_element() > 0.0 && surface.alpha <= 0.0
}

/// Runs indirect diffuse work, timing it as T_amb when it is the outermost (work nested in it,
/// deeper bounces, is inside that time already).
fn timed_ambient<'w, T>(counts: &mut Work<'w>, work: impl FnOnce(&mut Work<'w>) -> T) -> T {
    let start = (counts.ambient_depth == 0).then(Instant::now);
    counts.ambient_depth += 1;
    let out = work(counts);
    counts.ambient_depth -= 1;
    if let Some(start) = start {
        counts.t_amb += start.elapsed().as_secs_f64();
    }
    out
}

/// Drops (and counts) a component that is not a finite, non-negative colour, so no NaN or Inf
/// can reach the image whatever the scene's numbers.
fn sanitize(c: Components, counts: &mut RayCounts) -> Components {
    let fix = |v: Vec3, counts: &mut RayCounts| {
        if v.is_finite() {
            v.max(Vec3::ZERO)
        } else {
            counts.nonfinite += 1;
            Vec3::ZERO
        }
    };
    Components {
        emission: fix(c.emission, counts),
        direct: fix(c.direct, counts),
        specular: fix(c.specular, counts),
        indirect: fix(c.indirect, counts),
    }
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

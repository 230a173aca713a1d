//! A thread's bookkeeping as it shades one sample: its ray and cache statistics (summed over
//! threads at the end), what the sample is, what its rays found for the data layers and the
//! pixel's noise, and the guards every component passes (T_amb's clock, no NaN in the image).

use super::deferred::DeferredIndirect;
use super::direct;
use super::pixel_irradiance::PixelIrradiance;
use crate::image::components::Components;
use crate::tracer::SurfaceHit;
use glam::Vec3;
use std::time::Instant;

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
    /// Where the sample's eye path asks for indirect diffuse light, when it is looked up after
    /// the path is traced (`deferred`); None: looked up as the path reaches it.
    pub deferred_indirect: Option<Vec<DeferredIndirect>>,
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
            deferred_indirect: None,
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

/// Runs indirect diffuse work, timing it as T_amb when it is the outermost (work nested in it,
/// deeper bounces, is inside that time already).
pub(super) fn timed_ambient<'w, T>(counts: &mut Work<'w>, work: impl FnOnce(&mut Work<'w>) -> T) -> T {
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
pub(super) fn sanitize(c: Components, counts: &mut RayCounts) -> Components {
    Components {
        emission: sanitize_value(c.emission, counts),
        direct: sanitize_value(c.direct, counts),
        specular: sanitize_value(c.specular, counts),
        indirect: sanitize_value(c.indirect, counts),
    }
}

/// One colour as `sanitize` leaves it.
pub(super) fn sanitize_value(v: Vec3, counts: &mut RayCounts) -> Vec3 {
    if v.is_finite() {
        v.max(Vec3::ZERO)
    } else {
        counts.nonfinite += 1;
        Vec3::ZERO
    }
}

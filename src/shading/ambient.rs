//! The integrator's indirect diffuse light, L_a: read from the irradiance cache (one lookup a
//! pixel where its samples share a surface), computed as a new record where none covers the
//! point, left to a PA as a request in component mode, or sampled by brute force without the
//! cache. The rest of the path (emission, direct light, specular paths) is `super`'s.

use super::pixel_irradiance::{PixelIrradiance, on_plane};
use super::request::{AmbientRequest, RequestBuffer};
use super::work::timed_ambient;
use super::{Integrator, PathState, RayCounts, Work, cell_spread};
use crate::image::framebuffer::Layer;
use crate::irradiance::IrradianceCache;
use crate::irradiance::hemisphere::{CellSample, Frame, Hemisphere, cell_direction};
use crate::irradiance::record::Record;
use crate::sampling::{Rng, basis, cosine_hemisphere, grid_side};
use crate::sys::embree::Coherence;
use crate::tracer::SurfaceHit;
use glam::Vec3;

/// The cache's value at a held-out pixel's first surface beside two fresh records' values
/// (`Integrator::holdout`), and the surface's diffuse colour that turns them into light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Holdout {
    pub diffuse: Vec3,
    pub cached: Vec3,
    pub fresh: [Vec3; 2],
}

impl Integrator<'_> {
    /// A PR's L_a: the local cache's value if it has one; otherwise a request for a PA, and
    /// nothing in the pixel for now (the PA adds it to its own image, which is summed in).
    pub(super) fn cached_or_requested(
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
    pub(super) fn ambient_radiance(
        &self,
        hit: &SurfaceHit,
        state: PathState,
        rng: &mut Rng,
        counts: &mut Work<'_>,
    ) -> Vec3 {
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
    pub(super) fn brute_force_ambient(
        &self,
        hit: &SurfaceHit,
        state: PathState,
        rng: &mut Rng,
        counts: &mut Work<'_>,
    ) -> Vec3 {
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
            let value = record.value;
            if self.keeps_gaps {
                cache.keep_gap(record);
            }
            return value;
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

    /// What the cache's error is measured by at a pixel held out (`render::error_estimate`):
    /// at the first diffuse surface a camera ray stops at, the surface's diffuse colour, the
    /// value the cache gives there (what the pixel read) and two fresh records' values computed
    /// there from independent hemisphere samples, as the prepass would have made them. None
    /// where the ray stops at no diffuse surface, where no record may be read (a gap), or with
    /// no cache.
    pub fn holdout(&self, origin: Vec3, dir: Vec3, rngs: [&mut Rng; 2], counts: &mut Work<'_>) -> Option<Holdout> {
        let cache = self.cache?;
        if self.options.ambient_bounces == 0 {
            return None;
        }
        let (hit, surface) = self.first_surface(origin, dir, Coherence::Coherent, 0.0, counts)?;
        if surface.diffuse.max_element() <= 0.0 || surface.opacity < 1.0 {
            return None;
        }
        let headroom = self.headroom(cache, &hit, counts);
        let cached = cache.lookup(hit.position, hit.normal, headroom, 0)?;
        let [a, b] = rngs;
        let state = PathState::eye(false);
        let mut fresh =
            |rng: &mut Rng| timed_ambient(counts, |counts| self.compute_record(cache, &hit, state, rng, counts)).value;
        let fresh = [fresh(a), fresh(b)];
        Some(Holdout {
            diffuse: surface.diffuse,
            cached,
            fresh,
        })
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

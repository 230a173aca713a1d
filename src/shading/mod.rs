//! Shading by components (Radiance style): at every point a path reaches, emission L_e,
//! direct light L_d from the light sources, specular L_s by mirror and glossy rays carrying the
//! rippled coefficient jT (paper, eq. 1), and indirect diffuse L_a by sampling the hemisphere.
//!
//! Light is counted once: direct lighting samples every emitter, so rays gathering indirect
//! diffuse light do not count the emission they hit; specular rays do, since the direct
//! component leaves the specular lobe's view of area emitters to them.

pub mod components;
pub mod direct;
pub mod glossy;

use crate::sampling::{Rng, cosine_hemisphere, grid_side};
use crate::scene::Scene;
use crate::sys::embree::Coherence;
use crate::tracer::{SurfaceHit, Tracer};
use components::Components;
use glam::Vec3;

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
        }
    }
}

/// Rays traced, by purpose; per thread, summed at the end.
#[derive(Clone, Copy, Debug, Default)]
pub struct RayCounts {
    pub primary: u64,
    pub shadow: u64,
    pub specular: u64,
    pub ambient: u64,
    /// Contributions that came out NaN or infinite and were dropped (should stay 0).
    pub nonfinite: u64,
}

impl RayCounts {
    pub fn add(&mut self, o: &RayCounts) {
        self.primary += o.primary;
        self.shadow += o.shadow;
        self.specular += o.specular;
        self.ambient += o.ambient;
        self.nonfinite += o.nonfinite;
    }
    pub fn total(&self) -> u64 {
        self.primary + self.shadow + self.specular + self.ambient
    }
}

/// Where on a path a point is: diffuse bounces so far, specular depth, and the weight jT the
/// path carries to the eye.
#[derive(Clone, Copy, Debug)]
struct PathState {
    level: u32,
    specular_depth: u32,
    weight: f32,
    /// Whether emission seen at this hit counts (not for rays gathering indirect diffuse).
    count_emission: bool,
}

pub struct Integrator<'a> {
    pub scene: &'a Scene,
    pub tracer: &'a Tracer,
    pub options: &'a ShadingOptions,
}

/// Passes through fully transparent (alpha-masked) points before a ray gives up.
const MAX_MASKED_PASSES: u32 = 64;

impl<'a> Integrator<'a> {
    pub fn new(scene: &'a Scene, tracer: &'a Tracer, options: &'a ShadingOptions) -> Self {
        Integrator {
            scene,
            tracer,
            options,
        }
    }

    /// The components of light arriving at the eye along a primary ray.
    pub fn primary(
        &self,
        origin: Vec3,
        dir: Vec3,
        rng: &mut Rng,
        counts: &mut RayCounts,
    ) -> Components {
        counts.primary += 1;
        let state = PathState {
            level: 0,
            specular_depth: 0,
            weight: 1.0,
            count_emission: true,
        };
        self.trace(origin, dir, state, Coherence::Coherent, rng, counts)
    }

    fn trace(
        &self,
        origin: Vec3,
        dir: Vec3,
        state: PathState,
        coherence: Coherence,
        rng: &mut Rng,
        counts: &mut RayCounts,
    ) -> Components {
        let mut origin = origin;
        for _ in 0..MAX_MASKED_PASSES {
            let Some(hit) = self.tracer.intersect(self.scene, origin, dir, coherence) else {
                return Components::default();
            };
            let material = &self.scene.materials[hit.material as usize];
            let surface = material.at(hit.uv, &self.scene.textures);
            if surface.opacity <= 0.0 {
                origin = self.tracer.spawn_point(&hit, dir);
                continue;
            }
            let mut c = self.shade(&hit, dir, &surface, state, rng, counts) * surface.opacity;
            if surface.opacity < 1.0 {
                c.specular += self.transmit(&hit, dir, 1.0 - surface.opacity, state, rng, counts);
            }
            return c;
        }
        Components::default()
    }

    /// Light behind a partly transparent surface: a specular transmission with jT = 1 - opacity.
    fn transmit(
        &self,
        hit: &SurfaceHit,
        dir: Vec3,
        jt: f32,
        state: PathState,
        rng: &mut Rng,
        counts: &mut RayCounts,
    ) -> Vec3 {
        if state.specular_depth >= self.options.max_specular_depth
            || state.weight * jt < self.options.min_weight
        {
            return Vec3::ZERO;
        }
        counts.specular += 1;
        let next = PathState {
            specular_depth: state.specular_depth + 1,
            weight: state.weight * jt,
            count_emission: true,
            ..state
        };
        let origin = self.tracer.spawn_point(hit, dir);
        self.trace(origin, dir, next, Coherence::Incoherent, rng, counts)
            .total()
            * jt
    }

    fn shade(
        &self,
        hit: &SurfaceHit,
        dir: Vec3,
        surface: &crate::scene::material::SurfacePoint,
        state: PathState,
        rng: &mut Rng,
        counts: &mut RayCounts,
    ) -> Components {
        let material = &self.scene.materials[hit.material as usize];
        let wo = -dir;
        let mut c = Components::default();
        // Emitters shine from their front side only.
        if state.count_emission && material.is_emissive() && hit.geometric_normal.dot(wo) > 0.0 {
            c.emission = material.emission;
        }
        let has_diffuse = surface.diffuse.max_element() > 0.0;
        let has_specular = surface.specular.max_element() > 0.0;
        if has_diffuse || (has_specular && !self.scene.punctual_lights.is_empty()) {
            let samples = if state.level == 0 {
                self.options.light_samples.max(1)
            } else {
                1
            };
            c.direct = direct::direct_light(self, hit, wo, surface, samples, rng, counts);
        }
        if has_specular {
            c.specular = self.specular(hit, wo, surface, state, rng, counts);
        }
        if has_diffuse {
            c.indirect = surface.diffuse * self.ambient_radiance(hit, state, rng, counts);
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
        counts: &mut RayCounts,
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
        let next = PathState {
            specular_depth: state.specular_depth + 1,
            weight,
            count_emission: true,
            ..state
        };
        let origin = self.tracer.spawn_point(hit, wi);
        jt * self
            .trace(origin, wi, next, Coherence::Incoherent, rng, counts)
            .total()
    }

    /// Irradiance / pi arriving at a diffuse point from other surfaces (the part of L_a before
    /// the albedo), by cosine-weighted sampling of the hemisphere: -ad stratified samples at the
    /// first bounce, one per further bounce (an unbiased path continuation), -av past the last.
    fn ambient_radiance(
        &self,
        hit: &SurfaceHit,
        state: PathState,
        rng: &mut Rng,
        counts: &mut RayCounts,
    ) -> Vec3 {
        if state.level >= self.options.ambient_bounces {
            return self.options.ambient_value;
        }
        let next = PathState {
            level: state.level + 1,
            specular_depth: state.specular_depth,
            weight: state.weight,
            count_emission: false,
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
                .total();
        }
        sum / count as f32
    }
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

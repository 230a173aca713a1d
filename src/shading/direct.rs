//! L_d: light arriving straight from the light sources, by shadow rays. Area emitters are
//! picked through the light tree (power over squared distance) and sampled by area; every punctual light gets one ray. The diffuse part sees all
//! lights; the glossy lobe sees punctual lights here (nothing else can hit them) and area
//! emitters through its own specular rays.

use super::{Integrator, RayCounts, glossy};
use crate::sampling::Rng;
use crate::scene::material::SurfacePoint;
use crate::tracer::SurfaceHit;
use glam::Vec3;
use std::f32::consts::PI;

pub fn direct_light(
    integrator: &Integrator<'_>,
    hit: &SurfaceHit,
    wo: Vec3,
    surface: &SurfacePoint,
    emitter_samples: u32,
    rng: &mut Rng,
    counts: &mut RayCounts,
) -> Vec3 {
    let scene = integrator.scene;
    let tracer = integrator.tracer;
    let diffuse_brdf = surface.diffuse / PI;
    let mut total = Vec3::ZERO;

    if surface.diffuse.max_element() > 0.0 && !scene.emitters.is_empty() {
        let mut sum = Vec3::ZERO;
        // Stratified: the choice among emitters over k strata, the point on it over a grid,
        // so k samples spread over the lights instead of clumping. The grid cells are dealt
        // out in random order: pairing stratum k with cell k would tie each emitter to one
        // part of the grid, which is not uniform over the emitter.
        let side = crate::sampling::grid_side(emitter_samples);
        let mut cells: Vec<u32> = (0..side * side).collect();
        for i in (1..cells.len()).rev() {
            let j = (rng.next_u32() as usize) % (i + 1);
            cells.swap(i, j);
        }
        for k in 0..emitter_samples {
            let cell = cells[k as usize % cells.len()];
            let u1 = (k as f32 + rng.next_f32()) / emitter_samples as f32;
            let u2 = ((cell % side) as f32 + rng.next_f32()) / side as f32;
            let u3 = ((cell / side) as f32 + rng.next_f32()) / side as f32;
            let Some(light) = scene.emitters.sample(hit.position, u1, u2, u3) else {
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
            if cos_surface <= 0.0 || cos_light <= 0.0 || wi.dot(hit.facing_normal) <= 0.0 {
                continue;
            }
            let origin = tracer.spawn_point(hit, wi);
            // Stop short of the emitter so its own surface does not count as a blocker.
            let reach = (light.position - origin).length() - tracer.epsilon_at(light.position) * 2.0;
            if reach <= 0.0 {
                continue;
            }
            counts.shadow += 1;
            let visible = tracer.transmittance(scene, origin, wi, reach);
            if visible > 0.0 {
                sum += light.radiance * (visible * cos_surface * cos_light / (d2 * light.pdf_area));
            }
        }
        total += diffuse_brdf * sum / emitter_samples as f32;
    }

    for light in &scene.punctual_lights {
        let Some(sample) = light.illuminate(hit.position) else {
            continue;
        };
        let wi = sample.to_light;
        let cos_surface = hit.normal.dot(wi);
        if cos_surface <= 0.0 || wi.dot(hit.facing_normal) <= 0.0 {
            continue;
        }
        let brdf_cos =
            diffuse_brdf * cos_surface + surface.specular * glossy::eval_cos(hit.normal, wo, wi, surface.alpha);
        if brdf_cos.max_element() <= 0.0 {
            continue;
        }
        let origin = tracer.spawn_point(hit, wi);
        let reach = if sample.distance.is_finite() {
            (light.position - origin).length()
        } else {
            f32::INFINITY
        };
        counts.shadow += 1;
        let visible = tracer.transmittance(scene, origin, wi, reach);
        if visible > 0.0 {
            total += brdf_cos * sample.irradiance * visible;
        }
    }
    total
}

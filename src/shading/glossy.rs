//! The specular lobe: a GGX microfacet distribution of roughness alpha with Smith shadowing,
//! scaled by the specular reflectance (no Fresnel variation, as in Radiance's materials).
//! alpha = 0 is a perfect mirror.

use crate::sampling::basis;
use glam::Vec3;
use std::f32::consts::PI;

fn ggx_d(n_dot_h: f32, alpha: f32) -> f32 {
    let a2 = alpha * alpha;
    let d = n_dot_h * n_dot_h * (a2 - 1.0) + 1.0;
    a2 / (PI * d * d).max(1e-30)
}

fn smith_g1(n_dot_x: f32, alpha: f32) -> f32 {
    let a2 = alpha * alpha;
    let c2 = n_dot_x * n_dot_x;
    2.0 * n_dot_x / (n_dot_x + (a2 + (1.0 - a2) * c2).max(0.0).sqrt()).max(1e-30)
}

pub fn reflect(d: Vec3, n: Vec3) -> Vec3 {
    d - 2.0 * d.dot(n) * n
}

/// BRDF value times cos(theta_in) for light arriving along `wi` and leaving along `wo` (both
/// pointing away from the surface), without the reflectance factor. Zero for mirrors.
pub fn eval_cos(n: Vec3, wo: Vec3, wi: Vec3, alpha: f32) -> f32 {
    if alpha <= 0.0 {
        return 0.0;
    }
    let (cos_o, cos_i) = (n.dot(wo), n.dot(wi));
    if cos_o <= 0.0 || cos_i <= 0.0 {
        return 0.0;
    }
    let h = (wo + wi).normalize_or_zero();
    let value = ggx_d(n.dot(h), alpha) * smith_g1(cos_o, alpha) * smith_g1(cos_i, alpha) / (4.0 * cos_o);
    if value.is_finite() { value } else { 0.0 }
}

/// Samples an incoming direction for outgoing `wo`; returns it with the Monte Carlo weight
/// (BRDF x cos / pdf, without the reflectance factor). None when the sample leaves the
/// hemisphere.
pub fn sample(n: Vec3, wo: Vec3, alpha: f32, u1: f32, u2: f32) -> Option<(Vec3, f32)> {
    let cos_o = n.dot(wo);
    if cos_o <= 0.0 {
        return None;
    }
    if alpha <= 0.0 {
        return Some((reflect(-wo, n), 1.0));
    }
    // Half vector from the distribution D(h) cos(h).
    let phi = 2.0 * PI * u1;
    let cos_h2 = (1.0 - u2) / (1.0 + (alpha * alpha - 1.0) * u2);
    let cos_h = cos_h2.clamp(0.0, 1.0).sqrt();
    let sin_h = (1.0 - cos_h * cos_h).max(0.0).sqrt();
    let (t, b) = basis(n);
    let h = (t * (sin_h * phi.cos()) + b * (sin_h * phi.sin()) + n * cos_h).normalize();
    let wi = reflect(-wo, h);
    let cos_i = n.dot(wi);
    let o_dot_h = wo.dot(h);
    if cos_i <= 0.0 || o_dot_h <= 0.0 {
        return None;
    }
    // f cos / pdf = G * (o.h) / ((n.o)(n.h)) for this sampling.
    let weight = smith_g1(cos_o, alpha) * smith_g1(cos_i, alpha) * o_dot_h / (cos_o * cos_h).max(1e-30);
    (weight.is_finite() && weight > 0.0).then_some((wi, weight))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Rng;

    #[test]
    fn mirror_reflects() {
        let n = Vec3::Y;
        let wo = Vec3::new(1.0, 1.0, 0.0).normalize();
        let (wi, w) = sample(n, wo, 0.0, 0.3, 0.3).unwrap();
        assert!((wi - Vec3::new(-1.0, 1.0, 0.0).normalize()).length() < 1e-6);
        assert_eq!(w, 1.0);
    }

    #[test]
    fn sampling_weight_matches_evaluation() {
        // The mean of the sampled weights estimates the directional albedo, and so does a
        // uniform-hemisphere integral of eval_cos: both must agree, and not exceed one.
        let n = Vec3::Z;
        let wo = Vec3::new(0.5, 0.0, 0.8).normalize();
        let alpha = 0.3;
        let mut rng = Rng::new(3, 1);
        let count = 200_000;
        let mut by_sampling = 0.0f64;
        let mut by_uniform = 0.0f64;
        for _ in 0..count {
            if let Some((_, w)) = sample(n, wo, alpha, rng.next_f32(), rng.next_f32()) {
                by_sampling += w as f64;
            }
            let z = rng.next_f32();
            let phi = 2.0 * PI * rng.next_f32();
            let r = (1.0 - z * z).sqrt();
            let wi = Vec3::new(r * phi.cos(), r * phi.sin(), z);
            by_uniform += (eval_cos(n, wo, wi, alpha) * 2.0 * PI) as f64;
        }
        let (a, b) = (by_sampling / count as f64, by_uniform / count as f64);
        assert!(a <= 1.0 + 1e-3 && a > 0.8, "albedo {a}");
        assert!((a - b).abs() < 0.02, "sampled {a} vs integrated {b}");
    }
}

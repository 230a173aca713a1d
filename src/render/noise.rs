//! How noisy a pixel's estimates are: the variance of each noisy layer's value (its luminance),
//! estimated from the pixel's own samples. `--denoise` weighs the denoised layer against the
//! raw one by it (`image::denoise::blend_by_noise`): where the samples agree there is little
//! noise to remove, and the raw value is kept.
//!
//! The direct layer is not a plain mean where its shadow rays are pooled over the pixel (the
//! ratio estimate, `shading::direct::ShadowRatio`): it is `mean(d) + mean(e) * P / U`, with `d`
//! a sample's plainly sampled light, `e` its exact unshadowed light, `P` and `U` the sums of its
//! rays' light with and without blockers. Its variance is taken by the delta method: each
//! sample's linearised share `z = d + mean(e) (p - R u) / mean(u)` (R = P / U), whose variance
//! of the mean is the estimate's. Where the light is wholly visible (p = u) or wholly hidden
//! (p = 0) the shadow rays add none, as the ratio estimate has none there.
//!
//! Left out likewise: the light of punctual lights, each traced on the eye path
//! (`shading::direct::DirectLight::exact`). It is exact at each sample's point, and what spread
//! it shows over the pixel is the pixel's content (a hard shadow's edge, a texture) sampled
//! over its area, stratified, as the term of `e` below. Counted, a scene lit only by punctual
//! lights measured its pixels' spread as noise, and its filter ran for almost nothing: on
//! Sibenik's nave (the peers bench's two fastest settings, two seeds) the denoised composite's
//! relMSE was 1.426e-2 and 1.270e-2 against the raw 1.466e-2 and 1.312e-2 (2.7 and 3.2 %), for
//! 7 % of the render's time, where the raw curve gains 10 % of its error for 8 % more time.
//!
//! The term of `e` itself (`R (e - mean(e))`: how the unshadowed light changes over the pixel's
//! area) is left out: the samples are stratified over the pixel, so the mean's error from it is
//! far below what their spread says, and counted it made an object's antialiased edge look
//! noisy, so the blend kept the filter's blur there. On the Cornell box (64x64, direct light
//! only, 16 samples a pixel) the denoised direct layer's relMSE was 4.3e-4 with it, 3.05e-4
//! without (raw 2.8e-4, the filter alone 4.65e-4); at the peers bench's slowest setting of its
//! inside view 4.05e-5 with it, 3.38e-5 without (raw 3.98e-5).
//!
//! A pixel of one sample has no spread of samples, but its direct light is still a mean over
//! its shadow rays: their spread ray by ray (`shading::direct::RaySpread`) gives the ratio
//! estimate's variance and the plainly sampled part's (`single_sample_direct`). The rays are
//! stratified over the light, so it is an upper bound; the specular and indirect layers stay
//! unmeasured (zero) at one sample.

use crate::image::components::Components;
use crate::image::data::LayerNoise;
use crate::scene::light::luminance;
use crate::shading::direct::ShadowRatio;
use glam::Vec3;

/// The quantities of one sample the direct layer's variance is made of: d, e, p, u.
const DIRECT_TERMS: usize = 4;

/// First and second moments of the samples' terms.
#[derive(Clone, Copy, Debug)]
struct Moments<const K: usize> {
    sum: [f64; K],
    products: [[f64; K]; K],
}

impl<const K: usize> Default for Moments<K> {
    fn default() -> Self {
        Moments {
            sum: [0.0; K],
            products: [[0.0; K]; K],
        }
    }
}

impl<const K: usize> Moments<K> {
    fn add(&mut self, x: [f64; K]) {
        for i in 0..K {
            self.sum[i] += x[i];
            for j in 0..K {
                self.products[i][j] += x[i] * x[j];
            }
        }
    }

    /// The variance of the mean of `a . x` over `n` samples (unbiased sample variance over n).
    fn variance_of_mean(&self, a: [f64; K], n: f64) -> f64 {
        if n < 2.0 {
            return 0.0;
        }
        let mut second = 0.0;
        let mut first = 0.0;
        for i in 0..K {
            first += a[i] * self.sum[i];
            for j in 0..K {
                second += a[i] * a[j] * self.products[i][j];
            }
        }
        let squares = (second - first * first / n).max(0.0);
        squares / (n * (n - 1.0))
    }
}

/// A pixel's samples as they come, for `LayerNoise`.
#[derive(Clone, Debug, Default)]
pub struct PixelNoise {
    samples: u32,
    direct: Moments<DIRECT_TERMS>,
    /// The samples' shadow-ray pools and the variances their plainly sampled rays measured,
    /// summed: a single sample's direct noise (`single_sample_direct`).
    pooled: ShadowRatio,
    sampled_noise: f64,
    specular: Moments<1>,
    indirect: Moments<1>,
}

impl PixelNoise {
    /// One sample: its components (the direct light without its pooled shadow-ray share), the
    /// ratio estimate's parts it added to the pixel's pool, and the part of its direct light
    /// that is exact at its point (`exact`: punctual lights each traced), left out.
    pub fn add(&mut self, sample: &Components, pooled: ShadowRatio, exact: Vec3, sampled_noise: f32) {
        self.samples += 1;
        self.pooled += pooled;
        self.sampled_noise += sampled_noise as f64;
        let l = |v| luminance(v) as f64;
        self.direct.add([
            l(sample.direct - exact),
            l(pooled.exact),
            l(pooled.passed),
            l(pooled.unblocked),
        ]);
        self.specular.add([l(sample.specular)]);
        self.indirect.add([l(sample.indirect)]);
    }

    pub fn finish(&self) -> LayerNoise {
        let n = self.samples as f64;
        if self.samples == 1 {
            return LayerNoise {
                direct: self.single_sample_direct() as f32,
                ..LayerNoise::default()
            };
        }
        let [_, exact, passed, unblocked] = self.direct.sum;
        let (mean_exact, mean_unblocked) = (exact / n.max(1.0), unblocked / n.max(1.0));
        let (share, slope) = if unblocked > 0.0 {
            (passed / unblocked, mean_exact / mean_unblocked)
        } else {
            (0.0, 0.0)
        };
        let direct = self.direct.variance_of_mean([1.0, 0.0, slope, -slope * share], n);
        let single = |m: &Moments<1>| m.variance_of_mean([1.0], n) as f32;
        LayerNoise {
            direct: direct as f32,
            specular: single(&self.specular),
            indirect: single(&self.indirect),
        }
    }

    /// One sample tells nothing of its noise by itself, but its shadow rays do: the ratio
    /// estimate's share `R` spreads over them (`RaySpread::share_variance`), its light is
    /// `exact * R`; the plainly sampled part's rays measured their own (`sampled_noise`).
    /// Punctual lights, traced exactly, add none. The specular and indirect layers have no
    /// such measure and stay at zero (`image::denoise` weighs only the direct layer then).
    fn single_sample_direct(&self) -> f64 {
        let l = |v| luminance(v);
        let pool = &self.pooled;
        let share = pool.rays.share_variance(l(pool.passed), l(pool.unblocked));
        (l(pool.exact) as f64).powi(2) * share + self.sampled_noise
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Rng;
    use crate::shading::direct::RaySpread;

    fn sample(direct: f32) -> Components {
        Components {
            direct: Vec3::splat(direct),
            ..Default::default()
        }
    }

    /// The mean of the pixels' estimated variances, and the variance of their estimates.
    fn estimated_and_spread(variances: &[f64], estimates: &[f64]) -> (f64, f64) {
        let n = estimates.len() as f64;
        let mean = estimates.iter().sum::<f64>() / n;
        let spread = estimates.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (n - 1.0);
        (variances.iter().sum::<f64>() / n, spread)
    }

    fn parts(exact: f32, passed: f32, unblocked: f32) -> ShadowRatio {
        ShadowRatio {
            exact: Vec3::splat(exact),
            passed: Vec3::splat(passed),
            unblocked: Vec3::splat(unblocked),
            ..Default::default()
        }
    }

    #[test]
    fn a_plain_mean_has_the_sample_variance_over_its_count() {
        let mut noise = PixelNoise::default();
        for v in [1.0, 2.0, 3.0, 6.0] {
            noise.add(&sample(v), ShadowRatio::default(), Vec3::ZERO, 0.0);
        }
        // Sample variance 14 / 3, over 4 samples.
        assert!((noise.finish().direct - 14.0 / 12.0).abs() < 1e-6);
        let mut one = PixelNoise::default();
        one.add(&sample(5.0), ShadowRatio::default(), Vec3::ZERO, 0.0);
        assert_eq!(one.finish().direct, 0.0, "one sample tells nothing");
    }

    #[test]
    fn a_wholly_lit_or_hidden_pool_has_no_noise() {
        // The rays' light varies from sample to sample, but every ray got through (or none
        // did): the ratio estimate is exact there, whatever the rays brought.
        for through in [1.0, 0.0] {
            let mut noise = PixelNoise::default();
            for u in [0.2, 1.7, 0.9, 3.1] {
                noise.add(&sample(0.0), parts(2.0, u * through, u), Vec3::ZERO, 0.0);
            }
            assert!(noise.finish().direct.abs() < 1e-9, "share {through}");
        }
    }

    #[test]
    fn the_ratio_estimates_variance_matches_its_spread_over_many_pixels() {
        // A penumbra: each sample's rays see a light of random strength, half of it hidden at
        // random. The mean estimated variance over many pixels against the variance of the
        // pixels' ratio estimates themselves.
        let (pixels, samples) = (20_000, 8);
        let mut rng = Rng::new(3, 0);
        let (mut estimates, mut variances) = (Vec::new(), Vec::new());
        for _ in 0..pixels {
            let mut noise = PixelNoise::default();
            let mut pool = ShadowRatio::default();
            for _ in 0..samples {
                let u = 0.5 + rng.next_f32();
                let p = if rng.next_f32() < 0.5 { u } else { 0.0 };
                let part = parts(1.0, p, u);
                noise.add(&sample(0.0), part, Vec3::ZERO, 0.0);
                pool += part;
            }
            estimates.push(luminance(pool.estimate()) as f64 / samples as f64);
            variances.push(noise.finish().direct as f64);
        }
        let (estimated, spread) = estimated_and_spread(&variances, &estimates);
        assert!(
            (estimated / spread - 1.0).abs() < 0.15,
            "estimated {estimated:.3e} against the estimates' spread {spread:.3e}"
        );
    }

    /// One sample's ratio estimate over `rays` shadow rays in a penumbra: each ray sees a
    /// light of random strength, hidden at random with probability `hidden`.
    fn one_sample_in_a_penumbra(rng: &mut Rng, rays: u32, hidden: f32) -> ShadowRatio {
        let mut part = parts(1.5, 0.0, 0.0);
        part.rays.rays = rays as f32;
        for _ in 0..rays {
            let u = (0.5 + rng.next_f32()) / rays as f32;
            let p = if rng.next_f32() < hidden { 0.0 } else { u };
            part.passed += Vec3::splat(p);
            part.unblocked += Vec3::splat(u);
            part.rays.add(p, u);
        }
        part
    }

    #[test]
    fn one_samples_shadow_rays_measure_its_noise() {
        // The estimated variance of single-sample pixels, on average, against the spread of
        // their estimates themselves, at several shares of the light hidden.
        for hidden in [0.2, 0.5, 0.8] {
            let (pixels, rays) = (20_000, 16);
            let mut rng = Rng::new(5, 0);
            let (mut estimates, mut variances) = (Vec::new(), Vec::new());
            for _ in 0..pixels {
                let part = one_sample_in_a_penumbra(&mut rng, rays, hidden);
                let mut noise = PixelNoise::default();
                noise.add(&sample(0.0), part, Vec3::ZERO, 0.0);
                estimates.push(luminance(part.estimate()) as f64);
                variances.push(noise.finish().direct as f64);
            }
            let (estimated, spread) = estimated_and_spread(&variances, &estimates);
            assert!(
                (estimated / spread - 1.0).abs() < 0.15,
                "hidden {hidden}: estimated {estimated:.3e} against the estimates' spread {spread:.3e}"
            );
        }
    }

    #[test]
    fn one_sample_wholly_lit_has_no_noise_and_its_plain_rays_add_theirs() {
        let mut rng = Rng::new(6, 0);
        let mut noise = PixelNoise::default();
        noise.add(
            &sample(0.0),
            one_sample_in_a_penumbra(&mut rng, 8, 0.0),
            Vec3::ZERO,
            0.0,
        );
        assert!(noise.finish().direct.abs() < 1e-9, "every ray got through");
        let mut plain = PixelNoise::default();
        plain.add(&sample(0.3), ShadowRatio::default(), Vec3::ZERO, 0.25);
        assert_eq!(plain.finish().direct, 0.25, "the plain rays' own variance");
    }

    #[test]
    fn plain_rays_measure_the_variance_of_their_mean() {
        // Rays of light 1, 2, 3, 6 (each over the count of 4): the mean 3 has the sample
        // variance 14 / 3 over 4.
        let mut spread = RaySpread {
            rays: 4.0,
            ..Default::default()
        };
        for v in [1.0f32, 2.0, 3.0, 6.0] {
            spread.add(v / 4.0, v / 4.0);
        }
        assert!((spread.mean_variance(3.0) - 14.0 / 12.0).abs() < 1e-6);
    }

    #[test]
    fn punctual_lights_traced_exactly_add_no_noise() {
        // Half the samples fall in a point light's hard shadow: the spread is the pixel's
        // content, not noise; only what was sampled on top of it counts.
        let mut noise = PixelNoise::default();
        for (k, lit) in [2.0, 0.0, 2.0, 0.0].into_iter().enumerate() {
            let sampled = if k < 2 { 0.5 } else { 0.7 };
            noise.add(&sample(lit + sampled), ShadowRatio::default(), Vec3::splat(lit), 0.0);
        }
        let mut sampled_only = PixelNoise::default();
        for sampled in [0.5, 0.5, 0.7, 0.7] {
            sampled_only.add(&sample(sampled), ShadowRatio::default(), Vec3::ZERO, 0.0);
        }
        let (with, without) = (noise.finish().direct, sampled_only.finish().direct);
        assert!(
            without > 0.0 && (with - without).abs() < 1e-6,
            "{with} against {without}"
        );
    }
}

//! `--denoise`'s layer policy: which lighting layers are filtered, where, and how much of the
//! filter's output each pixel keeps. Running the filter itself (Intel Open Image Denoise's "RT"
//! filter, with its albedo and normal guides) is `filter`'s job.
//!
//! Which layers are noisy, and denoised:
//! - `direct`: shadow rays sample the lights (and, with `--direct analytic`, how much of an
//!   exactly computed irradiance gets through): Monte Carlo noise in penumbrae and with many
//!   lights;
//! - `specular`: glossy reflection and transmission sample their lobes: Monte Carlo noise;
//! - `indirect`: the cache's records are Monte Carlo estimates of their hemispheres, and with
//!   `-aa 0` every pixel samples its own; interpolated records leave smooth, low-frequency
//!   errors, which are not the per-pixel noise the denoiser was trained to remove (docs/layers.md);
//! - not `emission`: the emitters seen straight from the eye are exact but for the
//!   antialiasing of their edges, which a denoiser could only blur.
//!
//! The denoised composite, written as the layer `denoised`, is the sum of the raw emission and
//! the denoised layers, so the layers add up to it exactly, as the raw ones add up to R G B.
//! Denoising the composite itself gives another image (the filter is not linear), and a worse
//! one where emitters are seen: on the Cornell box (64x64, -ab 0, 1 sample and 1 shadow ray a
//! pixel, against a converged reference) it spread the light's edges, RMSE 0.29 where the sum
//! has 0.074 (the raw composite 0.077), for about the same relMSE (1.07e-2 and 1.14e-2; raw
//! 2.5e-2).
//!
//! A layer whose pixels measured their own noise is filtered only on the rectangles that hold
//! it (`noisy_patches`), and the filter's output weighed against the raw layer by that noise
//! (`blend_by_noise`); a layer not measured is filtered whole and kept as filtered.
//!
//! Guides are given to the filter as rendered, as guides that may carry noise (`cleanAux`
//! off: `Denoiser::guides` says why), or with `--denoise-prefilter` prefiltered once per image
//! (each by an RT filter of its own) and then given as clean.

mod filter;

pub use crate::sys::oidn::Quality;
pub use filter::{Denoiser, FilterGuides, Guides, guide_planes};

use super::data::LayerNoise;
use super::framebuffer::{FrameBuffer, Layer};
use super::noisy_patches::noisy_patches;
use crate::scene::light::luminance;
use filter::carries_data;
use glam::Vec3;
use std::time::Instant;

/// The layers that may carry Monte Carlo noise (see the module's comment), in the order written.
pub const NOISY_LAYERS: [Layer; 3] = [Layer::Direct, Layer::Specular, Layer::Indirect];

/// The layers worth denoising among `written`: `direct` and `specular` always; `indirect` only
/// where each pixel samples its own hemisphere (no irradiance cache: `-aa 0`). With the cache
/// the indirect layer is records interpolated, smooth between them, with nothing for the
/// filter to remove: on the conference room at -ab 2 (320x240, two settings, two seeds each)
/// the composite with `indirect` denoised and the one with it raw had the same relMSE to
/// within 1 % (8.54e-3 / 8.54e-3 at one setting, 4.96e-3 / 4.94e-3 at the other; the 4x4
/// relMSE as close), and its filter was half the denoiser's time.
pub fn layers_to_denoise(written: &[Layer], per_pixel_indirect: bool) -> Vec<Layer> {
    NOISY_LAYERS
        .into_iter()
        .filter(|l| written.contains(l) && (per_pixel_indirect || *l != Layer::Indirect))
        .collect()
}

/// The EXR layer a denoised layer is written as: `<layer>_denoised`, beside the raw one. One
/// name with no dot of its own, so that every compositor reads it as one layer: Nuke and
/// oiiotool take what comes before a channel's last dot as its layer, but Blender reads
/// `a.b.R` as render layer `a`, pass `b` (`direct.denoised.R` became pass `denoised` of a
/// render layer `direct`, apart from the other passes).
pub fn denoised_name(layer: Layer) -> String {
    format!("{}_denoised", layer.name())
}

/// The EXR layer of the denoised composite: the raw emission plus the denoised layers (the raw
/// composite stays in R G B A).
pub const DENOISED_COMPOSITE: &str = "denoised";

/// What `--denoise` made of a frame.
pub struct DenoisedFrame {
    /// The noisy layers among those written, each denoised (or as rendered, if in `left_raw`).
    pub layers: Vec<(Layer, Vec<Vec3>)>,
    /// Those of `layers` whose measured noise was none, too little to see or a negligible share
    /// of the image's (`left_raw_because`), and why: written as rendered, not filtered.
    pub left_raw: Vec<(Layer, LeftRaw)>,
    /// The raw emission plus the denoised layers.
    pub composite: Vec<Vec3>,
    /// Whether albedo and normal guides were used.
    pub guided: bool,
    /// Whether the guides were prefiltered (`--denoise-prefilter`).
    pub prefiltered: bool,
    /// The filtered layers whose output was weighed against the raw layer by the pixels'
    /// noise (`blend_by_noise`): those the pixels measured the noise of (`PixelSampling`).
    pub weighed: Vec<Layer>,
    /// "Intel Open Image Denoise 2.5.1", or that it was not started (no layer to filter).
    pub denoiser: String,
    /// The denoiser's own time: its device, the guides' prefiltering and every filter.
    pub seconds: f64,
    /// The pixels the filter ran on, over all layers filtered (patches' margins included): a
    /// layer whose noise the pixels measured is filtered where that noise is (`noisy_patches`).
    pub filtered_pixels: usize,
}

impl DenoisedFrame {
    /// The layers the filter ran on.
    pub fn filtered(&self) -> Vec<Layer> {
        self.layers
            .iter()
            .map(|(l, _)| *l)
            .filter(|l| !self.left_raw.iter().any(|(r, _)| r == l))
            .collect()
    }

    /// The EXR layers written, as the header lists them.
    pub fn names(&self) -> Vec<String> {
        self.layers
            .iter()
            .map(|(l, _)| denoised_name(*l))
            .chain(std::iter::once(DENOISED_COMPOSITE.to_string()))
            .collect()
    }
}

/// Where a pixel's samples hit nothing its noisy layers hold no light at all, but the filter,
/// seeing black guides there, spreads the neighbours' light into it (Sibenik's nave, 320x240:
/// the denoised composite's relMSE 2.0e-2 -> 3.0e-2, nearly all of it from the 371 pixels of
/// sky through the windows). So the raw value is kept in proportion to the share of the
/// pixel's samples that missed: exact where nothing was hit, the filter's where all hit.
fn keep_where_nothing_was_hit(denoised: &mut [Vec3], raw: &[Vec3], frame: &FrameBuffer) {
    let data = frame.data();
    if data.len() != denoised.len() {
        return;
    }
    for ((d, r), pixel) in denoised.iter_mut().zip(raw).zip(data) {
        let covered = pixel.covered();
        *d = *d * covered + *r * (1.0 - covered);
    }
}

/// The variance `noise` holds of the light layer `layer` (zero for one without noise: emission).
fn noise_of(noise: &LayerNoise, layer: Layer) -> f32 {
    match layer {
        Layer::Direct => noise.direct,
        Layer::Specular => noise.specular,
        Layer::Indirect => noise.indirect,
        Layer::Emission => 0.0,
    }
}

/// Half the side of the square over which `blend_by_noise` averages the noise and the
/// filter's change: the smallest (at least 1) whose pixels give the variance 48 degrees of
/// `freedom` (a pixel's own: `PixelSampling::freedom`): 3 at 2 samples a pixel, 2 at 4, 1
/// from 8; with one sample and 16 shadow rays 1.
/// The smaller the square, the closer the weight follows the light; the more degrees of
/// freedom, the less the noise of the variance itself moves it. Measured on the Cornell box
/// (two seeds, relMSE and 4x4 relMSE of the denoised composite): at 2 samples a pixel radius 1
/// 7.0e-4 / 1.66e-4, 3 6.6e-4 / 1.66e-4, 8 6.5e-4 / 1.67e-4; at 32 samples radius 1
/// 4.71e-5 / 1.13e-5, 3 4.79e-5 / 1.15e-5, 8 4.86e-5 / 1.18e-5.
fn blend_radius(freedom: u32) -> usize {
    let freedom = freedom.max(1) as usize;
    (1..).find(|r| freedom * (2 * r + 1) * (2 * r + 1) >= 48).unwrap()
}

/// How a frame was sampled: what its pixels' noise (`render::noise`) was measured from.
#[derive(Clone, Copy, Debug)]
pub struct PixelSampling {
    /// Samples a pixel (`--spp`).
    pub samples: u32,
    /// Shadow rays a sample's camera-ray hit sends (`--light-samples`).
    pub shadow_rays: u32,
    /// Samples in the pixels an edge crosses (`--edge-samples`).
    pub edge_samples: u32,
}

impl PixelSampling {
    /// Whether the pixels measured `layer`'s noise: every layer's from two samples on; with one
    /// sample only the direct light's, from its shadow rays if there are two or more, and only
    /// where the pixels an edge crosses take more samples. With one sample at an edge the
    /// pixel's error is where in it the sample fell, which its rays do not measure and the
    /// filter smooths: on the Cornell box (64x64, -ab 0, 16 shadow rays, three seeds, the
    /// direct layer's relMSE, filter alone / weighed / raw) 2.18e-3 / 2.53e-3 / 2.74e-3
    /// without edge samples; 6.20e-4 / 6.28e-4 / 6.39e-4 with 4; 2.61e-4 / 1.90e-4 / 1.91e-4
    /// with 16.
    fn measures(&self, layer: Layer) -> bool {
        self.samples >= 2 || (layer == Layer::Direct && self.shadow_rays >= 2 && self.edge_samples >= 2)
    }

    /// The degrees of freedom of a pixel's measured variance: its samples', or with one sample
    /// its shadow rays'.
    fn freedom(&self) -> u32 {
        if self.samples >= 2 {
            self.samples - 1
        } else {
            self.shadow_rays.saturating_sub(1)
        }
    }
}

/// The raw layer where it has little noise, the filter's output where it has much: each pixel
/// takes `raw + w (denoised - raw)` with `w = V / D` (at most 1), `V` the variance of the raw
/// value (`PixelData::noise`) and `D` the squared change the filter made, both averaged over
/// the pixels around it (their luminance). If the filter were exact, the change would be the
/// noise and `D` would be `V`: the filter's output is kept whole. Where it also moves the
/// light itself (it blurs a contact shadow, a texture's edge or a light's gradient that was
/// already clean), `D = V + B` with `B` its error, and `V / (V + B)` is the weight that makes
/// the mix's squared error `(1 - w)^2 V + w^2 B` least. So a clean layer stays as rendered and
/// a noisy one is denoised. Measured (two seeds, relMSE and 4x4 relMSE of the denoised
/// composite, the filter alone / blended / raw): the Cornell box's inside view at the peers
/// bench's slowest setting 5.9e-5 / 3.4e-5 / 4.0e-5 and 1.5e-5 / 6.9e-6 / 6.9e-6; its default
/// view at 4 samples a pixel 2.84e-4 / 2.89e-4 / 4.21e-4 and 9.1e-5 / 8.5e-5 / 8.8e-5, at 2
/// samples 6.6e-4 / 7.4e-4 / 1.38e-3 (the one loss: the variance of two samples is a poor
/// guide); the conference room unchanged within 1 % (its direct light is noisy everywhere).
fn blend_by_noise(
    denoised: &mut [Vec3],
    raw: &[Vec3],
    variance: &[f32],
    (width, height): (usize, usize),
    radius: usize,
) {
    let change: Vec<f32> = denoised
        .iter()
        .zip(raw)
        .map(|(d, r)| luminance(*d - *r).powi(2))
        .collect();
    let (variance, change) = (
        box_mean(variance, width, height, radius),
        box_mean(&change, width, height, radius),
    );
    for (i, (d, r)) in denoised.iter_mut().zip(raw).enumerate() {
        let w = if change[i] > 0.0 {
            (variance[i] / change[i]).clamp(0.0, 1.0)
        } else {
            1.0
        };
        *d = *r + (*d - *r) * w;
    }
}

/// The mean of `values` (a width x height image) over the square of half-side `radius` around
/// each pixel, clipped at the image's borders. Summed in f64 (a summed-area table).
fn box_mean(values: &[f32], width: usize, height: usize, radius: usize) -> Vec<f32> {
    let mut table = vec![0.0f64; (width + 1) * (height + 1)];
    for y in 0..height {
        let mut row = 0.0;
        for x in 0..width {
            row += values[y * width + x] as f64;
            table[(y + 1) * (width + 1) + x + 1] = table[y * (width + 1) + x + 1] + row;
        }
    }
    let mut out = vec![0.0f32; width * height];
    for y in 0..height {
        let (y0, y1) = (y.saturating_sub(radius), (y + radius + 1).min(height));
        for x in 0..width {
            let (x0, x1) = (x.saturating_sub(radius), (x + radius + 1).min(width));
            let at = |x: usize, y: usize| table[y * (width + 1) + x];
            let sum = at(x1, y1) - at(x0, y1) - at(x1, y0) + at(x0, y0);
            out[y * width + x] = (sum / ((x1 - x0) * (y1 - y0)) as f64) as f32;
        }
    }
    out
}

/// Below this share of the image's measured noise a layer is left raw (`noise_shares`).
pub const NEGLIGIBLE_NOISE_SHARE: f64 = 0.01;

/// Below this relative variance (`relative_noise`) a layer is left raw: a standard deviation
/// of 0.3 % of the pixels' light, under one step of an 8-bit display at mid grey, which the
/// filter could not make visibly better for its 0.7 microseconds a pixel (OIDN 2.5.1, fast, 2
/// cores). Measured on the peers bench's scenes (their fastest and slowest settings): the
/// Cornell box's direct light 9.2e-3 and 1.4e-4, the conference room's 1.3e-2 at its slowest;
/// Sibenik's specular layer (with `--lambertian`, what its alpha-blended material passes)
/// 6.3e-6 and 1.4e-6, where filtering it gave a composite no better (relMSE 1.458e-2 with it
/// denoised, 1.455e-2 raw).
pub const NEGLIGIBLE_RELATIVE_NOISE: f64 = 1e-5;

/// Why a noisy layer was written as rendered, not filtered.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LeftRaw {
    /// Its pixels' samples measured no Monte Carlo noise at all (a scene lit by punctual
    /// lights alone, each traced exactly: `render::noise`).
    NoNoise,
    /// Its relative variance, under `NEGLIGIBLE_RELATIVE_NOISE`.
    Invisible(f64),
    /// Its share of the image's measured noise, under `NEGLIGIBLE_NOISE_SHARE`.
    SmallShare(f64),
}

/// Each of `layers`' noise as the pixels' samples measured it, relative to the composite's
/// light (the way relMSE weighs error): the mean over pixels of the layer's variance over the
/// squared luminance of the raw composite. With the noise weighed in (`blend_by_noise`),
/// filtering a layer can lower the composite's error by at most this much. The squared
/// luminance is floored at a hundredth of the squared mean, so that black pixels do not weigh
/// without bound.
fn relative_noise(frame: &FrameBuffer, layers: &[Layer], weights: &[f64]) -> Vec<f64> {
    let pixels = weights.len().max(1) as f64;
    layers
        .iter()
        .map(|&layer| {
            let sum: f64 = relative_variance(frame, layer, weights).iter().map(|v| *v as f64).sum();
            sum / pixels
        })
        .collect()
}

/// Each pixel's weight in relMSE: one over the squared luminance of its raw composite, floored
/// at a hundredth of the squared mean (`relative_noise`).
fn relative_weights(frame: &FrameBuffer) -> Vec<f64> {
    let composite: Vec<f64> = (0..frame.data().len())
        .map(|i| {
            let light: Vec3 = Layer::ALL.iter().map(|l| frame.layer(*l)[i]).sum();
            luminance(light) as f64
        })
        .collect();
    let pixels = composite.len().max(1) as f64;
    let mean = composite.iter().sum::<f64>() / pixels;
    let floor = (0.1 * mean).powi(2).max(f64::MIN_POSITIVE);
    composite.iter().map(|c| 1.0 / (c * c).max(floor)).collect()
}

/// Each pixel's variance of `layer` times its `relative_weights`: its share of the relMSE the
/// layer's noise makes.
fn relative_variance(frame: &FrameBuffer, layer: Layer, weights: &[f64]) -> Vec<f32> {
    frame
        .data()
        .iter()
        .zip(weights)
        .map(|(d, w)| (noise_of(&d.noise, layer) as f64 * w) as f32)
        .collect()
}

/// Each layer's share of `noise` (`relative_noise`), all zero where none was measured.
/// A layer with a negligible share costs the filter's whole time for nothing measurable:
/// Sibenik's nave at the peers bench's fastest setting (320x240, 4 samples a pixel) measured
/// the specular layer at 0.13 % of the noise, and its filter took 62 ms (half the denoiser's
/// time, 4.5 % of the render's) for a composite no better.
fn noise_shares(noise: &[f64]) -> Vec<f64> {
    let total: f64 = noise.iter().sum();
    noise
        .iter()
        .map(|r| if total > 0.0 { r / total } else { 0.0 })
        .collect()
}

/// Whether a layer with relative variance `noise` and `share` of the image's noise is left
/// raw, and why; None: it is filtered.
fn left_raw_because(noise: f64, share: f64) -> Option<LeftRaw> {
    if noise <= 0.0 {
        Some(LeftRaw::NoNoise)
    } else if noise < NEGLIGIBLE_RELATIVE_NOISE {
        Some(LeftRaw::Invisible(noise))
    } else if share < NEGLIGIBLE_NOISE_SHARE {
        Some(LeftRaw::SmallShare(share))
    } else {
        None
    }
}

/// Denoises the noisy ones of `written` (the layers the EXR will hold; `indirect` only with
/// `per_pixel_indirect`: `layers_to_denoise`), and adds them, the raw emission and any raw
/// layer left up into the denoised composite. Each denoised layer whose noise the pixels
/// measured (`PixelSampling::measures`: all from two samples a pixel, with one the direct
/// light by its shadow rays) is weighed against the raw one by it (`blend_by_noise`), and left
/// raw where it has next to none; a layer not measured keeps the filter's output as it is.
pub fn denoise_frame(
    frame: &FrameBuffer,
    written: &[Layer],
    per_pixel_indirect: bool,
    sampling: PixelSampling,
    quality: Quality,
    threads: Option<usize>,
    prefilter: bool,
) -> Result<DenoisedFrame, String> {
    let start = Instant::now();
    let (w, h) = (frame.width, frame.height);
    // The device is started only for a layer that needs the filter: none may (a scene lit by
    // punctual lights alone).
    let mut device: Option<Denoiser> = None;
    // A frame with data layers carries its pixels' noise and guides; one sample a pixel
    // measured no noise.
    let guided = carries_data(frame);
    let weighs = |layer: Layer| guided && sampling.measures(layer);
    let candidates = layers_to_denoise(written, per_pixel_indirect);
    // Each pixel's weight in relMSE, for the layers' noise and where it is.
    let weights = relative_weights(frame);
    let noise = relative_noise(frame, &candidates, &weights);
    let shares = noise_shares(&noise);
    let verdicts: Vec<Option<LeftRaw>> = candidates
        .iter()
        .zip(noise.iter().zip(shares))
        .map(|(layer, (n, s))| weighs(*layer).then(|| left_raw_because(*n, s)).flatten())
        .collect();
    let mut weighed = Vec::new();
    let mut filtered_pixels = 0;
    // Guides, like the device, are made for the first layer filtered.
    let mut clean = None;
    let mut layers = Vec::new();
    let mut left_raw = Vec::new();
    for (layer, verdict) in candidates.into_iter().zip(verdicts) {
        if let Some(why) = verdict {
            layers.push((layer, frame.layer(layer).to_vec()));
            left_raw.push((layer, why));
            continue;
        }
        let denoiser = match &mut device {
            Some(d) => d,
            None => device.insert(Denoiser::new(quality, threads)?),
        };
        if clean.is_none() {
            let planes = guide_planes(frame);
            let guides = planes.as_ref().map(|(albedo, normal)| Guides { albedo, normal });
            clean = guides.map(|g| denoiser.guides(g, w, h, prefilter)).transpose()?;
        }
        // A layer whose pixels measured their noise is filtered where the noise is; the
        // filter's output elsewhere would be weighed away (`blend_by_noise`).
        let patches = weighs(layer)
            .then(|| {
                let noise = relative_variance(frame, layer, &weights);
                noisy_patches(&noise, w as usize, h as usize)
            })
            .flatten();
        let mut plane = match &patches {
            Some(patches) => denoiser.denoise_patches(frame.layer(layer), clean.as_ref(), w, patches)?,
            None => denoiser.denoise(frame.layer(layer), clean.as_ref(), w, h)?,
        };
        filtered_pixels += patches
            .as_ref()
            .map_or(w as usize * h as usize, |p| p.iter().map(|p| p.seen.area()).sum());
        if weighs(layer) {
            let variance: Vec<f32> = frame.data().iter().map(|d| noise_of(&d.noise, layer)).collect();
            let size = (w as usize, h as usize);
            blend_by_noise(
                &mut plane,
                frame.layer(layer),
                &variance,
                size,
                blend_radius(sampling.freedom()),
            );
            weighed.push(layer);
        }
        keep_where_nothing_was_hit(&mut plane, frame.layer(layer), frame);
        layers.push((layer, plane));
    }
    let mut composite = frame.layer(Layer::Emission).to_vec();
    for noisy in NOISY_LAYERS {
        let plane = layers
            .iter()
            .find(|(l, _)| *l == noisy)
            .map_or(frame.layer(noisy), |(_, p)| p.as_slice());
        composite.iter_mut().zip(plane).for_each(|(c, v)| *c += *v);
    }
    Ok(DenoisedFrame {
        layers,
        left_raw,
        composite,
        guided,
        prefiltered: guided && prefilter,
        weighed,
        denoiser: device.as_ref().map_or_else(
            || "Intel Open Image Denoise (not started: no layer to filter)".to_string(),
            Denoiser::describe,
        ),
        seconds: start.elapsed().as_secs_f64(),
        filtered_pixels,
    })
}

#[cfg(test)]
mod tests {
    use super::filter::{floats, vectors};
    use super::*;

    /// A channel's layer as Blender reads a single-part EXR (render layer, pass, channel: a
    /// name with one dot is a pass of the unnamed render layer) and as Nuke and oiiotool read it
    /// (everything before the last dot).
    fn layers_as_read(channel: &str) -> (String, String) {
        let parts: Vec<&str> = channel.split('.').collect();
        let blender = match parts.len() {
            2 => parts[0].to_string(),
            n if n >= 3 => format!("{}/{}", parts[0], parts[1..n - 1].join(".")),
            _ => String::new(),
        };
        let nuke = channel.rsplit_once('.').map_or("", |(layer, _)| layer).to_string();
        (blender, nuke)
    }

    #[test]
    fn every_compositor_reads_a_denoised_layer_as_a_pass_of_its_own() {
        for layer in NOISY_LAYERS {
            let name = denoised_name(layer);
            let (blender, nuke) = layers_as_read(&format!("{name}.R"));
            assert_eq!(blender, name, "Blender reads {name}.R as {blender}");
            assert_eq!(nuke, name);
            let (raw, _) = layers_as_read(&format!("{}.R", layer.name()));
            assert_ne!(raw, name, "the denoised layer stays apart from the raw one");
        }
        assert_eq!(
            layers_as_read("direct.denoised.R").0,
            "direct/denoised",
            "the old name, as Blender read it"
        );
    }
    use crate::image::components::Components;
    use crate::image::data::PixelData;
    use crate::sampling::Rng;

    /// One plane denoised (guides prefiltered first), and the seconds it took, device included:
    /// the filter alone, for the tests below.
    fn denoise_plane(
        color: &[Vec3],
        guides: Option<Guides<'_>>,
        width: u32,
        height: u32,
        quality: Quality,
        threads: Option<usize>,
    ) -> Result<(Vec<Vec3>, f64), String> {
        let start = Instant::now();
        let denoiser = Denoiser::new(quality, threads)?;
        let clean = guides.map(|g| denoiser.prefilter(g, width, height)).transpose()?;
        let plane = denoiser.denoise(color, clean.as_ref(), width, height)?;
        Ok((plane, start.elapsed().as_secs_f64()))
    }

    const W: u32 = 96;
    const H: u32 = 80;

    /// One sample a pixel with one shadow ray: no layer's noise measured.
    fn unmeasured() -> PixelSampling {
        PixelSampling {
            samples: 1,
            shadow_rays: 1,
            edge_samples: 0,
        }
    }

    fn four_samples() -> PixelSampling {
        PixelSampling {
            samples: 4,
            shadow_rays: 1,
            edge_samples: 0,
        }
    }

    /// A smooth HDR image: a different gradient in each channel, 0.2 to about 2.
    fn clean() -> Vec<Vec3> {
        (0..W * H)
            .map(|i| {
                let (x, y) = ((i % W) as f32 / W as f32, (i / W) as f32 / H as f32);
                Vec3::new(0.2 + 1.8 * x, 0.3 + 1.2 * y, 0.5 + 0.5 * (x + y))
            })
            .collect()
    }

    /// Monte Carlo-like noise: each pixel the mean of 4 samples of value / p with probability
    /// p = 0.5, else 0 (unbiased, relative standard deviation 0.5), seeded.
    fn noisy(clean: &[Vec3], seed: u64) -> Vec<Vec3> {
        let mut rng = Rng::new(seed, 0);
        clean
            .iter()
            .map(|&v| {
                let hits = (0..4).filter(|_| rng.next_f32() < 0.5).count() as f32;
                v * (hits / 4.0 / 0.5)
            })
            .collect()
    }

    fn rmse(a: &[Vec3], b: &[Vec3]) -> f64 {
        let se: f64 = a.iter().zip(b).map(|(x, y)| (*x - *y).length_squared() as f64).sum();
        (se / (3 * a.len()) as f64).sqrt()
    }

    #[test]
    fn box_means_clip_at_the_borders() {
        let values: Vec<f32> = (0..12).map(|i| i as f32).collect();
        // 4 wide, 3 high; radius 1.
        let mean = box_mean(&values, 4, 3, 1);
        assert_eq!(mean[0], (0.0 + 1.0 + 4.0 + 5.0) / 4.0);
        assert_eq!(
            mean[5],
            (0..3)
                .flat_map(|y| (0..3).map(move |x| (y * 4 + x) as f32))
                .sum::<f32>()
                / 9.0
        );
        assert_eq!(mean[11], (6.0 + 7.0 + 10.0 + 11.0) / 4.0);
        assert_eq!(box_mean(&values, 4, 3, 0), values);
    }

    #[test]
    fn the_blend_radius_gives_the_variance_enough_samples() {
        // Degrees of freedom: samples a pixel less one (2, 4, 8, 64 samples) ...
        assert_eq!(blend_radius(1), 3);
        assert_eq!(blend_radius(3), 2);
        assert_eq!(blend_radius(7), 1);
        assert_eq!(blend_radius(63), 1);
        // ... or, with one sample, shadow rays less one; none measured counts as one.
        let rays = |shadow_rays| PixelSampling {
            samples: 1,
            shadow_rays,
            edge_samples: 4,
        };
        assert_eq!(blend_radius(rays(16).freedom()), 1);
        assert_eq!(blend_radius(rays(4).freedom()), 2);
        assert_eq!(blend_radius(rays(1).freedom()), 3);
        assert!(rays(2).measures(Layer::Direct) && !rays(1).measures(Layer::Direct));
        assert!(!rays(16).measures(Layer::Specular) && !rays(16).measures(Layer::Indirect));
        let edges_unsampled = PixelSampling {
            edge_samples: 0,
            ..rays(16)
        };
        assert!(!edges_unsampled.measures(Layer::Direct));
        assert!(four_samples().measures(Layer::Indirect));
    }

    #[test]
    fn a_clean_layer_stays_raw_and_a_noisy_one_takes_the_filters_output() {
        let (w, h) = (16, 12);
        let raw = vec![Vec3::splat(1.0); w * h];
        let filtered = vec![Vec3::splat(1.2); w * h];
        // No noise: the filter's change is all error, the raw value is kept.
        let mut out = filtered.clone();
        blend_by_noise(&mut out, &raw, &vec![0.0; w * h], (w, h), 1);
        assert!(out.iter().all(|v| *v == Vec3::splat(1.0)));
        // Noise as large as the change: the filter's output whole.
        let mut out = filtered.clone();
        blend_by_noise(&mut out, &raw, &vec![0.04; w * h], (w, h), 1);
        assert!(out.iter().all(|v| (*v - Vec3::splat(1.2)).abs().max_element() < 1e-6));
        // A quarter of it: a quarter of the way (V / D = 0.01 / 0.04).
        let mut out = filtered;
        blend_by_noise(&mut out, &raw, &vec![0.01; w * h], (w, h), 1);
        assert!(out.iter().all(|v| (*v - Vec3::splat(1.05)).abs().max_element() < 1e-6));
    }

    #[test]
    fn the_indirect_layer_is_denoised_only_where_each_pixel_samples_it() {
        let written = [Layer::Emission, Layer::Direct, Layer::Specular, Layer::Indirect];
        assert_eq!(
            layers_to_denoise(&written, true),
            [Layer::Direct, Layer::Specular, Layer::Indirect]
        );
        assert_eq!(layers_to_denoise(&written, false), [Layer::Direct, Layer::Specular]);
        assert_eq!(layers_to_denoise(&[Layer::Indirect], false), []);
    }

    #[test]
    fn denoising_a_noisy_gradient_brings_it_much_closer_to_the_clean_one() {
        let clean = clean();
        let noisy = noisy(&clean, 7);
        let (denoised, seconds) = denoise_plane(&noisy, None, W, H, Quality::High, Some(2)).unwrap();
        let (before, after) = (rmse(&noisy, &clean), rmse(&denoised, &clean));
        eprintln!("noisy gradient: rmse {before:.4} raw, {after:.4} denoised, {seconds:.3} s");
        assert!(
            after < before / 4.0,
            "rmse {before:.4} noisy, {after:.4} denoised (at least 4x lower expected)"
        );
        assert!(seconds > 0.0);
    }

    #[test]
    fn guides_are_prefiltered_and_used() {
        let clean = clean();
        let noisy = noisy(&clean, 11);
        let albedo = vec![Vec3::splat(0.8); (W * H) as usize];
        let normal = vec![Vec3::Z; (W * H) as usize];
        let guides = Guides {
            albedo: &albedo,
            normal: &normal,
        };
        let (denoised, _) = denoise_plane(&noisy, Some(guides), W, H, Quality::Fast, Some(2)).unwrap();
        let (before, after) = (rmse(&noisy, &clean), rmse(&denoised, &clean));
        eprintln!("noisy gradient, guided: rmse {before:.4} raw, {after:.4} denoised");
        assert!(
            after < before / 4.0,
            "rmse {before:.4} noisy, {after:.4} denoised with guides"
        );
    }

    #[test]
    fn guides_pass_as_rendered_unless_prefiltering_is_asked_for() {
        // A noisy albedo: as rendered it passes unchanged; prefiltered it comes back smoother.
        let albedo: Vec<Vec3> = noisy(&vec![Vec3::splat(0.5); (W * H) as usize], 5)
            .into_iter()
            .map(|v| v.clamp(Vec3::ZERO, Vec3::ONE))
            .collect();
        let normal = vec![Vec3::Z; (W * H) as usize];
        let guides = Guides {
            albedo: &albedo,
            normal: &normal,
        };
        let denoiser = Denoiser::new(Quality::Fast, Some(2)).unwrap();
        let as_rendered = denoiser.guides(guides, W, H, false).unwrap();
        assert_eq!(as_rendered.albedo, floats(&albedo));
        // As rendered they go to the filter as guides that may be noisy, prefiltered as clean.
        assert!(!as_rendered.clean);
        let prefiltered = denoiser.guides(guides, W, H, true).unwrap();
        assert!(prefiltered.clean);
        let flat = vec![Vec3::splat(0.5); (W * H) as usize];
        assert!(rmse(&vectors(&prefiltered.albedo), &flat) < rmse(&albedo, &flat) / 2.0);
    }

    #[test]
    fn a_plane_of_the_wrong_size_is_refused() {
        let plane = vec![Vec3::ONE; 10];
        let err = denoise_plane(&plane, None, 4, 4, Quality::Fast, Some(1)).unwrap_err();
        assert!(err.contains("30 values for 4x4"), "{err}");
    }

    /// The light the filter alone (without `keep_where_nothing_was_hit`) puts where the frame's
    /// last columns see nothing.
    fn denoiser_spill(frame: &FrameBuffer, written: &[Layer]) -> f32 {
        assert!(written.contains(&Layer::Direct));
        let denoiser = Denoiser::new(Quality::Fast, Some(2)).unwrap();
        let (albedo, normal) = guide_planes(frame).unwrap();
        let guides = Guides {
            albedo: &albedo,
            normal: &normal,
        };
        let clean = denoiser.prefilter(guides, W, H).unwrap();
        let plane = denoiser
            .denoise(frame.layer(Layer::Direct), Some(&clean), W, H)
            .unwrap();
        (0..plane.len())
            .filter(|i| i % W as usize >= W as usize - 4)
            .map(|i| plane[i].max_element())
            .sum()
    }

    #[test]
    fn a_frame_gets_its_noisy_layers_denoised_not_its_emission_and_they_add_up_to_the_composite() {
        // The last columns see nothing (sky): no light in the noisy layers, and no surface.
        let sky = |i: usize| i % W as usize >= W as usize - 4;
        let mut clean = clean();
        for (i, c) in clean.iter_mut().enumerate() {
            if sky(i) {
                *c = Vec3::ZERO;
            }
        }
        let direct = noisy(&clean, 3)
            .into_iter()
            .enumerate()
            .map(|(i, d)| if sky(i) { Vec3::ZERO } else { d })
            .collect::<Vec<_>>();
        let mut frame = FrameBuffer::new(W, H);
        let mut surface = PixelData {
            albedo: Vec3::splat(0.5),
            normal: Vec3::Z,
            depth: 1.0,
            ..Default::default()
        };
        surface.object[0] = crate::image::cryptomatte::Entry { id: 1, coverage: 1.0 };
        for (i, d) in direct.iter().enumerate() {
            let components = Components {
                emission: if i % W as usize == 5 {
                    Vec3::splat(4.0)
                } else {
                    Vec3::ZERO
                },
                direct: *d,
                ..Default::default()
            };
            let (x, y) = (i as u32 % W, i as u32 / W);
            frame.set(x, y, &components);
            if !sky(i) {
                frame.set_data(x, y, &surface);
            }
        }
        let written = [Layer::Emission, Layer::Direct];
        let denoised = denoise_frame(&frame, &written, true, unmeasured(), Quality::Fast, Some(2), false).unwrap();
        assert_eq!(denoised.names(), ["direct_denoised", "denoised"]);
        assert!(
            denoised.guided,
            "every frame carries the albedo and normal planes that guide it"
        );
        assert!(
            denoised.denoiser.starts_with("Intel Open Image Denoise 2."),
            "{}",
            denoised.denoiser
        );
        let (layer, plane) = &denoised.layers[0];
        assert_eq!(*layer, Layer::Direct);
        assert!(rmse(plane, &clean) < rmse(&direct, &clean) / 4.0);
        // Where nothing was hit the filter's spill is not kept: no light there, exactly.
        let spill = denoiser_spill(&frame, &written);
        assert!(spill > 0.0, "the filter alone spreads light into the sky ({spill})");
        assert!((0..plane.len()).filter(|&i| sky(i)).all(|i| plane[i] == Vec3::ZERO));
        // The composite is the raw emission plus the denoised layer, exactly.
        for (i, c) in denoised.composite.iter().enumerate() {
            assert_eq!(*c, frame.layer(Layer::Emission)[i] + plane[i]);
        }
    }

    /// A frame of the smooth image as its direct light (`direct`, its variance recorded as
    /// `direct_noise` times the clean value's squared luminance) and a tenth of it as its
    /// specular light (`specular_noise` likewise), every pixel a surface.
    fn frame_with_noise(direct: &[Vec3], direct_noise: f32, specular_noise: f32) -> FrameBuffer {
        frame_with_noise_at(direct, |_| direct_noise, specular_noise)
    }

    /// `frame_with_noise` with pixel `i`'s direct noise `direct_noise(i)`.
    fn frame_with_noise_at(direct: &[Vec3], direct_noise: impl Fn(usize) -> f32, specular_noise: f32) -> FrameBuffer {
        let mut frame = FrameBuffer::new(W, H);
        for (i, (d, c)) in direct.iter().zip(clean()).enumerate() {
            let mut surface = PixelData {
                albedo: Vec3::splat(0.5),
                normal: Vec3::Z,
                depth: 1.0,
                noise: LayerNoise {
                    direct: direct_noise(i) * luminance(c).powi(2),
                    specular: specular_noise * luminance(c).powi(2),
                    indirect: 0.0,
                },
                ..Default::default()
            };
            surface.object[0] = crate::image::cryptomatte::Entry { id: 1, coverage: 1.0 };
            let components = Components {
                direct: *d,
                specular: c * 0.1,
                ..Default::default()
            };
            let (x, y) = (i as u32 % W, i as u32 / W);
            frame.set(x, y, &components);
            frame.set_data(x, y, &surface);
        }
        frame
    }

    #[test]
    fn noise_shares_are_each_layers_part_of_the_relative_variance() {
        let frame = frame_with_noise(&clean(), 0.03, 0.01);
        let noise = relative_noise(&frame, &[Layer::Direct, Layer::Specular], &relative_weights(&frame));
        let shares = noise_shares(&noise);
        assert!(
            (shares[0] - 0.75).abs() < 1e-9 && (shares[1] - 0.25).abs() < 1e-9,
            "{shares:?}"
        );
        let quiet = frame_with_noise(&clean(), 0.0, 0.0);
        let noise = relative_noise(&quiet, &[Layer::Direct, Layer::Specular], &relative_weights(&quiet));
        assert_eq!(noise, [0.0, 0.0]);
        assert_eq!(noise_shares(&noise), [0.0, 0.0]);
    }

    #[test]
    fn relative_noise_is_the_mean_variance_over_the_squared_light() {
        // The composite is the direct light and a tenth of it as specular light: a variance of
        // 0.03 times the direct light squared is 0.03 / 1.1^2 of the composite's light squared.
        let frame = frame_with_noise(&clean(), 0.03, 0.0);
        let noise = relative_noise(&frame, &[Layer::Direct], &relative_weights(&frame));
        assert!((noise[0] - 0.03 / 1.21).abs() < 1e-4, "{noise:?}");
    }

    #[test]
    fn a_layer_is_left_raw_without_noise_below_sight_or_with_a_negligible_share() {
        assert_eq!(left_raw_because(0.0, 0.0), Some(LeftRaw::NoNoise));
        assert_eq!(left_raw_because(2e-6, 1.0), Some(LeftRaw::Invisible(2e-6)));
        assert_eq!(left_raw_because(1e-3, 0.005), Some(LeftRaw::SmallShare(0.005)));
        assert_eq!(left_raw_because(1e-3, 0.5), None);
    }

    #[test]
    fn a_frame_noisy_in_one_corner_is_filtered_there_only() {
        // Noise (and its measured variance) in the top left 32x32 pixels, the rest clean.
        let corner = |i: usize| (i % W as usize) < 32 && (i / W as usize) < 32;
        let clean = clean();
        let noisy = noisy(&clean, 7);
        let direct: Vec<Vec3> = (0..clean.len())
            .map(|i| if corner(i) { noisy[i] } else { clean[i] })
            .collect();
        let frame = frame_with_noise_at(&direct, |i| if corner(i) { 0.25 } else { 0.0 }, 0.0);
        let written = [Layer::Direct];
        let denoised = denoise_frame(&frame, &written, false, four_samples(), Quality::Fast, Some(2), false).unwrap();
        // The filter saw the corner and its margin of context, 48x48 pixels, not the 96x80.
        assert_eq!(denoised.filtered_pixels, 48 * 48);
        let (_, plane) = &denoised.layers[0];
        let inside: Vec<usize> = (0..plane.len()).filter(|&i| corner(i)).collect();
        let pick = |p: &[Vec3]| inside.iter().map(|&i| p[i]).collect::<Vec<_>>();
        let (before, after) = (rmse(&pick(&direct), &pick(&clean)), rmse(&pick(plane), &pick(&clean)));
        assert!(
            after < before / 2.0,
            "rmse {before:.4} raw, {after:.4} denoised in the corner"
        );
        // Everywhere else the layer is as rendered, exactly.
        assert!((0..plane.len()).filter(|&i| !corner(i)).all(|i| plane[i] == direct[i]));
    }

    #[test]
    fn a_frame_without_measured_noise_runs_no_filter() {
        // Four samples a pixel that measured no noise (punctual lights traced exactly): the
        // layers are written as rendered and the composite is the raw one.
        let frame = frame_with_noise(&clean(), 0.0, 0.0);
        let written = [Layer::Direct, Layer::Specular];
        let denoised = denoise_frame(&frame, &written, false, four_samples(), Quality::Fast, Some(2), false).unwrap();
        assert!(denoised.filtered().is_empty());
        assert!(denoised.denoiser.contains("not started"), "{}", denoised.denoiser);
        assert_eq!(
            denoised.left_raw,
            [(Layer::Direct, LeftRaw::NoNoise), (Layer::Specular, LeftRaw::NoNoise)]
        );
        for (layer, plane) in &denoised.layers {
            assert_eq!(plane.as_slice(), frame.layer(*layer));
        }
    }

    #[test]
    fn a_layer_with_a_negligible_share_of_the_noise_is_written_as_rendered_and_not_filtered() {
        let direct = noisy(&clean(), 5);
        // The noise of 4 samples of value / 0.5 with probability 0.5: relative variance 1/4;
        // the specular layer's a thousandth of that.
        let frame = frame_with_noise(&direct, 0.25, 2.5e-4);
        let written = [Layer::Direct, Layer::Specular];
        let denoised = denoise_frame(&frame, &written, false, four_samples(), Quality::Fast, Some(2), false).unwrap();
        assert_eq!(
            denoised.names(),
            ["direct_denoised", "specular_denoised", "denoised"],
            "the layer set stays the same for a compositor's script"
        );
        assert_eq!(denoised.filtered(), [Layer::Direct]);
        assert_eq!(denoised.left_raw.len(), 1);
        let (layer, why) = denoised.left_raw[0];
        assert!(
            layer == Layer::Specular && matches!(why, LeftRaw::SmallShare(s) if s < NEGLIGIBLE_NOISE_SHARE),
            "{why:?}"
        );
        assert_eq!(denoised.layers[1].1, frame.layer(Layer::Specular));
        assert!(rmse(&denoised.layers[0].1, &clean()) < rmse(&direct, &clean()) / 2.0);
        // With the specular light as noisy as the direct, both are filtered.
        let frame = frame_with_noise(&direct, 0.25, 0.25);
        let denoised = denoise_frame(&frame, &written, false, four_samples(), Quality::Fast, Some(2), false).unwrap();
        assert_eq!(denoised.filtered(), [Layer::Direct, Layer::Specular]);
        assert!(denoised.left_raw.is_empty());
    }
}

//! `--denoise`: the noisy lighting layers and the composite, denoised by Intel Open Image
//! Denoise's "RT" filter (src/sys/oidn.rs), optionally guided by albedo and normal planes.
//!
//! Which layers are noisy, and denoised:
//! - `direct`: shadow rays sample the lights (and, with `--direct analytic`, how much of an
//!   exactly computed irradiance gets through): Monte Carlo noise in penumbrae and with many
//!   lights;
//! - `specular`: glossy reflection and transmission sample their lobes: Monte Carlo noise;
//! - `indirect`: the cache's records are Monte Carlo estimates of their hemispheres, and with
//!   `-aa 0` every pixel samples its own; interpolated records leave smooth, low-frequency
//!   errors, which are not the per-pixel noise the denoiser was trained to remove (README);
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
//! Guides are prefiltered once per image, as OIDN recommends for guides that may carry noise
//! (each by an RT filter of its own), and every colour plane is then filtered with `cleanAux`.

use super::framebuffer::{FrameBuffer, Layer};
pub use crate::sys::oidn::Quality;
use crate::sys::oidn::{Device, RtFilter};
use glam::Vec3;
use std::time::Instant;

/// The layers that carry Monte Carlo noise (see the module's comment), in the order written.
pub const NOISY_LAYERS: [Layer; 3] = [Layer::Direct, Layer::Specular, Layer::Indirect];

/// The EXR layer a denoised layer is written as: `<layer>.denoised`, beside the raw one.
pub fn denoised_name(layer: Layer) -> String {
    format!("{}.denoised", layer.name())
}

/// The EXR layer of the denoised composite: the raw emission plus the denoised layers (the raw
/// composite stays in R G B A).
pub const DENOISED_COMPOSITE: &str = "denoised";

/// Guide planes, one value a pixel: the albedo (reflectance, in [0, 1]) and the normal (unit
/// vectors, or zero where the eye ray hit nothing) of what each pixel sees.
#[derive(Clone, Copy)]
pub struct Guides<'a> {
    pub albedo: &'a [Vec3],
    pub normal: &'a [Vec3],
}

/// The guides `frame` carries: the albedo and normal of its data layers (gathered from the
/// beauty's own camera samples whatever `--aovs` writes), one value a pixel; None for a frame
/// without them.
pub fn guide_planes(frame: &FrameBuffer) -> Option<(Vec<Vec3>, Vec<Vec3>)> {
    let data = frame.data();
    if data.len() != frame.width as usize * frame.height as usize {
        return None;
    }
    Some((
        data.iter().map(|d| d.albedo).collect(),
        data.iter().map(|d| d.normal).collect(),
    ))
}

fn floats(plane: &[Vec3]) -> Vec<f32> {
    plane.iter().flat_map(|v| v.to_array()).collect()
}

fn vectors(floats: &[f32]) -> Vec<Vec3> {
    floats.chunks_exact(3).map(Vec3::from_slice).collect()
}

/// Guides after prefiltering, ready for every colour plane of the image.
pub struct CleanGuides {
    albedo: Vec<f32>,
    normal: Vec<f32>,
}

/// A committed OIDN device and the quality its filters run at.
pub struct Denoiser {
    device: Device,
    quality: Quality,
}

impl Denoiser {
    /// Opens the library and commits a CPU device (`threads`: None for every core). This is
    /// also the check `--denoise` makes before rendering.
    pub fn new(quality: Quality, threads: Option<usize>) -> Result<Denoiser, String> {
        Ok(Denoiser {
            device: Device::new(threads)?,
            quality,
        })
    }

    /// "Intel Open Image Denoise 2.5.1", for the header.
    pub fn describe(&self) -> String {
        format!("Intel Open Image Denoise {}", self.device.version())
    }

    /// Each guide denoised by a filter of its own (OIDN's prefiltering).
    pub fn prefilter(&self, guides: Guides<'_>, width: u32, height: u32) -> Result<CleanGuides, String> {
        let (albedo, normal) = (floats(guides.albedo), floats(guides.normal));
        let one = |albedo: Option<&[f32]>, normal: Option<&[f32]>| {
            self.device.run(&RtFilter {
                width: width as usize,
                height: height as usize,
                color: None,
                albedo,
                normal,
                hdr: false,
                clean_aux: false,
                quality: self.quality,
            })
        };
        Ok(CleanGuides {
            albedo: one(Some(&albedo), None)?,
            normal: one(None, Some(&normal))?,
        })
    }

    /// One colour plane (linear HDR) denoised, guided by `guides` when given.
    pub fn denoise(
        &self,
        color: &[Vec3],
        guides: Option<&CleanGuides>,
        width: u32,
        height: u32,
    ) -> Result<Vec<Vec3>, String> {
        let color = floats(color);
        let output = self.device.run(&RtFilter {
            width: width as usize,
            height: height as usize,
            color: Some(&color),
            albedo: guides.map(|g| g.albedo.as_slice()),
            normal: guides.map(|g| g.normal.as_slice()),
            hdr: true,
            clean_aux: guides.is_some(),
            quality: self.quality,
        })?;
        Ok(vectors(&output))
    }
}

/// One plane denoised (guides prefiltered first), and the seconds it took, device included.
pub fn denoise_plane(
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

/// What `--denoise` made of a frame.
pub struct DenoisedFrame {
    /// The noisy layers among those written, each denoised.
    pub layers: Vec<(Layer, Vec<Vec3>)>,
    /// The raw emission plus the denoised layers.
    pub composite: Vec<Vec3>,
    /// Whether albedo and normal guides were used.
    pub guided: bool,
    /// "Intel Open Image Denoise 2.5.1".
    pub denoiser: String,
    /// The denoiser's own time: its device, the guides' prefiltering and every filter.
    pub seconds: f64,
}

impl DenoisedFrame {
    /// The EXR layers written, as the header lists them.
    pub fn names(&self) -> Vec<String> {
        self.layers
            .iter()
            .map(|(l, _)| denoised_name(*l))
            .chain(std::iter::once(DENOISED_COMPOSITE.to_string()))
            .collect()
    }
}

/// Denoises the noisy ones of `written` (the layers the EXR will hold), and adds them and the
/// raw emission up into the denoised composite.
pub fn denoise_frame(
    frame: &FrameBuffer,
    written: &[Layer],
    quality: Quality,
    threads: Option<usize>,
) -> Result<DenoisedFrame, String> {
    let start = Instant::now();
    let (w, h) = (frame.width, frame.height);
    let denoiser = Denoiser::new(quality, threads)?;
    let planes = guide_planes(frame);
    let guides = planes.as_ref().map(|(albedo, normal)| Guides { albedo, normal });
    let clean = guides.map(|g| denoiser.prefilter(g, w, h)).transpose()?;
    let mut layers = Vec::new();
    for layer in NOISY_LAYERS.into_iter().filter(|l| written.contains(l)) {
        layers.push((layer, denoiser.denoise(frame.layer(layer), clean.as_ref(), w, h)?));
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
        composite,
        guided: clean.is_some(),
        denoiser: denoiser.describe(),
        seconds: start.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::components::Components;
    use crate::sampling::Rng;

    const W: u32 = 96;
    const H: u32 = 80;

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
    fn a_plane_of_the_wrong_size_is_refused() {
        let plane = vec![Vec3::ONE; 10];
        let err = denoise_plane(&plane, None, 4, 4, Quality::Fast, Some(1)).unwrap_err();
        assert!(err.contains("30 values for 4x4"), "{err}");
    }

    #[test]
    fn a_frame_gets_its_noisy_layers_denoised_not_its_emission_and_they_add_up_to_the_composite() {
        let clean = clean();
        let direct = noisy(&clean, 3);
        let mut frame = FrameBuffer::new(W, H);
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
            frame.set(i as u32 % W, i as u32 / W, &components);
        }
        let written = [Layer::Emission, Layer::Direct];
        let denoised = denoise_frame(&frame, &written, Quality::Fast, Some(2)).unwrap();
        assert_eq!(denoised.names(), ["direct.denoised", "denoised"]);
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
        // The composite is the raw emission plus the denoised layer, exactly.
        for (i, c) in denoised.composite.iter().enumerate() {
            assert_eq!(*c, frame.layer(Layer::Emission)[i] + plane[i]);
        }
    }
}

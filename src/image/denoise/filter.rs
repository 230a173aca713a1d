//! The denoiser's driver: Open Image Denoise's RT filter (src/sys/oidn.rs) run over one plane,
//! or over the noisy patches of one, with the albedo and normal guides given as rendered or
//! prefiltered. Which layers are filtered, and how the output is weighed against the raw
//! layer, is the policy of `super` (`denoise_frame`).

use super::Quality;
use crate::image::framebuffer::FrameBuffer;
use crate::image::noisy_patches::{Patch, Rect, crop, paste};
use crate::sys::oidn::{Device, RtFilter};
use glam::Vec3;

/// Guide planes, one value a pixel: the albedo (reflectance, in [0, 1]) and the normal (unit
/// vectors, or zero where the eye ray hit nothing) of what each pixel sees.
#[derive(Clone, Copy)]
pub struct Guides<'a> {
    pub albedo: &'a [Vec3],
    pub normal: &'a [Vec3],
}

/// Whether `frame` has its data layers (one `PixelData` a pixel): the guides and the pixels'
/// measured noise.
pub(super) fn carries_data(frame: &FrameBuffer) -> bool {
    frame.data().len() == frame.width as usize * frame.height as usize
}

/// The guides `frame` carries: the albedo and normal of its data layers (gathered from the
/// beauty's own camera samples whatever `--aovs` writes), one value a pixel; None for a frame
/// without them.
pub fn guide_planes(frame: &FrameBuffer) -> Option<(Vec<Vec3>, Vec<Vec3>)> {
    if !carries_data(frame) {
        return None;
    }
    let data = frame.data();
    Some((
        data.iter().map(|d| d.albedo).collect(),
        data.iter().map(|d| d.normal).collect(),
    ))
}

pub(super) fn floats(plane: &[Vec3]) -> Vec<f32> {
    plane.iter().flat_map(|v| v.to_array()).collect()
}

pub(super) fn vectors(floats: &[f32]) -> Vec<Vec3> {
    floats.chunks_exact(3).map(Vec3::from_slice).collect()
}

/// Guides ready for every colour plane of the image.
pub struct FilterGuides {
    pub(super) albedo: Vec<f32>,
    pub(super) normal: Vec<f32>,
    /// Prefiltered, and so given to the filter as clean (`cleanAux`).
    pub(super) clean: bool,
}

impl FilterGuides {
    /// The guides on `rect` of an image `width` wide: a patch's.
    fn crop(&self, width: usize, rect: Rect) -> FilterGuides {
        FilterGuides {
            albedo: crop(&self.albedo, width, 3, rect),
            normal: crop(&self.normal, width, 3, rect),
            clean: self.clean,
        }
    }
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
    pub fn prefilter(&self, guides: Guides<'_>, width: u32, height: u32) -> Result<FilterGuides, String> {
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
        Ok(FilterGuides {
            albedo: one(Some(&albedo), None)?,
            normal: one(None, Some(&normal))?,
            clean: true,
        })
    }

    /// The guides as the filter takes them: prefiltered when asked (`--denoise-prefilter`), else
    /// as rendered. A frame's guides come from the first hits of the camera samples (perfect
    /// mirrors followed exactly), so they carry no Monte Carlo noise for a prefilter to remove,
    /// and prefiltering cost more than it gave: OIDN 2.5.1 at 320x240, the peers bench's fastest
    /// settings, relMSE of the denoised composite against the converged reference, prefiltered
    /// / as rendered: Sibenik 2.96e-2 / 1.98e-2 (raw 2.03e-2: the prefilter blurred thin dark
    /// tracery into its bright surround, and the filter lit it), the conference room 1.96e-2 /
    /// 2.02e-2, the Cornell box (256x256) 7.4e-4 / 8.8e-4, for twice the denoiser's time.
    ///
    /// As rendered they are still not the converged image's albedo and normal: at a few
    /// samples a pixel an edge crossing it is resolved as coarsely in the guides as in the
    /// light, and a filter told the guides are clean keeps what they show, that coarseness
    /// included. So they go in as guides that may be noisy (`cleanAux` off), and the filter
    /// smooths it with the noise. Measured (the peers bench's settings, two seeds each, relMSE /
    /// 4x4 relMSE of the denoised composite, given as clean -> as may be noisy): the conference
    /// room 8.50e-3 / 2.48e-3 -> 7.93e-3 / 2.40e-3 at 4 samples a pixel, 7.54e-3 / 1.78e-3 ->
    /// 6.97e-3 / 1.69e-3 at 4, 5.04e-3 / 1.05e-3 -> 4.91e-3 / 1.04e-3 at 8; the Cornell box
    /// 7.23e-4 -> 7.14e-4 at 2, 1.94e-4 -> 1.92e-4 at 8, 1.23e-4 -> 1.22e-4 at 16 (4x4 equal
    /// or lower); Sibenik's nave 1.456e-2 -> 1.426e-2 and 1.301e-2 -> 1.270e-2 at 4, 7.14e-3
    /// -> 7.08e-3 at 8.
    pub fn guides(&self, guides: Guides<'_>, width: u32, height: u32, prefilter: bool) -> Result<FilterGuides, String> {
        if prefilter {
            return self.prefilter(guides, width, height);
        }
        Ok(FilterGuides {
            albedo: floats(guides.albedo),
            normal: floats(guides.normal),
            clean: false,
        })
    }

    /// One colour plane (linear HDR) denoised, guided by `guides` when given.
    pub fn denoise(
        &self,
        color: &[Vec3],
        guides: Option<&FilterGuides>,
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
            clean_aux: guides.is_some_and(|g| g.clean),
            quality: self.quality,
        })?;
        Ok(vectors(&output))
    }

    /// `color` denoised on `patches` only (each seen with its margin, its output kept on its
    /// kept rectangle), the raw value elsewhere.
    pub fn denoise_patches(
        &self,
        color: &[Vec3],
        guides: Option<&FilterGuides>,
        width: u32,
        patches: &[Patch],
    ) -> Result<Vec<Vec3>, String> {
        let w = width as usize;
        let mut out = color.to_vec();
        for patch in patches {
            let seen = patch.seen;
            let guides = guides.map(|g| g.crop(w, seen));
            let filtered = self.denoise(
                &crop(color, w, 1, seen),
                guides.as_ref(),
                seen.width() as u32,
                seen.height() as u32,
            )?;
            paste(&mut out, w, patch, &filtered);
        }
        Ok(out)
    }
}

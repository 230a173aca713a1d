//! The PNG preview: the composite exposed so its log-average luminance sits at middle grey,
//! compressed by Reinhard's curve, encoded as sRGB. A preview only; the EXR holds the numbers.

use crate::scene::light::luminance;
use glam::Vec3;

const MIDDLE_GREY: f32 = 0.18;

pub fn tone_map(pixels: &[Vec3]) -> Vec<u8> {
    tone_map_each(pixels.len(), |i| pixels[i])
}

/// `tone_map` of the `count` pixels `pixel` gives by index, made on the fly: no copy of the
/// image is held but the 8-bit result (a frame's composite is its layers' sum, computed twice
/// here rather than kept: 100 MB at 4K). On every core: the preview is made after the last
/// tile, and at 4K one thread took about 0.4 s.
pub fn tone_map_each(count: usize, pixel: impl Fn(usize) -> Vec3 + Sync) -> Vec<u8> {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get()).min(16);
    let chunk = count.div_ceil(threads).max(1);
    let ranges: Vec<std::ops::Range<usize>> = (0..count).step_by(chunk).map(|a| a..(a + chunk).min(count)).collect();
    let (log_sum, lit) = std::thread::scope(|scope| {
        let parts: Vec<_> = ranges
            .iter()
            .map(|range| {
                let pixel = &pixel;
                scope.spawn(move || {
                    let (mut log_sum, mut lit) = (0.0f64, 0usize);
                    for i in range.clone() {
                        let l = luminance(pixel(i));
                        if l.is_finite() && l > 0.0 {
                            log_sum += (l.max(1e-8) as f64).ln();
                            lit += 1;
                        }
                    }
                    (log_sum, lit)
                })
            })
            .collect();
        // Summed in the ranges' order: the exposure does not depend on the threads' timing.
        parts
            .into_iter()
            .map(|p| p.join().expect("a preview thread panicked"))
            .fold((0.0, 0), |a, b| (a.0 + b.0, a.1 + b.1))
    });
    let exposure = if lit == 0 {
        1.0
    } else {
        MIDDLE_GREY / ((log_sum / lit as f64).exp() as f32)
    };
    let mut out = vec![0u8; count * 3];
    std::thread::scope(|scope| {
        for (range, bytes) in ranges.iter().zip(out.chunks_mut(chunk * 3)) {
            let pixel = &pixel;
            scope.spawn(move || {
                for (i, rgb) in range.clone().zip(bytes.chunks_exact_mut(3)) {
                    let v = pixel(i) * exposure;
                    let mapped = if v.is_finite() { v / (Vec3::ONE + v) } else { Vec3::ZERO };
                    for (byte, c) in rgb.iter_mut().zip(mapped.to_array()) {
                        *byte = (linear_to_srgb(c.clamp(0.0, 1.0)) * 255.0 + 0.5) as u8;
                    }
                }
            });
        }
    });
    out
}

/// The composite kept for the preview while the EXR is streamed: four bytes a pixel (a shared
/// exponent and three 8-bit mantissas, Radiance's RGBE) instead of the twelve of a float RGB, so
/// 33 MB at 4K. About 1% of precision, below what an 8-bit preview shows.
#[derive(Clone, Debug)]
pub struct PreviewBuffer {
    pub width: u32,
    pub height: u32,
    pixels: Vec<[u8; 4]>,
}

impl PreviewBuffer {
    pub fn new(width: u32, height: u32) -> PreviewBuffer {
        PreviewBuffer {
            width,
            height,
            pixels: vec![[0; 4]; width as usize * height as usize],
        }
    }

    /// Keeps pixel `i` (row-major) as `rgb` (negative, NaN and infinite parts as 0).
    pub fn set(&mut self, i: usize, rgb: Vec3) {
        let rgb = Vec3::from_array(rgb.to_array().map(|c| if c.is_finite() { c.max(0.0) } else { 0.0 }));
        let largest = rgb.max_element();
        self.pixels[i] = if largest < 1e-32 {
            [0; 4]
        } else {
            // largest = m * 2^e with m in [0.5, 1): the mantissas are the parts * 256 / 2^e.
            let e = largest.log2().floor() as i32 + 1;
            let scale = (2.0f32).powi(8 - e);
            let m = (rgb * scale).to_array().map(|c| c.min(255.0) as u8);
            [m[0], m[1], m[2], (e + 128).clamp(1, 255) as u8]
        };
    }

    /// Pixel `i` as kept.
    pub fn get(&self, i: usize) -> Vec3 {
        let [r, g, b, e] = self.pixels[i];
        if e == 0 {
            return Vec3::ZERO;
        }
        let scale = (2.0f32).powi(e as i32 - 128 - 8);
        (Vec3::new(r as f32, g as f32, b as f32) + 0.5) * scale
    }

    pub fn len(&self) -> usize {
        self.pixels.len()
    }

    pub fn is_empty(&self) -> bool {
        self.pixels.is_empty()
    }
}

fn linear_to_srgb(c: f32) -> f32 {
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn maps_black_nan_and_bright_into_range() {
        let px = [Vec3::ZERO, Vec3::splat(f32::NAN), Vec3::splat(1e30), Vec3::splat(0.5)];
        let out = tone_map(&px);
        assert_eq!(out.len(), 12);
        assert_eq!(&out[0..3], &[0, 0, 0]);
        assert_eq!(&out[3..6], &[0, 0, 0]);
        assert!(out[6] >= 254);
    }

    #[test]
    fn the_reduced_copy_keeps_a_pixel_within_one_percent() {
        let mut kept = PreviewBuffer::new(4, 1);
        let values = [
            Vec3::new(0.25, 1.0, 3.5),
            Vec3::new(1e-6, 0.0, 2e-6),
            Vec3::splat(7e4),
            Vec3::ZERO,
        ];
        for (i, v) in values.iter().enumerate() {
            kept.set(i, *v);
        }
        for (i, v) in values.iter().enumerate() {
            let back = kept.get(i);
            let largest = v.max_element();
            assert!(
                (back - *v).abs().max_element() <= 0.01 * largest + 1e-30,
                "{v} came back as {back}"
            );
        }
        kept.set(3, Vec3::new(f32::NAN, -1.0, f32::INFINITY));
        assert_eq!(kept.get(3), Vec3::ZERO);
    }
}

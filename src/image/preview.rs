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
/// here rather than kept: 100 MB at 4K).
pub fn tone_map_each(count: usize, pixel: impl Fn(usize) -> Vec3) -> Vec<u8> {
    let (mut log_sum, mut lit) = (0.0f64, 0usize);
    for i in 0..count {
        let l = luminance(pixel(i));
        if l.is_finite() && l > 0.0 {
            log_sum += (l.max(1e-8) as f64).ln();
            lit += 1;
        }
    }
    let exposure = if lit == 0 {
        1.0
    } else {
        MIDDLE_GREY / ((log_sum / lit as f64).exp() as f32)
    };
    let mut out = Vec::with_capacity(count * 3);
    for i in 0..count {
        let v = pixel(i) * exposure;
        let mapped = if v.is_finite() { v / (Vec3::ONE + v) } else { Vec3::ZERO };
        for c in mapped.to_array() {
            out.push((linear_to_srgb(c.clamp(0.0, 1.0)) * 255.0 + 0.5) as u8);
        }
    }
    out
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
}

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
pub fn tone_map_each(count: usize, pixel: impl Fn(usize) -> Vec3 + Sync) -> Vec<u8> {
    let log = on_every_core(count, |range| {
        let mut log = LogLuminance::default();
        range.for_each(|i| log.add(pixel(i)));
        log
    })
    .into_iter()
    .fold(LogLuminance::default(), LogLuminance::merged);
    map_each(count, log.exposure(), pixel)
}

/// The sum of the pixels' log luminance (of those lit), which sets the exposure. Fixed point:
/// the sum is the same in whatever order the pixels come (a streamed frame's tiles come in the
/// order they finish), so the preview does not depend on the threads' timing.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LogLuminance {
    /// Sum of ln(luminance) * 2^32.
    sum: i128,
    lit: u64,
}

impl LogLuminance {
    pub fn add(&mut self, rgb: Vec3) {
        let l = luminance(rgb);
        if l.is_finite() && l > 0.0 {
            self.sum += ((l.max(1e-8) as f64).ln() * 4_294_967_296.0).round() as i128;
            self.lit += 1;
        }
    }

    /// The sum and the count of lit pixels, as a message carries them.
    pub fn parts(&self) -> (i128, u64) {
        (self.sum, self.lit)
    }

    pub fn from_parts(sum: i128, lit: u64) -> LogLuminance {
        LogLuminance { sum, lit }
    }

    pub fn merged(self, other: LogLuminance) -> LogLuminance {
        LogLuminance {
            sum: self.sum + other.sum,
            lit: self.lit + other.lit,
        }
    }

    /// What puts the log-average luminance at middle grey (1 when nothing is lit).
    pub fn exposure(&self) -> f32 {
        if self.lit == 0 {
            return 1.0;
        }
        let mean = self.sum as f64 / 4_294_967_296.0 / self.lit as f64;
        MIDDLE_GREY / (mean.exp() as f32)
    }
}

/// The 8-bit sRGB pixels of the `count` pixels `pixel` gives, times `exposure`, compressed by
/// Reinhard's curve, on every core.
fn map_each(count: usize, exposure: f32, pixel: impl Fn(usize) -> Vec3 + Sync) -> Vec<u8> {
    let mut out = vec![0u8; count * 3];
    let chunk = count.div_ceil(cores()).max(1);
    std::thread::scope(|scope| {
        for (k, bytes) in out.chunks_mut(chunk * 3).enumerate() {
            let pixel = &pixel;
            scope.spawn(move || {
                for (i, rgb) in (k * chunk..).zip(bytes.chunks_exact_mut(3)) {
                    let v = pixel(i) * exposure;
                    let mapped = if v.is_finite() { v / (Vec3::ONE + v) } else { Vec3::ZERO };
                    for (byte, c) in rgb.iter_mut().zip(mapped.to_array()) {
                        *byte = srgb_byte(c);
                    }
                }
            });
        }
    });
    out
}

fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get()).min(16)
}

/// `work` over the `count` indices cut into a range per core, the results in the ranges' order.
fn on_every_core<T: Send>(count: usize, work: impl Fn(std::ops::Range<usize>) -> T + Sync) -> Vec<T> {
    let chunk = count.div_ceil(cores()).max(1);
    std::thread::scope(|scope| {
        let parts: Vec<_> = (0..count)
            .step_by(chunk)
            .map(|a| {
                let work = &work;
                scope.spawn(move || work(a..(a + chunk).min(count)))
            })
            .collect();
        parts
            .into_iter()
            .map(|p| p.join().expect("a preview thread panicked"))
            .collect()
    })
}

/// A value in [0, 1] (clamped) as an 8-bit sRGB byte, from a table of 2^16 steps: the curve's
/// steepest slope (12.92 at black) moves a byte by at most 0.05 between steps, where computing
/// the curve for each of a frame's values took most of an 8K preview's time.
fn srgb_byte(c: f32) -> u8 {
    static TABLE: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
    let table = TABLE.get_or_init(|| {
        (0..=u16::MAX)
            .map(|k| (linear_to_srgb(k as f32 / u16::MAX as f32) * 255.0 + 0.5) as u8)
            .collect()
    });
    table[(c.clamp(0.0, 1.0) * u16::MAX as f32 + 0.5) as usize]
}

/// `rgb` in four bytes (negative, NaN and infinite parts as 0): a shared exponent and three
/// 8-bit mantissas.
pub fn rgbe(rgb: Vec3) -> [u8; 4] {
    let rgb = Vec3::from_array(rgb.to_array().map(|c| if c.is_finite() { c.max(0.0) } else { 0.0 }));
    let largest = rgb.max_element();
    if largest < 1e-32 {
        return [0; 4];
    }
    // largest = m * 2^e with m in [0.5, 1): the mantissas are the parts * 256 / 2^e.
    let e = largest.log2().floor() as i32 + 1;
    let scale = (2.0f32).powi(8 - e);
    let m = (rgb * scale).to_array().map(|c| c.min(255.0) as u8);
    [m[0], m[1], m[2], (e + 128).clamp(1, 255) as u8]
}

/// The composite kept for the preview while the EXR is streamed: four bytes a pixel (a shared
/// exponent and three 8-bit mantissas, Radiance's RGBE) instead of the twelve of a float RGB, so
/// 33 MB at 4K. About 1% of precision, below what an 8-bit preview shows.
#[derive(Clone, Debug)]
pub struct PreviewBuffer {
    pub width: u32,
    pub height: u32,
    pixels: Vec<[u8; 4]>,
    /// The exact pixels' log luminance, summed as they come: the exposure needs no pass over
    /// the frame at the end.
    log: LogLuminance,
}

impl PreviewBuffer {
    pub fn new(width: u32, height: u32) -> PreviewBuffer {
        PreviewBuffer {
            width,
            height,
            pixels: vec![[0; 4]; width as usize * height as usize],
            log: LogLuminance::default(),
        }
    }

    /// Keeps pixel `i` (row-major) as `rgb` (negative, NaN and infinite parts as 0).
    pub fn set(&mut self, i: usize, rgb: Vec3) {
        self.log.add(rgb);
        self.pixels[i] = rgbe(rgb);
    }

    /// Keeps pixel `i` as `rgbe` made elsewhere (a tile encoded where it was rendered), whose
    /// log luminance comes with `add_log`.
    pub fn put(&mut self, i: usize, rgbe: [u8; 4]) {
        self.pixels[i] = rgbe;
    }

    /// Adds the log luminance of pixels kept with `put`.
    pub fn add_log(&mut self, log: LogLuminance) {
        self.log = self.log.merged(log);
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

    /// The preview's 8-bit pixels, exposed by the exact pixels' log luminance. Each pixel must
    /// have been set once.
    pub fn tone_map(&self) -> Vec<u8> {
        map_each(self.pixels.len(), self.log.exposure(), |i| self.get(i))
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
    fn the_exposure_does_not_depend_on_the_pixels_order() {
        let pixels: Vec<Vec3> = (0..1000)
            .map(|i| Vec3::new(0.001 * i as f32, 0.3, 1e3 / (1 + i) as f32))
            .collect();
        let sum = |pixels: &mut dyn Iterator<Item = &Vec3>| {
            pixels.fold(LogLuminance::default(), |mut l, p| {
                l.add(*p);
                l
            })
        };
        let forward = sum(&mut pixels.iter());
        assert_eq!(forward, sum(&mut pixels.iter().rev()));
        let mean = pixels.iter().map(|p| (luminance(*p) as f64).ln()).sum::<f64>() / 1000.0;
        assert!((forward.exposure() - MIDDLE_GREY / mean.exp() as f32).abs() < 1e-5);
        // The table's bytes are the curve's, to the rounding.
        for k in 0..=1000 {
            let c = k as f32 / 1000.0;
            let exact = linear_to_srgb(c) * 255.0 + 0.5;
            assert!((srgb_byte(c) as f32 - exact).abs() <= 1.0, "{c}");
        }
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

//! The PNG preview: the composite exposed so its log-average luminance sits at middle grey,
//! compressed by Reinhard's curve, encoded as sRGB. A preview only; the EXR holds the numbers.

use crate::scene::light::luminance;
use glam::Vec3;

const MIDDLE_GREY: f32 = 0.18;

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
    let rgb = sanitized(rgb);
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

/// Most pixels a preview has. A larger frame's preview is the frame box-filtered down by the
/// smallest whole factor that fits (a 4K frame's is 1920x1080, an 8K frame's 2560x1440), so what a
/// streamed frame keeps for it stays under 50 MB whatever the frame's size. The EXR holds every
/// pixel; the preview is for looking.
pub const PREVIEW_MAX_PIXELS: usize = 1 << 22;

/// What the preview keeps of each of its pixels.
#[derive(Clone, Debug)]
enum Kept {
    /// A frame small enough for a pixel a pixel: four bytes each (a shared exponent and three
    /// 8-bit mantissas, Radiance's RGBE) instead of twelve, about 1% of precision, below what
    /// an 8-bit preview shows.
    Exact(Vec<[u8; 4]>),
    /// A larger frame: the sum of the pixels of each factor x factor block.
    Reduced(Vec<[f32; 3]>),
}

/// The composite kept for the preview while the EXR is streamed (or made from a frame held
/// whole): at the frame's size up to `PREVIEW_MAX_PIXELS`, reduced beyond.
#[derive(Clone, Debug)]
pub struct PreviewBuffer {
    /// The preview's size.
    pub width: u32,
    pub height: u32,
    /// The frame's width, and how many of its pixels a preview pixel's side spans.
    frame_width: u32,
    frame_height: u32,
    factor: u32,
    kept: Kept,
    /// The exact pixels' log luminance, summed as they come: the exposure needs no pass over
    /// the frame at the end.
    log: LogLuminance,
}

impl PreviewBuffer {
    /// The preview of a `width` x `height` frame.
    pub fn new(width: u32, height: u32) -> PreviewBuffer {
        let factor = reduction(width, height);
        let (pw, ph) = (width.div_ceil(factor), height.div_ceil(factor));
        let n = pw as usize * ph as usize;
        PreviewBuffer {
            width: pw,
            height: ph,
            frame_width: width,
            frame_height: height,
            factor,
            kept: if factor == 1 {
                Kept::Exact(vec![[0; 4]; n])
            } else {
                Kept::Reduced(vec![[0.0; 3]; n])
            },
            log: LogLuminance::default(),
        }
    }

    /// The preview pixel frame pixel `i` (row-major) falls in.
    fn cell(&self, i: usize) -> usize {
        let w = self.frame_width as usize;
        let (x, y) = (i % w, i / w);
        let k = self.factor as usize;
        (y / k) * self.width as usize + x / k
    }

    /// Keeps frame pixel `i` (row-major) as `rgb` (negative, NaN and infinite parts as 0).
    pub fn set(&mut self, i: usize, rgb: Vec3) {
        self.log.add(rgb);
        let cell = self.cell(i);
        match &mut self.kept {
            Kept::Exact(pixels) => pixels[cell] = rgbe(rgb),
            Kept::Reduced(sums) => add(&mut sums[cell], sanitized(rgb)),
        }
    }

    /// Keeps frame pixel `i` as `rgbe` made elsewhere (a tile encoded where it was rendered),
    /// whose log luminance comes with `add_log`.
    pub fn put(&mut self, i: usize, rgbe: [u8; 4]) {
        let cell = self.cell(i);
        match &mut self.kept {
            Kept::Exact(pixels) => pixels[cell] = rgbe,
            Kept::Reduced(sums) => add(&mut sums[cell], from_rgbe(rgbe)),
        }
    }

    /// Adds the log luminance of pixels kept with `put`.
    pub fn add_log(&mut self, log: LogLuminance) {
        self.log = self.log.merged(log);
    }

    /// Preview pixel `j`: the frame's pixel, or its block's mean.
    pub fn get(&self, j: usize) -> Vec3 {
        match &self.kept {
            Kept::Exact(pixels) => from_rgbe(pixels[j]),
            Kept::Reduced(sums) => {
                let (px, py) = (j as u32 % self.width, j as u32 / self.width);
                let k = self.factor;
                // A block at the right or bottom edge is cut by the frame's.
                let covered = (k.min(self.frame_width - px * k) * k.min(self.frame_height - py * k)) as f32;
                Vec3::from_array(sums[j]) / covered
            }
        }
    }

    /// The preview's pixels.
    pub fn len(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// The preview's 8-bit pixels, exposed by the exact pixels' log luminance. Each frame pixel
    /// must have been set once.
    pub fn tone_map(&self) -> Vec<u8> {
        map_each(self.len(), self.log.exposure(), |j| self.get(j))
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The smallest whole factor that brings a `width` x `height` frame within `PREVIEW_MAX_PIXELS`.
fn reduction(width: u32, height: u32) -> u32 {
    let mut k = 1u32;
    while width.div_ceil(k) as usize * height.div_ceil(k) as usize > PREVIEW_MAX_PIXELS {
        k += 1;
    }
    k
}

/// `rgb` with negative, NaN and infinite parts as 0.
fn sanitized(rgb: Vec3) -> Vec3 {
    Vec3::from_array(rgb.to_array().map(|c| if c.is_finite() { c.max(0.0) } else { 0.0 }))
}

fn add(sum: &mut [f32; 3], rgb: Vec3) {
    for (s, c) in sum.iter_mut().zip(rgb.to_array()) {
        *s += c;
    }
}

/// The value `rgbe` keeps (the middle of its step).
fn from_rgbe([r, g, b, e]: [u8; 4]) -> Vec3 {
    if e == 0 {
        return Vec3::ZERO;
    }
    let scale = (2.0f32).powi(e as i32 - 128 - 8);
    (Vec3::new(r as f32, g as f32, b as f32) + 0.5) * scale
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
        let mut kept = PreviewBuffer::new(4, 1);
        px.iter().enumerate().for_each(|(i, p)| kept.set(i, *p));
        let out = kept.tone_map();
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
    fn a_frame_beyond_the_budget_is_reduced_by_the_smallest_whole_factor() {
        for ((w, h), (pw, ph)) in [
            ((1920, 1080), (1920, 1080)),
            ((2048, 2048), (2048, 2048)),
            ((3840, 2160), (1920, 1080)),
            ((7680, 4320), (2560, 1440)),
            ((4097, 1025), (2049, 513)),
        ] {
            let preview = PreviewBuffer::new(w, h);
            assert_eq!((preview.width, preview.height), (pw, ph), "{w}x{h}");
            assert!(preview.len() <= PREVIEW_MAX_PIXELS);
        }
    }

    #[test]
    fn a_reduced_preview_pixel_is_its_blocks_mean_and_the_exposure_the_frames() {
        // 4100 x 1025 pixels, just over the budget, reduce by 2; the last row of blocks is cut
        // to the frame's one last row.
        let (w, h) = (4100u32, 1025u32);
        let mut preview = PreviewBuffer::new(w, h);
        assert_eq!((preview.width, preview.height, preview.factor), (2050, 513, 2));
        let value = |x: u32, y: u32| Vec3::new(x as f32, y as f32, 1.0 + (x + y) as f32);
        let mut exact = LogLuminance::default();
        for y in 0..h {
            for x in 0..w {
                let i = (y * w + x) as usize;
                exact.add(value(x, y));
                // Half the pixels come as a worker sends them (RGBE, their log apart).
                if (x + y) % 2 == 0 {
                    preview.set(i, value(x, y));
                } else {
                    let mut one = LogLuminance::default();
                    one.add(value(x, y));
                    preview.put(i, rgbe(value(x, y)));
                    preview.add_log(one);
                }
            }
        }
        assert_eq!(preview.log, exact, "the exposure is the full frame's");
        // A whole block (2x2 at (10, 7)) and the last row's blocks, cut to one frame row.
        let block = (value(20, 14) + value(21, 14) + value(20, 15) + value(21, 15)) / 4.0;
        let got = preview.get(7 * 2050 + 10);
        assert!(
            (got - block).abs().max_element() <= 0.01 * block.max_element(),
            "{got} against {block}"
        );
        let cut = (value(40, 1024) + value(41, 1024)) / 2.0;
        let got = preview.get(512 * 2050 + 20);
        assert!(
            (got - cut).abs().max_element() <= 0.01 * cut.max_element(),
            "{got} against {cut}"
        );
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

//! Base-colour textures: 8-bit RGBA kept as it was stored and decoded to linear floats by a
//! table as each texel is read, sampled bilinearly with the glTF sampler's wrap modes. Kept as
//! bytes, a texture takes a quarter of the memory of one decoded to floats, and the texel reads
//! of hemisphere rays, which land anywhere on it, miss the processor's caches less: with float
//! texels, on Sibenik (three 512x512 textures) at -ab 2, sampling was 9.6 % of the render, 85 %
//! of it waiting for the texel loads.
//!
//! A ray that stands for a whole cell of a record's hemisphere reads the texture averaged over
//! its footprint (`sample_footprint`): a mip pyramid of linear 2x2 means, each level half the
//! size of the one above. The cell's radiance is the mean over the cell, so the averaged
//! albedo is what the ray should see; it has less variance than one texel, and the coarse
//! levels it reads are small enough to stay in the processor's caches. Where the last bounce's
//! grid answers a cell ray from its hit alone, the hit reads one texel of that level
//! (`sample_cell`) rather than four.

use crate::sys::scene_io::GltfTexture;
use glam::Vec4;

const WRAP_CLAMP: i32 = 33071;
const WRAP_MIRROR: i32 = 33648;

/// A level of the pyramid below the stored image: linear RGBA in 16-bit fixed point (the
/// means of 8-bit sRGB texels need more than 8 bits to stay unbiased in the dark).
#[derive(Clone, Debug)]
struct MipLevel {
    width: u32,
    height: u32,
    texels: Vec<[u16; 4]>,
}

#[derive(Clone, Debug)]
pub struct Texture {
    pub name: String,
    width: u32,
    height: u32,
    texels: Vec<[u8; 4]>,
    /// A stored colour byte's linear value (sRGB decoded, or not, as the glTF says).
    decode: Box<[f32; 256]>,
    /// Level 1 (half the size) down to 1x1.
    mips: Vec<MipLevel>,
    wrap_s: i32,
    wrap_t: i32,
}

fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

fn wrap(coord: i64, size: u32, mode: i32) -> usize {
    let n = size as i64;
    let i = match mode {
        WRAP_CLAMP => coord.clamp(0, n - 1),
        WRAP_MIRROR => {
            let period = coord.rem_euclid(2 * n);
            if period < n { period } else { 2 * n - 1 - period }
        }
        // Repeat. A power-of-two size (most textures) wraps by a mask, which is the Euclidean
        // remainder in two's complement, where the remainder is a 64-bit division.
        _ if size.is_power_of_two() => coord & (n - 1),
        _ => coord.rem_euclid(n),
    };
    i as usize
}

const UNIT16: f32 = 65535.0;

fn to_unit16(v: Vec4) -> [u16; 4] {
    v.to_array().map(|c| (c.clamp(0.0, 1.0) * UNIT16).round() as u16)
}

fn from_unit16(t: [u16; 4]) -> Vec4 {
    Vec4::from_array(t.map(|c| c as f32)) * (1.0 / UNIT16)
}

/// The level below one of `width` x `height` texels read by `texel`: each texel the mean of
/// the (up to) 2x2 above it; an odd last row or column is folded into its neighbour's mean.
fn halve(width: u32, height: u32, texel: impl Fn(usize) -> Vec4) -> MipLevel {
    let (w, h) = ((width / 2).max(1), (height / 2).max(1));
    // Texel i of the level covers 2i and 2i + 1 above it; the last one takes what is left (3
    // where the size is odd, the 1 of a size of 1).
    let span = |i: u32, size: u32, half: u32| 2 * i..if i + 1 == half { size } else { 2 * i + 2 };
    let mut texels = Vec::with_capacity((w * h) as usize);
    for y in 0..h {
        for x in 0..w {
            let (mut sum, mut n) = (Vec4::ZERO, 0.0);
            for sy in span(y, height, h) {
                for sx in span(x, width, w) {
                    sum += texel((sy * width + sx) as usize);
                    n += 1.0;
                }
            }
            texels.push(to_unit16(sum / n));
        }
    }
    MipLevel {
        width: w,
        height: h,
        texels,
    }
}

/// Bilinear interpolation of the texels `at(column, row)` of a `width` x `height` image at
/// glTF coordinates `uv` (origin at the top-left), with the wrap modes given.
fn bilinear(
    uv: [f32; 2],
    (width, height): (u32, u32),
    (wrap_s, wrap_t): (i32, i32),
    at: impl Fn(usize) -> Vec4,
) -> Vec4 {
    let x = uv[0] as f64 * width as f64 - 0.5;
    let y = uv[1] as f64 * height as f64 - 0.5;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
    // Clamp far-away coordinates before converting so huge UVs cannot overflow.
    let (x0, y0) = (x0.clamp(-1e15, 1e15) as i64, y0.clamp(-1e15, 1e15) as i64);
    let texel = |xi: i64, yi: i64| {
        let col = wrap(xi, width, wrap_s);
        let row = wrap(yi, height, wrap_t);
        at(row * width as usize + col)
    };
    let top = texel(x0, y0) * (1.0 - fx) + texel(x0 + 1, y0) * fx;
    let bottom = texel(x0, y0 + 1) * (1.0 - fx) + texel(x0 + 1, y0 + 1) * fx;
    top * (1.0 - fy) + bottom * fy
}

/// `x.log2().round()` for a finite or infinite `x` above 1, from the float's bits: its exponent,
/// plus one where the mantissa is at least the square root of two (log2 of the mantissa at
/// least a half). libm's log2f was 0.8 % of a render at -ab 2 (Sibenik), a call per footprint.
fn round_log2(x: f32) -> u32 {
    const SQRT2_MANTISSA: u32 = 0x3504F3;
    let bits = x.to_bits();
    let exponent = ((bits >> 23) & 0xff).saturating_sub(127);
    exponent + u32::from(bits & 0x7f_ffff >= SQRT2_MANTISSA)
}

impl Texture {
    /// Bytes its texels take, the pyramid's included.
    pub fn memory_bytes(&self) -> u64 {
        let mips: usize = self
            .mips
            .iter()
            .map(|m| m.texels.len() * std::mem::size_of::<[u16; 4]>())
            .sum();
        (self.texels.len() * std::mem::size_of::<[u8; 4]>() + mips) as u64
    }

    pub fn from_gltf(t: &GltfTexture) -> Texture {
        let decode = Box::new(std::array::from_fn(|i| {
            if t.srgb {
                srgb_to_linear(i as f32 / 255.0)
            } else {
                i as f32 / 255.0
            }
        }));
        let expected = 4 * t.width as usize * t.height as usize;
        let (width, height, texels) = if t.width == 0 || t.height == 0 || t.rgba.len() != expected {
            // The loader guarantees sizes; a 1x1 white texel keeps sampling total if not.
            (1, 1, vec![[255; 4]])
        } else {
            let texels = t.rgba.chunks_exact(4).map(|p| [p[0], p[1], p[2], p[3]]).collect();
            (t.width, t.height, texels)
        };
        let mut texture = Texture {
            name: t.name.clone(),
            width,
            height,
            texels,
            decode,
            mips: Vec::new(),
            wrap_s: t.wrap_s,
            wrap_t: t.wrap_t,
        };
        let (mut w, mut h) = (width, height);
        while w > 1 || h > 1 {
            let next = match texture.mips.last() {
                None => halve(w, h, |i| texture.texel(i)),
                Some(above) => halve(w, h, |i| from_unit16(above.texels[i])),
            };
            (w, h) = (next.width, next.height);
            texture.mips.push(next);
        }
        texture
    }

    /// Texel `index` in linear floats.
    #[inline(always)]
    fn texel(&self, index: usize) -> Vec4 {
        let [r, g, b, a] = self.texels[index];
        let decode = &self.decode;
        Vec4::new(
            decode[r as usize],
            decode[g as usize],
            decode[b as usize],
            a as f32 / 255.0,
        )
    }

    /// Bilinear sample at glTF texture coordinates (origin at the image's top-left).
    pub fn sample(&self, uv: [f32; 2]) -> Vec4 {
        if !(uv[0].is_finite() && uv[1].is_finite()) {
            return self.texel(0);
        }
        bilinear(uv, (self.width, self.height), (self.wrap_s, self.wrap_t), |i| {
            self.texel(i)
        })
    }

    /// The level whose texels are about `width` wide in texture coordinates (0: the stored
    /// image): the nearest in log2, where a texel's side is the geometric mean of its two.
    fn level_for(&self, width: f32) -> usize {
        let texels = width * ((self.width as f32) * (self.height as f32)).sqrt();
        // Also a NaN footprint: the stored image.
        if texels.is_nan() || texels <= 1.0 {
            return 0;
        }
        (round_log2(texels) as usize).min(self.mips.len())
    }

    /// The texture averaged over a footprint `width` wide in texture coordinates: bilinear in
    /// the pyramid's level whose texels are that wide (`sample` for a footprint of a texel or
    /// less).
    pub fn sample_footprint(&self, uv: [f32; 2], width: f32) -> Vec4 {
        self.in_level(uv, width, |mip| {
            bilinear(uv, (mip.width, mip.height), (self.wrap_s, self.wrap_t), |i| {
                from_unit16(mip.texels[i])
            })
        })
    }

    /// The texture averaged over a footprint `width` wide, as one of many random points of a
    /// hemisphere's cell sees it: the texel under `uv` in the level whose texels are that wide
    /// (the stored image's bilinear sample for a footprint of a texel or less). One texel
    /// where `sample_footprint` blends four: over the cell's random point it is the box mean
    /// of the footprint where the other is a tent, the same mean with a little more variance,
    /// which the record's hundreds of rays average away. Not for camera rays, whose texels
    /// would show as blocks. On Sibenik at -ab 2 the last bounce's reads took 1.5 % less time.
    pub fn sample_cell(&self, uv: [f32; 2], width: f32) -> Vec4 {
        self.in_level(uv, width, |mip| {
            let (w, h) = (mip.width, mip.height);
            let index = |t: f32, size: u32| (t * size as f32).floor().clamp(-1e15, 1e15) as i64;
            let col = wrap(index(uv[0], w), w, self.wrap_s);
            let row = wrap(index(uv[1], h), h, self.wrap_t);
            from_unit16(mip.texels[row * w as usize + col])
        })
    }

    /// What `read` gives at `uv` in the pyramid's level for a footprint `width` wide: the
    /// stored image's bilinear sample where that is the image itself, and the level's first
    /// texel for coordinates that are not finite.
    #[inline]
    fn in_level(&self, uv: [f32; 2], width: f32, read: impl FnOnce(&MipLevel) -> Vec4) -> Vec4 {
        match self.level_for(width) {
            0 => self.sample(uv),
            level if uv[0].is_finite() && uv[1].is_finite() => read(&self.mips[level - 1]),
            level => from_unit16(self.mips[level - 1].texels[0]),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checker() -> Texture {
        Texture::from_gltf(&checker_gltf())
    }

    #[test]
    fn samples_texel_centres_exactly_and_decodes_srgb() {
        let t = checker();
        assert_eq!(t.sample([0.25, 0.5]).x, 0.0);
        assert!((t.sample([0.75, 0.5]).x - 1.0).abs() < 1e-6);
        assert!((t.sample([0.5, 0.5]).x - 0.5).abs() < 1e-6);
    }

    #[test]
    fn rounded_log2_from_the_bits_matches_libm() {
        let mut x = 1.0f32;
        while x < 1e30 {
            assert_eq!(round_log2(x), x.log2().round() as u32, "{x}");
            x *= 1.0137;
        }
        // Either side of a rounding boundary (2^2.5 = 5.657) and of a power of two.
        for x in [5.6568, 5.6570, 3.9999, 4.0, 4.0001, 1.4141, 1.4143] {
            assert_eq!(round_log2(x), x.log2().round() as u32, "{x}");
        }
        assert!(round_log2(f32::INFINITY) >= 128);
    }

    #[test]
    fn wraps_and_survives_absurd_coordinates() {
        let t = checker();
        assert!((t.sample([1.75, 0.5]).x - 1.0).abs() < 1e-6);
        assert!(t.sample([1e30, -1e30]).is_finite());
        assert!(t.sample([f32::NAN, 0.0]).is_finite());
        assert_eq!(wrap(-1, 4, WRAP_MIRROR), 0);
        assert_eq!(wrap(4, 4, WRAP_MIRROR), 3);
        assert_eq!(wrap(9, 4, WRAP_CLAMP), 3);
        // Repeat: the mask of a power-of-two size is the remainder, negative coordinates too.
        for size in [1u32, 2, 4, 512, 3, 6] {
            for coord in [-1_000_000_007i64, -513, -512, -5, -1, 0, 1, 5, 511, 512, 1 << 40] {
                assert_eq!(
                    wrap(coord, size, 10497),
                    coord.rem_euclid(size as i64) as usize,
                    "{coord} {size}"
                );
            }
        }
    }

    /// A `size` x `size` sRGB checkerboard of single texels, 0.2 and 0.8 linear.
    fn fine_checker(size: u32) -> Texture {
        let encode = |linear: f32| (255.0 * linear.powf(1.0 / 2.2)).round() as u8;
        let rgba = (0..size * size)
            .flat_map(|i| {
                let v = if (i % size + i / size).is_multiple_of(2) {
                    encode(0.2)
                } else {
                    encode(0.8)
                };
                [v, v, v, 255]
            })
            .collect();
        Texture::from_gltf(&GltfTexture {
            name: "checker".into(),
            rgba,
            width: size,
            height: size,
            wrap_s: 10497,
            wrap_t: 10497,
            srgb: true,
        })
    }

    #[test]
    fn each_level_holds_the_linear_means_of_the_texels_above_it() {
        let t = fine_checker(8);
        assert_eq!(
            t.mips.iter().map(|m| (m.width, m.height)).collect::<Vec<_>>(),
            [(4, 4), (2, 2), (1, 1)]
        );
        // The mean of the stored texels, decoded: what every level must hold everywhere.
        let mean = (0..64).map(|i| t.texel(i).x).sum::<f32>() / 64.0;
        for mip in &t.mips {
            for texel in &mip.texels {
                assert!((from_unit16(*texel).x - mean).abs() < 1e-4, "{texel:?} against {mean}");
                assert_eq!(texel[3], 65535);
            }
        }
        // Averaged as stored (sRGB bytes), the mean would be far off: 0.2 and 0.8 encode to
        // 0.48 and 0.90, whose mean decodes to 0.44.
        assert!((mean - 0.5).abs() < 0.01, "{mean}");
        // Odd sizes fold their last row and column in; a 1-wide image halves its height only.
        let odd = halve(3, 1, |i| Vec4::splat([0.0, 0.3, 0.9][i]));
        assert_eq!((odd.width, odd.height), (1, 1));
        assert!((from_unit16(odd.texels[0]).x - 0.4).abs() < 1e-4);
        assert_eq!(
            Texture::from_gltf(&GltfTexture {
                width: 1,
                height: 4,
                rgba: vec![9; 16],
                ..checker_gltf()
            })
            .mips
            .len(),
            2
        );
    }

    /// 2x1: black | white, repeat.
    fn checker_gltf() -> GltfTexture {
        GltfTexture {
            name: "t".into(),
            rgba: vec![0, 0, 0, 255, 255, 255, 255, 255],
            width: 2,
            height: 1,
            wrap_s: 10497,
            wrap_t: 10497,
            srgb: true,
        }
    }

    #[test]
    fn a_footprint_reads_the_level_whose_texels_are_as_wide() {
        let t = fine_checker(64);
        let texel = 1.0 / 64.0;
        for (width, level) in [
            (0.0, 0),
            (texel, 0),
            (1.3 * texel, 0),
            (2.0 * texel, 1),
            (8.0 * texel, 3),
            (1.0, 6),
            (1e9, 6),
        ] {
            assert_eq!(t.level_for(width), level, "footprint {width}");
        }
        assert_eq!(t.level_for(f32::NAN), 0);
        // A texel-wide footprint sees the checker; a wide one its mean.
        assert!((t.sample_footprint([0.5 * texel, 0.5 * texel], texel).x - 0.2).abs() < 0.01);
        for uv in [[0.3, 0.7], [0.01, 0.99], [5.2, -3.1]] {
            assert!((t.sample_footprint(uv, 4.0 * texel).x - 0.5).abs() < 0.01, "{uv:?}");
        }
        assert!(t.sample_footprint([f32::NAN, 0.5], 1.0).is_finite());
    }

    #[test]
    fn a_cell_ray_reads_the_box_mean_of_the_texels_under_its_footprint() {
        // 16x16 texels of random bytes: at a footprint of 4 texels, the mean of the 4x4 block
        // the point falls in (level 2 of the pyramid), wherever in the block and however the
        // coordinates wrap.
        let mut rng = crate::sampling::Rng::new(7, 0);
        let rgba: Vec<u8> = (0..16 * 16 * 4).map(|_| (rng.next_u32() & 0xff) as u8).collect();
        let t = Texture::from_gltf(&GltfTexture {
            name: "noise".into(),
            rgba,
            width: 16,
            height: 16,
            wrap_s: 10497,
            wrap_t: 10497,
            srgb: true,
        });
        let texel = 1.0 / 16.0;
        for _ in 0..200 {
            let (u, v) = (rng.next_f32(), rng.next_f32());
            let (bx, by) = ((u * 4.0) as usize, (v * 4.0) as usize);
            let mut mean = Vec4::ZERO;
            for y in 4 * by..4 * by + 4 {
                for x in 4 * bx..4 * bx + 4 {
                    mean += t.texel(y * 16 + x) / 16.0;
                }
            }
            for shift in [0.0, 3.0, -2.0] {
                let read = t.sample_cell([u + shift, v - shift], 4.0 * texel);
                assert!(
                    (read - mean).abs().max_element() < 1e-4,
                    "{u} {v}: {read} against {mean}"
                );
            }
        }
        // A footprint of a texel or less: the stored image's bilinear sample.
        assert_eq!(t.sample_cell([0.3, 0.6], 0.5 * texel), t.sample([0.3, 0.6]));
        assert!(t.sample_cell([f32::NAN, 0.5], 1.0).is_finite());
    }
}

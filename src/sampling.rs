//! Random numbers and the warps that turn them into directions. Every pixel sample seeds its
//! own generator from (seed, pixel, sample), so an image does not depend on which thread
//! rendered which tile.

use glam::Vec3;

/// PCG32 (O'Neill): small, fast, and good enough for Monte Carlo integration.
#[derive(Clone, Debug)]
pub struct Rng {
    state: u64,
    inc: u64,
}

/// SplitMix64 finaliser: spreads nearby seeds (neighbouring pixels) far apart.
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

impl Rng {
    pub fn new(seed: u64, stream: u64) -> Rng {
        let mut rng = Rng {
            state: 0,
            inc: (mix64(stream) << 1) | 1,
        };
        rng.next_u32();
        rng.state = rng.state.wrapping_add(mix64(seed));
        rng.next_u32();
        rng
    }

    /// The generator of one pixel sample.
    pub fn for_sample(seed: u64, pixel: u64, sample: u64) -> Rng {
        Rng::new(mix64(seed ^ mix64(pixel)), sample)
    }

    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    /// Uniform in [0, 1).
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }
}

/// An orthonormal basis around a unit normal (Duff et al.'s branchless construction).
pub fn basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// Cosine-weighted direction about `n` from two uniforms (density cos / pi).
pub fn cosine_hemisphere(n: Vec3, u1: f32, u2: f32) -> Vec3 {
    let r = u1.sqrt();
    let phi = 2.0 * std::f32::consts::PI * u2;
    let (t, b) = basis(n);
    let z = (1.0 - u1).max(0.0).sqrt();
    (t * (r * phi.cos()) + b * (r * phi.sin()) + n * z).normalize()
}

/// Side of the smallest square grid with at least `n` cells.
pub fn grid_side(n: u32) -> u32 {
    let mut side = (n as f64).sqrt() as u32;
    while side * side < n {
        side += 1;
    }
    side.max(1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniforms_are_in_range_and_streams_differ() {
        let mut a = Rng::for_sample(1, 2, 0);
        let mut b = Rng::for_sample(1, 3, 0);
        let mut same = 0;
        for _ in 0..1000 {
            let (x, y) = (a.next_f32(), b.next_f32());
            assert!((0.0..1.0).contains(&x));
            if x == y {
                same += 1;
            }
        }
        assert!(same < 5);
    }

    #[test]
    fn cosine_hemisphere_has_the_right_mean_cosine() {
        // E[cos] under a cos/pi density is 2/3.
        let mut rng = Rng::new(7, 0);
        let n = Vec3::new(0.3, -0.4, 0.866).normalize();
        let samples = 200_000;
        let mean: f64 = (0..samples)
            .map(|_| cosine_hemisphere(n, rng.next_f32(), rng.next_f32()).dot(n) as f64)
            .sum::<f64>()
            / samples as f64;
        assert!((mean - 2.0 / 3.0).abs() < 3e-3, "mean cosine {mean}");
    }

    #[test]
    fn basis_is_orthonormal() {
        for n in [Vec3::Z, -Vec3::Z, Vec3::X, Vec3::new(1.0, 2.0, -3.0).normalize()] {
            let (t, b) = basis(n);
            assert!(t.dot(b).abs() < 1e-5 && t.dot(n).abs() < 1e-5 && (t.length() - 1.0).abs() < 1e-5);
        }
    }
}

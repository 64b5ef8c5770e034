//! Deterministic sampling: every random number is a function of (seed, pixel, sample,
//! dimension), so a render does not depend on the thread count or the work split.

use glam::{vec3a, Vec3A};

/// SplitMix64 finaliser: a well-mixed 64-bit hash.
#[inline]
pub fn mix64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

/// Hash of a list of integers.
#[inline]
pub fn hash(parts: &[u64]) -> u64 {
    parts
        .iter()
        .fold(0x2545_F491_4F6C_DD1D, |h, &p| mix64(h ^ p))
}

/// A uniform float in [0, 1) from the top 24 bits of a hash.
#[inline]
pub fn unit_float(bits: u64) -> f32 {
    (bits >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
}

/// A small, fast random stream (SplitMix64).
#[derive(Debug, Clone)]
pub struct Rng {
    state: u64,
}

impl Rng {
    /// The stream for `key` (e.g. a hash of seed, pixel and sample).
    pub fn new(key: u64) -> Rng {
        Rng { state: key }
    }

    /// The next uniform float in [0, 1).
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        unit_float(mix64(self.state))
    }
}

/// Generalised golden-ratio constants of the 4-D Kronecker (R4) sequence: powers of
/// 1/φ₄, where φ₄ is the real root of x⁵ = x + 1.
const R4: [f64; 4] = {
    const PHI4: f64 = 1.167_303_978_261_418_7;
    [
        1.0 / PHI4,
        1.0 / (PHI4 * PHI4),
        1.0 / (PHI4 * PHI4 * PHI4),
        1.0 / (PHI4 * PHI4 * PHI4 * PHI4),
    ]
};

/// Point `index` of a randomly shifted 4-D low-discrepancy (R4) sequence; every prefix is
/// well spread over [0, 1)⁴.
#[inline]
pub fn low_discrepancy_4d(index: u32, shift: [f32; 4]) -> [f32; 4] {
    let i = index as f64 + 1.0;
    [0, 1, 2, 3].map(|d| ((shift[d] as f64 + i * R4[d]).fract()) as f32)
}

/// A cosine-weighted direction on the hemisphere around the unit normal `n`.
#[inline]
pub fn cosine_hemisphere(u1: f32, u2: f32, n: Vec3A) -> Vec3A {
    let r = u1.sqrt();
    let phi = std::f32::consts::TAU * u2;
    let (t, b) = orthonormal_basis(n);
    let z = (1.0 - u1).max(0.0).sqrt();
    (t * (r * phi.cos()) + b * (r * phi.sin()) + n * z).normalize()
}

/// Two unit vectors completing the unit vector `n` to an orthonormal basis
/// (Duff et al. 2017, branchless).
#[inline]
pub fn orthonormal_basis(n: Vec3A) -> (Vec3A, Vec3A) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        vec3a(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        vec3a(b, sign + n.y * n.y * a, -n.y),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cosine_samples_have_the_right_moments() {
        let n = vec3a(0.3, -0.5, 0.8).normalize();
        let mut rng = Rng::new(7);
        let count = 200_000;
        let (mut mean_cos, mut mean_dir) = (0.0f64, Vec3A::ZERO);
        for _ in 0..count {
            let d = cosine_hemisphere(rng.next_f32(), rng.next_f32(), n);
            assert!(d.dot(n) >= -1e-6);
            mean_cos += d.dot(n) as f64;
            mean_dir += d;
        }
        // For a cosine-weighted hemisphere, E[cos θ] = 2/3 and E[d] = (2/3)·n.
        assert!((mean_cos / count as f64 - 2.0 / 3.0).abs() < 3e-3);
        assert!((mean_dir / count as f32 - n * (2.0 / 3.0)).length() < 5e-3);
    }

    #[test]
    fn low_discrepancy_prefix_is_stratified() {
        let shift = [0.1, 0.2, 0.3, 0.4];
        let mut counts = [0usize; 16];
        for i in 0..64 {
            let p = low_discrepancy_4d(i, shift);
            counts[(p[0] * 4.0) as usize * 4 + (p[1] * 4.0) as usize] += 1;
        }
        assert!(counts.iter().all(|&c| (2..=6).contains(&c)), "{counts:?}");
    }

    #[test]
    fn basis_is_orthonormal() {
        for n in [Vec3A::Z, -Vec3A::Z, Vec3A::X, vec3a(0.6, 0.0, -0.8)] {
            let (t, b) = orthonormal_basis(n);
            assert!(t.dot(b).abs() < 1e-6 && t.dot(n).abs() < 1e-6 && b.dot(n).abs() < 1e-6);
            assert!((t.length() - 1.0).abs() < 1e-6 && (b.length() - 1.0).abs() < 1e-6);
        }
    }
}

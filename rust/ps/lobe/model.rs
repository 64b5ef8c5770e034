//! The lobe model of a pixel's lights, in groups of [`LANES`]: the shading `[n·l]₊` and
//! `[n·l]₊ (n·h)^p` of a normal, the residuals, the weighted sums and the fit of the diffuse
//! term and the lobe's height to them.

use glam::Vec3;

use crate::ps::kernel::{Lights, LANES};
use crate::ps::lanes::{Floats, Isa};

use super::{grouped, HalfVectors, Work};

/// Least `n·h` (so that `(n·h)^(p−1)` stays finite).
pub(super) const NH_MIN: f32 = 1e-6;

/// `(a, c) ≥ 0` minimising `Σ w (b − a f − c s)²` from its normal equations' sums.
#[inline(always)]
pub(super) fn diffuse_and_lobe(ff: f32, fs: f32, ss: f32, fb: f32, sb: f32) -> (f32, f32) {
    let det = ff * ss - fs * fs;
    if det > 1e-6 * ff * ss {
        let (a, c) = ((ss * fb - fs * sb) / det, (ff * sb - fs * fb) / det);
        if a >= 0.0 && c >= 0.0 {
            return (a, c);
        }
    }
    // On a bound: the better of the diffuse term alone and the lobe alone.
    let a = if ff > 0.0 { (fb / ff).max(0.0) } else { 0.0 };
    let c = if ss > 0.0 { (sb / ss).max(0.0) } else { 0.0 };
    // Σ w (b − a f)² − Σ w b² = a² ff − 2 a fb, likewise for the lobe: the larger drop wins.
    if a * fb >= c * sb {
        (a, 0.0)
    } else {
        (0.0, c)
    }
}

/// `[n·l]₊` and `[n·l]₊ (n·h)^p` of every light into `work`.
#[inline(always)]
pub(super) fn shading<V: Isa<LANES>>(
    isa: V,
    lights: &Lights,
    half: &HalfVectors,
    n: Vec3,
    shift: u32,
    work: &mut Work,
) {
    let groups = work.diffuse.len();
    let [lx, ly, lz] = lights
        .direction
        .each_ref()
        .map(|row| &grouped(row)[..groups]);
    let [hx, hy, hz] = half.0.each_ref().map(|row| &row[..groups]);
    let (diffuse, specular, nh) = (
        &mut work.diffuse[..groups],
        &mut work.specular[..groups],
        &mut work.nh[..groups],
    );
    let (zero, nh_min) = (isa.splat(0.0), isa.splat(NH_MIN));
    for g in 0..groups {
        let nl =
            (isa.floats(lx[g]) * n.x + isa.floats(ly[g]) * n.y + isa.floats(lz[g]) * n.z).max(zero);
        let cosine = (isa.floats(hx[g]) * n.x + isa.floats(hy[g]) * n.y + isa.floats(hz[g]) * n.z)
            .max(nh_min);
        let mut lobe = cosine;
        for _ in 0..shift {
            lobe = lobe * lobe;
        }
        diffuse[g] = nl.to_array();
        specular[g] = (nl * lobe).to_array();
        nh[g] = cosine.to_array();
    }
}

/// The sums over `groups` groups of [`LANES`] lights of each of the `N` values that `term`
/// gives for a group: lane by lane, then across the lanes. `term` is a closure marked
/// `#[inline(always)]`: a closure does not take the target features of the function it is
/// written in, and its intrinsics would otherwise be calls.
#[inline(always)]
pub(super) fn summed<V: Isa<LANES>, const N: usize>(
    isa: V,
    groups: usize,
    term: impl Fn(usize) -> [V::F; N],
) -> [f32; N] {
    let mut lanes = [isa.splat(0.0); N];
    for g in 0..groups {
        for (lane, value) in lanes.iter_mut().zip(term(g)) {
            *lane += value;
        }
    }
    // A loop, not `map`: a closure's `to_array` would be a call (see above).
    let mut sums = [0.0; N];
    for (sum, lane) in sums.iter_mut().zip(lanes) {
        *sum = lane.to_array().iter().sum();
    }
    sums
}

/// `(a, c)` of the current shading and weights.
#[inline(always)]
pub(super) fn lobe_scales<V: Isa<LANES>>(isa: V, work: &Work) -> (f32, f32) {
    let groups = work.diffuse.len();
    let (diffuse, specular, weight, b) = (
        &work.diffuse[..groups],
        &work.specular[..groups],
        &work.weight[..groups],
        &work.b[..groups],
    );
    let [ff, fs, ss, fb, sb] = summed(
        isa,
        groups,
        #[inline(always)]
        |g| {
            let (f, s, w, b) = (
                isa.floats(diffuse[g]),
                isa.floats(specular[g]),
                isa.floats(weight[g]),
                isa.floats(b[g]),
            );
            let (wf, ws) = (w * f, w * s);
            [wf * f, wf * s, ws * s, wf * b, ws * b]
        },
    );
    diffuse_and_lobe(ff, fs, ss, fb, sb)
}

/// Each light of group `g`'s residual under the model `a`, `c` of the current shading.
#[inline(always)]
pub(super) fn residual<V: Isa<LANES>>(isa: V, work: &Work, g: usize, a: f32, c: f32) -> V::F {
    isa.floats(work.b[g]) - isa.floats(work.diffuse[g]) * a - isa.floats(work.specular[g]) * c
}

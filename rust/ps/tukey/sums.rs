//! The Tukey fit's arithmetic side by side: the threshold fit's sums, Tukey's weights, a
//! select without a branch, and the sums across lanes.

use std::ops::{BitAnd, BitXor};

use glam::{Mat3, Vec3};

use crate::ps::kernel::{Lights, LANES, SATURATED};
use crate::ps::lanes::{Floats, Ints, Isa};

/// `if_true` where `mask`'s bits are set, else `if_false` (`wide`'s `select` is a call on
/// x86-64 before SSE4.1).
#[inline(always)]
pub(super) fn blend<T: Copy + BitXor<Output = T> + BitAnd<Output = T>>(
    mask: T,
    if_true: T,
    if_false: T,
) -> T {
    if_false ^ ((if_false ^ if_true) & mask)
}

/// Σ w l lᵀ, Σ w l b and Σ w of the threshold fit of a pixel whose channel-summed `b` are
/// `grey` (padded like `lights`): weight 1 above `level` and below [`SATURATED`], else 0.
#[inline(always)]
pub(super) fn threshold_sums<E: Isa<LANES>>(
    light: E,
    grey: &[f32],
    level: f32,
    lights: &Lights,
) -> (Mat3, Vec3, usize) {
    let (level, saturated, one) = (light.splat(level), light.splat(SATURATED), light.splat(1.0));
    let mut gram = [light.splat(0.0); 6];
    let mut rhs = [light.splat(0.0); 3];
    let mut count = light.splat_int(0);
    for at in (0..grey.len()).step_by(LANES) {
        let b = light.floats(eight(grey, at));
        let lit = b.simd_gt(level) & b.simd_lt(saturated);
        for (sum, outer) in gram.iter_mut().zip(&lights.outer) {
            *sum += (one & lit) * light.floats(eight(outer, at));
        }
        for (sum, direction) in rhs.iter_mut().zip(&lights.direction) {
            *sum += (b & lit) * light.floats(eight(direction, at));
        }
        count -= lit.to_bits();
    }
    (
        symmetric(lanes_of(gram).map(total)),
        Vec3::from_array(lanes_of(rhs).map(total)),
        count.to_array().iter().sum::<i32>() as usize,
    )
}

/// The eight values of `values` from `at`.
#[inline(always)]
pub(super) fn eight(values: &[f32], at: usize) -> [f32; LANES] {
    values[at..at + LANES]
        .try_into()
        .expect("padded to whole lanes")
}

/// The lanes of each of `sums`. (A loop, not a closure: a closure would not be compiled for
/// the instruction set of its caller.)
#[inline(always)]
pub(super) fn lanes_of<F: Floats<W>, const W: usize, const N: usize>(
    sums: [F; N],
) -> [[f32; W]; N] {
    let mut lanes = [[0.0; W]; N];
    for (lane, sum) in lanes.iter_mut().zip(sums) {
        *lane = sum.to_array();
    }
    lanes
}

/// Tukey's weight of an observation whose absolute residual has the bits `key`, for the
/// scale `inverse` (see [`Machine::residuals`](super::machine::Machine::residuals)): 0
/// where `key` is [`UNLIT`](super::UNLIT), a NaN that no comparison holds for.
#[inline(always)]
pub(super) fn tukey_weight<V: Isa<W>, const W: usize>(
    isa: V,
    inverse: V::F,
    key: [i32; W],
) -> V::F {
    let one = isa.splat(1.0);
    let u = isa.ints(key).to_floats() * inverse;
    let inside = u.simd_lt(one);
    // 1 − u², rounded once.
    let tukey = (u ^ isa.splat(-0.0)).mul_add(u, one);
    (tukey * tukey) & inside
}

/// The sum of the lanes of a sum taken side by side, in lane order.
pub(super) fn total(lanes: [f32; LANES]) -> f32 {
    lanes.iter().sum()
}

/// The symmetric matrix of xx, xy, xz, yy, yz, zz.
pub(super) fn symmetric(m: [f32; 6]) -> Mat3 {
    Mat3::from_cols(
        Vec3::new(m[0], m[1], m[2]),
        Vec3::new(m[1], m[3], m[4]),
        Vec3::new(m[2], m[4], m[5]),
    )
}

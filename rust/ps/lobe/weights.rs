//! Tukey's biweight in the lobe fit: each observation's weight, the robust scale of the lit
//! observations (their median absolute residual) and the loss that compares fits.

use crate::ps::kernel::{LANES, MAD_TO_SIGMA};
use crate::ps::lanes::{Floats, Ints, Isa};

use super::model::{residual, summed};
use super::{Work, LOBE_SCALES};

/// Least robust scale, as a fraction of `a + c` (noise-free data).
const SCALE_FLOOR: f32 = 1e-4;
/// Half-width of the bracket around the last median in which the next is sought, in units
/// of an `f32`'s last bit (about ±12 %).
const BRACKET: u32 = 1 << 20;

/// Tukey's biweight of each residual under the model `a`, `c`, in units of [`LOBE_SCALES`]
/// robust scales of the lit observations.
#[inline(always)]
pub(super) fn reweight<V: Isa<LANES>>(isa: V, a: f32, c: f32, work: &mut Work) {
    let Some(scale) = robust_scale(isa, a, c, work) else {
        return;
    };
    let reach = 1.0 / (LOBE_SCALES * scale);
    let (zero, one) = (isa.splat(0.0), isa.splat(1.0));
    for g in 0..work.weight.len() {
        let u = residual(isa, work, g, a, c) * reach;
        let t = one - u * u;
        work.weight[g] = (t.simd_gt(zero) & (t * t * isa.floats(work.usable[g]))).to_array();
    }
}

/// 1.4826 × the median absolute residual of the lit, unsaturated observations under the
/// model `a`, `c` (at least [`SCALE_FLOOR`] of `a + c`), `None` when none is lit.
#[inline(always)]
pub(super) fn robust_scale<V: Isa<LANES>>(isa: V, a: f32, c: f32, work: &mut Work) -> Option<f32> {
    // Absolute values: their bits order as the values do. Packed without a branch: every
    // residual is written, and the next slot taken only when its observation counts.
    let (zero, magnitude) = (isa.splat(0.0), isa.splat_int(i32::MAX).to_floats());
    let mut count = 0;
    for g in 0..work.diffuse.len() {
        let bits = (residual(isa, work, g, a, c) & magnitude)
            .to_bits()
            .to_array();
        let counts = (isa.floats(work.diffuse[g]).simd_gt(zero)
            & isa.floats(work.usable[g]).simd_gt(zero))
        .to_bits()
        .to_array();
        for (bits, counts) in bits.into_iter().zip(counts) {
            work.spread[count] = bits as u32;
            count += (counts & 1) as usize;
        }
    }
    if count == 0 {
        return None;
    }
    work.median_guess = select_near(&mut work.spread[..count], count / 2, work.median_guess);
    let median = f32::from_bits(work.median_guess);
    Some((MAD_TO_SIGMA * median).max(SCALE_FLOOR * (a + c)) + 1e-9)
}

/// The `rank`-th smallest of `keys` (from 0; `keys` reordered), found fast when it lies
/// within [`BRACKET`] of `guess`: only the keys in that bracket are then searched.
#[inline(always)]
pub(super) fn select_near(keys: &mut [u32], rank: usize, guess: u32) -> u32 {
    let (low, high) = (guess.saturating_sub(BRACKET), guess.saturating_add(BRACKET));
    let (mut below, mut within) = (0, 0);
    for &key in keys.iter() {
        below += usize::from(key < low);
        within += usize::from(key >= low && key <= high);
    }
    // The side of the bracket, or the bracket, that holds the rank: its keys packed to the
    // front (in place, without a branch), the rank counted from its start.
    let (first, last, rank) = if rank < below {
        (0, low - 1, rank)
    } else if rank < below + within {
        (low, high, rank - below)
    } else {
        (high + 1, u32::MAX, rank - below - within)
    };
    let mut kept = 0;
    for i in 0..keys.len() {
        let key = keys[i];
        keys[kept] = key;
        kept += usize::from(key >= first && key <= last);
    }
    *keys[..kept].select_nth_unstable(rank).1
}

/// Σ over the unsaturated observations of Tukey's loss `1 − (1 − u²)³` (1 beyond `|u| = 1`)
/// of the residual `u` under the model `a`, `c`, times `reach`.
#[inline(always)]
pub(super) fn loss<V: Isa<LANES>>(isa: V, a: f32, c: f32, reach: f32, work: &Work) -> f32 {
    let (zero, one) = (isa.splat(0.0), isa.splat(1.0));
    let [sum] = summed(
        isa,
        work.diffuse.len(),
        #[inline(always)]
        |g| {
            let u = residual(isa, work, g, a, c) * reach;
            let t = (one - u * u).max(zero);
            [isa.floats(work.usable[g]) * (one - t * t * t)]
        },
    );
    sum
}

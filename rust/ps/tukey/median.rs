//! Each lane's median absolute residual, by counting: a bisection on the keys' bits,
//! vectorised over the lanes, started from a bracket around the lane's previous median.

use crate::ps::lanes::{Ints, Isa};

use super::sums::blend;
use super::{REACH_MAX, SELECT, UNLIT};

/// For each `active` lane, the `lit / 2`-th smallest (from 0) of its `keys` below
/// [`UNLIT`], of which it has `lit`: a bisection on the keys' values, each step counting the
/// keys below a threshold of each lane, until at most [`SELECT`] keys (or one value) are left
/// in a lane's bracket, then one pass that sorts each lane's smallest [`SELECT`] keys of the
/// bracket. A lane with a `guess` (a positive key) first brackets its median by thresholds
/// ±`bracket` around it, then 4, 16, 64... times as far on the side where the median lies,
/// until one holds it.
#[inline(always)]
pub(super) fn median_keys<V: Isa<W>, const W: usize>(
    isa: V,
    keys: &[[i32; W]],
    lit: [i32; W],
    guess: [i32; W],
    bracket: [i32; W],
    active: [bool; W],
) -> [i32; W] {
    let rank = lit.map(|lit| lit / 2);
    // Invariant for each active lane: below(lo) ≤ rank < below(hi).
    let (mut lo, mut below_lo) = ([0i32; W], [0i32; W]);
    let (mut hi, mut below_hi) = ([UNLIT; W], lit);
    // How far from the guess the next threshold of a lane still bracketing lies: below it
    // when negative, above it when positive, 0 once the lane bisects.
    let mut reach = [0i32; W];
    let near_lo: [i32; W] =
        std::array::from_fn(|lane| guess[lane].saturating_sub(bracket[lane]).max(0));
    let near_hi: [i32; W] = std::array::from_fn(|lane| guess[lane].saturating_add(bracket[lane]));
    let (count_lo, count_hi) = (
        count_below(isa, keys, isa.ints(near_lo)).to_array(),
        count_below(isa, keys, isa.ints(near_hi)).to_array(),
    );
    for lane in 0..W {
        if !active[lane] {
            (hi[lane], below_hi[lane]) = (0, 0);
        } else if guess[lane] <= 0 {
            continue;
        } else if count_lo[lane] > rank[lane] {
            (hi[lane], below_hi[lane], reach[lane]) =
                (near_lo[lane], count_lo[lane], -4 * bracket[lane]);
        } else if count_hi[lane] <= rank[lane] {
            (lo[lane], below_lo[lane], reach[lane]) =
                (near_hi[lane], count_hi[lane], 4 * bracket[lane]);
        } else {
            (lo[lane], below_lo[lane], hi[lane], below_hi[lane]) =
                (near_lo[lane], count_lo[lane], near_hi[lane], count_hi[lane]);
        }
    }
    // The bisection, every lane's bounds side by side (no branch on a lane's count).
    let (zero, none, select, one) = (
        isa.splat_int(0),
        isa.splat_int(-1),
        isa.splat_int(SELECT as i32),
        isa.splat_int(1),
    );
    let (rank, guess, farthest, unbounded) = (
        isa.ints(rank),
        isa.ints(guess),
        isa.splat_int(REACH_MAX),
        isa.splat_int(i32::MAX),
    );
    let (mut lo, mut below_lo, mut hi, mut below_hi, mut reach) = (
        isa.ints(lo),
        isa.ints(below_lo),
        isa.ints(hi),
        isa.ints(below_hi),
        isa.ints(reach),
    );
    loop {
        // Lanes still bracketing try `guess + reach` within [lo, hi] (computed so that it
        // cannot overflow); bisecting lanes the middle of a bracket that holds more than
        // SELECT keys and values, the others nothing (-1).
        let above = guess + (hi - guess).min(reach);
        let beneath = guess - (guess - lo).min(zero - reach);
        let toward = blend(zero.simd_lt(reach), above.max(lo), beneath.min(hi));
        let open = select.simd_lt(below_hi - below_lo) & one.simd_lt(hi - lo);
        let middle = blend(open, lo + (hi - lo).halved(), none);
        let bisecting = reach.simd_eq(zero);
        let threshold = blend(bisecting, middle, toward);
        if threshold.to_array().iter().all(|&t| t < 0) {
            break;
        }
        let below = count_below(isa, keys, threshold);
        let counted = threshold.simd_lt(zero) ^ none;
        let holds = rank.simd_lt(below);
        let (lowers_hi, raises_lo) = (counted & holds, counted & (holds ^ none));
        (hi, below_hi) = (
            blend(lowers_hi, threshold, hi),
            blend(lowers_hi, below, below_hi),
        );
        (lo, below_lo) = (
            blend(raises_lo, threshold, lo),
            blend(raises_lo, below, below_lo),
        );
        // Still not bracketed (the median below a threshold below the guess, or above one
        // above it): four times as far next.
        let unbracketed = ((holds ^ reach.simd_lt(zero)) ^ none) & (bisecting ^ none);
        let capped = reach.min(farthest).max(zero - farthest);
        let quadrupled = (capped + capped) + (capped + capped);
        let grown = blend(
            farthest.simd_lt(reach),
            unbounded,
            blend(reach.simd_lt(zero - farthest), zero - unbounded, quadrupled),
        );
        reach = grown & (unbracketed & counted);
    }
    // At most SELECT keys, or one value, are left in [lo, hi): the keys go down a cascade
    // that keeps the SELECT smallest in order, each shifted by `lo + i32::MIN` (wrapping) so
    // that the keys from lo come first and those below it last.
    let offset = lo + isa.splat_int(i32::MIN);
    let mut smallest = [isa.splat_int(i32::MAX); SELECT];
    for key in keys {
        let mut carried = isa.ints(*key) - offset;
        for slot in &mut smallest {
            (*slot, carried) = (slot.min(carried), slot.max(carried));
        }
    }
    let mut sorted = [[0; W]; SELECT];
    for (lanes, slot) in sorted.iter_mut().zip(smallest) {
        *lanes = (slot + offset).to_array();
    }
    let (lo, below_lo, rank) = (lo.to_array(), below_lo.to_array(), rank.to_array());
    // More keys than SELECT are left only when they all have the value lo.
    std::array::from_fn(|lane| {
        sorted
            .get((rank[lane] - below_lo[lane]) as usize)
            .map_or(lo[lane], |keys| keys[lane])
    })
}

/// How many of each lane's `keys` are below its `threshold`.
#[inline(always)]
fn count_below<V: Isa<W>, const W: usize>(isa: V, keys: &[[i32; W]], threshold: V::I) -> V::I {
    // Four counts side by side: each one's subtractions wait on its own last only.
    let mut below = [isa.splat_int(0); 4];
    let mut quads = keys.chunks_exact(4);
    for quad in &mut quads {
        for (count, key) in below.iter_mut().zip(quad) {
            *count -= isa.ints(*key).simd_lt(threshold);
        }
    }
    for (count, key) in below.iter_mut().zip(quads.remainder()) {
        *count -= isa.ints(*key).simd_lt(threshold);
    }
    let [a, b, c, d] = below;
    (a + b) + (c + d)
}

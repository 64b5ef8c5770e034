//! Tukey re-weighting of photometric stereo, 8 or 16 pixels side by side.
//!
//! Each pixel starts from the threshold fit (observations above `shadow_fraction` of the
//! pixel's brightest) and re-weights every observation that the fit lights (`l·g > 0`) by
//! Tukey's biweight `(1 − u²)²` of its residual `u` in units of [`TUKEY_SCALES`] robust
//! scales (1.4826 × the median absolute residual of the lit observations), until the fit
//! moves by less than [`TUKEY_SETTLED`] of its length. Soft and cast shadows fall below the
//! fit, highlights above it: both lose their weight, attached shadows carry none. Saturated
//! observations carry none either.
//!
//! A chunk's observations are first copied out of the images image by image (runs of
//! consecutive pixels at once), so that the images are read in order rather than one value
//! of each of K images per pixel. The pixels of a chunk go through `W` lanes, structure of
//! arrays (one value of each lane per light), so that the residuals, weights and sums of
//! every lane are computed by the same vector instructions (16 lanes in AVX-512 registers,
//! or 8 in AVX2 and FMA ones, where the CPU has them, see [`crate::ps::lanes`]; the weights and
//! their sums in one pass of fused multiply-adds). A pixel's own loops over its lights run
//! 8 lights side by side whatever `W` is, so that its results are the same bits in every
//! instruction set. A lane whose pixel has settled is refilled with the next
//! pixel of the chunk at once (its threshold fit summed as it is read, over the lights side
//! by side), so pixels that need many re-weightings do not hold the others back. Each
//! lane's median comes from counting, vectorised over the lanes: a bisection on the
//! absolute residuals' bits (every lane's bounds in vector registers too, so that no branch
//! waits on a lane's count), started from a bracket around the lane's previous median,
//! twice as wide as that median's last move (widened until it holds the median), until a
//! few keys are left, which one pass sorts. A settled pixel's RGB albedo is each channel's
//! scale along its normal, summed over the lights side by side.
//!
//! This module hands the chunks of pixels to the lanes; beside it, each importing only those
//! above it: `sums`, the arithmetic side by side (threshold sums, Tukey's weights); `median`,
//! each lane's median by counting; `machine`, the lanes and their pixels.

use crate::error::Result;
use crate::ps::kernel::{fit_masked, Lights, PsOutput};
use crate::ps::lanes::Portable;

use machine::Machine;

mod machine;
mod median;
mod sums;

/// Tukey's biweight constant, in robust scales: an observation whose residual is beyond
/// 2.5 scales carries no weight. Below the 4.685 of 95 % Gaussian efficiency, because the
/// scale is measured on the contaminated observations themselves and so overstates the
/// noise where shadows and highlights are many.
pub const TUKEY_SCALES: f32 = 2.5;
/// Largest number of re-weightings.
pub const TUKEY_ITERATIONS: u8 = 20;
/// Re-weighting stops when the fit moves by less than this fraction of its length (a
/// step of 0.17° or less).
pub const TUKEY_SETTLED: f32 = 3e-3;
/// Fewest observations with weight that a re-weighted fit needs.
const TUKEY_MIN: usize = 4;
/// Least robust scale, as a fraction of the fit's length (noise-free data).
const SCALE_FLOOR: f32 = 1e-4;
/// Pixels per parallel task.
const CHUNK: usize = 512;
/// Key of an observation the fit does not light: above every absolute residual's key, and
/// the bits of a NaN.
const UNLIT: i32 = i32::MAX;
/// Widest half-width of the first bracket tried around a lane's previous median, in key
/// units (2²⁰ of the mantissa's 2²³ per octave: about ±9 %): the bracket of a pixel's first
/// median, whose guess is the previous pixel's.
const BRACKET: i32 = 1 << 20;
/// Narrowest half-width of that bracket (about ±0.1 %).
const BRACKET_MIN: i32 = 1 << 13;
/// Farthest step of a lane still bracketing its median that is quadrupled, in key units:
/// beyond, the next step goes to the end of the keys' range.
const REACH_MAX: i32 = 1 << 28;
/// Keys left in a lane's bracket when its median's bisection stops.
const SELECT: usize = 4;
/// Values left unused after each image's row of a staged chunk (a cache line), so that the
/// rows' values of one pixel do not all fall in the same cache set.
const STAGE_GAP: usize = 16;

/// Fits the pixels where `mask` is true from `images` laid out `(K, pixels, 3)` into `out`,
/// in the widest registers the CPU has (the same results in each).
pub(crate) fn fit_pixels(
    images: &[f32],
    mask: &[bool],
    lights: &Lights,
    shadow_fraction: f32,
    out: &mut PsOutput,
) -> Result<()> {
    let source = Source {
        images,
        n: mask.len(),
        lights,
        shadow_fraction,
    };
    #[cfg(target_arch = "x86_64")]
    {
        if let Some(avx512) = crate::ps::lanes::Avx512::detect() {
            // SAFETY: `detect` found AVX-512F, AVX2 and FMA.
            return fit_masked(
                mask,
                CHUNK,
                out,
                || Box::new(Machine::new(lights)),
                |machine, chunk, fits| unsafe { machine.run_avx512(avx512, &source, chunk, fits) },
            );
        }
        if let Some(avx2) = crate::ps::lanes::Avx2::detect() {
            // SAFETY: `detect` found AVX2 and FMA.
            return fit_masked(
                mask,
                CHUNK,
                out,
                || Box::new(Machine::new(lights)),
                |machine, chunk, fits| unsafe { machine.run_avx2(avx2, &source, chunk, fits) },
            );
        }
    }
    fit_masked(
        mask,
        CHUNK,
        out,
        || Box::new(Machine::<8>::new(lights)),
        |machine, chunk, fits| machine.run_in(Portable, Portable, &source, chunk, fits),
    )
}

/// Where the pixels' observations come from.
struct Source<'a> {
    /// `(K, n, 3)`.
    images: &'a [f32],
    /// Pixels per image.
    n: usize,
    lights: &'a Lights,
    shadow_fraction: f32,
}

#[cfg(test)]
mod tests;

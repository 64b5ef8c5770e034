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

use std::ops::{BitAnd, BitXor};

use glam::{Mat3, Vec3};

use crate::error::Result;
use crate::ps::lanes::{Floats, Ints, Isa, Portable};
use crate::ps::trim::{full_fit, solved, Lights, LANES, MAD_TO_SIGMA, SATURATED};
use crate::ps::{fit_masked, flag, PixelFit, PsOutput};

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

/// `W` lanes and their pixels' observations.
struct Machine<const W: usize> {
    /// Number of lights.
    lights: usize,
    /// Each light's direction `l` (x, y, z) and `l lᵀ` (xx, xy, xz, yy, yz, zz).
    light: Vec<[f32; 9]>,
    /// The raw observations of the chunk being fitted, image by image: a row per image of its
    /// pixels' RGB in chunk order, [`STAGE_GAP`] values between rows.
    staged: Vec<f32>,
    /// Values from one image's row of `staged` to the next.
    staged_stride: usize,
    /// Channel-summed `b` per light ([`SATURATED`] when saturated).
    grey: Vec<[f32; W]>,
    /// Lights padded to whole lanes, like [`Lights`].
    padded: usize,
    /// `b` per lane, channel and (padded) light: lane by lane, each lane's red, green and
    /// blue rows.
    channel: Vec<f32>,
    /// The weights of the lane being finished, per (padded) light.
    finishing: Vec<f32>,
    /// Bits of `|b − l·g|` per light ([`UNLIT`], a NaN's bits, where the fit does not
    /// light it or it is saturated): integers that order as the absolute residuals.
    key: Vec<[i32; W]>,
    /// Weights tried by the last re-weighting, per light: a lane's fit kept when it took
    /// them.
    candidate: Vec<[f32; W]>,
    /// Weights tried by the re-weighting before, per light: the fit kept of a lane that did
    /// not take the last ones (before its first re-weighting, see [`Machine::lane_fit`]).
    previous: Vec<[f32; W]>,
    /// The pixel being loaded's channel-summed `b`, light by light, padded with
    /// [`SATURATED`] like [`Lights`].
    own: Vec<f32>,
    /// Each lane's shadow level (its threshold fit's).
    level: [f32; W],
    /// The fit kept, `ρ n` summed over the channels.
    g: [Vec3; W],
    /// Σ w l lᵀ of the fit kept.
    gram: [Mat3; W],
    /// Observations with weight in the fit kept.
    count: [usize; W],
    /// Whether the lane holds a pixel.
    occupied: [bool; W],
    /// Pixel index of each lane.
    pixel: [usize; W],
    /// Re-weightings done.
    iterations: [u8; W],
    /// Each lane's last median key, 0 before the first.
    median_key: [i32; W],
    /// Half-width of the bracket tried around it next, in key units.
    bracket: [i32; W],
}

impl<const W: usize> Machine<W> {
    fn new(source: &Lights) -> Machine<W> {
        let lights = source.count;
        let light = (0..lights)
            .map(|k| {
                std::array::from_fn(|i| {
                    if i < 3 {
                        source.direction[i][k]
                    } else {
                        source.outer[i - 3][k]
                    }
                })
            })
            .collect();
        Machine {
            lights,
            light,
            staged: Vec::new(),
            staged_stride: 0,
            grey: vec![[0.0; W]; lights],
            padded: source.padded(),
            channel: vec![0.0; W * 3 * source.padded()],
            finishing: vec![0.0; source.padded()],
            key: vec![[UNLIT; W]; lights],
            candidate: vec![[0.0; W]; lights],
            previous: vec![[0.0; W]; lights],
            own: vec![SATURATED; source.padded()],
            level: [0.0; W],
            g: [Vec3::ZERO; W],
            gram: [Mat3::ZERO; W],
            count: [0; W],
            occupied: [false; W],
            pixel: [0; W],
            iterations: [0; W],
            median_key: [0; W],
            bracket: [BRACKET; W],
        }
    }

    /// Fits every pixel of `chunk`, appending to `fits`: the lanes in the registers of
    /// `isa`, each pixel's lights side by side in those of `light`.
    #[inline(always)]
    fn run_in<V: Isa<W>, E: Isa<LANES>>(
        &mut self,
        isa: V,
        light: E,
        source: &Source,
        chunk: &[usize],
        fits: &mut Vec<(usize, PixelFit)>,
    ) {
        self.stage(source, chunk);
        let mut queue = chunk.iter().copied().enumerate();
        for lane in 0..W {
            self.load(light, source, lane, &mut queue, fits);
        }
        while self.occupied.iter().any(|&o| o) {
            let (inverse, too_few_lit) = self.residuals(isa);
            std::mem::swap(&mut self.candidate, &mut self.previous);
            let (grams, rhs, counts) = self.candidate_sums(isa, inverse);
            let mut accept = [false; W];
            let mut finished = [false; W];
            for lane in (0..W).filter(|&lane| self.occupied[lane]) {
                let next = if too_few_lit[lane] {
                    None
                } else {
                    solved(grams[lane], rhs[lane], counts[lane], TUKEY_MIN)
                };
                let Some(next) = next else {
                    finished[lane] = true;
                    continue;
                };
                self.iterations[lane] += 1;
                let settled =
                    (next - self.g[lane]).length() <= TUKEY_SETTLED * self.g[lane].length();
                finished[lane] = settled || self.iterations[lane] == TUKEY_ITERATIONS;
                (self.g[lane], self.gram[lane], self.count[lane]) =
                    (next, grams[lane], counts[lane]);
                accept[lane] = true;
            }
            for lane in (0..W).filter(|&lane| finished[lane]) {
                fits.push((
                    self.pixel[lane],
                    self.lane_fit(light, lane, accept[lane], source.lights),
                ));
                self.load(light, source, lane, &mut queue, fits);
            }
        }
    }

    /// The red, green and blue `b` of `lane`, each per (padded) light.
    fn lane_channels(&self, lane: usize) -> (&[f32], &[f32], &[f32]) {
        let rows = &self.channel[lane * 3 * self.padded..][..3 * self.padded];
        let (red, rest) = rows.split_at(self.padded);
        let (green, blue) = rest.split_at(self.padded);
        (red, green, blue)
    }

    /// Puts the next pixel of `queue` ((position in the chunk, pixel index)) in `lane`, with
    /// its threshold fit as the fit kept; a pixel without one gets the full fit (in `fits`)
    /// and the next is tried. Empties the lane when `queue` is.
    #[inline(always)]
    fn load<E: Isa<LANES>>(
        &mut self,
        light: E,
        source: &Source,
        lane: usize,
        queue: &mut impl Iterator<Item = (usize, usize)>,
        fits: &mut Vec<(usize, PixelFit)>,
    ) {
        for (position, pixel) in queue {
            let level = source.shadow_fraction * self.gather(light, source.lights, lane, position);
            let (gram, rhs, count) = threshold_sums(light, &self.own, level, source.lights);
            if let Some(g) = solved(gram, rhs, count, 3) {
                (
                    self.g[lane],
                    self.gram[lane],
                    self.count[lane],
                    self.level[lane],
                ) = (g, gram, count, level);
                (
                    self.occupied[lane],
                    self.pixel[lane],
                    self.iterations[lane],
                    self.bracket[lane],
                ) = (true, pixel, 0, BRACKET);
                return;
            }
            let (red, green, blue) = self.lane_channels(lane);
            let rgb: Vec<[f32; 3]> = (0..self.lights)
                .map(|k| [red[k], green[k], blue[k]])
                .collect();
            fits.push((pixel, full_fit(&rgb, source.lights)));
        }
        self.occupied[lane] = false;
        for grey in &mut self.grey {
            grey[lane] = 0.0;
        }
    }

    /// Copies the observations of the pixels of `chunk` (increasing indices) into `staged`,
    /// image by image, each run of consecutive pixels at once: reading the images' rows in
    /// order is faster than reading every image's value of one pixel after another.
    fn stage(&mut self, source: &Source, chunk: &[usize]) {
        self.staged_stride = chunk.len() * 3 + STAGE_GAP;
        self.staged.resize(self.lights * self.staged_stride, 0.0);
        let mut runs: Vec<(usize, usize)> = Vec::new();
        for &pixel in chunk {
            match runs.last_mut() {
                Some((first, length)) if *first + *length == pixel => *length += 1,
                _ => runs.push((pixel, 1)),
            }
        }
        for (image, row) in source
            .images
            .chunks_exact(source.n * 3)
            .zip(self.staged.chunks_exact_mut(self.staged_stride))
        {
            let mut at = 0;
            for &(first, length) in &runs {
                row[at * 3..(at + length) * 3]
                    .copy_from_slice(&image[first * 3..(first + length) * 3]);
                at += length;
            }
        }
    }

    /// Reads the observations of the chunk's `position`-th pixel into `lane` (and its channel
    /// sums into `own`) and returns its brightest unsaturated channel-summed `b`: the raw values
    /// copied light by light from `staged`, then scaled, tested for saturation and summed
    /// over the lights side by side.
    #[inline(always)]
    fn gather<E: Isa<LANES>>(
        &mut self,
        light: E,
        lights: &Lights,
        lane: usize,
        position: usize,
    ) -> f32 {
        let rows = &mut self.channel[lane * 3 * self.padded..][..3 * self.padded];
        let (red, rest) = rows.split_at_mut(self.padded);
        let (green, blue) = rest.split_at_mut(self.padded);
        for (((image, red), green), blue) in self
            .staged
            .chunks_exact(self.staged_stride)
            .zip(&mut *red)
            .zip(&mut *green)
            .zip(&mut *blue)
        {
            let raw = &image[position * 3..position * 3 + 3];
            (*red, *green, *blue) = (raw[0], raw[1], raw[2]);
        }
        let saturated = light.splat(SATURATED);
        let mut brightest = light.splat(0.0);
        for at in (0..self.padded).step_by(LANES) {
            let mut b = [light.splat(0.0); 3];
            for ((b, row), scale) in b
                .iter_mut()
                .zip([&mut *red, &mut *green, &mut *blue])
                .zip(&lights.scale)
            {
                *b = light.floats(eight(row, at)) * light.floats(eight(scale, at));
                row[at..at + LANES].copy_from_slice(&b.to_array());
            }
            let [r, g, b] = b;
            let [red_level, green_level, blue_level] = &lights.saturated_b;
            let unsaturated = r.simd_lt(light.floats(eight(red_level, at)))
                & g.simd_lt(light.floats(eight(green_level, at)))
                & b.simd_lt(light.floats(eight(blue_level, at)));
            let sum = r + g + b;
            self.own[at..at + LANES]
                .copy_from_slice(&blend(unsaturated, sum, saturated).to_array());
            brightest = blend(unsaturated & sum.simd_gt(brightest), sum, brightest);
        }
        for (grey, &own) in self.grey.iter_mut().zip(&self.own) {
            grey[lane] = own;
        }
        brightest.to_array().into_iter().fold(0.0, f32::max)
    }

    /// The normal and albedo of `lane`'s fit kept (with the last re-weighting's weights if
    /// the lane took them, `took_last`, else with the weights of the one before; with the
    /// threshold fit's before the first re-weighting): the normal `g/|g|` and each channel's
    /// albedo the weighted least-squares scale along it, Σ w (n·l) b / Σ w (n·l)², summed
    /// over the lights side by side.
    #[inline(always)]
    fn lane_fit<E: Isa<LANES>>(
        &mut self,
        light: E,
        lane: usize,
        took_last: bool,
        lights: &Lights,
    ) -> PixelFit {
        let (g, gram, count) = (self.g[lane], self.gram[lane], self.count[lane]);
        if self.iterations[lane] == 0 {
            let level = self.level[lane];
            for (weight, grey) in self.finishing.iter_mut().zip(&self.grey) {
                *weight = if grey[lane] > level && grey[lane] < SATURATED {
                    1.0
                } else {
                    0.0
                };
            }
        } else {
            let kept = if took_last {
                &self.candidate
            } else {
                &self.previous
            };
            for (weight, kept) in self.finishing.iter_mut().zip(kept) {
                *weight = kept[lane];
            }
        }
        let normal = g.normalize();
        let (nx, ny, nz) = (
            light.splat(normal.x),
            light.splat(normal.y),
            light.splat(normal.z),
        );
        let mut sums = [light.splat(0.0); 3];
        let (red, green, blue) = self.lane_channels(lane);
        for at in (0..self.padded).step_by(LANES) {
            let shading = nx * light.floats(eight(&lights.direction[0], at))
                + ny * light.floats(eight(&lights.direction[1], at))
                + nz * light.floats(eight(&lights.direction[2], at));
            let weighted = light.floats(eight(&self.finishing, at)) * shading;
            for (sum, channel) in sums.iter_mut().zip([red, green, blue]) {
                *sum += weighted * light.floats(eight(channel, at));
            }
        }
        let denominator = normal.dot(gram * normal);
        let sums = lanes_of(sums).map(total);
        PixelFit {
            normal: normal.to_array(),
            albedo: sums.map(|sum| (sum / denominator).max(0.0)),
            flag: flag::OK,
            used: count as u16,
        }
    }

    /// The residuals of the lanes' fits and the Tukey scale of the re-weighting lanes' (1 /
    /// ([`TUKEY_SCALES`] × robust scale), 0 for the others). Returns it and the lanes whose
    /// fits light fewer than [`TUKEY_MIN`] unsaturated observations.
    #[inline(always)]
    fn residuals<V: Isa<W>>(&mut self, isa: V) -> ([f32; W], [bool; W]) {
        let g = self.g;
        let (gx, gy, gz) = (
            isa.floats(g.map(|g| g.x)),
            isa.floats(g.map(|g| g.y)),
            isa.floats(g.map(|g| g.z)),
        );
        let (zero, saturated, magnitude, unlit) = (
            isa.splat(0.0),
            isa.splat(SATURATED),
            isa.splat_int(0x7fff_ffff),
            isa.splat_int(UNLIT),
        );
        let mut lit = isa.splat_int(0);
        for ((grey, key), l) in self.grey.iter().zip(&mut self.key).zip(&self.light) {
            let grey = isa.floats(*grey);
            let predicted = gz.mul_add(isa.splat(l[2]), gy.mul_add(isa.splat(l[1]), gx * l[0]));
            let use_it = (predicted.simd_gt(zero) & grey.simd_lt(saturated)).to_bits();
            *key = blend(use_it, (grey - predicted).to_bits() & magnitude, unlit).to_array();
            lit -= use_it;
        }
        let lit = lit.to_array();
        let too_few_lit: [bool; W] = std::array::from_fn(|lane| lit[lane] < TUKEY_MIN as i32);
        let active: [bool; W] =
            std::array::from_fn(|lane| self.occupied[lane] && !too_few_lit[lane]);
        let median = median_keys(isa, &self.key, lit, self.median_key, self.bracket, active);
        let mut inverse = [0.0f32; W];
        for lane in (0..W).filter(|&lane| active[lane]) {
            let moved = median[lane]
                .abs_diff(self.median_key[lane])
                .min(BRACKET as u32) as i32;
            self.bracket[lane] = (2 * moved).clamp(BRACKET_MIN, BRACKET);
            self.median_key[lane] = median[lane];
            let scale = (MAD_TO_SIGMA * f32::from_bits(median[lane] as u32))
                .max(SCALE_FLOOR * g[lane].length());
            inverse[lane] = 1.0 / (TUKEY_SCALES * scale);
        }
        (inverse, too_few_lit)
    }

    /// Sets the candidate weights from the residuals and the Tukey scale `inverse` (see
    /// [`Machine::residuals`]; meaningless in the lanes where it is 0) and returns, for every
    /// lane, Σ w l lᵀ, Σ w l b (channel sum) and the number of observations with weight.
    #[inline(always)]
    fn candidate_sums<V: Isa<W>>(
        &mut self,
        isa: V,
        inverse: [f32; W],
    ) -> ([Mat3; W], [Vec3; W], [usize; W]) {
        // One pass: its ten sums stay in registers, and as each takes one fused multiply-add
        // a light, none waits on its last.
        let (inverse, zero) = (isa.floats(inverse), isa.splat(0.0));
        let mut rhs = [zero; 3];
        let mut gram = [zero; 6];
        let mut count = isa.splat_int(0);
        for (((candidate, grey), key), l) in self
            .candidate
            .iter_mut()
            .zip(&self.grey)
            .zip(&self.key)
            .zip(&self.light)
        {
            let weight = tukey_weight(isa, inverse, *key);
            *candidate = weight.to_array();
            let weighted = weight * isa.floats(*grey);
            for (sum, &l) in rhs.iter_mut().zip(&l[..3]) {
                *sum = weighted.mul_add(isa.splat(l), *sum);
            }
            count -= weight.simd_gt(zero).to_bits();
            for (sum, &ll) in gram.iter_mut().zip(&l[3..]) {
                *sum = weight.mul_add(isa.splat(ll), *sum);
            }
        }
        let (gram, rhs, count) = (lanes_of(gram), lanes_of(rhs), count.to_array());
        let grams = std::array::from_fn(|lane| symmetric(gram.map(|m| m[lane])));
        (
            grams,
            std::array::from_fn(|lane| Vec3::new(rhs[0][lane], rhs[1][lane], rhs[2][lane])),
            count.map(|c| c as usize),
        )
    }
}

#[cfg(target_arch = "x86_64")]
impl Machine<8> {
    /// [`Machine::run_in`] in AVX2 registers, compiled for AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    fn run_avx2(
        &mut self,
        isa: crate::ps::lanes::Avx2,
        source: &Source,
        chunk: &[usize],
        fits: &mut Vec<(usize, PixelFit)>,
    ) {
        self.run_in(isa, isa, source, chunk, fits);
    }
}

#[cfg(target_arch = "x86_64")]
impl Machine<16> {
    /// [`Machine::run_in`] with sixteen lanes in AVX-512 registers (each pixel's lights
    /// eight at a time in AVX2 registers, as in [`Machine::run_avx2`]), compiled for them.
    #[target_feature(enable = "avx512f,avx2,fma")]
    fn run_avx512(
        &mut self,
        isa: crate::ps::lanes::Avx512,
        source: &Source,
        chunk: &[usize],
        fits: &mut Vec<(usize, PixelFit)>,
    ) {
        self.run_in(isa, isa.avx2(), source, chunk, fits);
    }
}

/// `if_true` where `mask`'s bits are set, else `if_false` (`wide`'s `select` is a call on
/// x86-64 before SSE4.1).
#[inline(always)]
fn blend<T: Copy + BitXor<Output = T> + BitAnd<Output = T>>(mask: T, if_true: T, if_false: T) -> T {
    if_false ^ ((if_false ^ if_true) & mask)
}

/// Σ w l lᵀ, Σ w l b and Σ w of the threshold fit of a pixel whose channel-summed `b` are
/// `grey` (padded like `lights`): weight 1 above `level` and below [`SATURATED`], else 0.
#[inline(always)]
fn threshold_sums<E: Isa<LANES>>(
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
fn eight(values: &[f32], at: usize) -> [f32; LANES] {
    values[at..at + LANES]
        .try_into()
        .expect("padded to whole lanes")
}

/// The lanes of each of `sums`. (A loop, not a closure: a closure would not be compiled for
/// the instruction set of its caller.)
#[inline(always)]
fn lanes_of<F: Floats<W>, const W: usize, const N: usize>(sums: [F; N]) -> [[f32; W]; N] {
    let mut lanes = [[0.0; W]; N];
    for (lane, sum) in lanes.iter_mut().zip(sums) {
        *lane = sum.to_array();
    }
    lanes
}

/// Tukey's weight of an observation whose absolute residual has the bits `key`, for the
/// scale `inverse` (see [`Machine::residuals`]): 0 where `key` is [`UNLIT`], a NaN that no
/// comparison holds for.
#[inline(always)]
fn tukey_weight<V: Isa<W>, const W: usize>(isa: V, inverse: V::F, key: [i32; W]) -> V::F {
    let one = isa.splat(1.0);
    let u = isa.ints(key).to_floats() * inverse;
    let inside = u.simd_lt(one);
    // 1 − u², rounded once.
    let tukey = (u ^ isa.splat(-0.0)).mul_add(u, one);
    (tukey * tukey) & inside
}

/// The sum of the lanes of a sum taken side by side, in lane order.
fn total(lanes: [f32; LANES]) -> f32 {
    lanes.iter().sum()
}

/// The symmetric matrix of xx, xy, xz, yy, yz, zz.
fn symmetric(m: [f32; 6]) -> Mat3 {
    Mat3::from_cols(
        Vec3::new(m[0], m[1], m[2]),
        Vec3::new(m[1], m[3], m[4]),
        Vec3::new(m[2], m[4], m[5]),
    )
}

/// For each `active` lane, the `lit / 2`-th smallest (from 0) of its `keys` below
/// [`UNLIT`], of which it has `lit`: a bisection on the keys' values, each step counting the
/// keys below a threshold of each lane, until at most [`SELECT`] keys (or one value) are left
/// in a lane's bracket, then one pass that sorts each lane's smallest [`SELECT`] keys of the
/// bracket. A lane with a `guess` (a positive key) first brackets its median by thresholds
/// ±`bracket` around it, then 4, 16, 64... times as far on the side where the median lies,
/// until one holds it.
#[inline(always)]
fn median_keys<V: Isa<W>, const W: usize>(
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_keys_match_a_sort_for_ties_gaps_and_guesses_on_either_side() {
        check_median_keys(Portable);
        #[cfg(target_arch = "x86_64")]
        if let Some(avx2) = crate::ps::lanes::Avx2::detect() {
            check_median_keys(avx2);
        }
        #[cfg(target_arch = "x86_64")]
        if let Some(avx512) = crate::ps::lanes::Avx512::detect() {
            check_median_keys(avx512);
        }
    }

    /// The registers a test runs the fit in.
    #[derive(Debug, Clone, Copy)]
    enum Registers {
        Portable,
        #[cfg(target_arch = "x86_64")]
        Avx2,
        #[cfg(target_arch = "x86_64")]
        Avx512,
    }

    /// The registers of this CPU besides [`Registers::Portable`].
    fn wider_registers() -> Vec<Registers> {
        #[cfg(target_arch = "x86_64")]
        {
            let avx2 = crate::ps::lanes::Avx2::detect().map(|_| Registers::Avx2);
            let avx512 = crate::ps::lanes::Avx512::detect().map(|_| Registers::Avx512);
            avx2.into_iter().chain(avx512).collect()
        }
        #[cfg(not(target_arch = "x86_64"))]
        Vec::new()
    }

    /// A pixel's true normal and albedo.
    type Truth = (Vec3, f32);

    /// The fits of `pixels` pixels of random normals and albedos under `count` lights, with
    /// soft shadows, highlights and saturated observations among them, in `registers`, and
    /// each pixel's true normal and albedo.
    fn fits_of_noisy_pixels(
        pixels: usize,
        count: usize,
        registers: Registers,
    ) -> (Vec<(usize, PixelFit)>, Vec<Truth>) {
        let mut state = 99u32;
        let mut uniform = || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state as f32 / u32::MAX as f32
        };
        let directions: Vec<Vec3> = (0..count)
            .map(|k| {
                Vec3::new(
                    (k as f32 * 2.4).cos(),
                    (k as f32 * 2.4).sin(),
                    1.0 + k as f32 / 20.0,
                )
                .normalize()
            })
            .collect();
        let gram = directions
            .iter()
            .fold(Mat3::ZERO, |m, &l| m + crate::ps::outer(l));
        let lights = Lights::new(
            &directions,
            &vec![[1.0; 3]; count],
            &vec![[1.5; 3]; count],
            gram,
        );
        let mut images = vec![0.0f32; count * pixels * 3];
        let mut truth = Vec::with_capacity(pixels);
        for p in 0..pixels {
            let normal = Vec3::new(uniform() - 0.5, uniform() - 0.5, 1.0).normalize();
            let albedo = 0.2 + 0.6 * uniform();
            truth.push((normal, albedo));
            for (k, l) in directions.iter().enumerate() {
                let mut value = albedo * l.dot(normal).max(0.0);
                match (uniform() * 10.0) as u32 {
                    0 => value *= 0.3 * uniform(),
                    1 => value += 0.8 * uniform(),
                    _ => value *= 1.0 + 0.01 * (uniform() - 0.5),
                }
                images[(k * pixels + p) * 3..][..3].fill(value);
            }
        }
        let mask = vec![true; pixels];
        let pixels: Vec<usize> = (0..pixels).collect();
        let source = Source {
            images: &images,
            n: mask.len(),
            lights: &lights,
            shadow_fraction: 0.05,
        };
        let mut fits = Vec::new();
        match registers {
            Registers::Portable => {
                Machine::<8>::new(&lights).run_in(Portable, Portable, &source, &pixels, &mut fits)
            }
            // SAFETY: `wider_registers` found the instructions.
            #[cfg(target_arch = "x86_64")]
            Registers::Avx2 => unsafe {
                Machine::new(&lights).run_avx2(
                    crate::ps::lanes::Avx2::detect().expect("AVX2"),
                    &source,
                    &pixels,
                    &mut fits,
                )
            },
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Registers::Avx512 => unsafe {
                Machine::new(&lights).run_avx512(
                    crate::ps::lanes::Avx512::detect().expect("AVX-512"),
                    &source,
                    &pixels,
                    &mut fits,
                )
            },
        }
        (fits, truth)
    }

    #[test]
    fn the_fit_finds_the_true_normals_and_albedos_with_the_same_bits_in_every_instruction_set() {
        // 37: lights that fill no whole lane group and an odd one out in the pairwise sums.
        for count in [40, 37] {
            let (portable, truth) = fits_of_noisy_pixels(300, count, Registers::Portable);
            assert_eq!(portable.len(), 300);
            let (mut angle_deg, mut albedo_error) = (0.0, 0.0);
            for (pixel, fit) in &portable {
                let (normal, albedo) = truth[*pixel];
                angle_deg += Vec3::from(fit.normal)
                    .dot(normal)
                    .clamp(-1.0, 1.0)
                    .acos()
                    .to_degrees()
                    / 300.0;
                albedo_error += fit.albedo.iter().map(|a| (a - albedo).abs()).sum::<f32>() / 900.0;
            }
            assert!(
                angle_deg < 0.5 && albedo_error < 0.005,
                "{count} lights: mean error {angle_deg}°, albedo {albedo_error}"
            );
            // Sixteen lanes finish the pixels in another order: compare them pixel by pixel.
            let by_pixel = |mut fits: Vec<(usize, PixelFit)>| {
                fits.sort_by_key(|&(pixel, _)| pixel);
                fits
            };
            let portable = by_pixel(portable);
            for registers in wider_registers() {
                assert_eq!(
                    by_pixel(fits_of_noisy_pixels(300, count, registers).0),
                    portable,
                    "{count} lights, {registers:?}"
                );
            }
        }
    }

    fn check_median_keys<V: Isa<W>, const W: usize>(isa: V) {
        let mut state = 12345u32;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state
        };
        for trial in 0..200 {
            let k_count = 4 + (next() % 93) as usize;
            let mut keys = vec![[UNLIT; W]; k_count];
            for key in keys.iter_mut() {
                for lane in key.iter_mut() {
                    let roll = next() % 10;
                    *lane = match roll {
                        0 => UNLIT,
                        1 => 0x3c00_0000, // ties
                        _ => {
                            (next() % 0x4000_0000) as i32
                                + if trial % 2 == 0 { 0x3000_0000 } else { 0 }
                        }
                    };
                }
            }
            let lit: [i32; W] =
                std::array::from_fn(|lane| keys.iter().filter(|k| k[lane] != UNLIT).count() as i32);
            let guess: [i32; W] = std::array::from_fn(|lane| {
                [0, 0x3c00_0000, 0x3400_0000, 0x7000_0000][(lane + trial) % 4]
            });
            let active: [bool; W] = std::array::from_fn(|lane| lit[lane] > 0);
            let bracket: [i32; W] =
                std::array::from_fn(|lane| [BRACKET, BRACKET_MIN, 1 << 16][(lane + trial) % 3]);
            let median = median_keys(isa, &keys, lit, guess, bracket, active);
            for lane in (0..W).filter(|&lane| active[lane]) {
                let mut sorted: Vec<i32> = keys
                    .iter()
                    .map(|k| k[lane])
                    .filter(|&k| k != UNLIT)
                    .collect();
                sorted.sort_unstable();
                assert_eq!(
                    median[lane],
                    sorted[lit[lane] as usize / 2],
                    "trial {trial} lane {lane}"
                );
            }
        }
    }
}

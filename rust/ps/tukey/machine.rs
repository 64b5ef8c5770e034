//! The lanes of the Tukey fit and their pixels' observations: a chunk's observations staged
//! image by image, each lane loaded with a pixel and its threshold fit, re-weighted until it
//! settles, finished and refilled with the chunk's next pixel.

use glam::{Mat3, Vec3};

use crate::ps::kernel::{flag, full_fit, solved, Lights, PixelFit, LANES, MAD_TO_SIGMA, SATURATED};
use crate::ps::lanes::{Floats, Ints, Isa};

use super::median::median_keys;
use super::sums::{blend, eight, lanes_of, symmetric, threshold_sums, total, tukey_weight};
use super::*;

/// `W` lanes and their pixels' observations.
pub(super) struct Machine<const W: usize> {
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
    pub(super) fn new(source: &Lights) -> Machine<W> {
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
    pub(super) fn run_in<V: Isa<W>, E: Isa<LANES>>(
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
    pub(super) fn run_avx2(
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
    pub(super) fn run_avx512(
        &mut self,
        isa: crate::ps::lanes::Avx512,
        source: &Source,
        chunk: &[usize],
        fits: &mut Vec<(usize, PixelFit)>,
    ) {
        self.run_in(isa, isa.avx2(), source, chunk, fits);
    }
}

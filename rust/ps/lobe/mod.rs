//! Photometric stereo for glossy and metallic objects: a Lambertian base plus one specular
//! lobe per pixel.
//!
//! Each pixel starts from its Tukey fit ([`crate::ps::tukey`]) and fits its channel-summed
//! observations with `b_k = [n·l_k]₊ (a + c (n·h_k)^p)`: `h_k` is the half vector between
//! light k and the view direction (the camera's +z when it is distant, the pixel's own
//! direction toward a pinhole), `a ≥ 0` the diffuse albedo and
//! `c ≥ 0` the lobe's height (a Blinn-Phong lobe on a Lambertian base; `c = 0` is the
//! Lambertian fit). For each exponent p of [`LOBE_EXPONENTS`] and from two starts, the Tukey
//! normal and the half vector of the pixel's brightest observation, it alternates the linear
//! fit of (a, c) with a damped Gauss-Newton step of the normal on its tangent plane
//! (variable projection: the step allows for (a, c) following it), every observation
//! re-weighted, from the second round on, by Tukey's biweight of its residual in units of
//! [`LOBE_SCALES`] robust scales (1.4826 × the median absolute residual of the lit
//! observations): shadows and inter-reflections that neither term explains lose their
//! weight.
//!
//! A lobe fit replaces the Tukey fit only where it lowers Tukey's loss, summed over every
//! unsaturated observation at the Tukey fit's robust scale, by more than the Bayesian
//! information criterion asks for its two extra parameters (twice that from the second
//! start). Each channel's albedo is its own diffuse scale under the kept fit's weights: the
//! highlight goes to the lobe, not to the albedo. Saturated observations carry no weight.
//!
//! A pixel whose Tukey fit has too few observations, or lights fewer than [`LOBE_MIN_LIT`]
//! unsaturated ones, keeps that fit.
//!
//! A pixel's lights are taken [`LANES`] at a time in vector registers ([`crate::ps::lanes`]: AVX2
//! where the CPU has it, chosen at run time), with the same bits in each instruction set.
//!
//! This module takes each pixel from its Tukey fit to the fit kept; beside it, each
//! importing only those above it: `model`, the shading of a normal, the residuals and the
//! weighted sums; `weights`, Tukey's weights, the robust scale and the loss; `exponent`,
//! one exponent's fit from one start.

use glam::Vec3;

use crate::error::Result;
use crate::ps::kernel::{
    fit_masked, flag, gather, Lights, PixelFit, PsOutput, Scratch, LANES, SATURATED,
};
use crate::ps::lanes::{Isa, Portable};

use exponent::fit_exponent;
use model::{diffuse_and_lobe, shading};
use weights::{loss, robust_scale};

mod exponent;
mod model;
mod weights;

/// The lobe exponents tried, as powers of two: `p = 2^s` for `s` in `0..LOBE_EXPONENTS`
/// (1 to 128: lobes from about 60° to about 6° wide at half height).
pub const LOBE_EXPONENTS: u32 = 8;
/// Rounds of (a, c) fit and normal step per exponent and start (at most: a fit whose step
/// settles ends sooner), unless the settings ask for others.
pub const LOBE_ROUNDS: usize = 15;
/// Tukey's biweight constant of the lobe fit, in robust scales (as [`crate::ps::tukey::TUKEY_SCALES`]).
pub const LOBE_SCALES: f32 = 2.5;
/// Fewest unsaturated observations that the Tukey normal lights for a lobe to be tried: one
/// more than the lobe fit's five unknowns (the normal's two, `a`, `c` and the exponent), so
/// that a lobe cannot explain a pixel merely by having as many unknowns as observations.
pub const LOBE_MIN_LIT: usize = 6;
/// Parameters that a lobe adds to the Lambertian fit: its height and exponent.
const LOBE_PARAMETERS: f32 = 2.0;
/// Pixels per parallel task.
const TILE: usize = 32;

/// Refits every pixel where `mask` is true and whose Tukey fit in `out` is usable, from
/// `images` laid out `(K, pixels, 3)`, with a diffuse term and a specular lobe, each
/// exponent fitted for at most `rounds` rounds from each start, in the widest registers the
/// CPU has (the same results in each). The half vectors look from each pixel's direction
/// toward the camera in `views`, or without them from a distant camera along +z.
pub(crate) fn fit_pixels(
    images: &[f32],
    mask: &[bool],
    lights: &Lights,
    rounds: usize,
    views: Option<&[[f32; 3]]>,
    out: &mut PsOutput,
) -> Result<()> {
    let job = Job::new(images, lights, rounds, views, out);
    let work = || Box::new((Scratch::default(), Work::default(), HalfVectors::default()));
    #[cfg(target_arch = "x86_64")]
    if let Some(avx2) = crate::ps::lanes::Avx2::detect() {
        // SAFETY: `detect` found AVX2 and FMA.
        return fit_masked(mask, TILE, out, work, |state, tile, fits| unsafe {
            job.fit_tile_avx2(avx2, state, tile, fits)
        });
    }
    fit_masked(mask, TILE, out, work, |state, tile, fits| {
        job.fit_tile(Portable, state, tile, fits)
    })
}

/// What every tile's fit reads.
struct Job<'a> {
    /// `(K, n, 3)`.
    images: &'a [f32],
    /// Pixels per image.
    n: usize,
    lights: &'a Lights,
    /// The half vectors of a distant camera along +z.
    half: HalfVectors,
    /// Each pixel's direction toward the camera, where it is not the distant +z.
    views: Option<&'a [[f32; 3]]>,
    /// Most rounds of each exponent's fit.
    rounds: usize,
    /// Each pixel's Tukey normal, channel-summed albedo and flag.
    starts: Vec<([f32; 3], f32, u8)>,
}

impl<'a> Job<'a> {
    /// The lobe fit of `images` from the Tukey fits in `out`.
    fn new(
        images: &'a [f32],
        lights: &'a Lights,
        rounds: usize,
        views: Option<&'a [[f32; 3]]>,
        out: &PsOutput,
    ) -> Job<'a> {
        let starts = out
            .normals
            .iter()
            .zip(&out.albedo)
            .zip(&out.flags)
            .map(|((&normal, albedo), &f)| (normal, albedo.iter().sum(), f))
            .collect();
        Job {
            images,
            n: out.flags.len(),
            lights,
            half: HalfVectors::toward(lights, Vec3::Z),
            views,
            rounds,
            starts,
        }
    }

    /// Fits the pixels of `tile` into `fits` (those that keep the Tukey fit left out).
    #[inline(always)]
    fn fit_tile<V: Isa<LANES>>(
        &self,
        isa: V,
        (scratch, work, pixel_half): &mut (Scratch, Work, HalfVectors),
        tile: &[usize],
        fits: &mut Vec<(usize, PixelFit)>,
    ) {
        let lights = self.lights;
        gather(self.images, self.n, tile, lights, scratch);
        let padded = lights.padded();
        for (i, &p) in tile.iter().enumerate() {
            let (start, start_albedo, start_flag) = self.starts[p];
            let grey = &scratch.grey[i * padded..][..padded];
            let rgb = &scratch.rgb[i * lights.count..][..lights.count];
            let fit = if start_flag == flag::OK {
                let half = match self.views {
                    None => &self.half,
                    Some(views) => {
                        pixel_half.fill(lights, Vec3::from(views[p]));
                        &*pixel_half
                    }
                };
                refit(
                    isa,
                    self,
                    half,
                    grey,
                    rgb,
                    (Vec3::from(start), start_albedo),
                    work,
                )
            } else {
                None
            };
            if let Some(fit) = fit {
                fits.push((p, fit));
            }
        }
    }

    /// [`Job::fit_tile`] compiled for AVX2 and FMA: the same bits (no operation is fused
    /// that the portable build does not fuse), the sums over [`LANES`] lights in one register.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn fit_tile_avx2(
        &self,
        isa: crate::ps::lanes::Avx2,
        state: &mut (Scratch, Work, HalfVectors),
        tile: &[usize],
        fits: &mut Vec<(usize, PixelFit)>,
    ) {
        self.fit_tile(isa, state, tile, fits);
    }
}

/// Each light's half vector with a view direction, padded like [`Lights`], in groups of
/// [`LANES`] lights.
#[derive(Default)]
struct HalfVectors([Vec<Group>; 3]);

impl HalfVectors {
    /// The half vectors of `lights` with the unit direction `view` toward the camera.
    fn toward(lights: &Lights, view: Vec3) -> HalfVectors {
        let mut half = HalfVectors::default();
        half.fill(lights, view);
        half
    }

    /// Sets these to the half vectors of `lights` with `view`, reusing their memory.
    fn fill(&mut self, lights: &Lights, view: Vec3) {
        for axis in &mut self.0 {
            axis.clear();
            axis.resize(lights.padded() / LANES, [0.0; LANES]);
        }
        for k in 0..lights.count {
            let h = (lights.direction(k) + view).normalize_or_zero();
            for (axis, value) in self.0.iter_mut().zip(h.to_array()) {
                axis[k / LANES][k % LANES] = value;
            }
        }
    }

    #[inline(always)]
    fn get(&self, k: usize) -> Vec3 {
        Vec3::from(self.0.each_ref().map(|axis| axis[k / LANES][k % LANES]))
    }
}

/// [`LANES`] lights' values side by side: loops over a group's lanes vectorise.
type Group = [f32; LANES];

/// One pixel's working memory, one value per (padded) light, in groups of [`LANES`].
#[derive(Default)]
struct Work {
    /// Channel-summed `b`, 0 where saturated.
    b: Vec<Group>,
    /// 1 where unsaturated, 0 where saturated or padding.
    usable: Vec<Group>,
    /// The current fit's weights.
    weight: Vec<Group>,
    /// `[n·l]₊` and `[n·l]₊ (n·h)^p` of the current normal.
    diffuse: Vec<Group>,
    specular: Vec<Group>,
    /// `n·h` of the current normal (at least [`NH_MIN`](model::NH_MIN)).
    nh: Vec<Group>,
    /// Bits of the absolute residuals, the lit observations' packed at the front (a slot per
    /// padded light), for their median.
    spread: Vec<u32>,
    /// The best fit's weights so far.
    best_weight: Vec<Group>,
    /// The last median found of `spread`: where the next is sought first.
    median_guess: u32,
}

/// Light `k`'s value in `groups`.
#[inline(always)]
fn at(groups: &[Group], k: usize) -> f32 {
    groups[k / LANES][k % LANES]
}

/// A padded row of [`Lights`] in groups of [`LANES`].
#[inline(always)]
fn grouped(row: &[f32]) -> &[Group] {
    row.as_chunks().0
}

/// A fit of one exponent from one start.
struct LobeFit {
    normal: Vec3,
    /// Its [`loss`].
    cost: f32,
    /// `log2 p`.
    shift: u32,
    /// The lobe's height `c`.
    height: f32,
}

/// The lobe fit of one pixel of `job` (channel-summed `b` per padded light `grey`, RGB `b`
/// per light `rgb`) from its Tukey fit `start` (normal, channel-summed albedo), or `None`
/// when none explains the observations better than that fit.
///
/// Fits are compared by the sum of Tukey's loss `1 − (1 − u²)³` (1 beyond `|u| = 1`) over
/// every unsaturated observation, `u` the residual in units of [`LOBE_SCALES`] robust scales
/// of the Tukey fit: one scale for all, so that a fit cannot look better by giving up
/// observations.
#[inline(always)]
fn refit<V: Isa<LANES>>(
    isa: V,
    job: &Job,
    half: &HalfVectors,
    grey: &[f32],
    rgb: &[[f32; 3]],
    start: (Vec3, f32),
    work: &mut Work,
) -> Option<PixelFit> {
    let lights = job.lights;
    let groups = lights.padded() / LANES;
    for v in [
        &mut work.b,
        &mut work.usable,
        &mut work.weight,
        &mut work.diffuse,
        &mut work.specular,
        &mut work.nh,
        &mut work.best_weight,
    ] {
        v.clear();
        v.resize(groups, [0.0; LANES]);
    }
    work.spread.resize(groups * LANES, 0);
    for (k, &value) in grey.iter().enumerate() {
        let ok = k < lights.count && value < SATURATED;
        work.b[k / LANES][k % LANES] = if ok { value } else { 0.0 };
        work.usable[k / LANES][k % LANES] = if ok { 1.0 } else { 0.0 };
    }
    let brightest = (0..lights.count)
        .filter(|&k| at(&work.usable, k) > 0.0)
        .max_by(|&i, &j| at(&work.b, i).total_cmp(&at(&work.b, j)))?;
    let (normal, albedo) = start;
    shading(isa, lights, half, normal, 0, work);
    let lit = work
        .diffuse
        .as_flattened()
        .iter()
        .zip(work.usable.as_flattened())
        .filter(|&(&f, &u)| f > 0.0 && u > 0.0)
        .count();
    if lit < LOBE_MIN_LIT {
        return None;
    }
    let reach = 1.0 / (LOBE_SCALES * robust_scale(isa, albedo, 0.0, work)?);
    // Bayesian information criterion: the lobe fit must lower χ² (the loss near zero is 3u²
    // = 3/LOBE_SCALES² of a squared residual in robust scales) by more than ln N per
    // parameter it adds, N the unsaturated observations.
    let observations = work.usable.as_flattened().iter().sum::<f32>();
    let penalty = 3.0 / (LOBE_SCALES * LOBE_SCALES) * LOBE_PARAMETERS * observations.ln();
    let start_cost = loss(isa, albedo, 0.0, reach, work) - penalty;
    // A fit from the second start (a different basin, sought where the first found none)
    // must beat the best from the Tukey normal by the same margin again.
    let mut best: Option<LobeFit> = None;
    for (from, margin) in [(normal, 0.0), (half.get(brightest), penalty)] {
        // The loss is never negative: no fit can clear a bar below the margin.
        if best.as_ref().map_or(start_cost, |b| b.cost) <= margin {
            continue;
        }
        for shift in 0..LOBE_EXPONENTS {
            let fit = fit_exponent(isa, job, half, from, shift, reach, work);
            if fit.cost + margin < best.as_ref().map_or(start_cost, |b| b.cost) {
                work.best_weight.copy_from_slice(&work.weight);
                best = Some(fit);
            }
        }
    }
    finish(isa, rgb, lights, half, &best?, work)
}

/// The kept fit's normal and each channel's diffuse albedo under its weights.
#[inline(always)]
fn finish<V: Isa<LANES>>(
    isa: V,
    rgb: &[[f32; 3]],
    lights: &Lights,
    half: &HalfVectors,
    best: &LobeFit,
    work: &mut Work,
) -> Option<PixelFit> {
    shading(isa, lights, half, best.normal, best.shift, work);
    let (weight, diffuse, specular) = (
        work.best_weight.as_flattened(),
        work.diffuse.as_flattened(),
        work.specular.as_flattened(),
    );
    let used = weight[..lights.count]
        .iter()
        .zip(diffuse)
        .filter(|&(&w, &f)| w > 0.0 && f > 0.0)
        .count() as u16;
    let mut albedo = [0.0f32; 3];
    for (c, value) in albedo.iter_mut().enumerate() {
        let (mut ff, mut fs, mut ss, mut fb, mut sb) = (0.0f32, 0.0f32, 0.0f32, 0.0f32, 0.0f32);
        for (k, b) in rgb.iter().enumerate() {
            let (w, f, s) = (weight[k], diffuse[k], specular[k]);
            ff += w * f * f;
            fs += w * f * s;
            ss += w * s * s;
            fb += w * f * b[c];
            sb += w * s * b[c];
        }
        *value = diffuse_and_lobe(ff, fs, ss, fb, sb).0;
    }
    (best.normal.is_finite() && used >= 3).then(|| PixelFit {
        normal: best.normal.to_array(),
        albedo,
        flag: if best.height > 0.0 {
            flag::LOBE
        } else {
            flag::OK
        },
        used,
    })
}

#[cfg(test)]
mod tests;

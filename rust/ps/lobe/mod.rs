//! Photometric stereo for glossy and metallic objects: a Lambertian base plus one specular
//! lobe per pixel.
//!
//! Each pixel starts from its Tukey fit ([`crate::ps::tukey`]) and fits its channel-summed
//! observations with `b_k = [n·l_k]₊ (a + c (n·h_k)^p)`: `h_k` is the half vector between
//! light k and the view direction (the camera's +z, distant), `a ≥ 0` the diffuse albedo and
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

use glam::Vec3;

use crate::error::Result;
use crate::ps::lanes::{Floats, Ints, Isa, Portable};
use crate::ps::trim::{gather, Lights, Scratch, LANES, MAD_TO_SIGMA, SATURATED};
use crate::ps::{fit_masked, flag, PixelFit, PsOutput};

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
/// Least robust scale, as a fraction of `a + c` (noise-free data).
const SCALE_FLOOR: f32 = 1e-4;
/// Longest step of the normal per round (about 11°).
const STEP_MAX: f32 = 0.2;
/// Levenberg-Marquardt damping, as a fraction of the normal equations' trace.
const DAMPING: f32 = 1e-3;
/// A round whose step is shorter than this (about 0.06°) ends the exponent's fit.
const STEP_SETTLED: f32 = 1e-3;
/// Least `n·h` (so that `(n·h)^(p−1)` stays finite).
const NH_MIN: f32 = 1e-6;
/// Half-width of the bracket around the last median in which the next is sought, in units
/// of an `f32`'s last bit (about ±12 %).
const BRACKET: u32 = 1 << 20;
/// Pixels per parallel task.
const TILE: usize = 32;

/// Refits every pixel where `mask` is true and whose Tukey fit in `out` is usable, from
/// `images` laid out `(K, pixels, 3)`, with a diffuse term and a specular lobe, each
/// exponent fitted for at most `rounds` rounds from each start, in the widest registers the
/// CPU has (the same results in each).
pub(crate) fn fit_pixels(
    images: &[f32],
    mask: &[bool],
    lights: &Lights,
    rounds: usize,
    out: &mut PsOutput,
) -> Result<()> {
    let job = Job::new(images, lights, rounds, out);
    let work = || Box::new((Scratch::default(), Work::default()));
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
    half: HalfVectors,
    /// Most rounds of each exponent's fit.
    rounds: usize,
    /// Each pixel's Tukey normal, channel-summed albedo and flag.
    starts: Vec<([f32; 3], f32, u8)>,
}

impl<'a> Job<'a> {
    /// The lobe fit of `images` from the Tukey fits in `out`.
    fn new(images: &'a [f32], lights: &'a Lights, rounds: usize, out: &PsOutput) -> Job<'a> {
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
            half: HalfVectors::new(lights),
            rounds,
            starts,
        }
    }

    /// Fits the pixels of `tile` into `fits` (those that keep the Tukey fit left out).
    #[inline(always)]
    fn fit_tile<V: Isa<LANES>>(
        &self,
        isa: V,
        (scratch, work): &mut (Scratch, Work),
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
                refit(
                    isa,
                    self,
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
        state: &mut (Scratch, Work),
        tile: &[usize],
        fits: &mut Vec<(usize, PixelFit)>,
    ) {
        self.fit_tile(isa, state, tile, fits);
    }
}

/// Each light's half vector with the view direction (0, 0, 1), padded like [`Lights`], in
/// groups of [`LANES`] lights.
struct HalfVectors([Vec<Group>; 3]);

impl HalfVectors {
    fn new(lights: &Lights) -> HalfVectors {
        let mut half: [Vec<Group>; 3] =
            std::array::from_fn(|_| vec![[0.0; LANES]; lights.padded() / LANES]);
        for k in 0..lights.count {
            let h = (lights.direction(k) + Vec3::Z).normalize_or_zero();
            for (axis, value) in half.iter_mut().zip(h.to_array()) {
                axis[k / LANES][k % LANES] = value;
            }
        }
        HalfVectors(half)
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
    /// `n·h` of the current normal (at least [`NH_MIN`]).
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

/// `(a, c) ≥ 0` minimising `Σ w (b − a f − c s)²` from its normal equations' sums.
#[inline(always)]
fn diffuse_and_lobe(ff: f32, fs: f32, ss: f32, fb: f32, sb: f32) -> (f32, f32) {
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

/// Two unit vectors spanning the plane normal to `n`.
#[inline(always)]
fn tangents(n: Vec3) -> (Vec3, Vec3) {
    let reference = if n.z.abs() < 0.9 { Vec3::Z } else { Vec3::X };
    let t1 = n.cross(reference).normalize();
    (t1, n.cross(t1))
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
    grey: &[f32],
    rgb: &[[f32; 3]],
    start: (Vec3, f32),
    work: &mut Work,
) -> Option<PixelFit> {
    let (lights, half) = (job.lights, &job.half);
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
            let fit = fit_exponent(isa, job, from, shift, reach, work);
            if fit.cost + margin < best.as_ref().map_or(start_cost, |b| b.cost) {
                work.best_weight.copy_from_slice(&work.weight);
                best = Some(fit);
            }
        }
    }
    finish(isa, rgb, lights, half, &best?, work)
}

/// `[n·l]₊` and `[n·l]₊ (n·h)^p` of every light into `work`.
#[inline(always)]
fn shading<V: Isa<LANES>>(
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

/// Fits exponent `2^shift` from normal `from` for at most `job`'s rounds, its [`loss`] at
/// `reach`; leaves the fit's weights in `work.weight`.
#[inline(always)]
fn fit_exponent<V: Isa<LANES>>(
    isa: V,
    job: &Job,
    from: Vec3,
    shift: u32,
    reach: f32,
    work: &mut Work,
) -> LobeFit {
    let (lights, half) = (job.lights, &job.half);
    let p = (1u32 << shift) as f32;
    let mut n = from;
    work.weight.copy_from_slice(&work.usable);
    for round in 0..job.rounds {
        shading(isa, lights, half, n, shift, work);
        let (a, c) = lobe_scales(isa, work);
        let (t1, t2) = tangents(n);
        if round > 0 {
            reweight(isa, a, c, work);
        }
        // d model / d n = (a + c (n·h)^p) l + c p [n·l]₊ (n·h)^(p−1) h, where n·l > 0; the
        // normal equations of its two tangent components j1, j2 with (a, c) re-solved after
        // the step (variable projection, Kaufman's form): each column less its weighted
        // projection on the free ones of [n·l]₊ and [n·l]₊ (n·h)^p. The sums: the weighted
        // products of those four columns, and j1's and j2's with the residual.
        let groups = work.diffuse.len();
        let l = lights
            .direction
            .each_ref()
            .map(|row| &grouped(row)[..groups]);
        let h = half.0.each_ref().map(|row| &row[..groups]);
        let (diffuse, specular, nh, weight) = (
            &work.diffuse[..groups],
            &work.specular[..groups],
            &work.nh[..groups],
            &work.weight[..groups],
        );
        let (zero, nh_min, a_v, cp) = (
            isa.splat(0.0),
            isa.splat(NH_MIN),
            isa.splat(a),
            isa.splat(c * p),
        );
        let [m11, m12, m22, f1, f2, s1, s2, ff, fs, ss, q1, q2] = summed(
            isa,
            groups,
            #[inline(always)]
            |g| {
                let (nl, lit_lobe) = (isa.floats(diffuse[g]), isa.floats(specular[g]));
                // Unlit observations (and padding) add zeros.
                let w = nl.simd_gt(zero) & isa.floats(weight[g]);
                let along_l = a_v + lit_lobe * c / nl.max(nh_min);
                let along_h = lit_lobe * cp / isa.floats(nh[g]);
                let dx = along_l * isa.floats(l[0][g]) + along_h * isa.floats(h[0][g]);
                let dy = along_l * isa.floats(l[1][g]) + along_h * isa.floats(h[1][g]);
                let dz = along_l * isa.floats(l[2][g]) + along_h * isa.floats(h[2][g]);
                let j1 = dx * t1.x + dy * t1.y + dz * t1.z;
                let j2 = dx * t2.x + dy * t2.y + dz * t2.z;
                let r = residual(isa, work, g, a, c);
                let (wj1, wj2, wf, ws) = (w * j1, w * j2, w * nl, w * lit_lobe);
                [
                    wj1 * j1,
                    wj1 * j2,
                    wj2 * j2,
                    wf * j1,
                    wf * j2,
                    ws * j1,
                    ws * j2,
                    wf * nl,
                    wf * lit_lobe,
                    ws * lit_lobe,
                    wj1 * r,
                    wj2 * r,
                ]
            },
        );
        let (p11, p12, p22) = projected(a > 0.0, c > 0.0, [ff, fs, ss], [f1, s1], [f2, s2]);
        let (m11, m12, m22) = (m11 - p11, m12 - p12, m22 - p22);
        let damping = DAMPING * (m11 + m22) + 1e-12;
        let det = (m11 + damping) * (m22 + damping) - m12 * m12;
        let (s1, s2) = (
            ((m22 + damping) * q1 - m12 * q2) / det,
            ((m11 + damping) * q2 - m12 * q1) / det,
        );
        let mut step = t1 * s1 + t2 * s2;
        if !step.is_finite() {
            break;
        }
        let length = step.length();
        if length > STEP_MAX {
            step *= STEP_MAX / length;
        }
        n = (n + step).normalize();
        if length < STEP_SETTLED && round > 1 {
            break;
        }
    }
    shading(isa, lights, half, n, shift, work);
    let (a, c) = lobe_scales(isa, work);
    let cost = loss(isa, a, c, reach, work);
    LobeFit {
        normal: n,
        cost: if cost.is_finite() {
            cost
        } else {
            f32::INFINITY
        },
        shift,
        height: c,
    }
}

/// `uᵢᵀ G⁻¹ uⱼ` of the tangent columns' products `u1`, `u2` with the diffuse and lobe
/// columns (Gram `G` = `[ff, fs, ss]`), over the free ones (`diffuse`, `lobe`).
#[inline(always)]
fn projected(
    diffuse: bool,
    lobe: bool,
    [ff, fs, ss]: [f32; 3],
    u1: [f32; 2],
    u2: [f32; 2],
) -> (f32, f32, f32) {
    let det = ff * ss - fs * fs;
    match (diffuse, lobe) {
        (true, true) if det > 1e-6 * ff * ss => {
            let quad = |x: [f32; 2], y: [f32; 2]| {
                (x[0] * (ss * y[0] - fs * y[1]) + x[1] * (ff * y[1] - fs * y[0])) / det
            };
            (quad(u1, u1), quad(u1, u2), quad(u2, u2))
        }
        (true, _) if ff > 0.0 => (u1[0] * u1[0] / ff, u1[0] * u2[0] / ff, u2[0] * u2[0] / ff),
        (false, true) if ss > 0.0 => (u1[1] * u1[1] / ss, u1[1] * u2[1] / ss, u2[1] * u2[1] / ss),
        _ => (0.0, 0.0, 0.0),
    }
}

/// The sums over `groups` groups of [`LANES`] lights of each of the `N` values that `term`
/// gives for a group: lane by lane, then across the lanes. `term` is a closure marked
/// `#[inline(always)]`: a closure does not take the target features of the function it is
/// written in, and its intrinsics would otherwise be calls.
#[inline(always)]
fn summed<V: Isa<LANES>, const N: usize>(
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
fn lobe_scales<V: Isa<LANES>>(isa: V, work: &Work) -> (f32, f32) {
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
fn residual<V: Isa<LANES>>(isa: V, work: &Work, g: usize, a: f32, c: f32) -> V::F {
    isa.floats(work.b[g]) - isa.floats(work.diffuse[g]) * a - isa.floats(work.specular[g]) * c
}

/// Tukey's biweight of each residual under the model `a`, `c`, in units of [`LOBE_SCALES`]
/// robust scales of the lit observations.
#[inline(always)]
fn reweight<V: Isa<LANES>>(isa: V, a: f32, c: f32, work: &mut Work) {
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
fn robust_scale<V: Isa<LANES>>(isa: V, a: f32, c: f32, work: &mut Work) -> Option<f32> {
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
fn select_near(keys: &mut [u32], rank: usize, guess: u32) -> u32 {
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
fn loss<V: Isa<LANES>>(isa: V, a: f32, c: f32, reach: f32, work: &Work) -> f32 {
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
mod tests {
    use super::*;
    use crate::ps::{photometric_stereo, PsSettings, Robust};
    use crate::scene::Light;
    use glam::Vec3A;

    /// 48 lights on rings 15°–60° from the camera's axis.
    fn ring_lights() -> Vec<Vec3> {
        let mut out = Vec::new();
        for (ring, polar) in [15.0f32, 30.0, 45.0, 60.0].iter().enumerate() {
            for i in 0..12 {
                let azimuth = (i as f32 + 0.5 * ring as f32) * std::f32::consts::TAU / 12.0;
                let (sp, cp) = polar.to_radians().sin_cos();
                out.push(Vec3::new(sp * azimuth.cos(), sp * azimuth.sin(), cp));
            }
        }
        out
    }

    fn angle_deg(a: [f32; 3], b: Vec3) -> f32 {
        Vec3::from(a).dot(b).clamp(-1.0, 1.0).acos().to_degrees()
    }

    /// Pixels rendered with a Lambertian base (albedo `rho` per channel) and a Blinn-Phong
    /// lobe of exponent `exponent` and height `height`, fitted in `mode`.
    fn fit_glossy(
        normals: &[Vec3],
        rho: [f32; 3],
        height: f32,
        exponent: i32,
        mode: Robust,
    ) -> crate::ps::PsOutput {
        fit_glossy_with(
            normals,
            rho,
            height,
            exponent,
            PsSettings {
                robust: mode,
                ..PsSettings::default()
            },
        )
        .unwrap()
    }

    /// [`fit_glossy`] with `settings`.
    fn fit_glossy_with(
        normals: &[Vec3],
        rho: [f32; 3],
        height: f32,
        exponent: i32,
        settings: PsSettings,
    ) -> crate::error::Result<crate::ps::PsOutput> {
        let directions = ring_lights();
        let lights: Vec<Light> = directions
            .iter()
            .map(|&d| Light {
                direction: Vec3A::from(d),
                irradiance: [std::f32::consts::PI; 3],
            })
            .collect();
        let mut images = Vec::new();
        for &l in &directions {
            let h = (l + Vec3::Z).normalize();
            for &n in normals {
                let nl = n.dot(l).max(0.0);
                let lobe = height * n.dot(h).max(0.0).powi(exponent);
                images.extend(rho.map(|r| nl * (r + lobe)));
            }
        }
        photometric_stereo(&images, &vec![true; normals.len()], &lights, &settings)
    }

    fn tilted(count: usize) -> Vec<Vec3> {
        (0..count)
            .map(|i| {
                Vec3::new(
                    0.5 * (i as f32 * 0.7).sin(),
                    0.5 * (i as f32 * 1.3).cos(),
                    1.0,
                )
                .normalize()
            })
            .collect()
    }

    #[test]
    fn lobe_mode_recovers_normals_and_diffuse_albedo_of_glossy_pixels() {
        let normals = tilted(40);
        let lobe = fit_glossy(&normals, [0.2, 0.3, 0.4], 4.0, 32, Robust::Lobe);
        let tukey = fit_glossy(&normals, [0.2, 0.3, 0.4], 4.0, 32, Robust::Tukey);
        let mean = |out: &crate::ps::PsOutput| {
            normals
                .iter()
                .zip(&out.normals)
                .map(|(&n, &m)| angle_deg(m, n))
                .sum::<f32>()
                / normals.len() as f32
        };
        assert!(
            mean(&lobe) < 0.05,
            "lobe mode's mean error {}°",
            mean(&lobe)
        );
        assert!(
            mean(&tukey) > 5.0 * mean(&lobe),
            "the Tukey fit is already right ({}°): the test shows nothing",
            mean(&tukey)
        );
        for albedo in &lobe.albedo {
            for (value, truth) in albedo.iter().zip([0.2, 0.3, 0.4]) {
                assert!(
                    (value - truth).abs() < 0.01,
                    "diffuse albedo {albedo:?}, truth [0.2, 0.3, 0.4]"
                );
            }
        }
    }

    #[test]
    fn a_fit_of_few_rounds_tells_glossy_pixels_from_matte_ones() {
        let normals = tilted(40);
        let shortened = |height, lobe_rounds| {
            fit_glossy_with(
                &normals,
                [0.2, 0.3, 0.4],
                height,
                32,
                PsSettings {
                    robust: Robust::Lobe,
                    lobe_rounds,
                    ..PsSettings::default()
                },
            )
            .unwrap()
        };
        for rounds in [1, 5] {
            assert!(
                shortened(4.0, rounds)
                    .flags
                    .iter()
                    .all(|&f| f == flag::LOBE),
                "{rounds} rounds: a glossy pixel without a lobe"
            );
            assert!(
                shortened(0.0, rounds).flags.iter().all(|&f| f == flag::OK),
                "{rounds} rounds: a matte pixel with a lobe"
            );
        }
        // Five rounds leave the normals less settled than the full fit's (measured: worst
        // errors 1.30° and 0.13°).
        let worst = |out: &crate::ps::PsOutput| {
            normals
                .iter()
                .zip(&out.normals)
                .map(|(&n, &m)| angle_deg(m, n))
                .fold(0.0f32, f32::max)
        };
        assert!(
            worst(&shortened(4.0, 5)) > 3.0 * worst(&shortened(4.0, LOBE_ROUNDS)),
            "5 rounds fit as well as {LOBE_ROUNDS}: the rounds are not used"
        );
        let refused = fit_glossy_with(
            &normals,
            [0.2, 0.3, 0.4],
            4.0,
            32,
            PsSettings {
                robust: Robust::Lobe,
                lobe_rounds: 0,
                ..PsSettings::default()
            },
        );
        assert!(refused.unwrap_err().to_string().contains("lobe_rounds"));
    }

    #[test]
    fn the_auto_modes_check_beside_the_tukey_fit_is_each_fit_alone() {
        // Half the pixels glossy, half matte: the check's pixels pick from both.
        let directions = ring_lights();
        let lights: Vec<Light> = directions
            .iter()
            .map(|&d| Light {
                direction: Vec3A::from(d),
                irradiance: [std::f32::consts::PI; 3],
            })
            .collect();
        let normals = tilted(60);
        let mut images = Vec::new();
        for &l in &directions {
            let h = (l + Vec3::Z).normalize();
            for (p, &n) in normals.iter().enumerate() {
                let height = if p % 2 == 0 { 4.0 } else { 0.0 };
                images.extend(
                    [0.2f32, 0.3, 0.4]
                        .map(|r| n.dot(l).max(0.0) * (r + height * n.dot(h).max(0.0).powi(32))),
                );
            }
        }
        let mask: Vec<bool> = (0..normals.len()).map(|p| p != 7).collect();
        let check = [3, 10, 11, 40, 59, 2];
        let settings = PsSettings::default();
        let (fit, flags) =
            crate::ps::tukey_with_lobe_check(&images, &mask, &check, &lights, &settings, 5)
                .unwrap();
        assert_eq!(
            fit,
            photometric_stereo(
                &images,
                &mask,
                &lights,
                &PsSettings {
                    robust: Robust::Tukey,
                    ..settings
                }
            )
            .unwrap()
        );
        let observed: Vec<f32> = images
            .chunks_exact(3 * normals.len())
            .flat_map(|image| {
                check
                    .iter()
                    .flat_map(move |&p| image[3 * p..3 * p + 3].to_vec())
            })
            .collect();
        let alone = photometric_stereo(
            &observed,
            &[true; 6],
            &lights,
            &PsSettings {
                robust: Robust::Lobe,
                lobe_rounds: 5,
                ..settings
            },
        )
        .unwrap();
        assert_eq!(flags, alone.flags);
        assert_eq!(
            flags.iter().map(|&f| f == flag::LOBE).collect::<Vec<_>>(),
            check.map(|p| p % 2 == 0),
            "the glossy pixels take a lobe, the matte ones none"
        );
        let outside =
            crate::ps::tukey_with_lobe_check(&images, &mask, &[60], &lights, &settings, 5)
                .unwrap_err()
                .to_string();
        assert!(
            outside.starts_with("check: pixel 60 is outside"),
            "{outside}"
        );
    }

    #[test]
    fn lobe_mode_keeps_lambertian_pixels() {
        let normals = tilted(40);
        let out = fit_glossy(&normals, [0.5, 0.5, 0.5], 0.0, 1, Robust::Lobe);
        for (&n, (m, albedo)) in normals.iter().zip(out.normals.iter().zip(&out.albedo)) {
            assert!(
                angle_deg(*m, n) < 0.05,
                "normal off by {}°",
                angle_deg(*m, n)
            );
            assert!(
                albedo.iter().all(|&a| (a - 0.5).abs() < 2e-3),
                "albedo {albedo:?}"
            );
        }
    }

    #[test]
    fn pixels_with_few_lit_observations_keep_the_tukey_fit() {
        // Five lights: a lobe's five unknowns would fit any such pixel's observations.
        let directions: Vec<Vec3> = ring_lights().into_iter().step_by(10).collect();
        let lights: Vec<Light> = directions
            .iter()
            .map(|&d| Light {
                direction: Vec3A::from(d),
                irradiance: [1.0; 3],
            })
            .collect();
        let normals = tilted(20);
        let mut images = Vec::new();
        for &l in &directions {
            let h = (l + Vec3::Z).normalize();
            for &n in &normals {
                images.extend([n.dot(l).max(0.0) * (0.3 + 2.0 * n.dot(h).max(0.0).powi(16)); 3]);
            }
        }
        let mask = vec![true; normals.len()];
        let fit = |robust| {
            photometric_stereo(
                &images,
                &mask,
                &lights,
                &PsSettings {
                    robust,
                    ..PsSettings::default()
                },
            )
            .unwrap()
        };
        assert_eq!(fit(Robust::Lobe), fit(Robust::Tukey));
    }

    /// The lobe fits of glossy pixels with soft shadows, noise and saturated observations
    /// under `count` lights, in the portable registers and in each wider set this CPU has.
    fn fits_in_every_instruction_set(count: usize) -> Vec<Vec<(usize, PixelFit)>> {
        let mut rng = crate::sampler::Rng::new(7);
        let mut uniform = || rng.next_f32();
        let directions: Vec<Vec3> = ring_lights()
            .into_iter()
            .cycle()
            .take(count)
            .enumerate()
            .map(|(k, l)| (l + Vec3::new(0.0, 0.0, 0.01 * k as f32)).normalize())
            .collect();
        let gram = directions
            .iter()
            .fold(glam::Mat3::ZERO, |m, &l| m + crate::ps::outer(l));
        let lights = Lights::new(
            &directions,
            &vec![[1.0; 3]; count],
            &vec![[2.0; 3]; count],
            gram,
        );
        let normals = tilted(200);
        let mut images = vec![0.0f32; count * normals.len() * 3];
        for (k, &l) in directions.iter().enumerate() {
            let h = (l + Vec3::Z).normalize();
            for (p, &n) in normals.iter().enumerate() {
                let shade = if uniform() < 0.1 {
                    0.3 * uniform()
                } else {
                    1.0 + 0.01 * (uniform() - 0.5)
                };
                let value = shade
                    * n.dot(l).max(0.0)
                    * (0.3 + (p % 3) as f32 * n.dot(h).max(0.0).powi(1 << (p % 7)));
                images[(k * normals.len() + p) * 3..][..3].copy_from_slice(&[
                    value,
                    0.9 * value,
                    0.8 * value,
                ]);
            }
        }
        let n = normals.len();
        let mut out = PsOutput {
            normals: vec![[0.0; 3]; n],
            albedo: vec![[0.0; 3]; n],
            flags: vec![flag::MASKED_OUT; n],
            used: vec![0; n],
        };
        crate::ps::tukey::fit_pixels(&images, &vec![true; n], &lights, 0.05, &mut out).unwrap();
        let job = Job::new(&images, &lights, LOBE_ROUNDS, &out);
        let pixels: Vec<usize> = (0..n).collect();
        let mut state = (Scratch::default(), Work::default());
        let mut portable = Vec::new();
        job.fit_tile(Portable, &mut state, &pixels, &mut portable);
        let mut all = vec![portable];
        #[cfg(target_arch = "x86_64")]
        if let Some(avx2) = crate::ps::lanes::Avx2::detect() {
            let mut fits = Vec::new();
            // SAFETY: `detect` found AVX2 and FMA.
            unsafe { job.fit_tile_avx2(avx2, &mut state, &pixels, &mut fits) };
            all.push(fits);
        }
        all
    }

    #[test]
    fn every_instruction_set_fits_the_same_bits() {
        // 37: lights that fill no whole group of lanes.
        for count in [48, 37] {
            let all = fits_in_every_instruction_set(count);
            let lobes = all[0]
                .iter()
                .filter(|(_, fit)| fit.flag == flag::LOBE)
                .count();
            assert!(
                lobes > 50,
                "{count} lights: {lobes} of 200 pixels take a lobe, the test shows little"
            );
            for fits in &all[1..] {
                assert_eq!(fits, &all[0], "{count} lights");
            }
        }
    }

    #[test]
    fn select_near_finds_the_rank_of_a_sort_for_any_guess() {
        let mut rng = crate::sampler::Rng::new(3);
        for trial in 0..500 {
            let count = 1 + trial % 97;
            // Keys of residuals 0.001-10, a tenth of them tied.
            let keys: Vec<u32> = (0..count)
                .map(|_| {
                    if rng.next_f32() < 0.1 {
                        0.5f32.to_bits()
                    } else {
                        (0.001 * 10_000f32.powf(rng.next_f32())).to_bits()
                    }
                })
                .collect();
            let mut sorted = keys.clone();
            sorted.sort_unstable();
            let rank = (trial * 7) % count;
            let truth = sorted[rank];
            // The guess: the value itself, near it on either side, far off, and the ends.
            for guess in [
                truth,
                truth + 3,
                truth - truth.min(5_000),
                truth.saturating_add(1 << 24),
                truth.saturating_sub(1 << 24),
                0,
                u32::MAX,
            ] {
                assert_eq!(
                    select_near(&mut keys.clone(), rank, guess),
                    truth,
                    "rank {rank} of {count}, guess {guess}"
                );
            }
        }
    }

    #[test]
    fn bound_solutions_are_non_negative() {
        assert_eq!(diffuse_and_lobe(1.0, 0.0, 1.0, -1.0, 2.0), (0.0, 2.0));
        assert_eq!(diffuse_and_lobe(1.0, 0.0, 1.0, 3.0, -1.0), (3.0, 0.0));
        let (a, c) = diffuse_and_lobe(2.0, 1.0, 2.0, 3.0, 3.0);
        assert!((a - 1.0).abs() < 1e-6 && (c - 1.0).abs() < 1e-6);
    }
}

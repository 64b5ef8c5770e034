//! Photometric stereo for glossy and metallic objects: a Lambertian base plus one specular
//! lobe per pixel.
//!
//! Each pixel starts from its Tukey fit ([`crate::tukey`]) and fits its channel-summed
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

use glam::Vec3;

use crate::ps::{fit_masked, flag, PixelFit, PsOutput};
use crate::robust_ps::{gather, Lights, Scratch, LANES, SATURATED};

/// The lobe exponents tried, as powers of two: `p = 2^s` for `s` in `0..LOBE_EXPONENTS`
/// (1 to 128: lobes from about 60° to about 6° wide at half height).
pub const LOBE_EXPONENTS: u32 = 8;
/// Rounds of (a, c) fit and normal step per exponent and start.
pub const LOBE_ROUNDS: usize = 15;
/// Tukey's biweight constant of the lobe fit, in robust scales (as [`crate::tukey::TUKEY_SCALES`]).
pub const LOBE_SCALES: f32 = 2.5;
/// Fewest unsaturated observations that the Tukey normal lights for a lobe to be tried: one
/// more than the lobe fit's five unknowns (the normal's two, `a`, `c` and the exponent), so
/// that a lobe cannot explain a pixel merely by having as many unknowns as observations.
pub const LOBE_MIN_LIT: usize = 6;
/// Parameters that a lobe adds to the Lambertian fit: its height and exponent.
const LOBE_PARAMETERS: f32 = 2.0;
/// Median absolute deviation to the standard deviation of a normal distribution.
const MAD_TO_SIGMA: f32 = 1.4826;
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
/// Pixels per parallel task.
const TILE: usize = 32;

/// Refits every pixel where `mask` is true and whose Tukey fit in `out` is usable, from
/// `images` laid out `(K, pixels, 3)`, with a diffuse term and a specular lobe.
pub(crate) fn fit_pixels(images: &[f32], mask: &[bool], lights: &Lights, out: &mut PsOutput) {
    let n = mask.len();
    let starts: Vec<([f32; 3], f32, u8)> = out.normals.iter().zip(&out.albedo).zip(&out.flags).map(|((&normal, albedo), &f)| (normal, albedo.iter().sum(), f)).collect();
    let half = HalfVectors::new(lights);
    fit_masked(mask, TILE, out, || Box::new((Scratch::default(), Work::default())), |state, tile, fits| {
        let (scratch, work) = &mut **state;
        gather(images, n, tile, lights, scratch);
        let padded = lights.padded();
        for (i, &p) in tile.iter().enumerate() {
            let (start, start_albedo, start_flag) = starts[p];
            let grey = &scratch.grey[i * padded..][..padded];
            let rgb = &scratch.rgb[i * lights.count..][..lights.count];
            let fit = if start_flag == flag::OK { refit(grey, rgb, lights, &half, (Vec3::from(start), start_albedo), work) } else { None };
            if let Some(fit) = fit {
                fits.push((p, fit));
            }
        }
    });
}

/// Each light's half vector with the view direction (0, 0, 1), padded like [`Lights`].
struct HalfVectors([Vec<f32>; 3]);

impl HalfVectors {
    fn new(lights: &Lights) -> HalfVectors {
        let padded = lights.padded();
        let mut half = [vec![0.0; padded], vec![0.0; padded], vec![0.0; padded]];
        for k in 0..lights.count {
            let h = (lights.direction(k) + Vec3::Z).normalize_or_zero();
            for (axis, value) in half.iter_mut().zip(h.to_array()) {
                axis[k] = value;
            }
        }
        HalfVectors(half)
    }

    fn get(&self, k: usize) -> Vec3 {
        Vec3::new(self.0[0][k], self.0[1][k], self.0[2][k])
    }
}

/// One pixel's working memory, one value per (padded) light.
#[derive(Default)]
struct Work {
    /// Channel-summed `b`, 0 where saturated.
    b: Vec<f32>,
    /// 1 where unsaturated, 0 where saturated or padding.
    usable: Vec<f32>,
    /// The current fit's weights.
    weight: Vec<f32>,
    /// `[n·l]₊` and `[n·l]₊ (n·h)^p` of the current normal.
    diffuse: Vec<f32>,
    specular: Vec<f32>,
    /// `n·h` of the current normal (at least [`NH_MIN`]).
    nh: Vec<f32>,
    /// Bits of the absolute residuals of the lit observations, for their median.
    spread: Vec<u32>,
    /// The best fit's weights so far.
    best_weight: Vec<f32>,
}

impl Work {
    /// Observation `k`'s residual under the model `a`, `c` of the current shading.
    #[inline(always)]
    fn residual(&self, k: usize, a: f32, c: f32) -> f32 {
        self.b[k] - a * self.diffuse[k] - c * self.specular[k]
    }
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
fn tangents(n: Vec3) -> (Vec3, Vec3) {
    let reference = if n.z.abs() < 0.9 { Vec3::Z } else { Vec3::X };
    let t1 = n.cross(reference).normalize();
    (t1, n.cross(t1))
}

/// The lobe fit of one pixel (channel-summed `b` per padded light `grey`, RGB `b` per light
/// `rgb`) from its Tukey fit `start` (normal, channel-summed albedo), or `None` when none
/// explains the observations better than that fit.
///
/// Fits are compared by the sum of Tukey's loss `1 − (1 − u²)³` (1 beyond `|u| = 1`) over
/// every unsaturated observation, `u` the residual in units of [`LOBE_SCALES`] robust scales
/// of the Tukey fit: one scale for all, so that a fit cannot look better by giving up
/// observations.
fn refit(grey: &[f32], rgb: &[[f32; 3]], lights: &Lights, half: &HalfVectors, start: (Vec3, f32), work: &mut Work) -> Option<PixelFit> {
    let padded = lights.padded();
    let Work { b, usable, .. } = work;
    b.clear();
    usable.clear();
    for (k, &value) in grey.iter().enumerate() {
        let ok = k < lights.count && value < SATURATED;
        b.push(if ok { value } else { 0.0 });
        usable.push(if ok { 1.0 } else { 0.0 });
    }
    for v in [&mut work.weight, &mut work.diffuse, &mut work.specular, &mut work.nh, &mut work.best_weight] {
        v.clear();
        v.resize(padded, 0.0);
    }
    let brightest = (0..lights.count).filter(|&k| work.usable[k] > 0.0).max_by(|&i, &j| work.b[i].total_cmp(&work.b[j]))?;
    let (normal, albedo) = start;
    shading(lights, half, normal, 0, work);
    let lit = work.diffuse.iter().zip(&work.usable).filter(|&(&f, &u)| f > 0.0 && u > 0.0).count();
    if lit < LOBE_MIN_LIT {
        return None;
    }
    let reach = 1.0 / (LOBE_SCALES * robust_scale(albedo, 0.0, work)?);
    // Bayesian information criterion: the lobe fit must lower χ² (the loss near zero is 3u²
    // = 3/LOBE_SCALES² of a squared residual in robust scales) by more than ln N per
    // parameter it adds, N the unsaturated observations.
    let observations = work.usable.iter().sum::<f32>();
    let penalty = 3.0 / (LOBE_SCALES * LOBE_SCALES) * LOBE_PARAMETERS * observations.ln();
    let start_cost = loss(albedo, 0.0, reach, work) - penalty;
    // A fit from the second start (a different basin, sought where the first found none)
    // must beat the best from the Tukey normal by the same margin again.
    let mut best: Option<LobeFit> = None;
    for (from, margin) in [(normal, 0.0), (half.get(brightest), penalty)] {
        // The loss is never negative: no fit can clear a bar below the margin.
        if best.as_ref().map_or(start_cost, |b| b.cost) <= margin {
            continue;
        }
        for shift in 0..LOBE_EXPONENTS {
            let fit = fit_exponent(lights, half, from, shift, reach, work);
            if fit.cost + margin < best.as_ref().map_or(start_cost, |b| b.cost) {
                work.best_weight.copy_from_slice(&work.weight);
                best = Some(fit);
            }
        }
    }
    finish(rgb, lights, half, &best?, work)
}

/// `[n·l]₊` and `[n·l]₊ (n·h)^p` of every light into `work`.
fn shading(lights: &Lights, half: &HalfVectors, n: Vec3, shift: u32, work: &mut Work) {
    let [lx, ly, lz] = &lights.direction;
    let [hx, hy, hz] = &half.0;
    for k in 0..work.diffuse.len() {
        let nl = (n.x * lx[k] + n.y * ly[k] + n.z * lz[k]).max(0.0);
        let nh = (n.x * hx[k] + n.y * hy[k] + n.z * hz[k]).max(NH_MIN);
        let mut lobe = nh;
        for _ in 0..shift {
            lobe *= lobe;
        }
        work.diffuse[k] = nl;
        work.specular[k] = nl * lobe;
        work.nh[k] = nh;
    }
}

/// Fits exponent `2^shift` from normal `from`, its [`loss`] at `reach`; leaves the fit's
/// weights in `work.weight`.
fn fit_exponent(lights: &Lights, half: &HalfVectors, from: Vec3, shift: u32, reach: f32, work: &mut Work) -> LobeFit {
    let p = (1u32 << shift) as f32;
    let mut n = from;
    work.weight.copy_from_slice(&work.usable);
    for round in 0..LOBE_ROUNDS {
        shading(lights, half, n, shift, work);
        let (a, c) = lobe_scales(work);
        let (t1, t2) = tangents(n);
        if round > 0 {
            reweight(a, c, work);
        }
        // d model / d n = (a + c (n·h)^p) l + c p [n·l]₊ (n·h)^(p−1) h, where n·l > 0; the
        // normal equations of its two tangent components j1, j2 with (a, c) re-solved after
        // the step (variable projection, Kaufman's form): each column less its weighted
        // projection on the free ones of [n·l]₊ and [n·l]₊ (n·h)^p. The sums: the weighted
        // products of those four columns, and j1's and j2's with the residual.
        let (l, h) = (&lights.direction, &half.0);
        let [m11, m12, m22, f1, f2, s1, s2, ff, fs, ss, q1, q2] = summed(work.diffuse.len(), |k| {
            let (nl, lit_lobe) = (work.diffuse[k], work.specular[k]);
            // Unlit observations (and padding) add zeros: a select, not a branch.
            let w = if nl > 0.0 { work.weight[k] } else { 0.0 };
            let along_l = a + c * lit_lobe / nl.max(NH_MIN);
            let along_h = c * p * lit_lobe / work.nh[k];
            let derivative = [0, 1, 2].map(|axis| along_l * l[axis][k] + along_h * h[axis][k]);
            let j1 = derivative[0] * t1.x + derivative[1] * t1.y + derivative[2] * t1.z;
            let j2 = derivative[0] * t2.x + derivative[1] * t2.y + derivative[2] * t2.z;
            let r = work.residual(k, a, c);
            let (wj1, wj2, wf, ws) = (w * j1, w * j2, w * nl, w * lit_lobe);
            [wj1 * j1, wj1 * j2, wj2 * j2, wf * j1, wf * j2, ws * j1, ws * j2, wf * nl, wf * lit_lobe, ws * lit_lobe, wj1 * r, wj2 * r]
        });
        let (p11, p12, p22) = projected(a > 0.0, c > 0.0, [ff, fs, ss], [f1, s1], [f2, s2]);
        let (m11, m12, m22) = (m11 - p11, m12 - p12, m22 - p22);
        let damping = DAMPING * (m11 + m22) + 1e-12;
        let det = (m11 + damping) * (m22 + damping) - m12 * m12;
        let (s1, s2) = (((m22 + damping) * q1 - m12 * q2) / det, ((m11 + damping) * q2 - m12 * q1) / det);
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
    shading(lights, half, n, shift, work);
    let (a, c) = lobe_scales(work);
    let cost = loss(a, c, reach, work);
    LobeFit { normal: n, cost: if cost.is_finite() { cost } else { f32::INFINITY }, shift, height: c }
}

/// `uᵢᵀ G⁻¹ uⱼ` of the tangent columns' products `u1`, `u2` with the diffuse and lobe
/// columns (Gram `G` = `[ff, fs, ss]`), over the free ones (`diffuse`, `lobe`).
fn projected(diffuse: bool, lobe: bool, [ff, fs, ss]: [f32; 3], u1: [f32; 2], u2: [f32; 2]) -> (f32, f32, f32) {
    let det = ff * ss - fs * fs;
    match (diffuse, lobe) {
        (true, true) if det > 1e-6 * ff * ss => {
            let quad = |x: [f32; 2], y: [f32; 2]| (x[0] * (ss * y[0] - fs * y[1]) + x[1] * (ff * y[1] - fs * y[0])) / det;
            (quad(u1, u1), quad(u1, u2), quad(u2, u2))
        }
        (true, _) if ff > 0.0 => (u1[0] * u1[0] / ff, u1[0] * u2[0] / ff, u2[0] * u2[0] / ff),
        (false, true) if ss > 0.0 => (u1[1] * u1[1] / ss, u1[1] * u2[1] / ss, u2[1] * u2[1] / ss),
        _ => (0.0, 0.0, 0.0),
    }
}

/// The sums over `0..len` (a multiple of [`LANES`]) of each of the `N` values that `term`
/// gives for an index, [`LANES`] indices side by side (so that they vectorise).
#[inline(always)]
fn summed<const N: usize>(len: usize, term: impl Fn(usize) -> [f32; N]) -> [f32; N] {
    let mut lanes = [[0.0f32; LANES]; N];
    for start in (0..len).step_by(LANES) {
        for i in 0..LANES {
            for (lane, value) in lanes.iter_mut().zip(term(start + i)) {
                lane[i] += value;
            }
        }
    }
    lanes.map(|lane| lane.iter().sum())
}

/// `(a, c)` of the current shading and weights.
fn lobe_scales(work: &Work) -> (f32, f32) {
    let [ff, fs, ss, fb, sb] = summed(work.diffuse.len(), |k| {
        let (wf, ws, b) = (work.weight[k] * work.diffuse[k], work.weight[k] * work.specular[k], work.b[k]);
        [wf * work.diffuse[k], wf * work.specular[k], ws * work.specular[k], wf * b, ws * b]
    });
    diffuse_and_lobe(ff, fs, ss, fb, sb)
}

/// Tukey's biweight of each residual under the model `a`, `c`, in units of [`LOBE_SCALES`]
/// robust scales of the lit observations.
fn reweight(a: f32, c: f32, work: &mut Work) {
    let Some(scale) = robust_scale(a, c, work) else {
        return;
    };
    let reach = 1.0 / (LOBE_SCALES * scale);
    for k in 0..work.diffuse.len() {
        let u = work.residual(k, a, c) * reach;
        let t = 1.0 - u * u;
        work.weight[k] = if t > 0.0 { t * t * work.usable[k] } else { 0.0 };
    }
}

/// 1.4826 × the median absolute residual of the lit, unsaturated observations under the
/// model `a`, `c` (at least [`SCALE_FLOOR`] of `a + c`), `None` when none is lit.
fn robust_scale(a: f32, c: f32, work: &mut Work) -> Option<f32> {
    work.spread.clear();
    for k in 0..work.diffuse.len() {
        if work.diffuse[k] > 0.0 && work.usable[k] > 0.0 {
            work.spread.push(work.residual(k, a, c).abs().to_bits());
        }
    }
    if work.spread.is_empty() {
        return None;
    }
    // Absolute values: their bits order as the values do.
    let middle = work.spread.len() / 2;
    let median = f32::from_bits(*work.spread.select_nth_unstable(middle).1);
    Some((MAD_TO_SIGMA * median).max(SCALE_FLOOR * (a + c)) + 1e-9)
}

/// Σ over the unsaturated observations of Tukey's loss `1 − (1 − u²)³` (1 beyond `|u| = 1`)
/// of the residual `u` under the model `a`, `c`, times `reach`.
fn loss(a: f32, c: f32, reach: f32, work: &Work) -> f32 {
    let [sum] = summed(work.diffuse.len(), |k| {
        let u = work.residual(k, a, c) * reach;
        let t = (1.0 - u * u).max(0.0);
        [work.usable[k] * (1.0 - t * t * t)]
    });
    sum
}

/// The kept fit's normal and each channel's diffuse albedo under its weights.
fn finish(rgb: &[[f32; 3]], lights: &Lights, half: &HalfVectors, best: &LobeFit, work: &mut Work) -> Option<PixelFit> {
    shading(lights, half, best.normal, best.shift, work);
    let used = work.best_weight[..lights.count].iter().zip(&work.diffuse).filter(|&(&w, &f)| w > 0.0 && f > 0.0).count() as u16;
    let mut albedo = [0.0f32; 3];
    for (c, value) in albedo.iter_mut().enumerate() {
        let (mut ff, mut fs, mut ss, mut fb, mut sb) = (0.0f32, 0.0f32, 0.0f32, 0.0f32, 0.0f32);
        for (k, b) in rgb.iter().enumerate() {
            let (w, f, s) = (work.best_weight[k], work.diffuse[k], work.specular[k]);
            ff += w * f * f;
            fs += w * f * s;
            ss += w * s * s;
            fb += w * f * b[c];
            sb += w * s * b[c];
        }
        *value = diffuse_and_lobe(ff, fs, ss, fb, sb).0;
    }
    (best.normal.is_finite() && used >= 3).then(|| PixelFit { normal: best.normal.to_array(), albedo, flag: if best.height > 0.0 { flag::LOBE } else { flag::OK }, used })
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
    fn fit_glossy(normals: &[Vec3], rho: [f32; 3], height: f32, exponent: i32, mode: Robust) -> crate::ps::PsOutput {
        let directions = ring_lights();
        let lights: Vec<Light> = directions.iter().map(|&d| Light { direction: Vec3A::from(d), irradiance: [std::f32::consts::PI; 3] }).collect();
        let mut images = Vec::new();
        for &l in &directions {
            let h = (l + Vec3::Z).normalize();
            for &n in normals {
                let nl = n.dot(l).max(0.0);
                let lobe = height * n.dot(h).max(0.0).powi(exponent);
                images.extend(rho.map(|r| nl * (r + lobe)));
            }
        }
        let settings = PsSettings { robust: mode, ..PsSettings::default() };
        photometric_stereo(&images, &vec![true; normals.len()], &lights, &settings).unwrap()
    }

    fn tilted(count: usize) -> Vec<Vec3> {
        (0..count).map(|i| Vec3::new(0.5 * (i as f32 * 0.7).sin(), 0.5 * (i as f32 * 1.3).cos(), 1.0).normalize()).collect()
    }

    #[test]
    fn lobe_mode_recovers_normals_and_diffuse_albedo_of_glossy_pixels() {
        let normals = tilted(40);
        let lobe = fit_glossy(&normals, [0.2, 0.3, 0.4], 4.0, 32, Robust::Lobe);
        let tukey = fit_glossy(&normals, [0.2, 0.3, 0.4], 4.0, 32, Robust::Tukey);
        let mean = |out: &crate::ps::PsOutput| normals.iter().zip(&out.normals).map(|(&n, &m)| angle_deg(m, n)).sum::<f32>() / normals.len() as f32;
        assert!(mean(&lobe) < 0.05, "lobe mode's mean error {}°", mean(&lobe));
        assert!(mean(&tukey) > 5.0 * mean(&lobe), "the Tukey fit is already right ({}°): the test shows nothing", mean(&tukey));
        for albedo in &lobe.albedo {
            for (value, truth) in albedo.iter().zip([0.2, 0.3, 0.4]) {
                assert!((value - truth).abs() < 0.01, "diffuse albedo {albedo:?}, truth [0.2, 0.3, 0.4]");
            }
        }
    }

    #[test]
    fn lobe_mode_keeps_lambertian_pixels() {
        let normals = tilted(40);
        let out = fit_glossy(&normals, [0.5, 0.5, 0.5], 0.0, 1, Robust::Lobe);
        for (&n, (m, albedo)) in normals.iter().zip(out.normals.iter().zip(&out.albedo)) {
            assert!(angle_deg(*m, n) < 0.05, "normal off by {}°", angle_deg(*m, n));
            assert!(albedo.iter().all(|&a| (a - 0.5).abs() < 2e-3), "albedo {albedo:?}");
        }
    }

    #[test]
    fn pixels_with_few_lit_observations_keep_the_tukey_fit() {
        // Five lights: a lobe's five unknowns would fit any such pixel's observations.
        let directions: Vec<Vec3> = ring_lights().into_iter().step_by(10).collect();
        let lights: Vec<Light> = directions.iter().map(|&d| Light { direction: Vec3A::from(d), irradiance: [1.0; 3] }).collect();
        let normals = tilted(20);
        let mut images = Vec::new();
        for &l in &directions {
            let h = (l + Vec3::Z).normalize();
            for &n in &normals {
                images.extend([n.dot(l).max(0.0) * (0.3 + 2.0 * n.dot(h).max(0.0).powi(16)); 3]);
            }
        }
        let mask = vec![true; normals.len()];
        let fit = |robust| photometric_stereo(&images, &mask, &lights, &PsSettings { robust, ..PsSettings::default() }).unwrap();
        assert_eq!(fit(Robust::Lobe), fit(Robust::Tukey));
    }

    #[test]
    fn bound_solutions_are_non_negative() {
        assert_eq!(diffuse_and_lobe(1.0, 0.0, 1.0, -1.0, 2.0), (0.0, 2.0));
        assert_eq!(diffuse_and_lobe(1.0, 0.0, 1.0, 3.0, -1.0), (3.0, 0.0));
        let (a, c) = diffuse_and_lobe(2.0, 1.0, 2.0, 3.0, 3.0);
        assert!((a - 1.0).abs() < 1e-6 && (c - 1.0).abs() < 1e-6);
    }
}

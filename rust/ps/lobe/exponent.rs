//! One exponent's fit from one start: the linear fit of the diffuse term and the lobe's
//! height alternated with a damped Gauss-Newton step of the normal on its tangent plane
//! (variable projection), re-weighted from the second round on.

use glam::Vec3;

use crate::ps::kernel::LANES;
use crate::ps::lanes::{Floats, Isa};

use super::model::{lobe_scales, residual, shading, summed, NH_MIN};
use super::weights::{loss, reweight};
use super::{grouped, HalfVectors, Job, LobeFit, Work};

/// Longest step of the normal per round (about 11°).
const STEP_MAX: f32 = 0.2;
/// Levenberg-Marquardt damping, as a fraction of the normal equations' trace.
const DAMPING: f32 = 1e-3;
/// A round whose step is shorter than this (about 0.06°) ends the exponent's fit.
const STEP_SETTLED: f32 = 1e-3;

/// Two unit vectors spanning the plane normal to `n`.
#[inline(always)]
pub(super) fn tangents(n: Vec3) -> (Vec3, Vec3) {
    let reference = if n.z.abs() < 0.9 { Vec3::Z } else { Vec3::X };
    let t1 = n.cross(reference).normalize();
    (t1, n.cross(t1))
}

/// Fits exponent `2^shift` from normal `from` for at most `job`'s rounds, its [`loss`] at
/// `reach`; leaves the fit's weights in `work.weight`.
#[inline(always)]
pub(super) fn fit_exponent<V: Isa<LANES>>(
    isa: V,
    job: &Job,
    half: &HalfVectors,
    from: Vec3,
    shift: u32,
    reach: f32,
    work: &mut Work,
) -> LobeFit {
    let lights = job.lights;
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
pub(super) fn projected(
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

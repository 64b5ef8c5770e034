//! The least-squares pieces that every robust mode of photometric stereo shares (the
//! modes import them; they import no mode): the per-pixel output and its [`flag`]s, each
//! light's constants ([`PerLight`]) and the lights padded to whole lanes ([`Lights`]), a
//! pixel's observations gathered pixel-major ([`gather`]), the solve of its normal and
//! albedo from least-squares sums ([`finish`], [`solved`], [`full_fit`]), and the parallel
//! run over the mask's pixels ([`fit_masked`]).

use std::f32::consts::PI;
use std::sync::{Mutex, PoisonError};

use glam::{Mat3, Vec3};
use rayon::prelude::*;

use crate::error::Result;
use crate::memory::{try_vec, try_with_capacity};
use crate::scene::Light;

/// A set of lights is coplanar when the smallest eigenvalue of LᵀL is below this fraction of
/// the largest.
pub(crate) const COPLANAR_RATIO: f32 = 1e-4;

/// Lights summed side by side.
pub(crate) const LANES: usize = 8;

/// What happened at a pixel.
pub mod flag {
    /// Fitted from the observations the mode asks for.
    pub const OK: u8 = 0;
    /// Robust mode: fewer than 3 non-coplanar observations were left; the full fit was kept.
    pub const FULL_FIT: u8 = 1;
    /// No light reached the pixel (or it is outside the mask): normal (0, 0, 1), albedo 0.
    pub const DARK: u8 = 2;
    /// Outside the mask.
    pub const MASKED_OUT: u8 = 3;
    /// Lobe mode: fitted with a specular lobe ([`crate::ps::lobe`]); the albedo is the diffuse
    /// term's.
    pub const LOBE: u8 = 4;
}

/// Per-pixel results, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct PsOutput {
    /// Unit normals (zero outside the mask).
    pub normals: Vec<[f32; 3]>,
    /// RGB albedo.
    pub albedo: Vec<[f32; 3]>,
    /// One of [`flag`] per pixel.
    pub flags: Vec<u8>,
    /// Number of observations used.
    pub used: Vec<u16>,
}

impl PsOutput {
    /// The output of `n` pixels, all masked out until fitted.
    pub(crate) fn new(n: usize) -> Result<PsOutput> {
        let what = |array: &str| format!("photometric stereo's {array} of {n} pixels");
        Ok(PsOutput {
            normals: try_vec(&what("normals"), n, [0.0; 3])?,
            albedo: try_vec(&what("albedo"), n, [0.0; 3])?,
            flags: try_vec(&what("flags"), n, flag::MASKED_OUT)?,
            used: try_vec(&what("observation counts"), n, 0)?,
        })
    }
}

/// One pixel's fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PixelFit {
    pub normal: [f32; 3],
    pub albedo: [f32; 3],
    /// One of [`flag`].
    pub flag: u8,
    /// Observations used.
    pub used: u16,
}

impl PixelFit {
    /// No light reached the pixel.
    pub fn dark(used: u16) -> PixelFit {
        PixelFit {
            normal: [0.0, 0.0, 1.0],
            albedo: [0.0; 3],
            flag: flag::DARK,
            used,
        }
    }
}

/// Each light's constants of a fit.
pub(crate) struct PerLight {
    pub directions: Vec<Vec3>,
    /// π / E_kc, per light and channel.
    pub scale: Vec<[f32; 3]>,
    /// Raw saturation level times π / E_kc, per light and channel (∞ when off).
    pub saturated_b: Vec<[f32; 3]>,
}

impl PerLight {
    /// The constants of `lights`, raw values at or above `saturation` (in any channel)
    /// saturated; none when it is `None`.
    pub fn new(lights: &[Light], saturation: Option<f32>) -> PerLight {
        let scale: Vec<[f32; 3]> = lights
            .iter()
            .map(|l| l.irradiance.map(|e| PI / e))
            .collect();
        let level = saturation.unwrap_or(f32::INFINITY);
        let saturated_b = scale.iter().map(|s| s.map(|v| v * level)).collect();
        PerLight {
            directions: lights.iter().map(|l| l.direction.into()).collect(),
            scale,
            saturated_b,
        }
    }
}

/// The lights, structure of arrays, padded with zeros to a multiple of [`LANES`].
pub(crate) struct Lights {
    /// Number of real lights.
    pub count: usize,
    /// x, y, z of each direction.
    pub direction: [Vec<f32>; 3],
    /// xx, xy, xz, yy, yz, zz of each direction.
    pub outer: [Vec<f32>; 6],
    /// π / E_kc of each light, a row per channel.
    pub scale: [Vec<f32>; 3],
    /// Raw saturation level times π / E_kc of each light (∞ when off), a row per channel.
    pub saturated_b: [Vec<f32>; 3],
    /// Σ l lᵀ over every light.
    gram: Mat3,
}

impl Lights {
    /// From unit `directions`, `scale` = π / E and the saturated level of `b` per light.
    pub fn new(
        directions: &[Vec3],
        scale: &[[f32; 3]],
        saturated_b: &[[f32; 3]],
        gram: Mat3,
    ) -> Lights {
        let padded = directions.len().div_ceil(LANES) * LANES;
        let row = |values: &mut dyn Iterator<Item = f32>| -> Vec<f32> {
            values.chain(std::iter::repeat(0.0)).take(padded).collect()
        };
        let component = |f: &dyn Fn(Vec3) -> f32| row(&mut directions.iter().map(|&l| f(l)));
        let channel =
            |per_light: &[[f32; 3]], c: usize| row(&mut per_light.iter().map(|values| values[c]));
        Lights {
            count: directions.len(),
            direction: [
                component(&|l| l.x),
                component(&|l| l.y),
                component(&|l| l.z),
            ],
            outer: [
                component(&|l| l.x * l.x),
                component(&|l| l.x * l.y),
                component(&|l| l.x * l.z),
                component(&|l| l.y * l.y),
                component(&|l| l.y * l.z),
                component(&|l| l.z * l.z),
            ],
            scale: std::array::from_fn(|c| channel(scale, c)),
            saturated_b: std::array::from_fn(|c| channel(saturated_b, c)),
            gram,
        }
    }

    pub(crate) fn padded(&self) -> usize {
        self.direction[0].len()
    }

    pub(crate) fn direction(&self, k: usize) -> Vec3 {
        Vec3::new(
            self.direction[0][k],
            self.direction[1][k],
            self.direction[2][k],
        )
    }
}

/// Channel-summed `b` of a saturated observation: so large that its residual gives it no
/// weight, finite so that a zero weight times it adds nothing.
pub(crate) const SATURATED: f32 = f32::MAX;
/// Median absolute deviation to the standard deviation of a normal distribution: the robust
/// scale of the Tukey and lobe fits.
pub(crate) const MAD_TO_SIGMA: f32 = 1.4826;

/// A tile's working memory.
#[derive(Default)]
pub(crate) struct Scratch {
    /// Channel-summed `b` of each pixel, per padded light ([`SATURATED`] when saturated).
    pub grey: Vec<f32>,
    /// RGB `b` of each pixel, per light.
    pub rgb: Vec<[f32; 3]>,
}

/// Copies the tile's observations into `scratch`, pixel-major.
pub(crate) fn gather(
    images: &[f32],
    n: usize,
    tile: &[usize],
    lights: &Lights,
    scratch: &mut Scratch,
) {
    let (count, padded) = (lights.count, lights.padded());
    scratch.grey.clear();
    scratch.grey.resize(tile.len() * padded, 0.0);
    scratch.rgb.resize(tile.len() * count, [0.0; 3]);
    for k in 0..count {
        let (s, sat) = (
            lights.scale.each_ref().map(|row| row[k]),
            lights.saturated_b.each_ref().map(|row| row[k]),
        );
        let image = &images[k * n * 3..][..n * 3];
        for (i, &pixel) in tile.iter().enumerate() {
            let raw = &image[pixel * 3..pixel * 3 + 3];
            let b = [raw[0] * s[0], raw[1] * s[1], raw[2] * s[2]];
            scratch.rgb[i * count + k] = b;
            let unsaturated = b[0] < sat[0] && b[1] < sat[1] && b[2] < sat[2];
            scratch.grey[i * padded + k] = if unsaturated {
                b[0] + b[1] + b[2]
            } else {
                SATURATED
            };
        }
    }
}

/// `g = G⁻¹ r` when at least `fewest` weighted observations fix it, their lights not
/// (nearly) coplanar.
pub(crate) fn solved(gram: Mat3, rhs: Vec3, count: usize, fewest: usize) -> Option<Vec3> {
    if count < fewest || !well_posed(gram) {
        return None;
    }
    let g = gram.inverse() * rhs;
    (g.is_finite() && g != Vec3::ZERO).then_some(g)
}

/// Whether the smallest eigenvalue λ₁ of the Gram matrix `gram` is at least
/// [`COPLANAR_RATIO`] times its largest λ₃, by a test without the eigenvalues: λ₁ ≥
/// det / m₂ (m₂ = λ₁λ₂ + λ₁λ₃ + λ₂λ₃, the sum of its principal 2×2 minors) and λ₃ ≤ trace, so
/// det ≥ ratio · trace · m₂ is enough (and at most 9 times stricter than needed).
fn well_posed(gram: Mat3) -> bool {
    let a = gram.to_cols_array_2d();
    let trace = a[0][0] + a[1][1] + a[2][2];
    let minors = a[0][0] * a[1][1] - a[0][1] * a[1][0] + a[0][0] * a[2][2] - a[0][2] * a[2][0]
        + a[1][1] * a[2][2]
        - a[1][2] * a[2][1];
    gram.determinant() >= COPLANAR_RATIO * trace * minors && trace > 0.0
}

/// Plain least squares on every observation (RGB `b` of each light `rgb`), saturated ones
/// included: the fit kept when a robust selection leaves too few.
pub(crate) fn full_fit(rgb: &[[f32; 3]], lights: &Lights) -> PixelFit {
    let mut rhs = [Vec3::ZERO; 3];
    for (k, b) in rgb.iter().enumerate() {
        let l = lights.direction(k);
        for c in 0..3 {
            rhs[c] += l * b[c];
        }
    }
    match finish(lights.gram, rhs) {
        Some((normal, albedo)) => PixelFit {
            normal,
            albedo,
            flag: flag::FULL_FIT,
            used: lights.count as u16,
        },
        None => PixelFit::dark(lights.count as u16),
    }
}

/// Fits the pixels where `mask` is true, `chunk` of them at a time in parallel, into `out`:
/// `fit` appends (pixel, fit) for each pixel of a chunk (pixel indices in increasing order),
/// with the working state that `init` makes for each thread, and each chunk's fits go
/// straight into its own rows of `out`. Fails only when the list of the mask's pixels
/// cannot be allocated.
pub(crate) fn fit_masked<S>(
    mask: &[bool],
    chunk: usize,
    out: &mut PsOutput,
    init: impl Fn() -> S + Sync + Send,
    fit: impl Fn(&mut S, &[usize], &mut Vec<(usize, PixelFit)>) + Sync + Send,
) -> Result<()> {
    let pixels = masked_pixels(mask)?;
    let chunks: Vec<&[usize]> = pixels.chunks(chunk).collect();
    let mut windows = Vec::with_capacity(chunks.len());
    let (mut normals, mut albedo, mut flags, mut used) = (
        &mut out.normals[..],
        &mut out.albedo[..],
        &mut out.flags[..],
        &mut out.used[..],
    );
    let mut start = 0;
    for next in chunks
        .iter()
        .skip(1)
        .map(|chunk| chunk[0])
        .chain([mask.len()])
    {
        let rows = next - start;
        let window;
        (window, normals, albedo, flags, used) = {
            let (n, normals) = normals.split_at_mut(rows);
            let (a, albedo) = albedo.split_at_mut(rows);
            let (f, flags) = flags.split_at_mut(rows);
            let (u, used) = used.split_at_mut(rows);
            ((start, n, a, f, u), normals, albedo, flags, used)
        };
        windows.push(window);
        start = next;
    }
    let init = || (init(), Vec::with_capacity(chunk));
    for_each_with(
        chunks.into_iter().zip(windows),
        init,
        |(state, fits), (pixels, (first, normals, albedo, flags, used))| {
            fits.clear();
            fit(state, pixels, fits);
            for (p, pixel) in fits.drain(..) {
                let i = p - first;
                (normals[i], albedo[i], flags[i], used[i]) =
                    (pixel.normal, pixel.albedo, pixel.flag, pixel.used);
            }
        },
    );
    Ok(())
}

/// The indices where `mask` is true, in increasing order (before the threads start: blocks
/// of the mask with none are skipped).
fn masked_pixels(mask: &[bool]) -> Result<Vec<usize>> {
    const BLOCK: usize = 64;
    let count = mask.iter().filter(|&&inside| inside).count();
    let mut pixels = try_with_capacity(&format!("the list of the mask's {count} pixels"), count)?;
    for (block, flags) in mask.chunks(BLOCK).enumerate() {
        // Without an early exit, so that it runs over whole registers.
        if flags.iter().fold(false, |any, &m| any | m) {
            pixels.extend(
                flags
                    .iter()
                    .enumerate()
                    .filter_map(|(i, &m)| m.then_some(block * BLOCK + i)),
            );
        }
    }
    Ok(pixels)
}

/// Runs `work` on every item of `items`, in parallel, with one working state that `init`
/// makes per thread: each thread takes the next item when it is done with one (rayon's
/// `for_each_init` makes a state for every piece of work it splits off).
pub(crate) fn for_each_with<T: Send, S>(
    items: impl Iterator<Item = T> + Send,
    init: impl Fn() -> S + Sync,
    work: impl Fn(&mut S, T) + Sync,
) {
    let queue = Mutex::new(items);
    (0..rayon::current_num_threads())
        .into_par_iter()
        .for_each(|_| {
            let mut state = init();
            loop {
                // Its own statement, so that the lock is let go before the item is worked on.
                let next = queue.lock().unwrap_or_else(PoisonError::into_inner).next();
                let Some(item) = next else { break };
                work(&mut state, item);
            }
        });
}

/// Normal and RGB albedo from least-squares sums: `n = g/|g|` for `g = G⁻¹ Σ_c rhs_c`, and
/// each channel's albedo the scale along it. `None` when `g` is zero or not finite.
pub(crate) fn finish(gram: Mat3, rhs: [Vec3; 3]) -> Option<([f32; 3], [f32; 3])> {
    let g = gram.inverse() * (rhs[0] + rhs[1] + rhs[2]);
    if !g.is_finite() || g.length() == 0.0 {
        return None;
    }
    let normal = g.normalize();
    let denominator = normal.dot(gram * normal);
    Some((
        normal.to_array(),
        [0, 1, 2].map(|c| (normal.dot(rhs[c]) / denominator).max(0.0)),
    ))
}

pub(crate) fn outer(l: Vec3) -> Mat3 {
    Mat3::from_cols(l * l.x, l * l.y, l * l.z)
}

/// Smallest and largest eigenvalue of a symmetric positive semi-definite 3×3 matrix
/// (closed form, Smith 1961).
pub(crate) fn eigen_range(m: Mat3) -> (f32, f32) {
    let a = m.to_cols_array_2d().map(|c| c.map(f64::from));
    let p1 = a[0][1].powi(2) + a[0][2].powi(2) + a[1][2].powi(2);
    let q = (a[0][0] + a[1][1] + a[2][2]) / 3.0;
    if p1 <= 1e-30 * q.abs().max(1e-30) {
        let d = [a[0][0], a[1][1], a[2][2]];
        return (
            d.iter().copied().fold(f64::INFINITY, f64::min) as f32,
            d.iter().copied().fold(f64::NEG_INFINITY, f64::max) as f32,
        );
    }
    let p2 = (a[0][0] - q).powi(2) + (a[1][1] - q).powi(2) + (a[2][2] - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    let bm = |i: usize, j: usize| (a[i][j] - if i == j { q } else { 0.0 }) / p;
    let det = bm(0, 0) * (bm(1, 1) * bm(2, 2) - bm(1, 2) * bm(2, 1))
        - bm(0, 1) * (bm(1, 0) * bm(2, 2) - bm(1, 2) * bm(2, 0))
        + bm(0, 2) * (bm(1, 0) * bm(2, 1) - bm(1, 1) * bm(2, 0));
    let phi = (det / 2.0).clamp(-1.0, 1.0).acos() / 3.0;
    let largest = q + 2.0 * p * phi.cos();
    let smallest = q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos();
    (smallest as f32, largest as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn masked_pixels_are_the_true_indices_across_empty_full_and_partial_blocks() {
        for n in [0, 1, 63, 64, 65, 200, 1000] {
            let mask: Vec<bool> = (0..n)
                .map(|i: usize| (i / 70) % 3 == 1 || i % 97 == 5 || i + 1 == n)
                .collect();
            let expected: Vec<usize> = (0..n).filter(|&i| mask[i]).collect();
            assert_eq!(masked_pixels(&mask).unwrap(), expected, "{n} pixels");
        }
    }
}

//! Rank trimming, the per-pixel robust fit that needs each pixel's observations together,
//! and what it shares with the Tukey fit of [`crate::ps::tukey`].
//!
//! The object's pixels are taken in tiles of [`TILE`]; a tile's observations are gathered
//! pixel-major (each pixel's channel-summed `b` of every light, then its RGB for the
//! albedo) and each pixel keeps the observations between the darkest [`TRIM_DARKEST`] and
//! the brightest [`TRIM_BRIGHTEST`] of its own. Saturated observations are left out. The
//! weighted sums run over the lights in groups of [`LANES`] so that they vectorise.

use glam::{Mat3, Vec3};

use crate::error::Result;
use crate::ps::{finish, fit_masked, flag, PixelFit, PsOutput, COPLANAR_RATIO};

/// The trim mode drops this fraction of each pixel's darkest observations...
pub const TRIM_DARKEST: f32 = 0.4;
/// ...and this fraction of its brightest.
pub const TRIM_BRIGHTEST: f32 = 0.2;
/// Pixels per tile: a tile's observations stay in the core's caches.
const TILE: usize = 64;
/// Lights summed side by side.
pub(crate) const LANES: usize = 8;

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

/// One pixel's observations, pixel-major.
struct Pixel<'a> {
    /// Channel-summed `b` of each light ([`SATURATED`] when saturated, 0 for padding).
    grey: &'a [f32],
    /// RGB `b` of each light.
    rgb: &'a [[f32; 3]],
}

/// A tile's working memory.
#[derive(Default)]
pub(crate) struct Scratch {
    /// Channel-summed `b` of each pixel, per padded light ([`SATURATED`] when saturated).
    pub grey: Vec<f32>,
    /// RGB `b` of each pixel, per light.
    pub rgb: Vec<[f32; 3]>,
    work: Work,
}

/// One pixel's working memory, one value per (padded) light.
#[derive(Default)]
struct Work {
    /// Weights of the fit.
    weight: Vec<f32>,
    /// [`order_key`] of each observation, with the light in the low half.
    order: Vec<u64>,
}

/// Trims each pixel where `mask` is true, from `images` laid out `(K, pixels, 3)`, into `out`.
pub(crate) fn fit_pixels(
    images: &[f32],
    mask: &[bool],
    lights: &Lights,
    out: &mut PsOutput,
) -> Result<()> {
    let n = mask.len();
    fit_masked(
        mask,
        TILE,
        out,
        || Box::new(Scratch::default()),
        |scratch, tile, fits| {
            gather(images, n, tile, lights, scratch);
            let padded = lights.padded();
            let Scratch { grey, rgb, work } = &mut **scratch;
            for (i, &p) in tile.iter().enumerate() {
                let pixel = Pixel {
                    grey: &grey[i * padded..][..padded],
                    rgb: &rgb[i * lights.count..][..lights.count],
                };
                fits.push((p, trim(&pixel, lights, work)));
            }
        },
    )
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

/// The weighted sums of the normal's fit, Σ w l lᵀ and Σ w l b (channel sum), over the
/// lights in [`LANES`] side by side.
fn weighted_sums(pixel: &Pixel, lights: &Lights, weight: &[f32]) -> (Mat3, Vec3) {
    let mut gram = [[0.0f32; LANES]; 6];
    let mut rhs = [[0.0f32; LANES]; 3];
    for start in (0..weight.len()).step_by(LANES) {
        let w = &weight[start..start + LANES];
        let b = &pixel.grey[start..start + LANES];
        for (sums, outer) in gram.iter_mut().zip(&lights.outer) {
            let ll = &outer[start..start + LANES];
            for i in 0..LANES {
                sums[i] += w[i] * ll[i];
            }
        }
        for (sums, direction) in rhs.iter_mut().zip(&lights.direction) {
            let l = &direction[start..start + LANES];
            for i in 0..LANES {
                sums[i] += w[i] * b[i] * l[i];
            }
        }
    }
    let sum = |lanes: &[f32; LANES]| lanes.iter().sum::<f32>();
    let g = gram.map(|m| sum(&m));
    let gram = Mat3::from_cols(
        Vec3::new(g[0], g[1], g[2]),
        Vec3::new(g[1], g[3], g[4]),
        Vec3::new(g[2], g[4], g[5]),
    );
    (gram, Vec3::new(sum(&rhs[0]), sum(&rhs[1]), sum(&rhs[2])))
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

/// Normal and albedo of a pixel whose RGB `b` of each light is `rgb`, from its final
/// `weights`, light by light (Σ w l lᵀ = `gram`).
pub(crate) fn weighted_fit(
    rgb: &[[f32; 3]],
    lights: &Lights,
    weights: impl IntoIterator<Item = f32>,
    gram: Mat3,
    count: usize,
    fitted: u8,
) -> PixelFit {
    let mut rhs = [Vec3::ZERO; 3];
    for (k, (b, weight)) in rgb.iter().zip(weights).enumerate() {
        // A select, not a branch (which light has weight is unpredictable); an observation
        // without weight adds zeros, whatever its value.
        let (l, b) = if weight > 0.0 {
            (lights.direction(k) * weight, *b)
        } else {
            (Vec3::ZERO, [0.0; 3])
        };
        for c in 0..3 {
            rhs[c] += l * b[c];
        }
    }
    match finish(gram, rhs) {
        Some((normal, albedo)) => PixelFit {
            normal,
            albedo,
            flag: fitted,
            used: count as u16,
        },
        None => PixelFit::dark(count as u16),
    }
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

/// Floats as integers in the same order (negative ones below positive ones; NaN last).
#[inline]
fn order_key(value: f32) -> u32 {
    let bits = value.to_bits();
    if value.is_nan() {
        u32::MAX
    } else if bits >> 31 == 1 {
        !bits
    } else {
        bits | 0x8000_0000
    }
}

fn trim(pixel: &Pixel, lights: &Lights, work: &mut Work) -> PixelFit {
    let count = lights.count;
    let Work { weight, order, .. } = work;
    order.clear();
    order.extend(
        pixel.grey[..count]
            .iter()
            .enumerate()
            .map(|(k, &b)| (u64::from(order_key(b)) << 32) | k as u64),
    );
    let darkest = (TRIM_DARKEST * count as f32).round() as usize;
    let brightest = (TRIM_BRIGHTEST * count as f32).round() as usize;
    // The keys are distinct (the light in the low half), so the middle is the same set
    // whatever order it is left in.
    if darkest > 0 {
        order.select_nth_unstable(darkest - 1);
    }
    if brightest > 0 && count - brightest > darkest {
        order[darkest..].select_nth_unstable(count - brightest - darkest);
    }
    weight.clear();
    weight.resize(lights.padded(), 0.0);
    for &key in &order[darkest..count - brightest] {
        let k = (key & 0xffff_ffff) as usize;
        weight[k] = if pixel.grey[k] < SATURATED { 1.0 } else { 0.0 };
    }
    let kept = weight.iter().filter(|&&w| w > 0.0).count();
    let (gram, rhs) = weighted_sums(pixel, lights, weight);
    if solved(gram, rhs, kept, 3).is_some() {
        return weighted_fit(
            pixel.rgb,
            lights,
            weight.iter().copied(),
            gram,
            kept,
            flag::OK,
        );
    }
    // Too few lights to trim: every unsaturated observation, flagged.
    weight
        .iter_mut()
        .zip(pixel.grey)
        .for_each(|(w, &b)| *w = if b < SATURATED { 1.0 } else { 0.0 });
    let unsaturated = weight[..count].iter().filter(|&&w| w > 0.0).count();
    let (gram, rhs) = weighted_sums(pixel, lights, weight);
    if solved(gram, rhs, unsaturated, 3).is_some() {
        return weighted_fit(
            pixel.rgb,
            lights,
            weight.iter().copied(),
            gram,
            unsaturated,
            flag::FULL_FIT,
        );
    }
    full_fit(pixel.rgb, lights)
}

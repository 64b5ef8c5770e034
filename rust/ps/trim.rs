//! Rank trimming, the per-pixel robust fit that needs each pixel's observations together.
//!
//! The object's pixels are taken in tiles of [`TILE`]; a tile's observations are gathered
//! pixel-major (each pixel's channel-summed `b` of every light, then its RGB for the
//! albedo) and each pixel keeps the observations between the darkest [`TRIM_DARKEST`] and
//! the brightest [`TRIM_BRIGHTEST`] of its own. Saturated observations are left out. The
//! weighted sums run over the lights in groups of [`LANES`] so that they vectorise.

use glam::{Mat3, Vec3};

use crate::error::Result;
use crate::ps::kernel::{
    finish, fit_masked, flag, full_fit, gather, solved, Lights, PixelFit, PsOutput, Scratch, LANES,
    SATURATED,
};

/// The trim mode drops this fraction of each pixel's darkest observations...
pub const TRIM_DARKEST: f32 = 0.4;
/// ...and this fraction of its brightest.
pub const TRIM_BRIGHTEST: f32 = 0.2;
/// Pixels per tile: a tile's observations stay in the core's caches.
const TILE: usize = 64;

/// One pixel's observations, pixel-major.
struct Pixel<'a> {
    /// Channel-summed `b` of each light ([`SATURATED`] when saturated, 0 for padding).
    grey: &'a [f32],
    /// RGB `b` of each light.
    rgb: &'a [[f32; 3]],
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
        || Box::new((Scratch::default(), Work::default())),
        |state, tile, fits| {
            let (scratch, work) = &mut **state;
            gather(images, n, tile, lights, scratch);
            let padded = lights.padded();
            let Scratch { grey, rgb } = scratch;
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

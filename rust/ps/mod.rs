//! Calibrated Lambertian photometric stereo.
//!
//! Per pixel and channel c, image k holds `a_kc = ρ_c E_kc (n·l_k) / π`, so
//! `b_kc = π a_kc / E_kc = ρ_c (l_k·n)`. The normal comes from one least-squares fit over all
//! three channels (`g = (LᵀL)⁻¹ Lᵀ Σ_c b_c`, `n = g/|g|`); the albedo of each channel is then the
//! least-squares scale `ρ_c = (Ln)·b_c / |Ln|²`.
//!
//! Which observations a pixel's fit uses is its robust mode ([`Robust`]). Every mode but
//! [`Robust::None`] leaves saturated observations out. The threshold mode also drops, per
//! pixel, the observations in shadow (whose summed `b` is below `shadow_fraction` of that
//! pixel's brightest) and re-solves from the rest when at least 3 non-coplanar lights
//! remain; otherwise it keeps the full fit and flags the pixel. The Tukey (default) and trim
//! modes fit each pixel from its own observations ([`crate::ps::tukey`], [`crate::ps::trim`]);
//! the lobe mode refits the Tukey fit with a specular lobe where one explains the
//! observations better ([`crate::ps::lobe`]).
//!
//! The plain and threshold fits run over tiles of pixels, streaming through each image's rows
//! of the tile (twice in threshold mode: once for each pixel's brightest, once to
//! accumulate); only the tile's masked pixels are de-interleaved and summed, their sums kept
//! in structure-of-arrays form so that the loops run over contiguous values.

use std::f32::consts::PI;
use std::sync::{Mutex, PoisonError};

use glam::{Mat3, Vec3};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::memory::{try_vec, try_with_capacity};
use crate::ps::trim::Lights;
use crate::scene::Light;

mod lanes;
pub mod lobe;
pub mod trim;
pub mod tukey;

/// Pixels per tile.
const TILE: usize = 256;
/// A set of lights is coplanar when the smallest eigenvalue of LᵀL is below this fraction of
/// the largest.
pub(crate) const COPLANAR_RATIO: f32 = 1e-4;

/// Which observations a pixel's fit uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Robust {
    /// Every observation (plain least squares).
    None,
    /// Drop shadowed (below `shadow_fraction` of the pixel's brightest) and saturated ones.
    Threshold,
    /// Keep those between the darkest 40 % and the brightest 20 % ([`crate::ps::trim::TRIM_DARKEST`],
    /// [`crate::ps::trim::TRIM_BRIGHTEST`]), saturated ones counted as brightest and dropped.
    Trim,
    /// From the threshold fit, re-weight by Tukey's biweight of the residuals
    /// ([`crate::ps::tukey::TUKEY_SCALES`]).
    Tukey,
    /// From the Tukey fit, a Lambertian base plus one specular lobe per pixel, re-weighted
    /// by Tukey's biweight ([`crate::ps::lobe`]): for glossy and metallic objects.
    Lobe,
}

/// How to fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PsSettings {
    /// Which observations each pixel's fit uses.
    pub robust: Robust,
    /// In the threshold and Tukey modes, an observation is in shadow when its channel-summed
    /// `b` is below this fraction of the pixel's brightest (the Tukey mode's start).
    pub shadow_fraction: f32,
    /// In every robust mode, raw values at or above this level (in any channel) are saturated.
    pub saturation: Option<f32>,
    /// In the lobe mode, the rounds of each exponent's fit from each start (at least 1):
    /// [`crate::ps::lobe::LOBE_ROUNDS`] by default, fewer for a quicker look at which pixels
    /// take a lobe.
    pub lobe_rounds: usize,
}

impl Default for PsSettings {
    fn default() -> Self {
        PsSettings {
            robust: Robust::Tukey,
            shadow_fraction: 0.05,
            saturation: None,
            lobe_rounds: crate::ps::lobe::LOBE_ROUNDS,
        }
    }
}

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
    fn new(n: usize) -> Result<PsOutput> {
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

/// Checks the lights for photometric stereo: at least 3, not coplanar, positive irradiance.
pub fn check_lights(lights: &[Light]) -> Result<Mat3> {
    if lights.len() < 3 {
        return Err(Error::input(
            "lights",
            format!(
                "{} given; photometric stereo needs at least 3",
                lights.len()
            ),
        ));
    }
    for (k, light) in lights.iter().enumerate() {
        if !(light.direction.is_finite() && light.direction.length_squared() > 0.0) {
            return Err(Error::input(
                &format!("lights[{k}].direction"),
                format!(
                    "{:?} is not a finite non-zero vector",
                    light.direction.to_array()
                ),
            ));
        }
        if light
            .irradiance
            .iter()
            .any(|&e| !(e > 0.0 && e.is_finite()))
        {
            return Err(Error::input(
                &format!("lights[{k}].irradiance"),
                "must be positive in every channel",
            ));
        }
    }
    let gram = lights
        .iter()
        .fold(Mat3::ZERO, |m, l| m + outer(l.direction.into()));
    let (min, max) = eigen_range(gram);
    if min < COPLANAR_RATIO * max {
        return Err(Error::input(
            "lights",
            "directions are (nearly) coplanar: the normal is not determined",
        ));
    }
    Ok(gram)
}

/// Fits normals and albedo to `images` laid out `(K, pixels, 3)` (row-major images, RGB
/// interleaved) for the pixels where `mask` is true.
pub fn photometric_stereo(
    images: &[f32],
    mask: &[bool],
    lights: &[Light],
    settings: &PsSettings,
) -> Result<PsOutput> {
    let gram = check_lights(lights)?;
    check_images(images, mask, lights.len())?;
    check_settings(settings)?;
    fit_checked(images, mask, lights, gram, settings)
}

/// `photometric_stereo` of inputs already checked (`gram` from `check_lights`): what the
/// auto mode runs after checking its images once for both of its fits.
fn fit_checked(
    images: &[f32],
    mask: &[bool],
    lights: &[Light],
    gram: Mat3,
    settings: &PsSettings,
) -> Result<PsOutput> {
    let fit = Fit::new(lights, gram, settings);
    let mut out = PsOutput::new(mask.len())?;
    let per_pixel = Lights::new(&fit.directions, &fit.scale, &fit.saturated_b, gram);
    match settings.robust {
        Robust::Tukey => crate::ps::tukey::fit_pixels(
            images,
            mask,
            &per_pixel,
            settings.shadow_fraction,
            &mut out,
        )?,
        Robust::Lobe => {
            crate::ps::tukey::fit_pixels(
                images,
                mask,
                &per_pixel,
                settings.shadow_fraction,
                &mut out,
            )?;
            crate::ps::lobe::fit_pixels(images, mask, &per_pixel, settings.lobe_rounds, &mut out)?;
        }
        Robust::Trim => crate::ps::trim::fit_pixels(images, mask, &per_pixel, &mut out)?,
        Robust::None | Robust::Threshold => return Ok(fit.streamed(images, mask, out)),
    }
    Ok(out)
}

/// Refuses images that are not `(K, pixels, 3)` for `k_count` lights and the pixels of
/// `mask`, a mask of no pixel, and a NaN or infinity at a pixel where `mask` is true (named
/// by image and pixel index).
fn check_images(images: &[f32], mask: &[bool], k_count: usize) -> Result<()> {
    let n = mask.len();
    if n == 0 {
        return Err(Error::input(
            "images",
            "no pixel: the images and the mask are empty",
        ));
    }
    if images.len() != k_count * n * 3 {
        return Err(Error::input(
            "images",
            format!(
                "{} values for {k_count} lights x {n} pixels x 3",
                images.len()
            ),
        ));
    }
    let bad = images
        .par_chunks_exact(3 * n)
        .enumerate()
        .find_map_first(|(k, image)| {
            let pixels = image.chunks_exact(3).zip(mask).enumerate();
            pixels
                .filter(|(_, (_, &inside))| inside)
                .find_map(|(p, (rgb, _))| rgb.iter().find(|v| !v.is_finite()).map(|&v| (k, p, v)))
        });
    match bad {
        Some((k, p, v)) => Err(Error::input(
            "images",
            format!("non-finite value {v} in image {k} at pixel {p} (row-major)"),
        )),
        None => Ok(()),
    }
}

/// Refuses a shadow fraction outside [0, 1), a saturation level that is not a positive
/// finite number, and no lobe rounds.
fn check_settings(settings: &PsSettings) -> Result<()> {
    if !(0.0..1.0).contains(&settings.shadow_fraction) {
        return Err(Error::input(
            "shadow_fraction",
            format!("{} is not in [0, 1)", settings.shadow_fraction),
        ));
    }
    if let Some(level) = settings
        .saturation
        .filter(|level| !(*level > 0.0 && level.is_finite()))
    {
        return Err(Error::input(
            "saturation",
            format!("{level} is not a positive finite number"),
        ));
    }
    if settings.lobe_rounds == 0 {
        return Err(Error::input("lobe_rounds", "must be at least 1"));
    }
    Ok(())
}

/// The auto mode's two fits at once: `images` where `mask` is true in the Tukey mode (the
/// fit `settings` ask for, whatever their robust mode), and beside it, on the same threads,
/// the pixels `check` (indices into `mask`, in any order) in the lobe mode with
/// `check_rounds` rounds, the look at which pixels take a specular lobe that decides whether
/// the object wants the lobe mode. Returns the Tukey fit and the flag of each pixel of
/// `check`. The check's few pixels take the threads that the Tukey fit leaves idle, instead
/// of a call of their own before it.
pub fn tukey_with_lobe_check(
    images: &[f32],
    mask: &[bool],
    check: &[usize],
    lights: &[Light],
    settings: &PsSettings,
    check_rounds: usize,
) -> Result<(PsOutput, Vec<u8>)> {
    let n = mask.len();
    if let Some(&pixel) = check.iter().find(|&&pixel| pixel >= n) {
        return Err(Error::input(
            "check",
            format!("pixel {pixel} is outside the {n} pixels of the mask"),
        ));
    }
    if check_rounds == 0 {
        return Err(Error::input("check_rounds", "must be at least 1"));
    }
    let tukey = PsSettings {
        robust: Robust::Tukey,
        ..*settings
    };
    let lobe = PsSettings {
        robust: Robust::Lobe,
        lobe_rounds: check_rounds,
        ..*settings
    };
    if check.is_empty() {
        return Ok((
            photometric_stereo(images, mask, lights, &tukey)?,
            Vec::new(),
        ));
    }
    let gram = check_lights(lights)?;
    check_images(images, mask, lights.len())?;
    check_settings(&tukey)?;
    let look = || {
        let observed: Vec<f32> = images
            .chunks_exact(3 * n)
            .flat_map(|image| {
                check
                    .iter()
                    .flat_map(move |&pixel| image[3 * pixel..3 * pixel + 3].iter().copied())
            })
            .collect();
        photometric_stereo(&observed, &vec![true; check.len()], lights, &lobe)
    };
    let (fit, looked) = rayon::join(|| fit_checked(images, mask, lights, gram, &tukey), look);
    Ok((fit?, looked?.flags))
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
fn for_each_with<T: Send, S>(
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

impl Fit {
    /// The plain or threshold fit, streamed over tiles of the images.
    fn streamed(&self, images: &[f32], mask: &[bool], mut out: PsOutput) -> PsOutput {
        let k_count = self.directions.len();
        let n = mask.len();
        let tiles = out
            .normals
            .chunks_mut(TILE)
            .zip(out.albedo.chunks_mut(TILE))
            .zip(out.flags.chunks_mut(TILE))
            .zip(out.used.chunks_mut(TILE))
            .enumerate();
        for_each_with(
            tiles,
            || Box::new(Sums::default()),
            |sums, (tile, (((normals, albedo), flags), used))| {
                let start = tile * TILE;
                let pixels = normals.len();
                let kept = sums.keep(&mask[start..start + pixels]);
                if kept == 0 {
                    return;
                }
                let src = |k: usize| &images[(k * n + start) * 3..][..pixels * 3];
                self.accumulate_tile(src, sums, kept, kept == pixels);
                for (i, &p) in sums.at[..kept].iter().enumerate() {
                    let (normal, rho, f, count) = self.solve(sums, i, || {
                        (0..k_count).map(|k| self.observation(src(k), k, p))
                    });
                    normals[p] = normal;
                    albedo[p] = rho;
                    flags[p] = f;
                    used[p] = count;
                }
            },
        );
        out
    }
}

/// Per-pixel sums of the masked pixels of a tile, structure of arrays so that loops run over
/// contiguous values.
struct Sums {
    /// The tile's masked pixels (offsets in the tile), whose sums these are in order.
    at: [usize; TILE],
    /// Σ w l_j b_c, index `j·3 + c`.
    rhs: [[f32; TILE]; 9],
    /// Σ w l lᵀ: xx, xy, xz, yy, yz, zz.
    gram: [[f32; TILE]; 6],
    /// Σ w.
    count: [f32; TILE],
    /// Largest channel-summed `b` of each pixel.
    brightest: [f32; TILE],
    /// One light's `b` per channel, de-interleaved.
    b: [[f32; TILE]; 3],
}

impl Default for Sums {
    fn default() -> Self {
        Sums {
            at: [0; TILE],
            rhs: [[0.0; TILE]; 9],
            gram: [[0.0; TILE]; 6],
            count: [0.0; TILE],
            brightest: [0.0; TILE],
            b: [[0.0; TILE]; 3],
        }
    }
}

impl Sums {
    /// Takes the pixels of a tile where `tile_mask` is true; returns how many.
    fn keep(&mut self, tile_mask: &[bool]) -> usize {
        let mut kept = 0;
        for (p, &on) in tile_mask.iter().enumerate() {
            self.at[kept] = p;
            kept += usize::from(on);
        }
        kept
    }
}

/// Light-dependent constants of a fit.
struct Fit {
    directions: Vec<Vec3>,
    /// π / E_kc, per light and channel.
    scale: Vec<[f32; 3]>,
    /// Raw saturation level times π / E_kc, per light and channel (∞ when off).
    saturated_b: Vec<[f32; 3]>,
    gram: Mat3,
    settings: PsSettings,
}

impl Fit {
    fn new(lights: &[Light], gram: Mat3, settings: &PsSettings) -> Fit {
        let scale: Vec<[f32; 3]> = lights
            .iter()
            .map(|l| l.irradiance.map(|e| PI / e))
            .collect();
        let level = settings
            .saturation
            .filter(|_| settings.robust != Robust::None)
            .unwrap_or(f32::INFINITY);
        let saturated_b = scale.iter().map(|s| s.map(|v| v * level)).collect();
        Fit {
            directions: lights.iter().map(|l| l.direction.into()).collect(),
            scale,
            saturated_b,
            gram,
            settings: *settings,
        }
    }

    /// `b` of light k at tile pixel p, from that light's interleaved tile data.
    #[inline]
    fn observation(&self, src: &[f32], k: usize, p: usize) -> [f32; 3] {
        let s = self.scale[k];
        [
            src[p * 3] * s[0],
            src[p * 3 + 1] * s[1],
            src[p * 3 + 2] * s[2],
        ]
    }

    /// De-interleaves light k's `b` of the kept pixels of a tile (`dense` when they are all
    /// of its pixels) from that light's interleaved tile data.
    fn load(&self, sums: &mut Sums, src: &[f32], k: usize, kept: usize, dense: bool) {
        let s = self.scale[k];
        for c in 0..3 {
            let b = &mut sums.b[c][..kept];
            if dense {
                for (p, d) in b.iter_mut().enumerate() {
                    *d = src[p * 3 + c] * s[c];
                }
            } else {
                for (d, &p) in b.iter_mut().zip(&sums.at[..kept]) {
                    *d = src[p * 3 + c] * s[c];
                }
            }
        }
    }

    /// Fills `sums` for the `kept` pixels of one tile (`dense` when they are all of its
    /// pixels); `src(k)` is light k's interleaved data of the tile.
    fn accumulate_tile<'a>(
        &self,
        src: impl Fn(usize) -> &'a [f32],
        sums: &mut Sums,
        kept: usize,
        dense: bool,
    ) {
        for row in sums.rhs.iter_mut().chain(sums.gram.iter_mut()) {
            row[..kept].fill(0.0);
        }
        sums.count[..kept].fill(0.0);
        sums.brightest[..kept].fill(0.0);
        if self.settings.robust == Robust::Threshold {
            for k in 0..self.directions.len() {
                self.load(sums, src(k), k, kept, dense);
                let Sums { b, brightest, .. } = sums;
                for p in 0..kept {
                    brightest[p] = brightest[p].max(b[0][p] + b[1][p] + b[2][p]);
                }
            }
            let fraction = self.settings.shadow_fraction;
            for v in &mut sums.brightest[..kept] {
                *v *= fraction;
            }
        } else {
            sums.brightest[..kept].fill(f32::NEG_INFINITY);
        }
        for (k, l) in self.directions.iter().enumerate() {
            self.load(sums, src(k), k, kept, dense);
            let sat = self.saturated_b[k];
            let ll = [
                l.x * l.x,
                l.x * l.y,
                l.x * l.z,
                l.y * l.y,
                l.y * l.z,
                l.z * l.z,
            ];
            let lj = [l.x, l.y, l.z];
            let Sums {
                rhs,
                gram,
                count,
                brightest,
                b,
                ..
            } = sums;
            for p in 0..kept {
                let (b0, b1, b2) = (b[0][p], b[1][p], b[2][p]);
                let keep = b0 + b1 + b2 > brightest[p] && b0 < sat[0] && b1 < sat[1] && b2 < sat[2];
                let w = if keep { 1.0 } else { 0.0 };
                count[p] += w;
                for m in 0..6 {
                    gram[m][p] += w * ll[m];
                }
                for j in 0..3 {
                    let wl = w * lj[j];
                    rhs[j * 3][p] += wl * b0;
                    rhs[j * 3 + 1][p] += wl * b1;
                    rhs[j * 3 + 2][p] += wl * b2;
                }
            }
        }
    }

    /// Fits the tile's `p`-th kept pixel from its sums; `all` yields every observation of the
    /// pixel, for the full fit when the robust selection is not enough. Returns (normal,
    /// albedo, flag, observations used).
    fn solve<I: Iterator<Item = [f32; 3]>>(
        &self,
        sums: &Sums,
        p: usize,
        all: impl Fn() -> I,
    ) -> ([f32; 3], [f32; 3], u8, u16) {
        let k_count = self.directions.len();
        let g = |m: usize| sums.gram[m][p];
        let kept_gram = Mat3::from_cols(
            Vec3::new(g(0), g(1), g(2)),
            Vec3::new(g(1), g(3), g(4)),
            Vec3::new(g(2), g(4), g(5)),
        );
        let kept_rhs =
            [0, 1, 2].map(|c| Vec3::new(sums.rhs[c][p], sums.rhs[3 + c][p], sums.rhs[6 + c][p]));
        let count = sums.count[p] as usize;
        let (min, max) = eigen_range(kept_gram);
        let (gram, rhs, used, flag) = if count >= 3 && min >= COPLANAR_RATIO * max {
            (
                kept_gram,
                kept_rhs,
                count,
                if count == k_count || self.settings.robust != Robust::None {
                    flag::OK
                } else {
                    flag::FULL_FIT
                },
            )
        } else {
            let mut rhs = [Vec3::ZERO; 3];
            for (b, l) in all().zip(&self.directions) {
                for c in 0..3 {
                    rhs[c] += *l * b[c];
                }
            }
            (self.gram, rhs, k_count, flag::FULL_FIT)
        };
        match finish(gram, rhs) {
            Some((normal, albedo)) => (normal, albedo, flag, used as u16),
            None => ([0.0, 0.0, 1.0], [0.0; 3], flag::DARK, used as u16),
        }
    }
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
    use glam::vec3a;

    fn lights(dirs: &[[f32; 3]]) -> Vec<Light> {
        dirs.iter()
            .map(|d| Light {
                direction: vec3a(d[0], d[1], d[2]).normalize(),
                irradiance: [2.0, 3.0, 4.0],
            })
            .collect()
    }

    fn render(normal: Vec3, albedo: [f32; 3], lights: &[Light]) -> Vec<f32> {
        lights
            .iter()
            .flat_map(|l| {
                let cosine = normal.dot(l.direction.into()).max(0.0);
                [0, 1, 2].map(|c| albedo[c] * l.irradiance[c] * cosine / PI)
            })
            .collect()
    }

    #[test]
    fn recovers_normal_and_albedo_exactly_without_shadows() {
        let ls = lights(&[
            [0.0, 0.0, 1.0],
            [0.5, 0.1, 0.8],
            [-0.3, 0.4, 0.8],
            [0.1, -0.5, 0.8],
        ]);
        let normal = Vec3::new(0.1, -0.2, 1.0).normalize();
        let images = render(normal, [0.9, 0.5, 0.2], &ls);
        for robust in [
            Robust::None,
            Robust::Threshold,
            Robust::Trim,
            Robust::Tukey,
            Robust::Lobe,
        ] {
            let out = photometric_stereo(
                &images,
                &[true],
                &ls,
                &PsSettings {
                    robust,
                    ..Default::default()
                },
            )
            .unwrap();
            assert!(
                (Vec3::from(out.normals[0]) - normal).length() < 1e-5,
                "{robust:?} {:?}",
                out.normals[0]
            );
            for (got, want) in out.albedo[0].iter().zip([0.9, 0.5, 0.2]) {
                assert!((got - want).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn robust_mode_ignores_attached_shadows() {
        let ls = lights(&[
            [0.0, 0.0, 1.0],
            [0.7, 0.0, 0.7],
            [-0.7, 0.0, 0.7],
            [0.0, 0.7, 0.7],
            [0.0, -0.7, 0.7],
            [-0.9, -0.3, 0.3],
        ]);
        let normal = Vec3::new(0.6, 0.2, 0.8).normalize(); // the last light is behind it
        let images = render(normal, [0.5; 3], &ls);
        let plain = photometric_stereo(
            &images,
            &[true],
            &ls,
            &PsSettings {
                robust: Robust::None,
                ..Default::default()
            },
        )
        .unwrap();
        assert!((Vec3::from(plain.normals[0]) - normal).length() > 1e-2);
        for robust in [Robust::Threshold, Robust::Tukey] {
            let out = photometric_stereo(
                &images,
                &[true],
                &ls,
                &PsSettings {
                    robust,
                    ..Default::default()
                },
            )
            .unwrap();
            assert!((Vec3::from(out.normals[0]) - normal).length() < 1e-5);
            assert_eq!(out.used[0], 5);
        }
    }

    /// 24 lights around the pole; a normal lit by all of them.
    fn ring() -> Vec<Light> {
        let dirs: Vec<[f32; 3]> = (0..24)
            .map(|k| {
                let (azimuth, elevation) = (k as f32 * 0.9, 0.5 + 0.04 * k as f32);
                [
                    elevation.cos() * azimuth.cos(),
                    elevation.cos() * azimuth.sin(),
                    elevation.sin(),
                ]
            })
            .collect();
        lights(&dirs)
    }

    #[test]
    fn tukey_mode_sets_aside_soft_shadows_and_highlights_that_the_threshold_keeps() {
        let ls = ring();
        let normal = Vec3::new(0.1, 0.05, 1.0).normalize();
        let mut images = render(normal, [0.6; 3], &ls);
        for k in [2, 7, 11] {
            images[k * 3..k * 3 + 3].iter_mut().for_each(|v| *v *= 0.3); // partial cast shadows
        }
        for k in [4, 15] {
            images[k * 3..k * 3 + 3].iter_mut().for_each(|v| *v += 0.8); // highlights
        }
        let error = |robust| {
            let out = photometric_stereo(
                &images,
                &[true],
                &ls,
                &PsSettings {
                    robust,
                    ..Default::default()
                },
            )
            .unwrap();
            (
                (Vec3::from(out.normals[0]).dot(normal))
                    .clamp(-1.0, 1.0)
                    .acos()
                    .to_degrees(),
                out.used[0],
            )
        };
        let (threshold, _) = error(Robust::Threshold);
        let (tukey, used) = error(Robust::Tukey);
        assert!(threshold > 2.0, "threshold fit {threshold}");
        assert!(tukey < 0.1, "Tukey fit {tukey}");
        assert_eq!(used, 19);
    }

    #[test]
    fn trim_mode_keeps_the_middle_of_each_pixels_observations() {
        let ls = ring();
        let normal = Vec3::new(0.0, 0.1, 1.0).normalize();
        let mut images = render(normal, [0.5; 3], &ls);
        // The 5 brightest get highlights: exactly the 20 % the trim drops.
        let mut order: Vec<usize> = (0..24).collect();
        order.sort_by(|&a, &b| images[a * 3].total_cmp(&images[b * 3]));
        for &k in &order[19..] {
            images[k * 3..k * 3 + 3].iter_mut().for_each(|v| *v += 1.0);
        }
        let out = photometric_stereo(
            &images,
            &[true],
            &ls,
            &PsSettings {
                robust: Robust::Trim,
                ..Default::default()
            },
        )
        .unwrap();
        assert!((Vec3::from(out.normals[0]) - normal).length() < 1e-5);
        assert_eq!(out.used[0], 24 - 10 - 5);
    }

    #[test]
    fn every_mode_fits_a_pixel_alike_whichever_other_pixels_the_mask_holds() {
        // 1500 pixels: several chunks and tiles of every mode; some shadowed or highlighted
        // observations; a mask with runs and gaps of every length. Each pixel fitted alone,
        // with every pixel and with some must come out the same.
        let (ls, pixels) = (ring(), 1500);
        let mut images = vec![0.0; ls.len() * pixels * 3];
        for p in 0..pixels {
            let (u, v) = ((p % 50) as f32 / 50.0 - 0.5, (p / 50) as f32 / 30.0 - 0.5);
            let observed = render(
                Vec3::new(u, v, 1.0).normalize(),
                [0.3 + 0.4 * u.abs(), 0.5, 0.7 - 0.3 * v.abs()],
                &ls,
            );
            for (k, rgb) in observed.chunks_exact(3).enumerate() {
                let factor = match (p * 7 + k * 13) % 17 {
                    0 => 0.3,
                    1 => 2.0,
                    _ => 1.0,
                };
                for (c, value) in rgb.iter().enumerate() {
                    images[(k * pixels + p) * 3 + c] = value * factor;
                }
            }
        }
        let every = vec![true; pixels];
        let some: Vec<bool> = (0..pixels)
            .map(|p| (p * p / 7 + p / 11) % 3 != 0 && !(600..700).contains(&p))
            .collect();
        for robust in [
            Robust::None,
            Robust::Threshold,
            Robust::Trim,
            Robust::Tukey,
            Robust::Lobe,
        ] {
            let settings = PsSettings {
                robust,
                ..Default::default()
            };
            let (all, part) = (
                photometric_stereo(&images, &every, &ls, &settings).unwrap(),
                photometric_stereo(&images, &some, &ls, &settings).unwrap(),
            );
            assert!(
                all.flags.iter().all(|&f| f != flag::MASKED_OUT),
                "{robust:?}"
            );
            for p in (0..pixels).step_by(97) {
                let alone: Vec<f32> = (0..ls.len())
                    .flat_map(|k| images[(k * pixels + p) * 3..][..3].to_vec())
                    .collect();
                let one = photometric_stereo(&alone, &[true], &ls, &settings).unwrap();
                assert_eq!(
                    (one.normals[0], one.albedo[0], one.used[0]),
                    (all.normals[p], all.albedo[p], all.used[p]),
                    "{robust:?} pixel {p} alone"
                );
            }
            for (p, &kept) in some.iter().enumerate() {
                if kept {
                    let bits = |out: &PsOutput| {
                        (
                            out.normals[p].map(f32::to_bits),
                            out.albedo[p].map(f32::to_bits),
                            out.flags[p],
                            out.used[p],
                        )
                    };
                    assert_eq!(bits(&part), bits(&all), "{robust:?} pixel {p}");
                } else {
                    assert_eq!(
                        (part.normals[p], part.flags[p]),
                        ([0.0; 3], flag::MASKED_OUT),
                        "{robust:?} pixel {p}"
                    );
                }
            }
        }
    }

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

    #[test]
    fn too_few_or_coplanar_lights_are_errors() {
        let two = lights(&[[0.0, 0.0, 1.0], [0.5, 0.0, 0.8]]);
        assert!(check_lights(&two)
            .unwrap_err()
            .to_string()
            .contains("at least 3"));
        let coplanar = lights(&[
            [0.0, 0.0, 1.0],
            [0.5, 0.0, 0.8],
            [-0.5, 0.0, 0.8],
            [0.3, 0.0, 0.9],
        ]);
        assert!(check_lights(&coplanar)
            .unwrap_err()
            .to_string()
            .contains("coplanar"));
    }

    #[test]
    fn dark_and_masked_pixels_are_flagged() {
        let ls = lights(&[[0.0, 0.0, 1.0], [0.5, 0.1, 0.8], [-0.3, 0.4, 0.8]]);
        let images = vec![0.0; 3 * 2 * 3];
        let out = photometric_stereo(&images, &[true, false], &ls, &PsSettings::default()).unwrap();
        assert_eq!(out.flags, vec![flag::DARK, flag::MASKED_OUT]);
    }
}

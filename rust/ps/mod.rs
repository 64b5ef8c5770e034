//! Calibrated Lambertian photometric stereo: this module checks the inputs and dispatches
//! to the fit of the robust mode asked for.
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
//! modes fit each pixel from its own observations ([`tukey`], [`trim`]); the lobe mode refits
//! the Tukey fit with a specular lobe where one explains the observations better ([`lobe`]).
//!
//! The modules, each importing only those above it:
//! - `kernel`: what every mode shares: the output and its flags, the lights as the fits read
//!   them, the least-squares solve of a pixel, the parallel run over the mask's pixels;
//! - `lanes`: values side by side in vector registers, for the Tukey and lobe fits;
//! - `threshold`: the plain and threshold fits; [`trim`]: rank trimming; [`tukey`]: Tukey
//!   re-weighting; [`lobe`]: a specular lobe per pixel, from the Tukey fit.

use glam::Mat3;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::scene::Light;

use kernel::{eigen_range, outer, Lights, PerLight, COPLANAR_RATIO};
pub use kernel::{flag, PsOutput};

mod kernel;
mod lanes;
pub mod lobe;
mod threshold;
pub mod trim;
pub mod tukey;

/// Which observations a pixel's fit uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Robust {
    /// Every observation (plain least squares).
    None,
    /// Drop shadowed (below `shadow_fraction` of the pixel's brightest) and saturated ones.
    Threshold,
    /// Keep those between the darkest 40 % and the brightest 20 % ([`trim::TRIM_DARKEST`],
    /// [`trim::TRIM_BRIGHTEST`]), saturated ones counted as brightest and dropped.
    Trim,
    /// From the threshold fit, re-weight by Tukey's biweight of the residuals
    /// ([`tukey::TUKEY_SCALES`]).
    Tukey,
    /// From the Tukey fit, a Lambertian base plus one specular lobe per pixel, re-weighted
    /// by Tukey's biweight ([`lobe`]): for glossy and metallic objects.
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
    /// [`lobe::LOBE_ROUNDS`] by default, fewer for a quicker look at which pixels
    /// take a lobe.
    pub lobe_rounds: usize,
}

impl Default for PsSettings {
    fn default() -> Self {
        PsSettings {
            robust: Robust::Tukey,
            shadow_fraction: 0.05,
            saturation: None,
            lobe_rounds: lobe::LOBE_ROUNDS,
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
/// interleaved) for the pixels where `mask` is true. `views` holds, per pixel, the unit
/// direction from its surface point toward the camera (a pinhole's differs pixel by pixel),
/// which the lobe mode's half vectors take; None: a distant camera along +z.
pub fn photometric_stereo(
    images: &[f32],
    mask: &[bool],
    lights: &[Light],
    settings: &PsSettings,
    views: Option<&[[f32; 3]]>,
) -> Result<PsOutput> {
    let gram = check_lights(lights)?;
    check_images(images, mask, lights.len())?;
    check_settings(settings)?;
    check_views(views, mask.len())?;
    fit_checked(images, mask, lights, gram, settings, views)
}

/// Photometric stereo under lights that differ from pixel to pixel: point lights near the
/// object (contract §4b), whose direction and irradiance at each surface point the caller
/// computes. `images` are `(K, pixels, 3)` as for [`photometric_stereo`]; the m-th pixel of
/// `mask` (row-major) takes the K lights `lights[m·K..(m+1)·K]` (its direction toward each
/// light and its irradiance from it) and is otherwise fitted as [`photometric_stereo`] fits
/// a pixel with `settings`. An error names the first pixel whose lights are unusable.
pub fn photometric_stereo_per_pixel(
    images: &[f32],
    mask: &[bool],
    lights: &[Light],
    settings: &PsSettings,
    views: Option<&[[f32; 3]]>,
) -> Result<PsOutput> {
    let masked: Vec<usize> = (0..mask.len()).filter(|&p| mask[p]).collect();
    if masked.is_empty() {
        return Err(Error::input("mask", "has no pixel"));
    }
    if !lights.len().is_multiple_of(masked.len()) {
        return Err(Error::input(
            "lights",
            format!(
                "{} lights for {} pixels: expected the same number for each",
                lights.len(),
                masked.len()
            ),
        ));
    }
    let k_count = lights.len() / masked.len();
    check_images(images, mask, k_count)?;
    check_settings(settings)?;
    check_views(views, mask.len())?;
    let n = mask.len();
    let fits: Vec<Result<PsOutput>> = masked
        .par_iter()
        .enumerate()
        .map(|(m, &p)| {
            let own = &lights[m * k_count..(m + 1) * k_count];
            let gram = check_lights(own)
                .map_err(|e| Error::input(&format!("lights at pixel {p}"), e.to_string()))?;
            let mut observations = Vec::with_capacity(k_count * 3);
            for k in 0..k_count {
                observations.extend_from_slice(&images[(k * n + p) * 3..][..3]);
            }
            let view = views.map(|v| [v[p]]);
            fit_checked(
                &observations,
                &[true],
                own,
                gram,
                settings,
                view.as_ref().map(|v| &v[..]),
            )
        })
        .collect();
    let mut out = PsOutput::new(n)?;
    for (fit, &p) in fits.into_iter().zip(&masked) {
        let fit = fit?;
        out.normals[p] = fit.normals[0];
        out.albedo[p] = fit.albedo[0];
        out.flags[p] = fit.flags[0];
        out.used[p] = fit.used[0];
    }
    Ok(out)
}

/// `photometric_stereo` of inputs already checked (`gram` from `check_lights`): what the
/// auto mode runs after checking its images once for both of its fits.
fn fit_checked(
    images: &[f32],
    mask: &[bool],
    lights: &[Light],
    gram: Mat3,
    settings: &PsSettings,
    views: Option<&[[f32; 3]]>,
) -> Result<PsOutput> {
    let saturation = settings
        .saturation
        .filter(|_| settings.robust != Robust::None);
    let per_light = PerLight::new(lights, saturation);
    let mut out = PsOutput::new(mask.len())?;
    let per_pixel = Lights::new(
        &per_light.directions,
        &per_light.scale,
        &per_light.saturated_b,
        gram,
    );
    let shadow_fraction = settings.shadow_fraction;
    match settings.robust {
        Robust::Tukey => tukey::fit_pixels(images, mask, &per_pixel, shadow_fraction, &mut out)?,
        Robust::Lobe => {
            tukey::fit_pixels(images, mask, &per_pixel, shadow_fraction, &mut out)?;
            lobe::fit_pixels(
                images,
                mask,
                &per_pixel,
                settings.lobe_rounds,
                views,
                &mut out,
            )?;
        }
        Robust::Trim => trim::fit_pixels(images, mask, &per_pixel, &mut out)?,
        Robust::None | Robust::Threshold => {
            let shadow = (settings.robust == Robust::Threshold).then_some(shadow_fraction);
            return Ok(threshold::fit_pixels(
                images, mask, &per_light, gram, shadow, out,
            ));
        }
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

/// Refuses `views` that are not one unit vector toward the camera (z > 0) per pixel.
fn check_views(views: Option<&[[f32; 3]]>, pixels: usize) -> Result<()> {
    let Some(views) = views else {
        return Ok(());
    };
    if views.len() != pixels {
        return Err(Error::input(
            "views",
            format!("{} directions for {pixels} pixels", views.len()),
        ));
    }
    if let Some(p) = views.iter().position(|&[x, y, z]| {
        let length = (x * x + y * y + z * z).sqrt();
        !(z > 0.0 && (length - 1.0).abs() <= 1e-3)
    }) {
        return Err(Error::input(
            "views",
            format!(
                "{:?} at pixel {p} is not a unit vector toward the camera (z > 0)",
                views[p]
            ),
        ));
    }
    Ok(())
}

/// The auto mode's two fits at once: `images` where `mask` is true in the Tukey mode (the
/// fit `settings` ask for, whatever their robust mode), and beside it, on the same threads,
/// the pixels `check` (indices into `mask`, in any order) in the lobe mode with
/// `check_rounds` rounds, the look at which pixels take a specular lobe that decides whether
/// the object wants the lobe mode. Returns the Tukey fit and the flag of each pixel of
/// `check`. The check's few pixels take the threads that the Tukey fit leaves idle, instead
/// of a call of their own before it. `views` as for [`photometric_stereo`].
pub fn tukey_with_lobe_check(
    images: &[f32],
    mask: &[bool],
    check: &[usize],
    lights: &[Light],
    settings: &PsSettings,
    check_rounds: usize,
    views: Option<&[[f32; 3]]>,
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
            photometric_stereo(images, mask, lights, &tukey, views)?,
            Vec::new(),
        ));
    }
    let gram = check_lights(lights)?;
    check_images(images, mask, lights.len())?;
    check_settings(&tukey)?;
    check_views(views, n)?;
    let look = || {
        let observed: Vec<f32> = images
            .chunks_exact(3 * n)
            .flat_map(|image| {
                check
                    .iter()
                    .flat_map(move |&pixel| image[3 * pixel..3 * pixel + 3].iter().copied())
            })
            .collect();
        let seen: Option<Vec<[f32; 3]>> =
            views.map(|views| check.iter().map(|&pixel| views[pixel]).collect());
        fit_checked(
            &observed,
            &vec![true; check.len()],
            lights,
            gram,
            &lobe,
            seen.as_deref(),
        )
    };
    let (fit, looked) = rayon::join(
        || fit_checked(images, mask, lights, gram, &tukey, views),
        look,
    );
    Ok((fit?, looked?.flags))
}

#[cfg(test)]
mod tests;

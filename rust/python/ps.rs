//! Photometric stereo: the lights' check and the fits.

use numpy::ndarray::{Array, IxDyn};
use numpy::{
    IntoPyArray, PyArray1, PyArrayDyn, PyReadonlyArray2, PyReadonlyArray3, PyReadonlyArray4,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::ps::{
    check_lights as core_check_lights, photometric_stereo as core_ps,
    photometric_stereo_per_pixel as core_ps_per_pixel,
    tukey_with_lobe_check as core_tukey_with_lobe_check, PsOutput, PsSettings, Robust,
};
use crate::scene::Light;

use super::convert::{flat, lights_from};
use super::errors::{argument_error, to_py};

/// Checks lights for photometric stereo: at least 3, not (nearly) coplanar, irradiance
/// positive in every channel. Raises ValueError naming the field otherwise.
#[pyfunction]
pub(super) fn check_lights(
    light_directions: PyReadonlyArray2<'_, f32>,
    light_irradiance: PyReadonlyArray2<'_, f32>,
) -> PyResult<()> {
    let lights = lights_from(&light_directions, &light_irradiance)?;
    core_check_lights(&lights).map(|_| ()).map_err(to_py)
}

type PsArrays<'py> = (
    Bound<'py, PyArrayDyn<f32>>,
    Bound<'py, PyArrayDyn<f32>>,
    Bound<'py, PyArrayDyn<u8>>,
    Bound<'py, PyArrayDyn<u16>>,
);

/// Calibrated Lambertian photometric stereo on C-contiguous float32 images (K, H, W, 3):
/// (normals (H, W, 3), albedo (H, W, 3), flags (H, W) uint8, observations used (H, W) uint16).
/// `robust` is "none", "threshold", "trim", "tukey" or "lobe"; `lobe_rounds` the lobe mode's
/// most rounds per exponent and start (at least 1; its 15 by default); `views` None (the
/// lobe's half vectors look from a distant camera along +z) or (H, W, 3) float32, each
/// pixel's unit direction toward the camera (a pinhole's).
#[pyfunction]
#[pyo3(signature = (images, mask, light_directions, light_irradiance, robust="tukey", shadow_fraction=0.05, saturation=None, lobe_rounds=None, views=None))]
#[allow(clippy::too_many_arguments)]
pub(super) fn photometric_stereo<'py>(
    py: Python<'py>,
    images: PyReadonlyArray4<'_, f32>,
    mask: PyReadonlyArray2<'_, bool>,
    light_directions: PyReadonlyArray2<'_, f32>,
    light_irradiance: PyReadonlyArray2<'_, f32>,
    robust: &str,
    shadow_fraction: f32,
    saturation: Option<f32>,
    lobe_rounds: Option<usize>,
    views: Option<PyReadonlyArray3<'_, f32>>,
) -> PyResult<PsArrays<'py>> {
    let PsInputs {
        shape,
        lights,
        data,
        mask: mask_data,
    } = ps_inputs(&images, &mask, &light_directions, &light_irradiance)?;
    let settings = PsSettings {
        robust: robust_mode(robust)?,
        shadow_fraction,
        saturation,
        lobe_rounds: lobe_rounds.unwrap_or(crate::ps::lobe::LOBE_ROUNDS),
    };
    let views = views_of(views.as_ref(), &shape)?;
    let out = py
        .detach(|| core_ps(data, mask_data, &lights, &settings, views.as_deref()))
        .map_err(to_py)?;
    ps_arrays(py, out, shape[1], shape[2])
}

/// The (K, H, W, 3) shape of `images`, checked against the (H, W) `mask`.
fn image_shape(
    images: &PyReadonlyArray4<'_, f32>,
    mask: &PyReadonlyArray2<'_, bool>,
) -> PyResult<Vec<usize>> {
    let shape = images.shape().to_vec();
    if shape[3] != 3 || mask.shape() != [shape[1], shape[2]] {
        return Err(argument_error(
            "images",
            format!(
                "shape {shape:?} does not match mask {:?} x 3 channels",
                mask.shape()
            ),
        ));
    }
    Ok(shape)
}

/// The robust mode named `robust`.
fn robust_mode(robust: &str) -> PyResult<Robust> {
    Ok(match robust {
        "none" => Robust::None,
        "threshold" => Robust::Threshold,
        "trim" => Robust::Trim,
        "tukey" => Robust::Tukey,
        "lobe" => Robust::Lobe,
        other => {
            return Err(argument_error(
                "robust",
                format!("unknown mode {other:?}; expected none, threshold, trim, tukey or lobe"),
            ))
        }
    })
}

/// Photometric stereo under lights that differ from pixel to pixel (point lights near the
/// object): as [`photometric_stereo`], with `light_directions` and `light_irradiance`
/// (N, K, 3) float32 the unit direction toward each light and the irradiance from it at each
/// of the mask's N pixels (row-major).
#[pyfunction]
#[pyo3(signature = (images, mask, light_directions, light_irradiance, robust="tukey", shadow_fraction=0.05, saturation=None, lobe_rounds=None, views=None))]
#[allow(clippy::too_many_arguments)]
pub(super) fn photometric_stereo_per_pixel<'py>(
    py: Python<'py>,
    images: PyReadonlyArray4<'_, f32>,
    mask: PyReadonlyArray2<'_, bool>,
    light_directions: PyReadonlyArray3<'_, f32>,
    light_irradiance: PyReadonlyArray3<'_, f32>,
    robust: &str,
    shadow_fraction: f32,
    saturation: Option<f32>,
    lobe_rounds: Option<usize>,
    views: Option<PyReadonlyArray3<'_, f32>>,
) -> PyResult<PsArrays<'py>> {
    let shape = image_shape(&images, &mask)?;
    let mask_data = flat(&mask, "mask")?;
    let pixels = mask_data.iter().filter(|&&m| m).count();
    let expected = [pixels, shape[0], 3];
    for (name, array) in [
        ("light_directions", &light_directions),
        ("light_irradiance", &light_irradiance),
    ] {
        if array.shape() != expected {
            return Err(argument_error(
                name,
                format!(
                    "shape {:?}, expected {expected:?} (each of the mask's pixels, each image's light)",
                    array.shape()
                ),
            ));
        }
    }
    let directions = flat(&light_directions, "light_directions")?;
    let irradiance = flat(&light_irradiance, "light_irradiance")?;
    let lights: Vec<Light> = directions
        .chunks_exact(3)
        .zip(irradiance.chunks_exact(3))
        .map(|(d, e)| Light {
            direction: glam::Vec3A::new(d[0], d[1], d[2]),
            irradiance: [e[0], e[1], e[2]],
        })
        .collect();
    let data = flat(&images, "images")?;
    let settings = PsSettings {
        robust: robust_mode(robust)?,
        shadow_fraction,
        saturation,
        lobe_rounds: lobe_rounds.unwrap_or(crate::ps::lobe::LOBE_ROUNDS),
    };
    let views = views_of(views.as_ref(), &shape)?;
    let out = py
        .detach(|| core_ps_per_pixel(&data, &mask_data, &lights, &settings, views.as_deref()))
        .map_err(to_py)?;
    ps_arrays(py, out, shape[1], shape[2])
}

/// Each pixel's direction toward the camera from a (H, W, 3) array matching the images'
/// (K, H, W, 3) `shape`.
fn views_of(
    views: Option<&PyReadonlyArray3<'_, f32>>,
    shape: &[usize],
) -> PyResult<Option<Vec<[f32; 3]>>> {
    let Some(views) = views else {
        return Ok(None);
    };
    if views.shape() != [shape[1], shape[2], 3] {
        return Err(argument_error(
            "views",
            format!(
                "shape {:?} does not match the images' {:?} x 3",
                views.shape(),
                &shape[1..3]
            ),
        ));
    }
    let values = flat(views, "views")?;
    Ok(Some(
        values.chunks_exact(3).map(|v| [v[0], v[1], v[2]]).collect(),
    ))
}

/// The inputs of a photometric-stereo call, checked against each other.
struct PsInputs<'a> {
    /// The images' (K, H, W, 3).
    shape: Vec<usize>,
    lights: Vec<Light>,
    /// The images' values, row-major.
    data: &'a [f32],
    /// The mask's values, row-major.
    mask: &'a [bool],
}

/// The images, mask and lights of a photometric-stereo call, checked against each other.
fn ps_inputs<'a>(
    images: &'a PyReadonlyArray4<'_, f32>,
    mask: &'a PyReadonlyArray2<'_, bool>,
    light_directions: &PyReadonlyArray2<'_, f32>,
    light_irradiance: &PyReadonlyArray2<'_, f32>,
) -> PyResult<PsInputs<'a>> {
    let shape = image_shape(images, mask)?;
    let lights = lights_from(light_directions, light_irradiance)?;
    if lights.len() != shape[0] {
        return Err(argument_error(
            "images",
            format!("{} images for {} lights", shape[0], lights.len()),
        ));
    }
    let data = images
        .as_array()
        .to_slice()
        .ok_or_else(|| argument_error("images", "must be C-contiguous"))?;
    let mask_data = mask
        .as_array()
        .to_slice()
        .ok_or_else(|| argument_error("mask", "must be C-contiguous"))?;
    Ok(PsInputs {
        shape,
        lights,
        data,
        mask: mask_data,
    })
}

/// `out` as the arrays of [`photometric_stereo`], for images `h` × `w`.
fn ps_arrays(py: Python<'_>, out: PsOutput, h: usize, w: usize) -> PyResult<PsArrays<'_>> {
    let planar = |v: Vec<[f32; 3]>| Array::from_shape_vec(IxDyn(&[h, w, 3]), v.into_flattened());
    let err = |e: numpy::ndarray::ShapeError| PyValueError::new_err(e.to_string());
    Ok((
        planar(out.normals).map_err(err)?.into_pyarray(py),
        planar(out.albedo).map_err(err)?.into_pyarray(py),
        Array::from_shape_vec(IxDyn(&[h, w]), out.flags)
            .map_err(err)?
            .into_pyarray(py),
        Array::from_shape_vec(IxDyn(&[h, w]), out.used)
            .map_err(err)?
            .into_pyarray(py),
    ))
}

/// The auto mode's fits at once: [`photometric_stereo`] of `images` in the Tukey mode and,
/// on the same threads, of the pixels `check` (flat indices into the mask) in the lobe mode
/// with `check_rounds` rounds (seen along `views`, as for [`photometric_stereo`]). Returns
/// the Tukey fit's arrays and the flag of each pixel of `check`.
#[pyfunction]
#[pyo3(signature = (images, mask, check, light_directions, light_irradiance, shadow_fraction, saturation, check_rounds, views=None))]
#[allow(clippy::too_many_arguments)]
pub(super) fn tukey_with_lobe_check<'py>(
    py: Python<'py>,
    images: PyReadonlyArray4<'_, f32>,
    mask: PyReadonlyArray2<'_, bool>,
    check: Vec<usize>,
    light_directions: PyReadonlyArray2<'_, f32>,
    light_irradiance: PyReadonlyArray2<'_, f32>,
    shadow_fraction: f32,
    saturation: Option<f32>,
    check_rounds: usize,
    views: Option<PyReadonlyArray3<'_, f32>>,
) -> PyResult<(PsArrays<'py>, Bound<'py, PyArray1<u8>>)> {
    let PsInputs {
        shape,
        lights,
        data,
        mask: mask_data,
    } = ps_inputs(&images, &mask, &light_directions, &light_irradiance)?;
    let settings = PsSettings {
        robust: Robust::Tukey,
        shadow_fraction,
        saturation,
        lobe_rounds: crate::ps::lobe::LOBE_ROUNDS,
    };
    let views = views_of(views.as_ref(), &shape)?;
    let (fit, flags) = py
        .detach(|| {
            core_tukey_with_lobe_check(
                data,
                mask_data,
                &check,
                &lights,
                &settings,
                check_rounds,
                views.as_deref(),
            )
        })
        .map_err(to_py)?;
    Ok((
        ps_arrays(py, fit, shape[1], shape[2])?,
        PyArray1::from_vec(py, flags),
    ))
}

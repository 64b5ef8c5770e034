//! The inter-reflection estimate: a rendering compared with the images, and the estimate
//! filtered along the surface.

use numpy::ndarray::Array;
use numpy::{
    IntoPyArray, PyArray1, PyArray3, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::render::denoise::{denoise as core_denoise, Surface};
use crate::render::residual::{compare as core_compare, Observed, RenderedPlanes};
use crate::scene::Rgb;

use super::convert::flat;
use super::errors::{argument_error, to_py};

/// A rendering's inter-reflection estimate, the noise energy of each pixel's estimate and
/// the residual's sums.
type ComparisonArrays<'py> = (
    Bound<'py, PyArray3<f32>>,
    Bound<'py, PyArray1<f64>>,
    (f64, f64, f64, f64),
);

/// Compares a rendering of N pixels under K lights with their observations: the direct
/// image `direct` and the inter-reflected light of one or two halves of the camera paths,
/// `halves`, of `counts` paths a pixel each, all (K, N, 3), against pixels `first..first + N`
/// of `observed` (K, T, 3). Returns (the inter-reflected light (K, N, 3), each pixel's
/// Monte-Carlo noise energy (N,) (0 with one half), (Σ|rendered − observed|, Σ|observed|,
/// and Σ|direct + half − observed| for each half)), the sums over the observations whose
/// `keep` (K, T) is true.
#[pyfunction]
#[pyo3(signature = (direct, halves, counts, observed, keep=None, first=0))]
#[allow(clippy::too_many_arguments)]
pub(super) fn compare_rendering<'py>(
    py: Python<'py>,
    direct: PyReadonlyArray3<'_, f32>,
    halves: Vec<PyReadonlyArray3<'_, f32>>,
    counts: Vec<usize>,
    observed: PyReadonlyArray3<'_, f32>,
    keep: Option<PyReadonlyArray2<'_, bool>>,
    first: usize,
) -> PyResult<ComparisonArrays<'py>> {
    let shape = direct.shape().to_vec();
    if shape[2] != 3 {
        return Err(argument_error(
            "direct",
            format!("expected shape (K, N, 3), got {shape:?}"),
        ));
    }
    let (lights, pixels) = (shape[0], shape[1]);
    for half in &halves {
        if half.shape() != shape.as_slice() {
            return Err(argument_error(
                "halves",
                format!("shape {:?} differs from direct {shape:?}", half.shape()),
            ));
        }
    }
    let total = observed.shape()[1];
    if observed.shape()[0] != lights
        || observed.shape()[2] != 3
        || first.checked_add(pixels).is_none_or(|end| end > total)
    {
        return Err(argument_error(
            "observed",
            format!(
                "shape {:?} does not hold {pixels} pixels from {first} for {lights} lights",
                observed.shape()
            ),
        ));
    }
    if let Some(keep) = &keep {
        if keep.shape() != [lights, total] {
            return Err(argument_error(
                "keep",
                format!("shape {:?}, expected {:?}", keep.shape(), [lights, total]),
            ));
        }
    }
    let (direct, observed) = (flat(&direct, "direct")?, flat(&observed, "observed")?);
    let halves = halves
        .iter()
        .map(|half| flat(half, "halves"))
        .collect::<PyResult<Vec<_>>>()?;
    let keep = keep.as_ref().map(|keep| flat(keep, "keep")).transpose()?;
    let comparison = py
        .detach(|| {
            let half_slices: Vec<&[f32]> = halves.iter().map(|h| h.as_ref()).collect();
            let planes = RenderedPlanes {
                direct: &direct,
                halves: &half_slices,
                counts: &counts,
            };
            core_compare(
                &planes,
                &Observed {
                    values: &observed,
                    keep: keep.as_deref(),
                    total,
                    first,
                },
                lights,
                pixels,
            )
        })
        .map_err(to_py)?;
    let indirect = Array::from_shape_vec((lights, pixels, 3), comparison.indirect)
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    let sums = comparison.sums;
    Ok((
        indirect.into_pyarray(py),
        PyArray1::from_vec(py, comparison.noise_energy),
        (
            sums.difference,
            sums.observed,
            sums.half_difference[0],
            sums.half_difference[1],
        ),
    ))
}

/// A filtered inter-reflection estimate and each pixel's noise energy after the filter.
type DenoisedArrays<'py> = (Bound<'py, PyArray3<f32>>, Bound<'py, PyArray1<f64>>);

/// Filters the inter-reflection estimate `indirect` (K, N, 3) at the N pixels of `mask`
/// (H, W) in row-major order, and their noise energy `noise_energy` (N,), guided by the
/// surface: heights `height_px` (H, W) in pixels and `albedo` (H, W, 3) (`rust/denoise.rs`).
#[pyfunction]
pub(super) fn denoise_indirect<'py>(
    py: Python<'py>,
    indirect: PyReadonlyArray3<'_, f32>,
    noise_energy: PyReadonlyArray1<'_, f64>,
    mask: PyReadonlyArray2<'_, bool>,
    height_px: PyReadonlyArray2<'_, f32>,
    albedo: PyReadonlyArray3<'_, f32>,
) -> PyResult<DenoisedArrays<'py>> {
    let (h, w) = (mask.shape()[0], mask.shape()[1]);
    if h == 0 || w == 0 {
        return Err(argument_error(
            "mask",
            format!("shape {:?} has no pixel", mask.shape()),
        ));
    }
    if height_px.shape() != [h, w] {
        return Err(argument_error(
            "height_px",
            format!(
                "shape {:?} differs from mask {:?}",
                height_px.shape(),
                [h, w]
            ),
        ));
    }
    if albedo.shape() != [h, w, 3] {
        return Err(argument_error(
            "albedo",
            format!("shape {:?}, expected {:?}", albedo.shape(), [h, w, 3]),
        ));
    }
    let pixels: Vec<usize> = mask
        .as_array()
        .iter()
        .enumerate()
        .filter_map(|(i, &inside)| inside.then_some(i))
        .collect();
    let shape = indirect.shape().to_vec();
    if shape[1..] != [pixels.len(), 3] {
        return Err(argument_error(
            "indirect",
            format!(
                "shape {shape:?}, expected (K, {}, 3) for the mask's pixels",
                pixels.len()
            ),
        ));
    }
    let (heights, albedo_all) = (flat(&height_px, "height_px")?, flat(&albedo, "albedo")?);
    let height_px: Vec<f32> = pixels.iter().map(|&i| heights[i]).collect();
    let albedo: Vec<Rgb> = pixels
        .iter()
        .map(|&i| {
            [
                albedo_all[3 * i],
                albedo_all[3 * i + 1],
                albedo_all[3 * i + 2],
            ]
        })
        .collect();
    let (indirect, noise_energy) = (
        flat(&indirect, "indirect")?,
        flat(&noise_energy, "noise_energy")?,
    );
    let surface = Surface {
        size: (w, h),
        pixels: &pixels,
        height_px: &height_px,
        albedo: &albedo,
    };
    let denoised = py
        .detach(|| core_denoise(&surface, &indirect, &noise_energy))
        .map_err(to_py)?;
    let filtered = Array::from_shape_vec((shape[0], shape[1], 3), denoised.indirect)
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok((
        filtered.into_pyarray(py),
        PyArray1::from_vec(py, denoised.noise_energy),
    ))
}

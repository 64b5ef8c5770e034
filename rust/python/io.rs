//! Image files: EXR and PNG images, and stacks of them.

use std::path::PathBuf;

use numpy::ndarray::{Array, IxDyn};
use numpy::{IntoPyArray, PyArrayDyn, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::io::{exr_image, png_image, stack, Image};

use super::convert::flat;
use super::errors::{argument_error, renamed, to_py};

fn image_to_array(py: Python<'_>, image: Image) -> PyResult<Bound<'_, PyArrayDyn<f32>>> {
    let shape = if image.channels == 1 {
        vec![image.height, image.width]
    } else {
        vec![image.height, image.width, image.channels]
    };
    let array = Array::from_shape_vec(IxDyn(&shape), image.data)
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(array.into_pyarray(py))
}

/// The (H, W) or (H, W, C) array `array` as an image, refused by `name` unless it has a
/// pixel.
fn array_to_image(array: &PyReadonlyArrayDyn<'_, f32>, name: &str) -> PyResult<Image> {
    let shape = array.shape();
    let (height, width, channels) = match *shape {
        [h, w] => (h, w, 1),
        [h, w, c] => (h, w, c),
        _ => {
            return Err(argument_error(
                name,
                format!("expected an (H, W) or (H, W, C) array, got shape {shape:?}"),
            ))
        }
    };
    if height == 0 || width == 0 {
        return Err(argument_error(
            name,
            format!("shape {shape:?} has no pixel"),
        ));
    }
    let data = flat(array, name)?.into_owned();
    Ok(Image {
        width,
        height,
        channels,
        data,
    })
}

/// Reads an OpenEXR file: float32 (H, W, 3) for R, G, B or (H, W) for a single Y channel.
#[pyfunction]
pub(super) fn read_exr(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyArrayDyn<f32>>> {
    let image = py.detach(|| exr_image::read_exr(&path)).map_err(to_py)?;
    image_to_array(py, image)
}

/// Writes a float32 (H, W) array as a Y channel or (H, W, 3) as R, G, B to OpenEXR,
/// `compression` "zip" (default) or "rle".
#[pyfunction]
#[pyo3(signature = (path, array, compression = "zip"))]
pub(super) fn write_exr(
    py: Python<'_>,
    path: PathBuf,
    array: PyReadonlyArrayDyn<'_, f32>,
    compression: &str,
) -> PyResult<()> {
    let compression = match compression {
        "zip" => exr_image::ExrCompression::Zip,
        "rle" => exr_image::ExrCompression::Rle,
        other => {
            return Err(argument_error(
                "compression",
                format!("{other:?} is not one of \"zip\", \"rle\""),
            ))
        }
    };
    let image = array_to_image(&array, "array")?;
    py.detach(|| exr_image::write_exr_compressed(&path, &image, compression))
        .map_err(|e| to_py(renamed(e, "image", "array")))
}

/// Reads an 8- or 16-bit PNG: (values / (2^bits − 1) as float32, (H, W) or (H, W, 3); bits).
#[pyfunction]
pub(super) fn read_png(
    py: Python<'_>,
    path: PathBuf,
) -> PyResult<(Bound<'_, PyArrayDyn<f32>>, u8)> {
    let (image, bits) = py.detach(|| png_image::read_png(&path)).map_err(to_py)?;
    Ok((image_to_array(py, image)?, bits))
}

/// Writes float32 values in [0, 1], (H, W) gray or (H, W, 3) RGB, as an 8- or 16-bit PNG.
#[pyfunction]
pub(super) fn write_png(
    py: Python<'_>,
    path: PathBuf,
    array: PyReadonlyArrayDyn<'_, f32>,
    bit_depth: u8,
) -> PyResult<()> {
    let image = array_to_image(&array, "array")?;
    py.detach(|| png_image::write_png(&path, &image, bit_depth))
        .map_err(|e| to_py(renamed(e, "image", "array")))
}

/// Reads EXR/PNG images in parallel into one float32 (K, H, W, 3) array.
#[pyfunction]
pub(super) fn read_images(
    py: Python<'_>,
    paths: Vec<PathBuf>,
) -> PyResult<Bound<'_, PyArrayDyn<f32>>> {
    let (width, height, data) = py
        .detach(|| stack::read_image_stack(&paths))
        .map_err(to_py)?;
    let array = Array::from_shape_vec(IxDyn(&[paths.len(), height, width, 3]), data)
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(array.into_pyarray(py))
}

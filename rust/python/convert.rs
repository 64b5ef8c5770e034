//! Conversions of numpy arrays that several bindings share: an array's values in C order,
//! rows of three values, and the lights of two such arrays.

use std::borrow::Cow;

use numpy::PyReadonlyArray2;
use pyo3::prelude::*;

use crate::memory::try_collect;
use crate::scene::{lights_from_rows, Light};

use super::errors::{argument_error, renamed, to_py};

/// The rows of an (N, 3) array, or an error naming `name` for another shape.
pub(super) fn rows_of_3(array: &PyReadonlyArray2<'_, f32>, name: &str) -> PyResult<Vec<[f32; 3]>> {
    let a = array.as_array();
    if a.ncols() != 3 {
        return Err(argument_error(
            name,
            format!("expected shape (N, 3), got {:?}", a.shape()),
        ));
    }
    Ok(a.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect())
}

/// An array's values in C order: borrowed when the array is C-contiguous, copied otherwise
/// (a `MemoryError` naming `name` when the copy cannot be allocated).
pub(super) fn flat<'a, T: numpy::Element + Copy, D: numpy::ndarray::Dimension>(
    array: &'a numpy::PyReadonlyArray<'_, T, D>,
    name: &str,
) -> PyResult<Cow<'a, [T]>> {
    // numpy's own `as_slice` also lends Fortran-ordered data: ndarray's `to_slice` only C order.
    let view = array.as_array();
    match view.to_slice() {
        Some(values) => Ok(Cow::Borrowed(values)),
        None => Ok(Cow::Owned(
            try_collect(
                &format!("a C-ordered copy of {name}"),
                view.len(),
                view.iter().copied(),
            )
            .map_err(to_py)?,
        )),
    }
}

/// The lights of the (K, 3) arrays `directions` and `irradiance` (named `light_directions`
/// and `light_irradiance` in errors).
pub(super) fn lights_from(
    directions: &PyReadonlyArray2<'_, f32>,
    irradiance: &PyReadonlyArray2<'_, f32>,
) -> PyResult<Vec<Light>> {
    let directions = rows_of_3(directions, "light_directions")?;
    let irradiance = rows_of_3(irradiance, "light_irradiance")?;
    lights_from_rows(&directions, &irradiance)
        .map_err(|e| to_py(renamed(e, "irradiance", "light_irradiance")))
}

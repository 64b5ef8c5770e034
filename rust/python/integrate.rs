//! Normal integration: the sparse Cholesky factorisation, and the discontinuity-preserving
//! integration.

use numpy::ndarray::Array2;
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::integrate::bilateral::{
    integrate_bilateral as core_integrate_bilateral, BilateralSettings, Projection,
};
use crate::integrate::sparse_cholesky::SparseCholesky as CoreSparseCholesky;

use super::convert::flat;
use super::errors::{argument_error, to_py};

/// The surface of the float32 (H, W, 3) `normals` at the bool (H, W) `mask`'s pixels that
/// keeps its depth discontinuities (the core's `integrate::bilateral`): float64 (H, W) log
/// depth along the optical axis for a pinhole `intrinsics` (fx, fy, cx, cy), else heights in
/// pixel units, NaN outside the mask; uint8 (H, W) cut edges (1: to the right neighbour, 2:
/// to the pixel below); the re-weighted solves done; whether they converged.
#[pyfunction]
#[pyo3(signature = (normals, mask, intrinsics=None, sharpness=2.0, max_iterations=150, tolerance=1e-4))]
#[allow(clippy::type_complexity)]
pub(super) fn integrate_bilateral<'py>(
    py: Python<'py>,
    normals: PyReadonlyArray3<'_, f32>,
    mask: PyReadonlyArray2<'_, bool>,
    intrinsics: Option<(f64, f64, f64, f64)>,
    sharpness: f64,
    max_iterations: usize,
    tolerance: f64,
) -> PyResult<(
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<u8>>,
    usize,
    bool,
)> {
    let (height, width) = mask.as_array().dim();
    if normals.as_array().dim() != (height, width, 3) {
        return Err(argument_error(
            "normals",
            format!(
                "shape {:?} for a {height}x{width} mask (expected (H, W, 3))",
                normals.as_array().shape()
            ),
        ));
    }
    let normal_values = flat(&normals, "normals")?;
    let mask_values = flat(&mask, "mask")?;
    let projection = match intrinsics {
        Some((fx, fy, cx, cy)) => Projection::Perspective { fx, fy, cx, cy },
        None => Projection::Orthographic,
    };
    let settings = BilateralSettings {
        sharpness,
        max_iterations,
        tolerance,
    };
    let surface = py
        .detach(|| {
            core_integrate_bilateral(
                &normal_values,
                &mask_values,
                height,
                width,
                projection,
                settings,
            )
        })
        .map_err(to_py)?;
    let shaped = |e: numpy::ndarray::ShapeError| PyValueError::new_err(e.to_string());
    let values = Array2::from_shape_vec((height, width), surface.values).map_err(shaped)?;
    let cuts = Array2::from_shape_vec((height, width), surface.cuts).map_err(shaped)?;
    Ok((
        values.into_pyarray(py),
        cuts.into_pyarray(py),
        surface.iterations,
        surface.converged,
    ))
}

/// Non-negative int64 indices as `usize`, or an error naming `name`.
fn indices_of(array: &PyReadonlyArray1<'_, i64>, name: &str) -> PyResult<Vec<usize>> {
    array
        .as_array()
        .iter()
        .map(|&i| {
            usize::try_from(i).map_err(|_| argument_error(name, format!("negative index {i}")))
        })
        .collect()
}

/// The Cholesky factorisation `L Lᵀ` of a sparse symmetric positive definite matrix,
/// factored once (faer), for many solves.
///
/// Parameters: `indptr`, `indices` (int64) and `data` (float64), the CSR (or CSC: the same
/// for a symmetric matrix) arrays of an n×n matrix with sorted indices, of which only the
/// upper triangle is read; `name`, the argument named in errors (an `ArgumentError` when
/// the arrays are malformed or the matrix is not positive definite).
#[pyclass(frozen, module = "irtps._core")]
pub(super) struct SparseCholesky {
    inner: CoreSparseCholesky,
    name: String,
}

#[pymethods]
impl SparseCholesky {
    #[new]
    #[pyo3(signature = (indptr, indices, data, name="matrix"))]
    fn new(
        py: Python<'_>,
        indptr: PyReadonlyArray1<'_, i64>,
        indices: PyReadonlyArray1<'_, i64>,
        data: PyReadonlyArray1<'_, f64>,
        name: &str,
    ) -> PyResult<SparseCholesky> {
        let indptr = indices_of(&indptr, name)?;
        let indices = indices_of(&indices, name)?;
        let data = data.as_array().to_vec();
        let n = indptr.len().saturating_sub(1);
        let inner = py
            .detach(|| CoreSparseCholesky::factor(name, n, &indptr, &indices, &data))
            .map_err(to_py)?;
        Ok(SparseCholesky {
            inner,
            name: name.to_string(),
        })
    }

    /// The matrix's dimension n.
    #[getter]
    fn dim(&self) -> usize {
        self.inner.dim()
    }

    /// Number of float64 values stored in the factor L.
    #[getter]
    fn factor_len(&self) -> usize {
        self.inner.factor_len()
    }

    /// The solution x of `A x = b` for a float64 (n,) right-hand side `b`.
    fn solve<'py>(
        &self,
        py: Python<'py>,
        b: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let mut x = b.as_array().to_vec();
        if x.len() != self.inner.dim() {
            return Err(argument_error(
                "b",
                format!(
                    "length {} for the {}x{} matrix {}",
                    x.len(),
                    self.inner.dim(),
                    self.inner.dim(),
                    self.name
                ),
            ));
        }
        py.detach(|| self.inner.solve_in_place("b", &mut x, 1))
            .map_err(to_py)?;
        Ok(PyArray1::from_vec(py, x))
    }
}

//! Normal integration's sparse Cholesky factorisation.

use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::prelude::*;

use crate::integrate::sparse_cholesky::SparseCholesky as CoreSparseCholesky;

use super::errors::{argument_error, to_py};

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

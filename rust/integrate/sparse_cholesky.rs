//! Sparse Cholesky factorisation, factored once and solved many times (faer).
//!
//! Normal integration solves the same symmetric positive definite system (a weighted
//! graph Laplacian on the mask's pixels) once per IRT-PS pass, with only the right-hand
//! side changing. [`SparseCholesky`] does the symbolic analysis (fill-reducing ordering,
//! elimination tree) and the numeric `L Lᵀ` factorisation once; each solve is then two
//! triangular sweeps.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{LltError, LltRegularization};
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::FaerError;
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};

use crate::error::{Error, Result};
use crate::memory::{check_available, dense_kernel_workspace_bytes, try_vec};

/// Refuses, with [`Error::Memory`], a factorisation or solve on a thread that might not have
/// the address space for the workspace faer's dense kernels allocate, without a way to
/// fail, on the thread's first matrix product (64 MiB on a machine with 32 MiB of L3).
/// Checked before every call, so that a thread that already holds it is refused slightly
/// early rather than a new one aborting the process.
fn check_dense_kernel_workspace(name: &str) -> Result<()> {
    check_available(
        &format!("{name}: the workspace of the dense matrix kernels"),
        dense_kernel_workspace_bytes(),
    )
}

/// How [`SparseCholesky::factor_with`] factors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Factorisation {
    /// Simplicial or supernodal, as faer's estimate of the flops prefers.
    Auto,
    /// Supernodal whatever that estimate: for a factor refactored many times
    /// ([`SparseCholesky::refactor`], an iteratively re-weighted solve), whose dense
    /// supernode kernels make each numeric factorisation faster than the simplicial one on
    /// a grid's Laplacian.
    Supernodal,
}

/// The `L Lᵀ` factorisation of a sparse symmetric positive definite matrix.
#[derive(Debug)]
pub struct SparseCholesky {
    symbolic: SymbolicCholesky<usize>,
    values: Vec<f64>,
}

impl SparseCholesky {
    /// Factors the n×n matrix given in compressed sparse column form (`indptr` of length
    /// n + 1, `indices` strictly increasing within each column, `data`).
    ///
    /// Only the upper triangle (row ≤ column) is read: the matrix is taken to be
    /// symmetric. A symmetric matrix's CSR arrays are also its CSC arrays, so either may
    /// be given. `name` is the input named in errors: malformed arrays, or a matrix that
    /// is not positive definite.
    pub fn factor(
        name: &str,
        n: usize,
        indptr: &[usize],
        indices: &[usize],
        data: &[f64],
    ) -> Result<Self> {
        Self::factor_with(name, n, indptr, indices, data, Factorisation::Auto)
    }

    /// [`SparseCholesky::factor`] with the method `method`.
    pub fn factor_with(
        name: &str,
        n: usize,
        indptr: &[usize],
        indices: &[usize],
        data: &[f64],
        method: Factorisation,
    ) -> Result<Self> {
        check_compressed(name, n, indptr, indices, data)?;
        let structure = SymbolicSparseColMatRef::new_checked(n, n, indptr, None, indices);
        let matrix = SparseColMatRef::new(structure, data);
        let symbolic = factorize_symbolic_cholesky(
            structure,
            Side::Upper,
            Default::default(),
            CholeskySymbolicParams {
                supernodal_flop_ratio_threshold: match method {
                    Factorisation::Auto => SupernodalThreshold::AUTO,
                    Factorisation::Supernodal => SupernodalThreshold::FORCE_SUPERNODAL,
                },
                ..Default::default()
            },
        )
        .map_err(|e| match e {
            FaerError::OutOfMemory => Error::memory_of_unknown_size(format!(
                "{name}: the symbolic Cholesky analysis of a {n}x{n} matrix"
            )),
            e => Error::input(name, format!("symbolic Cholesky analysis failed: {e:?}")),
        })?;
        let values = try_vec(
            &format!("{name}: a Cholesky factor of {} values", symbolic.len_val()),
            symbolic.len_val(),
            0.0,
        )?;
        let mut factor = SparseCholesky { symbolic, values };
        factor.factor_numeric(name, matrix)?;
        Ok(factor)
    }

    /// Factors again a matrix of the same sparsity pattern as the one this factor was made
    /// from (the same `indptr` and `indices`) with new values `data`, reusing the symbolic
    /// analysis: the re-weighted systems of an iteratively re-weighted least-squares
    /// solve.
    pub fn refactor(
        &mut self,
        name: &str,
        indptr: &[usize],
        indices: &[usize],
        data: &[f64],
    ) -> Result<()> {
        let n = self.dim();
        check_compressed(name, n, indptr, indices, data)?;
        let structure = SymbolicSparseColMatRef::new_checked(n, n, indptr, None, indices);
        self.factor_numeric(name, SparseColMatRef::new(structure, data))
    }

    /// The numeric `L Lᵀ` factorisation of `matrix` into `self.values`.
    fn factor_numeric(
        &mut self,
        name: &str,
        matrix: SparseColMatRef<'_, usize, f64>,
    ) -> Result<()> {
        // On the calling thread only: each thread that runs a dense kernel takes a workspace
        // of its own (see `check_dense_kernel_workspace`), and the supernodes of an
        // integration's Laplacian are too small for threads to pay.
        let par = Par::Seq;
        let symbolic = &self.symbolic;
        let workspace = symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default());
        let mut scratch = MemBuffer::try_new(workspace).map_err(|_| {
            Error::memory(
                format!("{name}: the Cholesky factorisation's workspace"),
                workspace.size_bytes(),
            )
        })?;
        check_dense_kernel_workspace(name)?;
        symbolic
            .factorize_numeric_llt(&mut self.values, matrix, Side::Upper, LltRegularization::default(), par, MemStack::new(&mut scratch), Default::default())
            .map_err(|LltError::NonPositivePivot { index }| {
                Error::input(name, format!("matrix is not positive definite (non-positive pivot at elimination step {index})"))
            })?;
        Ok(())
    }

    /// The matrix's dimension n.
    pub fn dim(&self) -> usize {
        self.symbolic.nrows()
    }

    /// Number of values stored in the factor `L` (its nonzeros, with the supernodes'
    /// explicit zeros): 8 bytes each.
    pub fn factor_len(&self) -> usize {
        self.values.len()
    }

    /// Solves `A x = b` in place for `columns` right-hand sides stored one after the other
    /// in `rhs` (column-major n × columns); `name` is the input named in errors.
    pub fn solve_in_place(&self, name: &str, rhs: &mut [f64], columns: usize) -> Result<()> {
        let n = self.dim();
        if rhs.len() != n * columns {
            return Err(Error::input(
                name,
                format!(
                    "{} values for {columns} right-hand sides of length {n}",
                    rhs.len()
                ),
            ));
        }
        let par = Par::Seq;
        if let Some(value) = rhs.iter().find(|v| !v.is_finite()) {
            return Err(Error::input(name, format!("non-finite value {value}")));
        }
        let workspace = self.symbolic.solve_in_place_scratch::<f64>(columns, par);
        let mut scratch = MemBuffer::try_new(workspace).map_err(|_| {
            Error::memory(
                format!("{name}: the solve's workspace"),
                workspace.size_bytes(),
            )
        })?;
        check_dense_kernel_workspace(name)?;
        let target = MatMut::from_column_major_slice_mut(rhs, n, columns);
        LltRef::new(&self.symbolic, &self.values).solve_in_place_with_conj(
            Conj::No,
            target,
            par,
            MemStack::new(&mut scratch),
        );
        Ok(())
    }
}

/// Checks compressed sparse column arrays, so that faer's own checks (which panic) pass.
fn check_compressed(
    name: &str,
    n: usize,
    indptr: &[usize],
    indices: &[usize],
    data: &[f64],
) -> Result<()> {
    if n == 0 {
        return Err(Error::input(name, "a 0x0 matrix has nothing to factor"));
    }
    if indptr.len() != n + 1 {
        return Err(Error::input(
            name,
            format!(
                "indptr has {} entries for {n} columns (expected {})",
                indptr.len(),
                n + 1
            ),
        ));
    }
    if indptr[0] != 0 || indptr[n] != indices.len() {
        return Err(Error::input(
            name,
            format!(
                "indptr must run from 0 to the {} stored entries",
                indices.len()
            ),
        ));
    }
    if data.len() != indices.len() {
        return Err(Error::input(
            name,
            format!("{} values for {} indices", data.len(), indices.len()),
        ));
    }
    if let Some(value) = data.iter().find(|v| !v.is_finite()) {
        return Err(Error::input(name, format!("non-finite value {value}")));
    }
    for (column, bounds) in indptr.windows(2).enumerate() {
        if bounds[0] > bounds[1] || bounds[1] > indices.len() {
            return Err(Error::input(
                name,
                format!("indptr decreases at column {column}"),
            ));
        }
        let rows = &indices[bounds[0]..bounds[1]];
        if rows.windows(2).any(|pair| pair[0] >= pair[1])
            || rows.last().is_some_and(|&row| row >= n)
        {
            return Err(Error::input(
                name,
                format!("column {column}: row indices must be increasing and below {n}"),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// CSC arrays of the n×n tridiagonal matrix with `diagonal` and −1 off the diagonal.
    fn tridiagonal(n: usize, diagonal: f64) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
        let (mut indptr, mut indices, mut data) = (vec![0], Vec::new(), Vec::new());
        for j in 0..n {
            for i in j.saturating_sub(1)..(j + 2).min(n) {
                indices.push(i);
                data.push(if i == j { diagonal } else { -1.0 });
            }
            indptr.push(indices.len());
        }
        (indptr, indices, data)
    }

    fn multiply(indptr: &[usize], indices: &[usize], data: &[f64], x: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; x.len()];
        for j in 0..x.len() {
            for k in indptr[j]..indptr[j + 1] {
                y[indices[k]] += data[k] * x[j];
            }
        }
        y
    }

    #[test]
    fn solves_an_spd_system_for_several_right_hand_sides() {
        let n = 200;
        let (indptr, indices, data) = tridiagonal(n, 2.5);
        let factor = SparseCholesky::factor("laplacian", n, &indptr, &indices, &data).unwrap();
        assert_eq!(factor.dim(), n);
        assert!(factor.factor_len() >= 2 * n - 1);
        let x1: Vec<f64> = (0..n).map(|i| (i as f64 * 0.1).sin()).collect();
        let x2: Vec<f64> = (0..n).map(|i| 1.0 + i as f64 / n as f64).collect();
        let mut rhs = multiply(&indptr, &indices, &data, &x1);
        rhs.extend(multiply(&indptr, &indices, &data, &x2));
        factor.solve_in_place("b", &mut rhs, 2).unwrap();
        for (got, want) in rhs.iter().zip(x1.iter().chain(&x2)) {
            assert!((got - want).abs() < 1e-12, "{got} != {want}");
        }
    }

    #[test]
    fn the_supernodal_factor_solves_and_refactors_as_the_default_one() {
        let n = 300;
        let (indptr, indices, data) = tridiagonal(n, 2.5);
        let x: Vec<f64> = (0..n).map(|i| (i as f64 * 0.07).cos()).collect();
        let mut default = SparseCholesky::factor("laplacian", n, &indptr, &indices, &data).unwrap();
        let mut supernodal = SparseCholesky::factor_with(
            "laplacian",
            n,
            &indptr,
            &indices,
            &data,
            Factorisation::Supernodal,
        )
        .unwrap();
        let heavier: Vec<f64> = data
            .iter()
            .map(|v| if *v > 0.0 { 4.0 } else { *v })
            .collect();
        default
            .refactor("laplacian", &indptr, &indices, &heavier)
            .unwrap();
        supernodal
            .refactor("laplacian", &indptr, &indices, &heavier)
            .unwrap();
        let b = multiply(&indptr, &indices, &heavier, &x);
        for factor in [&default, &supernodal] {
            let mut solved = b.clone();
            factor.solve_in_place("b", &mut solved, 1).unwrap();
            for (got, want) in solved.iter().zip(&x) {
                assert!((got - want).abs() < 1e-12, "{got} != {want}");
            }
        }
    }

    #[test]
    fn an_indefinite_matrix_is_an_error_naming_the_input() {
        let (indptr, indices, data) = tridiagonal(10, 1.0);
        let err =
            SparseCholesky::factor("normal_matrix", 10, &indptr, &indices, &data).unwrap_err();
        assert!(
            err.to_string()
                .starts_with("normal_matrix: matrix is not positive definite"),
            "{err}"
        );
    }

    #[test]
    fn malformed_arrays_are_errors_not_panics() {
        let (indptr, indices, data) = tridiagonal(4, 3.0);
        assert!(SparseCholesky::factor("a", 5, &indptr, &indices, &data)
            .unwrap_err()
            .to_string()
            .contains("indptr"));
        let mut unsorted = indices.clone();
        unsorted.swap(0, 1);
        assert!(SparseCholesky::factor("a", 4, &indptr, &unsorted, &data)
            .unwrap_err()
            .to_string()
            .contains("increasing"));
        let mut outside = indices.clone();
        *outside.last_mut().unwrap() = 9;
        assert!(SparseCholesky::factor("a", 4, &indptr, &outside, &data).is_err());
        assert!(SparseCholesky::factor("a", 4, &indptr, &indices, &data[1..]).is_err());
        let factor = SparseCholesky::factor("a", 4, &indptr, &indices, &data).unwrap();
        assert!(factor
            .solve_in_place("b", &mut [1.0; 3], 1)
            .unwrap_err()
            .to_string()
            .starts_with("b:"));
    }
}

//! Normal integration's linear algebra: the sparse Cholesky factorisation that the
//! least-squares integrators of `irtps.geometry.integrate` solve with
//! ([`sparse_cholesky`]).

pub mod bilateral;
pub mod sparse_cholesky;

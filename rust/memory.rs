//! Fallible allocation: a large buffer that cannot be had is an [`Error::Memory`] naming
//! what it was for and its size, never an abort of the process.
//!
//! Buffers that the core allocates itself go through [`try_vec`] and [`try_collect`].
//! Memory that third-party crates allocate (the BVH of obvhs, faer's symbolic analysis,
//! the EXR decoder's planes) cannot fail gracefully; [`check_available`] reserves an
//! estimate of it up front instead.

use std::mem::size_of;

use crate::error::{Error, Result};

/// A vector of `len` copies of `value`, or [`Error::Memory`] for `what`.
pub fn try_vec<T: Clone>(what: &str, len: usize, value: T) -> Result<Vec<T>> {
    let mut values = try_with_capacity(what, len)?;
    values.resize(len, value);
    Ok(values)
}

/// An empty vector with room for `len` values, or [`Error::Memory`] for `what`.
pub fn try_with_capacity<T>(what: &str, len: usize) -> Result<Vec<T>> {
    let mut values = Vec::new();
    values.try_reserve_exact(len).map_err(|_| Error::memory(what, len.saturating_mul(size_of::<T>())))?;
    Ok(values)
}

/// The values of `values`, at most `len` of them, in a vector allocated for `len`, or
/// [`Error::Memory`] for `what`.
pub fn try_collect<T>(what: &str, len: usize, values: impl IntoIterator<Item = T>) -> Result<Vec<T>> {
    let mut out = try_with_capacity(what, len)?;
    out.extend(values.into_iter().take(len));
    Ok(out)
}

/// Refuses, with [`Error::Memory`] for `what`, when `bytes` bytes cannot be allocated now:
/// for memory that a third-party crate will allocate without a way to fail. The bytes are
/// reserved (address space, not touched) and given back at once.
pub fn check_available(what: &str, bytes: usize) -> Result<()> {
    try_with_capacity::<u8>(what, bytes).map(drop)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_impossible_allocation_is_an_error_naming_it() {
        let err = try_vec("the test's buffer", usize::MAX / 8, 0u64).unwrap_err();
        assert_eq!(err, Error::memory("the test's buffer", usize::MAX / 8 * 8));
        assert_eq!(err.to_string(), format!("the test's buffer: could not allocate {} bytes", usize::MAX / 8 * 8));
        assert!(check_available("the BVH", usize::MAX).is_err());
    }

    #[test]
    fn possible_allocations_hold_their_values() {
        assert_eq!(try_vec("four", 4, 7u8).unwrap(), vec![7; 4]);
        assert_eq!(try_collect("three", 3, 0..10).unwrap(), vec![0, 1, 2]);
        check_available("a kilobyte", 1000).unwrap();
    }
}

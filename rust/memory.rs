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
    values
        .try_reserve_exact(len)
        .map_err(|_| Error::memory(what, len.saturating_mul(size_of::<T>())))?;
    Ok(values)
}

/// The values of `values`, at most `len` of them, in a vector allocated for `len`, or
/// [`Error::Memory`] for `what`.
pub fn try_collect<T>(
    what: &str,
    len: usize,
    values: impl IntoIterator<Item = T>,
) -> Result<Vec<T>> {
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

/// The bytes of address space that faer's dense matrix kernels (private-gemm-x86) take, on
/// a thread's first matrix product, for a workspace that lives as long as the thread and
/// cannot fail gracefully: twice the last-level (L3) cache, as that crate sizes it from
/// `/sys/devices/system/cpu` (64 MiB on a machine with 32 MiB of L3). Elsewhere, or where
/// the caches cannot be read, the crate's defaults (2 MiB of L3), raised like its own
/// figures to at least 4 times the L2 cache and 16 times the L1 cache.
pub fn dense_kernel_workspace_bytes() -> usize {
    static BYTES: std::sync::OnceLock<usize> = std::sync::OnceLock::new();
    *BYTES.get_or_init(|| {
        let [l1, l2, l3] = cache_sizes().unwrap_or([0; 3]);
        let l1 = l1.max(32 << 10);
        let l2 = l2.max(256 << 10).max(4 * l1);
        let l3 = l3.max(2 << 20).max(4 * l2);
        2 * l3.next_multiple_of(4096)
    })
}

/// The largest data (or unified) cache of levels 1, 2 and 3 that Linux reports, in bytes.
fn cache_sizes() -> Option<[usize; 3]> {
    let mut sizes = [0usize; 3];
    for cpu in std::fs::read_dir("/sys/devices/system/cpu").ok()?.flatten() {
        if !cpu.file_name().to_string_lossy().starts_with("cpu") {
            continue;
        }
        let Ok(indices) = std::fs::read_dir(cpu.path().join("cache")) else {
            continue;
        };
        for index in indices.flatten() {
            let read = |name: &str| {
                std::fs::read_to_string(index.path().join(name))
                    .map(|s| s.trim().to_string())
                    .unwrap_or_default()
            };
            if !matches!(read("type").as_str(), "Data" | "Unified") {
                continue;
            }
            let Ok(level @ 1..=3) = read("level").parse::<usize>() else {
                continue;
            };
            let size = read("size");
            let (digits, unit) = match size.strip_suffix('K') {
                Some(digits) => (digits, 1 << 10),
                None => match size.strip_suffix('M') {
                    Some(digits) => (digits, 1 << 20),
                    None => match size.strip_suffix('G') {
                        Some(digits) => (digits, 1 << 30),
                        None => (size.as_str(), 1),
                    },
                },
            };
            if let Ok(count) = digits.parse::<usize>() {
                sizes[level - 1] = sizes[level - 1].max(count.saturating_mul(unit));
            }
        }
    }
    Some(sizes)
}

/// Bytes from which [`with_huge_pages`] asks for huge pages: below, a buffer is read from a
/// few pages that the TLB holds anyway.
const HUGE_PAGES_FROM: usize = 8 << 20;

/// An empty vector with room for `len` values, or [`Error::Memory`] for `what`, whose memory
/// the kernel is asked to back with huge pages when it is large (Linux's transparent huge
/// pages, 2 MiB a page, through `madvise`): a buffer read at random places, such as a
/// scanned environment's BVH and shading records, then misses the TLB far less, and its page
/// walks (costlier still in a virtual machine) go. Only a hint, given before the memory is
/// first written: where the kernel declines, or on other systems, nothing changes.
pub fn with_huge_pages<T>(what: &str, len: usize) -> Result<Vec<T>> {
    let values = try_with_capacity(what, len)?;
    advise_huge_pages(&values);
    Ok(values)
}

/// Gives the hint of [`with_huge_pages`] for the spare capacity of `values` when it is
/// large, before any of it is written (written pages stay as they are).
pub fn advise_huge_pages<T>(values: &Vec<T>) {
    let bytes = values.capacity().saturating_mul(size_of::<T>());
    if bytes >= HUGE_PAGES_FROM {
        madvise_huge_pages(values.as_ptr().cast::<u8>(), bytes);
    }
}

/// `values` moved onto memory given [`with_huge_pages`]' hint, when they are as large as it
/// asks for (else as they are).
pub fn on_huge_pages<T: Copy>(what: &str, values: Vec<T>) -> Result<Vec<T>> {
    if values.len().saturating_mul(size_of::<T>()) < HUGE_PAGES_FROM {
        return Ok(values);
    }
    let mut moved = with_huge_pages(what, values.len())?;
    moved.extend_from_slice(&values);
    Ok(moved)
}

/// `madvise(MADV_HUGEPAGE)` over the whole 2 MiB pages inside `bytes` bytes from `start`.
#[cfg(target_os = "linux")]
fn madvise_huge_pages(start: *const u8, bytes: usize) {
    const HUGE_PAGE: usize = 2 << 20;
    let first = (start as usize).next_multiple_of(HUGE_PAGE);
    let end = (start as usize + bytes) / HUGE_PAGE * HUGE_PAGE;
    if end > first {
        // SAFETY: the range lies inside one live allocation; the advice changes how its
        // pages are backed, never their contents. A refusal (an old kernel, huge pages
        // disabled) is ignored: the memory stays as it was.
        unsafe {
            libc::madvise(first as *mut libc::c_void, end - first, libc::MADV_HUGEPAGE);
        }
    }
}

#[cfg(not(target_os = "linux"))]
fn madvise_huge_pages(_start: *const u8, _bytes: usize) {}

/// Asks the processor to start loading the cache line holding the start of `value`, so that
/// a read of it a little later does not wait as long for memory. Only a hint: nothing is
/// read or checked, and it does nothing on processors other than x86-64.
#[inline(always)]
pub fn prefetch<T>(value: &T) {
    // SAFETY: SSE is part of every x86-64 processor, and a prefetch reads nothing (any
    // address may be hinted).
    #[cfg(target_arch = "x86_64")]
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
            (value as *const T).cast::<i8>(),
        );
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = value;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_impossible_allocation_is_an_error_naming_it() {
        let err = try_vec("the test's buffer", usize::MAX / 8, 0u64).unwrap_err();
        assert_eq!(err, Error::memory("the test's buffer", usize::MAX / 8 * 8));
        assert_eq!(
            err.to_string(),
            format!(
                "the test's buffer: could not allocate {} bytes",
                usize::MAX / 8 * 8
            )
        );
        assert!(check_available("the BVH", usize::MAX).is_err());
    }

    #[test]
    fn possible_allocations_hold_their_values() {
        assert_eq!(try_vec("four", 4, 7u8).unwrap(), vec![7; 4]);
        assert_eq!(try_collect("three", 3, 0..10).unwrap(), vec![0, 1, 2]);
        check_available("a kilobyte", 1000).unwrap();
    }

    #[test]
    fn the_dense_kernels_workspace_is_at_least_the_crates_default() {
        let bytes = dense_kernel_workspace_bytes();
        assert!(
            bytes >= 2 * (2 << 20) && bytes.is_multiple_of(4096),
            "{bytes}"
        );
        assert!(bytes <= 1 << 40, "{bytes}");
    }
}

//! Values side by side in the widest vector registers the CPU has, for code that applies
//! the same arithmetic to several pixels ([`crate::ps::tukey`]) or to several lights of one
//! pixel ([`crate::ps::lobe`]): eight in 256-bit registers, sixteen in 512-bit ones.
//!
//! Such code is generic over an [`Isa`] of `W` lanes and is compiled once per instruction
//! set: with [`Portable`] (the `wide` crate: two SSE2 halves on x86-64, whatever the target
//! has elsewhere), and, inside functions compiled for them, on x86-64 CPUs that have AVX2
//! and FMA with [`Avx2`] (one 256-bit register) and on those that also have AVX-512 with
//! [`Avx512`] (sixteen lanes in one 512-bit register). Each lane computes the same bits in
//! every one: the same operations in the same order, each multiply-add rounded once (on a
//! target without FMA instructions [`Portable`] does it in software, correctly but slowly).
//! Comparisons return masks, all bits set where true.
//!
//! This module holds the traits and [`Portable`]; `x86` the AVX2 and AVX-512 registers.

use std::ops::{Add, AddAssign, BitAnd, BitXor, Div, Mul, Sub, SubAssign};

/// `W` `f32` in registers.
pub trait Floats<const W: usize>:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Mul<f32, Output = Self>
    + Div<Output = Self>
    + BitAnd<Output = Self>
    + BitXor<Output = Self>
    + AddAssign
{
    /// The integers of the same instruction set.
    type Ints: Ints<W, Floats = Self>;
    /// Mask of `self < other` (false where either is a NaN).
    fn simd_lt(self, other: Self) -> Self;
    /// Mask of `self > other`.
    fn simd_gt(self, other: Self) -> Self;
    /// `self × a + b`, rounded once.
    fn mul_add(self, a: Self, b: Self) -> Self;
    /// `self` where `self > other`, else `other` (so `other` where either is a NaN, as
    /// `f32::max` does for a NaN `self`).
    fn max(self, other: Self) -> Self;
    /// The bits of each value.
    fn to_bits(self) -> Self::Ints;
    fn to_array(self) -> [f32; W];
}

/// `W` `i32` in registers (additions and subtractions wrap).
pub trait Ints<const W: usize>:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + SubAssign
    + BitAnd<Output = Self>
    + BitXor<Output = Self>
{
    /// The floats of the same instruction set.
    type Floats: Floats<W, Ints = Self>;
    /// Mask of `self < other`.
    fn simd_lt(self, other: Self) -> Self;
    /// Mask of `self == other`.
    fn simd_eq(self, other: Self) -> Self;
    /// Each value shifted right by one bit, its sign kept (halved, rounded down).
    fn halved(self) -> Self;
    fn min(self, other: Self) -> Self;
    fn max(self, other: Self) -> Self;
    /// The floats whose bits these are.
    fn to_floats(self) -> Self::Floats;
    fn to_array(self) -> [i32; W];
}

/// An instruction set of `W` lanes: the way into its registers.
pub trait Isa<const W: usize>: Copy {
    type F: Floats<W, Ints = Self::I>;
    type I: Ints<W, Floats = Self::F>;
    fn floats(self, values: [f32; W]) -> Self::F;
    fn ints(self, values: [i32; W]) -> Self::I;

    #[inline(always)]
    fn splat(self, value: f32) -> Self::F {
        self.floats([value; W])
    }

    #[inline(always)]
    fn splat_int(self, value: i32) -> Self::I {
        self.ints([value; W])
    }
}

/// What every target has, through the `wide` crate.
#[derive(Debug, Clone, Copy)]
pub struct Portable;

impl Isa<8> for Portable {
    type F = wide::f32x8;
    type I = wide::i32x8;

    #[inline(always)]
    fn floats(self, values: [f32; 8]) -> wide::f32x8 {
        wide::f32x8::new(values)
    }

    #[inline(always)]
    fn ints(self, values: [i32; 8]) -> wide::i32x8 {
        wide::i32x8::new(values)
    }
}

impl Floats<8> for wide::f32x8 {
    type Ints = wide::i32x8;

    #[inline(always)]
    fn mul_add(self, a: Self, b: Self) -> Self {
        // `wide` rounds once only where the target has fused multiply-adds.
        if cfg!(any(
            target_feature = "fma",
            all(target_arch = "aarch64", target_feature = "neon")
        )) {
            wide::f32x8::mul_add(self, a, b)
        } else {
            let (x, y, z) = (self.to_array(), a.to_array(), b.to_array());
            let mut fused = [0.0; 8];
            for (i, value) in fused.iter_mut().enumerate() {
                *value = x[i].mul_add(y[i], z[i]);
            }
            wide::f32x8::new(fused)
        }
    }

    #[inline(always)]
    fn max(self, other: Self) -> Self {
        // By the comparison, not `wide`'s `fast_max`: NEON's maximum returns a NaN.
        other ^ (self.simd_gt(other) & (self ^ other))
    }

    #[inline(always)]
    fn simd_lt(self, other: Self) -> Self {
        wide::f32x8::simd_lt(self, other)
    }

    #[inline(always)]
    fn simd_gt(self, other: Self) -> Self {
        wide::f32x8::simd_gt(self, other)
    }

    #[inline(always)]
    fn to_bits(self) -> wide::i32x8 {
        wide::bytemuck::cast(self)
    }

    #[inline(always)]
    fn to_array(self) -> [f32; 8] {
        wide::f32x8::to_array(self)
    }
}

impl Ints<8> for wide::i32x8 {
    type Floats = wide::f32x8;

    #[inline(always)]
    fn simd_lt(self, other: Self) -> Self {
        wide::i32x8::simd_lt(self, other)
    }

    #[inline(always)]
    fn simd_eq(self, other: Self) -> Self {
        wide::i32x8::simd_eq(self, other)
    }

    #[inline(always)]
    fn halved(self) -> Self {
        self >> 1u32
    }

    #[inline(always)]
    fn min(self, other: Self) -> Self {
        wide::i32x8::min(self, other)
    }

    #[inline(always)]
    fn max(self, other: Self) -> Self {
        wide::i32x8::max(self, other)
    }

    #[inline(always)]
    fn to_floats(self) -> wide::f32x8 {
        wide::bytemuck::cast(self)
    }

    #[inline(always)]
    fn to_array(self) -> [i32; 8] {
        wide::i32x8::to_array(self)
    }
}

#[cfg(target_arch = "x86_64")]
pub use x86::{Avx2, Avx512};

#[cfg(target_arch = "x86_64")]
mod x86;

#[cfg(test)]
mod tests;

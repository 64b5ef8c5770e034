//! Eight values side by side in the widest vector registers the CPU has, for code that
//! applies the same arithmetic to eight pixels ([`crate::tukey`]).
//!
//! Such code is generic over an [`Isa`] and is compiled once per instruction set: with
//! [`Portable`] (the `wide` crate: two SSE2 halves on x86-64, whatever the target has
//! elsewhere) and, on x86-64 CPUs that have AVX2 and FMA, with [`Avx2`] (one 256-bit
//! register) inside a function compiled for them. Both compute the same bits: the same
//! operations in the same order, each multiply-add rounded once (on a target without FMA
//! instructions [`Portable`] does it in software, correctly but slowly). Comparisons return
//! masks, all bits set where true.

use std::ops::{Add, AddAssign, BitAnd, BitXor, Mul, Sub, SubAssign};

/// Values side by side.
pub const WIDTH: usize = 8;

/// Eight `f32` in registers.
pub trait Floats: Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Mul<f32, Output = Self> + BitAnd<Output = Self> + BitXor<Output = Self> + AddAssign {
    /// The integers of the same instruction set.
    type Ints: Ints<Floats = Self>;
    /// Mask of `self < other` (false where either is a NaN).
    fn simd_lt(self, other: Self) -> Self;
    /// Mask of `self > other`.
    fn simd_gt(self, other: Self) -> Self;
    /// `self × a + b`, rounded once.
    fn mul_add(self, a: Self, b: Self) -> Self;
    /// The bits of each value.
    fn to_bits(self) -> Self::Ints;
    fn to_array(self) -> [f32; WIDTH];
}

/// Eight `i32` in registers (additions and subtractions wrap).
pub trait Ints: Copy + Add<Output = Self> + Sub<Output = Self> + SubAssign + BitAnd<Output = Self> + BitXor<Output = Self> {
    /// The floats of the same instruction set.
    type Floats: Floats<Ints = Self>;
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
    fn to_array(self) -> [i32; WIDTH];
}

/// An instruction set: the way into its registers.
pub trait Isa: Copy {
    type F: Floats<Ints = Self::I>;
    type I: Ints<Floats = Self::F>;
    fn floats(self, values: [f32; WIDTH]) -> Self::F;
    fn ints(self, values: [i32; WIDTH]) -> Self::I;

    #[inline(always)]
    fn splat(self, value: f32) -> Self::F {
        self.floats([value; WIDTH])
    }

    #[inline(always)]
    fn splat_int(self, value: i32) -> Self::I {
        self.ints([value; WIDTH])
    }
}

/// What every target has, through the `wide` crate.
#[derive(Debug, Clone, Copy)]
pub struct Portable;

impl Isa for Portable {
    type F = wide::f32x8;
    type I = wide::i32x8;

    #[inline(always)]
    fn floats(self, values: [f32; WIDTH]) -> wide::f32x8 {
        wide::f32x8::new(values)
    }

    #[inline(always)]
    fn ints(self, values: [i32; WIDTH]) -> wide::i32x8 {
        wide::i32x8::new(values)
    }
}

impl Floats for wide::f32x8 {
    type Ints = wide::i32x8;

    #[inline(always)]
    fn mul_add(self, a: Self, b: Self) -> Self {
        // `wide` rounds once only where the target has fused multiply-adds.
        if cfg!(any(target_feature = "fma", all(target_arch = "aarch64", target_feature = "neon"))) {
            wide::f32x8::mul_add(self, a, b)
        } else {
            let (x, y, z) = (self.to_array(), a.to_array(), b.to_array());
            let mut fused = [0.0; WIDTH];
            for (i, value) in fused.iter_mut().enumerate() {
                *value = x[i].mul_add(y[i], z[i]);
            }
            wide::f32x8::new(fused)
        }
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
    fn to_array(self) -> [f32; WIDTH] {
        wide::f32x8::to_array(self)
    }
}

impl Ints for wide::i32x8 {
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
    fn to_array(self) -> [i32; WIDTH] {
        wide::i32x8::to_array(self)
    }
}

#[cfg(target_arch = "x86_64")]
pub use avx2::Avx2;

#[cfg(target_arch = "x86_64")]
mod avx2 {
    //! AVX2 registers. A value of these types exists only once [`Avx2::detect`] has found
    //! AVX2 and FMA on this CPU, which is what makes their intrinsics safe to call.

    use std::arch::x86_64::*;
    use std::ops::{Add, AddAssign, BitAnd, BitXor, Mul, Sub, SubAssign};

    use super::{Floats, Ints, Isa, WIDTH};

    /// Proof that this CPU has AVX2 and FMA.
    #[derive(Debug, Clone, Copy)]
    pub struct Avx2(());

    impl Avx2 {
        /// `Some` when this CPU has AVX2 and FMA.
        pub fn detect() -> Option<Avx2> {
            (std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")).then_some(Avx2(()))
        }
    }

    /// Eight `f32` in an AVX register.
    #[derive(Debug, Clone, Copy)]
    pub struct F(__m256);

    /// Eight `i32` in an AVX register.
    #[derive(Debug, Clone, Copy)]
    pub struct I(__m256i);

    impl Isa for Avx2 {
        type F = F;
        type I = I;

        #[inline(always)]
        fn floats(self, values: [f32; WIDTH]) -> F {
            // SAFETY: `self` proves AVX2; the pointer reads 8 floats.
            F(unsafe { _mm256_loadu_ps(values.as_ptr()) })
        }

        #[inline(always)]
        fn ints(self, values: [i32; WIDTH]) -> I {
            // SAFETY: as above, 8 integers.
            I(unsafe { _mm256_loadu_si256(values.as_ptr().cast()) })
        }
    }

    /// `$body` over AVX2 intrinsics: sound because a value of these types exists only on a
    /// CPU with AVX2 and FMA (module documentation).
    macro_rules! avx {
        ($body:expr) => {
            // SAFETY: see the macro's documentation.
            unsafe { $body }
        };
    }

    /// `impl $trait for $type` by the intrinsic `$intrinsic`.
    macro_rules! binary {
        ($type:ident, $trait:ident, $method:ident, $intrinsic:ident) => {
            impl $trait for $type {
                type Output = $type;
                #[inline(always)]
                fn $method(self, other: $type) -> $type {
                    $type(avx!($intrinsic(self.0, other.0)))
                }
            }
        };
    }

    binary!(F, Add, add, _mm256_add_ps);
    binary!(F, Sub, sub, _mm256_sub_ps);
    binary!(F, Mul, mul, _mm256_mul_ps);
    binary!(F, BitAnd, bitand, _mm256_and_ps);
    binary!(F, BitXor, bitxor, _mm256_xor_ps);
    binary!(I, Add, add, _mm256_add_epi32);
    binary!(I, Sub, sub, _mm256_sub_epi32);
    binary!(I, BitAnd, bitand, _mm256_and_si256);
    binary!(I, BitXor, bitxor, _mm256_xor_si256);

    impl AddAssign for F {
        #[inline(always)]
        fn add_assign(&mut self, other: F) {
            *self = *self + other;
        }
    }

    impl SubAssign for I {
        #[inline(always)]
        fn sub_assign(&mut self, other: I) {
            *self = *self - other;
        }
    }

    impl Mul<f32> for F {
        type Output = F;
        #[inline(always)]
        fn mul(self, other: f32) -> F {
            F(avx!(_mm256_mul_ps(self.0, _mm256_set1_ps(other))))
        }
    }

    impl Floats for F {
        type Ints = I;

        #[inline(always)]
        fn mul_add(self, a: F, b: F) -> F {
            F(avx!(_mm256_fmadd_ps(self.0, a.0, b.0)))
        }

        #[inline(always)]
        fn simd_lt(self, other: F) -> F {
            F(avx!(_mm256_cmp_ps::<_CMP_LT_OQ>(self.0, other.0)))
        }

        #[inline(always)]
        fn simd_gt(self, other: F) -> F {
            F(avx!(_mm256_cmp_ps::<_CMP_GT_OQ>(self.0, other.0)))
        }

        #[inline(always)]
        fn to_bits(self) -> I {
            I(avx!(_mm256_castps_si256(self.0)))
        }

        #[inline(always)]
        fn to_array(self) -> [f32; WIDTH] {
            let mut values = [0.0; WIDTH];
            avx!(_mm256_storeu_ps(values.as_mut_ptr(), self.0));
            values
        }
    }

    impl Ints for I {
        type Floats = F;

        #[inline(always)]
        fn simd_lt(self, other: I) -> I {
            I(avx!(_mm256_cmpgt_epi32(other.0, self.0)))
        }

        #[inline(always)]
        fn simd_eq(self, other: I) -> I {
            I(avx!(_mm256_cmpeq_epi32(self.0, other.0)))
        }

        #[inline(always)]
        fn halved(self) -> I {
            I(avx!(_mm256_srai_epi32::<1>(self.0)))
        }

        #[inline(always)]
        fn min(self, other: I) -> I {
            I(avx!(_mm256_min_epi32(self.0, other.0)))
        }

        #[inline(always)]
        fn max(self, other: I) -> I {
            I(avx!(_mm256_max_epi32(self.0, other.0)))
        }

        #[inline(always)]
        fn to_floats(self) -> F {
            F(avx!(_mm256_castsi256_ps(self.0)))
        }

        #[inline(always)]
        fn to_array(self) -> [i32; WIDTH] {
            let mut values = [0; WIDTH];
            avx!(_mm256_storeu_si256(values.as_mut_ptr().cast(), self.0));
            values
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every operation of `isa` on values that cover signs, zeros and the largest integer.
    fn check<V: Isa>(isa: V) {
        let a = isa.floats([1.0, -2.0, 3.0, -4.0, 0.5, 6.0, -0.0, 8.0]);
        let b = isa.splat(2.0);
        assert_eq!((a + b).to_array(), [3.0, 0.0, 5.0, -2.0, 2.5, 8.0, 2.0, 10.0]);
        assert_eq!((a - b).to_array()[3], -6.0);
        assert_eq!((a * b).to_array()[5], 12.0);
        assert_eq!((a * 0.5).to_array()[7], 4.0);
        let mut sum = a;
        sum += b;
        assert_eq!(sum.to_array()[0], 3.0);
        let near_one = isa.splat(1.0 + f32::EPSILON * 2048.0);
        let fused = near_one.mul_add(near_one, isa.splat(-(1.0 + f32::EPSILON * 4096.0)));
        assert_eq!(fused.to_array(), [f32::EPSILON / 2.0; WIDTH], "a multiply-add rounds once (twice would give 0)");
        let nan = isa.splat_int(i32::MAX).to_floats();
        for mask in [nan.simd_lt(a), nan.simd_gt(a), a.simd_lt(nan), (nan * 0.0).simd_lt(a)] {
            assert_eq!(mask.to_bits().to_array(), [0; WIDTH], "no comparison with a NaN holds");
        }
        assert_eq!(a.simd_lt(b).to_bits().to_array(), [-1, -1, 0, -1, -1, 0, -1, 0]);
        assert_eq!((a & a.simd_gt(b)).to_array(), [0.0, 0.0, 3.0, 0.0, 0.0, 6.0, 0.0, 8.0]);
        assert_eq!((a ^ isa.splat(-0.0)).to_array(), [-1.0, 2.0, -3.0, 4.0, -0.5, -6.0, 0.0, -8.0]);
        assert_eq!(a.to_bits().to_floats().to_array(), a.to_array());
        let i = isa.ints([5, -1, i32::MAX, 0, 7, 7, -8, 2]);
        let j = isa.splat_int(2);
        assert_eq!(i.simd_lt(j).to_array(), [0, -1, 0, -1, 0, 0, -1, 0]);
        assert_eq!(((i + j) - j).to_array()[2], i32::MAX, "integers wrap");
        assert_eq!((i + j).to_array()[2], i32::MIN + 1, "integers wrap");
        assert_eq!(i.simd_eq(j).to_array(), [0, 0, 0, 0, 0, 0, 0, -1]);
        assert_eq!(i.halved().to_array(), [2, -1, i32::MAX / 2, 0, 3, 3, -4, 1]);
        assert_eq!(i.min(j).to_array(), [2, -1, 2, 0, 2, 2, -8, 2]);
        assert_eq!(i.max(j).to_array(), [5, 2, i32::MAX, 2, 7, 7, 2, 2]);
        let mut count = isa.splat_int(0);
        count -= i.simd_lt(j);
        assert_eq!(count.to_array(), [0, 1, 0, 1, 0, 0, 1, 0]);
        assert_eq!((i + j).to_array()[6], -6);
        assert_eq!((i & j).to_array()[2], 2);
        assert_eq!((i ^ j).to_array(), [7, -3, i32::MAX ^ 2, 2, 5, 5, -6, 0]);
    }

    #[test]
    fn portable_lanes_act_on_each_value_and_compare_to_masks() {
        check(Portable);
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx2_lanes_act_on_each_value_and_compare_to_masks() {
        if let Some(avx2) = Avx2::detect() {
            check(avx2);
        }
    }
}

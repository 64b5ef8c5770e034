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
mod x86 {
    //! AVX2 and AVX-512 registers. A value of these types exists only once [`Avx2::detect`]
    //! or [`Avx512::detect`] has found the instructions it needs on this CPU, which is what
    //! makes their intrinsics safe to call.

    use std::arch::x86_64::*;
    use std::ops::{Add, AddAssign, BitAnd, BitXor, Div, Mul, Sub, SubAssign};

    use super::{Floats, Ints, Isa};

    /// Proof that this CPU has AVX2 and FMA.
    #[derive(Debug, Clone, Copy)]
    pub struct Avx2(());

    impl Avx2 {
        /// `Some` when this CPU has AVX2 and FMA.
        pub fn detect() -> Option<Avx2> {
            (is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma"))
                .then_some(Avx2(()))
        }
    }

    /// Proof that this CPU has AVX-512 (foundation), AVX2 and FMA.
    #[derive(Debug, Clone, Copy)]
    pub struct Avx512(());

    impl Avx512 {
        /// `Some` when this CPU has AVX-512F, AVX2 and FMA.
        pub fn detect() -> Option<Avx512> {
            (is_x86_feature_detected!("avx512f") && Avx2::detect().is_some()).then_some(Avx512(()))
        }

        /// The AVX2 registers, which this CPU has too.
        pub fn avx2(self) -> Avx2 {
            Avx2(())
        }
    }

    /// `$body` over AVX2 or AVX-512 intrinsics: sound because a value of these types exists
    /// only on a CPU with the instructions they use (module documentation).
    macro_rules! simd {
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
                    $type(simd!($intrinsic(self.0, other.0)))
                }
            }
        };
    }

    /// `+=` and `-=` by `+` and `-`.
    macro_rules! assign {
        ($floats:ident, $ints:ident) => {
            impl AddAssign for $floats {
                #[inline(always)]
                fn add_assign(&mut self, other: $floats) {
                    *self = *self + other;
                }
            }

            impl SubAssign for $ints {
                #[inline(always)]
                fn sub_assign(&mut self, other: $ints) {
                    *self = *self - other;
                }
            }
        };
    }

    /// Eight `f32` in an AVX register.
    #[derive(Debug, Clone, Copy)]
    pub struct F8(__m256);

    /// Eight `i32` in an AVX register.
    #[derive(Debug, Clone, Copy)]
    pub struct I8(__m256i);

    impl Isa<8> for Avx2 {
        type F = F8;
        type I = I8;

        #[inline(always)]
        fn floats(self, values: [f32; 8]) -> F8 {
            // SAFETY: `self` proves AVX2; the pointer reads 8 floats.
            F8(unsafe { _mm256_loadu_ps(values.as_ptr()) })
        }

        #[inline(always)]
        fn ints(self, values: [i32; 8]) -> I8 {
            // SAFETY: as above, 8 integers.
            I8(unsafe { _mm256_loadu_si256(values.as_ptr().cast()) })
        }
    }

    binary!(F8, Add, add, _mm256_add_ps);
    binary!(F8, Sub, sub, _mm256_sub_ps);
    binary!(F8, Mul, mul, _mm256_mul_ps);
    binary!(F8, Div, div, _mm256_div_ps);
    binary!(F8, BitAnd, bitand, _mm256_and_ps);
    binary!(F8, BitXor, bitxor, _mm256_xor_ps);
    binary!(I8, Add, add, _mm256_add_epi32);
    binary!(I8, Sub, sub, _mm256_sub_epi32);
    binary!(I8, BitAnd, bitand, _mm256_and_si256);
    binary!(I8, BitXor, bitxor, _mm256_xor_si256);
    assign!(F8, I8);

    impl Mul<f32> for F8 {
        type Output = F8;
        #[inline(always)]
        fn mul(self, other: f32) -> F8 {
            F8(simd!(_mm256_mul_ps(self.0, _mm256_set1_ps(other))))
        }
    }

    impl Floats<8> for F8 {
        type Ints = I8;

        #[inline(always)]
        fn mul_add(self, a: F8, b: F8) -> F8 {
            F8(simd!(_mm256_fmadd_ps(self.0, a.0, b.0)))
        }

        #[inline(always)]
        fn max(self, other: F8) -> F8 {
            F8(simd!(_mm256_max_ps(self.0, other.0)))
        }

        #[inline(always)]
        fn simd_lt(self, other: F8) -> F8 {
            F8(simd!(_mm256_cmp_ps::<_CMP_LT_OQ>(self.0, other.0)))
        }

        #[inline(always)]
        fn simd_gt(self, other: F8) -> F8 {
            F8(simd!(_mm256_cmp_ps::<_CMP_GT_OQ>(self.0, other.0)))
        }

        #[inline(always)]
        fn to_bits(self) -> I8 {
            I8(simd!(_mm256_castps_si256(self.0)))
        }

        #[inline(always)]
        fn to_array(self) -> [f32; 8] {
            let mut values = [0.0; 8];
            simd!(_mm256_storeu_ps(values.as_mut_ptr(), self.0));
            values
        }
    }

    impl Ints<8> for I8 {
        type Floats = F8;

        #[inline(always)]
        fn simd_lt(self, other: I8) -> I8 {
            I8(simd!(_mm256_cmpgt_epi32(other.0, self.0)))
        }

        #[inline(always)]
        fn simd_eq(self, other: I8) -> I8 {
            I8(simd!(_mm256_cmpeq_epi32(self.0, other.0)))
        }

        #[inline(always)]
        fn halved(self) -> I8 {
            I8(simd!(_mm256_srai_epi32::<1>(self.0)))
        }

        #[inline(always)]
        fn min(self, other: I8) -> I8 {
            I8(simd!(_mm256_min_epi32(self.0, other.0)))
        }

        #[inline(always)]
        fn max(self, other: I8) -> I8 {
            I8(simd!(_mm256_max_epi32(self.0, other.0)))
        }

        #[inline(always)]
        fn to_floats(self) -> F8 {
            F8(simd!(_mm256_castsi256_ps(self.0)))
        }

        #[inline(always)]
        fn to_array(self) -> [i32; 8] {
            let mut values = [0; 8];
            simd!(_mm256_storeu_si256(values.as_mut_ptr().cast(), self.0));
            values
        }
    }

    /// Sixteen `f32` in an AVX-512 register.
    #[derive(Debug, Clone, Copy)]
    pub struct F16(__m512);

    /// Sixteen `i32` in an AVX-512 register.
    #[derive(Debug, Clone, Copy)]
    pub struct I16(__m512i);

    impl Isa<16> for Avx512 {
        type F = F16;
        type I = I16;

        #[inline(always)]
        fn floats(self, values: [f32; 16]) -> F16 {
            // SAFETY: `self` proves AVX-512F; the pointer reads 16 floats.
            F16(unsafe { _mm512_loadu_ps(values.as_ptr()) })
        }

        #[inline(always)]
        fn ints(self, values: [i32; 16]) -> I16 {
            // SAFETY: as above, 16 integers.
            I16(unsafe { _mm512_loadu_si512(values.as_ptr().cast()) })
        }
    }

    /// All bits set in the lanes of `mask`, none elsewhere.
    #[inline(always)]
    fn widened(mask: __mmask16) -> __m512i {
        simd!(_mm512_maskz_mov_epi32(mask, _mm512_set1_epi32(-1)))
    }

    binary!(F16, Add, add, _mm512_add_ps);
    binary!(F16, Sub, sub, _mm512_sub_ps);
    binary!(F16, Mul, mul, _mm512_mul_ps);
    binary!(F16, Div, div, _mm512_div_ps);
    binary!(I16, Add, add, _mm512_add_epi32);
    binary!(I16, Sub, sub, _mm512_sub_epi32);
    binary!(I16, BitAnd, bitand, _mm512_and_si512);
    binary!(I16, BitXor, bitxor, _mm512_xor_si512);
    assign!(F16, I16);

    impl BitAnd for F16 {
        type Output = F16;
        #[inline(always)]
        fn bitand(self, other: F16) -> F16 {
            // AVX-512F has the bitwise operations for integers only.
            F16(simd!(_mm512_castsi512_ps(_mm512_and_si512(
                _mm512_castps_si512(self.0),
                _mm512_castps_si512(other.0)
            ))))
        }
    }

    impl BitXor for F16 {
        type Output = F16;
        #[inline(always)]
        fn bitxor(self, other: F16) -> F16 {
            F16(simd!(_mm512_castsi512_ps(_mm512_xor_si512(
                _mm512_castps_si512(self.0),
                _mm512_castps_si512(other.0)
            ))))
        }
    }

    impl Mul<f32> for F16 {
        type Output = F16;
        #[inline(always)]
        fn mul(self, other: f32) -> F16 {
            F16(simd!(_mm512_mul_ps(self.0, _mm512_set1_ps(other))))
        }
    }

    impl Floats<16> for F16 {
        type Ints = I16;

        #[inline(always)]
        fn mul_add(self, a: F16, b: F16) -> F16 {
            F16(simd!(_mm512_fmadd_ps(self.0, a.0, b.0)))
        }

        #[inline(always)]
        fn max(self, other: F16) -> F16 {
            F16(simd!(_mm512_max_ps(self.0, other.0)))
        }

        #[inline(always)]
        fn simd_lt(self, other: F16) -> F16 {
            F16(simd!(_mm512_castsi512_ps(widened(_mm512_cmp_ps_mask::<
                _CMP_LT_OQ,
            >(
                self.0, other.0
            )))))
        }

        #[inline(always)]
        fn simd_gt(self, other: F16) -> F16 {
            F16(simd!(_mm512_castsi512_ps(widened(_mm512_cmp_ps_mask::<
                _CMP_GT_OQ,
            >(
                self.0, other.0
            )))))
        }

        #[inline(always)]
        fn to_bits(self) -> I16 {
            I16(simd!(_mm512_castps_si512(self.0)))
        }

        #[inline(always)]
        fn to_array(self) -> [f32; 16] {
            let mut values = [0.0; 16];
            simd!(_mm512_storeu_ps(values.as_mut_ptr(), self.0));
            values
        }
    }

    impl Ints<16> for I16 {
        type Floats = F16;

        #[inline(always)]
        fn simd_lt(self, other: I16) -> I16 {
            I16(widened(simd!(_mm512_cmplt_epi32_mask(self.0, other.0))))
        }

        #[inline(always)]
        fn simd_eq(self, other: I16) -> I16 {
            I16(widened(simd!(_mm512_cmpeq_epi32_mask(self.0, other.0))))
        }

        #[inline(always)]
        fn halved(self) -> I16 {
            I16(simd!(_mm512_srai_epi32::<1>(self.0)))
        }

        #[inline(always)]
        fn min(self, other: I16) -> I16 {
            I16(simd!(_mm512_min_epi32(self.0, other.0)))
        }

        #[inline(always)]
        fn max(self, other: I16) -> I16 {
            I16(simd!(_mm512_max_epi32(self.0, other.0)))
        }

        #[inline(always)]
        fn to_floats(self) -> F16 {
            F16(simd!(_mm512_castsi512_ps(self.0)))
        }

        #[inline(always)]
        fn to_array(self) -> [i32; 16] {
            let mut values = [0; 16];
            simd!(_mm512_storeu_si512(values.as_mut_ptr().cast(), self.0));
            values
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `pattern` repeated over `W` lanes.
    fn lanes<T: Copy, const W: usize>(pattern: [T; 8]) -> [T; W] {
        std::array::from_fn(|lane| pattern[lane % 8])
    }

    /// Every operation of `isa` on values that cover signs, zeros and the largest integer.
    fn check<V: Isa<W>, const W: usize>(isa: V) {
        let a = isa.floats(lanes([1.0, -2.0, 3.0, -4.0, 0.5, 6.0, -0.0, 8.0]));
        let b = isa.splat(2.0);
        assert_eq!(
            (a + b).to_array(),
            lanes([3.0, 0.0, 5.0, -2.0, 2.5, 8.0, 2.0, 10.0])
        );
        assert_eq!((a - b).to_array()[3], -6.0);
        assert_eq!((a * b).to_array()[5], 12.0);
        assert_eq!((a * 0.5).to_array()[W - 1], 4.0);
        assert_eq!(
            (a / b).to_array(),
            lanes([0.5, -1.0, 1.5, -2.0, 0.25, 3.0, -0.0, 4.0])
        );
        assert_eq!(
            a.max(isa.splat(0.0)).to_array(),
            lanes([1.0, 0.0, 3.0, 0.0, 0.5, 6.0, 0.0, 8.0])
        );
        let mut sum = a;
        sum += b;
        assert_eq!(sum.to_array()[0], 3.0);
        let near_one = isa.splat(1.0 + f32::EPSILON * 2048.0);
        let fused = near_one.mul_add(near_one, isa.splat(-(1.0 + f32::EPSILON * 4096.0)));
        assert_eq!(
            fused.to_array(),
            [f32::EPSILON / 2.0; W],
            "a multiply-add rounds once (twice would give 0)"
        );
        let nan = isa.splat_int(i32::MAX).to_floats();
        for mask in [
            nan.simd_lt(a),
            nan.simd_gt(a),
            a.simd_lt(nan),
            (nan * 0.0).simd_lt(a),
        ] {
            assert_eq!(
                mask.to_bits().to_array(),
                [0; W],
                "no comparison with a NaN holds"
            );
        }
        assert_eq!(
            nan.max(b).to_array(),
            [2.0; W],
            "the maximum of a NaN and a number is the number"
        );
        assert!(
            b.max(nan).to_array().iter().all(|v| v.is_nan()),
            "a NaN second is kept"
        );
        assert_eq!(
            a.simd_lt(b).to_bits().to_array(),
            lanes([-1, -1, 0, -1, -1, 0, -1, 0])
        );
        assert_eq!(
            (a & a.simd_gt(b)).to_array(),
            lanes([0.0, 0.0, 3.0, 0.0, 0.0, 6.0, 0.0, 8.0])
        );
        assert_eq!(
            (a ^ isa.splat(-0.0)).to_array(),
            lanes([-1.0, 2.0, -3.0, 4.0, -0.5, -6.0, 0.0, -8.0])
        );
        assert_eq!(a.to_bits().to_floats().to_array(), a.to_array());
        let i = isa.ints(lanes([5, -1, i32::MAX, 0, 7, 7, -8, 2]));
        let j = isa.splat_int(2);
        assert_eq!(i.simd_lt(j).to_array(), lanes([0, -1, 0, -1, 0, 0, -1, 0]));
        assert_eq!(((i + j) - j).to_array()[2], i32::MAX, "integers wrap");
        assert_eq!((i + j).to_array()[2], i32::MIN + 1, "integers wrap");
        assert_eq!(i.simd_eq(j).to_array(), lanes([0, 0, 0, 0, 0, 0, 0, -1]));
        assert_eq!(
            i.halved().to_array(),
            lanes([2, -1, i32::MAX / 2, 0, 3, 3, -4, 1])
        );
        assert_eq!(i.min(j).to_array(), lanes([2, -1, 2, 0, 2, 2, -8, 2]));
        assert_eq!(i.max(j).to_array(), lanes([5, 2, i32::MAX, 2, 7, 7, 2, 2]));
        let mut count = isa.splat_int(0);
        count -= i.simd_lt(j);
        assert_eq!(count.to_array(), lanes([0, 1, 0, 1, 0, 0, 1, 0]));
        assert_eq!((i + j).to_array()[6], -6);
        assert_eq!((i & j).to_array()[2], 2);
        assert_eq!(
            (i ^ j).to_array(),
            lanes([7, -3, i32::MAX ^ 2, 2, 5, 5, -6, 0])
        );
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

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx512_lanes_act_on_each_value_and_compare_to_masks() {
        if let Some(avx512) = Avx512::detect() {
            check(avx512);
        }
    }
}

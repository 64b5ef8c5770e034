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
        (is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")).then_some(Avx2(()))
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

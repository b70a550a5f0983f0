//! [`SimdF32`] on `__m512` (16 lanes): AVX-512F alone. Masks are `k` registers (`__mmask16`), selects mask
//! blends; the bit operations go through the integer domain (`vpandd`, `vpord`: the f32 forms need
//! AVX-512DQ).

use super::SimdF32;
use std::arch::x86_64::*;

/// `a` and `b` combined by the integer operation `op`, as f32.
macro_rules! bits {
    ($op:ident) => {
        |a: __m512, b: __m512| {
            _mm512_castsi512_ps($op(_mm512_castps_si512(a), _mm512_castps_si512(b)))
        }
    };
}

impl SimdF32 for __m512 {
    const LANES: usize = 16;
    type Mask = __mmask16;
    type I32 = __m512i;

    ops! { () -> Self = (); zero: _mm512_setzero_ps }
    ops! { (v: f32) -> Self = (v); splat: _mm512_set1_ps }
    ops! { (p: *const f32) -> Self = (p); load: _mm512_loadu_ps }
    ops! { (p: *mut f32, v: Self) -> () = (p, v); store: _mm512_storeu_ps }
    ops! { (v: Self) -> Self = (v); sqrt: _mm512_sqrt_ps, abs: _mm512_abs_ps }
    ops! { (a: Self, b: Self) -> Self = (a, b);
    add: _mm512_add_ps, sub: _mm512_sub_ps, mul: _mm512_mul_ps, div: _mm512_div_ps,
    max: _mm512_max_ps, and: bits!(_mm512_and_si512), or: bits!(_mm512_or_si512) }
    ops! { (a: Self, b: Self) -> Self::Mask = (a, b);
    lt: _mm512_cmp_ps_mask::<_CMP_LT_OQ>, gt: _mm512_cmp_ps_mask::<_CMP_GT_OQ>,
    ge: _mm512_cmp_ps_mask::<_CMP_GE_OQ>, eq: _mm512_cmp_ps_mask::<_CMP_EQ_OQ>,
    ord: _mm512_cmp_ps_mask::<_CMP_ORD_Q>, unord: _mm512_cmp_ps_mask::<_CMP_UNORD_Q> }
    ops! { (v: Self) -> Self::I32 = (v); to_i32: _mm512_cvttps_epi32 }
    ops! { (i: Self::I32) -> Self = (i); from_i32: _mm512_cvtepi32_ps }
    ops! { (m: Self::Mask, v: Self) -> Self = (m, v); keep: _mm512_maskz_mov_ps }

    #[inline(always)]
    unsafe fn load_splat(p: *const f32) -> Self {
        // SAFETY: the caller guarantees AVX-512F and a valid `p`.
        unsafe { _mm512_set1_ps(*p) }
    }
    #[inline(always)]
    unsafe fn load_pairs(p: *const f32) -> (Self, Self) {
        // SAFETY: the caller guarantees AVX-512F and 32 readable values at `p`. Indices 0..16 pick from `a`,
        // 16..32 from `b`.
        unsafe {
            let (a, b) = (_mm512_loadu_ps(p), _mm512_loadu_ps(p.add(16)));
            let even = _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30);
            let odd = _mm512_setr_epi32(1, 3, 5, 7, 9, 11, 13, 15, 17, 19, 21, 23, 25, 27, 29, 31);
            (
                _mm512_permutex2var_ps(a, even, b),
                _mm512_permutex2var_ps(a, odd, b),
            )
        }
    }
    #[inline(always)]
    unsafe fn sign_mask(v: Self) -> Self::Mask {
        // SAFETY: the caller guarantees AVX-512F.
        unsafe { _mm512_test_epi32_mask(_mm512_castps_si512(v), _mm512_set1_epi32(i32::MIN)) }
    }
    #[inline(always)]
    unsafe fn mask_or(a: Self::Mask, b: Self::Mask) -> Self::Mask {
        a | b
    }
    #[inline(always)]
    unsafe fn mask_any(m: Self::Mask) -> bool {
        m != 0
    }
    #[inline(always)]
    unsafe fn select(m: Self::Mask, b: Self, a: Self) -> Self {
        // SAFETY: the caller guarantees AVX-512F.
        unsafe { _mm512_mask_blend_ps(m, a, b) }
    }
    #[inline(always)]
    unsafe fn clear(m: Self::Mask, v: Self) -> Self {
        // SAFETY: the caller guarantees AVX-512F.
        unsafe { _mm512_maskz_mov_ps(!m, v) }
    }
    #[inline(always)]
    unsafe fn inc_where(i: Self::I32, m: Self::Mask) -> Self::I32 {
        // SAFETY: the caller guarantees AVX-512F.
        unsafe { _mm512_mask_add_epi32(i, m, i, _mm512_set1_epi32(1)) }
    }
}

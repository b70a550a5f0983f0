//! [`SimdF32`] on `__m256` (8 lanes): AVX2 + FMA. Masks are registers of all-ones / all-zeros lanes, selects
//! `blendv` (which reads only the sign bit, so [`SimdF32::sign_mask`] is the value itself).

use super::SimdF32;
use std::arch::x86_64::*;

impl SimdF32 for __m256 {
    const LANES: usize = 8;
    type Mask = __m256;
    type I32 = __m256i;

    ops! { () -> Self = (); zero: _mm256_setzero_ps }
    ops! { (v: f32) -> Self = (v); splat: _mm256_set1_ps }
    ops! { (p: *const f32) -> Self = (p); load: _mm256_loadu_ps }
    ops! { (p: *mut f32, v: Self) -> () = (p, v); store: _mm256_storeu_ps }
    ops! { (v: Self) -> Self = (v); sqrt: _mm256_sqrt_ps }
    ops! { (a: Self, b: Self) -> Self = (a, b);
    add: _mm256_add_ps, sub: _mm256_sub_ps, mul: _mm256_mul_ps, div: _mm256_div_ps,
    max: _mm256_max_ps, and: _mm256_and_ps, or: _mm256_or_ps }
    ops! { (a: Self, b: Self) -> Self::Mask = (a, b);
    lt: _mm256_cmp_ps::<_CMP_LT_OQ>, gt: _mm256_cmp_ps::<_CMP_GT_OQ>, ge: _mm256_cmp_ps::<_CMP_GE_OQ>,
    eq: _mm256_cmp_ps::<_CMP_EQ_OQ>, ord: _mm256_cmp_ps::<_CMP_ORD_Q>, unord: _mm256_cmp_ps::<_CMP_UNORD_Q> }
    ops! { (a: Self::Mask, b: Self::Mask) -> Self::Mask = (a, b); mask_or: _mm256_or_ps }
    ops! { (v: Self) -> Self::I32 = (v); to_i32: _mm256_cvttps_epi32 }
    ops! { (i: Self::I32) -> Self = (i); from_i32: _mm256_cvtepi32_ps }

    #[inline(always)]
    unsafe fn load_splat(p: *const f32) -> Self {
        // SAFETY: the caller guarantees AVX and a valid `p`.
        unsafe { _mm256_broadcast_ss(&*p) }
    }
    #[inline(always)]
    unsafe fn load_pairs(p: *const f32) -> (Self, Self) {
        // SAFETY: the caller guarantees AVX2 and 16 readable values at `p`.
        unsafe {
            let (a, b) = (_mm256_loadu_ps(p), _mm256_loadu_ps(p.add(8)));
            // [r0 r1 r4 r5 | r2 r3 r6 r7] → pixel order by 64-bit lanes 0, 2, 1, 3.
            let re = _mm256_shuffle_ps::<0x88>(a, b);
            let im = _mm256_shuffle_ps::<0xdd>(a, b);
            let re = _mm256_castpd_ps(_mm256_permute4x64_pd::<0xd8>(_mm256_castps_pd(re)));
            let im = _mm256_castpd_ps(_mm256_permute4x64_pd::<0xd8>(_mm256_castps_pd(im)));
            (re, im)
        }
    }
    #[inline(always)]
    unsafe fn abs(v: Self) -> Self {
        // SAFETY: the caller guarantees AVX.
        unsafe { _mm256_andnot_ps(_mm256_set1_ps(-0.0), v) }
    }
    #[inline(always)]
    unsafe fn sign_mask(v: Self) -> Self::Mask {
        v
    }
    #[inline(always)]
    unsafe fn mask_any(m: Self::Mask) -> bool {
        // SAFETY: the caller guarantees AVX.
        unsafe { _mm256_movemask_ps(m) != 0 }
    }
    #[inline(always)]
    unsafe fn select(m: Self::Mask, b: Self, a: Self) -> Self {
        // SAFETY: the caller guarantees AVX.
        unsafe { _mm256_blendv_ps(a, b, m) }
    }
    #[inline(always)]
    unsafe fn keep(m: Self::Mask, v: Self) -> Self {
        // SAFETY: the caller guarantees AVX.
        unsafe { _mm256_and_ps(v, m) }
    }
    #[inline(always)]
    unsafe fn clear(m: Self::Mask, v: Self) -> Self {
        // SAFETY: the caller guarantees AVX.
        unsafe { _mm256_andnot_ps(m, v) }
    }
    #[inline(always)]
    unsafe fn inc_where(i: Self::I32, m: Self::Mask) -> Self::I32 {
        // SAFETY: the caller guarantees AVX2. A set lane of `m` is −1 as an i32.
        unsafe { _mm256_sub_epi32(i, _mm256_castps_si256(m)) }
    }
}

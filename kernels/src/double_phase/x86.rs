//! The double phase rows' x86-64 entry points: [`DpmSimd`] on `__m256` (AVX2, eight pixels per step) and
//! `__m512` (AVX-512F, sixteen), and the `#[target_feature]` functions of [`super::PATHS`], each the generic
//! body of [`super::simd`] on its register. The compiler's own vectorisation of the portable body stayed at
//! xmm width with spills (about 4–6 ns per pixel per pass); written out, a pass costs about a nanosecond or
//! two with AVX2, and AVX-512 runs 1.8× the AVX2 rows on Zen 5 (`docs/BENCHMARKS.md`).

use std::arch::x86_64::*;

use super::body::{EncodeParams, LANES};
use super::simd::{self, DpmSimd};

impl DpmSimd for __m256 {
    /// Pixels 0–3 and 4–7 of each step.
    type Sum = (__m256d, __m256d);

    #[inline(always)]
    unsafe fn sum_zero() -> Self::Sum {
        // SAFETY: the caller guarantees AVX.
        unsafe { (_mm256_setzero_pd(), _mm256_setzero_pd()) }
    }
    #[inline(always)]
    unsafe fn sum_add(sum: &mut Self::Sum, p: Self) {
        // SAFETY: the caller guarantees AVX.
        unsafe {
            sum.0 = _mm256_add_pd(sum.0, _mm256_cvtps_pd(_mm256_castps256_ps128(p)));
            sum.1 = _mm256_add_pd(sum.1, _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(p)));
        }
    }
    #[inline(always)]
    unsafe fn sum_store(sum: Self::Sum, out: &mut [f64; 8]) {
        // SAFETY: the caller guarantees AVX; 4 + 4 values of `out`.
        unsafe {
            _mm256_storeu_pd(out.as_mut_ptr(), sum.0);
            _mm256_storeu_pd(out.as_mut_ptr().add(4), sum.1);
        }
    }
    #[inline(always)]
    unsafe fn sign_pattern(sign: &[f32; LANES]) -> Self {
        // SAFETY: the caller guarantees AVX; 8 values.
        unsafe { _mm256_loadu_ps(sign.as_ptr()) }
    }
    #[inline(always)]
    unsafe fn store_codes(c: __m256i, p: *mut u8) {
        // SAFETY: the caller guarantees AVX2 and 8 writable bytes at `p`.
        unsafe {
            let c = _mm256_and_si256(c, _mm256_set1_epi32(255));
            let w = _mm256_packus_epi32(c, c); // [c0..c3 c0..c3 | c4..c7 c4..c7] as u16
            let b = _mm256_packus_epi16(w, w); // bytes c0..c3 repeated | c4..c7 repeated
            let lo = _mm256_castsi256_si128(b);
            let hi = _mm256_extracti128_si256::<1>(b);
            _mm_storel_epi64(p.cast(), _mm_unpacklo_epi32(lo, hi));
        }
    }
}

impl DpmSimd for __m512 {
    /// Eight f64 lanes: a step's pixels 0–7 added first, then 8–15.
    type Sum = __m512d;

    #[inline(always)]
    unsafe fn sum_zero() -> Self::Sum {
        // SAFETY: the caller guarantees AVX-512F.
        unsafe { _mm512_setzero_pd() }
    }
    #[inline(always)]
    unsafe fn sum_add(sum: &mut Self::Sum, p: Self) {
        // SAFETY: the caller guarantees AVX-512F.
        unsafe {
            let bits = _mm512_castps_si512(p);
            let lo = _mm256_castsi256_ps(_mm512_castsi512_si256(bits));
            let hi = _mm256_castsi256_ps(_mm512_extracti64x4_epi64::<1>(bits));
            *sum = _mm512_add_pd(*sum, _mm512_cvtps_pd(lo));
            *sum = _mm512_add_pd(*sum, _mm512_cvtps_pd(hi));
        }
    }
    #[inline(always)]
    unsafe fn sum_store(sum: Self::Sum, out: &mut [f64; 8]) {
        // SAFETY: the caller guarantees AVX-512F; 8 values of `out`.
        unsafe { _mm512_storeu_pd(out.as_mut_ptr(), sum) }
    }
    #[inline(always)]
    unsafe fn sign_pattern(sign: &[f32; LANES]) -> Self {
        // The sign pattern of eight pixels, twice (LANES is even: pixel parity repeats).
        let mut pattern = [0.0f32; 2 * LANES];
        pattern[..LANES].copy_from_slice(sign);
        pattern[LANES..].copy_from_slice(sign);
        // SAFETY: the caller guarantees AVX-512F; 16 values.
        unsafe { _mm512_loadu_ps(pattern.as_ptr()) }
    }
    #[inline(always)]
    unsafe fn store_codes(c: __m512i, p: *mut u8) {
        // SAFETY: the caller guarantees AVX-512F and 16 writable bytes at `p`. `vpmovdb` truncates: the low
        // byte of each lane, the code mod 256.
        unsafe { _mm_storeu_si128(p.cast(), _mm512_cvtepi32_epi8(c)) }
    }
}

/// The four `#[target_feature]` entry points of one ISA: the generic bodies of [`simd`] on `$reg`.
macro_rules! entry_points {
    ($reg:ty, $lanes:literal, $features:literal, $cpu:literal, $analyse:ident, $planes:ident, $encode:ident, $abs:ident) => {
        /// Pass 1 on one row (lengths checked by the caller), as [`super::body::analyse_body`].
        ///
        /// # Safety
        #[doc = concat!("The CPU has ", $cpu, "; `field.len() == 2·phase.len()`.")]
        #[target_feature(enable = $features)]
        pub(crate) unsafe fn $analyse(field: &[f32], phase: &mut [f32]) -> (f32, f64) {
            // SAFETY: the register's ISA is enabled here; the lengths as the caller guarantees.
            unsafe { simd::analyse::<$reg, $lanes>(field, phase) }
        }

        /// Pass 1 on one row held as planes (lengths checked by the caller), as
        /// [`super::body::analyse_planes_body`].
        ///
        /// # Safety
        #[doc = concat!("The CPU has ", $cpu, "; `re`, `im_arg` and `abs` of one length.")]
        #[target_feature(enable = $features)]
        pub(crate) unsafe fn $planes(re: &[f32], im_arg: &mut [f32], abs: &mut [f32]) -> (f32, f64) {
            // SAFETY: the register's ISA is enabled here; the lengths as the caller guarantees.
            unsafe { simd::analyse_planes::<$reg, $lanes>(re, im_arg, abs) }
        }

        /// Pass 2 on one row (lengths checked by the caller), as [`super::body::encode_row_of`]`::<2>`.
        ///
        /// # Safety
        #[doc = concat!("The CPU has ", $cpu, "; `field.len() == 2·phase.len()`, `codes` (if any) as long as `phase`.")]
        #[target_feature(enable = $features)]
        pub(crate) unsafe fn $encode(
            field: &[f32],
            phase: &mut [f32],
            codes: Option<&mut [u8]>,
            prm: &EncodeParams,
        ) {
            // SAFETY: the register's ISA is enabled here; the lengths as the caller guarantees.
            unsafe { simd::encode::<$reg, $lanes, 2>(field, phase, codes, prm) }
        }

        /// Pass 2 on one row whose magnitudes are given, as [`super::body::encode_row_of`]`::<1>`.
        ///
        /// # Safety
        #[doc = concat!("The CPU has ", $cpu, "; `abs.len() == phase.len()`, `codes` (if any) as long as `phase`.")]
        #[target_feature(enable = $features)]
        pub(crate) unsafe fn $abs(
            abs: &[f32],
            phase: &mut [f32],
            codes: Option<&mut [u8]>,
            prm: &EncodeParams,
        ) {
            // SAFETY: the register's ISA is enabled here; the lengths as the caller guarantees.
            unsafe { simd::encode::<$reg, $lanes, 1>(abs, phase, codes, prm) }
        }
    };
}

entry_points!(
    __m256,
    8,
    "avx2,fma",
    "AVX2 and FMA",
    analyse_avx2,
    analyse_planes_avx2,
    encode_avx2,
    encode_abs_avx2
);
entry_points!(
    __m512,
    16,
    "avx512f",
    "AVX-512F",
    analyse_avx512,
    analyse_planes_avx512,
    encode_avx512,
    encode_abs_avx512
);

//! `conv3x3.u8s8.8x3.avx512vnni`: AVX-512 VNNI (512-bit `vpdpbusd`, u8 × s8, 4 products per lane) on the
//! generic loop [`simd_u8::conv`](super::simd_u8::conv): 8 output channels × 3 zmm (48 pixels) = 24
//! accumulators + 3 inputs + 1 weight of 32 zmm.

use super::job::{entry_points, U8Job, U8Out};
use super::simd_u8::{conv, peak_chains, SimdQ};
use std::arch::x86_64::*;

/// AVX-512 VNNI accumulator: 16 pixels.
#[derive(Clone, Copy)]
pub(crate) struct Avx512Vnni(__m512i);

impl SimdQ for Avx512Vnni {
    const PX: usize = 16;
    const WB: usize = 4;
    type X = __m512i;
    type W = __m512i;
    type F = __m512;
    #[inline(always)]
    unsafe fn init(v: i32) -> Self {
        // SAFETY: the caller guarantees AVX-512F.
        unsafe { Avx512Vnni(_mm512_set1_epi32(v)) }
    }
    #[inline(always)]
    unsafe fn load_x(p: *const u8) -> Self::X {
        // SAFETY: the caller guarantees AVX-512F and 64 readable bytes at `p`.
        unsafe { _mm512_loadu_si512(p.cast()) }
    }
    #[inline(always)]
    unsafe fn load_w(p: *const u8) -> Self::W {
        // SAFETY: the caller guarantees AVX-512F and 4 readable bytes at `p`.
        unsafe { _mm512_set1_epi32(p.cast::<i32>().read_unaligned()) }
    }
    #[inline(always)]
    unsafe fn dot(self, x: Self::X, w: Self::W) -> Self {
        // SAFETY: the caller guarantees AVX-512 VNNI.
        unsafe { Avx512Vnni(_mm512_dpbusd_epi32(self.0, x, w)) }
    }
    #[inline(always)]
    unsafe fn to_f32(self) -> __m512 {
        // SAFETY: the caller guarantees AVX-512F.
        unsafe { _mm512_cvtepi32_ps(self.0) }
    }
    #[inline(always)]
    unsafe fn splat(v: f32) -> __m512 {
        // SAFETY: the caller guarantees AVX-512F.
        unsafe { _mm512_set1_ps(v) }
    }
    #[inline(always)]
    unsafe fn mul(a: __m512, b: __m512) -> __m512 {
        // SAFETY: the caller guarantees AVX-512F.
        unsafe { _mm512_mul_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn add(a: __m512, b: __m512) -> __m512 {
        // SAFETY: the caller guarantees AVX-512F.
        unsafe { _mm512_add_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn sub(a: __m512, b: __m512) -> __m512 {
        // SAFETY: the caller guarantees AVX-512F.
        unsafe { _mm512_sub_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn relu(v: __m512) -> __m512 {
        // SAFETY: the caller guarantees AVX-512F. `vmaxps(v, 0)` = `v > 0 ? v : 0`.
        unsafe { _mm512_max_ps(v, _mm512_setzero_ps()) }
    }
    #[inline(always)]
    unsafe fn load_byte(p: *const u8, lane: usize) -> __m512 {
        // SAFETY: the caller guarantees AVX-512F and 64 readable bytes at `p`.
        unsafe {
            let w = _mm512_loadu_si512(p.cast());
            let s = _mm512_srl_epi32(w, _mm_cvtsi32_si128(8 * lane as i32));
            _mm512_cvtepi32_ps(_mm512_and_si512(s, _mm512_set1_epi32(0xFF)))
        }
    }
    #[inline(always)]
    unsafe fn quant(v: __m512, inv: __m512, zp: __m512) -> __m512 {
        // SAFETY: the caller guarantees AVX-512F. `vrndscaleps` with 0 fraction bits, nearest even.
        unsafe {
            let r = _mm512_roundscale_ps::<{ _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC }>(
                _mm512_mul_ps(v, inv),
            );
            let y = _mm512_max_ps(_mm512_add_ps(r, zp), _mm512_setzero_ps());
            _mm512_min_ps(y, _mm512_set1_ps(255.0))
        }
    }
    #[inline(always)]
    unsafe fn store_u8x4(p: *mut u8, q: [__m512; 4], valid: usize, border: u8) {
        // SAFETY: the caller guarantees AVX-512F and 64 writable bytes at `p`.
        unsafe {
            let mut word = _mm512_cvttps_epi32(q[0]);
            word = _mm512_or_si512(word, _mm512_slli_epi32::<8>(_mm512_cvttps_epi32(q[1])));
            word = _mm512_or_si512(word, _mm512_slli_epi32::<16>(_mm512_cvttps_epi32(q[2])));
            word = _mm512_or_si512(word, _mm512_slli_epi32::<24>(_mm512_cvttps_epi32(q[3])));
            let k = ((1u32 << valid) - 1) as __mmask16;
            let b = _mm512_set1_epi32(i32::from_ne_bytes([border; 4]));
            _mm512_storeu_si512(p.cast(), _mm512_mask_blend_epi32(k, b, word))
        }
    }
    #[inline(always)]
    unsafe fn store_f32(p: *mut f32, v: __m512, valid: usize) {
        // SAFETY: the caller guarantees AVX-512F and `valid` writable values at `p`; the masked store writes
        // only the first `valid` lanes.
        unsafe { _mm512_mask_storeu_ps(p, ((1u32 << valid) - 1) as __mmask16, v) }
    }
}

entry_points! {
    "avx512f,avx512bw,avx512vnni,avx2,fma", U8Job, U8Out;
    /// `conv3x3.u8s8.8x3.avx512vnni`.
    ///
    /// # Safety
    /// The CPU has AVX-512F/BW and AVX-512 VNNI; the job was checked and packed with `PackKind::I8`.
    fn conv_avx512vnni = conv::<Avx512Vnni, 8, 3>;
}

/// 512-bit `vpdpbusd` peak: 24 chains; ops = `iters · 24 · 64 · 2`.
///
/// # Safety
/// The CPU has AVX-512 VNNI.
#[target_feature(enable = "avx512f,avx512vnni")]
pub(crate) unsafe fn peak_avx512vnni(iters: u64) -> i32 {
    let (x, w) = (_mm512_set1_epi8(3), _mm512_set1_epi8(-2));
    // SAFETY: AVX-512 VNNI enabled here and present on the CPU (the caller's guarantee).
    let acc = unsafe { peak_chains::<Avx512Vnni, 24>(iters, x, w) };
    _mm512_reduce_add_epi32(
        acc.iter()
            .fold(_mm512_setzero_si512(), |s, a| _mm512_add_epi32(s, a.0)),
    )
}

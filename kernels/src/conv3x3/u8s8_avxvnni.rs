//! `conv3x3.u8s8.4x2.avxvnni`: AVX-VNNI (256-bit `{vex} vpdpbusd`, u8 × s8, 4 products per lane) on the
//! generic loop [`simd_u8::conv`](super::simd_u8::conv): 4 output channels × 2 ymm (16 pixels) = 8
//! accumulators + 2 inputs + 1 weight of 16 ymm. Its f32 epilogue is the AVX2 row's (macro `epilogue_256`
//! from [`u8s8_avx2`](super::u8s8_avx2)): the row differs from the tested AVX2 row only in
//! `load_x`/`load_w`/`dot`/`to_f32`.

use super::job::{entry_points, U8Job, U8Out};
use super::simd_u8::{conv, peak_chains, SimdQ};
use super::u8s8_avx2::{epilogue_256, MASK};
use std::arch::x86_64::*;

/// AVX-VNNI accumulator: 8 pixels.
#[derive(Clone, Copy)]
pub(crate) struct AvxVnni(__m256i);

impl SimdQ for AvxVnni {
    const PX: usize = 8;
    const WB: usize = 4;
    type X = __m256i;
    type W = __m256i;
    epilogue_256!();
    #[inline(always)]
    unsafe fn init(v: i32) -> Self {
        // SAFETY: the caller guarantees AVX2.
        unsafe { AvxVnni(_mm256_set1_epi32(v)) }
    }
    #[inline(always)]
    unsafe fn load_x(p: *const u8) -> Self::X {
        // SAFETY: the caller guarantees AVX2 and 32 readable bytes at `p`.
        unsafe { _mm256_loadu_si256(p.cast()) }
    }
    #[inline(always)]
    unsafe fn load_w(p: *const u8) -> Self::W {
        // SAFETY: the caller guarantees AVX2 and 4 readable bytes at `p`.
        unsafe { _mm256_set1_epi32(p.cast::<i32>().read_unaligned()) }
    }
    #[inline(always)]
    unsafe fn dot(self, x: Self::X, w: Self::W) -> Self {
        // SAFETY: the caller guarantees AVX-VNNI. u8 (x) × s8 (w), 4 products per lane, exact.
        unsafe { AvxVnni(_mm256_dpbusd_avx_epi32(self.0, x, w)) }
    }
    #[inline(always)]
    unsafe fn to_f32(self) -> __m256 {
        // SAFETY: the caller guarantees AVX2.
        unsafe { _mm256_cvtepi32_ps(self.0) }
    }
}

entry_points! {
    "avx2,fma,avxvnni", U8Job, U8Out;
    /// `conv3x3.u8s8.4x2.avxvnni`.
    ///
    /// # Safety
    /// The CPU has AVX2 and AVX-VNNI; the job was checked and packed with `PackKind::I8`.
    fn conv_avxvnni = conv::<AvxVnni, 4, 2>;
}

/// 256-bit `vpdpbusd` peak: 12 chains; ops = `iters · 12 · 32 · 2`.
///
/// # Safety
/// The CPU has AVX-VNNI.
#[target_feature(enable = "avx2,avxvnni")]
pub(crate) unsafe fn peak_avxvnni(iters: u64) -> i32 {
    let (x, w) = (_mm256_set1_epi8(3), _mm256_set1_epi8(-2));
    // SAFETY: AVX-VNNI enabled here and present on the CPU (the caller's guarantee).
    let acc = unsafe { peak_chains::<AvxVnni, 12>(iters, x, w) };
    let s = acc
        .iter()
        .fold(_mm256_setzero_si256(), |s, a| _mm256_add_epi32(s, a.0));
    _mm256_extract_epi32::<0>(s)
}

//! `conv3x3.f32.8x3.avx512`: AVX-512F, 512-bit registers (and `conv3x3.f32.6x4.avx512`, the same loop for
//! 6-channel layers: [`G6`] × [`NV6`]).
//!
//! Register tile: 8 output channels × 3 zmm (48 pixels) = 24 accumulators, + 3 input vectors + 1 broadcast
//! weight = 28 of the 32 zmm registers. Per reduction step: 3 loads + 8 broadcasts for 24 FMAs. The loop and
//! index code is the generic [`simd_f32::conv`](super::simd_f32::conv) shared with the tested AVX2 and NEON
//! rows; only the register operations below are specific (the test machine has no AVX-512).

use super::f32_avx2::x86_shared;
use super::job::{entry_points, F32Job, F32Out};
use super::simd_f32::{conv as generic_conv, peak_chains, ConvF32};
use super::{wino2x2, wino4x4};
use std::arch::x86_64::*;

/// Output-channel tile.
pub(crate) const G: usize = 8;
/// zmm vectors of pixels per tile.
pub(crate) const NV: usize = 3;

impl ConvF32 for __m512 {
    #[inline(always)]
    unsafe fn fma(acc: Self, a: Self, b: Self) -> Self {
        // SAFETY: the caller guarantees AVX-512F.
        unsafe { _mm512_fmadd_ps(a, b, acc) }
    }
    #[inline(always)]
    unsafe fn interleave(e: Self, o: Self) -> (Self, Self) {
        // SAFETY: the caller guarantees AVX-512F. Indices 0..16 pick from `e`, 16..32 from `o`.
        unsafe {
            let lo = _mm512_setr_epi32(0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23);
            let hi =
                _mm512_setr_epi32(8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31);
            (
                _mm512_permutex2var_ps(e, lo, o),
                _mm512_permutex2var_ps(e, hi, o),
            )
        }
    }
    // `load_stride4`: lane `4q + k` holds quadruple `q + 4k`, the same for every `p`; `interleave4` undoes it.
    x86_shared!(
        _mm512_loadu_ps,
        _mm512_unpacklo_ps,
        _mm512_unpackhi_ps,
        _mm512_shuffle_ps
    );
    #[inline(always)]
    unsafe fn next_columns(p: *const f32, c0: Self, c1: Self) -> [Self; 2] {
        // SAFETY: the caller guarantees AVX-512F and `66` readable values at `p`. `load_stride4` puts
        // quadruple `q + 4j` in lane `4q + j`: the next quadruple's lane is `4q + 4 + j` for `q < 3`, `j + 1`
        // for `q = 3`, and quadruple 16 (lane 15's next) is not in `c0`, `c1`: index 16 picks `p[64]`,
        // `p[65]` from the second operand.
        unsafe {
            let next = _mm512_setr_epi32(4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 1, 2, 3, 16);
            [
                _mm512_permutex2var_ps(c0, next, _mm512_set1_ps(*p.add(64))),
                _mm512_permutex2var_ps(c1, next, _mm512_set1_ps(*p.add(65))),
            ]
        }
    }
    #[inline(always)]
    unsafe fn keep_first(v: Self, n: usize) -> Self {
        debug_assert!(n < 16);
        let m: __mmask16 = ((1u32 << n) - 1) as u16;
        // SAFETY: the caller guarantees AVX-512F.
        unsafe { _mm512_maskz_mov_ps(m, v) }
    }
}

/// Output-channel tile of `conv3x3.f32.6x4.avx512`: the 6-channel last layers (the hologram CNN's 24 + 4 → 6,
/// the pre-filter's 8 + 6 → 6). The 8 × 3 tile computes 8 channels for their 6: a quarter of its
/// multiply-adds are wasted.
pub(crate) const G6: usize = 6;
/// zmm vectors of pixels per `conv3x3.f32.6x4.avx512` tile: 6 channels × 4 zmm (64 pixels) = 24
/// accumulators, + 4 input vectors + 1 broadcast weight = 29 of the 32 zmm registers; per reduction step 4
/// loads + 6 broadcasts for 24 multiply-adds, every one of them useful at 6 channels.
pub(crate) const NV6: usize = 4;

/// Vectors of tiles per Winograd register tile (8 channels × 2 × 16 = 32 tiles, 64 output pixels: the
/// most `MAX_TILE` allows).
pub(crate) const WINO_NV: usize = 2;

/// Output channels of the wide F(4×4, 3×3) register tile: a whole 24-channel layer in one group.
pub(crate) const WINO4_G: usize = 24;

entry_points! {
    "avx512f,avx2,fma", F32Job, F32Out;
    /// The registry entry (48-pixel tile).
    ///
    /// # Safety
    /// The CPU has AVX-512F (and AVX2, FMA); `job` was checked by the safe API.
    fn conv = generic_conv::<__m512, G, NV>;
    /// The registry entry of `conv3x3.f32.6x4.avx512` (the generic direct loop at [`G6`] × [`NV6`], 64
    /// pixels).
    ///
    /// # Safety
    /// The CPU has AVX-512F (and AVX2, FMA); `job` was checked by the safe API.
    fn conv6 = generic_conv::<__m512, G6, NV6>;
    /// `conv3x3.f32.wino2x2.8x2.avx512`: Winograd F(2×2, 3×3), 8 output channels × 2 zmm of tiles.
    ///
    /// # Safety
    /// The CPU has AVX-512F; `job` was checked by the safe API and its weights packed for Winograd.
    fn winograd = wino2x2::conv::<__m512, G, WINO_NV>;
    /// `conv3x3.f32.wino4x4.8x1.avx512`: Winograd F(4×4, 3×3), 8 output channels × 1 zmm of tiles (16 tiles,
    /// 64 output pixels: the most `MAX_TILE` allows; 8 accumulators, one load and 8 broadcasts per step).
    ///
    /// # Safety
    /// The CPU has AVX-512F; `job` was checked by the safe API and its weights packed for F(4×4, 3×3).
    fn winograd4 = wino4x4::conv::<__m512, G, 1>;
    /// `conv3x3.f32.wino4x4.24x1.avx512`: Winograd F(4×4, 3×3), 24 output channels × 1 zmm of tiles (16
    /// tiles, 64 output pixels).
    ///
    /// Register tile: 24 accumulators + 1 vector of transformed inputs, the 24 weights broadcast from memory
    /// by the multiply-adds themselves (`vfmadd231ps m32{1to16}`): 25 of the 32 zmm registers, 24 independent
    /// FMA chains per reduction step (the 8-channel tile's 8 chains are just the latency × throughput of two
    /// FMA pipes: any stall shows) and one load of `V` per 24 multiply-adds instead of per 8. A 24-channel
    /// layer is one group, so each chunk's `V` (54 KiB, more than L1) is read once instead of three times.
    /// Measured on Zen 5 (benchmarks/history/BENCHMARKS-2026.md): the f32 8-layer CNN at 1080p on 2 threads
    /// about 9 % faster (medians of six rounds) than with the 8 × 1 tile; layers of fewer channels keep the
    /// 8 × 1 row (the least padding, [`selected_f32_for`]).
    ///
    /// [`selected_f32_for`]: crate::registry::selected_f32_for
    ///
    /// # Safety
    /// The CPU has AVX-512F; `job` was checked by the safe API and its weights packed for F(4×4, 3×3) with
    /// [`WINO4_G`] channels per group.
    fn winograd4_wide = wino4x4::conv::<__m512, WINO4_G, 1>;
}

/// FMA peak loop: `iters` × 24 independent 16-lane FMAs. FLOPs = `iters · 24 · 16 · 2`.
///
/// # Safety
/// The CPU has AVX-512F.
#[target_feature(enable = "avx512f")]
pub(crate) unsafe fn peak(iters: u64) -> f32 {
    // SAFETY: AVX-512F enabled here and present on the CPU (the caller's guarantee).
    unsafe { _mm512_reduce_add_ps(peak_chains::<__m512, 24>(iters)) }
}

//! `conv3x3.f32.6x2.avx2`: AVX2 + FMA, 256-bit registers.
//!
//! Register tile: 6 output channels × 2 ymm (16 pixels) = 12 accumulators, + 2 input vectors + 1 broadcast
//! weight = 15 of the 16 ymm registers. Per reduction step: 2 loads + 6 broadcasts for 12 FMAs, within the
//! load ports' budget while the two FMA pipes stay busy. The kernel is load-bound on Zen 3 (loads per FMA:
//! 6 × 2 → 0.67, 3 × 3 → 0.67, 2 × 4 → 0.75; 4 × 3 → 0.58 needs all 16 registers and spills): measured on
//! the 24→24 layer at 384×384, 6 × 2 57.6 GFLOP/s, 3 × 3 53.3, 4 × 3 43.7, 2 × 4 40.3 (README).

use super::job::{entry_points, F32Job, F32Out};
use super::simd_f32::{conv as generic_conv, peak_chains, ConvF32};
use super::{wino2x2, wino4x4};
#[cfg(test)]
use crate::simd::Pair;
use std::arch::x86_64::*;

/// Output-channel tile.
pub(crate) const G: usize = 6;
/// ymm vectors of pixels per tile.
pub(crate) const NV: usize = 2;

static MASK: [i32; 16] = [-1, -1, -1, -1, -1, -1, -1, -1, 0, 0, 0, 0, 0, 0, 0, 0];

impl ConvF32 for __m256 {
    #[inline(always)]
    unsafe fn fma(acc: Self, a: Self, b: Self) -> Self {
        // SAFETY: the caller guarantees FMA.
        unsafe { _mm256_fmadd_ps(a, b, acc) }
    }
    #[inline(always)]
    unsafe fn load_deinterleaved(p: *const f32) -> (Self, Self) {
        // SAFETY: the caller guarantees AVX and 16 readable values at `p`. Within 128-bit lanes:
        // `[p0 p2 p8 p10 | p4 p6 p12 p14]` and the odd ones: pairs (tiles) in the order 0 1 4 5 2 3 6 7, the
        // same for every `p`, which `interleave` undoes without crossing 128-bit lanes either.
        unsafe {
            let (a, b) = (_mm256_loadu_ps(p), _mm256_loadu_ps(p.add(8)));
            (
                _mm256_shuffle_ps::<0b10_00_10_00>(a, b),
                _mm256_shuffle_ps::<0b11_01_11_01>(a, b),
            )
        }
    }
    #[inline(always)]
    unsafe fn interleave(e: Self, o: Self) -> (Self, Self) {
        // SAFETY: the caller guarantees AVX. Lanes hold pairs 0 1 4 5 | 2 3 6 7 (`load_deinterleaved`):
        // `[e0 o0 e1 o1 | e4 o4 e5 o5]` = pixels 0..8, `[e2 o2 e3 o3 | e6 o6 e7 o7]` = pixels 8..16.
        unsafe { (_mm256_unpacklo_ps(e, o), _mm256_unpackhi_ps(e, o)) }
    }
    // `load_stride4`: the quadruples in the order 0 2 4 6 | 1 3 5 7 (one per 128-bit lane of each load), the
    // same for every `p`; `interleave4` undoes it.
    x86_shared!(
        _mm256_loadu_ps,
        _mm256_unpacklo_ps,
        _mm256_unpackhi_ps,
        _mm256_shuffle_ps
    );
    #[inline(always)]
    unsafe fn keep_first(v: Self, n: usize) -> Self {
        debug_assert!(n < 8);
        // SAFETY: the caller guarantees AVX; `8 − n ∈ 1..=8`, so the 8 mask values read are inside MASK.
        unsafe {
            let m = _mm256_loadu_si256(MASK.as_ptr().add(8 - n).cast());
            _mm256_and_ps(v, _mm256_castsi256_ps(m))
        }
    }
}

/// The [`ConvF32`] methods the x86 rows share at every register width, written with the width's intrinsics
/// (`x86_shared!(load, unpacklo, unpackhi, shuffle)`): `load_stride4` (four loads of `LANES` values, then
/// the transpose of `interleave4`), `interleave4` (the 4×4 transpose inside every 128-bit lane: lane half `h`
/// of result `j` holds element `j` of lane half `h` of `r[0]`, `r[1]`, `r[2]`, `r[3]`; its own inverse) and
/// `prefetch` (`prefetcht0`).
macro_rules! x86_shared {
    ($load:ident, $unpacklo:ident, $unpackhi:ident, $shuffle:ident) => {
        #[inline(always)]
        unsafe fn load_stride4(p: *const f32) -> [Self; 4] {
            let l = <Self as $crate::simd::SimdF32>::LANES;
            // SAFETY: the caller guarantees the ISA and `4·LANES` readable values at `p`.
            unsafe {
                Self::interleave4([
                    $load(p),
                    $load(p.add(l)),
                    $load(p.add(2 * l)),
                    $load(p.add(3 * l)),
                ])
            }
        }
        #[inline(always)]
        unsafe fn interleave4(r: [Self; 4]) -> [Self; 4] {
            // SAFETY: the caller guarantees the ISA; register-only operations.
            unsafe {
                let t0 = $unpacklo(r[0], r[1]);
                let t1 = $unpackhi(r[0], r[1]);
                let t2 = $unpacklo(r[2], r[3]);
                let t3 = $unpackhi(r[2], r[3]);
                [
                    $shuffle::<0b01_00_01_00>(t0, t2),
                    $shuffle::<0b11_10_11_10>(t0, t2),
                    $shuffle::<0b01_00_01_00>(t1, t3),
                    $shuffle::<0b11_10_11_10>(t1, t3),
                ]
            }
        }
        #[inline(always)]
        unsafe fn prefetch(p: *const f32) {
            // SAFETY: `prefetcht0` never faults.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(p.cast()) }
        }
    };
}
pub(super) use x86_shared;

entry_points! {
    "avx2,fma", F32Job, F32Out;
    /// The registry entry (16-pixel tile).
    ///
    /// # Safety
    /// The CPU has AVX2 and FMA; `job` was checked by the safe API.
    fn conv = generic_conv::<__m256, G, NV>;
    /// `conv3x3.f32.wino2x2.6x2.avx2`: Winograd F(2×2, 3×3) with the direct row's 6 × 2 register tile (6
    /// output channels × 16 tiles = 32 output pixels of two rows), for the same reason (load-bound; 15 of 16
    /// ymm).
    ///
    /// # Safety
    /// The CPU has AVX2 and FMA; `job` was checked by the safe API and its weights packed for Winograd.
    fn winograd = wino2x2::conv::<__m256, G, NV>;
    /// `conv3x3.f32.wino4x4.6x2.avx2`: Winograd F(4×4, 3×3) with the direct row's 6 × 2 register tile (6
    /// output channels × 2 ymm of tiles: 16 tiles, 64 output pixels, the most `MAX_TILE` allows).
    ///
    /// # Safety
    /// The CPU has AVX2 and FMA; `job` was checked by the safe API and its weights packed for F(4×4, 3×3).
    fn winograd4 = wino4x4::conv::<__m256, G, NV>;
    /// Tests only: the AVX-512 tile geometry (8 × 3 × 16 lanes, 48 pixels) on AVX2 registers.
    ///
    /// # Safety
    /// As [`conv`].
    #[cfg(test)]
    fn conv_avx512_geometry = generic_conv::<Ymm2, 8, 3>;
    /// Tests only: the geometry of `conv3x3.f32.6x4.avx512` (6 × 4 × 16 lanes, 64 pixels) on AVX2 registers.
    ///
    /// # Safety
    /// As [`conv`].
    #[cfg(test)]
    fn conv6_avx512_geometry = generic_conv::<Ymm2, 6, 4>;
    /// Tests only: the AVX-512 Winograd geometry (8 channels × 2 vectors of 16 lanes = 32 tiles, 64 pixels)
    /// on AVX2 registers.
    ///
    /// # Safety
    /// As [`winograd`].
    #[cfg(test)]
    fn winograd_avx512_geometry = wino2x2::conv::<Ymm2, 8, 2>;
    /// Tests only: the AVX-512 F(4×4, 3×3) geometry (8 channels × 1 vector of 16 lanes = 16 tiles) on AVX2
    /// registers.
    ///
    /// # Safety
    /// As [`winograd4`].
    #[cfg(test)]
    fn winograd4_avx512_geometry = wino4x4::conv::<Ymm2, 8, 1>;
    /// Tests only: the wide AVX-512 F(4×4, 3×3) geometry (24 channels × 1 vector of 16 lanes = 16 tiles) on
    /// AVX2 registers (they spill: correctness only).
    ///
    /// # Safety
    /// As [`winograd4`].
    #[cfg(test)]
    fn winograd4_wide_avx512_geometry = wino4x4::conv::<Ymm2, 24, 1>;
}

/// FMA peak loop: `iters` × 12 independent 8-lane FMAs; returns a value derived from the result (to keep the
/// loop alive). FLOPs = `iters · 12 · 8 · 2`.
///
/// # Safety
/// The CPU has AVX2 and FMA.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn peak(iters: u64) -> f32 {
    let mut out = [0.0f32; 8];
    // SAFETY: AVX2 + FMA enabled here and present on the CPU (the caller's guarantee); `out` holds 8 values.
    unsafe { _mm256_storeu_ps(out.as_mut_ptr(), peak_chains::<__m256, 12>(iters)) };
    out.iter().sum()
}

/// Tests only: two ymm registers acting as one 16-lane register ([`Pair`]), so that the generic loop runs
/// the AVX-512 row's tile geometry (8 output channels × 3 vectors of 16 lanes = 48 pixels, masks up to 16
/// lanes) on a CPU without AVX-512. Only the register operations of `f32_avx512.rs` and `simd/avx512.rs`
/// remain untested here.
#[cfg(test)]
type Ymm2 = Pair<__m256>;

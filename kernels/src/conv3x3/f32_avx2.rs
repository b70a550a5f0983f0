//! `conv3x3.f32.6x2.avx2`: AVX2 + FMA, 256-bit registers.
//!
//! Register tile: 6 output channels × 2 ymm (16 pixels) = 12 accumulators, + 2 input vectors + 1 broadcast
//! weight = 15 of the 16 ymm registers. Per reduction step: 2 loads + 6 broadcasts for 12 FMAs, within the
//! load ports' budget while the two FMA pipes stay busy. The kernel is load-bound on Zen 3 (loads per FMA:
//! 6 × 2 → 0.67, 3 × 3 → 0.67, 2 × 4 → 0.75; 4 × 3 → 0.58 needs all 16 registers and spills): measured on
//! the 24→24 layer at 384×384, 6 × 2 57.6 GFLOP/s, 3 × 3 53.3, 4 × 3 43.7, 2 × 4 40.3 (README).

use super::job::{F32Job, F32Out};
use super::simd_f32::{conv as generic_conv, SimdF32};
use super::{wino2x2, wino4x4};
use std::arch::x86_64::*;

/// Output-channel tile.
pub(crate) const G: usize = 6;
/// ymm vectors of pixels per tile.
pub(crate) const NV: usize = 2;

static MASK: [i32; 16] = [-1, -1, -1, -1, -1, -1, -1, -1, 0, 0, 0, 0, 0, 0, 0, 0];

impl SimdF32 for __m256 {
    const LANES: usize = 8;
    #[inline(always)]
    unsafe fn zero() -> Self {
        // SAFETY: the caller guarantees AVX.
        unsafe { _mm256_setzero_ps() }
    }
    #[inline(always)]
    unsafe fn splat(p: *const f32) -> Self {
        // SAFETY: the caller guarantees AVX and a valid `p`.
        unsafe { _mm256_broadcast_ss(&*p) }
    }
    #[inline(always)]
    unsafe fn load(p: *const f32) -> Self {
        // SAFETY: the caller guarantees AVX and 8 readable values at `p`.
        unsafe { _mm256_loadu_ps(p) }
    }
    #[inline(always)]
    unsafe fn store(p: *mut f32, v: Self) {
        // SAFETY: the caller guarantees AVX and 8 writable values at `p`.
        unsafe { _mm256_storeu_ps(p, v) }
    }
    #[inline(always)]
    unsafe fn fma(acc: Self, a: Self, b: Self) -> Self {
        // SAFETY: the caller guarantees FMA.
        unsafe { _mm256_fmadd_ps(a, b, acc) }
    }
    #[inline(always)]
    unsafe fn add(a: Self, b: Self) -> Self {
        // SAFETY: the caller guarantees AVX.
        unsafe { _mm256_add_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn relu(v: Self) -> Self {
        // SAFETY: the caller guarantees AVX. `maxps(v, 0)` returns the second operand for NaN and ±0.
        unsafe { _mm256_max_ps(v, _mm256_setzero_ps()) }
    }
    #[inline(always)]
    unsafe fn sub(a: Self, b: Self) -> Self {
        // SAFETY: the caller guarantees AVX.
        unsafe { _mm256_sub_ps(a, b) }
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
    #[inline(always)]
    unsafe fn load_stride4(p: *const f32) -> [Self; 4] {
        // SAFETY: the caller guarantees AVX and 32 readable values at `p`. A 4×4 transpose inside each
        // 128-bit lane (one quadruple per lane of each load): quadruples in the order 0 2 4 6 | 1 3 5 7, the
        // same for every `p`; the transpose is its own inverse (`interleave4`).
        unsafe {
            transpose4_in_lanes([
                _mm256_loadu_ps(p),
                _mm256_loadu_ps(p.add(8)),
                _mm256_loadu_ps(p.add(16)),
                _mm256_loadu_ps(p.add(24)),
            ])
        }
    }
    #[inline(always)]
    unsafe fn interleave4(c: [Self; 4]) -> [Self; 4] {
        // SAFETY: the caller guarantees AVX.
        unsafe { transpose4_in_lanes(c) }
    }
    #[inline(always)]
    unsafe fn prefetch(p: *const f32) {
        // SAFETY: `prefetcht0` never faults.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(p.cast()) }
    }
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

/// The 4×4 transpose inside every 128-bit lane of four registers: lane half `h` of result `j` holds element
/// `j` of lane half `h` of `r[0]`, `r[1]`, `r[2]`, `r[3]`.
///
/// # Safety
/// The CPU has AVX.
#[inline(always)]
unsafe fn transpose4_in_lanes(r: [__m256; 4]) -> [__m256; 4] {
    // SAFETY: the caller guarantees AVX.
    unsafe {
        let t0 = _mm256_unpacklo_ps(r[0], r[1]);
        let t1 = _mm256_unpackhi_ps(r[0], r[1]);
        let t2 = _mm256_unpacklo_ps(r[2], r[3]);
        let t3 = _mm256_unpackhi_ps(r[2], r[3]);
        [
            _mm256_shuffle_ps::<0b01_00_01_00>(t0, t2),
            _mm256_shuffle_ps::<0b11_10_11_10>(t0, t2),
            _mm256_shuffle_ps::<0b01_00_01_00>(t1, t3),
            _mm256_shuffle_ps::<0b11_10_11_10>(t1, t3),
        ]
    }
}

/// The registry entry.
///
/// # Safety
/// The CPU has AVX2 and FMA; `job` was checked by the safe API.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn conv(job: &F32Job<'_>, out: &mut F32Out<'_>) {
    // SAFETY: AVX2 + FMA enabled here; 16-pixel tile ≤ MAX_TILE; the job was checked by the caller.
    unsafe { generic_conv::<__m256, G, NV>(job, out) }
}

/// `conv3x3.f32.wino2x2.6x2.avx2`: Winograd F(2×2, 3×3) with the direct row's 6 × 2 register tile (6
/// output channels × 16 tiles = 32 output pixels of two rows), for the same reason (load-bound; 15 of 16 ymm).
///
/// # Safety
/// The CPU has AVX2 and FMA; `job` was checked by the safe API and its weights packed for Winograd.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn winograd(job: &F32Job<'_>, out: &mut F32Out<'_>) {
    // SAFETY: AVX2 + FMA enabled here; 32-pixel tile ≤ MAX_TILE; the job was checked by the caller.
    unsafe { wino2x2::conv::<__m256, G, NV>(job, out) }
}

/// FMA peak loop: `iters` × 12 independent 8-lane FMAs; returns a value derived from the result (to keep the
/// loop alive). FLOPs = `iters · 12 · 8 · 2`.
///
/// # Safety
/// The CPU has AVX2 and FMA.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn peak(iters: u64) -> f32 {
    let mut acc = [_mm256_set1_ps(1.0); 12];
    let a = _mm256_set1_ps(0.999_999);
    let b = _mm256_set1_ps(1e-7);
    for _ in 0..iters {
        for x in acc.iter_mut() {
            *x = _mm256_fmadd_ps(*x, a, b);
        }
    }
    let mut s = _mm256_setzero_ps();
    for x in acc {
        s = _mm256_add_ps(s, x);
    }
    let mut out = [0.0f32; 8];
    // SAFETY: `out` holds 8 values.
    unsafe { _mm256_storeu_ps(out.as_mut_ptr(), s) };
    out.iter().sum()
}

/// Tests only: two ymm registers acting as one 16-lane register, so that the generic loop runs the
/// AVX-512 row's tile geometry (8 output channels × 3 vectors of 16 lanes = 48 pixels, masks up to 16
/// lanes) on a CPU without AVX-512. Only the register operations of `f32_avx512.rs` remain untested here.
#[cfg(test)]
#[derive(Clone, Copy)]
pub(crate) struct Ymm2(__m256, __m256);

#[cfg(test)]
impl SimdF32 for Ymm2 {
    const LANES: usize = 16;
    #[inline(always)]
    unsafe fn zero() -> Self {
        // SAFETY: the caller guarantees AVX.
        unsafe { Ymm2(__m256::zero(), __m256::zero()) }
    }
    #[inline(always)]
    unsafe fn splat(p: *const f32) -> Self {
        // SAFETY: the caller guarantees AVX and a valid `p`.
        unsafe { Ymm2(__m256::splat(p), __m256::splat(p)) }
    }
    #[inline(always)]
    unsafe fn load(p: *const f32) -> Self {
        // SAFETY: the caller guarantees 16 readable values at `p`.
        unsafe { Ymm2(__m256::load(p), __m256::load(p.add(8))) }
    }
    #[inline(always)]
    unsafe fn store(p: *mut f32, v: Self) {
        // SAFETY: the caller guarantees 16 writable values at `p`.
        unsafe {
            __m256::store(p, v.0);
            __m256::store(p.add(8), v.1)
        }
    }
    #[inline(always)]
    unsafe fn fma(acc: Self, a: Self, b: Self) -> Self {
        // SAFETY: the caller guarantees FMA.
        unsafe { Ymm2(__m256::fma(acc.0, a.0, b.0), __m256::fma(acc.1, a.1, b.1)) }
    }
    #[inline(always)]
    unsafe fn add(a: Self, b: Self) -> Self {
        // SAFETY: the caller guarantees AVX.
        unsafe { Ymm2(__m256::add(a.0, b.0), __m256::add(a.1, b.1)) }
    }
    #[inline(always)]
    unsafe fn relu(v: Self) -> Self {
        // SAFETY: the caller guarantees AVX.
        unsafe { Ymm2(__m256::relu(v.0), __m256::relu(v.1)) }
    }
    #[inline(always)]
    unsafe fn sub(a: Self, b: Self) -> Self {
        // SAFETY: the caller guarantees AVX.
        unsafe { Ymm2(__m256::sub(a.0, b.0), __m256::sub(a.1, b.1)) }
    }
    #[inline(always)]
    unsafe fn load_deinterleaved(p: *const f32) -> (Self, Self) {
        // SAFETY: the caller guarantees AVX2 and 32 readable values at `p`.
        unsafe {
            let (e0, o0) = __m256::load_deinterleaved(p);
            let (e1, o1) = __m256::load_deinterleaved(p.add(16));
            (Ymm2(e0, e1), Ymm2(o0, o1))
        }
    }
    #[inline(always)]
    unsafe fn interleave(e: Self, o: Self) -> (Self, Self) {
        // SAFETY: the caller guarantees AVX.
        unsafe {
            let (p0, p1) = __m256::interleave(e.0, o.0);
            let (p2, p3) = __m256::interleave(e.1, o.1);
            (Ymm2(p0, p1), Ymm2(p2, p3))
        }
    }
    #[inline(always)]
    unsafe fn load_stride4(p: *const f32) -> [Self; 4] {
        // SAFETY: the caller guarantees AVX and 64 readable values at `p`.
        unsafe {
            let lo = __m256::load_stride4(p);
            let hi = __m256::load_stride4(p.add(32));
            [0, 1, 2, 3].map(|j| Ymm2(lo[j], hi[j]))
        }
    }
    #[inline(always)]
    unsafe fn interleave4(c: [Self; 4]) -> [Self; 4] {
        // SAFETY: the caller guarantees AVX.
        unsafe {
            let lo = __m256::interleave4(c.map(|v| v.0));
            let hi = __m256::interleave4(c.map(|v| v.1));
            [
                Ymm2(lo[0], lo[1]),
                Ymm2(lo[2], lo[3]),
                Ymm2(hi[0], hi[1]),
                Ymm2(hi[2], hi[3]),
            ]
        }
    }
    #[inline(always)]
    unsafe fn keep_first(v: Self, n: usize) -> Self {
        // SAFETY: the caller guarantees AVX; `n < 16`, so each half gets `n < 8` or `n − 8 < 8`.
        unsafe {
            if n < 8 {
                Ymm2(__m256::keep_first(v.0, n), __m256::zero())
            } else if n == 8 {
                Ymm2(v.0, __m256::zero())
            } else {
                Ymm2(v.0, __m256::keep_first(v.1, n - 8))
            }
        }
    }
}

/// Tests only: the AVX-512 tile geometry (8 × 3 × 16 lanes) on AVX2 registers.
///
/// # Safety
/// As [`conv`].
#[cfg(test)]
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn conv_avx512_geometry(job: &F32Job<'_>, out: &mut F32Out<'_>) {
    // SAFETY: as `conv`; 48-pixel tile ≤ MAX_TILE.
    unsafe { generic_conv::<Ymm2, 8, 3>(job, out) }
}

/// Tests only: the geometry of `conv3x3.f32.6x4.avx512` (6 × 4 × 16 lanes) on AVX2 registers.
///
/// # Safety
/// As [`conv`].
#[cfg(test)]
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn conv6_avx512_geometry(job: &F32Job<'_>, out: &mut F32Out<'_>) {
    // SAFETY: as `conv`; 64-pixel tile ≤ MAX_TILE.
    unsafe { generic_conv::<Ymm2, 6, 4>(job, out) }
}

/// Tests only: the AVX-512 Winograd geometry (8 channels × 2 vectors of 16 lanes = 32 tiles) on AVX2
/// registers.
///
/// # Safety
/// As [`winograd`].
#[cfg(test)]
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn winograd_avx512_geometry(job: &F32Job<'_>, out: &mut F32Out<'_>) {
    // SAFETY: as `winograd`; 64-pixel tile ≤ MAX_TILE.
    unsafe { wino2x2::conv::<Ymm2, 8, 2>(job, out) }
}

/// `conv3x3.f32.wino4x4.6x2.avx2`: Winograd F(4×4, 3×3) with the direct row's 6 × 2 register tile (6 output
/// channels × 2 ymm of tiles: 16 tiles, 64 output pixels, the most `MAX_TILE` allows).
///
/// # Safety
/// The CPU has AVX2 and FMA; `job` was checked by the safe API and its weights packed for F(4×4, 3×3).
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn winograd4(job: &F32Job<'_>, out: &mut F32Out<'_>) {
    // SAFETY: AVX2 + FMA enabled here; 64-pixel tile ≤ MAX_TILE; the job was checked by the caller.
    unsafe { wino4x4::conv::<__m256, G, NV>(job, out) }
}

/// Tests only: the AVX-512 F(4×4, 3×3) geometry (8 channels × 1 vector of 16 lanes = 16 tiles) on AVX2
/// registers.
///
/// # Safety
/// As [`winograd4`].
#[cfg(test)]
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn winograd4_avx512_geometry(job: &F32Job<'_>, out: &mut F32Out<'_>) {
    // SAFETY: as `winograd4`; 64-pixel tile ≤ MAX_TILE.
    unsafe { wino4x4::conv::<Ymm2, 8, 1>(job, out) }
}

/// Tests only: the wide AVX-512 F(4×4, 3×3) geometry (24 channels × 1 vector of 16 lanes = 16 tiles) on AVX2
/// registers (they spill: correctness only).
///
/// # Safety
/// As [`winograd4`].
#[cfg(test)]
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn winograd4_wide_avx512_geometry(job: &F32Job<'_>, out: &mut F32Out<'_>) {
    // SAFETY: as `winograd4`; 64-pixel tile ≤ MAX_TILE.
    unsafe { wino4x4::conv::<Ymm2, 24, 1>(job, out) }
}

//! `conv3x3.f32.8x3.neon`: aarch64 Advanced SIMD, 128-bit registers.
//!
//! Register tile: 8 output channels × 3 q registers (12 pixels) = 24 accumulators, + 3 input vectors + 1
//! broadcast weight (`ld1r`) = 28 of the 32 q registers. Per reduction step: 3 loads + 8 broadcast loads for
//! 24 FMAs. Shares the generic loop [`simd_f32::conv`](super::simd_f32::conv) with the x86 rows.

use super::job::{entry_points, F32Job, F32Out};
use super::simd_f32::{conv as generic_conv, peak_chains, ConvF32};
use super::{wino2x2, wino4x4};
use std::arch::aarch64::*;

/// Output-channel tile.
pub(crate) const G: usize = 8;
/// q vectors of pixels per tile.
pub(crate) const NV: usize = 3;

static MASK: [u32; 8] = [u32::MAX, u32::MAX, u32::MAX, u32::MAX, 0, 0, 0, 0];

impl ConvF32 for float32x4_t {
    #[inline(always)]
    unsafe fn fma(acc: Self, a: Self, b: Self) -> Self {
        // SAFETY: NEON.
        unsafe { vfmaq_f32(acc, a, b) }
    }
    #[inline(always)]
    unsafe fn fma_step<const G: usize, const NV: usize>(
        acc: &mut [[Self; NV]; G],
        x: &[Self; NV],
        w: *const f32,
    ) {
        // Four weights per q register, each used by element: every NEON row's `G` is a multiple of 4 (8).
        const {
            assert!(
                G.is_multiple_of(4),
                "NEON f32 tiles take output channels in fours"
            )
        };
        for q in 0..G / 4 {
            // SAFETY: weights `4q..4q + 4 ≤ G` at `w`.
            let wq = unsafe { vld1q_f32(w.add(4 * q)) };
            for v in 0..NV {
                // SAFETY: NEON is baseline on aarch64; `4q + 3 < G`.
                unsafe {
                    acc[4 * q][v] = vfmaq_laneq_f32::<0>(acc[4 * q][v], x[v], wq);
                    acc[4 * q + 1][v] = vfmaq_laneq_f32::<1>(acc[4 * q + 1][v], x[v], wq);
                    acc[4 * q + 2][v] = vfmaq_laneq_f32::<2>(acc[4 * q + 2][v], x[v], wq);
                    acc[4 * q + 3][v] = vfmaq_laneq_f32::<3>(acc[4 * q + 3][v], x[v], wq);
                }
            }
        }
    }
    #[inline(always)]
    unsafe fn interleave(e: Self, o: Self) -> (Self, Self) {
        // SAFETY: NEON is baseline on aarch64.
        unsafe { (vzip1q_f32(e, o), vzip2q_f32(e, o)) }
    }
    #[inline(always)]
    unsafe fn load_stride4(p: *const f32) -> [Self; 4] {
        // SAFETY: NEON; the caller guarantees 16 readable values at `p`. `ld4`: lane `i` of register `j` is
        // `p[4i + j]` (the identity permutation).
        unsafe {
            let q = vld4q_f32(p);
            [q.0, q.1, q.2, q.3]
        }
    }
    #[inline(always)]
    unsafe fn next_columns(p: *const f32, c0: Self, c1: Self) -> [Self; 2] {
        // SAFETY: NEON; the caller guarantees 18 readable values at `p`. Lane `i` holds quadruple `i`, so the
        // next quadruple's values are one lane on (`ext`), the last lane's from `p[16]`, `p[17]`.
        unsafe {
            [
                vextq_f32::<1>(c0, vdupq_n_f32(*p.add(16))),
                vextq_f32::<1>(c1, vdupq_n_f32(*p.add(17))),
            ]
        }
    }
    #[inline(always)]
    unsafe fn interleave4(c: [Self; 4]) -> [Self; 4] {
        // SAFETY: NEON. The 4×4 transpose: register `i` = lane `i` of `c[0..4]`.
        unsafe {
            let (x0, x1) = (vzip1q_f32(c[0], c[2]), vzip2q_f32(c[0], c[2]));
            let (y0, y1) = (vzip1q_f32(c[1], c[3]), vzip2q_f32(c[1], c[3]));
            [
                vzip1q_f32(x0, y0),
                vzip2q_f32(x0, y0),
                vzip1q_f32(x1, y1),
                vzip2q_f32(x1, y1),
            ]
        }
    }
    #[inline(always)]
    unsafe fn relu(v: Self) -> Self {
        // SAFETY: NEON.
        unsafe { vmaxq_f32(v, vdupq_n_f32(0.0)) }
    }
    #[inline(always)]
    unsafe fn keep_first(v: Self, n: usize) -> Self {
        debug_assert!(n < 4);
        // SAFETY: NEON; `4 − n ∈ 1..=4`, so the 4 mask values read are inside MASK.
        unsafe {
            let m = vld1q_u32(MASK.as_ptr().add(4 - n));
            vreinterpretq_f32_u32(vandq_u32(vreinterpretq_u32_f32(v), m))
        }
    }
}

entry_points! {
    "neon", F32Job, F32Out;
    /// The registry entry (12-pixel tile).
    ///
    /// # Safety
    /// `job` was checked by the safe API (NEON is always present on aarch64).
    fn conv = generic_conv::<float32x4_t, G, NV>;
    /// `conv3x3.f32.wino2x2.8x3.neon`: Winograd F(2×2, 3×3) with the direct row's 8 × 3 register tile (8
    /// output channels × 12 tiles = 24 output pixels of two rows).
    ///
    /// # Safety
    /// `job` was checked by the safe API and its weights packed for Winograd.
    fn winograd = wino2x2::conv::<float32x4_t, G, NV>;
    /// `conv3x3.f32.wino4x4.8x3.neon`: Winograd F(4×4, 3×3) with the direct row's 8 × 3 register tile (8
    /// output channels × 3 q registers of tiles: 12 tiles, 48 output pixels).
    ///
    /// # Safety
    /// `job` was checked by the safe API and its weights packed for F(4×4, 3×3).
    fn winograd4 = wino4x4::conv::<float32x4_t, G, NV>;
}

/// FMA peak loop: `iters` × 24 independent 4-lane FMAs. FLOPs = `iters · 24 · 4 · 2`.
///
/// # Safety
/// None beyond NEON, which every aarch64 CPU has.
#[target_feature(enable = "neon")]
pub(crate) unsafe fn peak(iters: u64) -> f32 {
    // SAFETY: NEON enabled here and present on every aarch64 CPU.
    vaddvq_f32(unsafe { peak_chains::<float32x4_t, 24>(iters) })
}

//! `conv3x3.u8s8.4x1.neon`: the int8 row for aarch64 without the dot product (Cortex-A53 class), on the
//! generic loop [`simd_u8::conv`](super::simd_u8::conv): inputs widened to i16 (`uxtl`), `smlal` with i16
//! weights; one q accumulator per pixel holds the 4 channel partial sums, added pairwise once per tile
//! (`addp`). 4 output channels × 4 pixels = 16 accumulators.
//!
//! The NEON f32 epilogue (macro `epilogue_neon`) is written once here and shared by the dot-product rows
//! ([`u8s8_neondot`](super::u8s8_neondot), [`u8s8_neoni8mm`](super::u8s8_neoni8mm)).

use super::job::{U8Job, U8Out};
use super::simd_u8::{conv, SimdQ};
use std::arch::aarch64::*;

/// Lane numbers 0–3: the lanes below `valid` of a partial store.
pub(super) static LANE_INDEX: [u32; 4] = [0, 1, 2, 3];

/// Widening accumulator: 4 pixels, one q register (4 channel partials) each.
#[derive(Clone, Copy)]
pub(crate) struct NeonWide([int32x4_t; 4]);

macro_rules! epilogue_neon {
    () => {
        type F = float32x4_t;
        #[inline(always)]
        unsafe fn splat(v: f32) -> float32x4_t {
            // SAFETY: NEON.
            unsafe { vdupq_n_f32(v) }
        }
        #[inline(always)]
        unsafe fn mul(a: float32x4_t, b: float32x4_t) -> float32x4_t {
            // SAFETY: NEON.
            unsafe { vmulq_f32(a, b) }
        }
        #[inline(always)]
        unsafe fn add(a: float32x4_t, b: float32x4_t) -> float32x4_t {
            // SAFETY: NEON.
            unsafe { vaddq_f32(a, b) }
        }
        #[inline(always)]
        unsafe fn sub(a: float32x4_t, b: float32x4_t) -> float32x4_t {
            // SAFETY: NEON.
            unsafe { vsubq_f32(a, b) }
        }
        #[inline(always)]
        unsafe fn relu(v: float32x4_t) -> float32x4_t {
            // SAFETY: NEON. `fmax(v, +0)`: −0 gives +0 as the scalar `v > 0 ? v : 0` (no NaN reaches here).
            unsafe { vmaxq_f32(v, vdupq_n_f32(0.0)) }
        }
        #[inline(always)]
        unsafe fn load_byte(p: *const u8, lane: usize) -> float32x4_t {
            // SAFETY: NEON; the caller guarantees 16 readable bytes at `p`.
            unsafe {
                let w = vreinterpretq_u32_u8(vld1q_u8(p));
                let s = vshlq_u32(w, vdupq_n_s32(-8 * lane as i32));
                vcvtq_f32_u32(vandq_u32(s, vdupq_n_u32(0xFF)))
            }
        }
        #[inline(always)]
        unsafe fn quant(v: float32x4_t, inv: float32x4_t, zp: float32x4_t) -> float32x4_t {
            // SAFETY: NEON. `frintn` rounds to nearest even.
            unsafe {
                let r = vrndnq_f32(vmulq_f32(v, inv));
                let y = vmaxq_f32(vaddq_f32(r, zp), vdupq_n_f32(0.0));
                vminq_f32(y, vdupq_n_f32(255.0))
            }
        }
        #[inline(always)]
        unsafe fn store_u8x4(p: *mut u8, q: [float32x4_t; 4], valid: usize, border: u8) {
            // SAFETY: NEON; the caller guarantees 16 writable bytes at `p`.
            unsafe {
                let mut word = vcvtq_u32_f32(q[0]);
                word = vorrq_u32(word, vshlq_n_u32::<8>(vcvtq_u32_f32(q[1])));
                word = vorrq_u32(word, vshlq_n_u32::<16>(vcvtq_u32_f32(q[2])));
                word = vorrq_u32(word, vshlq_n_u32::<24>(vcvtq_u32_f32(q[3])));
                if valid < 4 {
                    let keep = vcltq_u32(vld1q_u32(LANE_INDEX.as_ptr()), vdupq_n_u32(valid as u32));
                    let b = vdupq_n_u32(u32::from_ne_bytes([border; 4]));
                    word = vbslq_u32(keep, word, b);
                }
                vst1q_u8(p, vreinterpretq_u8_u32(word))
            }
        }
        #[inline(always)]
        unsafe fn store_f32(p: *mut f32, v: float32x4_t, valid: usize) {
            // SAFETY: NEON; the caller guarantees `valid` writable values at `p`; `tmp` holds 4.
            unsafe {
                if valid == 4 {
                    vst1q_f32(p, v)
                } else {
                    let mut tmp = [0.0f32; 4];
                    vst1q_f32(tmp.as_mut_ptr(), v);
                    std::ptr::copy_nonoverlapping(tmp.as_ptr(), p, valid);
                }
            }
        }
    };
}
pub(super) use epilogue_neon;

impl SimdQ for NeonWide {
    const PX: usize = 4;
    const WB: usize = 8;
    type X = (int16x8_t, int16x8_t);
    type W = int16x8_t;
    epilogue_neon!();
    #[inline(always)]
    unsafe fn init(v: i32) -> Self {
        // SAFETY: NEON. Only lane 0 of each pixel's register starts at `v`.
        unsafe {
            let s = vsetq_lane_s32::<0>(v, vdupq_n_s32(0));
            NeonWide([s; 4])
        }
    }
    #[inline(always)]
    unsafe fn load_x(p: *const u8) -> Self::X {
        // SAFETY: NEON; 16 readable bytes at `p`.
        unsafe {
            let v = vld1q_u8(p);
            (
                vreinterpretq_s16_u16(vmovl_u8(vget_low_u8(v))),
                vreinterpretq_s16_u16(vmovl_high_u8(v)),
            )
        }
    }
    #[inline(always)]
    unsafe fn load_w(p: *const u8) -> Self::W {
        // SAFETY: NEON; 8 readable bytes at `p` (4 × i16), duplicated into both halves.
        unsafe { vreinterpretq_s16_u64(vdupq_n_u64(p.cast::<u64>().read_unaligned())) }
    }
    #[inline(always)]
    unsafe fn dot(self, x: Self::X, w: Self::W) -> Self {
        // SAFETY: NEON. i16 × i16 → i32 multiply-accumulate, exact.
        unsafe {
            let [a0, a1, a2, a3] = self.0;
            let wl = vget_low_s16(w);
            NeonWide([
                vmlal_s16(a0, vget_low_s16(x.0), wl),
                vmlal_high_s16(a1, x.0, w),
                vmlal_s16(a2, vget_low_s16(x.1), wl),
                vmlal_high_s16(a3, x.1, w),
            ])
        }
    }
    #[inline(always)]
    unsafe fn to_f32(self) -> float32x4_t {
        // SAFETY: NEON. Two pairwise adds leave one sum per pixel, in pixel order.
        unsafe {
            let [a0, a1, a2, a3] = self.0;
            vcvtq_f32_s32(vpaddq_s32(vpaddq_s32(a0, a1), vpaddq_s32(a2, a3)))
        }
    }
}

/// `conv3x3.u8s8.4x1.neon`.
///
/// # Safety
/// The job was checked by the safe API and packed with `PackKind::I16`.
#[target_feature(enable = "neon")]
pub(crate) unsafe fn conv_wide(job: &U8Job<'_>, out: &mut U8Out<'_>) {
    // SAFETY: NEON; the caller's guarantees.
    unsafe { conv::<NeonWide, 4, 1>(job, out) }
}

/// `smlal` peak: 24 chains of 4 multiply-adds; ops = `iters · 24 · 4 · 2`.
///
/// # Safety
/// NEON only.
#[target_feature(enable = "neon")]
pub(crate) unsafe fn peak_wide(iters: u64) -> i32 {
    let mut acc = [vdupq_n_s32(1); 24];
    let w = vdup_n_s16(-2);
    for _ in 0..iters {
        for a in acc.iter_mut() {
            // The product depends on the accumulator, so it cannot be hoisted out of the loop.
            *a = vmlal_s16(*a, vget_low_s16(vreinterpretq_s16_s32(*a)), w);
        }
    }
    acc.iter().fold(0, |s, &a| s.wrapping_add(vaddvq_s32(a)))
}

//! `conv3x3.u8s8.8x3.neoni8mm`: `USDOT` (FEAT_I8MM), u8 × s8 directly, on the generic loop
//! [`simd_u8::conv`](super::simd_u8::conv). 8 output channels × 3 q (12 pixels) = 24 accumulators, 3 inputs
//! and 2 weight registers of 32 q. The by-element `step4` is the dot-product row's (macro `step4_by_element`
//! from [`u8s8_neondot`](super::u8s8_neondot), which explains it), the f32 epilogue the NEON row's (macro
//! `epilogue_neon` from [`u8s8_neon`](super::u8s8_neon)); `USDOT` is written with `asm!` as `SDOT` is there.

use super::job::{U8Job, U8Out};
use super::simd_u8::{conv, SimdQ};
use super::u8s8_neon::{epilogue_neon, LANE_INDEX};
use super::u8s8_neondot::step4_by_element;
use std::arch::aarch64::*;
use std::arch::asm;

/// USDOT accumulator: 4 pixels.
#[derive(Clone, Copy)]
pub(crate) struct NeonUsdot(int32x4_t);

impl SimdQ for NeonUsdot {
    const PX: usize = 4;
    const WB: usize = 4;
    type X = uint8x16_t;
    type W = int8x16_t;
    epilogue_neon!();
    step4_by_element!("i8mm", "usdot");
    #[inline(always)]
    unsafe fn init(v: i32) -> Self {
        // SAFETY: NEON.
        unsafe { NeonUsdot(vdupq_n_s32(v)) }
    }
    #[inline(always)]
    unsafe fn load_x(p: *const u8) -> Self::X {
        // SAFETY: NEON; 16 readable bytes.
        unsafe { vld1q_u8(p) }
    }
    #[inline(always)]
    unsafe fn load_w(p: *const u8) -> Self::W {
        // SAFETY: NEON; 4 readable bytes.
        unsafe { vreinterpretq_s8_u32(vdupq_n_u32(p.cast::<u32>().read_unaligned())) }
    }
    #[inline(always)]
    unsafe fn dot(self, x: Self::X, w: Self::W) -> Self {
        let mut acc = self.0;
        // SAFETY: USDOT exists: the caller runs this only in a function compiled with `i8mm` on a CPU that
        // has it; register-only, no memory access.
        unsafe {
            asm!(
                ".arch_extension i8mm",
                "usdot {acc:v}.4s, {x:v}.16b, {w:v}.16b",
                acc = inout(vreg) acc,
                x = in(vreg) x,
                w = in(vreg) w,
                options(pure, nomem, nostack, preserves_flags)
            )
        };
        NeonUsdot(acc)
    }
    #[inline(always)]
    unsafe fn to_f32(self) -> float32x4_t {
        // SAFETY: NEON.
        unsafe { vcvtq_f32_s32(self.0) }
    }
}

/// `conv3x3.u8s8.8x3.neoni8mm`.
///
/// # Safety
/// The CPU has i8mm; the job was checked and packed with `PackKind::I8`.
#[target_feature(enable = "neon,dotprod,i8mm")]
pub(crate) unsafe fn conv_i8mm(job: &U8Job<'_>, out: &mut U8Out<'_>) {
    // SAFETY: i8mm enabled; the caller's guarantees.
    unsafe { conv::<NeonUsdot, 8, 3>(job, out) }
}

/// USDOT peak: 24 chains of 16 multiply-adds; ops = `iters · 24 · 16 · 2`.
///
/// # Safety
/// The CPU has i8mm.
#[target_feature(enable = "neon,dotprod,i8mm")]
pub(crate) unsafe fn peak_i8mm(iters: u64) -> i32 {
    let mut acc = [NeonUsdot(vdupq_n_s32(1)); 24];
    let x = vdupq_n_u8(3);
    let w = vdupq_n_s8(-2);
    for _ in 0..iters {
        for a in acc.iter_mut() {
            // SAFETY: i8mm enabled here and present on the CPU (the caller's guarantee).
            *a = unsafe { a.dot(x, w) };
        }
    }
    acc.iter().fold(0, |s, a| s.wrapping_add(vaddvq_s32(a.0)))
}

//! `conv3x3.u8s8.8x3.neoni8mm`: `USDOT` (FEAT_I8MM), u8 × s8 directly, on the generic loop
//! [`simd_u8::conv`](super::simd_u8::conv). 8 output channels × 3 q (12 pixels) = 24 accumulators, 3 inputs
//! and 2 weight registers of 32 q. All but `load_x` is the dot-product row's (macros `dot_by_element` and
//! `dot_entry_points` from [`u8s8_neondot`](super::u8s8_neondot), which explains the by-element `step4`),
//! the f32 epilogue the NEON row's (macro `epilogue_neon` from [`u8s8_neon`](super::u8s8_neon)); `USDOT` is
//! written with `asm!` as `SDOT` is there.

use super::job::{entry_points, U8Job, U8Out};
use super::simd_u8::{conv, peak_chains, SimdQ};
use super::u8s8_neon::{epilogue_neon, LANE_INDEX};
use super::u8s8_neondot::{dot_by_element, dot_entry_points};
use std::arch::aarch64::*;
use std::arch::asm;

/// USDOT accumulator: 4 pixels.
#[derive(Clone, Copy)]
pub(crate) struct NeonUsdot(int32x4_t);

impl SimdQ for NeonUsdot {
    type X = uint8x16_t;
    dot_by_element!(NeonUsdot, "i8mm", "usdot");
    #[inline(always)]
    unsafe fn load_x(p: *const u8) -> Self::X {
        // SAFETY: NEON; 16 readable bytes.
        unsafe { vld1q_u8(p) }
    }
}

dot_entry_points! {
    "neon,dotprod,i8mm", NeonUsdot, vdupq_n_u8(3);
    /// `conv3x3.u8s8.8x3.neoni8mm`.
    ///
    /// # Safety
    /// The CPU has i8mm; the job was checked and packed with `PackKind::I8`.
    fn conv_i8mm;
    /// USDOT peak.
    ///
    /// # Safety
    /// The CPU has i8mm.
    fn peak_i8mm;
}

//! `conv3x3.u8s8.8x3.neondot`: `SDOT` (FEAT_DotProd) on `q ⊕ 0x80 = q − 128` (s8) × s8, on the generic
//! loop [`simd_u8::conv`](super::simd_u8::conv); the packing adds `128·Σw` to the accumulator start. 8 output
//! channels × 3 q (12 pixels) = 24 accumulators + 3 inputs + 2 weight registers of 32 q.
//!
//! The dot-product rows (this one and [`u8s8_neoni8mm`](super::u8s8_neoni8mm)) load the weights of four
//! output channels in one q register and use the instructions' by-element form (`sdot v.4s, x.16b,
//! w.4b[l]`, macro `step4_by_element`, [`SimdQ::step4`]): per reduction step of the 8 × 3 tile, 3 input loads
//! (+ 3 `eor` for SDOT), 2 weight loads and 24 dot products, against 8 broadcast loads with the plain form (a
//! sixth fewer instructions in the inner loop).
//!
//! `SDOT`/`USDOT` are written with `asm!` (the `vdotq`/`vusdotq` intrinsics are not stable at the crate's
//! MSRV) inside functions compiled with the `dotprod`/`i8mm` target features. The f32 epilogue is the NEON
//! row's (macro `epilogue_neon` from [`u8s8_neon`](super::u8s8_neon)).

use super::job::{U8Job, U8Out};
use super::simd_u8::{conv, SimdQ};
use super::u8s8_neon::{epilogue_neon, LANE_INDEX};
use std::arch::aarch64::*;
use std::arch::asm;

/// SDOT accumulator: 4 pixels.
#[derive(Clone, Copy)]
pub(crate) struct NeonSdot(int32x4_t);

/// `step4` of a path with a dot product by element: the four channels' 4-byte weight groups in one q
/// register (one `ldr q`), then `<insn> acc.4s, x.16b, w.4b[l]` per channel `l` and pixel unit: 1 weight
/// load per 4 output channels instead of 4 broadcasts (`ld1r`).
macro_rules! step4_by_element {
    ($ext:literal, $insn:literal) => {
        #[inline(always)]
        unsafe fn step4<const NV: usize>(acc: &mut [[Self; NV]], x: &[Self::X; NV], p: *const u8) {
            // SAFETY: NEON; the caller guarantees 16 readable bytes at `p`.
            let w4 = unsafe { vreinterpretq_s8_u8(vld1q_u8(p)) };
            for (l, accg) in acc.iter_mut().enumerate().take(4) {
                for (a, &xv) in accg.iter_mut().zip(x.iter()) {
                    let mut r = a.0;
                    // SAFETY: the instruction exists: the caller runs this only in a function compiled with
                    // its extension on a CPU that has it; register-only, no memory access.
                    unsafe {
                        macro_rules! lane {
                            ($i:literal) => {
                                asm!(
                                    concat!(".arch_extension ", $ext),
                                    concat!($insn, " {acc:v}.4s, {x:v}.16b, {w:v}.4b[", $i, "]"),
                                    acc = inout(vreg) r,
                                    x = in(vreg) xv,
                                    w = in(vreg) w4,
                                    options(pure, nomem, nostack, preserves_flags)
                                )
                            };
                        }
                        match l {
                            0 => lane!("0"),
                            1 => lane!("1"),
                            2 => lane!("2"),
                            _ => lane!("3"),
                        }
                    }
                    *a = Self(r);
                }
            }
        }
    };
}
pub(super) use step4_by_element;

impl SimdQ for NeonSdot {
    const PX: usize = 4;
    const WB: usize = 4;
    type X = int8x16_t;
    type W = int8x16_t;
    epilogue_neon!();
    step4_by_element!("dotprod", "sdot");
    #[inline(always)]
    unsafe fn init(v: i32) -> Self {
        // SAFETY: NEON.
        unsafe { NeonSdot(vdupq_n_s32(v)) }
    }
    #[inline(always)]
    unsafe fn load_x(p: *const u8) -> Self::X {
        // SAFETY: NEON; 16 readable bytes. `q ⊕ 0x80` read as s8 is `q − 128`.
        unsafe { vreinterpretq_s8_u8(veorq_u8(vld1q_u8(p), vdupq_n_u8(0x80))) }
    }
    #[inline(always)]
    unsafe fn load_w(p: *const u8) -> Self::W {
        // SAFETY: NEON; 4 readable bytes.
        unsafe { vreinterpretq_s8_u32(vdupq_n_u32(p.cast::<u32>().read_unaligned())) }
    }
    #[inline(always)]
    unsafe fn dot(self, x: Self::X, w: Self::W) -> Self {
        let mut acc = self.0;
        // SAFETY: SDOT exists: the caller runs this only in a function compiled with `dotprod` on a CPU that
        // has it; register-only, no memory access.
        unsafe {
            asm!(
                ".arch_extension dotprod",
                "sdot {acc:v}.4s, {x:v}.16b, {w:v}.16b",
                acc = inout(vreg) acc,
                x = in(vreg) x,
                w = in(vreg) w,
                options(pure, nomem, nostack, preserves_flags)
            )
        };
        NeonSdot(acc)
    }
    #[inline(always)]
    unsafe fn to_f32(self) -> float32x4_t {
        // SAFETY: NEON.
        unsafe { vcvtq_f32_s32(self.0) }
    }
}

/// `conv3x3.u8s8.8x3.neondot`.
///
/// # Safety
/// The CPU has the dot product; the job was checked and packed with `PackKind::I8Xor128`.
#[target_feature(enable = "neon,dotprod")]
pub(crate) unsafe fn conv_dot(job: &U8Job<'_>, out: &mut U8Out<'_>) {
    // SAFETY: dotprod enabled; the caller's guarantees.
    unsafe { conv::<NeonSdot, 8, 3>(job, out) }
}

/// SDOT peak: 24 chains of 16 multiply-adds; ops = `iters · 24 · 16 · 2`.
///
/// # Safety
/// The CPU has the dot product.
#[target_feature(enable = "neon,dotprod")]
pub(crate) unsafe fn peak_dot(iters: u64) -> i32 {
    let mut acc = [NeonSdot(vdupq_n_s32(1)); 24];
    let x = vdupq_n_s8(3);
    let w = vdupq_n_s8(-2);
    for _ in 0..iters {
        for a in acc.iter_mut() {
            // SAFETY: dotprod enabled here and present on the CPU (the caller's guarantee).
            *a = unsafe { a.dot(x, w) };
        }
    }
    acc.iter().fold(0, |s, a| s.wrapping_add(vaddvq_s32(a.0)))
}

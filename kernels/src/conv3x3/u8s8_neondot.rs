//! `conv3x3.u8s8.8x3.neondot`: `SDOT` (FEAT_DotProd) on `q ⊕ 0x80 = q − 128` (s8) × s8, on the generic
//! loop [`simd_u8::conv`](super::simd_u8::conv); the packing adds `128·Σw` to the accumulator start. 8 output
//! channels × 3 q (12 pixels) = 24 accumulators + 3 inputs + 2 weight registers of 32 q.
//!
//! The dot-product rows (this one and [`u8s8_neoni8mm`](super::u8s8_neoni8mm)) load the weights of four
//! output channels in one q register and use the instructions' by-element form (`sdot v.4s, x.16b,
//! w.4b[l]`, [`SimdQ::step4`]; macro `dot_by_element`, which writes the two rows' common parts once): per reduction step of the 8 × 3 tile, 3 input loads
//! (+ 3 `eor` for SDOT), 2 weight loads and 24 dot products, against 8 broadcast loads with the plain form (a
//! sixth fewer instructions in the inner loop).
//!
//! `SDOT`/`USDOT` are written with `asm!` (the `vdotq`/`vusdotq` intrinsics are not stable at the crate's
//! MSRV) inside functions compiled with the `dotprod`/`i8mm` target features. The f32 epilogue is the NEON
//! row's (macro `epilogue_neon` from [`u8s8_neon`](super::u8s8_neon)).

use super::job::{entry_points, U8Job, U8Out};
use super::simd_u8::{conv, peak_chains, SimdQ};
use super::u8s8_neon::{epilogue_neon, LANE_INDEX};
use std::arch::aarch64::*;
use std::arch::asm;

/// SDOT accumulator: 4 pixels.
#[derive(Clone, Copy)]
pub(crate) struct NeonSdot(int32x4_t);

/// What the dot-product rows share, for an accumulator type `$q` (one `int32x4_t`: 4 pixels) whose `dot` is
/// `<$insn> acc.4s, x.16b, w.16b` under the target feature `$ext`: in `impl SimdQ for $q`, the constants, the
/// weight type, the NEON epilogue, `init`, `load_w`, `dot`, `to_f32` and the by-element `step4` (the four
/// channels' 4-byte weight groups in one q register, one `ldr q`, then `<$insn> acc.4s, x.16b, w.4b[l]` per
/// channel `l` and pixel unit: 1 weight load per 4 output channels instead of 4 broadcasts, `ld1r`);
/// `load_x` and the type `X` are the row's own.
macro_rules! dot_by_element {
    ($q:ident, $ext:literal, $insn:literal) => {
        const PX: usize = 4;
        const WB: usize = 4;
        type W = int8x16_t;
        epilogue_neon!();
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
        #[inline(always)]
        unsafe fn init(v: i32) -> Self {
            // SAFETY: NEON.
            unsafe { $q(vdupq_n_s32(v)) }
        }
        #[inline(always)]
        unsafe fn load_w(p: *const u8) -> Self::W {
            // SAFETY: NEON; 4 readable bytes.
            unsafe { vreinterpretq_s8_u32(vdupq_n_u32(p.cast::<u32>().read_unaligned())) }
        }
        #[inline(always)]
        unsafe fn dot(self, x: Self::X, w: Self::W) -> Self {
            let mut acc = self.0;
            // SAFETY: the instruction exists: the caller runs this only in a function compiled with its
            // extension on a CPU that has it; register-only, no memory access.
            unsafe {
                asm!(
                    concat!(".arch_extension ", $ext),
                    concat!($insn, " {acc:v}.4s, {x:v}.16b, {w:v}.16b"),
                    acc = inout(vreg) acc,
                    x = in(vreg) x,
                    w = in(vreg) w,
                    options(pure, nomem, nostack, preserves_flags)
                )
            };
            $q(acc)
        }
        #[inline(always)]
        unsafe fn to_f32(self) -> float32x4_t {
            // SAFETY: NEON.
            unsafe { vcvtq_f32_s32(self.0) }
        }
    };
}
pub(super) use dot_by_element;

/// The entry points of a dot-product row (8 × 3 tile of `$q`) and of its peak loop (24 chains of 16
/// multiply-adds from `x` = `$x` and `w` = −2; ops = `iters · 24 · 16 · 2`), compiled with `$features`.
macro_rules! dot_entry_points {
    ($features:literal, $q:ident, $x:expr; $(#[$conv_attr:meta])* fn $conv:ident; $(#[$peak_attr:meta])* fn $peak:ident;) => {
        entry_points! {
            $features, U8Job, U8Out;
            $(#[$conv_attr])*
            fn $conv = conv::<$q, 8, 3>;
        }
        $(#[$peak_attr])*
        #[target_feature(enable = $features)]
        pub(crate) unsafe fn $peak(iters: u64) -> i32 {
            // SAFETY: the features are enabled here and present on the CPU (the caller's guarantee).
            let acc = unsafe { peak_chains::<$q, 24>(iters, $x, vdupq_n_s8(-2)) };
            acc.iter().fold(0, |s, a| s.wrapping_add(vaddvq_s32(a.0)))
        }
    };
}
pub(super) use dot_entry_points;

impl SimdQ for NeonSdot {
    type X = int8x16_t;
    dot_by_element!(NeonSdot, "dotprod", "sdot");
    #[inline(always)]
    unsafe fn load_x(p: *const u8) -> Self::X {
        // SAFETY: NEON; 16 readable bytes. `q ⊕ 0x80` read as s8 is `q − 128`.
        unsafe { vreinterpretq_s8_u8(veorq_u8(vld1q_u8(p), vdupq_n_u8(0x80))) }
    }
}

dot_entry_points! {
    "neon,dotprod", NeonSdot, vdupq_n_s8(3);
    /// `conv3x3.u8s8.8x3.neondot`.
    ///
    /// # Safety
    /// The CPU has the dot product; the job was checked and packed with `PackKind::I8Xor128`.
    fn conv_dot;
    /// SDOT peak.
    ///
    /// # Safety
    /// The CPU has the dot product.
    fn peak_dot;
}

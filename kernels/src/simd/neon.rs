//! [`SimdF32`] on `float32x4_t` (4 lanes): aarch64 Advanced SIMD. Masks are `uint32x4_t` of all-ones /
//! all-zeros lanes, selects `bsl`; `min`/`max` are a compare and a select (x86's NaN rule, not `fmin`'s).

use super::SimdF32;
use std::arch::aarch64::*;

/// `a` and `b` combined by the `uint32x4_t` operation `op`, as f32.
macro_rules! bits {
    ($op:ident) => {
        |a: float32x4_t, b: float32x4_t| {
            vreinterpretq_f32_u32($op(vreinterpretq_u32_f32(a), vreinterpretq_u32_f32(b)))
        }
    };
}

impl SimdF32 for float32x4_t {
    const LANES: usize = 4;
    type Mask = uint32x4_t;
    type I32 = int32x4_t;

    ops! { () -> Self = (0.0); zero: vdupq_n_f32 }
    ops! { (v: f32) -> Self = (v); splat: vdupq_n_f32 }
    ops! { (p: *const f32) -> Self = (p); load: vld1q_f32, load_splat: vld1q_dup_f32 }
    ops! { (p: *mut f32, v: Self) -> () = (p, v); store: vst1q_f32 }
    ops! { (v: Self) -> Self = (v); sqrt: vsqrtq_f32, abs: vabsq_f32 }
    ops! { (a: Self, b: Self) -> Self = (a, b);
    add: vaddq_f32, sub: vsubq_f32, mul: vmulq_f32, div: vdivq_f32,
    max: |a, b| vbslq_f32(vcgtq_f32(a, b), a, b),
    and: bits!(vandq_u32), or: bits!(vorrq_u32) }
    ops! { (a: Self, b: Self) -> Self::Mask = (a, b);
    lt: vcltq_f32, gt: vcgtq_f32, ge: vcgeq_f32, eq: vceqq_f32,
    ord: |a, b| vandq_u32(vceqq_f32(a, a), vceqq_f32(b, b)),
    unord: |a, b| vmvnq_u32(vandq_u32(vceqq_f32(a, a), vceqq_f32(b, b))) }
    ops! { (a: Self::Mask, b: Self::Mask) -> Self::Mask = (a, b); mask_or: vorrq_u32 }
    ops! { (m: Self::Mask, b: Self, a: Self) -> Self = (m, b, a); select: vbslq_f32 }
    ops! { (m: Self::Mask, v: Self) -> Self = (m, v);
    keep: |m, v| vreinterpretq_f32_u32(vandq_u32(vreinterpretq_u32_f32(v), m)),
    clear: |m, v| vreinterpretq_f32_u32(vbicq_u32(vreinterpretq_u32_f32(v), m)) }
    // `fcvtzs`: truncation, saturating, NaN → 0.
    ops! { (v: Self) -> Self::I32 = (v); to_i32: vcvtq_s32_f32 }
    ops! { (i: Self::I32) -> Self = (i); from_i32: vcvtq_f32_s32 }

    #[inline(always)]
    unsafe fn load_pairs(p: *const f32) -> (Self, Self) {
        // SAFETY: the caller guarantees 8 readable values at `p`; `ld2` deinterleaves pairs.
        unsafe {
            let v = vld2q_f32(p);
            (v.0, v.1)
        }
    }
    #[inline(always)]
    unsafe fn sign_mask(v: Self) -> Self::Mask {
        // SAFETY: NEON. The arithmetic shift spreads the sign bit over the lane.
        unsafe { vreinterpretq_u32_s32(vshrq_n_s32::<31>(vreinterpretq_s32_f32(v))) }
    }
    #[inline(always)]
    unsafe fn mask_any(m: Self::Mask) -> bool {
        // SAFETY: NEON.
        unsafe { vmaxvq_u32(m) != 0 }
    }
    #[inline(always)]
    unsafe fn inc_where(i: Self::I32, m: Self::Mask) -> Self::I32 {
        // SAFETY: NEON. A set lane of `m` is −1 as an i32.
        unsafe { vsubq_s32(i, vreinterpretq_s32_u32(m)) }
    }
}

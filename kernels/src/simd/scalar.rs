//! [`SimdF32`] on `f32` (one lane): the portable rows. Masks are `bool`.

use super::SimdF32;

/// `f32` from `u32` bits combined by `op`.
fn bits(a: f32, b: f32, op: impl Fn(u32, u32) -> u32) -> f32 {
    f32::from_bits(op(a.to_bits(), b.to_bits()))
}

impl SimdF32 for f32 {
    const LANES: usize = 1;
    type Mask = bool;
    type I32 = i32;

    #[inline(always)]
    unsafe fn zero() -> Self {
        0.0
    }
    #[inline(always)]
    unsafe fn splat(v: f32) -> Self {
        v
    }
    #[inline(always)]
    unsafe fn load_splat(p: *const f32) -> Self {
        // SAFETY: the caller guarantees a valid `p`.
        unsafe { *p }
    }
    #[inline(always)]
    unsafe fn load(p: *const f32) -> Self {
        // SAFETY: the caller guarantees a valid `p`.
        unsafe { *p }
    }
    #[inline(always)]
    unsafe fn store(p: *mut f32, v: Self) {
        // SAFETY: the caller guarantees a valid `p`.
        unsafe { *p = v }
    }
    #[inline(always)]
    unsafe fn load_pairs(p: *const f32) -> (Self, Self) {
        // SAFETY: the caller guarantees 2 readable values at `p`.
        unsafe { (*p, *p.add(1)) }
    }
    #[inline(always)]
    unsafe fn add(a: Self, b: Self) -> Self {
        a + b
    }
    #[inline(always)]
    unsafe fn sub(a: Self, b: Self) -> Self {
        a - b
    }
    #[inline(always)]
    unsafe fn mul(a: Self, b: Self) -> Self {
        a * b
    }
    #[inline(always)]
    unsafe fn div(a: Self, b: Self) -> Self {
        a / b
    }
    #[inline(always)]
    unsafe fn sqrt(v: Self) -> Self {
        v.sqrt()
    }
    #[inline(always)]
    unsafe fn max(a: Self, b: Self) -> Self {
        if a > b {
            a
        } else {
            b
        }
    }
    #[inline(always)]
    unsafe fn abs(v: Self) -> Self {
        v.abs()
    }
    #[inline(always)]
    unsafe fn and(a: Self, b: Self) -> Self {
        bits(a, b, |a, b| a & b)
    }
    #[inline(always)]
    unsafe fn or(a: Self, b: Self) -> Self {
        bits(a, b, |a, b| a | b)
    }
    #[inline(always)]
    unsafe fn lt(a: Self, b: Self) -> bool {
        a < b
    }
    #[inline(always)]
    unsafe fn gt(a: Self, b: Self) -> bool {
        a > b
    }
    #[inline(always)]
    unsafe fn ge(a: Self, b: Self) -> bool {
        a >= b
    }
    #[inline(always)]
    unsafe fn eq(a: Self, b: Self) -> bool {
        a == b
    }
    #[inline(always)]
    unsafe fn ord(a: Self, b: Self) -> bool {
        !a.is_nan() && !b.is_nan()
    }
    #[inline(always)]
    unsafe fn unord(a: Self, b: Self) -> bool {
        a.is_nan() || b.is_nan()
    }
    #[inline(always)]
    unsafe fn sign_mask(v: Self) -> bool {
        v.is_sign_negative()
    }
    #[inline(always)]
    unsafe fn mask_or(a: bool, b: bool) -> bool {
        a | b
    }
    #[inline(always)]
    unsafe fn mask_any(m: bool) -> bool {
        m
    }
    #[inline(always)]
    unsafe fn select(m: bool, b: Self, a: Self) -> Self {
        if m {
            b
        } else {
            a
        }
    }
    #[inline(always)]
    unsafe fn keep(m: bool, v: Self) -> Self {
        if m {
            v
        } else {
            0.0
        }
    }
    #[inline(always)]
    unsafe fn clear(m: bool, v: Self) -> Self {
        if m {
            0.0
        } else {
            v
        }
    }
    #[inline(always)]
    unsafe fn to_i32(v: Self) -> i32 {
        v as i32
    }
    #[inline(always)]
    unsafe fn from_i32(i: i32) -> Self {
        i as f32
    }
    #[inline(always)]
    unsafe fn inc_where(i: i32, m: bool) -> i32 {
        i.wrapping_add(i32::from(m))
    }
}

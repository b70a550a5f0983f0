//! The f32 register trait that the SIMD families share, in the style of tract-linalg's and XNNPACK's
//! micro-kernels: a family writes its body once, generic over [`SimdF32`], and each ISA keeps only a thin
//! `#[target_feature]` entry point that instantiates the body with its register type. Every method is
//! `#[inline(always)]`, so the body is compiled with the entry point's features.
//!
//! Implementations (one register per type, no wrapper): `__m256` (`avx2.rs`, 8 lanes, AVX2 + FMA), `__m512`
//! (`avx512.rs`, 16 lanes, AVX-512F only: bit operations go through the integer domain, masks are `k`
//! registers), `float32x4_t` (`neon.rs`, 4 lanes) and `f32` (`scalar.rs`, one lane, the portable rows). A
//! family adds its own operations as an extension trait: the conv3x3 rows' Winograd transposes and
//! multiply-add step (`conv3x3::simd_f32::ConvF32`), the double phase rows' pair loads, f64 sums and code
//! stores (`double_phase::simd::DpmSimd`).
//!
//! Semantics are those of the x86 instructions where they differ: [`max`](SimdF32::max) returns the second
//! operand when either is NaN (x86's `maxps`; the NEON impl selects by a compare to match), comparisons are
//! ordered and quiet (false on NaN, as Rust's `<`), [`to_i32`](SimdF32::to_i32) truncates (out-of-range lanes: `i32::MIN` on
//! x86, saturated on NEON and scalar). The generic bodies that need bit-exact results across ISAs (the
//! double phase rows) use only operations whose results agree.

/// [`SimdF32`] methods that are one intrinsic applied to their arguments: `PARAMS -> RET = ARGS; name:
/// intrinsic, …` (the parameters and the call's arguments as written once for every listed method).
macro_rules! ops {
    ($params:tt -> $ret:ty = $args:tt; $($name:ident: $f:expr),+ $(,)?) => {$(
        #[inline(always)]
        unsafe fn $name $params -> $ret {
            // SAFETY: the caller guarantees the implementation's ISA and, for a pointer, the values that
            // the trait method documents; the method is this one intrinsic.
            unsafe { $f $args }
        }
    )+};
}

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx512;
#[cfg(target_arch = "aarch64")]
mod neon;
#[cfg(test)]
mod pair;
mod scalar;
#[cfg(test)]
pub(crate) use pair::Pair;

/// One SIMD register of `LANES` f32 values. All methods are `unsafe`: the caller guarantees that the CPU has
/// the ISA of the implementation and that pointers are valid for `LANES` values.
///
/// Each family uses the subset its body needs (on aarch64 only conv3x3's), so a method may be unused in a
/// build: `dead_code` is allowed for the trait.
#[allow(dead_code)]
pub(crate) trait SimdF32: Copy {
    /// f32 lanes per register (at most 16).
    const LANES: usize;
    /// A per-lane condition: a register of all-ones / all-zeros lanes (AVX2, NEON), a `k` register
    /// (AVX-512), a `bool` (scalar).
    type Mask: Copy;
    /// `LANES` i32 lanes (the integer register of the same width).
    type I32: Copy;

    /// All lanes 0.
    unsafe fn zero() -> Self;
    /// All lanes `v`.
    unsafe fn splat(v: f32) -> Self;
    /// All lanes the f32 at `p` (a broadcast load: `vbroadcastss`, `ld1r`).
    unsafe fn load_splat(p: *const f32) -> Self;
    /// Unaligned load of `LANES` values.
    unsafe fn load(p: *const f32) -> Self;
    /// Unaligned store of `LANES` values.
    unsafe fn store(p: *mut f32, v: Self);
    /// The `LANES` pairs `(p[2i], p[2i + 1])` at `p` (`2·LANES` values) deinterleaved in order: lane `i` of
    /// the first register holds `p[2i]`, of the second `p[2i + 1]` (NEON's `ld2`).
    unsafe fn load_pairs(p: *const f32) -> (Self, Self);

    /// `a + b`.
    unsafe fn add(a: Self, b: Self) -> Self;
    /// `a − b`.
    unsafe fn sub(a: Self, b: Self) -> Self;
    /// `a · b` (never fused with a following add).
    unsafe fn mul(a: Self, b: Self) -> Self;
    /// `a / b` (IEEE, correctly rounded).
    unsafe fn div(a: Self, b: Self) -> Self;
    /// `√v` (IEEE, correctly rounded).
    unsafe fn sqrt(v: Self) -> Self;
    /// `a > b ? a : b` per lane (NaN: `b`, as `maxps`).
    unsafe fn max(a: Self, b: Self) -> Self;
    /// `|v|` (the sign bit cleared).
    unsafe fn abs(v: Self) -> Self;

    /// Bitwise `a & b`.
    unsafe fn and(a: Self, b: Self) -> Self;
    /// Bitwise `a | b`.
    unsafe fn or(a: Self, b: Self) -> Self;

    /// `a < b` (ordered: false on NaN).
    unsafe fn lt(a: Self, b: Self) -> Self::Mask;
    /// `a > b` (ordered).
    unsafe fn gt(a: Self, b: Self) -> Self::Mask;
    /// `a ≥ b` (ordered).
    unsafe fn ge(a: Self, b: Self) -> Self::Mask;
    /// `a = b` (ordered).
    unsafe fn eq(a: Self, b: Self) -> Self::Mask;
    /// Neither `a` nor `b` is NaN.
    unsafe fn ord(a: Self, b: Self) -> Self::Mask;
    /// `a` or `b` is NaN.
    unsafe fn unord(a: Self, b: Self) -> Self::Mask;
    /// The lanes whose sign bit is set (−0 and negative NaNs included). Only for [`select`](Self::select):
    /// on AVX2 it is `v` itself (`blendv` reads the sign bit).
    unsafe fn sign_mask(v: Self) -> Self::Mask;
    /// `a | b` on masks.
    unsafe fn mask_or(a: Self::Mask, b: Self::Mask) -> Self::Mask;
    /// Whether any lane of `m` is set.
    unsafe fn mask_any(m: Self::Mask) -> bool;

    /// `if m { b } else { a }` per lane.
    unsafe fn select(m: Self::Mask, b: Self, a: Self) -> Self;
    /// `if m { v } else { 0 }` per lane.
    unsafe fn keep(m: Self::Mask, v: Self) -> Self;
    /// `if m { 0 } else { v }` per lane.
    unsafe fn clear(m: Self::Mask, v: Self) -> Self;

    /// `v` truncated towards zero to i32 (`cvttps2dq`; out of range and NaN: see the module docs).
    unsafe fn to_i32(v: Self) -> Self::I32;
    /// `i` as f32 (rounded to nearest).
    unsafe fn from_i32(i: Self::I32) -> Self;
    /// `if m { i + 1 } else { i }` per lane (wrapping).
    unsafe fn inc_where(i: Self::I32, m: Self::Mask) -> Self::I32;
}

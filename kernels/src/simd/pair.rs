//! Tests only: two registers acting as one of twice the lanes ([`Pair`]), so that a generic body runs a
//! wider ISA's geometry (e.g. the AVX-512 conv3x3 tiles on AVX2 registers) on a CPU without it.

use super::SimdF32;

/// Two registers as one: lanes `0..V::LANES` in `.0`, the rest in `.1`.
#[derive(Clone, Copy)]
pub(crate) struct Pair<V>(pub V, pub V);

impl<V: SimdF32> Pair<V> {
    /// A deinterleaving load of `V` (`load`: `2·V::LANES` values) at `p` and at `p + 2·V::LANES`, as the
    /// two halves of each register (lane order within a half as `load` gives it).
    ///
    /// # Safety
    /// The ISA of `V`; `4·V::LANES` readable values at `p`.
    #[inline(always)]
    pub(crate) unsafe fn halves(
        p: *const f32,
        load: unsafe fn(*const f32) -> (V, V),
    ) -> (Self, Self) {
        // SAFETY: the caller guarantees the ISA and `2·V::LANES` values at `p` and after them.
        let ((e0, o0), (e1, o1)) = unsafe { (load(p), load(p.add(2 * V::LANES))) };
        (Pair(e0, e1), Pair(o0, o1))
    }
}

/// Binary operations, each on both halves: `wrap` builds the result (`Pair` for registers, a tuple for masks).
macro_rules! both {
    ($wrap:ident: $($name:ident($a:ident, $b:ident) -> $ret:ty;)*) => {$(
        #[inline(always)]
        unsafe fn $name($a: Self, $b: Self) -> $ret {
            // SAFETY: the caller's guarantees, for each half.
            unsafe { $wrap(V::$name($a.0, $b.0), V::$name($a.1, $b.1)) }
        }
    )*};
}

/// A tuple of the two halves' masks.
#[inline(always)]
fn tuple<A, B>(a: A, b: B) -> (A, B) {
    (a, b)
}

impl<V: SimdF32> SimdF32 for Pair<V> {
    const LANES: usize = 2 * V::LANES;
    type Mask = (V::Mask, V::Mask);
    type I32 = (V::I32, V::I32);

    #[inline(always)]
    unsafe fn zero() -> Self {
        // SAFETY: the caller's ISA.
        unsafe { Pair(V::zero(), V::zero()) }
    }
    #[inline(always)]
    unsafe fn splat(v: f32) -> Self {
        // SAFETY: the caller's ISA.
        unsafe { Pair(V::splat(v), V::splat(v)) }
    }
    #[inline(always)]
    unsafe fn load_splat(p: *const f32) -> Self {
        // SAFETY: the caller guarantees a valid `p`.
        unsafe { Pair(V::load_splat(p), V::load_splat(p)) }
    }
    #[inline(always)]
    unsafe fn load(p: *const f32) -> Self {
        // SAFETY: the caller guarantees `2·V::LANES` readable values at `p`.
        unsafe { Pair(V::load(p), V::load(p.add(V::LANES))) }
    }
    #[inline(always)]
    unsafe fn store(p: *mut f32, v: Self) {
        // SAFETY: the caller guarantees `2·V::LANES` writable values at `p`.
        unsafe {
            V::store(p, v.0);
            V::store(p.add(V::LANES), v.1)
        }
    }
    #[inline(always)]
    unsafe fn load_pairs(p: *const f32) -> (Self, Self) {
        // SAFETY: the caller guarantees the ISA and `4·V::LANES` readable values at `p`.
        unsafe { Pair::halves(p, V::load_pairs) }
    }
    both! { Pair:
        add(a, b) -> Self; sub(a, b) -> Self; mul(a, b) -> Self; div(a, b) -> Self;
        max(a, b) -> Self; and(a, b) -> Self; or(a, b) -> Self;
    }
    both! { tuple:
        lt(a, b) -> Self::Mask; gt(a, b) -> Self::Mask; ge(a, b) -> Self::Mask; eq(a, b) -> Self::Mask;
        ord(a, b) -> Self::Mask; unord(a, b) -> Self::Mask;
    }
    #[inline(always)]
    unsafe fn sqrt(v: Self) -> Self {
        // SAFETY: the caller's ISA.
        unsafe { Pair(V::sqrt(v.0), V::sqrt(v.1)) }
    }
    #[inline(always)]
    unsafe fn abs(v: Self) -> Self {
        // SAFETY: the caller's ISA.
        unsafe { Pair(V::abs(v.0), V::abs(v.1)) }
    }
    #[inline(always)]
    unsafe fn sign_mask(v: Self) -> Self::Mask {
        // SAFETY: the caller's ISA.
        unsafe { (V::sign_mask(v.0), V::sign_mask(v.1)) }
    }
    #[inline(always)]
    unsafe fn mask_or(a: Self::Mask, b: Self::Mask) -> Self::Mask {
        // SAFETY: the caller's ISA.
        unsafe { (V::mask_or(a.0, b.0), V::mask_or(a.1, b.1)) }
    }
    #[inline(always)]
    unsafe fn mask_any(m: Self::Mask) -> bool {
        // SAFETY: the caller's ISA.
        unsafe { V::mask_any(m.0) || V::mask_any(m.1) }
    }
    #[inline(always)]
    unsafe fn select(m: Self::Mask, b: Self, a: Self) -> Self {
        // SAFETY: the caller's ISA.
        unsafe { Pair(V::select(m.0, b.0, a.0), V::select(m.1, b.1, a.1)) }
    }
    #[inline(always)]
    unsafe fn keep(m: Self::Mask, v: Self) -> Self {
        // SAFETY: the caller's ISA.
        unsafe { Pair(V::keep(m.0, v.0), V::keep(m.1, v.1)) }
    }
    #[inline(always)]
    unsafe fn clear(m: Self::Mask, v: Self) -> Self {
        // SAFETY: the caller's ISA.
        unsafe { Pair(V::clear(m.0, v.0), V::clear(m.1, v.1)) }
    }
    #[inline(always)]
    unsafe fn to_i32(v: Self) -> Self::I32 {
        // SAFETY: the caller's ISA.
        unsafe { (V::to_i32(v.0), V::to_i32(v.1)) }
    }
    #[inline(always)]
    unsafe fn from_i32(i: Self::I32) -> Self {
        // SAFETY: the caller's ISA.
        unsafe { Pair(V::from_i32(i.0), V::from_i32(i.1)) }
    }
    #[inline(always)]
    unsafe fn inc_where(i: Self::I32, m: Self::Mask) -> Self::I32 {
        // SAFETY: the caller's ISA.
        unsafe { (V::inc_where(i.0, m.0), V::inc_where(i.1, m.1)) }
    }
}

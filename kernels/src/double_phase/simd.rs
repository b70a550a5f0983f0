//! The double phase rows written once for every vector ISA: the portable body of [`super::body`] operation
//! for operation (same constants, same order, multiply then add: no FMA contraction), generic over the
//! crate's register trait ([`SimdF32`]) with this family's few register operations ([`DpmSimd`]: the pair
//! loads, the f64 sums, the code store). Every function is `#[inline(always)]`, so it is compiled with the
//! features of the `#[target_feature]` entry point that instantiates it (`x86.rs`: AVX2 on `__m256`, eight
//! pixels per step; AVX-512F on `__m512`, sixteen), and the results are bit-identical with the portable body
//! (tested on rows and on the exhaustive sweep).
//!
//! Register tile: one register of pixels per step (`LANES` pixels: their `(re, im)` after the pair load, the
//! polynomial and the selects in about ten more registers; nothing spills on either ISA). Pass 1 keeps the
//! row's maxima in one register and the phase sums in eight f64 lanes ([`DpmSimd::Sum`]): lane `i` sums
//! pixels `i, i + 8, i + 16, …` in order on every ISA, so the f64 sum is bit-identical too.
//!
//! The subtle points, each as in the portable body: `atan2`'s quadrant fix-up reads `x`'s sign bit
//! ([`SimdF32::sign_mask`]: `blendv` on AVX2, a bit test on AVX-512), so `x = −0` and negative NaNs take the
//! `π − r` branch; the wrap adds or subtracts `2π` by selects where every lane lies within `[−4π, 4π)` and
//! falls back to [`wrap_phase`] lane by lane otherwise (NaN counts as near and stays NaN); the code is
//! `round(256·P/2π) mod 256` by truncation and a compare (`cvtt` gives `i32::MIN` for NaN, whose low byte is
//! 0, as the portable `NaN as i32` = 0).

use std::f32::consts::{FRAC_PI_2, FRAC_PI_4, PI, TAU};

use super::body::{wrap_phase, EncodeParams, ASIN_P, ATAN_P, HUGE, TAN_PI_8};
use crate::simd::SimdF32;

/// The double phase rows' register operations beyond [`SimdF32`].
pub(crate) trait DpmSimd: SimdF32 {
    /// The eight f64 accumulators of the phase sums (lane `i`: pixels `i mod 8`).
    type Sum: Copy;
    /// Eight f64 zeros.
    unsafe fn sum_zero() -> Self::Sum;
    /// Adds lane `j` of `p` (as f64) to accumulator `j mod 8`: lanes 0–7 first, then 8–15.
    unsafe fn sum_add(sum: &mut Self::Sum, p: Self);
    /// The eight accumulators in order.
    unsafe fn sum_store(sum: Self::Sum, out: &mut [f64; 8]);
    /// The register whose lane `j` is `sign[j mod 8]`.
    unsafe fn sign_pattern(sign: &[f32; 8]) -> Self;
    /// The low bytes of the `LANES` i32 lanes of `c` (each lane's value mod 256) to `LANES` bytes at `p`.
    unsafe fn store_codes(c: Self::I32, p: *mut u8);
}

/// [`super::atan2`] on one register.
///
/// # Safety
/// The ISA of `S`.
#[inline(always)]
unsafe fn atan2_v<S: SimdF32>(y: S, x: S) -> S {
    // SAFETY: the caller guarantees the ISA; register operations only.
    unsafe {
        let (ax, ay) = (S::abs(x), S::abs(y));
        let swap = S::gt(ay, ax);
        let n = S::select(swap, ax, ay);
        let d = S::select(swap, ay, ax);
        let s = S::select(S::gt(d, S::splat(HUGE)), S::splat(0.25), S::splat(1.0));
        let (n, d) = (S::mul(n, s), S::mul(d, s));
        let upper = S::mask_or(
            S::gt(n, S::mul(S::splat(TAN_PI_8), d)),
            S::eq(n, S::splat(f32::INFINITY)),
        );
        let num = S::select(upper, S::sub(n, d), n);
        let den = S::select(upper, S::add(n, d), d);
        let t = S::div(num, den);
        let t = S::keep(S::ord(t, t), t);
        let z = S::mul(t, t);
        let mut p = S::mul(S::splat(ATAN_P[0]), z);
        p = S::mul(S::add(p, S::splat(ATAN_P[1])), z);
        p = S::mul(S::add(p, S::splat(ATAN_P[2])), z);
        p = S::add(p, S::splat(ATAN_P[3]));
        let p = S::add(S::mul(S::mul(p, z), t), t);
        let r = S::select(upper, S::add(p, S::splat(FRAC_PI_4)), p);
        let r = S::select(swap, S::sub(S::splat(FRAC_PI_2), r), r);
        let r = S::select(S::sign_mask(x), S::sub(S::splat(PI), r), r);
        let r = S::or(r, S::and(y, S::splat(-0.0)));
        S::select(S::unord(x, y), S::splat(f32::NAN), r)
    }
}

/// [`super::acos_unit`] on one register.
///
/// # Safety
/// The ISA of `S`.
#[inline(always)]
unsafe fn acos_v<S: SimdF32>(x: S) -> S {
    // SAFETY: the caller guarantees the ISA; register operations only.
    unsafe {
        let big = S::gt(x, S::splat(0.5));
        let z = S::select(
            big,
            S::mul(S::sub(S::splat(1.0), x), S::splat(0.5)),
            S::mul(x, x),
        );
        let s = S::select(big, S::sqrt(z), x);
        let mut p = S::mul(S::splat(ASIN_P[0]), z);
        p = S::mul(S::add(p, S::splat(ASIN_P[1])), z);
        p = S::mul(S::add(p, S::splat(ASIN_P[2])), z);
        p = S::mul(S::add(p, S::splat(ASIN_P[3])), z);
        p = S::add(p, S::splat(ASIN_P[4]));
        let p = S::add(S::mul(S::mul(p, z), s), s);
        S::select(
            big,
            S::mul(S::splat(2.0), p),
            S::sub(S::splat(FRAC_PI_2), p),
        )
    }
}

/// Pass 1's running statistics: the lanes' maxima of `|H|²` and the f64 phase sums.
struct Stats<S: DpmSimd, const L: usize> {
    max: S,
    sum: S::Sum,
}

impl<S: DpmSimd, const L: usize> Stats<S, L> {
    /// Nothing seen.
    ///
    /// # Safety
    /// The ISA of `S`.
    #[inline(always)]
    unsafe fn new() -> Self {
        // SAFETY: the caller guarantees the ISA.
        unsafe {
            Self {
                max: S::zero(),
                sum: S::sum_zero(),
            }
        }
    }

    /// Pass 1 on one register of pixels given as `(re, im)`: phases to `out` (`LANES` values), the maxima
    /// and sums updated; returns `|H|²`.
    ///
    /// # Safety
    /// The ISA of `S`; `out` has `LANES` writable f32.
    #[inline(always)]
    unsafe fn step(&mut self, re: S, im: S, out: *mut f32) -> S {
        // SAFETY: the caller guarantees the memory and the ISA.
        unsafe {
            let p = atan2_v(im, re);
            S::store(out, p);
            let n2 = S::add(S::mul(re, re), S::mul(im, im));
            // maxps(a, b) = a > b ? a : b: a NaN |H|² is skipped, as in the portable body.
            self.max = S::max(n2, self.max);
            S::sum_add(&mut self.sum, p);
            n2
        }
    }

    /// The row's `(max |H|², Σ arg H)`.
    ///
    /// # Safety
    /// The ISA of `S`.
    #[inline(always)]
    unsafe fn finish(self) -> (f32, f64) {
        let (mut m, mut s) = ([0.0f32; L], [0.0f64; 8]);
        // SAFETY: stores into local arrays of `LANES` f32 and 8 f64.
        unsafe {
            S::store(m.as_mut_ptr(), self.max);
            S::sum_store(self.sum, &mut s);
        }
        let m = m.iter().fold(0.0f32, |a, &b| if b > a { b } else { a });
        (m, s.iter().sum())
    }
}

/// Pass 1 on one row (lengths checked by the caller), as [`super::body::analyse_body`].
///
/// # Safety
/// The ISA of `S`; `field.len() == 2·phase.len()`.
#[inline(always)]
pub(super) unsafe fn analyse<S: DpmSimd, const L: usize>(
    field: &[f32],
    phase: &mut [f32],
) -> (f32, f64) {
    debug_assert!(S::LANES == L && field.len() == 2 * phase.len());
    let n = phase.len();
    // SAFETY: the ISA of `S`.
    let mut stats = unsafe { Stats::<S, L>::new() };
    let (mut x, full) = (0, n / L * L);
    while x < full {
        // SAFETY: x + LANES ≤ n pixels: 2·LANES values of `field` and LANES of `phase` from there.
        unsafe {
            let (re, im) = S::load_pairs(field.as_ptr().add(2 * x));
            stats.step(re, im, phase.as_mut_ptr().add(x));
        }
        x += L;
    }
    if x < n {
        // Zero padding: arg 0 = 0 and |0|² = 0 change neither statistic (a sum lane is never −0: it
        // starts at +0, and +0 + −0 = +0).
        let (mut f, mut out) = ([[0.0f32; L]; 2], [0.0f32; L]);
        f.as_flattened_mut()[..2 * (n - x)].copy_from_slice(&field[2 * x..]);
        // SAFETY: local arrays of 2·LANES and LANES values.
        unsafe {
            let (re, im) = S::load_pairs(f.as_flattened().as_ptr());
            stats.step(re, im, out.as_mut_ptr());
        }
        phase[x..].copy_from_slice(&out[..n - x]);
    }
    // SAFETY: the ISA of `S`.
    unsafe { stats.finish() }
}

/// Pass 1 on one row held as planes (lengths checked by the caller), as
/// [`super::body::analyse_planes_body`]: `im_arg` from `Im H` to `arg H`, `abs` receives `|H|`.
///
/// # Safety
/// The ISA of `S`; `re`, `im_arg` and `abs` of one length.
#[inline(always)]
pub(super) unsafe fn analyse_planes<S: DpmSimd, const L: usize>(
    re: &[f32],
    im_arg: &mut [f32],
    abs: &mut [f32],
) -> (f32, f64) {
    debug_assert!(S::LANES == L && re.len() == im_arg.len() && abs.len() == im_arg.len());
    let (n, l) = (im_arg.len(), L);
    // SAFETY: the ISA of `S`.
    let mut stats = unsafe { Stats::<S, L>::new() };
    let (full, mut x) = (n - n % l, 0);
    while x < full {
        // SAFETY: x + LANES ≤ n: LANES values of each plane from there (`im_arg` read before it is
        // written).
        unsafe {
            let out = im_arg.as_mut_ptr().add(x);
            let n2 = stats.step(S::load(re.as_ptr().add(x)), S::load(out), out);
            S::store(abs.as_mut_ptr().add(x), S::sqrt(n2));
        }
        x += l;
    }
    if x < n {
        let k = n - x;
        let (mut r, mut i, mut a) = ([0.0f32; L], [0.0f32; L], [0.0f32; L]);
        r[..k].copy_from_slice(&re[x..]);
        i[..k].copy_from_slice(&im_arg[x..]);
        // SAFETY: local arrays of LANES values; zero padding changes neither statistic.
        unsafe {
            let v = (S::load(r.as_ptr()), S::load(i.as_ptr()));
            let n2 = stats.step(v.0, v.1, i.as_mut_ptr());
            S::store(a.as_mut_ptr(), S::sqrt(n2));
        }
        im_arg[x..].copy_from_slice(&i[..k]);
        abs[x..].copy_from_slice(&a[..k]);
    }
    // SAFETY: the ISA of `S`.
    unsafe { stats.finish() }
}

/// `|H|` of one register of pixels at `f`: `W = 2` interleaved `(re, im)` pairs (`2·LANES` values),
/// `√(re² + im²)`; `W = 1` the magnitudes themselves (`LANES` values).
///
/// # Safety
/// The ISA of `S`; `f` has `W·LANES` readable f32.
#[inline(always)]
unsafe fn magnitude<S: DpmSimd, const W: usize>(f: *const f32) -> S {
    // SAFETY: the caller guarantees the memory and the ISA.
    unsafe {
        if W == 2 {
            let (re, im) = S::load_pairs(f);
            S::sqrt(S::add(S::mul(re, re), S::mul(im, im)))
        } else {
            S::load(f)
        }
    }
}

/// Pass 2 on one register of pixels of magnitude `mag`: `phase` (`LANES` values at `p`) becomes the wrapped
/// double phase; returns the codes as i32 lanes (mod 256 by [`DpmSimd::store_codes`]).
///
/// # Safety
/// The ISA of `S`; `p` has `LANES` readable and writable f32.
#[inline(always)]
unsafe fn encode_step<S: DpmSimd, const L: usize>(
    mag: S,
    p: *mut f32,
    mean: S,
    inv_a: S,
    sign: S,
) -> S::I32 {
    // SAFETY: the caller guarantees the memory and the ISA.
    unsafe {
        let r = S::mul(mag, inv_a);
        let one = S::splat(1.0);
        let r = S::select(S::gt(r, one), one, r);
        let v = S::add(S::sub(S::load(p), mean), S::mul(sign, acos_v(r)));
        let (tau, zero) = (S::splat(TAU), S::zero());
        // Far outside [−4π, 4π): the portable wrap (`rem_euclid`) per lane. NaN counts as near.
        let far = S::mask_or(
            S::lt(v, S::splat(-2.0 * TAU)),
            S::ge(v, S::splat(2.0 * TAU)),
        );
        let w = if !S::mask_any(far) {
            let mut w = v;
            for _ in 0..2 {
                w = S::select(S::lt(w, zero), S::add(w, tau), w);
            }
            for _ in 0..2 {
                w = S::select(S::ge(w, tau), S::sub(w, tau), w);
            }
            S::clear(S::mask_or(S::ge(w, tau), S::lt(w, zero)), w)
        } else {
            let mut a = [0.0f32; L];
            S::store(a.as_mut_ptr(), v);
            for x in a.iter_mut() {
                *x = wrap_phase(*x);
            }
            S::load(a.as_ptr())
        };
        S::store(p, w);
        // The code: round(w·256/2π) by truncation and a compare.
        let x = S::mul(w, S::splat(256.0 / TAU));
        let i = S::to_i32(x);
        let frac = S::sub(x, S::from_i32(i));
        S::inc_where(i, S::ge(frac, S::splat(0.5)))
    }
}

/// Pass 2 on one row of `W` values per pixel ([`magnitude`]; lengths checked by the caller), as
/// [`super::body::encode_row_of`]`::<2>` (`W = 2`) and [`super::body::encode_row_of`]`::<1>` (`W = 1`).
///
/// # Safety
/// The ISA of `S`; `field.len() == W·phase.len()`, `codes` (if any) as long as `phase`.
#[inline(always)]
pub(super) unsafe fn encode<S: DpmSimd, const L: usize, const W: usize>(
    field: &[f32],
    phase: &mut [f32],
    mut codes: Option<&mut [u8]>,
    prm: &EncodeParams,
) {
    debug_assert!(S::LANES == L && field.len() == W * phase.len());
    let (l, n) = (L, phase.len());
    let full = n / l * l;
    // SAFETY: the ISA of `S`.
    let (mean, inv_a, sign) = unsafe {
        (
            S::splat(prm.mean),
            S::splat(prm.inv_a),
            S::sign_pattern(&prm.sign),
        )
    };
    let mut x = 0;
    while x < full {
        // SAFETY: x + LANES ≤ n pixels: W·LANES values of `field` and LANES of `phase` from there.
        let c = unsafe {
            let mag = magnitude::<S, W>(field.as_ptr().add(W * x));
            encode_step::<S, L>(mag, phase.as_mut_ptr().add(x), mean, inv_a, sign)
        };
        if let Some(codes) = codes.as_deref_mut() {
            debug_assert!(x + l <= codes.len());
            // SAFETY: LANES bytes from x (x + LANES ≤ n = codes.len()).
            unsafe { S::store_codes(c, codes.as_mut_ptr().add(x)) };
        }
        x += l;
    }
    if x < n {
        let k = n - x;
        let (mut f, mut p, mut c) = ([[0.0f32; L]; 2], [0.0f32; L], [0u8; L]);
        f.as_flattened_mut()[..W * k].copy_from_slice(&field[W * x..]);
        p[..k].copy_from_slice(&phase[x..]);
        // SAFETY: local arrays of 2·LANES and LANES values and LANES bytes.
        unsafe {
            let mag = magnitude::<S, W>(f.as_flattened().as_ptr());
            let v = encode_step::<S, L>(mag, p.as_mut_ptr(), mean, inv_a, sign);
            S::store_codes(v, c.as_mut_ptr());
        }
        phase[x..].copy_from_slice(&p[..k]);
        if let Some(codes) = codes {
            codes[x..].copy_from_slice(&c[..k]);
        }
    }
}

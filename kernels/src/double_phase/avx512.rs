//! The double phase rows in AVX-512F intrinsics (zmm, sixteen pixels per step): [`super::avx2`]'s
//! operations, in the same order and with the same constants, on twice the lanes, so the results are
//! bit-identical with the portable body (tested). Selects are mask blends (`k` registers) instead of
//! `blendv`; the absolute value and the sign copy are bit operations, as in the AVX2 path.
//!
//! Register use per step: the 16 pixels' `(re, im)` in two zmm after a two-source permute
//! (`vpermt2ps`), the polynomial and the selects in about ten more; nothing spills. Pass 1 keeps the f64
//! phase sums in eight lanes (one zmm of f64) and adds a step's first eight phases, then its last eight:
//! lane `i` sums pixels `i, i + 8, i + 16, …` in order, as the eight-lane paths do, so the sum is
//! bit-identical too.

use std::arch::x86_64::*;
use std::f32::consts::{FRAC_PI_2, FRAC_PI_4, PI, TAU};

use super::body::{wrap_phase, EncodeParams, ASIN_P, ATAN_P, HUGE, LANES, TAN_PI_8};

/// Pixels per step.
const STEP: usize = 2 * LANES;

/// Sixteen `(re, im)` pairs at `f` (32 values) as `(re, im)` vectors in pixel order.
///
/// # Safety
/// AVX-512F; `f` points to 32 readable f32.
#[inline(always)]
unsafe fn load_pairs(f: *const f32) -> (__m512, __m512) {
    // SAFETY: the caller guarantees 32 readable values and AVX-512F.
    unsafe {
        let a = _mm512_loadu_ps(f);
        let b = _mm512_loadu_ps(f.add(16));
        let even = _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30);
        let odd = _mm512_setr_epi32(1, 3, 5, 7, 9, 11, 13, 15, 17, 19, 21, 23, 25, 27, 29, 31);
        (
            _mm512_permutex2var_ps(a, even, b),
            _mm512_permutex2var_ps(a, odd, b),
        )
    }
}

/// `if m { b } else { a }` per lane.
#[inline(always)]
unsafe fn sel(m: __mmask16, b: __m512, a: __m512) -> __m512 {
    // SAFETY: AVX-512F (the callers run with it).
    unsafe { _mm512_mask_blend_ps(m, a, b) }
}

#[inline(always)]
unsafe fn splat(v: f32) -> __m512 {
    // SAFETY: AVX-512F.
    unsafe { _mm512_set1_ps(v) }
}

/// The lanes whose sign bit is set (NaN included, as `blendv` reads it).
#[inline(always)]
unsafe fn sign_set(x: __m512) -> __mmask16 {
    // SAFETY: AVX-512F.
    unsafe { _mm512_test_epi32_mask(_mm512_castps_si512(x), _mm512_set1_epi32(i32::MIN)) }
}

/// [`super::atan2`] on sixteen lanes.
///
/// # Safety
/// AVX-512F.
#[inline(always)]
unsafe fn atan2_v(y: __m512, x: __m512) -> __m512 {
    // SAFETY: AVX-512F by the caller; register operations only.
    unsafe {
        let (ax, ay) = (_mm512_abs_ps(x), _mm512_abs_ps(y));
        let swap = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(ay, ax);
        let n = sel(swap, ax, ay);
        let d = sel(swap, ay, ax);
        let s = sel(
            _mm512_cmp_ps_mask::<_CMP_GT_OQ>(d, splat(HUGE)),
            splat(0.25),
            splat(1.0),
        );
        let (n, d) = (_mm512_mul_ps(n, s), _mm512_mul_ps(d, s));
        let upper = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(n, _mm512_mul_ps(splat(TAN_PI_8), d))
            | _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(n, splat(f32::INFINITY));
        let num = sel(upper, _mm512_sub_ps(n, d), n);
        let den = sel(upper, _mm512_add_ps(n, d), d);
        let t = _mm512_div_ps(num, den);
        let t = _mm512_maskz_mov_ps(_mm512_cmp_ps_mask::<_CMP_ORD_Q>(t, t), t);
        let z = _mm512_mul_ps(t, t);
        let mut p = _mm512_mul_ps(splat(ATAN_P[0]), z);
        p = _mm512_mul_ps(_mm512_add_ps(p, splat(ATAN_P[1])), z);
        p = _mm512_mul_ps(_mm512_add_ps(p, splat(ATAN_P[2])), z);
        p = _mm512_add_ps(p, splat(ATAN_P[3]));
        let p = _mm512_add_ps(_mm512_mul_ps(_mm512_mul_ps(p, z), t), t);
        let r = sel(upper, _mm512_add_ps(p, splat(FRAC_PI_4)), p);
        let r = sel(swap, _mm512_sub_ps(splat(FRAC_PI_2), r), r);
        let r = sel(sign_set(x), _mm512_sub_ps(splat(PI), r), r);
        let y_sign = _mm512_and_si512(_mm512_castps_si512(y), _mm512_set1_epi32(i32::MIN));
        let r = _mm512_castsi512_ps(_mm512_or_si512(_mm512_castps_si512(r), y_sign));
        sel(_mm512_cmp_ps_mask::<_CMP_UNORD_Q>(x, y), splat(f32::NAN), r)
    }
}

/// [`super::acos_unit`] on sixteen lanes.
///
/// # Safety
/// AVX-512F.
#[inline(always)]
unsafe fn acos_v(x: __m512) -> __m512 {
    // SAFETY: AVX-512F by the caller; register operations only.
    unsafe {
        let big = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(x, splat(0.5));
        let z = sel(
            big,
            _mm512_mul_ps(_mm512_sub_ps(splat(1.0), x), splat(0.5)),
            _mm512_mul_ps(x, x),
        );
        let s = sel(big, _mm512_sqrt_ps(z), x);
        let mut p = _mm512_mul_ps(splat(ASIN_P[0]), z);
        p = _mm512_mul_ps(_mm512_add_ps(p, splat(ASIN_P[1])), z);
        p = _mm512_mul_ps(_mm512_add_ps(p, splat(ASIN_P[2])), z);
        p = _mm512_mul_ps(_mm512_add_ps(p, splat(ASIN_P[3])), z);
        p = _mm512_add_ps(p, splat(ASIN_P[4]));
        let p = _mm512_add_ps(_mm512_mul_ps(_mm512_mul_ps(p, z), s), s);
        sel(
            big,
            _mm512_mul_ps(splat(2.0), p),
            _mm512_sub_ps(splat(FRAC_PI_2), p),
        )
    }
}

/// Pass 1 on sixteen pixels given as `(re, im)`: phases to `out` (16 values), running maxima and the eight
/// f64 sums (first the step's pixels 0–7, then 8–15); returns `|H|²`.
///
/// # Safety
/// AVX-512F; `out` has 16 writable f32.
#[inline(always)]
unsafe fn analyse16(
    re: __m512,
    im: __m512,
    out: *mut f32,
    max: &mut __m512,
    sum: &mut __m512d,
) -> __m512 {
    // SAFETY: the caller guarantees the memory and AVX-512F.
    unsafe {
        let p = atan2_v(im, re);
        _mm512_storeu_ps(out, p);
        let n2 = _mm512_add_ps(_mm512_mul_ps(re, re), _mm512_mul_ps(im, im));
        // maxps(a, b) = a > b ? a : b: a NaN |H|² is skipped, as in the portable body.
        *max = _mm512_max_ps(n2, *max);
        let bits = _mm512_castps_si512(p);
        let lo = _mm256_castsi256_ps(_mm512_castsi512_si256(bits));
        let hi = _mm256_castsi256_ps(_mm512_extracti64x4_epi64::<1>(bits));
        *sum = _mm512_add_pd(*sum, _mm512_cvtps_pd(lo));
        *sum = _mm512_add_pd(*sum, _mm512_cvtps_pd(hi));
        n2
    }
}

/// The row's `(max |H|², Σ arg H)` from the lanes' maxima and the eight f64 sums.
///
/// # Safety
/// AVX-512F.
#[inline(always)]
unsafe fn row_stats(max: __m512, sum: __m512d) -> (f32, f64) {
    let (mut m, mut s) = ([0.0f32; STEP], [0.0f64; LANES]);
    // SAFETY: stores into local arrays of 16 f32 and 8 f64.
    unsafe {
        _mm512_storeu_ps(m.as_mut_ptr(), max);
        _mm512_storeu_pd(s.as_mut_ptr(), sum);
    }
    let m = m.iter().fold(0.0f32, |a, &b| if b > a { b } else { a });
    (m, s.iter().sum())
}

/// Pass 1 on one row (lengths checked by the caller), as [`super::body::analyse_body`].
///
/// # Safety
/// The CPU has AVX-512F; `field.len() == 2·phase.len()`.
#[target_feature(enable = "avx512f")]
pub(crate) unsafe fn analyse_avx512(field: &[f32], phase: &mut [f32]) -> (f32, f64) {
    debug_assert_eq!(field.len(), 2 * phase.len());
    let n = phase.len();
    let full = n / STEP * STEP;
    let mut max = _mm512_setzero_ps();
    let mut sum = _mm512_setzero_pd();
    let mut x = 0;
    while x < full {
        // SAFETY: x + 16 ≤ n pixels: 32 values of `field` and 16 of `phase` from there.
        unsafe {
            let (re, im) = load_pairs(field.as_ptr().add(2 * x));
            analyse16(re, im, phase.as_mut_ptr().add(x), &mut max, &mut sum);
        }
        x += STEP;
    }
    if x < n {
        // Zero padding: arg 0 = 0 and |0|² = 0 change neither statistic (a sum lane is never −0: it
        // starts at +0, and +0 + −0 = +0).
        let mut f = [0.0f32; 2 * STEP];
        f[..2 * (n - x)].copy_from_slice(&field[2 * x..]);
        let mut out = [0.0f32; STEP];
        // SAFETY: local arrays of 32 and 16 values.
        unsafe {
            let (re, im) = load_pairs(f.as_ptr());
            analyse16(re, im, out.as_mut_ptr(), &mut max, &mut sum);
        }
        phase[x..].copy_from_slice(&out[..n - x]);
    }
    // SAFETY: AVX-512F (this function's feature).
    unsafe { row_stats(max, sum) }
}

/// Pass 1 on one row held as planes (lengths checked by the caller), as
/// [`super::body::analyse_planes_body`]: `im_arg` from `Im H` to `arg H`, `abs` receives `|H|`.
///
/// # Safety
/// The CPU has AVX-512F; `re`, `im_arg` and `abs` of one length.
#[target_feature(enable = "avx512f")]
pub(crate) unsafe fn analyse_planes_avx512(
    re: &[f32],
    im_arg: &mut [f32],
    abs: &mut [f32],
) -> (f32, f64) {
    debug_assert!(re.len() == im_arg.len() && abs.len() == im_arg.len());
    let n = im_arg.len();
    let full = n / STEP * STEP;
    let mut max = _mm512_setzero_ps();
    let mut sum = _mm512_setzero_pd();
    let mut x = 0;
    while x < full {
        // SAFETY: x + 16 ≤ n: 16 values of each plane from there (`im_arg` read before it is written).
        unsafe {
            let out = im_arg.as_mut_ptr().add(x);
            let (r, i) = (_mm512_loadu_ps(re.as_ptr().add(x)), _mm512_loadu_ps(out));
            let n2 = analyse16(r, i, out, &mut max, &mut sum);
            _mm512_storeu_ps(abs.as_mut_ptr().add(x), _mm512_sqrt_ps(n2));
        }
        x += STEP;
    }
    if x < n {
        let k = n - x;
        let (mut r, mut i, mut a) = ([0.0f32; STEP], [0.0f32; STEP], [0.0f32; STEP]);
        r[..k].copy_from_slice(&re[x..]);
        i[..k].copy_from_slice(&im_arg[x..]);
        // SAFETY: local arrays of 16 values; zero padding changes neither statistic.
        unsafe {
            let v = (_mm512_loadu_ps(r.as_ptr()), _mm512_loadu_ps(i.as_ptr()));
            let n2 = analyse16(v.0, v.1, i.as_mut_ptr(), &mut max, &mut sum);
            _mm512_storeu_ps(a.as_mut_ptr(), _mm512_sqrt_ps(n2));
        }
        im_arg[x..].copy_from_slice(&i[..k]);
        abs[x..].copy_from_slice(&a[..k]);
    }
    // SAFETY: AVX-512F (this function's feature).
    unsafe { row_stats(max, sum) }
}

/// `|H|` of sixteen pixels at `f`: `W = 2` interleaved `(re, im)` pairs (32 values), `√(re² + im²)`; `W = 1`
/// the magnitudes themselves (16 values).
///
/// # Safety
/// AVX-512F; `f` has `16·W` readable f32.
#[inline(always)]
unsafe fn magnitude16<const W: usize>(f: *const f32) -> __m512 {
    // SAFETY: the caller guarantees the memory and AVX-512F.
    unsafe {
        if W == 2 {
            let (re, im) = load_pairs(f);
            _mm512_sqrt_ps(_mm512_add_ps(_mm512_mul_ps(re, re), _mm512_mul_ps(im, im)))
        } else {
            _mm512_loadu_ps(f)
        }
    }
}

/// Pass 2 on sixteen pixels of magnitude `mag`: `phase` (16 values at `p`) becomes the wrapped double
/// phase; returns the codes as sixteen bytes.
///
/// # Safety
/// AVX-512F; `p` has 16 readable and writable f32.
#[inline(always)]
unsafe fn encode16(mag: __m512, p: *mut f32, mean: __m512, inv_a: __m512, sign: __m512) -> __m128i {
    // SAFETY: the caller guarantees the memory and AVX-512F.
    unsafe {
        let r = _mm512_mul_ps(mag, inv_a);
        let one = splat(1.0);
        let r = sel(_mm512_cmp_ps_mask::<_CMP_GT_OQ>(r, one), one, r);
        let v = _mm512_add_ps(
            _mm512_sub_ps(_mm512_loadu_ps(p), mean),
            _mm512_mul_ps(sign, acos_v(r)),
        );
        let (tau, zero) = (splat(TAU), _mm512_setzero_ps());
        // Far outside [−4π, 4π): the portable wrap (`rem_euclid`) per lane. NaN counts as near.
        let far = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(v, splat(-2.0 * TAU))
            | _mm512_cmp_ps_mask::<_CMP_GE_OQ>(v, splat(2.0 * TAU));
        let w = if far == 0 {
            let mut w = v;
            for _ in 0..2 {
                w = sel(
                    _mm512_cmp_ps_mask::<_CMP_LT_OQ>(w, zero),
                    _mm512_add_ps(w, tau),
                    w,
                );
            }
            for _ in 0..2 {
                w = sel(
                    _mm512_cmp_ps_mask::<_CMP_GE_OQ>(w, tau),
                    _mm512_sub_ps(w, tau),
                    w,
                );
            }
            let out = _mm512_cmp_ps_mask::<_CMP_GE_OQ>(w, tau)
                | _mm512_cmp_ps_mask::<_CMP_LT_OQ>(w, zero);
            _mm512_maskz_mov_ps(!out, w)
        } else {
            let mut a = [0.0f32; STEP];
            _mm512_storeu_ps(a.as_mut_ptr(), v);
            for x in a.iter_mut() {
                *x = wrap_phase(*x);
            }
            _mm512_loadu_ps(a.as_ptr())
        };
        _mm512_storeu_ps(p, w);
        // The code: round(w·256/2π) by truncation and a compare, mod 256 (cvtt gives i32::MIN for NaN,
        // whose low byte is 0 as the portable `NaN as i32` = 0).
        let x = _mm512_mul_ps(w, splat(256.0 / TAU));
        let i = _mm512_cvttps_epi32(x);
        let frac = _mm512_sub_ps(x, _mm512_cvtepi32_ps(i));
        let up = _mm512_cmp_ps_mask::<_CMP_GE_OQ>(frac, splat(0.5));
        let i = _mm512_mask_add_epi32(i, up, i, _mm512_set1_epi32(1));
        // The low byte of each lane (vpmovdb truncates): the code mod 256.
        _mm512_cvtepi32_epi8(i)
    }
}

/// Pass 2 on one row (lengths checked by the caller), as [`super::body::encode_body`].
///
/// # Safety
/// The CPU has AVX-512F; `field.len() == 2·phase.len()`, `codes` (if any) as long as `phase`.
#[target_feature(enable = "avx512f")]
pub(crate) unsafe fn encode_avx512(
    field: &[f32],
    phase: &mut [f32],
    codes: Option<&mut [u8]>,
    prm: &EncodeParams,
) {
    debug_assert_eq!(field.len(), 2 * phase.len());
    // SAFETY: AVX-512F (this function's feature); the lengths as `encode_row_of` needs.
    unsafe { encode_row_of::<2>(field, phase, codes, prm) }
}

/// Pass 2 on one row whose magnitudes are given, as [`super::body::encode_abs_body`].
///
/// # Safety
/// The CPU has AVX-512F; `abs.len() == phase.len()`, `codes` (if any) as long as `phase`.
#[target_feature(enable = "avx512f")]
pub(crate) unsafe fn encode_abs_avx512(
    abs: &[f32],
    phase: &mut [f32],
    codes: Option<&mut [u8]>,
    prm: &EncodeParams,
) {
    debug_assert_eq!(abs.len(), phase.len());
    // SAFETY: AVX-512F (this function's feature); the lengths as `encode_row_of` needs.
    unsafe { encode_row_of::<1>(abs, phase, codes, prm) }
}

/// Pass 2 on one row of `W` values per pixel ([`magnitude16`]).
///
/// # Safety
/// AVX-512F; `field.len() == W·phase.len()`, `codes` (if any) as long as `phase`.
#[inline(always)]
unsafe fn encode_row_of<const W: usize>(
    field: &[f32],
    phase: &mut [f32],
    mut codes: Option<&mut [u8]>,
    prm: &EncodeParams,
) {
    let n = phase.len();
    let full = n / STEP * STEP;
    // The sign pattern of eight pixels, twice (LANES is even: pixel parity repeats).
    let mut pattern = [0.0f32; STEP];
    pattern[..LANES].copy_from_slice(&prm.sign);
    pattern[LANES..].copy_from_slice(&prm.sign);
    // SAFETY: AVX-512F by the caller; reads 16 values of a local array.
    let (mean, inv_a, sign) = unsafe {
        (
            _mm512_set1_ps(prm.mean),
            _mm512_set1_ps(prm.inv_a),
            _mm512_loadu_ps(pattern.as_ptr()),
        )
    };
    let mut x = 0;
    while x < full {
        // SAFETY: x + 16 ≤ n pixels: 16·W values of `field` and 16 of `phase` from there.
        let c = unsafe {
            let mag = magnitude16::<W>(field.as_ptr().add(W * x));
            encode16(mag, phase.as_mut_ptr().add(x), mean, inv_a, sign)
        };
        if let Some(codes) = codes.as_deref_mut() {
            // SAFETY: 16 bytes from x (x + 16 ≤ n = codes.len()).
            unsafe { _mm_storeu_si128(codes.as_mut_ptr().add(x).cast(), c) };
        }
        x += STEP;
    }
    if x < n {
        let k = n - x;
        let mut f = [0.0f32; 2 * STEP];
        f[..W * k].copy_from_slice(&field[W * x..]);
        let mut p = [0.0f32; STEP];
        p[..k].copy_from_slice(&phase[x..]);
        let mut c = [0u8; STEP];
        // SAFETY: local arrays of 32 and 16 values and 16 bytes.
        unsafe {
            let v = encode16(
                magnitude16::<W>(f.as_ptr()),
                p.as_mut_ptr(),
                mean,
                inv_a,
                sign,
            );
            _mm_storeu_si128(c.as_mut_ptr().cast(), v);
        }
        phase[x..].copy_from_slice(&p[..k]);
        if let Some(codes) = codes {
            codes[x..].copy_from_slice(&c[..k]);
        }
    }
}

//! The double phase rows in AVX2 intrinsics (ymm, eight pixels per step): the portable body of
//! [`super::body`] operation for operation (same constants, same order, no FMA contraction), so the results
//! are bit-identical with it (tested). The compiler's own vectorisation of the portable body stayed at xmm
//! width with spills (about 4–6 ns per pixel per pass); written out, a pass costs about a nanosecond or two
//! (`docs/BENCHMARKS.md`).

use std::arch::x86_64::*;
use std::f32::consts::{FRAC_PI_2, FRAC_PI_4, PI, TAU};

use super::body::{wrap_phase, EncodeParams, ASIN_P, ATAN_P, HUGE, LANES, TAN_PI_8};

/// Eight `(re, im)` pairs at `f` (16 values) as `(re, im)` vectors in pixel order.
///
/// # Safety
/// AVX2; `f` points to 16 readable f32.
#[inline(always)]
unsafe fn load_pairs(f: *const f32) -> (__m256, __m256) {
    // SAFETY: the caller guarantees 16 readable values and AVX2.
    unsafe {
        let a = _mm256_loadu_ps(f);
        let b = _mm256_loadu_ps(f.add(8));
        // [r0 r1 r4 r5 | r2 r3 r6 r7] → pixel order by 64-bit lanes 0, 2, 1, 3.
        let re = _mm256_shuffle_ps::<0x88>(a, b);
        let im = _mm256_shuffle_ps::<0xdd>(a, b);
        let re = _mm256_castpd_ps(_mm256_permute4x64_pd::<0xd8>(_mm256_castps_pd(re)));
        let im = _mm256_castpd_ps(_mm256_permute4x64_pd::<0xd8>(_mm256_castps_pd(im)));
        (re, im)
    }
}

/// `if m { b } else { a }` per lane (`m` all ones or all zeros).
#[inline(always)]
unsafe fn sel(m: __m256, b: __m256, a: __m256) -> __m256 {
    // SAFETY: AVX (the callers run with AVX2).
    unsafe { _mm256_blendv_ps(a, b, m) }
}

#[inline(always)]
unsafe fn splat(v: f32) -> __m256 {
    // SAFETY: AVX.
    unsafe { _mm256_set1_ps(v) }
}

/// [`super::atan2`] on eight lanes.
///
/// # Safety
/// AVX2.
#[inline(always)]
unsafe fn atan2_v(y: __m256, x: __m256) -> __m256 {
    // SAFETY: AVX2 by the caller; register operations only.
    unsafe {
        let sign = splat(-0.0);
        let (ax, ay) = (_mm256_andnot_ps(sign, x), _mm256_andnot_ps(sign, y));
        let swap = _mm256_cmp_ps::<_CMP_GT_OQ>(ay, ax);
        let n = sel(swap, ax, ay);
        let d = sel(swap, ay, ax);
        let s = sel(
            _mm256_cmp_ps::<_CMP_GT_OQ>(d, splat(HUGE)),
            splat(0.25),
            splat(1.0),
        );
        let (n, d) = (_mm256_mul_ps(n, s), _mm256_mul_ps(d, s));
        let upper = _mm256_or_ps(
            _mm256_cmp_ps::<_CMP_GT_OQ>(n, _mm256_mul_ps(splat(TAN_PI_8), d)),
            _mm256_cmp_ps::<_CMP_EQ_OQ>(n, splat(f32::INFINITY)),
        );
        let num = sel(upper, _mm256_sub_ps(n, d), n);
        let den = sel(upper, _mm256_add_ps(n, d), d);
        let t = _mm256_div_ps(num, den);
        let t = _mm256_and_ps(t, _mm256_cmp_ps::<_CMP_ORD_Q>(t, t));
        let z = _mm256_mul_ps(t, t);
        let mut p = _mm256_mul_ps(splat(ATAN_P[0]), z);
        p = _mm256_mul_ps(_mm256_add_ps(p, splat(ATAN_P[1])), z);
        p = _mm256_mul_ps(_mm256_add_ps(p, splat(ATAN_P[2])), z);
        p = _mm256_add_ps(p, splat(ATAN_P[3]));
        let p = _mm256_add_ps(_mm256_mul_ps(_mm256_mul_ps(p, z), t), t);
        let r = sel(upper, _mm256_add_ps(p, splat(FRAC_PI_4)), p);
        let r = sel(swap, _mm256_sub_ps(splat(FRAC_PI_2), r), r);
        // blendv reads the mask's sign bit: x's own.
        let r = _mm256_blendv_ps(r, _mm256_sub_ps(splat(PI), r), x);
        let r = _mm256_or_ps(r, _mm256_and_ps(y, sign));
        sel(_mm256_cmp_ps::<_CMP_UNORD_Q>(x, y), splat(f32::NAN), r)
    }
}

/// [`super::acos_unit`] on eight lanes.
///
/// # Safety
/// AVX2.
#[inline(always)]
unsafe fn acos_v(x: __m256) -> __m256 {
    // SAFETY: AVX2 by the caller; register operations only.
    unsafe {
        let big = _mm256_cmp_ps::<_CMP_GT_OQ>(x, splat(0.5));
        let z = sel(
            big,
            _mm256_mul_ps(_mm256_sub_ps(splat(1.0), x), splat(0.5)),
            _mm256_mul_ps(x, x),
        );
        let s = sel(big, _mm256_sqrt_ps(z), x);
        let mut p = _mm256_mul_ps(splat(ASIN_P[0]), z);
        p = _mm256_mul_ps(_mm256_add_ps(p, splat(ASIN_P[1])), z);
        p = _mm256_mul_ps(_mm256_add_ps(p, splat(ASIN_P[2])), z);
        p = _mm256_mul_ps(_mm256_add_ps(p, splat(ASIN_P[3])), z);
        p = _mm256_add_ps(p, splat(ASIN_P[4]));
        let p = _mm256_add_ps(_mm256_mul_ps(_mm256_mul_ps(p, z), s), s);
        sel(
            big,
            _mm256_mul_ps(splat(2.0), p),
            _mm256_sub_ps(splat(FRAC_PI_2), p),
        )
    }
}

/// Pass 1 on eight pixels given as `(re, im)`: phases to `out` (8 values), running maxima and sums;
/// returns `|H|²`.
///
/// # Safety
/// AVX2; `out` has 8 writable f32.
#[inline(always)]
unsafe fn analyse8(
    re: __m256,
    im: __m256,
    out: *mut f32,
    max: &mut __m256,
    sum_lo: &mut __m256d,
    sum_hi: &mut __m256d,
) -> __m256 {
    // SAFETY: the caller guarantees the memory and AVX2.
    unsafe {
        let p = atan2_v(im, re);
        _mm256_storeu_ps(out, p);
        let n2 = _mm256_add_ps(_mm256_mul_ps(re, re), _mm256_mul_ps(im, im));
        // maxps(a, b) = a > b ? a : b: a NaN |H|² is skipped, as in the portable body.
        *max = _mm256_max_ps(n2, *max);
        *sum_lo = _mm256_add_pd(*sum_lo, _mm256_cvtps_pd(_mm256_castps256_ps128(p)));
        *sum_hi = _mm256_add_pd(*sum_hi, _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(p)));
        n2
    }
}

/// The row's `(max |H|², Σ arg H)` from the lanes' maxima and the f64 sums.
///
/// # Safety
/// AVX2.
#[inline(always)]
unsafe fn row_stats(max: __m256, lo: __m256d, hi: __m256d) -> (f32, f64) {
    let (mut m, mut s) = ([0.0f32; LANES], [0.0f64; LANES]);
    // SAFETY: stores into local arrays of 8 values (4 + 4 f64).
    unsafe {
        _mm256_storeu_ps(m.as_mut_ptr(), max);
        _mm256_storeu_pd(s.as_mut_ptr(), lo);
        _mm256_storeu_pd(s.as_mut_ptr().add(4), hi);
    }
    let m = m.iter().fold(0.0f32, |a, &b| if b > a { b } else { a });
    (m, s.iter().sum())
}

/// Pass 1 on one row (lengths checked by the caller), as [`super::body::analyse_body`].
///
/// # Safety
/// The CPU has AVX2 and FMA; `field.len() == 2·phase.len()`.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn analyse_avx2(field: &[f32], phase: &mut [f32]) -> (f32, f64) {
    debug_assert_eq!(field.len(), 2 * phase.len());
    let n = phase.len();
    let full = n / LANES * LANES;
    let mut max = _mm256_setzero_ps();
    let (mut lo, mut hi) = (_mm256_setzero_pd(), _mm256_setzero_pd());
    let mut x = 0;
    while x < full {
        // SAFETY: x + 8 ≤ n pixels: 16 values of `field` and 8 of `phase` from there.
        unsafe {
            let (re, im) = load_pairs(field.as_ptr().add(2 * x));
            analyse8(
                re,
                im,
                phase.as_mut_ptr().add(x),
                &mut max,
                &mut lo,
                &mut hi,
            );
        }
        x += LANES;
    }
    if x < n {
        // Zero padding: arg 0 = 0 and |0|² = 0 change neither statistic.
        let mut f = [0.0f32; 2 * LANES];
        f[..2 * (n - x)].copy_from_slice(&field[2 * x..]);
        let mut out = [0.0f32; LANES];
        // SAFETY: local arrays of 16 and 8 values.
        unsafe {
            let (re, im) = load_pairs(f.as_ptr());
            analyse8(re, im, out.as_mut_ptr(), &mut max, &mut lo, &mut hi);
        }
        phase[x..].copy_from_slice(&out[..n - x]);
    }
    // SAFETY: AVX2 (this function's feature).
    unsafe { row_stats(max, lo, hi) }
}

/// Pass 1 on one row held as planes (lengths checked by the caller), as
/// [`super::body::analyse_planes_body`]: `im_arg` from `Im H` to `arg H`, `abs` receives `|H|`.
///
/// # Safety
/// The CPU has AVX2 and FMA; `re`, `im_arg` and `abs` of one length.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn analyse_planes_avx2(
    re: &[f32],
    im_arg: &mut [f32],
    abs: &mut [f32],
) -> (f32, f64) {
    debug_assert!(re.len() == im_arg.len() && abs.len() == im_arg.len());
    let n = im_arg.len();
    let full = n / LANES * LANES;
    let mut max = _mm256_setzero_ps();
    let (mut lo, mut hi) = (_mm256_setzero_pd(), _mm256_setzero_pd());
    let mut x = 0;
    while x < full {
        // SAFETY: x + 8 ≤ n: 8 values of each plane from there (`im_arg` read before it is written).
        unsafe {
            let out = im_arg.as_mut_ptr().add(x);
            let (r, i) = (_mm256_loadu_ps(re.as_ptr().add(x)), _mm256_loadu_ps(out));
            let n2 = analyse8(r, i, out, &mut max, &mut lo, &mut hi);
            _mm256_storeu_ps(abs.as_mut_ptr().add(x), _mm256_sqrt_ps(n2));
        }
        x += LANES;
    }
    if x < n {
        let k = n - x;
        let (mut r, mut i, mut a) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
        r[..k].copy_from_slice(&re[x..]);
        i[..k].copy_from_slice(&im_arg[x..]);
        // SAFETY: local arrays of 8 values; zero padding changes neither statistic.
        unsafe {
            let v = (_mm256_loadu_ps(r.as_ptr()), _mm256_loadu_ps(i.as_ptr()));
            let n2 = analyse8(v.0, v.1, i.as_mut_ptr(), &mut max, &mut lo, &mut hi);
            _mm256_storeu_ps(a.as_mut_ptr(), _mm256_sqrt_ps(n2));
        }
        im_arg[x..].copy_from_slice(&i[..k]);
        abs[x..].copy_from_slice(&a[..k]);
    }
    // SAFETY: AVX2 (this function's feature).
    unsafe { row_stats(max, lo, hi) }
}

/// `|H|` of eight pixels at `f`: `W = 2` interleaved `(re, im)` pairs (16 values), `√(re² + im²)`; `W = 1`
/// the magnitudes themselves (8 values).
///
/// # Safety
/// AVX2; `f` has `8·W` readable f32.
#[inline(always)]
unsafe fn magnitude8<const W: usize>(f: *const f32) -> __m256 {
    // SAFETY: the caller guarantees the memory and AVX2.
    unsafe {
        if W == 2 {
            let (re, im) = load_pairs(f);
            _mm256_sqrt_ps(_mm256_add_ps(_mm256_mul_ps(re, re), _mm256_mul_ps(im, im)))
        } else {
            _mm256_loadu_ps(f)
        }
    }
}

/// Pass 2 on eight pixels of magnitude `mag`: `phase` (8 values at `p`) becomes the wrapped double phase;
/// returns the codes as eight i32 lanes.
///
/// # Safety
/// AVX2; `p` has 8 readable and writable f32.
#[inline(always)]
unsafe fn encode8(mag: __m256, p: *mut f32, mean: __m256, inv_a: __m256, sign: __m256) -> __m256i {
    // SAFETY: the caller guarantees the memory and AVX2.
    unsafe {
        let r = _mm256_mul_ps(mag, inv_a);
        let one = splat(1.0);
        let r = sel(_mm256_cmp_ps::<_CMP_GT_OQ>(r, one), one, r);
        let v = _mm256_add_ps(
            _mm256_sub_ps(_mm256_loadu_ps(p), mean),
            _mm256_mul_ps(sign, acos_v(r)),
        );
        let (tau, zero) = (splat(TAU), _mm256_setzero_ps());
        // Far outside [−4π, 4π): the portable wrap (`rem_euclid`) per lane. NaN counts as near.
        let far = _mm256_or_ps(
            _mm256_cmp_ps::<_CMP_LT_OQ>(v, splat(-2.0 * TAU)),
            _mm256_cmp_ps::<_CMP_GE_OQ>(v, splat(2.0 * TAU)),
        );
        let w = if _mm256_movemask_ps(far) == 0 {
            let mut w = v;
            w = sel(
                _mm256_cmp_ps::<_CMP_LT_OQ>(w, zero),
                _mm256_add_ps(w, tau),
                w,
            );
            w = sel(
                _mm256_cmp_ps::<_CMP_LT_OQ>(w, zero),
                _mm256_add_ps(w, tau),
                w,
            );
            w = sel(
                _mm256_cmp_ps::<_CMP_GE_OQ>(w, tau),
                _mm256_sub_ps(w, tau),
                w,
            );
            w = sel(
                _mm256_cmp_ps::<_CMP_GE_OQ>(w, tau),
                _mm256_sub_ps(w, tau),
                w,
            );
            let out = _mm256_or_ps(
                _mm256_cmp_ps::<_CMP_GE_OQ>(w, tau),
                _mm256_cmp_ps::<_CMP_LT_OQ>(w, zero),
            );
            _mm256_andnot_ps(out, w)
        } else {
            let mut a = [0.0f32; LANES];
            _mm256_storeu_ps(a.as_mut_ptr(), v);
            for x in a.iter_mut() {
                *x = wrap_phase(*x);
            }
            _mm256_loadu_ps(a.as_ptr())
        };
        _mm256_storeu_ps(p, w);
        // The code: round(w·256/2π) by truncation and a compare, mod 256 (cvtt gives i32::MIN for NaN,
        // whose low byte is 0 as the portable `NaN as i32` = 0).
        let x = _mm256_mul_ps(w, splat(256.0 / TAU));
        let i = _mm256_cvttps_epi32(x);
        let frac = _mm256_sub_ps(x, _mm256_cvtepi32_ps(i));
        let up = _mm256_castps_si256(_mm256_cmp_ps::<_CMP_GE_OQ>(frac, splat(0.5)));
        // `up` is −1 where rounding up.
        _mm256_and_si256(_mm256_sub_epi32(i, up), _mm256_set1_epi32(255))
    }
}

/// The low bytes of eight i32 lanes (each in `0..=255`), in order.
///
/// # Safety
/// AVX2.
#[inline(always)]
unsafe fn pack_codes(c: __m256i) -> [u8; LANES] {
    // SAFETY: AVX2 by the caller; stores into a local array of 8 bytes.
    unsafe {
        let w = _mm256_packus_epi32(c, c); // [c0..c3 c0..c3 | c4..c7 c4..c7] as u16
        let b = _mm256_packus_epi16(w, w); // bytes c0..c3 repeated | c4..c7 repeated
        let lo = _mm256_castsi256_si128(b);
        let hi = _mm256_extracti128_si256::<1>(b);
        let v = _mm_unpacklo_epi32(lo, hi);
        let mut out = [0u8; LANES];
        _mm_storel_epi64(out.as_mut_ptr().cast(), v);
        out
    }
}

/// Pass 2 on one row (lengths checked by the caller), as [`super::body::encode_body`].
///
/// # Safety
/// The CPU has AVX2 and FMA; `field.len() == 2·phase.len()`, `codes` (if any) as long as `phase`.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn encode_avx2(
    field: &[f32],
    phase: &mut [f32],
    codes: Option<&mut [u8]>,
    prm: &EncodeParams,
) {
    debug_assert_eq!(field.len(), 2 * phase.len());
    // SAFETY: AVX2 (this function's feature); the lengths as `encode_row_of` needs.
    unsafe { encode_row_of::<2>(field, phase, codes, prm) }
}

/// Pass 2 on one row whose magnitudes are given, as [`super::body::encode_abs_body`].
///
/// # Safety
/// The CPU has AVX2 and FMA; `abs.len() == phase.len()`, `codes` (if any) as long as `phase`.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn encode_abs_avx2(
    abs: &[f32],
    phase: &mut [f32],
    codes: Option<&mut [u8]>,
    prm: &EncodeParams,
) {
    debug_assert_eq!(abs.len(), phase.len());
    // SAFETY: AVX2 (this function's feature); the lengths as `encode_row_of` needs.
    unsafe { encode_row_of::<1>(abs, phase, codes, prm) }
}

/// Pass 2 on one row of `W` values per pixel ([`magnitude8`]).
///
/// # Safety
/// AVX2; `field.len() == W·phase.len()`, `codes` (if any) as long as `phase`.
#[inline(always)]
unsafe fn encode_row_of<const W: usize>(
    field: &[f32],
    phase: &mut [f32],
    mut codes: Option<&mut [u8]>,
    prm: &EncodeParams,
) {
    let n = phase.len();
    let full = n / LANES * LANES;
    // SAFETY: AVX2 by the caller; reads 8 values of a local array.
    let (mean, inv_a, sign) = unsafe {
        (
            _mm256_set1_ps(prm.mean),
            _mm256_set1_ps(prm.inv_a),
            _mm256_loadu_ps(prm.sign.as_ptr()),
        )
    };
    let mut x = 0;
    while x < full {
        // SAFETY: x + 8 ≤ n pixels: 8·W values of `field` and 8 of `phase` from there.
        let c = unsafe {
            let mag = magnitude8::<W>(field.as_ptr().add(W * x));
            encode8(mag, phase.as_mut_ptr().add(x), mean, inv_a, sign)
        };
        if let Some(codes) = codes.as_deref_mut() {
            // SAFETY: AVX2.
            codes[x..x + LANES].copy_from_slice(&unsafe { pack_codes(c) });
        }
        x += LANES;
    }
    if x < n {
        let k = n - x;
        let mut f = [0.0f32; 2 * LANES];
        f[..W * k].copy_from_slice(&field[W * x..]);
        let mut p = [0.0f32; LANES];
        p[..k].copy_from_slice(&phase[x..]);
        // SAFETY: local arrays of 16 and 8 values; AVX2.
        let c = unsafe {
            let mag = magnitude8::<W>(f.as_ptr());
            pack_codes(encode8(mag, p.as_mut_ptr(), mean, inv_a, sign))
        };
        phase[x..].copy_from_slice(&p[..k]);
        if let Some(codes) = codes {
            codes[x..].copy_from_slice(&c[..k]);
        }
    }
}

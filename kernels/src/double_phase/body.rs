//! The double phase rows' portable bodies ([`crate::double_phase`] gives the method and the error bounds):
//! plain safe Rust on chunks of [`LANES`] pixels held in fixed-size arrays, branch-free (selects only), which
//! the compiler vectorises as far as it can (SSE2 on x86-64, NEON on aarch64). The AVX2 path
//! (`super::avx2`) writes the same operations out in intrinsics. Rust never contracts `a·b + c` into an
//! FMA and never reorders float arithmetic, so every path computes bit-identical values (tested).

use std::f32::consts::{FRAC_PI_2, FRAC_PI_4, PI, TAU};

/// Pixels per chunk: one AVX2 register of f32, two SSE2 / NEON registers.
pub(crate) const LANES: usize = 8;

/// `tan(π/8)`: above it, `atan(t) = π/4 + atan((t − 1)/(t + 1))`.
pub(crate) const TAN_PI_8: f32 = 0.414_213_57;

/// Above this magnitude `n + d` could overflow: both are scaled by 1/4 first (the ratio is unchanged).
pub(crate) const HUGE: f32 = 1.0e37;

/// The Cephes `atanf` polynomial, highest power first: `atan(t) ≈ t + t·z·(((P0·z + P1)·z + P2)·z + P3)`,
/// `z = t²`, on `|t| ≤ tan(π/8)`.
pub(crate) const ATAN_P: [f32; 4] = [
    8.053_744_5e-2,
    -1.387_768_5e-1,
    1.997_771_1e-1,
    -3.333_295e-1,
];

/// The Cephes `asinf` polynomial, highest power first: `asin(s) ≈ s + s·z·((((P0·z + P1)·z + P2)·z + P3)·z
/// + P4)`, `z = s²`, on `s ∈ [0, 1/2]`.
pub(crate) const ASIN_P: [f32; 5] = [
    4.216_32e-2,
    2.418_131e-2,
    4.547_002_6e-2,
    7.495_300_3e-2,
    1.666_675_2e-1,
];

/// `atan2(y, x)` in radians, `[−π, π]`, with the signs of zeros and infinities as IEEE `atan2`: `(±0, +0)`
/// → ±0, `(±0, −0)` → ±π, `(±∞, ±∞)` → ±π/4 or ±3π/4; NaN in, NaN out.
///
/// Method: `n = min(|x|, |y|)`, `d = max(|x|, |y|)`, `t = n/d ∈ [0, 1]` (or `(n − d)/(n + d)` when
/// `n > tan(π/8)·d`, adding π/4: one division either way), then the Cephes `atanf` polynomial on
/// `|t| ≤ tan(π/8)` (`ATAN_P`, degree 9 in `t`), then the octant: `π/2 − r` where `|y| > |x|`, `π − r`
/// where `x < 0`, the sign of `y`. Error: at most [`super::ATAN2_MAX_ERROR`] = 4.8e-7 rad (2·10⁻⁵ of an SLM
/// code step) from the exact value.
#[inline(always)]
pub fn atan2(y: f32, x: f32) -> f32 {
    let (ax, ay) = (x.abs(), y.abs());
    let swap = ay > ax;
    let n = if swap { ax } else { ay };
    let d = if swap { ay } else { ax };
    let s = if d > HUGE { 0.25 } else { 1.0 };
    let (n, d) = (n * s, d * s);
    // Both infinite: `n > tan(π/8)·d` is false (∞ > ∞); the upper branch gives π/4 as IEEE wants.
    let upper = n > TAN_PI_8 * d || n == f32::INFINITY;
    let num = if upper { n - d } else { n };
    let den = if upper { n + d } else { d };
    let t = num / den;
    // 0/0 (both zero) and ∞/∞ (both infinite); a NaN input is restored below.
    let t = if t.is_nan() { 0.0 } else { t };
    let z = t * t;
    let p = (((ATAN_P[0] * z + ATAN_P[1]) * z + ATAN_P[2]) * z + ATAN_P[3]) * z * t + t;
    let r = if upper { p + FRAC_PI_4 } else { p };
    let r = if swap { FRAC_PI_2 - r } else { r };
    let r = if x.is_sign_negative() { PI - r } else { r };
    let r = f32::from_bits(r.to_bits() | (y.to_bits() & 0x8000_0000));
    if x.is_nan() || y.is_nan() {
        f32::NAN
    } else {
        r
    }
}

/// `acos(x)` in radians for `x ∈ [0, 1]` (the caller clamps; NaN in, NaN out).
///
/// Method: `acos(x) = π/2 − asin(x)` for `x ≤ 1/2`, `2·asin(√((1 − x)/2))` above (`1 − x` is exact there),
/// with the Cephes `asinf` polynomial on `[0, 1/2]` (`ASIN_P`, degree 11 in `s`). Error: at most
/// [`super::ACOS_MAX_ERROR`] = 2.4e-7 rad (10⁻⁵ of an SLM code step) from the exact value.
#[inline(always)]
pub fn acos_unit(x: f32) -> f32 {
    let big = x > 0.5;
    let z = if big { (1.0 - x) * 0.5 } else { x * x };
    let s = if big { z.sqrt() } else { x };
    let p =
        ((((ASIN_P[0] * z + ASIN_P[1]) * z + ASIN_P[2]) * z + ASIN_P[3]) * z + ASIN_P[4]) * z * s
            + s;
    if big {
        2.0 * p
    } else {
        FRAC_PI_2 - p
    }
}

/// Wraps a phase in radians to `[0, 2π)`. NaN stays NaN. For `|phase| < 4π` it adds or subtracts `2π` at
/// most twice (exact to the rounding of that sum); beyond, `rem_euclid`.
#[inline(always)]
pub fn wrap_phase(phase: f32) -> f32 {
    if (-2.0 * TAU..2.0 * TAU).contains(&phase) {
        wrap_near(phase)
    } else {
        let w = phase.rem_euclid(TAU);
        // rem_euclid can round up to exactly 2π for tiny negative inputs.
        if w >= TAU {
            0.0
        } else {
            w
        }
    }
}

/// [`wrap_phase`] for `phase ∈ [−4π, 4π)`, branch-free (also NaN → NaN).
#[inline(always)]
fn wrap_near(phase: f32) -> f32 {
    // Selects, not `w + 0`: that would turn −0 into +0 (the scalar wrap keeps −0).
    let mut w = phase;
    w = if w < 0.0 { w + TAU } else { w };
    w = if w < 0.0 { w + TAU } else { w };
    w = if w >= TAU { w - TAU } else { w };
    w = if w >= TAU { w - TAU } else { w };
    // Adding 2π to a tiny negative value can round up to exactly 2π. Not `!(0..2π).contains`: NaN stays NaN.
    #[allow(clippy::manual_range_contains)]
    if w >= TAU || w < 0.0 {
        0.0
    } else {
        w
    }
}

/// The linear look-up table's code of a phase already wrapped to `[0, 2π)`: `round(p·256/2π) mod 256`,
/// ties away from zero (as `f32::round`); NaN gives 0 (as `NaN as u32`). Branch-free, no libm call.
#[inline(always)]
pub fn linear_code_wrapped(p: f32) -> u8 {
    let x = p * (256.0 / TAU);
    let i = x as i32;
    // Exact: x < 2²³. NaN compares false.
    let frac = x - i as f32;
    let c = i + if frac >= 0.5 { 1 } else { 0 };
    (c & 255) as u8
}

/// Pass 1 on `LANES` pixels given as `(re, im)`: phases out, running max of `|H|²` and f64 sums per lane;
/// returns each pixel's `|H|²`.
#[inline(always)]
fn analyse_lanes(
    re: &[f32; LANES],
    im: &[f32; LANES],
    out: &mut [f32],
    max: &mut [f32; LANES],
    sum: &mut [f64; LANES],
) -> [f32; LANES] {
    let mut n2 = [0.0f32; LANES];
    for i in 0..LANES {
        let p = atan2(im[i], re[i]);
        out[i] = p;
        n2[i] = re[i] * re[i] + im[i] * im[i];
        // As f32::max: a NaN |H|² is skipped.
        max[i] = if n2[i] > max[i] { n2[i] } else { max[i] };
        sum[i] += p as f64;
    }
    n2
}

/// Pass 1 on `LANES` pixels of interleaved `(re, im)` pairs.
#[inline(always)]
fn analyse_chunk(f: &[f32], out: &mut [f32], max: &mut [f32; LANES], sum: &mut [f64; LANES]) {
    let (mut re, mut im) = ([0.0f32; LANES], [0.0f32; LANES]);
    for i in 0..LANES {
        re[i] = f[2 * i];
        im[i] = f[2 * i + 1];
    }
    analyse_lanes(&re, &im, out, max, sum);
}

/// The row's statistics from the lanes': `(max |H|², Σ arg H)`.
#[inline(always)]
fn row_stats(max: &[f32; LANES], sum: &[f64; LANES]) -> (f32, f64) {
    let m = max.iter().fold(0.0f32, |a, &b| if b > a { b } else { a });
    (m, sum.iter().sum())
}

/// Pass 1 on one row: `field` interleaved `(re, im)` pairs, `phase` one value per pixel (lengths checked
/// by the caller). Returns `(max |H|², Σ arg H)`.
#[inline(always)]
pub(crate) fn analyse_body(field: &[f32], phase: &mut [f32]) -> (f32, f64) {
    let mut max = [0.0f32; LANES];
    let mut sum = [0.0f64; LANES];
    let mut fc = field.chunks_exact(2 * LANES);
    let mut pc = phase.chunks_exact_mut(LANES);
    for (f, out) in (&mut fc).zip(&mut pc) {
        analyse_chunk(f, out, &mut max, &mut sum);
    }
    let (ft, pt) = (fc.remainder(), pc.into_remainder());
    if !pt.is_empty() {
        // Zero padding: arg 0 = 0 and |0|² = 0 change neither statistic.
        let mut f = [0.0f32; 2 * LANES];
        f[..ft.len()].copy_from_slice(ft);
        let mut out = [0.0f32; LANES];
        analyse_chunk(&f, &mut out, &mut max, &mut sum);
        pt.copy_from_slice(&out[..pt.len()]);
    }
    row_stats(&max, &sum)
}

/// Pass 1 on one row held as planes (lengths checked by the caller): `re`, `im_arg` (`Im H` in, `arg H`
/// out) and `abs` (receives `|H| = √(Re² + Im²)`, the value pass 2 computes from the pairs). The same
/// statistics as [`analyse_body`] on the interleaved row, in the same order.
#[inline(always)]
pub(crate) fn analyse_planes_body(re: &[f32], im_arg: &mut [f32], abs: &mut [f32]) -> (f32, f64) {
    let mut max = [0.0f32; LANES];
    let mut sum = [0.0f64; LANES];
    let mut rc = re.chunks_exact(LANES);
    let mut ic = im_arg.chunks_exact_mut(LANES);
    let mut ac = abs.chunks_exact_mut(LANES);
    for ((r, i), a) in (&mut rc).zip(&mut ic).zip(&mut ac) {
        let (mut rv, mut iv) = ([0.0f32; LANES], [0.0f32; LANES]);
        rv.copy_from_slice(r);
        iv.copy_from_slice(i);
        let n2 = analyse_lanes(&rv, &iv, i, &mut max, &mut sum);
        for (a, n) in a.iter_mut().zip(n2) {
            *a = n.sqrt();
        }
    }
    let (rt, it, at) = (rc.remainder(), ic.into_remainder(), ac.into_remainder());
    if !it.is_empty() {
        // Zero padding, as in `analyse_body`.
        let (mut rv, mut iv) = ([0.0f32; LANES], [0.0f32; LANES]);
        rv[..rt.len()].copy_from_slice(rt);
        iv[..it.len()].copy_from_slice(it);
        let mut out = [0.0f32; LANES];
        let n2 = analyse_lanes(&rv, &iv, &mut out, &mut max, &mut sum);
        let k = it.len();
        it.copy_from_slice(&out[..k]);
        for (a, n) in at.iter_mut().zip(n2) {
            *a = n.sqrt();
        }
    }
    row_stats(&max, &sum)
}

/// What pass 2 needs besides the row: the mean phase, `1/a`, and the sign of `acos` per lane (`+1` where
/// `x + y` is even).
#[derive(Debug, Clone, Copy)]
pub(crate) struct EncodeParams {
    pub mean: f32,
    pub inv_a: f32,
    pub sign: [f32; LANES],
}

impl EncodeParams {
    pub(crate) fn new(mean: f32, inv_a: f32, odd_row: bool) -> Self {
        let mut sign = [1.0f32; LANES];
        for (i, s) in sign.iter_mut().enumerate() {
            if (i + odd_row as usize) % 2 == 1 {
                *s = -1.0;
            }
        }
        Self { mean, inv_a, sign }
    }
}

/// Pass 2 on `LANES` pixels of magnitude `mag` (`|H|`): `phase` (arg H) becomes the wrapped double phase
/// `φ − mean ± acos(|H|/a)`; returns the linear look-up table's codes.
#[inline(always)]
fn encode_lanes(mag: &[f32; LANES], phase: &mut [f32], prm: &EncodeParams) -> [u8; LANES] {
    let mut v = [0.0f32; LANES];
    let mut near = true;
    for i in 0..LANES {
        let r = mag[i] * prm.inv_a;
        // As f32::min(r, 1.0) but for NaN, whose phase is NaN anyway.
        let r = if r > 1.0 { 1.0 } else { r };
        // a − θ and a + (−1)·θ are the same IEEE operation.
        v[i] = (phase[i] - prm.mean) + prm.sign[i] * acos_unit(r);
        // NaN counts as near: `wrap_near` keeps it NaN, as `wrap_phase` does.
        near &= !(v[i] < -2.0 * TAU || v[i] >= 2.0 * TAU);
    }
    if near {
        for i in 0..LANES {
            phase[i] = wrap_near(v[i]);
        }
    } else {
        // Only for a mean phase far outside [−π, π] (a caller's value): `rem_euclid` where needed.
        for i in 0..LANES {
            phase[i] = wrap_phase(v[i]);
        }
    }
    let mut codes = [0u8; LANES];
    for i in 0..LANES {
        codes[i] = linear_code_wrapped(phase[i]);
    }
    codes
}

/// Pass 2 on `LANES` pixels: `W = 2` values per pixel are interleaved `(re, im)` pairs (`|H| = √(re² +
/// im²)`), `W = 1` the magnitudes themselves (from [`analyse_planes_body`]).
#[inline(always)]
fn encode_chunk<const W: usize>(f: &[f32], phase: &mut [f32], prm: &EncodeParams) -> [u8; LANES] {
    let mut mag = [0.0f32; LANES];
    for i in 0..LANES {
        mag[i] = if W == 2 {
            let (re, im) = (f[2 * i], f[2 * i + 1]);
            (re * re + im * im).sqrt()
        } else {
            f[i]
        };
    }
    encode_lanes(&mag, phase, prm)
}

/// Pass 2 on one row (lengths checked by the caller): `phase` holds `arg H` from pass 1 and becomes the
/// wrapped double phase; `codes`, if given, the linear look-up table's codes. `field` holds `W` values per
/// pixel ([`encode_chunk`]): `W = 2` interleaved pairs ([`super::encode_row`]'s portable path), `W = 1` the
/// magnitudes `|H|` ([`super::encode_abs_row`]'s, bit-identical with `W = 2` on the pairs they came from).
#[inline(always)]
pub(crate) fn encode_row_of<const W: usize>(
    field: &[f32],
    phase: &mut [f32],
    codes: Option<&mut [u8]>,
    prm: &EncodeParams,
) {
    let mut fc = field.chunks_exact(W * LANES);
    let mut pc = phase.chunks_exact_mut(LANES);
    let mut tail_codes = [0u8; LANES];
    match codes {
        Some(codes) => {
            let mut cc = codes.chunks_exact_mut(LANES);
            for ((f, p), c) in (&mut fc).zip(&mut pc).zip(&mut cc) {
                c.copy_from_slice(&encode_chunk::<W>(f, p, prm));
            }
            encode_tail::<W>(fc.remainder(), pc.into_remainder(), &mut tail_codes, prm);
            let ct = cc.into_remainder();
            let n = ct.len();
            ct.copy_from_slice(&tail_codes[..n]);
        }
        None => {
            for (f, p) in (&mut fc).zip(&mut pc) {
                encode_chunk::<W>(f, p, prm);
            }
            encode_tail::<W>(fc.remainder(), pc.into_remainder(), &mut tail_codes, prm);
        }
    }
}

/// The last `phase.len() < LANES` pixels of a row, through a zero-padded chunk.
#[inline(always)]
fn encode_tail<const W: usize>(
    field: &[f32],
    phase: &mut [f32],
    codes: &mut [u8; LANES],
    prm: &EncodeParams,
) {
    if phase.is_empty() {
        return;
    }
    let n = phase.len();
    let mut f = [0.0f32; 2 * LANES];
    f[..field.len()].copy_from_slice(field);
    let mut p = [0.0f32; LANES];
    p[..n].copy_from_slice(phase);
    *codes = encode_chunk::<W>(&f[..W * LANES], &mut p, prm);
    phase.copy_from_slice(&p[..n]);
}

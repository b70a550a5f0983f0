//! The double phase encoding's per-pixel arithmetic (paper Eq. 7, the SDK's `encoding` module), vectorised:
//! pass 1 `arg H = atan2(Im H, Re H)` with the row's maximum `|H|²` and `Σ arg H` (f64), pass 2 the wrapped
//! double phase `φ − mean ± acos(|H|/a)` (`+` where `x + y` is even) and the linear look-up table's 8-bit
//! code `round(256·P/2π) mod 256`.
//!
//! libm's `atan2f` and `acosf` are function calls per pixel that the compiler cannot vectorise; with the
//! branchy wrap they cost about 29 ns per pixel (1080p, one thread). Here `atan2` and `acos` are
//! polynomials with branch-free range reduction ([`atan2`], [`acos_unit`]: the Cephes `atanf`/`asinf`
//! polynomials), the wrap adds or subtracts `2π` by selects, and the code rounds by truncation and a
//! compare (`f32::round` is a libm call on SSE2). Three paths: the portable body (`body.rs`, plain safe Rust
//! on chunks of 8 pixels in fixed-size arrays, which the compiler vectorises as far as it can: SSE2 on
//! x86-64, NEON on aarch64) and, on x86-64, the same operations written once over the crate's register
//! trait (`simd.rs`, generic over `crate::simd::SimdF32`) and instantiated in `x86.rs` on AVX2 (ymm, 8
//! pixels per step: the compiler's vectorisation of the body stayed at xmm width with spills, 2–3× slower)
//! and on AVX-512F (zmm, 16 pixels per step, mask blends: 1.8× the AVX2 rows on Zen 5,
//! `docs/BENCHMARKS.md`). None uses FMA
//! (Rust does not contract `a·b + c`, and the intrinsics multiply and add apart), so every path is
//! bit-identical (tested on rows and on the exhaustive sweep).
//!
//! A field the pre-filter left as two planes needs no interleaved copy: [`analyse_planes_row`] reads `Re H`
//! and `Im H` where they are, writes `arg H` over `Im H` and `|H|` into a plane of its own, and
//! [`encode_abs_row`] runs pass 2 from `|H|` (the value pass 2 computes from the pairs), so pass 2 reads two
//! planes of one value per pixel instead of the pairs and `arg H`; the same bits as the interleaved rows
//! on every path (tested).
//!
//! # Error bounds (measured, `tests`)
//!
//! Against the exact value (f64 `atan2`/`acos` rounded to f32 is within half an f32 ulp of it):
//!
//! * [`atan2`]: at most [`ATAN2_MAX_ERROR`] = 4.8e-7 rad (2 ulp of π) over every finite and infinite input:
//!   measured on all 2³¹ non-negative f32 `y` against `x = ±1` and `x = ±1.7`, ±0, and 10⁷ random pairs of
//!   any signs and exponents (denormals included);
//! * [`acos_unit`]: at most [`ACOS_MAX_ERROR`] = 2.4e-7 rad (1 ulp of π/2..π) on every f32 in `[0, 1]`
//!   (exhaustive, 1 065 353 217 values);
//! * the encoded phase (both, the subtraction of the mean, the sum and the wrap): within
//!   [`PHASE_MAX_ERROR`] = 1.2e-6 rad of the same formula with libm's `atan2f`/`acosf` (compared modulo
//!   `2π`), that is 5·10⁻⁵ of one SLM code step (`2π/256` = 0.0245 rad).
//!
//! So an 8-bit code equals libm's or differs by exactly one step (mod 256), and only where libm's phase lies
//! within 1.2e-6 rad of a rounding boundary between two codes: on random fields about 1 pixel in 10⁴ at
//! most (`tests`; the SDK counts the real frames).

pub(crate) mod body;
#[cfg(target_arch = "x86_64")]
mod simd;
#[cfg(target_arch = "x86_64")]
pub(crate) mod x86;

pub use body::{acos_unit, atan2, linear_code_wrapped, wrap_phase};

use crate::dispatch::{self, Path};
use crate::error::KernelError;
use crate::isa::Isa;
use crate::pack::check_len;

/// One level's double phase rows, on checked lengths.
#[derive(Debug, Clone, Copy)]
pub(crate) struct DpmFns {
    /// Pass 1 ([`analyse_row`]): interleaved `(re, im)` in, `arg H` out; `(max |H|², Σ arg)`.
    pub analyse: unsafe fn(&[f32], &mut [f32]) -> (f32, f64),
    /// Pass 2 ([`encode_row`]): the wrapped double phase in place, codes if asked.
    pub encode: EncodeFn,
    /// Pass 1 on planes ([`analyse_planes_row`]): `re`, `Im H` in place → `arg H`, `|H|` out.
    pub analyse_planes: AnalysePlanesFn,
    /// Pass 2 on magnitudes ([`encode_abs_row`]).
    pub encode_abs: EncodeFn,
}

/// Pass 1 on a row held as planes: `re`, `Im H` in place → `arg H`, `|H|` out; `(max |H|², Σ arg H)`.
pub(crate) type AnalysePlanesFn = unsafe fn(&[f32], &mut [f32], &mut [f32]) -> (f32, f64);
/// Pass 2 of the double phase encoding on a row: the wrapped double phase in place, codes if asked.
pub(crate) type EncodeFn = unsafe fn(&[f32], &mut [f32], Option<&mut [u8]>, &body::EncodeParams);

/// The double phase rows' paths, best first: AVX-512F (zmm), AVX2 (ymm), the portable body (SSE2 / NEON).
pub(crate) static PATHS: &[Path<DpmFns>] = &[
    #[cfg(target_arch = "x86_64")]
    Path {
        isa: Isa::Avx512,
        run: DpmFns {
            analyse: x86::analyse_avx512,
            encode: x86::encode_avx512,
            analyse_planes: x86::analyse_planes_avx512,
            encode_abs: x86::encode_abs_avx512,
        },
    },
    #[cfg(target_arch = "x86_64")]
    Path {
        isa: Isa::Avx2Fma,
        run: DpmFns {
            analyse: x86::analyse_avx2,
            encode: x86::encode_avx2,
            analyse_planes: x86::analyse_planes_avx2,
            encode_abs: x86::encode_abs_avx2,
        },
    },
    Path {
        isa: Isa::Scalar,
        run: DpmFns {
            analyse: body::analyse_body,
            encode: body::encode_row_of::<2>,
            analyse_planes: body::analyse_planes_body,
            encode_abs: body::encode_row_of::<1>,
        },
    },
];

/// The maximum error of [`atan2`] in radians against the exact `atan2` (module docs: how it was measured).
pub const ATAN2_MAX_ERROR: f32 = 4.8e-7;
/// The maximum error of [`acos_unit`] in radians on `[0, 1]` against the exact `acos` (exhaustive).
pub const ACOS_MAX_ERROR: f32 = 2.4e-7;
/// The maximum distance (radians, modulo 2π) of a phase from [`encode_row`] to the same formula evaluated
/// with libm's `atan2f` and `acosf` for a mean phase in `[−π, π]`.
pub const PHASE_MAX_ERROR: f32 = 1.2e-6;

/// Pass 1 of the double phase encoding on one row of `n` pixels: `field` holds `2n` values, the
/// interleaved `(Re H, Im H)` of each pixel (the memory of `n` complex f32), `phase` receives `arg H`
/// ([`atan2`], radians in `[−π, π]`). Returns `(max |H|², Σ arg H)`, the sum in f64 (eight lanes summed
/// apart, then together). A NaN `|H|²` is skipped by the maximum, as `f32::max` does. Errors: lengths
/// ([`KernelError::Length`]), `isa` not available ([`KernelError::Isa`]).
pub fn analyse_row(field: &[f32], phase: &mut [f32], isa: Isa) -> Result<(f32, f64), KernelError> {
    check_len(
        "double phase field (2 values per pixel)",
        field.len(),
        2 * phase.len(),
    )?;
    let run = dispatch::pick(PATHS, isa)?.analyse;
    // SAFETY: `pick` checked that this CPU has `isa`, which includes the level of the path it returned;
    // the lengths are checked above.
    Ok(unsafe { run(field, phase) })
}

/// Pass 2 of the double phase encoding on one row of `n` pixels (Eq. 7): `phase` holds `arg H` from
/// [`analyse_row`] and becomes `wrap(φ − mean ± acos(min(|H|·inv_a, 1)))` in `[0, 2π)`, `+` where `x + y`
/// is even (`x` the pixel's index in the row, `odd_row` the parity of `y`); `codes`, if given, receives the
/// linear look-up table's 8-bit codes `round(256·P/2π) mod 256`. `field` as for [`analyse_row`]. Errors:
/// lengths ([`KernelError::Length`]), `isa` not available ([`KernelError::Isa`]).
pub fn encode_row(
    field: &[f32],
    phase: &mut [f32],
    codes: Option<&mut [u8]>,
    odd_row: bool,
    mean: f32,
    inv_a: f32,
    isa: Isa,
) -> Result<(), KernelError> {
    let row = (false, field, odd_row);
    encode_checked(row, phase, codes, mean, inv_a, isa)
}

/// Pass 1 on one row of `n` pixels held as two planes, as the pre-filter writes them: `re` holds `Re H`,
/// `im_arg` holds `Im H` and receives `arg H` (as [`analyse_row`]'s `phase`), `abs` receives `|H| =
/// √(Re² + Im²)` for [`encode_abs_row`]. Returns [`analyse_row`]'s `(max |H|², Σ arg H)` of the interleaved
/// row, bit for bit (the same lanes in the same order), and writes the same `arg H`; no interleaved copy of the
/// field is made (pass 2 then reads `|H|` and `arg H`, two planes, instead of the field and `arg H`). Errors:
/// lengths ([`KernelError::Length`]), `isa` not available ([`KernelError::Isa`]).
pub fn analyse_planes_row(
    re: &[f32],
    im_arg: &mut [f32],
    abs: &mut [f32],
    isa: Isa,
) -> Result<(f32, f64), KernelError> {
    check_len("double phase Re H plane", re.len(), im_arg.len())?;
    check_len("double phase |H| plane", abs.len(), im_arg.len())?;
    let run = dispatch::pick(PATHS, isa)?.analyse_planes;
    // SAFETY: `pick` checked that this CPU has `isa`, which includes the level of the path it returned;
    // the lengths are checked above.
    Ok(unsafe { run(re, im_arg, abs) })
}

/// [`encode_row`] on a row whose magnitudes `|H|` are given (`abs`, one value per pixel, from
/// [`analyse_planes_row`]) instead of its `(Re H, Im H)` pairs: bit-identical to [`encode_row`] on the pairs
/// they came from (`|H|` is the value [`encode_row`] computes). Errors: as [`encode_row`].
pub fn encode_abs_row(
    abs: &[f32],
    phase: &mut [f32],
    codes: Option<&mut [u8]>,
    odd_row: bool,
    mean: f32,
    inv_a: f32,
    isa: Isa,
) -> Result<(), KernelError> {
    let row = (true, abs, odd_row);
    encode_checked(row, phase, codes, mean, inv_a, isa)
}

/// [`encode_row`] (`magnitudes` false: `values` holds the pairs) or [`encode_abs_row`] (true: `|H|`), the
/// lengths checked.
fn encode_checked(
    (magnitudes, values, odd_row): (bool, &[f32], bool),
    phase: &mut [f32],
    codes: Option<&mut [u8]>,
    mean: f32,
    inv_a: f32,
    isa: Isa,
) -> Result<(), KernelError> {
    let (what, per_pixel) = if magnitudes {
        ("double phase |H| plane", 1)
    } else {
        ("double phase field (2 values per pixel)", 2)
    };
    check_len(what, values.len(), per_pixel * phase.len())?;
    if let Some(c) = &codes {
        check_len("double phase codes", c.len(), phase.len())?;
    }
    let params = body::EncodeParams::new(mean, inv_a, odd_row);
    let paths = dispatch::pick(PATHS, isa)?;
    let run = if magnitudes {
        paths.encode_abs
    } else {
        paths.encode
    };
    // SAFETY: `pick` checked that this CPU has `isa`, which includes the level of the path it returned;
    // the lengths are checked above.
    unsafe { run(values, phase, codes, &params) };
    Ok(())
}

#[cfg(test)]
mod tests;

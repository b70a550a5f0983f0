//! The hologram CNN's heads as complex phasors, vectorised: amplitude head `a` and phase head `p` (turns,
//! `[0, 1]` by the model contract) → `a·e^{iθ}`, `θ = 2π·(p − 0.5)`, interleaved `(re, im)` as the memory of
//! complex f32 (the midpoint hologram the offset propagation transforms, paper Eq. 6).
//!
//! libm's `sinf` and `cosf` are two function calls per pixel that the compiler cannot vectorise: at 1080p,
//! 10 ns per pixel (one 1080p plane in 21.4 ms, below). Here both come from one branch-free
//! [`sincos_turns`] on the angle in *turns*: the whole and quarter turns are removed exactly (rounding by
//! the `1.5·2²⁴` and `1.5·2²³` tricks, Sterbenz's lemma for the subtraction), so the only rounding before the polynomials is
//! `x = r·2π` on `|x| ≤ π/4`, and the Cephes `sinf`/`cosf` polynomials (degree 7 and 8) give the rest; the
//! quadrant swaps and negates by selects and sign-bit flips. Any finite `p` works (a phase head far outside
//! `[0, 1]` is reduced exactly); NaN and infinities are reported, not hidden ([`phasors`] returns whether
//! every input was finite).
//!
//! The same body runs on every path, compiled portable (SSE2 / NEON: 4 lanes) and, on x86-64, inside
//! `#[target_feature(enable = "avx2")]` and `"avx512f"` functions (8 and 16 lanes), on chunks of 16 pixels.
//! Rust never contracts `a·b + c` into an FMA, so every path gives the bit-identical result (tested).
//!
//! # Error bound (measured, `tests`)
//!
//! Against the exact `a·(cos θ, sin θ)` of `θ = 2π·(p − 0.5)` (with `p − 0.5` rounded to f32, as the
//! definition in f32 does; computed in f64): each component within [`PHASOR_MAX_ERROR`]`·|a|` = 1.0e-7·|a|
//! (measured worst 9.1e-8 on every f32 `p` in `[0, 1]`, exhaustive, 1 065 353 217 values; 9.0e-8 on 10⁷
//! random `p` of any sign and exponent up to 2⁴⁰). As a phase error that is at most 1.0e-7 rad, 4·10⁻⁶ of an
//! SLM code step (`2π/256`). libm's `from_polar(a, (p − 0.5)·2π)`, which rounds the angle to f32 first, is
//! up to 2.1e-7 from the exact value on the same sweep.
//!
//! Speed, one 1080×1920 plane in place, one thread (AMD EPYC Zen 4; `cargo bench -p tensorholo-kernels
//! --bench conv3x3 -- phasors`, criterion medians): AVX-512 1.90 ms, AVX2 2.26 ms, portable (SSE2) 4.16 ms;
//! libm's `sin_cos` per pixel 21.4 ms.

pub(crate) mod body;

pub use body::{phasor, sincos_turns};

use crate::dispatch::{self, Path};
use crate::error::KernelError;
use crate::isa::Isa;
use crate::pack::check_len;

/// One level's phasor rows.
#[derive(Debug, Clone, Copy)]
pub(crate) struct PhasorFns {
    /// [`phasors`] on checked lengths; whether every input was finite.
    pub polar: unsafe fn(&[f32], &[f32], &mut [f32]) -> bool,
    /// [`phasors_in_place`] on checked lengths.
    pub polar_in_place: unsafe fn(&mut [f32], &[f32]) -> bool,
}

/// The phasor rows' paths, best first: the portable body's `#[target_feature]` copies, then the body
/// itself (SSE2 / NEON).
pub(crate) static PATHS: &[Path<PhasorFns>] = &[
    #[cfg(target_arch = "x86_64")]
    Path {
        isa: Isa::Avx512,
        run: PhasorFns {
            polar: body::x86::polar_avx512,
            polar_in_place: body::x86::polar_in_place_avx512,
        },
    },
    #[cfg(target_arch = "x86_64")]
    Path {
        isa: Isa::Avx2Fma,
        run: PhasorFns {
            polar: body::x86::polar_avx2,
            polar_in_place: body::x86::polar_in_place_avx2,
        },
    },
    Path {
        isa: Isa::Scalar,
        run: PhasorFns {
            polar: body::polar_body,
            polar_in_place: body::polar_in_place_body,
        },
    },
];

/// The maximum error of each component of [`phasor`], in units of `|a|` (module docs: how it was measured).
pub const PHASOR_MAX_ERROR: f32 = 1.0e-7;

/// `out[2i], out[2i + 1] ← a·cos θ, a·sin θ` with `a = amplitude[i]`, `θ = 2π·(phase[i] − 0.5)` ([`phasor`]
/// on every pixel): `amplitude` and `phase` hold `n` values (any `n`, e.g. one `[H, W]` plane), `out` `2n`
/// (the memory of `n` complex f32). Returns whether every input value was finite (a NaN or infinite head
/// gives a NaN or meaningless phasor). Errors: lengths ([`KernelError::Length`]), `isa` not available
/// ([`KernelError::Isa`]).
pub fn phasors(
    amplitude: &[f32],
    phase: &[f32],
    out: &mut [f32],
    isa: Isa,
) -> Result<bool, KernelError> {
    check_len("phasor amplitudes", amplitude.len(), phase.len())?;
    check_len("phasors (2 values per pixel)", out.len(), 2 * phase.len())?;
    let run = dispatch::pick(PATHS, isa)?.polar;
    // SAFETY: `pick` checked that this CPU has `isa`, which includes the level of the path it returned;
    // the lengths are checked above.
    Ok(unsafe { run(amplitude, phase, out) })
}

/// [`phasors`] in place: `buf` (`2n` values) holds the `n` amplitudes in its first half and receives the
/// `n` interleaved phasors (the memory of a complex field whose first half the CNN wrote its amplitude head
/// into); `phase` holds the `n` phase heads. Bit-identical to [`phasors`]. Errors: as [`phasors`].
pub fn phasors_in_place(buf: &mut [f32], phase: &[f32], isa: Isa) -> Result<bool, KernelError> {
    check_len("phasors (2 values per pixel)", buf.len(), 2 * phase.len())?;
    let run = dispatch::pick(PATHS, isa)?.polar_in_place;
    // SAFETY: `pick` checked that this CPU has `isa`, which includes the level of the path it returned;
    // the lengths are checked above.
    Ok(unsafe { run(buf, phase) })
}

#[cfg(test)]
mod tests;

//! The u8 grid ([`QuantU8`]: scale and zero point) and its arithmetic, shared by the buffers
//! ([`crate::buffer`]), the int8 plan ([`crate::Conv3x3U8`]) and the heads ([`crate::heads`]): rounding to
//! nearest even without a libm call, ONNX `QuantizeLinear`'s clamp, and the scale check.

use crate::error::KernelError;

/// Scale and zero point of a u8 tensor: `real = (q − zero_point)·scale`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QuantU8 {
    /// Real units per step (finite, > 0).
    pub scale: f32,
    /// The u8 value of real 0.
    pub zero_point: u8,
}

/// `1.5·2²³`: adding and subtracting it rounds an f32 of magnitude ≤ 2²² to the nearest integer, ties to
/// even (the default rounding mode), with plain additions that every vector ISA has.
pub(crate) const ROUND_MAGIC: f32 = 12_582_912.0;

/// `round_ties_even(x)` for `|x| ≤ 2²²` (exact; NaN stays NaN), branch-free and vectorisable: SSE2, the
/// x86-64 baseline, has no rounding instruction, so `f32::round_ties_even` is a libm call there.
#[inline(always)]
fn round_small(x: f32) -> f32 {
    (x + ROUND_MAGIC) - ROUND_MAGIC
}

/// `clamp(round_ties_even(x) + zp, 0, 255)` in f32 (NaN → 0), as every int8 path computes it. `x` is
/// clamped to ±1024 first, which changes no result (`zp ≤ 255`) and keeps [`round_small`] exact.
#[inline(always)]
pub(crate) fn quantize_f32(x: f32, zp: f32) -> f32 {
    // `clamp` lets a NaN through.
    let x = x.clamp(-1024.0, 1024.0);
    let y = round_small(x) + zp;
    // `max`/`min` in this order match `maxps`/`minps` with the constant second (also for NaN → 0).
    let y = if y > 0.0 { y } else { 0.0 };
    if y < 255.0 {
        y
    } else {
        255.0
    }
}

/// `clamp(round_ties_even(x) + zp, 0, 255)` as a u8, computed in f32 exactly as every int8 kernel does
/// ([`quantize_f32`]); branch-free, so the buffers' fill loops vectorise.
#[inline(always)]
pub(crate) fn quantize(x: f32, zp: u8) -> u8 {
    // The value is a whole number in [0, 255]. Adding 2²³ puts it, exactly, in the low bits of the
    // mantissa, read back as an integer: plain vector additions, where a float-to-int conversion (`as u8`
    // or `as i32`, saturating) is compiled one value at a time.
    (quantize_f32(x, zp as f32) + 8_388_608.0).to_bits() as u8
}

pub(crate) fn check_scale(what: &str, s: f32) -> Result<(), KernelError> {
    if s.is_finite() && s > 0.0 {
        Ok(())
    } else {
        Err(KernelError::Parameter {
            what: format!("{what} = {s} is not finite and positive"),
        })
    }
}

//! Phase wrapping and the linear (identity) look-up table from phase to 8-bit SLM codes.

use std::f32::consts::TAU;

use ndarray::{Array, ArrayView, Dimension};

/// Wraps a phase in radians to `[0, 2π)`. NaN stays NaN (callers validate their inputs). For the usual
/// few-cycle range (double phase values lie within ±3π) it adds or subtracts `2π` at most twice, beyond it
/// takes `rem_euclid`: [`tensorholo_kernels::double_phase::wrap_phase`], which the double phase rows use.
pub fn wrap_phase(phase: f32) -> f32 {
    tensorholo_kernels::double_phase::wrap_phase(phase)
}

/// The identity look-up table of an ideal SLM with a linear response over one `2π` cycle: code `c ∈ 0..=255`
/// displays phase `2π·c/256` (so 256 codes cover `[0, 2π)` without repeating 0 and 2π).
///
/// Calibrated global and per-pixel tables (paper Methods, Eq. 12–13) replace this in the `slm` module.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinearLut;

impl LinearLut {
    /// Phase in radians (any value; wrapped first) → nearest 8-bit code.
    pub fn code(&self, phase: f32) -> u8 {
        let c = (wrap_phase(phase) * (256.0 / TAU)).round() as u32;
        (c % 256) as u8
    }

    /// Phase in radians that code `c` displays: `2π·c/256`.
    pub fn phase(&self, code: u8) -> f32 {
        code as f32 * (TAU / 256.0)
    }
}

/// Converts a phase array (radians, any shape such as `[3, H, W]`) to 8-bit codes through the [`LinearLut`].
/// The worst-case quantisation error is `π/256` rad.
pub fn phase_to_codes<D: Dimension>(phase: ArrayView<f32, D>) -> Array<u8, D> {
    phase.mapv(|p| LinearLut.code(p))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn wrap_is_in_range_and_preserves_the_unit_phasor(p in -1000.0f32..1000.0) {
            let w = wrap_phase(p);
            prop_assert!((0.0..TAU).contains(&w));
            let (a, b) = (num_complex::Complex32::from_polar(1.0, p), num_complex::Complex32::from_polar(1.0, w));
            prop_assert!((a - b).norm() < 2e-4 * (1.0 + p.abs() / 100.0));
        }

        #[test]
        fn lut_quantisation_error_is_at_most_half_a_step(p in 0.0f32..TAU) {
            let back = LinearLut.phase(LinearLut.code(p));
            let err = (back - p).abs().min(TAU - (back - p).abs());
            prop_assert!(err <= TAU / 512.0 + 1e-5, "phase {p} -> {back}");
        }
    }

    #[test]
    fn lut_codes_are_the_identity_on_code_phases() {
        for c in 0..=255u8 {
            assert_eq!(LinearLut.code(LinearLut.phase(c)), c);
        }
        assert_eq!(
            LinearLut.code(TAU - 1e-4),
            0,
            "just below 2π wraps to code 0"
        );
        assert_eq!(LinearLut.code(-TAU / 256.0), 255);
    }
}

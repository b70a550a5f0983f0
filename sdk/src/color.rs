//! sRGB transfer functions (IEC 61966-2-1) between 8-bit display values and linear intensity, and the
//! amplitude convention of `docs/CONVENTIONS.md` §5.5: amplitude = √(linear intensity), per colour.

/// sRGB-encoded value in `[0, 1]` → linear intensity in `[0, 1]` (IEC 61966-2-1 piecewise curve).
/// Values outside `[0, 1]` are clamped first.
pub(crate) fn srgb_to_linear(v: f32) -> f32 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear intensity in `[0, 1]` → sRGB-encoded value in `[0, 1]` (inverse of [`srgb_to_linear`]).
/// Values outside `[0, 1]` (and NaN, mapped to 0) are clamped first.
pub(crate) fn linear_to_srgb(v: f32) -> f32 {
    let v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
    if v <= 0.003_130_8 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// 8-bit sRGB code → field amplitude `√(linear intensity)` in `[0, 1]`.
pub fn srgb8_to_amplitude(code: u8) -> f32 {
    srgb_to_linear(code as f32 / 255.0).sqrt()
}

/// Field amplitude (≥ 0, `1` = white) → 8-bit sRGB code of its intensity `amplitude²`, rounded.
pub fn amplitude_to_srgb8(amplitude: f32) -> u8 {
    (linear_to_srgb(amplitude * amplitude) * 255.0).round() as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trips_every_code() {
        for code in 0..=255u8 {
            assert_eq!(amplitude_to_srgb8(srgb8_to_amplitude(code)), code);
        }
    }

    #[test]
    fn srgb_mid_grey_is_about_a_fifth_of_linear_intensity() {
        // sRGB 0.5 ≈ 0.214 linear (IEC 61966-2-1).
        assert!((srgb_to_linear(0.5) - 0.21404).abs() < 1e-4);
        assert_eq!(srgb8_to_amplitude(255), 1.0);
        assert_eq!(srgb8_to_amplitude(0), 0.0);
    }
}

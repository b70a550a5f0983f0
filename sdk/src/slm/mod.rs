//! The SLM: phase look-up tables (global, per-pixel in compact tiles), the display calibration file, the
//! per-pixel calibration from camera captures (paper Methods, Eq. 12–13), the laser intensity map, the
//! deep-black test of Fig. 11, and a simulated SLM to test them on.
//!
//! - [`lut`]: [`PhaseCurve`] (phase of each code), [`TiledCurves`] (per-pixel curves, bilinear between tiles),
//!   [`PhaseLut`] (phase → code, allocation-free).
//! - [`codes`]: the one map between 8-bit codes and displayed phase ([`displayed_phase`], [`codes_of`]):
//!   a calibration's look-up tables or the linear one.
//! - [`mod@file`]: [`DisplayCalibration`], the versioned `.holocal` file with a checksum.
//! - [`calibrate`]: the 2×2 calibration patterns and [`calibrate::calibrate`] (Eq. 12–13, streamed).
//! - [`captures`]: PNG captures decoded row by row and downsampled to the SLM.
//! - [`intensity`]: the laser intensity scale map (5×5 median, normalised).
//! - [`simulate`]: [`simulate::SimulatedSlm`], a panel with a spatially varying response and its camera.
//! - [`model`]: [`model::DisplayModel`], the display as it is (source, crosstalk, phase response, zero order,
//!   aberration) in a `tensorholo.display-model` file; [`model_captures`], the test patterns, the captures'
//!   manifest and a simulated display's captures; [`model_fit`], the model fitted from captures.
#![cfg_attr(
    feature = "research",
    doc = "- [`spots`] (feature `research`): the display's aberration (Eq. 14–19) fitted from camera captures \
           of focused spots (phase diversity): patterns, forward model, fit, simulated display."
)]
#![cfg_attr(
    not(feature = "research"),
    doc = "- `spots` (feature `research`, off in this build): the aberration calibration from spot captures."
)]

pub mod calibrate;
pub mod captures;
pub mod codes;
pub mod file;
pub mod intensity;
pub mod lut;
pub mod model;
pub mod model_captures;
pub mod model_fit;
pub mod simulate;
#[cfg(feature = "research")]
pub mod spots;

pub use codes::{codes_of, displayed_phase};
pub use file::{ColourCalibration, DisplayCalibration};
pub use lut::{LutRepresentation, PhaseCurve, PhaseLut, TiledCurves};

use ndarray::{Array3, ArrayView3};
use num_complex::Complex32;

use crate::error::{HoloError, Result};
use crate::optics::FourierFilter;

/// The deep-black test pattern of paper Fig. 11 for each colour's LUT: the double phase encoding of a black
/// target, a checkerboard of phases `π/2` (`x + y` even) and `3π/2` (odd), through each colour's look-up
/// table. Returns codes `[3, height, width]`.
///
/// Errors: [`HoloError::ShapeMismatch`] if a per-pixel LUT is for another size.
pub fn black_test_codes(luts: [&PhaseLut; 3], height: usize, width: usize) -> Result<Array3<u8>> {
    let half = std::f32::consts::FRAC_PI_2;
    let phase: Vec<f32> = (0..height * width)
        .map(|i| {
            if (i / width + i % width).is_multiple_of(2) {
                half
            } else {
                3.0 * half
            }
        })
        .collect();
    let mut codes = Array3::<u8>::zeros((3, height, width));
    for (c, lut) in luts.iter().enumerate() {
        let mut plane = codes.index_axis_mut(ndarray::Axis(0), c);
        let out = plane
            .as_slice_mut()
            .ok_or_else(|| HoloError::Internal("codes not contiguous".into()))?;
        lut.apply(height, width, &phase, out)?;
    }
    Ok(codes)
}

/// Mean intensity per colour that a phase-only SLM showing `phase` `[3, H, W]` (radians, as displayed)
/// sends through the Fourier filter (Eq. 8–9), relative to a uniform pattern's (which passes whole: 1). On
/// the [`black_test_codes`] pattern this is the display's black level; its inverse the contrast.
///
/// Errors: [`HoloError::ShapeMismatch`] for a stack that is not `[3, H, W]`.
pub fn filtered_intensity(phase: ArrayView3<f32>) -> Result<[f64; 3]> {
    let (c, h, w) = phase.dim();
    if c != 3 {
        return Err(HoloError::ShapeMismatch {
            what: "displayed phase".into(),
            expected: vec![3, h, w],
            got: phase.shape().to_vec(),
        });
    }
    let filter = FourierFilter::new(h, w)?;
    let mut scratch = filter.plan().scratch();
    let mut out = [0f64; 3];
    for (ch, o) in out.iter_mut().enumerate() {
        let mut field: Vec<Complex32> = phase
            .index_axis(ndarray::Axis(0), ch)
            .iter()
            .map(|&p| Complex32::from_polar(1.0, p))
            .collect();
        filter.apply(&mut field, &mut scratch)?;
        *o = field.iter().map(|v| v.norm_sqr() as f64).sum::<f64>() / (h * w) as f64;
    }
    Ok(out)
}

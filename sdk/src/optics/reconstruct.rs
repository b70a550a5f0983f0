//! Simulated reconstruction: focal stacks of complex holograms and of phase-only SLM patterns.

use ndarray::{Array3, ArrayView3, Axis};
use num_complex::Complex32;
use rayon::prelude::*;

use super::filter::aperture_mask;
use super::{check_colour_stack, check_finite_field, par_channels};
use super::{Carrier, FourierFilter, OpticalSetup, PropagationOptions};
use crate::error::{invalid, HoloError, Result};

/// Amplitude focal stack: for every normalised depth `d` in `depths`, `|ASM(field, z(d) − plane_z_m)|` per
/// colour, where `field` `[3, H, W]` (R, G, B) lies at axial position `plane_z_m` (metres from the midpoint
/// plane: 0 for the midpoint hologram, the offset `s` for an SLM-plane field) and `z(d) = (0.5 − d)·volume`.
///
/// With `aperture`, the Fourier filter of Eq. 8–9 is applied at the field's plane first (what the physical
/// aperture of the display does to an SLM pattern). One forward FFT per colour, one inverse per depth.
///
/// Returns one `[3, H, W]` amplitude array per depth (same order as `depths`).
///
/// Errors: a field that is not `[3, H, W]`, non-finite values, a depth outside `[0, 1]`, an invalid setup.
pub fn focal_stack(
    field: ArrayView3<Complex32>,
    setup: &OpticalSetup,
    plane_z_m: f64,
    depths: &[f64],
    options: PropagationOptions,
    aperture: bool,
) -> Result<Vec<Array3<f32>>> {
    let (h, w) = check_colour_stack("field", &field)?;
    check_finite_field("field", &field)?;
    if let Some(&d) = depths.iter().find(|d| !(0.0..=1.0).contains(*d)) {
        return Err(invalid(
            "depths",
            format!("normalised depths must lie in [0, 1], got {d}"),
        ));
    }
    if !plane_z_m.is_finite() {
        return Err(invalid("plane_z_m", "must be finite"));
    }
    let props = setup.propagators(h, w, options)?;
    let field = field.as_standard_layout();
    // per colour: Vec over depths of [H*W] amplitudes
    let per_colour: Vec<Vec<Vec<f32>>> = (0..3)
        .into_par_iter()
        .map(|c| -> Result<Vec<Vec<f32>>> {
            let prop = &props[c];
            let plan = prop.plan();
            let mut scratch = plan.scratch();
            let mut spectrum = vec![Complex32::default(); plan.spectrum_len()];
            let lane = field.index_axis(Axis(0), c);
            let src = lane
                .as_slice()
                .ok_or_else(|| HoloError::InvalidData("layout".into()))?;
            plan.forward(src, &mut spectrum, &mut scratch)?;
            let mask: Option<Vec<Complex32>> = aperture.then(|| {
                aperture_mask(plan)
                    .into_iter()
                    .map(|v| Complex32::new(v, 0.0))
                    .collect()
            });
            let mut out_field = vec![Complex32::default(); h * w];
            depths
                .iter()
                .map(|&d| {
                    let mut tf =
                        prop.transfer_function(setup.depth_to_z(d) - plane_z_m, Carrier::Remove)?;
                    if let Some(m) = &mask {
                        tf.multiply(m)?;
                    }
                    plan.inverse(&spectrum, tf.values(), &mut out_field, &mut scratch)?;
                    Ok(out_field.iter().map(|v| v.norm()).collect())
                })
                .collect()
        })
        .collect::<Result<_>>()?;
    Ok((0..depths.len())
        .map(|k| {
            let mut a = Array3::<f32>::zeros((3, h, w));
            for (c, colour) in per_colour.iter().enumerate() {
                a.index_axis_mut(Axis(0), c)
                    .as_slice_mut()
                    .expect("fresh array is contiguous")
                    .copy_from_slice(&colour[k]);
            }
            a
        })
        .collect())
}

/// What a phase-only SLM pattern `phase` `[3, H, W]` (radians, R, G, B) shows after the display's Fourier
/// filter (Eq. 8–9), expressed at the midpoint plane: `ASM(F⁻¹{F{e^{iP}}·M}, −s) · e^{+i2πs/λ}` (Eq. 10),
/// with `s = offset_m` the SLM's distance from the midpoint plane (`docs/CONVENTIONS.md` §4).
///
/// For a double-phase pattern this is the post-encoding midpoint hologram, whose amplitude approximates the
/// encoded amplitude divided by its global maximum ([`crate::encoding::DoublePhase`]).
///
/// Errors: wrong shape, non-finite phase, invalid setup or offset.
pub fn simulate_phase_only(
    phase: ArrayView3<f32>,
    setup: &OpticalSetup,
    offset_m: f64,
    options: PropagationOptions,
) -> Result<Array3<Complex32>> {
    let (h, w) = check_colour_stack("phase pattern", &phase)?;
    if phase.iter().any(|p| !p.is_finite()) {
        return Err(HoloError::InvalidData(
            "phase pattern has non-finite values".into(),
        ));
    }
    if !offset_m.is_finite() {
        return Err(invalid("offset_m", "must be finite"));
    }
    let mut field = phase.mapv(|p| Complex32::from_polar(1.0, p));
    let filter = FourierFilter::new(h, w)?;
    let props = setup.propagators(h, w, options)?;
    par_channels(&mut field, |c, slice| {
        let mut scratch = filter.plan().scratch();
        filter.apply(slice, &mut scratch)?;
        if offset_m != 0.0 {
            props[c].propagate_by(slice, -offset_m, Carrier::Remove)?;
        }
        Ok(())
    })?;
    Ok(field)
}

/// The post-encoding midpoint hologram of a double-phase pattern in the units of the encoded hologram:
/// [`simulate_phase_only`] multiplied by the encoding's global amplitude normaliser `amplitude_scale`
/// ([`crate::encoding::DoublePhase::amplitude_scale`]), so that its amplitude compares directly with the
/// scene's or the ground truth's (the "phase-only" column of the Table 2 protocol).
///
/// Errors: as [`simulate_phase_only`]; [`HoloError::InvalidParameter`] for a non-positive scale.
pub fn post_encoding_midpoint(
    phase: ArrayView3<f32>,
    amplitude_scale: f32,
    setup: &OpticalSetup,
    offset_m: f64,
    options: PropagationOptions,
) -> Result<Array3<Complex32>> {
    if !(amplitude_scale > 0.0 && amplitude_scale.is_finite()) {
        return Err(invalid(
            "amplitude_scale",
            format!("must be > 0, got {amplitude_scale}"),
        ));
    }
    Ok(
        simulate_phase_only(phase, setup, offset_m, options)?
            * Complex32::new(amplitude_scale, 0.0),
    )
}

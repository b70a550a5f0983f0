//! Simulated reconstruction: focal stacks of complex holograms and of phase-only SLM patterns.

use ndarray::{Array3, ArrayView3, Axis};
use num_complex::Complex32;
use rayon::prelude::*;

use super::channels::{check_colour_stack, check_finite_field, par_channels};
use super::filter::aperture_mask;
use super::filter::FourierFilter;
use super::propagation::{Carrier, PropagationOptions};
use super::setup::OpticalSetup;
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
    // The stack is allocated once; each colour writes its channel of every depth in place (no per-colour
    // copies to gather: at 1080p with three depths, 75 MB less at the peak of `holo render`'s previews).
    let mut stack: Vec<Array3<f32>> = depths.iter().map(|_| Array3::zeros((3, h, w))).collect();
    let mut lanes: Vec<Vec<&mut [f32]>> = (0..3).map(|_| Vec::new()).collect();
    for a in &mut stack {
        let flat = a
            .as_slice_mut()
            .ok_or_else(|| HoloError::Internal("fresh array is contiguous".into()))?;
        for (lane, c) in lanes.iter_mut().zip(flat.chunks_exact_mut(h * w)) {
            lane.push(c);
        }
    }
    let colour = |(c, outs): (usize, Vec<&mut [f32]>)| -> Result<()> {
        let prop = &props[c];
        let plan = prop.plan();
        let mut scratch = plan.scratch();
        let mut spectrum = vec![Complex32::default(); plan.spectrum_len()];
        let lane = field.index_axis(Axis(0), c);
        let src = lane
            .as_slice()
            .ok_or_else(|| HoloError::InvalidData("layout".into()))?;
        plan.forward(src, &mut spectrum, &mut scratch)?;
        if aperture {
            // The aperture is 0 or 1: applied to the spectrum once, it gives the same values as applied
            // to every depth's transfer function.
            for (s, m) in spectrum.iter_mut().zip(aperture_mask(plan)) {
                *s *= m;
            }
        }
        let mut out_field = vec![Complex32::default(); h * w];
        for (&d, out) in depths.iter().zip(outs) {
            // Its even quarter: a fourth of the f64 phases, the same values bit for bit.
            let tf =
                prop.even_transfer_function(setup.depth_to_z(d) - plane_z_m, Carrier::Remove)?;
            plan.inverse_even(&spectrum, &tf, &mut out_field, &mut scratch)?;
            for (o, v) in out.iter_mut().zip(&out_field) {
                *o = v.norm();
            }
        }
        Ok(())
    };
    // Each colour's working set is six complex planes (spectrum, scratch, output, transfer function): 100 MB at
    // 1080p. Large frames run their colours one after the other, small ones in parallel.
    if h * w <= PARALLEL_COLOURS_MAX_PIXELS {
        lanes.into_par_iter().enumerate().try_for_each(colour)?;
    } else {
        lanes.into_iter().enumerate().try_for_each(colour)?;
    }
    Ok(stack)
}

/// The largest frame (pixels) whose colours [`focal_stack`] reconstructs in parallel: 1 Mpixel, 540×960 and
/// below (at most 3 × 50 MB of working set); larger frames run one colour at a time (`holo render`'s 1080p
/// previews peak 100 MB lower).
const PARALLEL_COLOURS_MAX_PIXELS: usize = 1 << 20;

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

#[cfg(test)]
mod tests {
    use super::*;

    /// The aperture applied once to the spectrum, with the transfer functions' even quarters, gives, bit for
    /// bit, what the per-depth product of the full transfer function and the aperture gave (the former
    /// implementation), on a random field.
    #[test]
    fn focal_stack_with_the_aperture_equals_the_per_depth_product() {
        let (h, w) = (18, 26);
        let field = Array3::from_shape_fn((3, h, w), |(c, y, x)| {
            let t = (c * 131 + y * 31 + x * 7) as f32;
            Complex32::new((t * 0.37).sin(), (t * 0.11).cos())
        });
        let setup = OpticalSetup::default();
        let depths = [0.1, 0.55, 0.9];
        let options = PropagationOptions::default();
        let stack = focal_stack(field.view(), &setup, 6e-3, &depths, options, true).unwrap();
        let props = setup.propagators(h, w, options).unwrap();
        for (c, prop) in props.iter().enumerate() {
            let plan = prop.plan();
            let mut scratch = plan.scratch();
            let mut spectrum = vec![Complex32::default(); plan.spectrum_len()];
            let src: Vec<Complex32> = field.index_axis(Axis(0), c).iter().copied().collect();
            plan.forward(&src, &mut spectrum, &mut scratch).unwrap();
            let mask: Vec<Complex32> = aperture_mask(plan)
                .into_iter()
                .map(|v| Complex32::new(v, 0.0))
                .collect();
            assert!(mask.iter().any(|m| m.re == 0.0) && mask.iter().any(|m| m.re == 1.0));
            for (k, &d) in depths.iter().enumerate() {
                let mut tf = prop
                    .transfer_function(setup.depth_to_z(d) - 6e-3, Carrier::Remove)
                    .unwrap();
                tf.multiply(&mask).unwrap();
                let mut out = vec![Complex32::default(); h * w];
                plan.inverse(&spectrum, tf.values(), &mut out, &mut scratch)
                    .unwrap();
                let want: Vec<f32> = out.iter().map(|v| v.norm()).collect();
                let got: Vec<f32> = stack[k].index_axis(Axis(0), c).iter().copied().collect();
                assert_eq!(got, want, "colour {c}, depth {d}");
            }
        }
    }
}

//! Colour stacks `[3, H, W]`: their checks, one colour per thread ([`par_channels`]), and the allocating
//! [`propagate_colour`].

use ndarray::{Array3, ArrayView3, Axis};
use num_complex::Complex32;
use rayon::prelude::*;

use super::propagation::{Carrier, PropagationOptions};
use super::setup::OpticalSetup;
use crate::error::{invalid, HoloError, Result};

/// Checks a colour stack is `[3, H, W]` with `H, W ≥ 1` and returns `(H, W)`.
pub(crate) fn check_colour_stack<T>(what: &str, a: &ArrayView3<T>) -> Result<(usize, usize)> {
    let (c, h, w) = a.dim();
    if c != 3 || h == 0 || w == 0 {
        return Err(HoloError::ShapeMismatch {
            what: format!("{what} (expected [3, height, width], channels R, G, B)"),
            expected: vec![3, h.max(1), w.max(1)],
            got: vec![c, h, w],
        });
    }
    Ok((h, w))
}

/// Checks every value of a complex field is finite.
pub(crate) fn check_finite_field(what: &str, a: &ArrayView3<Complex32>) -> Result<()> {
    let bad = a.iter().filter(|v| !v.is_finite()).count();
    if bad > 0 {
        return Err(HoloError::InvalidData(format!(
            "{what} has {bad} non-finite (NaN or infinite) values"
        )));
    }
    Ok(())
}

/// Runs `f(channel, slice)` on each channel of a standard-layout `[C, H, W]` array, channels in parallel.
pub(crate) fn par_channels<T: Send + Sync>(
    field: &mut Array3<T>,
    f: impl Fn(usize, &mut [T]) -> Result<()> + Sync + Send,
) -> Result<()> {
    field
        .axis_iter_mut(Axis(0))
        .into_par_iter()
        .enumerate()
        .try_for_each(|(c, mut lane)| {
            let slice = lane
                .as_slice_mut()
                .ok_or_else(|| invalid("field", "must be in standard (row-major) layout"))?;
            f(c, slice)
        })
}

/// Propagates a colour stack `[3, H, W]` (R, G, B) in place by `distance_m` metres with the angular spectrum
/// method (Eq. 2), one colour per thread, each at its own wavelength of `setup`.
///
/// With [`Carrier::Remove`] this is the offset propagation of Eq. 6 (`distance_m = s`, midpoint → SLM) and
/// its inverse of Eq. 10 (`distance_m = −s`, SLM → midpoint), `docs/CONVENTIONS.md` §5.2.
///
/// Allocating convenience: plans and transfer functions are built per call. Hot paths keep [`Propagator`](super::propagation::Propagator)s,
/// [`TransferFunction`](super::propagation::TransferFunction)s and [`Scratch`](super::propagation::Scratch) instead.
///
/// Errors: invalid setup or distance ([`HoloError::InvalidParameter`]), a field that is not `[3, H, W]`
/// ([`HoloError::ShapeMismatch`]), non-finite values ([`HoloError::InvalidData`]).
pub fn propagate_colour(
    field: &mut Array3<Complex32>,
    setup: &OpticalSetup,
    distance_m: f64,
    carrier: Carrier,
    options: PropagationOptions,
) -> Result<()> {
    let (h, w) = check_colour_stack("field", &field.view())?;
    check_finite_field("field", &field.view())?;
    if !field.is_standard_layout() {
        *field = field.as_standard_layout().into_owned();
    }
    let props = setup.propagators(h, w, options)?;
    par_channels(field, |c, slice| {
        props[c].propagate_by(slice, distance_m, carrier)
    })
}

//! [`PlaneMultiplier`]: the spectral multiplier `m = M · H(d) · E` that takes a field at the SLM to the one a
//! viewer sees focused `d` metres away (the Fourier filter's aperture, the angular spectrum method's
//! transfer function and an eye's pupil function), shared by the refinement's loss planes (`refine::model`)
//! and the display model's captures (`slm::model`).

use num_complex::Complex32;
use tensorholo_kernels::Isa;

use super::propagation::{Carrier, EvenMultiplier, Propagator};
use super::zernike::{pupil_multiplier, ZernikeCoefficients};
use crate::error::Result;

/// One loss plane's multiplier `m_d`.
#[derive(Debug)]
pub(crate) enum PlaneMultiplier {
    /// `M · H(z_d − s)`, even in both frequencies: its quarter.
    Even(EvenMultiplier),
    /// `M · H(z_d − s) · E_d` with a viewer's aberration: every value, in the plan's spectrum layout.
    Full(Vec<Complex32>),
}

impl PlaneMultiplier {
    /// Every value `[rows, cols]` of the plan's spectrum layout (the even form expanded): for `W`, and the GPU.
    pub(crate) fn full(&self, rows: usize, cols: usize, isa: Isa) -> Vec<Complex32> {
        let mut full = vec![Complex32::new(1.0, 0.0); rows * cols];
        for (r, row) in full.chunks_exact_mut(cols).enumerate() {
            self.multiply_row(r, row, isa);
        }
        full
    }

    /// `row ← m_d·row` on row `r` of the plan's spectrum layout.
    pub(crate) fn multiply_row(&self, r: usize, row: &mut [Complex32], isa: Isa) {
        match self {
            Self::Even(m) => m.multiply_row(r, row, isa),
            Self::Full(m) => {
                let cols = row.len();
                for (x, m) in row.iter_mut().zip(&m[r * cols..(r + 1) * cols]) {
                    *x *= m;
                }
            }
        }
    }
}

/// The multiplier `m = M · H(distance_m) · E` of `prop`'s grid: the Fourier filter's `aperture` (Eq. 8–9) times
/// the carrier-free transfer function over `distance_m` metres (Eq. 2, Eq. 10), times, where `aberration` is
/// given, the pupil function `E = circ·exp(−i·ΣZ_j)` of those Zernike coefficients (the conjugate of the
/// correction kernel of Eq. 5). The refinement's loss planes and the display model's captures
/// (`slm::model`) are both made here.
///
/// Errors: as [`Propagator::even_transfer_function_masked`].
pub(crate) fn plane_multiplier(
    prop: &Propagator,
    aperture: &impl Fn(i64, i64) -> f32,
    distance_m: f64,
    aberration: Option<&ZernikeCoefficients>,
) -> Result<PlaneMultiplier> {
    let even = prop.even_transfer_function_masked(distance_m, Carrier::Remove, aperture)?;
    let Some(coefficients) = aberration else {
        return Ok(PlaneMultiplier::Even(even));
    };
    // m = M·H·E: the even multiplier's values, times the conjugate of the correction kernel at this distance.
    let plan = prop.plan();
    let (rows, cols) = (plan.computational_shape().1, plan.computational_shape().0);
    let mut full = PlaneMultiplier::Even(even).full(rows, cols, plan.fft().isa());
    let kernel = pupil_multiplier(plan, coefficients);
    for (m, k) in full.iter_mut().zip(&kernel) {
        *m *= k.conj();
    }
    Ok(PlaneMultiplier::Full(full))
}

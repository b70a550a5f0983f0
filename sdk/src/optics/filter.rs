//! The Fourier (aperture) filter of paper Eq. 8–9: a centred circular aperture in the Fourier plane of the SLM
//! that passes the first diffraction order and blocks the high-frequency double-phase term.

use num_complex::Complex32;

use super::propagation::{Scratch, SpectralPlan};
use crate::error::Result;

/// Circular Fourier-plane aperture (Eq. 9): `M(kx, ky) = 1` where `kx² + ky² ≤ r²`, else 0, with `kx, ky` the
/// signed frequency indices of the unpadded `[height, width]` grid (centred spectrum) and
/// `r = min(height, width)/2` (`docs/CONVENTIONS.md` §5.4: the paper's "half of the image resolution").
///
/// On a padded plan the indices are rescaled to the unpadded grid, so the aperture is the same physical
/// filter.
#[derive(Debug, Clone)]
pub struct FourierFilter {
    plan: SpectralPlan,
    mask: Vec<f32>,
    multiplier: Vec<Complex32>,
}

impl FourierFilter {
    /// Builds the aperture for `[height, width]` fields on an unpadded grid.
    ///
    /// Errors: [`crate::HoloError::InvalidParameter`] for a zero size.
    pub fn new(height: usize, width: usize) -> Result<Self> {
        let plan = SpectralPlan::new(height, width, super::propagation::Padding::None)?;
        let mask = aperture_mask(&plan);
        let norm = 1.0 / plan.spectrum_len() as f32;
        let multiplier = mask
            .iter()
            .map(|&m| Complex32::new(m * norm, 0.0))
            .collect();
        Ok(Self {
            plan,
            mask,
            multiplier,
        })
    }

    /// The plan the filter runs on.
    pub fn plan(&self) -> &SpectralPlan {
        &self.plan
    }

    /// Filters `field` (`[height, width]` row-major) in place: `F⁻¹{F{field} · M}` (Eq. 8).
    ///
    /// Errors: [`crate::HoloError::ShapeMismatch`] if `field` has the wrong size.
    pub fn apply(&self, field: &mut [Complex32], scratch: &mut Scratch) -> Result<()> {
        self.plan.apply(field, &self.multiplier, scratch)
    }

    #[cfg(feature = "gpu")]
    /// The spectral multiplier [`FourierFilter::apply`] uses: the aperture with the inverse-FFT normalisation,
    /// in [`SpectralPlan`] layout.
    pub(crate) fn multiplier(&self) -> &[Complex32] {
        &self.multiplier
    }

    /// The 0/1 aperture in [`SpectralPlan`] layout (transposed, FFT order).
    pub fn mask(&self) -> &[f32] {
        &self.mask
    }
}

/// The 0/1 circular aperture of Eq. 9 on any plan's computational grid (see [`FourierFilter`]).
pub(crate) fn aperture_mask(plan: &SpectralPlan) -> Vec<f32> {
    let aperture = aperture_fn(plan);
    plan.build_multiplier(|kx, ky| Complex32::new(aperture(kx, ky), 0.0))
        .into_iter()
        .map(|c| c.re)
        .collect()
}

/// The aperture of [`aperture_mask`] as a function of signed DFT bin indices `(kx, ky)` of `plan`'s
/// computational grid: 1 inside, 0 outside (even in both indices).
pub(crate) fn aperture_fn(plan: &SpectralPlan) -> impl Fn(i64, i64) -> f32 {
    let (ch, cw) = plan.computational_shape();
    let (h, w) = (plan.height() as f64, plan.width() as f64);
    let (sy, sx) = (h / ch as f64, w / cw as f64);
    let r = h.min(w) / 2.0;
    move |kx, ky| {
        let (u, v) = (kx as f64 * sx, ky as f64 * sy);
        if u * u + v * v <= r * r {
            1.0
        } else {
            0.0
        }
    }
}

//! The refinement's image formation model and its analytic gradient (`docs/REFINE.md`).
//!
//! For one colour with SLM phase `φ` `[H, W]` (radians), `u = e^{iφ}`, the field the viewer sees focused at
//! loss plane `d` is `U_d = A_d u = F⁻¹{m_d · F{u}}` with `m_d = M · H(z_d − s)`: the Fourier filter's
//! aperture (Eq. 8–9) times the carrier-free transfer function from the SLM plane at offset `s` to the focal
//! plane `z_d` (Eq. 2, Eq. 10). The loss is `L = Σ_d ‖k·|U_d| − T_d‖²` with the least-squares scale
//! `k = Σ_d⟨|U_d|, T_d⟩ / Σ_d ‖U_d‖²`, i.e. `L = Σ_d ‖T_d‖² − A²/B` with `A = Σ_d⟨|U_d|, T_d⟩`,
//! `B = Σ_d ‖U_d‖²`.
//!
//! Its gradient with respect to `u` (as `∂L/∂Re u + i·∂L/∂Im u`; `k` at its optimum contributes nothing,
//! ∂L/∂k = 0) is `g = Σ_d A_d^H (2k²·U_d − 2k·T_d·U_d/|U_d|)`, and `A_d^H = F⁻¹{conj(m_d) · F{·}}`, so
//! `g = F⁻¹{2k²·W·F{u} − 2k·Σ_d conj(m_d)·F{V_d}}` with `W = N·Σ_d |m_d|²` (real, made once; `N` the
//! grid's size, the FFT's normalisation being folded into `m_d`) and `V_d = T_d·U_d/|U_d|` (0 where
//! `U_d = 0`). Then `∂L/∂φ = Im(g·conj(u))`. Per colour and iteration: one forward FFT of `u`, per plane one
//! inverse (`U_d`) and one forward (`V_d`), and one inverse for `g`: `2D + 2` FFTs.
//!
//! A viewer with an aberration (`AberrationProfile`: a prescription or measured Zernike coefficients) sees
//! through the eye's pupil function `E_d = circ(ρ ≤ 1)·exp(−i·ΣZ_j(ρ, θ))`, the conjugate of the correction
//! kernel `Φ_d` of Eq. 5 (`Φ_d·E_d = circ`: the corrected hologram looks sharp), with the coefficients at each
//! loss plane's own distance `d = z_d − s` from the SLM. The model is then `m_d = M · H(z_d − s) · E_d` and
//! the target stays the unaberrated one: minimising the loss makes a pattern that the viewer sees sharp,
//! corrected at every loss plane (where the real-time path applies one distance's kernel). `E_d` has odd
//! terms (coma, oblique astigmatism), so such `m_d` are kept whole instead of in the even multiplier's quarter.

use num_complex::Complex32;

use crate::display::AberrationProfile;
use crate::error::Result;
use crate::optics::fft::Fft2;
use crate::optics::filter::aperture_fn;
use crate::optics::multiplier::{plane_multiplier, PlaneMultiplier};
use crate::optics::{OpticalSetup, PropagationOptions};

/// One colour's fixed parts of the model: its loss planes' multipliers `m_d` and the weight `W`.
#[derive(Debug)]
pub(super) struct ColourModel {
    /// `m_d` per loss plane.
    pub(super) planes: Vec<PlaneMultiplier>,
    /// `W = N·Σ_d |m_d|²`, the plan's spectrum layout.
    pub(super) weight: Vec<f32>,
}

impl ColourModel {
    /// The model of colour `colour` of `setup` on an unpadded `[height, width]` grid for an SLM `offset_m`
    /// metres from the midpoint plane and loss planes at normalised `depths`, seen through `viewer`'s
    /// aberration where one is given (see the module docs).
    ///
    /// Errors: as [`crate::optics::Propagator::new`] and [`crate::optics::Propagator::even_transfer_function`].
    pub(super) fn new(
        setup: &OpticalSetup,
        options: PropagationOptions,
        colour: usize,
        (height, width): (usize, usize),
        offset_m: f64,
        depths: &[f64],
        viewer: Option<&AberrationProfile>,
    ) -> Result<Self> {
        let prop = setup.propagator(colour, (height, width), options)?;
        let plan = prop.plan();
        let aperture = aperture_fn(plan);
        let n = plan.spectrum_len();
        let (rows, cols) = (plan.computational_shape().1, plan.computational_shape().0);
        let isa = plan.fft().isa();
        let planes = depths
            .iter()
            .map(|&d| {
                let distance_m = setup.depth_to_z(d) - offset_m;
                let eye = viewer.map(|v| v.coefficients(distance_m, colour));
                plane_multiplier(&prop, &aperture, distance_m, eye.as_ref())
            })
            .collect::<Result<Vec<_>>>()?;
        // W from the full multipliers: apply each plane's m_d to a spectrum of ones.
        let mut weight = vec![0.0f32; n];
        for m in &planes {
            for (w, v) in weight.iter_mut().zip(&m.full(rows, cols, isa)) {
                *w += v.norm_sqr() * n as f32;
            }
        }
        Ok(Self { planes, weight })
    }
}

/// `acc ← acc + conj(m)·x` on row `r` of the plan's layout (`acc` and `x` that row's values), reading the even
/// multiplier's quarter: row `r` mirrors row `rows − r`, column `c ≥ cols/2 + 1` column `cols − c`.
pub(super) fn add_conj_product(
    m: &PlaneMultiplier,
    r: usize,
    acc: &mut [Complex32],
    x: &[Complex32],
) {
    let m = match m {
        PlaneMultiplier::Even(m) => m,
        PlaneMultiplier::Full(m) => {
            let cols = acc.len();
            for ((a, v), m) in acc.iter_mut().zip(x).zip(&m[r * cols..(r + 1) * cols]) {
                *a += m.conj() * v;
            }
            return;
        }
    };
    let q = m.quarter_row(r);
    let qc = q.len();
    let (acc_low, acc_high) = acc.split_at_mut(qc);
    let (x_low, x_high) = x.split_at(qc);
    for ((a, v), m) in acc_low.iter_mut().zip(x_low).zip(q) {
        *a += m.conj() * v;
    }
    for ((a, v), m) in acc_high
        .iter_mut()
        .zip(x_high)
        .zip(q[1..=x_high.len()].iter().rev())
    {
        *a += m.conj() * v;
    }
}

/// Pixels a lane of the sums of [`plane_term`] takes: sixteen independent partial sums, so that the loop
/// vectorises (a fixed order all the same: the same bits on every run).
const LANES: usize = 16;

/// One (colour, plane) term of an iteration, in a slot's buffers: from the colour's spectrum `spectrum`
/// (`F{u}`), `field ← U_d`; the sums `(⟨|U_d|, T_d⟩, ‖U_d‖²)`; and, with `adjoint`, `work ← F{V_d}` (the
/// caller adds `conj(m_d)·work` to its colour, [`add_conj_product`]). `work` and `field` are the slot's;
/// `scratch` its FFT scratch.
#[allow(clippy::too_many_arguments)]
pub(super) fn plane_term(
    fft: &Fft2,
    m: &PlaneMultiplier,
    spectrum: &[Complex32],
    target: &[f32],
    work: &mut [Complex32],
    field: &mut [Complex32],
    scratch: &mut [Complex32],
    adjoint: bool,
) -> (f64, f64) {
    let cols = fft.height();
    let isa = fft.isa();
    work.copy_from_slice(spectrum);
    for (r, row) in work.chunks_exact_mut(cols).enumerate() {
        m.multiply_row(r, row, isa);
    }
    fft.inverse(work, field, scratch);
    let (mut a, mut b) = (0.0f64, 0.0f64);
    let mut fields = field.chunks_exact_mut(LANES);
    let mut targets = target.chunks_exact(LANES);
    for (u, t) in (&mut fields).zip(&mut targets) {
        let (mut la, mut lb) = ([0.0f32; LANES], [0.0f32; LANES]);
        for k in 0..LANES {
            let (n2, tk) = (u[k].norm_sqr(), t[k]);
            let n = n2.sqrt();
            la[k] = n * tk;
            lb[k] = n2;
            // V = T·U/|U| (0 where U = 0).
            let s = if n > 0.0 { tk / n } else { 0.0 };
            u[k] = Complex32::new(u[k].re * s, u[k].im * s);
        }
        a += la.iter().map(|&v| f64::from(v)).sum::<f64>();
        b += lb.iter().map(|&v| f64::from(v)).sum::<f64>();
    }
    for (u, &t) in fields.into_remainder().iter_mut().zip(targets.remainder()) {
        let n2 = u.norm_sqr();
        let n = n2.sqrt();
        a += f64::from(n * t);
        b += f64::from(n2);
        let s = if n > 0.0 { t / n } else { 0.0 };
        *u = Complex32::new(u.re * s, u.im * s);
    }
    if adjoint {
        fft.forward(field, work, scratch);
    }
    (a, b)
}

//! What a refinement is asked to do: its options ([`RefineOptions`], checked by
//! [`RefineOptions::validate`]), where it starts ([`RefineStart`], [`initial_phase`]), and what it reports
//! ([`IterationRecord`], [`RefineReport`]).

use ndarray::Array3;

use super::target::loss_depths;
use crate::error::{invalid, Result};
use crate::splitmix::SplitMix64;

/// The most iterations one refinement runs: 10,000 (about an hour at 1080p on two cores; the issue's
/// holograms converge within a few hundred).
pub const MAX_ITERATIONS: usize = 10_000;

/// The largest Adam step a refinement accepts, radians: `π` (a larger step jumps across whole fringes).
pub const MAX_STEP_RAD: f32 = std::f32::consts::PI;

/// What a refinement does: its iteration count, its optimiser's settings and how many focal planes the loss
/// sees. `Default`: 10 iterations, Adam with step 0.02 rad, `β₁ = 0.9`, `β₂ = 0.999`, `ε = 1e-8`, 7 loss
/// planes (chosen by measurement on real frames, `docs/REFINE.md`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct RefineOptions {
    /// Iterations, `1..=`[`MAX_ITERATIONS`].
    pub iterations: usize,
    /// Adam's step size (learning rate), radians of SLM phase; `(0, MAX_STEP_RAD]`.
    pub step_rad: f32,
    /// Adam's decay of the gradient's running mean, `[0, 1)`.
    pub beta1: f32,
    /// Adam's decay of the squared gradient's running mean, `[0, 1)`.
    pub beta2: f32,
    /// Adam's denominator guard, `> 0`.
    pub epsilon: f32,
    /// Loss planes ([`loss_depths`]), [`PLANES_RANGE`](super::target::PLANES_RANGE).
    pub planes: usize,
    /// Evaluate the loss at the phase the SLM shows: `φ` through the look-up table to 8-bit codes and back
    /// to the codes' displayed phases (`Refiner::with_calibration`; the linear table without one), the
    /// gradient passed straight through the rounding (the straight-through estimator). The refined pattern
    /// is then optimised as the display shows it, quantisation and the SLM's response included. `false`
    /// optimises the continuous phase.
    pub quantised: bool,
}

impl Default for RefineOptions {
    fn default() -> Self {
        Self {
            iterations: 10,
            step_rad: 0.02,
            beta1: 0.9,
            beta2: 0.999,
            epsilon: 1e-8,
            planes: 7,
            quantised: true,
        }
    }
}

impl RefineOptions {
    /// Checks every field against its range.
    ///
    /// Errors: [`crate::HoloError::InvalidParameter`] naming the field (`iterations`, `step_rad`, `beta1`, `beta2`,
    /// `epsilon`, `planes`) and its range.
    pub fn validate(&self) -> Result<()> {
        if !(1..=MAX_ITERATIONS).contains(&self.iterations) {
            return Err(invalid(
                "iterations",
                format!(
                    "{} refinement iterations; give 1 to {MAX_ITERATIONS}",
                    self.iterations
                ),
            ));
        }
        if !(self.step_rad.is_finite() && self.step_rad > 0.0 && self.step_rad <= MAX_STEP_RAD) {
            return Err(invalid(
                "step_rad",
                format!(
                    "Adam step {} rad; give a finite step in (0, π] radians (default 0.02)",
                    self.step_rad
                ),
            ));
        }
        for (name, v) in [("beta1", self.beta1), ("beta2", self.beta2)] {
            if !(0.0..1.0).contains(&v) {
                return Err(invalid(name, format!("{v}; Adam's decays lie in [0, 1)")));
            }
        }
        if !(self.epsilon.is_finite() && self.epsilon > 0.0) {
            return Err(invalid(
                "epsilon",
                format!("{}; give a finite value > 0", self.epsilon),
            ));
        }
        loss_depths(self.planes).map(|_| ())
    }
}

/// Where a refinement starts: the phase pattern it is handed, or one it makes ([`initial_phase`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RefineStart {
    /// The CNN's SLM pattern (the default: a warm start).
    Cnn,
    /// The previous frame's refined pattern (video).
    Previous,
    /// SM-LBM (Eq. 1–4) encoded by the double phase method (Eq. 7), without CNN.
    SmLbmDpm,
    /// Zero phase everywhere (the cold start of iterative methods).
    Zero,
    /// Uniform random phase in `[0, 2π)` from a seeded SplitMix64 stream.
    Random {
        /// The stream's seed.
        seed: u64,
    },
}

/// A start pattern `[3, height, width]` (radians) that needs no hologram: zero for [`RefineStart::Zero`],
/// uniform random in `[0, 2π)` for [`RefineStart::Random`] (pixel order, R then G then B).
///
/// Errors: [`crate::HoloError::InvalidParameter`] (`start`) for a start that is a hologram's pattern
/// ([`RefineStart::Cnn`], [`RefineStart::Previous`], [`RefineStart::SmLbmDpm`]: the caller makes those), or
/// a zero size.
pub fn initial_phase(start: RefineStart, height: usize, width: usize) -> Result<Array3<f32>> {
    if height == 0 || width == 0 {
        return Err(invalid("size", format!("{height}×{width}: both ≥ 1")));
    }
    match start {
        RefineStart::Zero => Ok(Array3::zeros((3, height, width))),
        RefineStart::Random { seed } => {
            let mut rng = SplitMix64::new(seed);
            Ok(Array3::from_shape_simple_fn((3, height, width), || {
                (rng.next_f64() * std::f64::consts::TAU) as f32
            }))
        }
        other => Err(invalid(
            "start",
            format!(
                "{other:?} is the pattern of a hologram the caller computes, not one made here"
            ),
        )),
    }
}

/// One point of a refinement's history: the loss and the PSNR against the target at the loss planes,
/// before iteration `iteration` updates the phase (`iteration = iterations`: after the last update).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct IterationRecord {
    /// Iterations done so far.
    pub iteration: usize,
    /// `Σ_colours Σ_d ‖k·|U_d| − T_d‖²` (amplitude², summed over pixels).
    pub loss: f64,
    /// `10·log10(1 / MSE)` dB, the MSE of that loss over every colour, plane and pixel (data range 1, as
    /// the Table 2 protocol's amplitudes), with each colour's least-squares scale.
    pub psnr_db: f64,
}

/// What [`Refiner::refine`](super::engine::Refiner::refine) reports.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RefineReport {
    /// The loss and PSNR at the start and after every iteration (`iterations + 1` records).
    pub history: Vec<IterationRecord>,
    /// Wall-clock seconds of all iterations (the final loss evaluation included).
    pub iterations_s: f64,
}

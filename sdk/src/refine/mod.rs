//! Focal-stack refinement of a phase-only SLM pattern: a few iterations of gradient descent (Adam) on the
//! SLM phase so that what the viewer sees at a stack of focal planes matches a target hologram's focal
//! stack, warm-started from the CNN's pattern (`docs/REFINE.md`).
//!
//! The image formation model is the display's own: the SLM field `e^{iφ}` through the Fourier filter
//! (paper Eq. 8–9) and propagated by the angular spectrum method from the SLM plane to each focal plane
//! (Eq. 2, Eq. 10). The loss, per colour, is `Σ_d ‖k·|U_d| − T_d‖²` with the least-squares scale `k` (as the
//! scores of `docs/REFINE.md`); its gradient is analytic (the derivation in `refine/model.rs` and `docs/REFINE.md`), so no autodiff framework
//! is needed. Targets: the SM-LBM ground truth (Eq. 1–4), the CNN's own midpoint hologram, or a given
//! focal stack ([`FocalTarget`]). Starts: any phase pattern (the CNN's, the previous frame's refined one,
//! SM-LBM + double phase), zero or random ([`initial_phase`]).
//!
//! A [`Refiner`] is made once per frame size, target and display; [`Refiner::refine`] allocates nothing per
//! iteration after its first, runs colours and planes in parallel on its own threads, and gives the same
//! bits for the same inputs whatever the thread count (every sum in a fixed order).

mod frame;
#[cfg(feature = "gpu")]
mod gpu;
pub(crate) mod model;
pub mod target;
#[cfg(test)]
mod tests;

use std::f32::consts::TAU;
use std::ops::ControlFlow;
use std::time::Instant;

use ndarray::{Array3, ArrayView3, ArrayViewMut3};
use num_complex::Complex32;
use rayon::prelude::*;

use crate::display::model::{ColourRuntime, DisplayModel, LINEAR_SLOPE};
use crate::display::AberrationProfile;
use crate::error::{invalid, HoloError, Result};
use crate::optics::{check_colour_stack, OpticalSetup, Padding, PropagationOptions, SpectralPlan};
use crate::slm::{DisplayCalibration, PhaseLut};
use crate::splitmix::SplitMix64;
pub use frame::{
    FrameRefinement, FrameRefiner, HeldOutScores, RefineDisplay, RefineTarget, RefinedFrame,
    DEFAULT_TARGET_LEVELS,
};
#[cfg(feature = "gpu")]
pub use gpu::GpuRefinement;
use model::{plane_term, ColourModel};
pub use target::{held_out_depths, loss_depths, FocalTarget, PLANES_RANGE};

/// The most iterations one refinement runs: 10,000 (about an hour at 1080p on two cores; the issue's
/// holograms converge within a few hundred).
pub const MAX_ITERATIONS: usize = 10_000;

/// The largest Adam step a refinement accepts, radians: `π` (a larger step jumps across whole fringes).
pub const MAX_STEP_RAD: f32 = std::f32::consts::PI;

/// The largest drive a refinement through a display model reaches, radians of the linear table: code 255,
/// `2π·255/256`.
const MAX_DRIVE_RAD: f32 = 255.0 * LINEAR_SLOPE;

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
    /// Loss planes ([`loss_depths`]), [`PLANES_RANGE`].
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
    /// Errors: [`HoloError::InvalidParameter`] naming the field (`iterations`, `step_rad`, `beta1`, `beta2`,
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
/// Errors: [`HoloError::InvalidParameter`] (`start`) for a start that is a hologram's pattern
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

/// What [`Refiner::refine`] reports.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RefineReport {
    /// The loss and PSNR at the start and after every iteration (`iterations + 1` records).
    pub history: Vec<IterationRecord>,
    /// Wall-clock seconds of all iterations (the final loss evaluation included).
    pub iterations_s: f64,
}

/// A refinement planned for one frame size, display, SLM offset and target: the loss planes' multipliers,
/// the FFT plan, the per-colour buffers and the optimiser's state are made here once.
#[derive(Debug)]
pub struct Refiner {
    options: RefineOptions,
    target: FocalTarget,
    plan: SpectralPlan,
    colours: Vec<ColourModel>,
    state: Vec<ColourState>,
    slots: Vec<Slot>,
    pool: rayon::ThreadPool,
    /// Per colour `Σ_d ‖T_d‖²`.
    target_energy: [f64; 3],
    /// The SLM's look-up tables (linear without a calibration).
    luts: [PhaseLut; 3],
    /// What the colour models were made from (a viewer's aberration remakes them).
    model_inputs: (OpticalSetup, PropagationOptions, f64),
    /// The viewer's aberration the model sees through ([`Refiner::with_viewer`]).
    viewer: Option<AberrationProfile>,
    /// Per colour the display model's SLM (`Refiner::with_display_model`); `None`: the ideal SLM.
    display: Vec<Option<ColourRuntime>>,
}

/// Another focal stack's planes (e.g. the held-out ones) with their multipliers, seen as a [`Refiner`]'s model
/// sees them (its display, offset and viewer): scored with that refiner's buffers by
/// `Refiner::score_planes`, so that a score at other planes needs no second set of FFT and field buffers
/// (at 1080p, 0.2 GB less than a second refiner).
#[derive(Debug)]
pub(crate) struct PlaneSet {
    target: FocalTarget,
    colours: Vec<ColourModel>,
    energy: [f64; 3],
}

/// One colour's buffers.
#[derive(Debug)]
struct ColourState {
    /// `F{u}` of this iteration.
    spectrum: Vec<Complex32>,
    /// `Σ_d conj(m_d)·F{V_d}`, then the gradient's spectrum.
    adjoint: Vec<Complex32>,
    /// `u`, then (the FFT overwrites it) the gradient `g` in space.
    field: Vec<Complex32>,
    /// `u = e^{iφ}` of this iteration (`φ` as the SLM shows it where quantised).
    unit: Vec<Complex32>,
    /// The codes and displayed phases of a quantised iteration.
    codes: Vec<u8>,
    shown: Vec<f32>,
    scratch: Vec<Complex32>,
    /// Adam's running means of the gradient and its square.
    mean: Vec<f32>,
    square: Vec<f32>,
    /// `(A, B)` of this iteration.
    sums: (f64, f64),
}

/// One (colour, plane) term's buffers.
#[derive(Debug)]
struct Slot {
    work: Vec<Complex32>,
    field: Vec<Complex32>,
    scratch: Vec<Complex32>,
    sums: (f64, f64),
}

impl Refiner {
    /// Plans a refinement of `[H, W]` patterns (the target's size) for the display `setup` with its SLM
    /// `offset_m` metres from the midpoint plane (`docs/CONVENTIONS.md` §4), the loss at the target's planes,
    /// on `threads` threads (≥ 1).
    ///
    /// Errors: [`HoloError::InvalidParameter`] for bad `options` (naming the field), a padded propagation
    /// (`options.pad`: the refinement runs on the real-time pipeline's unpadded grid), a non-finite offset,
    /// zero threads, an invalid setup; those of building the plans.
    pub fn new(
        setup: &OpticalSetup,
        propagation: PropagationOptions,
        offset_m: f64,
        target: FocalTarget,
        options: RefineOptions,
        threads: usize,
    ) -> Result<Self> {
        options.validate()?;
        setup.validate()?;
        if propagation.pad {
            return Err(invalid(
                "pad",
                "the refinement runs on the unpadded grid of the real-time pipeline (the Fourier filter and \
                 the offset propagation as one multiplier); padded propagation is not supported",
            ));
        }
        if !offset_m.is_finite() {
            return Err(invalid(
                "offset_m",
                format!("must be finite, got {offset_m}"),
            ));
        }
        if threads == 0 {
            return Err(invalid("threads", "need at least one thread"));
        }
        let size = target.size();
        let (h, w) = size;
        let plan = SpectralPlan::new(h, w, Padding::None)?;
        let colours = (0..3)
            .map(|c| ColourModel::new(setup, propagation, c, size, offset_m, target.depths(), None))
            .collect::<Result<Vec<_>>>()?;
        let n = h * w;
        let zero = Complex32::new(0.0, 0.0);
        let scratch_len = plan.fft().scratch_len();
        let state = (0..3)
            .map(|_| ColourState {
                spectrum: vec![zero; n],
                // The gradient's buffers are made by the first `refine` (a refiner that only scores never
                // needs them: 100 MB less per colour at 1080p).
                adjoint: Vec::new(),
                field: vec![zero; n],
                unit: vec![zero; n],
                codes: if options.quantised {
                    vec![0; n]
                } else {
                    Vec::new()
                },
                shown: if options.quantised {
                    vec![0.0; n]
                } else {
                    Vec::new()
                },
                scratch: vec![zero; scratch_len],
                mean: Vec::new(),
                square: Vec::new(),
                sums: (0.0, 0.0),
            })
            .collect();
        // One slot a thread, at most one a (colour, plane) term.
        let slots = (0..threads.min(3 * target.depths().len()))
            .map(|_| Slot {
                work: vec![zero; n],
                field: vec![zero; n],
                scratch: vec![zero; scratch_len],
                sums: (0.0, 0.0),
            })
            .collect();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|i| format!("tensorholo-refine-{i}"))
            .build()
            .map_err(|e| HoloError::Internal(format!("refinement thread pool: {e}")))?;
        let target_energy = energy(&target);
        Ok(Self {
            options,
            target,
            plan,
            colours,
            state,
            slots,
            pool,
            target_energy,
            luts: [PhaseLut::linear(), PhaseLut::linear(), PhaseLut::linear()],
            model_inputs: (*setup, propagation, offset_m),
            viewer: None,
            display: vec![None, None, None],
        })
    }

    /// The colour models of `depths` for this refiner's display, offset and viewer.
    fn colour_models(&self, depths: &[f64]) -> Result<Vec<ColourModel>> {
        let (setup, propagation, offset_m) = self.model_inputs;
        let size = self.target.size();
        (0..3)
            .map(|c| {
                ColourModel::new(
                    &setup,
                    propagation,
                    c,
                    size,
                    offset_m,
                    depths,
                    self.viewer.as_ref(),
                )
            })
            .collect()
    }

    /// The planes of `target` (its own depths, e.g. [`held_out_depths`]) as this refiner's model sees them
    /// (display, offset, viewer), for [`Refiner::score_planes`].
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for a target of another size; those of making the multipliers.
    pub(crate) fn plane_set(&self, target: FocalTarget) -> Result<PlaneSet> {
        if target.size() != self.target.size() {
            let ((h, w), (th, tw)) = (self.target.size(), target.size());
            return Err(HoloError::ShapeMismatch {
                what: "plane set's target vs the refiner's".into(),
                expected: vec![3, h, w],
                got: vec![3, th, tw],
            });
        }
        Ok(PlaneSet {
            colours: self.colour_models(target.depths())?,
            energy: energy(&target),
            target,
        })
    }

    /// The record (loss, PSNR) of `phase` `[3, H, W]` (radians, taken as given: not quantised) against the
    /// planes of `set`, computed with this refiner's buffers; the refiner's own target, planes and optimiser
    /// state are left as they were.
    ///
    /// Errors: as [`Refiner::score`].
    pub(crate) fn score_planes(
        &mut self,
        set: &mut PlaneSet,
        phase: ArrayView3<f32>,
    ) -> Result<IterationRecord> {
        let swap = |r: &mut Self, set: &mut PlaneSet| {
            std::mem::swap(&mut r.target, &mut set.target);
            std::mem::swap(&mut r.colours, &mut set.colours);
            std::mem::swap(&mut r.target_energy, &mut set.energy);
        };
        let quantised = std::mem::replace(&mut self.options.quantised, false);
        swap(self, set);
        let record = self.score(phase);
        swap(self, set);
        self.options.quantised = quantised;
        record
    }

    /// The viewer's aberration (a prescription or measured coefficients, `docs/ABERRATION.md`) that the model
    /// sees through: each loss plane's multiplier gains the eye's pupil function at that plane's distance, the
    /// conjugate of the correction kernel (`refine::model`, docs/REFINE.md "A viewer's aberration"), so that
    /// the refined pattern is the one the viewer sees sharp. The target stays what it was: the unaberrated
    /// focal stack. `None`: an unaberrated viewer (as [`Refiner::new`]).
    ///
    /// Errors: as [`Refiner::new`] (remaking the multipliers).
    pub(crate) fn with_viewer(mut self, viewer: Option<&AberrationProfile>) -> Result<Self> {
        self.viewer = viewer.cloned();
        self.colours = self.colour_models(self.target.depths())?;
        Ok(self)
    }

    /// Refines through the display model `model` (`display::model`, docs/REFINE.md "Through a display
    /// model"): the phase is then the SLM's drive in radians of the linear table (`2π·code/256`), kept in
    /// `[0, 2π·255/256]` by a projected step instead of wrapping, and the loss sees
    /// `u = S·(exp(i·R(K ∗ codes)) + z)` through the model's aberration. `None` or a model without parts: the
    /// ideal display, bit for bit.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for a model of another SLM size; [`HoloError::InvalidParameter`]
    /// (`display_model`) for a model with an aberration on a refiner that already sees through a viewer's;
    /// those of remaking the multipliers.
    pub(crate) fn with_display_model(mut self, model: Option<&DisplayModel>) -> Result<Self> {
        let Some(model) = model.filter(|m| !m.is_ideal()) else {
            return Ok(self);
        };
        let (h, w) = self.target.size();
        model.validate()?;
        model.check_size(h, w)?;
        for (slot, part) in self.display.iter_mut().zip(&model.colours) {
            *slot = Some(ColourRuntime::new(part, h, w));
        }
        if model.colours.iter().any(|c| c.aberration.is_some()) {
            if self.viewer.is_some() {
                return Err(invalid(
                    "display_model",
                    "a display model with an aberration and a viewer's aberration at once: give one",
                ));
            }
            let coefficients =
                std::array::from_fn(|c| model.colours[c].aberration.unwrap_or_default());
            let optics = AberrationProfile::new(vec![crate::display::AberrationSample {
                distance_m: 0.0,
                coefficients,
            }])?;
            self = self.with_viewer(Some(&optics))?;
        }
        Ok(self)
    }

    /// The display calibration whose look-up tables a quantised refinement ([`RefineOptions::quantised`])
    /// sends its phases through (`None`: an ideal SLM, the linear table).
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for a per-pixel calibration of another SLM size than the target's.
    pub(crate) fn with_calibration(
        mut self,
        calibration: Option<&DisplayCalibration>,
    ) -> Result<Self> {
        let (h, w) = self.target.size();
        let linear = PhaseLut::linear();
        for (c, lut) in self.luts.iter_mut().enumerate() {
            let chosen = lut_of(calibration, c, &linear);
            if let Some(size) = chosen.size().filter(|&s| s != (h, w)) {
                return Err(HoloError::ShapeMismatch {
                    what: "display calibration vs the refinement's SLM pattern".into(),
                    expected: vec![size.0, size.1],
                    got: vec![h, w],
                });
            }
            *lut = chosen.clone();
        }
        Ok(self)
    }

    /// Replaces the target by `target` (e.g. the next video frame's), keeping the plans made for the old
    /// one's size and planes.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for a target of another size; [`HoloError::InvalidParameter`]
    /// (`depths`) for other planes. The refiner keeps its target on error.
    pub(crate) fn set_target(&mut self, target: FocalTarget) -> Result<()> {
        if target.size() != self.target.size() {
            let ((h, w), (th, tw)) = (self.target.size(), target.size());
            return Err(HoloError::ShapeMismatch {
                what: "new refinement target vs the refiner's".into(),
                expected: vec![3, h, w],
                got: vec![3, th, tw],
            });
        }
        if target.depths() != self.target.depths() {
            return Err(invalid(
                "depths",
                format!(
                    "the new target's planes {:?} differ from the refiner's {:?}",
                    target.depths(),
                    self.target.depths()
                ),
            ));
        }
        self.target_energy = energy(&target);
        self.target = target;
        Ok(())
    }

    /// The options this refiner runs.
    pub fn options(&self) -> &RefineOptions {
        &self.options
    }

    /// The target it aims at.
    pub fn target(&self) -> &FocalTarget {
        &self.target
    }

    /// Refines `phase` `[3, H, W]` (radians, R, G, B; any values) in place for [`RefineOptions::iterations`]
    /// iterations of Adam, each from a fresh optimiser state; the result is wrapped to `[0, 2π)`.
    /// `progress(record)` is called with the start's record and after every iteration; returning
    /// `ControlFlow::Break(())` stops the refinement, leaving `phase` as it was handed in.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for a pattern of another size than the target's;
    /// [`HoloError::InvalidData`] for a non-finite phase; [`HoloError::Cancelled`] when `progress` stopped
    /// it (naming the iteration).
    pub fn refine(
        &mut self,
        mut phase: ArrayViewMut3<f32>,
        progress: &mut dyn FnMut(&IterationRecord) -> ControlFlow<()>,
    ) -> Result<RefineReport> {
        self.check_phase(phase.view())?;
        let t = Instant::now();
        let mut work = phase.as_standard_layout().into_owned();
        if self.display.iter().any(Option::is_some) {
            // Through a display model the phase is the drive: projected into the codes' range.
            work.mapv_inplace(|p| p.rem_euclid(TAU).min(MAX_DRIVE_RAD));
        }
        let n = self.plan.height() * self.plan.width();
        for s in &mut self.state {
            s.mean.clear();
            s.mean.resize(n, 0.0);
            s.square.clear();
            s.square.resize(n, 0.0);
        }
        let iterations = self.options.iterations;
        let mut history = Vec::with_capacity(iterations + 1);
        for it in 0..=iterations {
            let last = it == iterations;
            let flat = work
                .as_slice_mut()
                .ok_or_else(|| HoloError::Internal("refinement phase not contiguous".into()))?;
            self.evaluate(flat, !last)?;
            let record = self.record(it);
            history.push(record);
            if progress(&record).is_break() {
                return Err(HoloError::Cancelled(format!(
                    "refinement stopped by its caller after {it} of {iterations} iterations; the pattern \
                     is unchanged"
                )));
            }
            if !last {
                self.step(flat, it + 1, n);
            }
        }
        work.mapv_inplace(|p| {
            let w = p.rem_euclid(TAU);
            if w >= TAU {
                0.0
            } else {
                w
            }
        });
        phase.assign(&work);
        Ok(RefineReport {
            history,
            iterations_s: t.elapsed().as_secs_f64(),
        })
    }

    /// The loss record of `phase` `[3, H, W]` against the target without changing it (iteration 0).
    ///
    /// Errors: as [`Refiner::refine`].
    pub(crate) fn score(&mut self, phase: ArrayView3<f32>) -> Result<IterationRecord> {
        self.check_phase(phase)?;
        let mut work = phase.as_standard_layout().into_owned();
        let flat = work
            .as_slice_mut()
            .ok_or_else(|| HoloError::Internal("refinement phase not contiguous".into()))?;
        self.evaluate(flat, false)?;
        Ok(self.record(0))
    }

    /// The loss of `phase` and its gradient `∂L/∂φ` `[3, H, W]` (for tests against finite differences).
    #[cfg(test)]
    pub(crate) fn loss_and_gradient(&mut self, phase: ArrayView3<f32>) -> (f64, Array3<f32>) {
        let mut work = phase.as_standard_layout().into_owned();
        let flat = work.as_slice_mut().unwrap();
        self.evaluate(flat, true).unwrap();
        let loss = self.record(0).loss;
        let mut grad = Array3::zeros((3, self.plan.height(), self.plan.width()));
        for (c, mut g) in grad.outer_iter_mut().enumerate() {
            let s = &self.state[c];
            if let Some(model) = &mut self.display[c] {
                model.backward(&s.field);
                for (o, d) in g.iter_mut().zip(&model.grad) {
                    *o = d / LINEAR_SLOPE;
                }
                continue;
            }
            for ((o, g), u) in g.iter_mut().zip(&s.field).zip(&s.unit) {
                *o = g.im * u.re - g.re * u.im;
            }
        }
        (loss, grad)
    }

    fn check_phase(&self, phase: ArrayView3<f32>) -> Result<()> {
        let (h, w) = check_colour_stack("refinement start pattern", &phase)?;
        if (h, w) != self.target.size() {
            return Err(HoloError::ShapeMismatch {
                what: "refinement start pattern vs its target".into(),
                expected: vec![3, self.plan.height(), self.plan.width()],
                got: vec![3, h, w],
            });
        }
        if let Some(v) = phase.iter().find(|v| !v.is_finite()) {
            return Err(HoloError::InvalidData(format!(
                "the refinement's start pattern holds {v}: phases are finite radians"
            )));
        }
        Ok(())
    }

    /// This iteration's loss sums of `phase` (flat `[3, H, W]`), and with `gradient` each colour's gradient
    /// `g` (in `state[c].field`, space).
    fn evaluate(&mut self, phase: &[f32], gradient: bool) -> Result<()> {
        let quantised = self.options.quantised;
        let Self {
            plan,
            colours,
            state,
            slots,
            pool,
            target,
            luts,
            display,
            ..
        } = self;
        let (h, w) = (plan.height(), plan.width());
        let fft = plan.fft();
        let n = plan.height() * plan.width();
        let planes = target.depths().len();
        pool.install(|| {
            // 1. F{u} per colour.
            state
                .par_iter_mut()
                .zip(display.par_iter_mut())
                .enumerate()
                .try_for_each(|(c, (s, model))| {
                    let own = &phase[c * n..(c + 1) * n];
                    if let Some(model) = model {
                        // The drive in codes (rounded where quantised: the gradient passes straight through).
                        s.shown.resize(n, 0.0);
                        for (d, &p) in s.shown.iter_mut().zip(own) {
                            let v = (p / LINEAR_SLOPE).clamp(0.0, 255.0);
                            *d = if quantised { v.round() } else { v };
                        }
                        model.forward(&s.shown, &mut s.unit);
                    } else if quantised {
                        luts[c].apply(h, w, own, &mut s.codes)?;
                        luts[c].displayed_phases(h, w, &s.codes, &mut s.shown)?;
                        unit_phasors(&s.shown, &mut s.unit);
                    } else {
                        unit_phasors(own, &mut s.unit);
                    }
                    s.field.copy_from_slice(&s.unit);
                    fft.forward(&mut s.field, &mut s.spectrum, &mut s.scratch);
                    s.sums = (0.0, 0.0);
                    if gradient {
                        // Made at the first gradient, kept after (a refiner that only scores never makes it).
                        s.adjoint.resize(n, Complex32::new(0.0, 0.0));
                        s.adjoint.fill(Complex32::new(0.0, 0.0));
                    }
                    Ok::<(), HoloError>(())
                })?;
            // 2. The (colour, plane) terms in waves of one per slot, added to their colour in (colour, plane)
            //    order whatever the wave's size.
            let total = 3 * planes;
            for start in (0..total).step_by(slots.len()) {
                let wave = start..(start + slots.len()).min(total);
                let term = |t: usize| (t / planes, t % planes);
                slots[..wave.len()]
                    .par_iter_mut()
                    .enumerate()
                    .for_each(|(i, slot)| {
                        let (c, d) = term(start + i);
                        slot.sums = plane_term(
                            fft,
                            &colours[c].planes[d],
                            &state[c].spectrum,
                            target.plane(d, c),
                            &mut slot.work,
                            &mut slot.field,
                            &mut slot.scratch,
                            gradient,
                        );
                    });
                for (i, slot) in slots[..wave.len()].iter().enumerate() {
                    let s = &mut state[term(start + i).0];
                    s.sums.0 += slot.sums.0;
                    s.sums.1 += slot.sums.1;
                }
                if gradient {
                    add_terms(state, colours, &slots[..wave.len()], fft.height(), |i| {
                        term(start + i)
                    });
                }
            }
            if !gradient {
                return Ok(());
            }
            // 3. g = F⁻¹{2k²·W·F{u} − 2k·Σ_d conj(m_d)·F{V_d}} per colour.
            state
                .par_iter_mut()
                .zip(colours.par_iter())
                .for_each(|(s, model)| {
                    let k = least_squares_scale(s.sums) as f32;
                    let (kk, k2) = (2.0 * k * k, 2.0 * k);
                    for ((a, &x), &w) in s.adjoint.iter_mut().zip(&s.spectrum).zip(&model.weight) {
                        *a = x * (kk * w) - *a * k2;
                    }
                    fft.inverse(&mut s.adjoint, &mut s.field, &mut s.scratch);
                });
            Ok(())
        })
    }

    /// Adam's update of `phase` (flat `[3, H, W]`) from each colour's gradient, step `t` (1-based).
    fn step(&mut self, phase: &mut [f32], t: usize, n: usize) {
        let o = self.options;
        let (c1, c2) = (1.0 - o.beta1.powi(t as i32), 1.0 - o.beta2.powi(t as i32));
        let (state, display) = (&mut self.state, &mut self.display);
        self.pool.install(|| {
            phase
                .par_chunks_mut(n)
                .zip(state.par_iter_mut())
                .zip(display.par_iter_mut())
                .for_each(|((p, s), model)| {
                    let ColourState {
                        field,
                        unit,
                        mean,
                        square,
                        ..
                    } = s;
                    // Through a display model: ∂L/∂drive back through the model (display::model), per radian
                    // of the drive.
                    let through = model.as_mut().map(|model| {
                        model.backward(field);
                        &model.grad[..]
                    });
                    for (i, ((((p, g), u), m), v)) in p
                        .iter_mut()
                        .zip(field.iter())
                        .zip(unit.iter())
                        .zip(mean)
                        .zip(square)
                        .enumerate()
                    {
                        // ∂L/∂φ = Im(g·conj(u)), u = e^{iφ}.
                        let grad = match through {
                            Some(d) => d[i] / LINEAR_SLOPE,
                            None => g.im * u.re - g.re * u.im,
                        };
                        *m = o.beta1 * *m + (1.0 - o.beta1) * grad;
                        *v = o.beta2 * *v + (1.0 - o.beta2) * grad * grad;
                        *p -= o.step_rad * (*m / c1) / ((*v / c2).sqrt() + o.epsilon);
                        if through.is_some() {
                            // A projected step: the codes stay in 0…255 (wrapping diverged with crosstalk).
                            *p = p.clamp(0.0, MAX_DRIVE_RAD);
                        }
                    }
                });
        });
    }

    /// The record of this iteration's sums.
    fn record(&self, iteration: usize) -> IterationRecord {
        let sums = std::array::from_fn(|c| self.state[c].sums);
        let count = 3 * self.target.depths().len() * self.plan.height() * self.plan.width();
        loss_record(iteration, sums, &self.target_energy, count)
    }
}

/// The record of an iteration from each colour's sums `(A, B)` (`L = Σ_c (E_c − A²/B)`, `E_c` the target's
/// energy) over `count` values.
fn loss_record(
    iteration: usize,
    sums: [(f64, f64); 3],
    energy: &[f64; 3],
    count: usize,
) -> IterationRecord {
    let loss: f64 = sums
        .iter()
        .zip(energy)
        .map(|(&(a, b), &e)| if b > 0.0 { (e - a * a / b).max(0.0) } else { e })
        .sum();
    let mse = loss / count as f64;
    IterationRecord {
        iteration,
        loss,
        psnr_db: if mse > 0.0 {
            -10.0 * mse.log10()
        } else {
            f64::INFINITY
        },
    }
}

/// Adds a wave's slot terms (`term_of(i)`: slot `i`'s colour and plane) to their colours' adjoint spectra,
/// `Σ conj(m_d)·F{V_d}`, each colour's terms in slot order (rows of the spectrum, `cols` values each, in
/// parallel: the same sum, in the same order, for every element).
fn add_terms(
    state: &mut [ColourState],
    colours: &[ColourModel],
    slots: &[Slot],
    cols: usize,
    term_of: impl Fn(usize) -> (usize, usize) + Sync,
) {
    for (c, s) in state.iter_mut().enumerate() {
        if !(0..slots.len()).any(|i| term_of(i).0 == c) {
            continue;
        }
        s.adjoint
            .par_chunks_mut(cols)
            .enumerate()
            .for_each(|(r, out)| {
                for (i, slot) in slots.iter().enumerate() {
                    let (cc, d) = term_of(i);
                    if cc == c {
                        model::add_conj_product(
                            &colours[c].planes[d],
                            r,
                            out,
                            &slot.work[r * cols..(r + 1) * cols],
                        );
                    }
                }
            });
    }
}

/// `unit ← e^{iφ}` for the phases `phase` (radians), through the kernels' branch-free sine and cosine of an
/// angle in turns ([`tensorholo_kernels::phasor::sincos_turns`], within 1e-7 of the exact values).
fn unit_phasors(phase: &[f32], unit: &mut [Complex32]) {
    const TURNS: f32 = 1.0 / TAU;
    for (u, &p) in unit.iter_mut().zip(phase) {
        let (sin, cos) = tensorholo_kernels::phasor::sincos_turns(p * TURNS);
        *u = Complex32::new(cos, sin);
    }
}

/// Per colour `Σ_d ‖T_d‖²` of `target`.
fn energy(target: &FocalTarget) -> [f64; 3] {
    let mut out = [0.0f64; 3];
    for (c, e) in out.iter_mut().enumerate() {
        *e = (0..target.depths().len())
            .flat_map(|k| target.plane(k, c))
            .map(|&t| f64::from(t) * f64::from(t))
            .sum();
    }
    out
}

/// `k = A/B` (0 for a field that shows nothing).
fn least_squares_scale((a, b): (f64, f64)) -> f64 {
    if b > 0.0 {
        a / b
    } else {
        0.0
    }
}

/// The phase in radians each 8-bit code of `codes` `[3, H, W]` displays on the SLM: through `calibration`'s
/// look-up tables where one is given (`crate::slm::PhaseLut::displayed_phases`), the linear table's
/// `2π·code/256` otherwise. What a refinement warm-started from an SLM frame starts from: the pattern the
/// display shows, quantisation included.
///
/// Errors: [`HoloError::ShapeMismatch`] for codes that are not `[3, H, W]` or a calibration of another SLM
/// size.
pub fn displayed_phase(
    codes: ArrayView3<u8>,
    calibration: Option<&DisplayCalibration>,
) -> Result<Array3<f32>> {
    per_colour(codes, "SLM codes", calibration, |lut, h, w, k, o| {
        lut.displayed_phases(h, w, k, o)
    })
}

/// The 8-bit codes `[3, H, W]` of a phase pattern `phase` (radians, any values: wrapped first), through
/// `calibration`'s look-up tables where one is given ([`crate::slm::PhaseLut::apply`]), the linear table
/// otherwise: what the SLM is sent after a refinement.
///
/// Errors: [`HoloError::ShapeMismatch`] as [`displayed_phase`]; [`HoloError::InvalidData`] for a non-finite
/// phase.
pub fn codes_of(
    phase: ArrayView3<f32>,
    calibration: Option<&DisplayCalibration>,
) -> Result<Array3<u8>> {
    if phase.iter().any(|v| !v.is_finite()) {
        return Err(HoloError::InvalidData(
            "the SLM phase pattern holds NaN or infinite values".into(),
        ));
    }
    per_colour(
        phase,
        "SLM phase pattern",
        calibration,
        |lut, h, w, p, o| lut.apply(h, w, p, o),
    )
}

/// `f(lut, H, W, input plane, output plane)` for each colour of a `[3, H, W]` input (`what` in a shape
/// error) with that colour's look-up table ([`lut_of`]), into a new `[3, H, W]` array.
fn per_colour<A: Copy, B: Copy + Default>(
    input: ArrayView3<A>,
    what: &str,
    calibration: Option<&DisplayCalibration>,
    f: impl Fn(&PhaseLut, usize, usize, &[A], &mut [B]) -> Result<()>,
) -> Result<Array3<B>> {
    let (h, w) = check_colour_stack(what, &input)?;
    let input = input.as_standard_layout();
    let mut out = Array3::<B>::from_elem((3, h, w), B::default());
    let linear = PhaseLut::linear();
    let n = h * w;
    let all = out
        .as_slice_mut()
        .ok_or_else(|| HoloError::Internal("fresh array not contiguous".into()))?;
    for (c, o) in all.chunks_exact_mut(n).enumerate() {
        f(
            lut_of(calibration, c, &linear),
            h,
            w,
            plane(input.as_slice(), c, n)?,
            o,
        )?;
    }
    Ok(out)
}

/// The PSNR in dB of what the SLM pattern `phase` `[3, H, W]` (radians) shows against `target`'s focal
/// stack, each colour at its least-squares scale (the refinement's loss as a score,
/// [`IterationRecord::psnr_db`]), for the display `setup` with its SLM `offset_m` metres from the midpoint
/// plane. Scoring a refinement at [`held_out_depths`] measures it where its loss never looked.
///
/// Errors: as [`Refiner::new`] and `Refiner::score`.
pub fn focal_psnr(
    phase: ArrayView3<f32>,
    setup: &OpticalSetup,
    propagation: PropagationOptions,
    offset_m: f64,
    target: FocalTarget,
) -> Result<f64> {
    let options = RefineOptions {
        iterations: 1,
        planes: target.depths().len().clamp(PLANES_RANGE.0, PLANES_RANGE.1),
        quantised: false,
        ..Default::default()
    };
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    Refiner::new(setup, propagation, offset_m, target, options, threads)?
        .score(phase)
        .map(|r| r.psnr_db)
}

/// Colour `c`'s look-up table: the calibration's, or `linear`.
fn lut_of<'a>(
    calibration: Option<&'a DisplayCalibration>,
    c: usize,
    linear: &'a PhaseLut,
) -> &'a PhaseLut {
    calibration
        .and_then(|cal| cal.colours.get(c))
        .map_or(linear, |col| &col.lut)
}

/// Plane `c` (`n` values) of a contiguous `[3, H, W]` array.
fn plane<T>(all: Option<&[T]>, c: usize, n: usize) -> Result<&[T]> {
    all.map(|a| &a[c * n..(c + 1) * n])
        .ok_or_else(|| HoloError::Internal("standard-layout array not contiguous".into()))
}

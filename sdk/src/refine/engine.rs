//! The engine of a refinement, in two parts as a planner and its plan: [`Refiner::new`] plans one frame
//! size, display, SLM offset and target (the loss planes' multipliers, the FFT plan, the per-colour buffers
//! and the optimiser's state, made once), and the process runs it (the loss, its analytic gradient, Adam's
//! step; [`Refiner::refine`] through [`super::iterations::drive`], which the GPU's iterations share).

use std::f32::consts::TAU;
use std::ops::ControlFlow;

#[cfg(test)]
use ndarray::Array3;
use ndarray::{ArrayView3, ArrayViewMut3};
use num_complex::Complex32;
use rayon::prelude::*;

use super::iterations::{check_start, drive, loss_record, Iterations};
use super::model::{add_conj_product, plane_term, ColourModel};
use super::options::{IterationRecord, RefineOptions, RefineReport};
use super::target::FocalTarget;
use crate::display::AberrationProfile;
use crate::error::{invalid, HoloError, Result};
use crate::optics::{OpticalSetup, Padding, PropagationOptions, SpectralPlan};
use crate::slm::codes::colour_lut;
use crate::slm::model::{ColourRuntime, DisplayModel, LINEAR_SLOPE};
use crate::slm::{DisplayCalibration, PhaseLut};

/// The largest drive a refinement through a display model reaches, radians of the linear table: code 255,
/// `2π·255/256`.
const MAX_DRIVE_RAD: f32 = 255.0 * LINEAR_SLOPE;

/// Through a display model the phase is the drive: `phase` projected into the codes' range,
/// `[0, 2π·255/256]` (wrapped first), before the iterations start (the CPU's and the GPU's alike).
pub(super) fn project_drive(phase: &mut [f32]) {
    for p in phase.iter_mut() {
        *p = p.rem_euclid(TAU).min(MAX_DRIVE_RAD);
    }
}

/// A refinement planned for one frame size, display, SLM offset and target: the loss planes' multipliers,
/// the FFT plan, the per-colour buffers and the optimiser's state are made here once.
#[derive(Debug)]
pub struct Refiner {
    pub(super) options: RefineOptions,
    pub(super) target: FocalTarget,
    pub(super) plan: SpectralPlan,
    pub(super) colours: Vec<ColourModel>,
    state: Vec<ColourState>,
    slots: Vec<Slot>,
    pool: rayon::ThreadPool,
    /// Per colour `Σ_d ‖T_d‖²`.
    pub(super) target_energy: [f64; 3],
    /// The SLM's look-up tables (linear without a calibration).
    pub(super) luts: [PhaseLut; 3],
    /// What the colour models were made from (a viewer's aberration remakes them).
    model_inputs: (OpticalSetup, PropagationOptions, f64),
    /// The viewer's aberration the model sees through ([`Refiner::with_viewer`]).
    viewer: Option<AberrationProfile>,
    /// Per colour the display model's SLM (`Refiner::with_display_model`); `None`: the ideal SLM.
    pub(super) display: Vec<Option<ColourRuntime>>,
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

    /// Checks that `target` has this refiner's size (`what` names the two in the error).
    ///
    /// Errors: [`HoloError::ShapeMismatch`].
    fn check_size(&self, target: &FocalTarget, what: &str) -> Result<()> {
        let ((h, w), (th, tw)) = (self.target.size(), target.size());
        if (th, tw) == (h, w) {
            return Ok(());
        }
        Err(HoloError::ShapeMismatch {
            what: what.into(),
            expected: vec![3, h, w],
            got: vec![3, th, tw],
        })
    }

    /// The planes of `target` (its own depths, e.g. [`held_out_depths`]) as this refiner's model sees them
    /// (display, offset, viewer), for [`Refiner::score_planes`].
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for a target of another size; those of making the multipliers.
    pub(crate) fn plane_set(&self, target: FocalTarget) -> Result<PlaneSet> {
        self.check_size(&target, "plane set's target vs the refiner's")?;
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

    /// Refines through the display model `model` (`slm::model`, docs/REFINE.md "Through a display
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
        model.validate_for(self.viewer.is_some())?;
        model.check_size(h, w)?;
        for (slot, part) in self.display.iter_mut().zip(&model.colours) {
            *slot = Some(ColourRuntime::new(part, h, w));
        }
        if model.colours.iter().any(|c| c.aberration.is_some()) {
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
        for (c, lut) in self.luts.iter_mut().enumerate() {
            let chosen = colour_lut(calibration, c);
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
        self.check_size(&target, "new refinement target vs the refiner's")?;
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
        phase: ArrayViewMut3<f32>,
        progress: &mut dyn FnMut(&IterationRecord) -> ControlFlow<()>,
    ) -> Result<RefineReport> {
        drive(self, phase, progress)
    }

    /// The loss record of `phase` `[3, H, W]` against the target without changing it (iteration 0).
    ///
    /// Errors: as [`Refiner::refine`].
    pub(crate) fn score(&mut self, phase: ArrayView3<f32>) -> Result<IterationRecord> {
        check_start(self.target.size(), phase)?;
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
                    let k = least_squares_scale(s.sums).unwrap_or(0.0) as f32;
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
                    // Through a display model: ∂L/∂drive back through the model (slm::model), per radian
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
        let (energy, count, _) = self.records();
        loss_record(
            iteration,
            std::array::from_fn(|c| self.state[c].sums),
            &energy,
            count,
        )
    }
}

impl Iterations for Refiner {
    fn size(&self) -> (usize, usize) {
        self.target.size()
    }

    fn records(&self) -> ([f64; 3], usize, usize) {
        let (h, w) = self.target.size();
        let count = 3 * self.target.depths().len() * h * w;
        (self.target_energy, count, self.options.iterations)
    }

    fn run(
        &mut self,
        phase: &mut [f32],
        sums: &mut dyn FnMut(usize, [(f64, f64); 3]) -> ControlFlow<()>,
    ) -> Result<()> {
        if self.display.iter().any(Option::is_some) {
            project_drive(phase);
        }
        let n = self.plan.height() * self.plan.width();
        for s in &mut self.state {
            s.mean.clear();
            s.mean.resize(n, 0.0);
            s.square.clear();
            s.square.resize(n, 0.0);
        }
        let iterations = self.options.iterations;
        for it in 0..=iterations {
            let last = it == iterations;
            self.evaluate(phase, !last)?;
            if sums(it, std::array::from_fn(|c| self.state[c].sums)).is_break() {
                return Ok(());
            }
            if !last {
                self.step(phase, it + 1, n);
            }
        }
        Ok(())
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
                        add_conj_product(
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

/// The least-squares scale `k = A/B` of a shown amplitude `s` against a target `t` from the sums
/// `A = Σ s·t`, `B = Σ s²` (`‖k·s − t‖²` is smallest there): the one scale of the refinement's loss, its
/// records and its frame's `amplitude_scale`. `None` for a field that shows nothing (`B = 0`).
pub(super) fn least_squares_scale((a, b): (f64, f64)) -> Option<f64> {
    (b > 0.0).then(|| a / b)
}

/// The PSNR (dB) of `phase` `[3, H, W]` (radians of the drive) at the held-out planes of a refinement with
/// `planes` loss planes ([`super::held_out_depths`]), as the display of `model` shows it, against the focal
/// stack of `midpoint` `[3, H, W]`: the tests' score of a pattern on a simulated display (what
/// `FrameRefiner::with_scoring_model` reports).
#[cfg(test)]
pub(crate) fn held_out_psnr(
    (setup, propagation, offset_m): (&OpticalSetup, PropagationOptions, f64),
    midpoint: ndarray::ArrayView3<Complex32>,
    planes: usize,
    model: &DisplayModel,
    phase: ArrayView3<f32>,
) -> f64 {
    let held = super::held_out_depths(planes).unwrap();
    let target = FocalTarget::from_midpoint(midpoint, setup, propagation, &held).unwrap();
    let options = RefineOptions {
        planes,
        ..RefineOptions::default()
    };
    let mut r = Refiner::new(setup, propagation, offset_m, target.clone(), options, 2)
        .unwrap()
        .with_display_model(Some(model))
        .unwrap();
    let mut set = r.plane_set(target).unwrap();
    r.score_planes(&mut set, phase).unwrap().psnr_db
}

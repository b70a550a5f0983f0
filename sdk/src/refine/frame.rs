//! One frame's refinement as apps and the CLI ask for it (the photo mode): what the frame is refined against
//! ([`RefineTarget`]), where it starts ([`RefineStart`]), and the scores at the held-out planes
//! ([`FrameRefiner`]).

use std::ops::ControlFlow;
use std::sync::Arc;
use std::time::Instant;

use ndarray::{Array3, ArrayView3};
use num_complex::Complex32;

use super::device::{DeviceIterations, Prepared, RefineDevice};
use super::engine::{least_squares_scale, Refiner};
use super::iterations::drive;
use super::options::{initial_phase, IterationRecord, RefineOptions, RefineReport, RefineStart};
use super::target::{held_out_depths, loss_depths, FocalTarget};
use crate::display::AberrationProfile;
use crate::encoding::DoublePhaseMethod;
use crate::error::{invalid, HoloError, Result};
use crate::optics::{simulate_phase_only, OpticalSetup, PropagationOptions};
use crate::reference::ReferencePipeline;
use crate::slm::codes::{codes_of, displayed_phase};
use crate::slm::model::DisplayModel;
use crate::slm::DisplayCalibration;
use crate::synthesis::{SceneLayer, SmLbm};

/// The SM-LBM planes of the default target: 512 (docs/REFINE.md: the target's cost against its levels).
pub const DEFAULT_TARGET_LEVELS: usize = 512;

/// The most SM-LBM planes a refinement's target may have: the synthesis's own bound (2²⁰).
pub(crate) const MAX_TARGET_LEVELS: usize = 1 << 20;

/// What a frame is refined against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RefineTarget {
    /// The SM-LBM ground truth of the frame's points (paper Eq. 1–4) with `levels` depth planes (the
    /// default, with [`DEFAULT_TARGET_LEVELS`]).
    SmLbm {
        /// Depth planes, ≥ 1.
        levels: usize,
    },
    /// The CNN's own midpoint hologram: no synthesis, recovers the encoding's loss and little more.
    CnnMidpoint,
}

impl Default for RefineTarget {
    fn default() -> Self {
        Self::SmLbm {
            levels: DEFAULT_TARGET_LEVELS,
        }
    }
}

/// One frame's refinement: the optimiser's options, the target, the start. `Default`: 10 iterations of
/// [`RefineOptions::default`] against SM-LBM of 512 planes from the CNN's codes.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct FrameRefinement {
    /// Iterations, step, planes.
    pub options: RefineOptions,
    /// What the frame is refined against.
    pub target: RefineTarget,
    /// Where it starts.
    pub start: RefineStart,
}

impl Default for FrameRefinement {
    fn default() -> Self {
        Self {
            options: RefineOptions::default(),
            target: RefineTarget::default(),
            start: RefineStart::Cnn,
        }
    }
}

impl FrameRefinement {
    /// Checks the options and the target.
    ///
    /// Errors: as [`RefineOptions::validate`]; [`HoloError::InvalidParameter`] (`levels`) for SM-LBM planes
    /// outside 1..=2²⁰ (the synthesis's bound).
    pub fn validate(&self) -> Result<()> {
        self.options.validate()?;
        if let RefineTarget::SmLbm { levels } = self.target {
            if !(1..=MAX_TARGET_LEVELS).contains(&levels) {
                return Err(invalid(
                    "levels",
                    format!(
                        "{levels} SM-LBM planes for the refinement's target; give 1 to {MAX_TARGET_LEVELS} (the \
                         synthesis's bound; default {DEFAULT_TARGET_LEVELS})"
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// The PSNR (dB) at the planes halfway between the loss planes ([`held_out_depths`]), which the loss never
/// saw, against the target's focal stack, each colour at its least-squares scale.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct HeldOutScores {
    /// The held-out planes' normalised depths.
    pub depths: Vec<f64>,
    /// The CNN's codes, as the display shows them (where the frame had them).
    pub cnn_codes_psnr_db: Option<f64>,
    /// The start.
    pub start_psnr_db: f64,
    /// The refined continuous phase.
    pub refined_psnr_db: f64,
    /// The refined pattern's 8-bit codes, as the display shows them: what the SLM is sent.
    pub refined_codes_psnr_db: f64,
}

/// A refined frame.
#[derive(Debug, Clone)]
pub struct RefinedFrame {
    /// The refined phase `[3, H, W]`, radians in `[0, 2π)`.
    pub phase: Array3<f32>,
    /// Its 8-bit codes `[3, H, W]` through the display's look-up tables.
    pub codes: Array3<u8>,
    /// The least-squares scale of what the codes show at the midpoint plane against the target midpoint's
    /// amplitude, over every colour (the frame's `amplitude_scale`: previews and the Table 2 scores compare
    /// `scale·|displayed|` with the target).
    pub amplitude_scale: f32,
    /// The loss and PSNR per iteration, and the iterations' seconds.
    pub report: RefineReport,
    /// The scores at the held-out planes.
    pub held_out: HeldOutScores,
    /// Seconds to make the target (and an SM-LBM start).
    pub target_s: f64,
    /// The start the iterations ran from: the request's, except that [`RefineStart::Previous`] starts from
    /// the CNN's pattern ([`RefineStart::Cnn`]) at the first frame and wherever the CNN's pattern has the
    /// lower loss against this frame's target (a moving camera: the previous frame's pattern shows the last
    /// view).
    pub start: RefineStart,
    /// Where the iterations ran: `cpu`, or the GPU adapter's name (`FrameRefiner::for_pipeline` on a session's GPU,
    /// cargo feature `gpu`).
    pub backend: String,
    /// Why the CPU ran them where a GPU was given (a calibrated look-up table), else `None`.
    pub backend_reason: Option<String>,
}

/// The display a frame is refined for.
#[derive(Debug, Clone)]
pub struct RefineDisplay {
    /// Wavelengths, pixel pitch, volume.
    pub optics: OpticalSetup,
    /// The angular spectrum options (unpadded).
    pub propagation: PropagationOptions,
    /// The SLM's distance from the midpoint plane, metres.
    pub offset_m: f64,
    /// The double phase method of an SM-LBM start ([`RefineStart::SmLbmDpm`]).
    pub encoding: DoublePhaseMethod,
    /// The SLM's look-up tables (`None`: linear) and laser intensity maps, which scale the SM-LBM target (and
    /// start) as they scale the CNN's input: the refinement keeps what the map gains.
    pub calibration: Option<Arc<DisplayCalibration>>,
    /// The viewer's aberration (`None`: none), which the refinement's model sees through
    /// (`Refiner::with_viewer`): the refined pattern stays corrected, at every loss plane's own distance.
    /// The target is the unaberrated one, so [`RefineTarget::CnnMidpoint`] is refused where the CNN corrects
    /// the aberration itself (`viewer_corrected_by_cnn`: its midpoint hologram is the corrected one).
    pub viewer: Option<Arc<AberrationProfile>>,
    /// Whether the hologram CNN was trained for `viewer`'s aberration (the session's
    /// `AberrationReport::by_cnn`).
    pub viewer_corrected_by_cnn: bool,
}

/// The amplitudes `[3, H, W]` of `layers` each multiplied per colour by `calibration`'s laser intensity map
/// (`slm::intensity`; a colour without one unscaled), as the pipeline scales the CNN's input; `None` without
/// a calibration or maps.
///
/// Errors: [`HoloError::ShapeMismatch`] for a map of another size than the layers'.
fn intensity_scaled(
    layers: &[SceneLayer],
    calibration: Option<&DisplayCalibration>,
) -> Result<Option<Vec<Array3<f32>>>> {
    let Some(cal) = calibration.filter(|c| c.has_intensity()) else {
        return Ok(None);
    };
    layers
        .iter()
        .map(|l| {
            let mut a = l.amplitude.to_owned();
            for (mut plane, colour) in a.outer_iter_mut().zip(&cal.colours) {
                if let Some(map) = &colour.intensity_scale {
                    if map.dim() != plane.dim() {
                        return Err(HoloError::ShapeMismatch {
                            what: "laser intensity map vs the refined frame".into(),
                            expected: vec![map.dim().0, map.dim().1],
                            got: vec![plane.dim().0, plane.dim().1],
                        });
                    }
                    plane *= map;
                }
            }
            Ok(a)
        })
        .collect::<Result<Vec<_>>>()
        .map(Some)
}

/// Refines a session's frames one after another: one [`Refiner`] for the frame size (made at the first
/// frame, its target replaced for each next one) and, for [`RefineStart::Previous`], the last refined
/// pattern.
#[derive(Debug)]
pub struct FrameRefiner {
    request: FrameRefinement,
    display: RefineDisplay,
    threads: usize,
    refiner: Option<Refiner>,
    previous: Option<Array3<f32>>,
    /// The display model the loss sees ([`FrameRefiner::with_display_model`]).
    model: Option<Arc<DisplayModel>>,
    /// The display model the held-out planes are scored through ([`FrameRefiner::with_scoring_model`]), and
    /// its refiner (made at the first frame).
    scoring: Option<Arc<DisplayModel>>,
    scorer: Option<Refiner>,
    /// The device the iterations run on (`None`: the CPU), chosen once (`FrameRefiner::for_pipeline`), and
    /// the refinement prepared on it at the first frame (later frames replace its target only).
    device: Option<Box<dyn RefineDevice>>,
    on_device: Option<Box<dyn DeviceIterations>>,
}

impl FrameRefiner {
    /// A refiner of frames on `display` with `threads` threads.
    ///
    /// Errors: as [`FrameRefinement::validate`]; [`HoloError::InvalidParameter`] for zero threads, a padded
    /// propagation (`pad`), or the CNN target for a viewer whose aberration the CNN corrects itself (`target`).
    pub fn new(request: FrameRefinement, display: RefineDisplay, threads: usize) -> Result<Self> {
        request.validate()?;
        if threads == 0 {
            return Err(invalid("threads", "need at least one thread"));
        }
        if display.propagation.pad {
            return Err(invalid(
                "pad",
                "the refinement runs on the unpadded grid of the real-time pipeline",
            ));
        }
        if request.target == RefineTarget::CnnMidpoint
            && display.viewer.is_some()
            && display.viewer_corrected_by_cnn
        {
            return Err(invalid(
                "target",
                "the CNN's midpoint hologram cannot be the target of a viewer whose aberration the CNN \
                 corrects itself (it is the corrected hologram, not the scene): refine against SM-LBM",
            ));
        }
        Ok(Self {
            request,
            display,
            threads,
            refiner: None,
            previous: None,
            model: None,
            scoring: None,
            scorer: None,
            device: None,
            on_device: None,
        })
    }

    /// Refines through the fitted display `model` (`slm::model`, docs/REFINE.md "Through a display
    /// model"): the codes are optimised as that display shows them (source, crosstalk, phase response, zero
    /// order, aberration), kept in 0…255 by a projected step, and the held-out scores are what it shows. The
    /// model's response replaces a calibration's look-up table. On the GPU backend the iterations run there
    /// through the model (`refine.wgsl`'s `model_` kernels). `None`, or a model without parts: the ideal
    /// display, bit for bit.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`display_model`) for a model with a phase response beside a
    /// calibration with a calibrated look-up table, or a model with an aberration beside a viewer's; a model
    /// that does not validate ([`HoloError::InvalidData`] naming the entry). A model of another SLM size than
    /// the frame's is refused at the first frame ([`HoloError::ShapeMismatch`]).
    pub fn with_display_model(mut self, model: Option<Arc<DisplayModel>>) -> Result<Self> {
        if let Some(m) = &model {
            m.validate_for(self.display.viewer.is_some())?;
            let calibrated = self
                .display
                .calibration
                .as_deref()
                .is_some_and(DisplayCalibration::has_calibrated_lut);
            if calibrated {
                return Err(invalid(
                    "display_model",
                    "a display model and a calibration's look-up table at once: the model's phase response \
                     replaces the table (fit the model from the captures instead)",
                ));
            }
        }
        self.model = model;
        self.refiner = None;
        self.on_device = None;
        Ok(self)
    }

    /// Scores the held-out planes ([`RefinedFrame::held_out`]) as the display of `model` shows the patterns,
    /// instead of the display the loss sees: a simulated display's hidden parameters (`holo calibrate model
    /// simulate`'s `hidden.json`), to measure what refining through a fitted model gains on that display
    /// (docs/REFINE.md "Through a display model"). A second refiner scores them (made at the first frame).
    /// `None`: the display the loss sees.
    ///
    /// Errors: [`HoloError::InvalidData`] for a model that does not validate (naming the entry);
    /// [`HoloError::InvalidParameter`] (`display_model`) for a model with an aberration beside a viewer's. A
    /// model of another SLM size than the frame's is refused at the first frame ([`HoloError::ShapeMismatch`]).
    pub fn with_scoring_model(mut self, model: Option<Arc<DisplayModel>>) -> Result<Self> {
        if let Some(m) = &model {
            m.validate_for(self.display.viewer.is_some())?;
        }
        self.scoring = model;
        self.scorer = None;
        Ok(self)
    }

    /// Runs the iterations on `device` (`None`: the CPU): the same model, loss and Adam, prepared there at
    /// the first frame (each later frame hands it its target only); the held-out scores stay on the CPU. A
    /// device may decline a refinement (the GPU a quantised one through a calibrated look-up table): it then
    /// runs on the CPU and [`RefinedFrame::backend_reason`] says why.
    pub(crate) fn on_device(mut self, device: Option<Box<dyn RefineDevice>>) -> Self {
        self.device = device;
        self.on_device = None;
        self
    }

    /// The request it runs.
    pub fn request(&self) -> &FrameRefinement {
        &self.request
    }

    /// Refines one frame: `layers` its scene points (the SM-LBM target and start), `cnn_midpoint` the CNN's
    /// midpoint hologram `[3, H, W]` (the [`RefineTarget::CnnMidpoint`] target), `cnn_codes` its SLM codes
    /// `[3, H, W]` (the [`RefineStart::Cnn`] start, scored too). `progress` as [`Refiner::refine`].
    ///
    /// Errors: [`HoloError::InvalidData`] for a frame under 11 × 11 pixels (the SSIM window: `holo render`
    /// refuses such frames, and the held-out scores of so few pixels are not numbers);
    /// [`HoloError::InvalidParameter`] (`target`) for the CNN target without `cnn_midpoint`; those of
    /// [`SmLbm::synthesize`], [`Refiner::new`] and [`Refiner::refine`] (a cancelled run:
    /// [`HoloError::Cancelled`]).
    pub fn refine(
        &mut self,
        layers: &[SceneLayer],
        cnn_midpoint: Option<ArrayView3<Complex32>>,
        cnn_codes: ArrayView3<u8>,
        progress: &mut dyn FnMut(&IterationRecord) -> ControlFlow<()>,
    ) -> Result<RefinedFrame> {
        let (_, h, w) = cnn_codes.dim();
        let min = crate::metrics::SSIM_WINDOW;
        if h < min || w < min {
            return Err(HoloError::InvalidData(format!(
                "the frame is {h}×{w} pixels: the refinement needs at least {min}×{min} (the SSIM window of the \
                 quality scores; render larger)"
            )));
        }
        let t = Instant::now();
        let d = &self.display;
        let needs_smlbm = matches!(self.request.target, RefineTarget::SmLbm { .. })
            || self.request.start == RefineStart::SmLbmDpm;
        let levels = match self.request.target {
            RefineTarget::SmLbm { levels } => levels,
            RefineTarget::CnnMidpoint => DEFAULT_TARGET_LEVELS,
        };
        let reference = if needs_smlbm {
            let pipeline = ReferencePipeline {
                synthesis: SmLbm {
                    levels,
                    setup: d.optics,
                    options: d.propagation,
                    silhouette_masks: true,
                },
                offset_m: d.offset_m,
                encoding: d.encoding,
            };
            // A calibration's laser intensity maps scale the target as they scale the CNN's: the refinement
            // aims at what the unevenly lit display can show, and keeps what the map gains.
            let scaled = intensity_scaled(layers, d.calibration.as_deref())?;
            let layers: Vec<SceneLayer> = layers
                .iter()
                .enumerate()
                .map(|(k, l)| SceneLayer {
                    amplitude: scaled
                        .as_ref()
                        .map_or_else(|| l.amplitude.view(), |a| a[k].view()),
                    depth: l.depth.view(),
                    valid: l.valid.as_ref().map(|v| v.view()),
                })
                .collect();
            Some(pipeline.run(&layers, &|_, _| {})?)
        } else {
            None
        };
        // Only the midpoint (the target) and the double phase pattern (a start) of the reference are kept.
        let (smlbm_midpoint, smlbm_phase) = match reference {
            Some(r) => (Some(r.midpoint), Some(r.double_phase.phase)),
            None => (None, None),
        };
        let midpoint = match (self.request.target, smlbm_midpoint, cnn_midpoint) {
            (RefineTarget::SmLbm { .. }, Some(m), _) => m,
            (RefineTarget::CnnMidpoint, _, Some(m)) => m.to_owned(),
            _ => {
                return Err(invalid(
                    "target",
                    "the CNN's midpoint hologram is the target, and none was given",
                ))
            }
        };
        let target_s = t.elapsed().as_secs_f64();
        let calibration = d.calibration.as_deref();
        let cnn_phase = displayed_phase(cnn_codes, calibration)?;
        let (_, h, w) = cnn_phase.dim();
        let start = match (self.request.start, smlbm_phase, self.previous.take()) {
            (RefineStart::Cnn, _, _) | (RefineStart::Previous, _, None) => None,
            (RefineStart::Previous, _, Some(previous)) => Some(previous),
            (RefineStart::SmLbmDpm, Some(p), _) => Some(p),
            (RefineStart::SmLbmDpm, None, _) => {
                return Err(HoloError::Internal("the SM-LBM start was not made".into()))
            }
            (other, _, _) => Some(initial_phase(other, h, w)?),
        };
        let starts = match &start {
            // The previous frame's pattern, or the CNN's where it scores better.
            Some(p) if self.request.start == RefineStart::Previous => {
                Starts::BetterOf(p.view(), cnn_phase.view())
            }
            Some(p) => Starts::One(p.view(), self.request.start),
            None => Starts::One(cnn_phase.view(), RefineStart::Cnn),
        };
        let mut refined =
            self.refine_from(midpoint.view(), starts, Some(cnn_phase.view()), progress)?;
        refined.target_s = target_s;
        if self.request.start == RefineStart::Previous {
            self.previous = Some(refined.phase.clone());
        }
        Ok(refined)
    }

    /// Refines `start` `[3, H, W]` (radians) against the focal stack of the target midpoint hologram
    /// `midpoint` `[3, H, W]` (what [`FrameRefiner::refine`] does after making both; `holo reference
    /// --refine` hands its own SM-LBM), scoring the start, the result and `cnn` (the CNN's pattern, where
    /// given) at the held-out planes. `target_s` is 0.
    ///
    /// Errors: as [`Refiner::new`], `Refiner::set_target` and [`Refiner::refine`].
    pub fn refine_against(
        &mut self,
        midpoint: ArrayView3<Complex32>,
        start: ArrayView3<f32>,
        cnn: Option<ArrayView3<f32>>,
        progress: &mut dyn FnMut(&IterationRecord) -> ControlFlow<()>,
    ) -> Result<RefinedFrame> {
        let kind = self.request.start;
        self.refine_from(midpoint, Starts::One(start, kind), cnn, progress)
    }

    /// [`FrameRefiner::refine_against`] from `starts`.
    fn refine_from(
        &mut self,
        midpoint: ArrayView3<Complex32>,
        starts: Starts<'_>,
        cnn: Option<ArrayView3<f32>>,
        progress: &mut dyn FnMut(&IterationRecord) -> ControlFlow<()>,
    ) -> Result<RefinedFrame> {
        let d = &self.display;
        let options = self.request.options;
        let calibration = d.calibration.as_deref();
        let loss_planes = loss_depths(options.planes)?;
        let target = FocalTarget::from_midpoint(midpoint, &d.optics, d.propagation, &loss_planes)?;
        let refiner = match &mut self.refiner {
            Some(r) => {
                r.set_target(target)?;
                r
            }
            slot @ None => slot.insert(
                Refiner::new(
                    &d.optics,
                    d.propagation,
                    d.offset_m,
                    target,
                    options,
                    self.threads,
                )?
                .with_calibration(calibration)?
                .with_viewer(d.viewer.as_deref())?
                .with_display_model(self.model.as_deref())?,
            ),
        };
        let (start, start_kind) = match starts {
            Starts::One(p, kind) => (p, kind),
            Starts::BetterOf(previous, cnn_start) => {
                // Two loss evaluations on the CPU (half an iteration each).
                if refiner.score(cnn_start)?.loss < refiner.score(previous)?.loss {
                    (cnn_start, RefineStart::Cnn)
                } else {
                    (previous, RefineStart::Previous)
                }
            }
        };
        let mut phase = start.to_owned();
        let mut backend_reason = None;
        let prepared = match (&self.device, &mut self.on_device) {
            (Some(_), Some(g)) => {
                g.set_target(refiner)?;
                Some(g)
            }
            (Some(device), slot @ None) => match device.prepare(refiner)? {
                Prepared::Ready(g) => Some(slot.insert(g)),
                Prepared::Declined(reason) => {
                    backend_reason = Some(reason);
                    None
                }
            },
            (None, _) => None,
        };
        let (report, backend) = match (prepared, &self.device) {
            (Some(g), Some(device)) => (
                drive(g.as_mut(), phase.view_mut(), progress)?,
                device.name(),
            ),
            _ => (
                refiner.refine(phase.view_mut(), progress)?,
                "cpu".to_string(),
            ),
        };
        let codes = codes_of(phase.view(), calibration)?;
        let shown = displayed_phase(codes.view(), calibration)?;
        let held = held_out_depths(options.planes)?;
        let held_target = FocalTarget::from_midpoint(midpoint, &d.optics, d.propagation, &held)?;
        // Scored with the refiner's own buffers (only the held-out planes' target and multipliers are made,
        // and dropped after), or with the scoring model's refiner.
        let scorer = match (&self.scoring, &mut self.scorer) {
            (None, _) => refiner,
            (Some(_), Some(s)) => s,
            (Some(model), slot @ None) => slot.insert(
                Refiner::new(
                    &d.optics,
                    d.propagation,
                    d.offset_m,
                    held_target.clone(),
                    options,
                    self.threads,
                )?
                .with_calibration(calibration)?
                .with_viewer(d.viewer.as_deref())?
                .with_display_model(Some(model))?,
            ),
        };
        let mut set = scorer.plane_set(held_target)?;
        let mut score = |p: ArrayView3<f32>| scorer.score_planes(&mut set, p).map(|r| r.psnr_db);
        let held_out = HeldOutScores {
            cnn_codes_psnr_db: cnn.map(&mut score).transpose()?,
            start_psnr_db: score(start)?,
            refined_psnr_db: score(phase.view())?,
            refined_codes_psnr_db: score(shown.view())?,
            depths: held,
        };
        drop(set);
        let amplitude_scale = amplitude_scale(shown.view(), midpoint, d)?;
        Ok(RefinedFrame {
            phase,
            codes,
            amplitude_scale,
            report,
            held_out,
            target_s: 0.0,
            start: start_kind,
            backend,
            backend_reason,
        })
    }
}

/// Where [`FrameRefiner::refine_from`] starts: one pattern (and what it is), or the better of the previous
/// frame's and the CNN's by their loss against the frame's target.
enum Starts<'a> {
    One(ArrayView3<'a, f32>, RefineStart),
    BetterOf(ArrayView3<'a, f32>, ArrayView3<'a, f32>),
}

/// The least-squares scale of what `shown` (radians) shows at the midpoint plane against `midpoint`'s
/// amplitude, over every colour (1 for a pattern that shows nothing). Without the viewer's aberration: a
/// scale for previews, which show the pattern without an eye.
fn amplitude_scale(
    shown: ArrayView3<f32>,
    midpoint: ArrayView3<Complex32>,
    d: &RefineDisplay,
) -> Result<f32> {
    let field = simulate_phase_only(shown, &d.optics, d.offset_m, d.propagation)?;
    let (mut a, mut b) = (0.0f64, 0.0f64);
    for (s, t) in field.iter().zip(midpoint.iter()) {
        let (s, t) = (f64::from(s.norm()), f64::from(t.norm()));
        a += s * t;
        b += s * s;
    }
    Ok(least_squares_scale((a, b)).map_or(1.0, |k| k as f32))
}

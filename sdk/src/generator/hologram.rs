//! [`HologramGenerator`]: the shipped CNNs and one session behind a lock, and [`GeneratorInfo`], what it
//! runs.

use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;

use std::ops::ControlFlow;

use crate::cnn::{PlanReport, ThreadCount};
use crate::display::{AberrationProfile, Prescription};
use crate::encoding::{DoublePhaseMethod, PhaseContinuity};
use crate::error::{invalid, HoloError, Result};
use crate::foveation::Gaze;
use crate::model::{HologramModel, ModelKind, Precision};
use crate::optics::{focal_stack, post_encoding_midpoint};
use crate::pipeline::{
    AberrationReport, BackendReport, HologramPipeline, HologramSession, PrefilterMode,
    PrefilterSource, SlmFrame,
};
use crate::refine::{FrameRefinement, FrameRefiner, IterationRecord, RefineTarget};
use crate::scene::{ldi_from_camera_frames, CameraFrame, CameraFrameReport, RgbdFrame};
use crate::slm::codes::displayed_phase;
use crate::slm::DisplayCalibration;
use crate::synthesis::SceneLayer;

use super::config::GeneratorConfig;
use super::frames::{preview_image, GeneratorBenchmark, PatternTimings, Preview, SlmPatterns};
#[cfg(doc)]
use super::stream::DEFAULT_STREAM_CAPACITY;
use super::stream::{HologramStream, StreamListener};

/// What a [`HologramGenerator`] runs, for apps to show and for bug reports.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct GeneratorInfo {
    /// `tensorholo` version.
    pub version: String,
    /// Hologram width in pixels.
    pub width: usize,
    /// Hologram height in pixels.
    pub height: usize,
    /// Hologram CNN depth.
    pub layers: usize,
    /// Weight format.
    pub precision: Precision,
    /// Source of the hologram CNN (embedded file name).
    pub hologram_model: String,
    /// Source of the pre-filter CNN, if one runs.
    pub prefilter_model: Option<String>,
    /// Why a pre-filter runs or not.
    pub prefilter_reason: String,
    /// Encoding after the CNN (`Plain` after a pre-filter, DDPM).
    pub encoding: DoublePhaseMethod,
    /// SLM offset in metres.
    pub offset_m: f64,
    /// The chosen CNN plan (layout, threads, autotuning timings).
    pub plan: PlanReport,
    /// Which backend runs the frames and why (after the first frame: the self-check's result).
    pub backend: BackendReport,
    /// The display calibration applied, in words ([`DisplayCalibration::summary`]), or `None`.
    pub calibration: Option<String>,
    /// How the hologram CNN's training display maps onto this display, in one line
    /// ([`HologramPipeline::display_mapping_description`], [`crate::display::DisplayMapping::description`]),
    /// e.g. "… serves 4 µm with a 1.5 mm volume (σ = 0.250000); offset 1.5 mm ↔ 6 mm trained; …".
    pub display_mapping: String,
    /// The viewer's aberration correction: the applied distance and coefficients, and the residual left
    /// over the volume ([`AberrationReport`]); `None` without one.
    pub aberration: Option<AberrationReport>,
}

/// RGB-D camera frames → SLM patterns with the shipped CNNs (see the [module docs](super)).
#[derive(Debug)]
pub struct HologramGenerator {
    config: GeneratorConfig,
    pipeline: HologramPipeline,
    session: Mutex<HologramSession>,
    /// The display calibration of new sessions and streams ([`HologramGenerator::set_calibration`]).
    calibration: Mutex<Option<Arc<DisplayCalibration>>>,
    /// The viewer's aberration correction of new sessions and streams
    /// ([`HologramGenerator::set_aberration`]).
    aberration: Mutex<Option<Arc<AberrationProfile>>>,
}

impl HologramGenerator {
    /// Loads the shipped CNNs of `config.models`, checks them against the display, and prepares the session
    /// for `config.height × config.width` (autotuning the CNN plan: see [`PlanReport`]).
    ///
    /// Errors: [`HoloError::InvalidParameter`] for an invalid configuration ([`GeneratorConfig::validate`]),
    /// a layer count other than 8/15/30, [`crate::pipeline::PrefilterMode::Required`] at an offset without a shipped
    /// pre-filter; model errors as [`HologramPipeline::embedded`].
    #[cfg(feature = "embedded-models")]
    pub fn new(config: GeneratorConfig) -> Result<Self> {
        config.validate()?;
        let pipeline = HologramPipeline::embedded(&config.models, config.pipeline_config())?;
        Self::with_pipeline(config, pipeline)
    }

    /// As [`HologramGenerator::new`] with the caller's ONNX files instead of the embedded ones: its own
    /// trained weights, or the shipped files downloaded by an app built without them (a smaller binary).
    /// `hologram` is an RGB-D hologram CNN and `prefilter` an optional DDPM pre-filter CNN for
    /// `config.offset_m`, both checked against the display like the shipped ones (metadata and I/O contract,
    /// `docs/CONVENTIONS.md` §7). `config.models` is replaced by what the files are (layers, precision); a
    /// pre-filter runs if and only if one is given.
    ///
    /// Errors: as [`GeneratorConfig::validate`]; [`HoloError::ModelLoad`] / [`HoloError::ModelMetadata`] /
    /// [`HoloError::ModelContract`] for a file that is not such a model or belongs to another display or
    /// offset (as [`HologramModel::from_bytes`]); as [`HologramPipeline::new`].
    pub fn from_onnx(
        mut config: GeneratorConfig,
        hologram: &[u8],
        prefilter: Option<&[u8]>,
    ) -> Result<Self> {
        config.validate()?;
        let pipeline_config = config.pipeline_config();
        let expected = pipeline_config.model_config(1);
        let load =
            |bytes, name, kind| HologramModel::from_named_bytes(bytes, name, kind, &expected);
        let hologram = load(
            hologram,
            "hologram CNN (caller's ONNX)",
            ModelKind::Hologram,
        )?;
        let prefilter = prefilter
            .map(|b| load(b, "pre-filter CNN (caller's ONNX)", ModelKind::PreFilter))
            .transpose()?;
        let md = hologram.metadata();
        config.models.layers = md.layers;
        config.models.precision = Precision::from_metadata(&md.precision).unwrap_or(Precision::F32);
        config.models.prefilter = if prefilter.is_some() {
            PrefilterMode::Required
        } else {
            PrefilterMode::Off
        };
        let source = match prefilter {
            Some(p) => PrefilterSource::Given(Arc::new(p)),
            None => PrefilterSource::Shipped(PrefilterMode::Off),
        };
        let pipeline = HologramPipeline::with_prefilter(
            Arc::new(hologram),
            source,
            config.models.precision,
            pipeline_config,
        )?;
        Self::with_pipeline(config, pipeline)
    }

    /// As [`HologramGenerator::new`] with CNNs the caller loaded (`config.models` is then only reported).
    ///
    /// Errors: as [`GeneratorConfig::validate`] and [`HologramPipeline::session`].
    pub(crate) fn with_pipeline(
        config: GeneratorConfig,
        pipeline: HologramPipeline,
    ) -> Result<Self> {
        config.validate()?;
        let mut pipeline = match &config.saved_plans {
            Some(plans) => pipeline.with_saved_plans(plans.clone())?,
            None => pipeline,
        };
        if let Some(profile) = config.aberration_profile()? {
            pipeline = pipeline.with_aberration(profile)?;
        }
        let calibration = pipeline.calibration().cloned();
        let aberration = pipeline.aberration().cloned();
        let session = open_session(&pipeline, &config, calibration.clone(), aberration.clone())?;
        Ok(Self {
            config,
            pipeline,
            session: Mutex::new(session),
            calibration: Mutex::new(calibration),
            aberration: Mutex::new(aberration),
        })
    }

    /// Replaces the viewer's aberration correction of the frames rendered from now on and of streams started
    /// later (`None`: none), without a new session ([`HologramSession::set_aberration`]): e.g. a slider of
    /// measured coefficients. Make the generator with a prescription or an aberration profile in its
    /// configuration (a zero one will do) so that it encodes with AA-DPM, which holds for corrected fields.
    ///
    /// Errors: as [`HologramSession::set_aberration`] (a profile for another display). The generator keeps
    /// its correction on error.
    pub fn set_aberration(&self, profile: Option<Arc<AberrationProfile>>) -> Result<()> {
        let mut current = lock_slot(&self.aberration);
        self.session()?.set_aberration(profile.clone())?;
        *current = profile;
        Ok(())
    }

    /// [`HologramGenerator::set_aberration`] with a spectacle prescription (`None`: none), converted on this
    /// generator's display ([`AberrationProfile::from_prescription`]): a prescription slider.
    ///
    /// Errors: as [`Prescription::validate`] and [`HologramGenerator::set_aberration`].
    pub fn set_prescription(&self, prescription: Option<Prescription>) -> Result<()> {
        let profile = prescription
            .map(|p| AberrationProfile::from_prescription(&p, &self.config.optics))
            .transpose()?;
        self.set_aberration(profile.map(Arc::new))
    }

    /// The viewer's aberration correction applied, if any, and what it applies and leaves.
    pub(crate) fn aberration(&self) -> Option<(Arc<AberrationProfile>, AberrationReport)> {
        let session = self.session().ok()?;
        session.aberration().map(|(p, r)| (p.clone(), r.clone()))
    }

    /// Applies a display's calibration (`None`: an ideal SLM) to the frames rendered from now on and to
    /// streams started later (a running stream keeps the one it started with): its per-colour look-up tables
    /// turn the double phase pattern into codes, and its laser intensity map scales the CNN's target
    /// (`docs/CALIBRATION.md`; [`HologramPipeline::with_calibration`]). Previews then show what the
    /// calibrated panel displays.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] if the calibration is for another SLM size than
    /// `config.height × config.width`; [`HoloError::InvalidParameter`] if its wavelengths differ from
    /// `config.optics` by more than 1 nm. The generator keeps its calibration on error.
    pub fn set_calibration(&self, calibration: Option<Arc<DisplayCalibration>>) -> Result<()> {
        let mut current = lock_slot(&self.calibration);
        self.session()?.set_calibration(calibration.clone())?;
        *current = calibration;
        Ok(())
    }

    /// The display calibration applied, if any.
    pub(crate) fn calibration(&self) -> Option<Arc<DisplayCalibration>> {
        lock_slot(&self.calibration).clone()
    }

    /// Renders the built-in test scene ([`crate::scene::procedural::default_scene`]) `frames` times after one
    /// warm-up frame, at this generator's resolution, and returns the median stage timings: what an app shows
    /// as its device's speed.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`frames`) for 0 frames; as `HologramGenerator::render_rgbd`.
    pub fn benchmark(&self, frames: usize) -> Result<GeneratorBenchmark> {
        if frames == 0 {
            return Err(invalid("frames", "a benchmark needs at least 1 frame"));
        }
        let c = self.config();
        let scene = crate::scene::procedural::default_scene(c.height, c.width)?;
        self.render_rgbd(&scene)?;
        let mut all = Vec::with_capacity(frames);
        for _ in 0..frames {
            all.push(self.render_rgbd(&scene)?.timings);
        }
        let median = PatternTimings::median(&all);
        let per_frame = median.convert_s + median.frame.total_s;
        Ok(GeneratorBenchmark {
            frames,
            median,
            fps: if per_frame > 0.0 {
                1.0 / per_frame
            } else {
                0.0
            },
        })
    }

    /// The configuration.
    pub(crate) fn config(&self) -> &GeneratorConfig {
        &self.config
    }

    /// The session, recreated if a panic poisoned its lock (so a bug in one call cannot lose the generator).
    fn session(&self) -> Result<MutexGuard<'_, HologramSession>> {
        match self.session.lock() {
            Ok(g) => Ok(g),
            Err(poisoned) => {
                let mut g = poisoned.into_inner();
                let aberration = lock_slot(&self.aberration).clone();
                *g = open_session(&self.pipeline, &self.config, self.calibration(), aberration)?;
                self.session.clear_poison();
                log::warn!("a call panicked while rendering; the session was recreated");
                Ok(g)
            }
        }
    }

    /// Converts a camera frame to the RGB-D frame the CNN sees at the hologram resolution
    /// ([`CameraFrame::to_rgbd`] with the configuration's fit and depth range).
    ///
    /// Errors: as [`CameraFrame::to_rgbd`].
    pub fn convert(&self, frame: &CameraFrame<&[u8]>) -> Result<(RgbdFrame, CameraFrameReport)> {
        frame.to_rgbd(
            self.config.height,
            self.config.width,
            &self.config.frame_options(),
        )
    }

    /// Renders one camera frame into SLM patterns.
    ///
    /// Errors: the conversion's ([`CameraFrame::to_rgbd`]: bad buffer sizes or strides, no valid depth…)
    /// and the session's ([`HologramSession::render`]: among them [`HoloError::InvalidData`] for a black frame,
    /// e.g. a covered lens, whose hologram would be the CNN's bias shown at full brightness). The generator
    /// stays usable after any error.
    pub fn render(&self, frame: &CameraFrame<&[u8]>) -> Result<SlmPatterns> {
        self.render_with(frame, |session, rgbd| session.render(rgbd))
    }

    /// Converts `frame`, then renders it with `render` on the generator's session.
    fn render_with(
        &self,
        frame: &CameraFrame<&[u8]>,
        render: impl for<'s> FnOnce(&'s mut HologramSession, &RgbdFrame) -> Result<&'s SlmFrame>,
    ) -> Result<SlmPatterns> {
        let t = Instant::now();
        let (rgbd, report) = self.convert(frame)?;
        let convert_s = t.elapsed().as_secs_f64();
        let mut session = self.session()?;
        let out = render(&mut session, &rgbd)?;
        Ok(SlmPatterns::from_frame(out, convert_s, report.range_used))
    }

    /// Renders one camera frame foveated on `gaze` (`docs/FOVEATION.md`): the 3D CNN around the gaze, the
    /// paper's 2D hologram with synthetic blur, in focus at the gaze's depth, elsewhere
    /// ([`HologramSession::render_foveated`]). `gaze` is a point of the hologram (after the camera frame's
    /// fit: pixels of the `width × height` output, `(0, 0)` the top-left pixel's centre, x right, y down), with
    /// an eye tracker's vergence depth in metres if it has one ([`Gaze::depth_m`]; else the scene's depth
    /// there). The patterns' normaliser is the same for every gaze on one frame.
    ///
    /// Errors: [`HoloError::InvalidParameter`] naming `foveation` for a generator made without
    /// [`GeneratorConfig::foveation`], or `gaze` for a point outside the hologram or not finite; otherwise
    /// as [`HologramGenerator::render`]. The generator stays usable after any error.
    pub fn render_foveated(&self, frame: &CameraFrame<&[u8]>, gaze: &Gaze) -> Result<SlmPatterns> {
        self.render_with(frame, |session, rgbd| session.render_foveated(rgbd, gaze))
    }

    /// The photo mode: renders one camera frame as [`HologramGenerator::render`] does, then refines its SLM
    /// patterns with `refinement` (focal-stack refinement warm-started from the CNN's codes, against the
    /// frame's SM-LBM focal stack by default; [`crate::refine`], `docs/REFINE.md`) through the generator's
    /// display calibration. `progress(record)` is called with the start's loss and after every iteration
    /// (on the calling thread); `ControlFlow::Break(())` cancels. Takes seconds on a phone: call it off the
    /// UI thread. The patterns' `amplitude_scale` is the refined pattern's least-squares scale. With a
    /// viewer's aberration (a prescription or an aberration profile), the refinement's model sees through the
    /// viewer's eye, so the refined patterns stay corrected (`docs/REFINE.md`, "A viewer's aberration"). The
    /// iterations run where the session's frames run: on its GPU where it has one (`gpu` feature,
    /// [`FrameRefiner::for_pipeline`]).
    ///
    /// Errors: as [`HologramGenerator::render`]; [`HoloError::InvalidParameter`] for a bad `refinement`
    /// (naming the setting: `iterations`, `step_rad`, `planes`, `levels`), or `target` for the CNN target with
    /// a CNN trained for the viewer's aberration; [`HoloError::Cancelled`] when `progress` stopped it.
    /// The generator stays usable after any error.
    pub fn render_refined(
        &self,
        frame: &CameraFrame<&[u8]>,
        refinement: &FrameRefinement,
        progress: &mut dyn FnMut(&IterationRecord) -> ControlFlow<()>,
    ) -> Result<SlmPatterns> {
        refinement.validate()?;
        // The viewer's aberration the session corrects (the generator's or the pipeline's): the refinement's
        // model sees through it, so the refined pattern stays corrected.
        let viewer = self.aberration().map(|(profile, _)| profile);
        let t = Instant::now();
        let (rgbd, report) = self.convert(frame)?;
        let convert_s = t.elapsed().as_secs_f64();
        let cnn_target = refinement.target == RefineTarget::CnnMidpoint;
        let (mut patterns, midpoint, backend) = {
            let mut session = self.session()?;
            if cnn_target {
                session.set_full_outputs(true);
            }
            let rendered = session
                .render(&rgbd)
                .map(|out| SlmPatterns::from_frame(out, convert_s, report.range_used));
            let midpoint = match (&rendered, cnn_target) {
                (Ok(_), true) => session.last_heads().map(|h| h.to_field()).transpose(),
                _ => Ok(None),
            };
            if cnn_target {
                session.set_full_outputs(false);
            }
            (rendered?, midpoint?, session.backend_report().clone())
        };
        let threads = match self.config.cnn.threads {
            ThreadCount::Fixed(n) => n.max(1),
            _ => crate::cnn::default_threads(),
        };
        // The calibration and the viewer's aberration the session applies now.
        let mut refiner = FrameRefiner::for_session(
            *refinement,
            &self.pipeline,
            &backend,
            (self.calibration(), viewer),
            threads,
        )?
        .with_display_model(self.config.display_model.clone())?;
        let refined = refiner.refine(
            &[SceneLayer::from(&rgbd)],
            midpoint.as_ref().map(|m| m.view()),
            patterns.codes.view(),
            progress,
        )?;
        patterns.codes = refined.codes;
        patterns.amplitude_scale = refined.amplitude_scale;
        Ok(patterns)
    }

    /// Renders a layered depth image delivered as camera frames, one per layer front to back (a renderer's
    /// depth-peeling pass), with the buffer rules of [`HologramGenerator::render`] for every layer
    /// ([`ldi_from_camera_frames`]: one depth range for all layers; in the back layers an invalid depth sample,
    /// e.g. 0, means "no point here"). Needs a generator with an LDI hologram CNN
    /// (`config.models.input` = [`crate::model::SceneInput::Ldi`]); an LDI of fewer layers than the CNN takes
    /// is padded with empty layers.
    ///
    /// Errors: the conversion's ([`ldi_from_camera_frames`]: buffers, layer sizes, depth order);
    /// [`HoloError::InvalidParameter`] (`ldi`) for more layers than the CNN takes (with an RGB-D CNN: more than
    /// one); as [`HologramSession::render_ldi`]. The generator stays usable after any error.
    pub fn render_ldi(&self, layers: &[CameraFrame<&[u8]>]) -> Result<SlmPatterns> {
        let t = Instant::now();
        let (ldi, report) = ldi_from_camera_frames(
            layers,
            self.config.height,
            self.config.width,
            &self.config.frame_options(),
        )?;
        let convert_s = t.elapsed().as_secs_f64();
        let mut session = self.session()?;
        let out = session.render_ldi(&ldi)?;
        Ok(SlmPatterns::from_frame(out, convert_s, report.range_used))
    }

    /// Renders an RGB-D frame already at the hologram resolution (`[3, H, W]` amplitude, `[H, W]` depth).
    ///
    /// Errors: as [`HologramSession::render`].
    pub(crate) fn render_rgbd(&self, frame: &RgbdFrame) -> Result<SlmPatterns> {
        let mut session = self.session()?;
        let out = session.render(frame)?;
        Ok(SlmPatterns::from_frame(out, 0.0, None))
    }

    /// What a viewer sees of `patterns` focused at normalised depth `focus` ∈ [0, 1] (0 = near): the phase
    /// the SLM displays for the 8-bit codes (through the calibrated curves of
    /// [`HologramGenerator::set_calibration`], else [`crate::encoding::LinearLut::phase`]; quantisation included), as a phase-only
    /// field (Eq. 8–10, no aperture) propagated from the midpoint plane to `z(focus)`, as sRGB.
    ///
    /// Errors: [`HoloError::InvalidParameter`] for a focus outside [0, 1] or NaN; as
    /// [`post_encoding_midpoint`] and [`focal_stack`].
    pub fn preview_patterns(&self, patterns: &SlmPatterns, focus: f32) -> Result<Preview> {
        if !(0.0..=1.0).contains(&focus) {
            return Err(invalid(
                "focus",
                format!("is a normalised depth in [0, 1] (0 = near), got {focus}"),
            ));
        }
        let calibration = self.calibration();
        let calibrated = calibration
            .as_ref()
            .is_some_and(|cal| cal.has_calibrated_lut());
        if !calibrated {
            // The accelerator's preview reads codes through the linear table; a calibrated panel's runs below.
            let mut session = self.session()?;
            let same_size = patterns.codes.dim() == (3, self.config.height, self.config.width);
            if same_size {
                let shown = session.accelerator_preview(
                    &patterns.codes,
                    patterns.amplitude_scale,
                    focus as f64,
                );
                match shown {
                    Some(Ok(amp)) => return Ok(preview_image(&amp)),
                    Some(Err(HoloError::Gpu(e))) => {
                        log::warn!("GPU preview failed ({e}); computing it on the CPU")
                    }
                    Some(Err(e)) => return Err(e),
                    None => {}
                }
            }
        }
        let cfg = &self.config;
        let phase = displayed_phase(patterns.codes.view(), calibration.as_deref())?;
        let shown = post_encoding_midpoint(
            phase.view(),
            patterns.amplitude_scale,
            &cfg.optics,
            cfg.offset_m,
            cfg.options,
        )?;
        let stack = focal_stack(
            shown.view(),
            &cfg.optics,
            0.0,
            &[focus as f64],
            cfg.options,
            false,
        )?;
        let amp = stack
            .first()
            .ok_or_else(|| HoloError::Internal("focal stack returned no image".into()))?;
        Ok(preview_image(amp))
    }

    /// Renders `frame` and returns what a viewer sees focused at normalised depth `focus` ∈ [0, 1]
    /// ([`HologramGenerator::preview_patterns`]), for the phone's screen.
    ///
    /// Errors: as [`HologramGenerator::render`] and [`HologramGenerator::preview_patterns`].
    pub fn preview(&self, frame: &CameraFrame<&[u8]>, focus: f32) -> Result<Preview> {
        if !(0.0..=1.0).contains(&focus) {
            return Err(invalid(
                "focus",
                format!("is a normalised depth in [0, 1] (0 = near), got {focus}"),
            ));
        }
        let patterns = self.render(frame)?;
        self.preview_patterns(&patterns, focus)
    }

    /// What this generator runs: models, precision, pre-filter and why, the chosen CNN plan, the display
    /// mapping.
    ///
    /// Errors: [`HoloError::Internal`] only if the session cannot be recreated after a panic.
    pub fn info(&self) -> Result<GeneratorInfo> {
        let (plan, backend, aberration) = {
            let session = self.session()?;
            (
                session.plan_report().clone(),
                session.backend_report().clone(),
                session.aberration().map(|(_, r)| r.clone()),
            )
        };
        let md = self.pipeline.hologram_model().metadata();
        Ok(GeneratorInfo {
            version: env!("CARGO_PKG_VERSION").to_string(),
            width: self.config.width,
            height: self.config.height,
            layers: md.layers,
            precision: self.config.models.precision,
            hologram_model: self.pipeline.hologram_model().source_name().to_string(),
            prefilter_model: self
                .pipeline
                .prefilter_model()
                .map(|m| m.source_name().to_string()),
            prefilter_reason: self.pipeline.prefilter_reason().to_string(),
            encoding: self.pipeline.encoding(),
            offset_m: self.config.offset_m,
            plan,
            backend,
            calibration: self.calibration().map(|c| c.summary()),
            display_mapping: self.pipeline.display_mapping_description(),
            aberration,
        })
    }

    /// Starts a video stream whose results go to `listener` ([`HologramStream`]); its queue holds
    /// `capacity` frames (≥ 1; [`DEFAULT_STREAM_CAPACITY`]). The stream has its own session (the CNN plans
    /// and the autotuning result are shared with this generator's), so [`HologramGenerator::render`] stays
    /// available meanwhile. Each delivered [`SlmPatterns::phase_churn`] counts the change from the previous
    /// frame; [`GeneratorConfig::align_phase`] aligns each frame's global phase to the previous one's.
    ///
    /// Errors: [`HoloError::InvalidParameter`] for a capacity of 0, or `align_phase` with a calibration whose
    /// look-up tables are calibrated; as [`HologramPipeline::session`].
    pub fn stream(
        &self,
        listener: Box<dyn StreamListener>,
        capacity: usize,
    ) -> Result<HologramStream> {
        if capacity == 0 {
            return Err(invalid("capacity", "a stream queue holds at least 1 frame"));
        }
        // The stream's session repeats this generator's plans (a tuned generator's too): both give the same
        // codes.
        let plans = Arc::new(self.session()?.plan_report().saved());
        let pipeline = self.pipeline.repeating(plans);
        let aberration = lock_slot(&self.aberration).clone();
        let calibration = self.calibration();
        let calibrated = calibration.as_ref().is_some_and(|c| c.has_calibrated_lut());
        let temporal = PhaseContinuity::new(self.config.align_phase, calibrated)?;
        let session = open_session(&pipeline, &self.config, calibration, aberration)?;
        HologramStream::start(session, self.config.clone(), temporal, listener, capacity)
    }
}

/// A session for `config`'s size with `calibration` that downloads only what [`SlmPatterns`] holds (codes and
/// normaliser) from the GPU.
fn open_session(
    pipeline: &HologramPipeline,
    config: &GeneratorConfig,
    calibration: Option<Arc<DisplayCalibration>>,
    aberration: Option<Arc<AberrationProfile>>,
) -> Result<HologramSession> {
    let mut session = pipeline.session(config.height, config.width)?;
    session.set_full_outputs(false);
    session.set_calibration(calibration)?;
    // The pipeline's own correction is already applied; a later `set_aberration` replaced it.
    if pipeline.aberration() != aberration.as_ref() {
        session.set_aberration(aberration)?;
    }
    Ok(session)
}

/// A slot of a plain `Option<Arc>` (the calibration, the aberration profile), consistent whatever a panicking
/// thread did.
fn lock_slot<T>(slot: &Mutex<Option<Arc<T>>>) -> MutexGuard<'_, Option<Arc<T>>> {
    slot.lock().unwrap_or_else(|e| e.into_inner())
}

#[cfg(all(test, feature = "embedded-models"))]
mod tests {
    use super::*;
    use crate::cnn::{CnnEngine, ThreadCount};
    use crate::display::DisplayProfile;
    use crate::generator::config::tests::PROFILE_4UM;
    use crate::optics::OpticalSetup;
    use crate::pipeline::Backend;

    /// Small and deterministic: one thread, the native engine, the CPU.
    fn quick(mut c: GeneratorConfig) -> GeneratorConfig {
        c.cnn.threads = ThreadCount::Fixed(1);
        c.cnn.engine = CnnEngine::Native;
        c.backend = Backend::Cpu;
        c
    }

    /// The shipped 8 µm CNNs drive the 4 µm SLM of a profile: a frame renders, the 6 mm pre-filter serves
    /// the 1.5 mm offset, and the info's display mapping says σ = 0.25.
    #[test]
    fn a_generator_for_a_4um_profile_renders_and_reports_its_mapping() {
        let profile = DisplayProfile::from_json_str(PROFILE_4UM).unwrap();
        let g = HologramGenerator::new(quick(GeneratorConfig::for_display(&profile))).unwrap();
        let scene = crate::scene::procedural::default_scene(48, 64).unwrap();
        let out = g.render_rgbd(&scene).unwrap();
        assert_eq!(out.codes.dim(), (3, 48, 64));
        assert!(out.codes.iter().any(|&c| c != out.codes[[0, 0, 0]]));
        let info = g.info().unwrap();
        assert!(
            info.display_mapping.contains("σ = 0.25"),
            "{}",
            info.display_mapping
        );
        assert!(
            info.display_mapping
                .contains("serves 4 µm with a 1.5 mm volume"),
            "{}",
            info.display_mapping
        );
        assert!(
            info.prefilter_model
                .as_deref()
                .is_some_and(|m| m.contains("6mm")),
            "{:?}: {}",
            info.prefilter_model,
            info.prefilter_reason
        );
        let json = serde_json::to_string(&info).unwrap();
        assert!(json.contains("\"display_mapping\""), "{json}");
    }

    /// The configured tolerance reaches the model check: a 532 nm green laser is refused by default, naming
    /// the wavelengths, and served (reported "widened") at 3 %.
    #[test]
    fn the_wavelength_ratio_tolerance_reaches_the_model_check() {
        // A green 8 % off 520 nm costs more than the rule allows: refused, naming the lasers.
        let mut c = quick(GeneratorConfig::new(64, 48));
        c.optics.wavelengths_m = [638e-9, 561.6e-9, 450e-9];
        let sigma = |c: &GeneratorConfig| {
            crate::display::DisplayMapping::compute(
                &OpticalSetup::default(),
                &c.optics,
                0.0,
                None,
                28.08,
            )
            .unwrap()
            .scale
        };
        c.optics.volume_depth_m = sigma(&c) * 6e-3;
        c.offset_m = sigma(&c) * 6e-3;
        match HologramGenerator::new(c.clone()) {
            Err(HoloError::DisplayNotServed(r)) => {
                assert!(r.key.ends_with("wavelengths_m"), "{}", r.key)
            }
            other => panic!("expected a refusal naming the wavelengths, got {other:?}"),
        }
        c.wavelength_ratio_tolerance = Some(0.05);
        let g = HologramGenerator::new(c).unwrap();
        let info = g.info().unwrap();
        assert!(
            info.display_mapping.contains("widened"),
            "{}",
            info.display_mapping
        );
    }
}

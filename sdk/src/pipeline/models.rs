//! [`HologramPipeline`]: the loaded CNNs plus the display configuration and calibration, checked against
//! each other once; a factory of sessions (`HologramPipeline::session`, in `session.rs`). Imports no executor
//! and no session.

use std::sync::Arc;

use super::config::PipelineConfig;
use super::correction::AberrationReport;
use super::selection::{shipped_prefilter, ModelSelection, PrefilterMode, PrefilterSource};
use crate::cnn::{PlanRequest, PlanSource, SavedPlans};
use crate::display::{AberrationProfile, DisplayMapping};
use crate::encoding::DoublePhaseMethod;
use crate::error::{invalid, HoloError, Result};
use crate::model::{HologramModel, ModelKind, Precision};
use crate::slm::DisplayCalibration;

/// The loaded CNNs plus their configuration: a factory of [`HologramSession`](crate::pipeline::HologramSession)s.
#[derive(Debug, Clone)]
pub struct HologramPipeline {
    config: PipelineConfig,
    hologram: Arc<HologramModel>,
    prefilter: Option<Arc<HologramModel>>,
    /// Why the pipeline runs (or does not run) a pre-filter CNN, for logs and reports.
    prefilter_reason: String,
    /// Whether the caller gave the pre-filter CNN or required it ([`PrefilterMode::Required`]): such a
    /// pre-filter is used or refused, never dropped ([`HologramPipeline::with_aberration`]).
    prefilter_given: bool,
    /// How the hologram CNN's training display maps onto the configured one.
    display_mapping: DisplayMapping,
    /// The display calibration sessions apply ([`HologramPipeline::with_calibration`]); `None`: an ideal SLM.
    calibration: Option<Arc<DisplayCalibration>>,
    /// The viewer's aberration profile sessions correct ([`HologramPipeline::with_aberration`]); `None`: an
    /// ideal eye behind ideal optics.
    aberration: Option<Arc<AberrationProfile>>,
    /// The saved CNN plans sessions repeat ([`HologramPipeline::with_saved_plans`]); `None`: the plan table,
    /// or a timing with [`CnnOptions::tune`](crate::cnn::CnnOptions::tune).
    saved_plans: Option<Arc<SavedPlans>>,
    /// The app's own GPU context ([`HologramPipeline::with_gpu_context`]); `None`: the shared one.
    #[cfg(feature = "gpu")]
    gpu_context: Option<crate::gpu::GpuContext>,
}

impl HologramPipeline {
    /// Combines a hologram CNN with an optional pre-filter CNN (DDPM) under `config`.
    ///
    /// A volume within 1 % of the one the models serve (`σ·V`, [`DisplayMapping`]) runs at `σ·V`
    /// ([`HologramPipeline::config`] then holds it); a smaller one maps the scene's depths into the part of the
    /// models' volume it needs ([`DisplayMapping::depth_fraction`], applied to every frame's depths).
    ///
    /// Errors: [`HoloError::InvalidParameter`] for an invalid setup or offset, a pre-filter with a 0 m offset,
    /// or models of the wrong kind; [`HoloError::DisplayNotServed`] for a display the models do not serve
    /// (what would serve it is in the error); [`HoloError::ModelMetadata`] for other metadata mismatches; [`HoloError::ModelContract`] for a model no CPU CNN engine
    /// of this build runs ([`crate::cnn::check_runnable`]: e.g. a graph only tract runs, in a build without
    /// the `tract` feature).
    pub fn new(
        hologram: Arc<HologramModel>,
        prefilter: Option<Arc<HologramModel>>,
        mut config: PipelineConfig,
    ) -> Result<Self> {
        config.optics.validate()?;
        crate::optics::check_offset("offset_m", config.offset_m)?;
        config.cnn.validate()?;
        let expected = config.model_config(hologram.metadata().input_layers);
        let display_mapping = hologram.metadata().check(ModelKind::Hologram, &expected)?;
        if let Some(p) = &prefilter {
            if config.offset_m == 0.0 {
                return Err(invalid(
                    "prefilter",
                    "a pre-filter CNN belongs to a non-zero SLM offset (DDPM, Eq. 6); none is used at 0 m",
                ));
            }
            p.metadata().check(ModelKind::PreFilter, &expected)?;
        }
        crate::cnn::check_runnable(&hologram)?;
        if let Some(p) = &prefilter {
            crate::cnn::check_runnable(p)?;
        }
        // A volume within the rounding of σ·V runs at σ·V (the mapping says so in its description).
        config.optics.volume_depth_m = display_mapping.running_volume_depth_m();
        let prefilter_given = prefilter.is_some();
        let prefilter_reason = if prefilter_given {
            "pre-filter CNN given by the caller"
        } else if config.offset_m == 0.0 {
            "no pre-filter at a 0 mm offset"
        } else {
            "no pre-filter CNN given"
        }
        .to_string();
        log::info!(
            "{}",
            display_mapping.description(&hologram.metadata().describe())
        );
        Ok(Self {
            config,
            hologram,
            prefilter,
            prefilter_reason,
            prefilter_given,
            display_mapping,
            calibration: None,
            aberration: None,
            saved_plans: None,
            #[cfg(feature = "gpu")]
            gpu_context: None,
        })
    }

    /// The shipped models (`models/`, feature `embedded-models`) chosen by name: the hologram CNN taking
    /// `selection.input` with `selection.layers` layers (RGB-D: 8, 15 or 30; LDI: 8) in `selection.precision`,
    /// and the DDPM pre-filter CNN of
    /// `config.offset_m` as `selection.prefilter` says (`HologramPipeline::with_shipped_prefilter`).
    ///
    /// Errors: [`HoloError::InvalidParameter`] for a layer count or (with [`PrefilterMode::Required`]) an
    /// offset without a shipped model; as [`HologramModel::from_bytes`] and [`HologramPipeline::new`].
    #[cfg(feature = "embedded-models")]
    pub fn embedded(selection: &ModelSelection, config: PipelineConfig) -> Result<Self> {
        let expected = config.model_config(selection.input.input_layers());
        let hologram = crate::model::embedded::scene_hologram_model(
            selection.input,
            selection.layers,
            selection.precision,
            &expected,
        )?;
        Self::with_prefilter(
            Arc::new(hologram),
            PrefilterSource::Shipped(selection.prefilter),
            selection.precision,
            config,
        )
    }

    /// Combines `hologram` with the shipped pre-filter CNN of `config.offset_m` (in `precision`) as `mode`
    /// says; the rule the CLI and the bindings share:
    /// - [`PrefilterMode::Off`], or a 0 m offset: none (encoding with `config.encoding`);
    /// - [`PrefilterMode::Auto`]: the shipped pre-filter of the offset (6 or 12 mm) trained on the holograms of
    ///   a CNN of this depth (`tensorholo.hologram_layers`): `prefilter_6mm.onnx` for 8 layers (the LDI CNN
    ///   included), `prefilter_6mm_holo15.onnx` / `_holo30` for 15 / 30 layers (embedded with the features
    ///   `models-15` / `models-30`, as their CNNs). A pre-filter can fall below AA-DPM with a CNN it was not
    ///   trained with (`models/MODEL_CARD.md`). Otherwise none, and [`HologramPipeline::prefilter_reason`]
    ///   says why;
    /// - [`PrefilterMode::Required`]: as Auto, and where no pre-filter of this depth is embedded, the 8-layer
    ///   CNN's.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`prefilter`) for [`PrefilterMode::Required`] at 0 m or at an
    /// offset without a shipped pre-filter; [`HoloError::InvalidParameter`] (`prefilter`) without the
    /// `embedded-models` feature unless the mode resolves to none; as [`HologramPipeline::new`].
    pub fn with_shipped_prefilter(
        hologram: Arc<HologramModel>,
        mode: PrefilterMode,
        precision: Precision,
        config: PipelineConfig,
    ) -> Result<Self> {
        crate::optics::check_offset("offset_m", config.offset_m)?;
        let (prefilter, reason) = shipped_prefilter(&hologram, mode, precision, &config)?;
        let mut pipeline = Self::new(hologram, prefilter.map(Arc::new), config)?;
        pipeline.prefilter_reason = reason;
        pipeline.prefilter_given = mode == PrefilterMode::Required;
        Ok(pipeline)
    }

    /// Combines `hologram` with its pre-filter CNN from `source`: the one rule that decides which CNNs run,
    /// used by [`HologramPipeline::embedded`], `HologramGenerator::from_onnx` and `holo render`.
    /// - [`PrefilterSource::Shipped`]: as `HologramPipeline::with_shipped_prefilter` (shipped pre-filters in
    ///   `precision`);
    /// - [`PrefilterSource::Given`]: the caller's pre-filter, as [`HologramPipeline::new`] (refused at a 0 m
    ///   offset, never silently dropped).
    ///
    /// Errors: as `HologramPipeline::with_shipped_prefilter` and [`HologramPipeline::new`].
    pub fn with_prefilter(
        hologram: Arc<HologramModel>,
        source: PrefilterSource,
        precision: Precision,
        config: PipelineConfig,
    ) -> Result<Self> {
        match source {
            PrefilterSource::Shipped(mode) => {
                Self::with_shipped_prefilter(hologram, mode, precision, config)
            }
            PrefilterSource::Given(p) => Self::new(hologram, Some(p), config),
        }
    }

    /// Why this pipeline runs a pre-filter CNN or not (e.g. "shipped 6 mm pre-filter (auto, trained with the
    /// 30-layer hologram CNN)").
    pub fn prefilter_reason(&self) -> &str {
        &self.prefilter_reason
    }

    /// How the hologram CNN's training display maps onto this pipeline's display ([`DisplayMapping`],
    /// `docs/DISPLAYS.md`): the depth scale `σ` (1 on the paper's display), the per-colour mismatch, the
    /// non-paraxial residual. [`HologramPipeline::display_mapping_description`] says it in one line.
    pub fn display_mapping(&self) -> &DisplayMapping {
        &self.display_mapping
    }

    /// [`HologramPipeline::display_mapping`] as one line for logs and reports, e.g. "the 8-layer hologram CNN
    /// (trained at 8 µm, 6 mm volume) serves 4 µm with a 1.5 mm volume (σ = 0.250000); offset 1.5 mm ↔ 6 mm
    /// trained; wavelength mismatch 0.00 % (tolerance 0.50 %); non-paraxial residual 0.084 rad (bound 0.25
    /// rad)".
    pub fn display_mapping_description(&self) -> String {
        self.display_mapping
            .description(&self.hologram.metadata().describe())
    }

    /// Runs the GPU backend on `ctx` (e.g. [`crate::gpu::GpuContext::from_device`] with the app's own wgpu
    /// device) instead of the process-wide shared context.
    #[cfg(feature = "gpu")]
    pub fn with_gpu_context(mut self, ctx: crate::gpu::GpuContext) -> Self {
        self.gpu_context = Some(ctx);
        self
    }

    /// Makes every session from now on repeat `plans` (a tuning saved earlier, [`crate::cnn::PlanReport::saved`]):
    /// its engine, layout, threads and layer rows where it has them for the session, the plan table's
    /// otherwise; nothing is timed, so every run gives the same bits.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`cnn.tune`) where [`CnnOptions::tune`](crate::cnn::CnnOptions::tune) asks to time
    /// instead; [`HoloError::InvalidParameter`] (`tuning`) for plans that fail
    /// `SavedPlans::validate`. Plans made for another kernel ISA level are refused when a session is made.
    pub fn with_saved_plans(mut self, plans: Arc<SavedPlans>) -> Result<Self> {
        if self.config.cnn.tune {
            return Err(invalid(
                "cnn.tune",
                "saved plans and a new tuning were both asked for: give one",
            ));
        }
        plans.validate()?;
        self.saved_plans = Some(plans);
        Ok(self)
    }

    /// This pipeline with its sessions repeating `plans` (a session's own decisions,
    /// [`crate::cnn::PlanReport::saved`]), `cnn.tune` off: a second session (a stream's) makes the same plans
    /// as the first without timing again.
    pub(crate) fn repeating(&self, plans: Arc<SavedPlans>) -> Self {
        let mut p = self.clone();
        p.config.cnn.tune = false;
        p.saved_plans = Some(plans);
        p
    }

    /// The saved CNN plans sessions repeat, if any ([`HologramPipeline::with_saved_plans`]).
    pub fn saved_plans(&self) -> Option<&Arc<SavedPlans>> {
        self.saved_plans.as_ref()
    }

    /// What a session's CNN plans are made from: the configuration's layout, threads and algorithm, from the
    /// saved plans, a timing (`cnn.tune`) or the plan table.
    pub(super) fn plan_request(&self) -> Result<PlanRequest> {
        let c = &self.config;
        let source = match (&self.saved_plans, c.cnn.tune) {
            (Some(_), true) => {
                return Err(invalid(
                    "cnn.tune",
                    "saved plans and a new tuning were both asked for: give one",
                ))
            }
            (Some(p), false) => PlanSource::Saved(p.clone()),
            (None, true) => PlanSource::Tune,
            (None, false) => PlanSource::Table,
        };
        Ok(PlanRequest { cnn: c.cnn, source })
    }

    /// Applies a display's calibration (`.holocal`, [`DisplayCalibration`]) in every session made from now
    /// on: its per-colour look-up table turns the double phase pattern into codes (instead of the linear
    /// one), and its laser intensity scale map, where present, multiplies the target amplitude before the
    /// hologram CNN (`docs/CALIBRATION.md`). Sessions must then have the calibration's SLM size.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`calibration`) if a colour's wavelength differs from
    /// the pipeline's optics by more than 1 nm (a look-up table holds for one wavelength only).
    pub fn with_calibration(mut self, calibration: Arc<DisplayCalibration>) -> Result<Self> {
        check_calibration_wavelengths(&calibration, &self.config.optics.wavelengths_m)?;
        self.calibration = Some(calibration);
        Ok(self)
    }

    /// Corrects the viewer's aberrations (`profile`, `docs/ABERRATION.md`) in every session made from now on:
    /// the correction kernel of its coefficients at the midpoint plane multiplies the midpoint hologram's
    /// spectrum in the offset propagation's pass ([`HologramSession::set_aberration`], which also changes it
    /// on a running session), on the CPU frame and the GPU frame alike.
    ///
    /// A hologram CNN trained for aberrations (its metadata's `tensorholo.aberration`, from an
    /// aberration-corrected dataset: `training/retrain.sh --display` with a profile's `aberration`) corrects
    /// them itself, at every distance: it runs only with the same profile, no kernel is applied on top, and its
    /// pre-filter (trained on its corrected holograms) is kept ([`HologramPipeline::corrected_by_cnn`]).
    ///
    /// The pipeline then encodes with its configured double phase method (AA-DPM by default), not with a DDPM
    /// pre-filter CNN, which is dropped ([`HologramPipeline::prefilter_reason`] says so) where the pipeline
    /// chose it ([`PrefilterMode::Auto`]) and refused where the caller gave or required it: the shipped
    /// pre-filters were trained on uncorrected fields, and on corrected ones they fall far below AA-DPM once
    /// the correction is more than weak. Measured on a real frame through a cylindrical lens, focal-stack PSNR
    /// of the 6 mm pre-filter minus AA-DPM: +1.2 dB at 0.25 D, +0.2 at 0.5 D, −2.0 at 1 D, −14.6 at 2 D, −23.7
    /// at 5 D (`sdk/tests/aberration_realtime.rs`, `the_ddpm_prefilter_falls_below_aa_dpm_on_corrected_fields`), so a
    /// correction that a viewer may move (a slider) keeps one encoding that holds at every strength.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`wavelengths_m`, `pixel_pitch_m`) for a profile calibrated
    /// for another display (`AberrationProfile::check_setup`), or (`prefilter`) for a pre-filter CNN the
    /// caller gave or required ([`PrefilterMode::Required`]); [`HoloError::ModelMetadata`]
    /// (`tensorholo.aberration`) for a hologram CNN trained for other aberrations, naming both.
    ///
    /// [`HologramSession::set_aberration`]: crate::pipeline::HologramSession::set_aberration
    pub fn with_aberration(mut self, profile: Arc<AberrationProfile>) -> Result<Self> {
        profile.check_setup(&self.config.optics)?;
        if let Some(trained) = &self.hologram.metadata().aberration {
            if !trained.same_aberrations(&profile) {
                return Err(HoloError::ModelMetadata {
                    key: "tensorholo.aberration".into(),
                    found: format!("trained for {}", trained.describe()),
                    expected: format!(
                        "the aberrations given ({}): retrain for them (training/retrain.sh --display with \
                         the profile's `aberration`), or give the file the model was trained for",
                        profile.describe()
                    ),
                });
            }
            self.aberration = Some(profile);
            return Ok(self);
        }
        if self.prefilter.is_some() && self.prefilter_given {
            return Err(invalid(
                "prefilter",
                "a pre-filter CNN was given or required, but the DDPM pre-filters were trained on uncorrected \
                 fields and fall below AA-DPM on corrected ones (−2 dB at 1 D of cylinder, −24 dB at 5 D; \
                 docs/ABERRATION.md): with an aberration correction, let the pipeline choose \
                 (PrefilterMode::Auto) or give none",
            ));
        }
        if self.prefilter.take().is_some() {
            self.prefilter_reason = format!(
                "no pre-filter CNN: with an aberration correction the pipeline encodes with {:?} (the \
                 shipped DDPM pre-filters were trained on uncorrected fields and fall below it on corrected \
                 ones: −2 dB at 1 D of cylinder, −24 dB at 5 D; docs/ABERRATION.md)",
                self.config.encoding
            );
        }
        self.aberration = Some(profile);
        Ok(self)
    }

    /// The viewer's aberration profile sessions correct, if any.
    pub fn aberration(&self) -> Option<&Arc<AberrationProfile>> {
        self.aberration.as_ref()
    }

    /// What the pipeline's aberration correction applies and leaves, as its sessions report it
    /// ([`HologramSession::aberration`](crate::pipeline::HologramSession::aberration)): the coefficients at the
    /// midpoint plane and the residual over the volume, or that the CNN corrects (`AberrationReport::by_cnn`);
    /// `None` without a correction.
    pub fn aberration_report(&self) -> Option<AberrationReport> {
        let profile = self.aberration.as_ref()?;
        let (optics, offset_m) = (&self.config.optics, self.config.offset_m);
        Some(if self.corrected_by_cnn() {
            AberrationReport::by_cnn(profile, offset_m)
        } else {
            AberrationReport::new(profile, optics, offset_m)
        })
    }

    /// Whether the hologram CNN itself corrects the pipeline's aberrations (it was trained for them, metadata
    /// `tensorholo.aberration`): sessions then apply no correction kernel.
    pub fn corrected_by_cnn(&self) -> bool {
        self.hologram.metadata().aberration.is_some()
    }

    /// Checks, when a session is made, that a hologram CNN trained for aberrations runs with them.
    ///
    /// Errors: [`HoloError::ModelMetadata`] (`tensorholo.aberration`) for such a CNN in a pipeline without an
    /// aberration profile.
    pub(super) fn check_trained_aberration(&self) -> Result<()> {
        match (&self.hologram.metadata().aberration, &self.aberration) {
            (Some(trained), None) => Err(HoloError::ModelMetadata {
                key: "tensorholo.aberration".into(),
                found: format!("trained for {}", trained.describe()),
                expected: "a pipeline with those aberrations (holo render --aberration FILE or the display \
                           profile's `aberration`; HologramPipeline::with_aberration): without them its \
                           holograms are corrected for optics that are not there"
                    .into(),
            }),
            _ => Ok(()),
        }
    }

    /// The display calibration sessions apply, if any.
    pub fn calibration(&self) -> Option<&Arc<DisplayCalibration>> {
        self.calibration.as_ref()
    }

    /// The configuration.
    pub fn config(&self) -> &PipelineConfig {
        &self.config
    }

    /// The hologram CNN.
    pub fn hologram_model(&self) -> &Arc<HologramModel> {
        &self.hologram
    }

    /// The pre-filter CNN, if any.
    pub fn prefilter_model(&self) -> Option<&Arc<HologramModel>> {
        self.prefilter.as_ref()
    }

    /// The double phase method this pipeline encodes with: [`DoublePhaseMethod::Plain`] after a pre-filter
    /// CNN (DDPM), otherwise the configured one.
    pub fn encoding(&self) -> DoublePhaseMethod {
        if self.prefilter.is_some() {
            DoublePhaseMethod::Plain
        } else {
            self.config.encoding
        }
    }
}

/// The app's GPU context, if it gave one ([`HologramPipeline::with_gpu_context`]).
#[cfg(feature = "gpu")]
impl HologramPipeline {
    pub(super) fn gpu_context(&self) -> Option<&crate::gpu::GpuContext> {
        self.gpu_context.as_ref()
    }
}

/// Largest wavelength difference (metres) between a display calibration and the pipeline's optics.
const CALIBRATION_WAVELENGTH_TOLERANCE_M: f64 = 1e-9;

/// Refuses a calibration measured at other wavelengths than the display's `wavelengths_m` (R, G, B; more
/// than 1 nm apart).
pub(super) fn check_calibration_wavelengths(
    cal: &DisplayCalibration,
    wavelengths_m: &[f64; 3],
) -> Result<()> {
    for (c, (col, &want)) in cal.colours.iter().zip(wavelengths_m).enumerate() {
        if (col.wavelength_m - want).abs() > CALIBRATION_WAVELENGTH_TOLERANCE_M {
            return Err(invalid(
                "calibration",
                format!(
                    "the {} look-up table was measured at {:.1} nm, the display's {} laser is {:.1} nm; \
                     calibrate at the display's wavelengths",
                    crate::slm::file::COLOUR_NAMES[c],
                    col.wavelength_m * 1e9,
                    crate::slm::file::COLOUR_NAMES[c],
                    want * 1e9
                ),
            ));
        }
    }
    Ok(())
}

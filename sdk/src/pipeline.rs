//! The real-time hologram pipeline (`docs/CONVENTIONS.md` §8, paper Fig. 3): RGB-D frame (or layered depth
//! image) → hologram CNN (tract) → midpoint hologram → offset propagation (Eq. 6) → pre-filter CNN (DDPM) →
//! double phase encoding (Eq. 7) → look-up table → three 8-bit SLM planes.
//!
//! - [`HologramPipeline`] holds the loaded CNNs and the display configuration, checked against each other
//!   once.
//! - [`HologramSession`] (one per resolution) owns everything a frame reuses: the tract plans, FFT plans,
//!   transfer functions, double-phase encoders and scratch buffers, and three colour worker threads. After
//!   the first frame, the optics stages (offset propagation, pre-filter input, double phase, LUT) perform no
//!   heap allocation (`sdk/tests/pipeline_alloc.rs` counts); the CNN stages allocate inside tract.
//! - [`HologramSession::render_stream`] overlaps the hologram CNN of frame `n + 1` with the optics of frame
//!   `n` (two threads); its output equals [`HologramSession::render`]'s bit for bit.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::mpsc::sync_channel;
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Instant;

use ndarray::{Array3, ArrayView3, Axis};
use num_complex::Complex32;

use crate::encoding::{normaliser, ChannelEncoder, ChannelStats, DoublePhaseMethod};
use crate::error::{invalid, HoloError, Result};
use crate::model::contract::{self, head_to_phasor};
use crate::model::{
    CnnLayout, HologramModel, ModelConfig, ModelKind, ModelPlan, PlanReport, PlanRequest,
    Precision, ThreadCount,
};
use crate::optics::{Carrier, OpticalSetup, PropagationOptions, Scratch, SpectralPlan};
use crate::scene::{LayeredDepthImage, RgbdFrame};
use crate::slm::{DisplayCalibration, LutRepresentation, PhaseLut};

/// Where a [`HologramSession`] computes its frames.
///
/// - [`Backend::Cpu`]: tract for the CNNs and rustfft for the optics (the reference).
/// - [`Backend::Gpu`]: the whole frame in WGSL compute shaders through wgpu (Metal on iOS, Vulkan on Android
///   and Linux; cargo feature `gpu`, [`crate::gpu`]), any adapter including a software one. Session creation
///   fails with [`HoloError::Gpu`] where there is none.
/// - [`Backend::Auto`] (the default): the GPU where a hardware adapter exists, the session can be built on it
///   and its first frame passes a self-check against the CPU path; otherwise the CPU. The reason is logged and
///   kept in [`HologramSession::backend_report`].
///
/// With [`Backend::Gpu`] or [`Backend::Auto`], a GPU failure mid-stream (a lost device) re-renders that frame
/// on the CPU and keeps the CPU for later frames: no frame is lost.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Backend {
    /// The GPU when it is there and agrees with the CPU on the first frame, else the CPU.
    #[default]
    Auto,
    /// Always the CPU.
    Cpu,
    /// Always the GPU (an error at session creation without one).
    Gpu,
}

impl Backend {
    /// Short name: `auto`, `cpu`, `gpu`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Cpu => "cpu",
            Self::Gpu => "gpu",
        }
    }
}

impl std::fmt::Display for Backend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Backend {
    type Err = HoloError;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "auto" => Ok(Self::Auto),
            "cpu" => Ok(Self::Cpu),
            "gpu" => Ok(Self::Gpu),
            _ => Err(invalid(
                "backend",
                format!("expected auto, cpu or gpu, got {s:?}"),
            )),
        }
    }
}

/// The arithmetic of the GPU backend's CNNs ([`Backend::Gpu`]; `crate::gpu::cnn`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum GpuPrecision {
    /// [`GpuPrecision::F16`] where the adapter has `SHADER_F16`, else [`GpuPrecision::F32`] (the default;
    /// [`Backend::Auto`]'s first-frame self-check guards the accuracy either way).
    #[default]
    Auto,
    /// f32 storage and arithmetic (within 3e-7 of tract's f32 on lavapipe).
    F32,
    /// Hidden activations stored as f16 (half the memory and traffic), products in f16, sums in f32; the
    /// network's input and output stay f32. Needs the device's `SHADER_F16` (f32 without it). Within 5.1e-4
    /// of tract's f32 on lavapipe (docs/GPU.md).
    F16,
}

impl GpuPrecision {
    /// `"auto"`, `"f32"` or `"f16"`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::F32 => "f32",
            Self::F16 => "f16",
        }
    }

    /// What runs on an adapter with (`shader_f16`) or without f16 shaders: [`GpuPrecision::F32`] or
    /// [`GpuPrecision::F16`].
    pub fn resolve(self, shader_f16: bool) -> Self {
        match self {
            Self::F16 | Self::Auto if shader_f16 => Self::F16,
            _ => Self::F32,
        }
    }
}

/// Display and encoding settings of a [`HologramPipeline`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct PipelineConfig {
    /// Wavelengths, pixel pitch and volume depth (must match the models' metadata).
    pub optics: OpticalSetup,
    /// Angular spectrum options of the offset propagation.
    pub options: PropagationOptions,
    /// Signed distance `s` in metres from the midpoint plane to the SLM (Eq. 6; the paper uses 0, 6e-3 and
    /// 12e-3). A pre-filter CNN, if given, must be trained for this offset.
    pub offset_m: f64,
    /// Double phase method used *without* a pre-filter CNN (with one, DDPM encodes with plain Eq. 7).
    pub encoding: DoublePhaseMethod,
    /// Memory layout tract runs the hologram CNN in ([`CnnLayout`]; results agree to float rounding);
    /// [`CnnLayout::Auto`] (the default) times both at session creation and keeps the faster. The
    /// pre-filter CNN always runs channels-first: with its 8 filters the channels-last matrix product has
    /// only 8 rows, and it measured 2.1× slower (`holo bench --skip-cnn --layout nchw,nhwc`, 384², 1
    /// thread: 89 ms against 42 ms); tract 0.23 cannot move its graph channels-last anyway.
    pub cnn_layout: CnnLayout,
    /// Threads of the CNNs' matrix products ([`ThreadCount::Auto`], the default, times 1, half and all
    /// cores at session creation). The three colours of the optics always run on their own three threads.
    pub cnn_threads: ThreadCount,
    /// Where sessions compute their frames ([`Backend`]; default [`Backend::Auto`]).
    pub backend: Backend,
    /// The GPU CNNs' arithmetic (default [`GpuPrecision::Auto`]: f16 where the adapter has it); f16 falls back
    /// to f32 on an adapter without `SHADER_F16` (the backend report says so).
    pub gpu_precision: GpuPrecision,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            optics: OpticalSetup::default(),
            options: PropagationOptions::default(),
            offset_m: 0.0,
            encoding: DoublePhaseMethod::default(),
            cnn_layout: CnnLayout::default(),
            cnn_threads: ThreadCount::default(),
            backend: Backend::default(),
            gpu_precision: GpuPrecision::default(),
        }
    }
}

/// Whether the DDPM pre-filter CNN runs between offset propagation and double phase encoding (paper Eq. 6),
/// chosen by name ([`HologramPipeline::with_shipped_prefilter`] has the rule).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum PrefilterMode {
    /// The shipped pre-filter where one exists for the offset and was trained with this CNN depth.
    #[default]
    Auto,
    /// Never: encode with the configured double phase method (AA-DPM by default).
    Off,
    /// Always the shipped pre-filter of the offset; an error where none is shipped.
    Required,
}

impl PrefilterMode {
    /// Short name: `auto`, `off`, `required`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Off => "off",
            Self::Required => "required",
        }
    }
}

/// The shipped CNNs by name ([`HologramPipeline::embedded`]). `Default`: 8 layers, f32, pre-filter
/// [`PrefilterMode::Auto`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
pub struct ModelSelection {
    /// Hologram CNN depth: 8, 15 or 30 convolution layers.
    pub layers: usize,
    /// Weight format of both CNNs.
    pub precision: Precision,
    /// Whether the DDPM pre-filter CNN runs.
    pub prefilter: PrefilterMode,
}

impl Default for ModelSelection {
    fn default() -> Self {
        Self {
            layers: 8,
            precision: Precision::F32,
            prefilter: PrefilterMode::Auto,
        }
    }
}

/// The rule of [`HologramPipeline::with_shipped_prefilter`]: the pre-filter to run (if any) and why.
fn shipped_prefilter(
    hologram: &HologramModel,
    mode: PrefilterMode,
    precision: Precision,
    config: &PipelineConfig,
) -> Result<(Option<HologramModel>, String)> {
    let mm = config.offset_m * 1e3;
    if mode == PrefilterMode::Off {
        return Ok((None, "pre-filter off".into()));
    }
    if config.offset_m == 0.0 {
        return match mode {
            PrefilterMode::Required => Err(invalid(
                "prefilter",
                "a pre-filter CNN belongs to a non-zero SLM offset (DDPM, Eq. 6); none exists at 0 mm",
            )),
            _ => Ok((None, "no pre-filter at a 0 mm offset".into())),
        };
    }
    #[cfg(feature = "embedded-models")]
    {
        use crate::model::embedded::{prefilter_model, PREFILTER_OFFSETS_MM};
        let shipped = PREFILTER_OFFSETS_MM
            .into_iter()
            .find(|&o| (o as f64 - mm).abs() < 1e-6);
        let Some(offset_mm) = shipped else {
            return match mode {
                PrefilterMode::Required => Err(invalid(
                    "prefilter",
                    format!(
                        "no shipped pre-filter CNN for a {mm} mm offset (shipped: {PREFILTER_OFFSETS_MM:?} \
                         mm); use one of those offsets, or the pre-filter off"
                    ),
                )),
                _ => Ok((
                    None,
                    format!("no shipped pre-filter for {mm} mm (shipped: {PREFILTER_OFFSETS_MM:?} mm)"),
                )),
            };
        };
        let expected = ModelConfig {
            optics: config.optics,
            offset_m: config.offset_m,
            input_layers: hologram.metadata().input_layers,
        };
        let p = prefilter_model(offset_mm, precision, &expected)?;
        let layers = hologram.metadata().layers;
        let trained = p.metadata().hologram_layers;
        if mode == PrefilterMode::Required || trained == Some(layers) {
            let why = format!(
                "shipped {offset_mm} mm pre-filter ({}, trained with the {} hologram CNN)",
                if mode == PrefilterMode::Required {
                    "required"
                } else {
                    "auto"
                },
                trained.map_or("unknown".to_string(), |l| format!("{l}-layer"))
            );
            return Ok((Some(p), why));
        }
        Ok((
            None,
            format!(
                "the shipped {offset_mm} mm pre-filter was trained with the {} hologram CNN, this one has \
                 {layers} layers: encoding without it (require it to force it)",
                trained.map_or("unknown".to_string(), |l| format!("{l}-layer"))
            ),
        ))
    }
    #[cfg(not(feature = "embedded-models"))]
    {
        let _ = (hologram, precision);
        match mode {
            PrefilterMode::Required => Err(invalid(
                "prefilter",
                "this build has no embedded models (feature `embedded-models`); pass a pre-filter file",
            )),
            _ => Ok((None, format!("no embedded pre-filter in this build ({mm} mm)"))),
        }
    }
}

/// The loaded CNNs plus their configuration: a factory of [`HologramSession`]s.
#[derive(Debug, Clone)]
pub struct HologramPipeline {
    config: PipelineConfig,
    hologram: Arc<HologramModel>,
    prefilter: Option<Arc<HologramModel>>,
    /// Why the pipeline runs (or does not run) a pre-filter CNN, for logs and reports.
    prefilter_reason: String,
    /// The display calibration sessions apply ([`HologramPipeline::with_calibration`]); `None`: an ideal SLM.
    calibration: Option<Arc<DisplayCalibration>>,
    /// The app's own GPU context ([`HologramPipeline::with_gpu_context`]); `None`: the shared one.
    #[cfg(feature = "gpu")]
    gpu_context: Option<crate::gpu::GpuContext>,
}

impl HologramPipeline {
    /// Combines a hologram CNN with an optional pre-filter CNN (DDPM) under `config`.
    ///
    /// Errors: [`HoloError::InvalidParameter`] for an invalid setup or offset, a pre-filter with a 0 m offset,
    /// or models of the wrong kind; [`HoloError::ModelMetadata`] if a model's metadata does not match
    /// `config` (optics; the pre-filter's offset).
    pub fn new(
        hologram: Arc<HologramModel>,
        prefilter: Option<Arc<HologramModel>>,
        config: PipelineConfig,
    ) -> Result<Self> {
        config.optics.validate()?;
        if !config.offset_m.is_finite() {
            return Err(invalid("offset_m", "must be finite"));
        }
        let expected = ModelConfig {
            optics: config.optics,
            offset_m: config.offset_m,
            input_layers: hologram.metadata().input_layers,
        };
        hologram.metadata().check(ModelKind::Hologram, &expected)?;
        if let Some(p) = &prefilter {
            if config.offset_m == 0.0 {
                return Err(invalid(
                    "prefilter",
                    "a pre-filter CNN belongs to a non-zero SLM offset (DDPM, Eq. 6); none is used at 0 m",
                ));
            }
            p.metadata().check(ModelKind::PreFilter, &expected)?;
        }
        let prefilter_reason = if prefilter.is_some() {
            "pre-filter CNN given by the caller"
        } else if config.offset_m == 0.0 {
            "no pre-filter at a 0 mm offset"
        } else {
            "no pre-filter CNN given"
        }
        .to_string();
        Ok(Self {
            config,
            hologram,
            prefilter,
            prefilter_reason,
            calibration: None,
            #[cfg(feature = "gpu")]
            gpu_context: None,
        })
    }

    /// The shipped models (`models/`, feature `embedded-models`) chosen by name: the RGB-D hologram CNN with
    /// `selection.layers` ∈ {8, 15, 30} layers in `selection.precision`, and the DDPM pre-filter CNN of
    /// `config.offset_m` as `selection.prefilter` says ([`HologramPipeline::with_shipped_prefilter`]).
    ///
    /// Errors: [`HoloError::InvalidParameter`] for a layer count or (with [`PrefilterMode::Required`]) an
    /// offset without a shipped model; as [`HologramModel::from_bytes`] and [`HologramPipeline::new`].
    #[cfg(feature = "embedded-models")]
    pub fn embedded(selection: &ModelSelection, config: PipelineConfig) -> Result<Self> {
        let expected = ModelConfig {
            optics: config.optics,
            offset_m: config.offset_m,
            input_layers: 1,
        };
        let hologram = crate::model::embedded::hologram_model(
            selection.layers,
            selection.precision,
            &expected,
        )?;
        Self::with_shipped_prefilter(
            Arc::new(hologram),
            selection.prefilter,
            selection.precision,
            config,
        )
    }

    /// Combines `hologram` with the shipped pre-filter CNN of `config.offset_m` (in `precision`) as `mode`
    /// says; the rule the CLI and the bindings share:
    /// - [`PrefilterMode::Off`], or a 0 m offset: none (encoding with `config.encoding`);
    /// - [`PrefilterMode::Required`]: the shipped pre-filter of the offset (6 or 12 mm), whatever the CNN;
    /// - [`PrefilterMode::Auto`]: the shipped pre-filter of the offset only where one exists and it was trained
    ///   on holograms of a CNN of this depth (`tensorholo.hologram_layers`): the shipped pre-filters display
    ///   1.2 dB above AA-DPM with the 8-layer CNN they were trained with, 0.8 dB above with 15 layers and
    ///   0.3–0.7 dB below with 30 (`models/MODEL_CARD.md`). Otherwise none, and
    ///   [`HologramPipeline::prefilter_reason`] says why.
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
        if !config.offset_m.is_finite() {
            return Err(invalid("offset_m", "must be finite"));
        }
        let (prefilter, reason) = shipped_prefilter(&hologram, mode, precision, &config)?;
        let mut pipeline = Self::new(hologram, prefilter.map(Arc::new), config)?;
        pipeline.prefilter_reason = reason;
        Ok(pipeline)
    }

    /// Why this pipeline runs a pre-filter CNN or not (e.g. "the shipped 6 mm pre-filter was trained with the
    /// 8-layer hologram CNN, this one has 30 layers").
    pub fn prefilter_reason(&self) -> &str {
        &self.prefilter_reason
    }

    /// Runs the GPU backend on `ctx` (e.g. [`crate::gpu::GpuContext::from_device`] with the app's own wgpu
    /// device) instead of the process-wide shared context.
    #[cfg(feature = "gpu")]
    pub fn with_gpu_context(mut self, ctx: crate::gpu::GpuContext) -> Self {
        self.gpu_context = Some(ctx);
        self
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

    /// The display calibration sessions apply, if any.
    pub fn calibration(&self) -> Option<&Arc<DisplayCalibration>> {
        self.calibration.as_ref()
    }

    /// The configuration.
    pub fn config(&self) -> &PipelineConfig {
        &self.config
    }

    /// The hologram CNN.
    pub fn hologram_model(&self) -> &HologramModel {
        &self.hologram
    }

    /// The pre-filter CNN, if any.
    pub fn prefilter_model(&self) -> Option<&HologramModel> {
        self.prefilter.as_deref()
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

    /// Prepares a session for `height × width` frames: optimises the CNNs for that size (cached in the
    /// models), plans the FFTs, computes the offset transfer functions and allocates all buffers, and starts
    /// three colour worker threads.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`size`) for a size of 0 or above
    /// [`crate::generator::MAX_HOLOGRAM_PIXELS`], checked first; as [`HologramModel::plan`],
    /// [`SpectralPlan::new`] and [`ChannelEncoder::new`].
    pub fn session(&self, height: usize, width: usize) -> Result<HologramSession> {
        HologramSession::new(self, height, width)
    }
}

/// Largest wavelength difference (metres) between a display calibration and the pipeline's optics.
const CALIBRATION_WAVELENGTH_TOLERANCE_M: f64 = 1e-9;

/// Refuses a calibration measured at other wavelengths than the display's `wavelengths_m` (R, G, B; more
/// than 1 nm apart).
fn check_calibration_wavelengths(cal: &DisplayCalibration, wavelengths_m: &[f64; 3]) -> Result<()> {
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

/// Colour `c`'s look-up table in `cal`, or `None` where the linear table of the double phase encoder
/// already gives its codes.
fn calibrated_lut(cal: Option<&Arc<DisplayCalibration>>, c: usize) -> Option<&PhaseLut> {
    let lut = &cal?.colours.get(c)?.lut;
    (!matches!(lut.representation(), LutRepresentation::Linear)).then_some(lut)
}

/// The CNN heads of the midpoint hologram, `[3, H, W]` each: amplitude in `[0, √2]`, phase in `[0, 1]`
/// meaning `(p − 0.5)·2π` rad (`docs/CONVENTIONS.md` §7.1).
#[derive(Debug, Clone, PartialEq)]
pub struct Heads {
    /// Amplitude head `[3, H, W]`.
    pub amplitude: Array3<f32>,
    /// Phase head `[3, H, W]`.
    pub phase: Array3<f32>,
}

impl Heads {
    /// The complex midpoint hologram `[3, H, W]` (R, G, B): `A·e^{i(p − 0.5)2π}`
    /// ([`contract::heads_to_field`]).
    ///
    /// Errors: [`HoloError::ShapeMismatch`] if the two heads differ in shape.
    pub fn to_field(&self) -> Result<Array3<Complex32>> {
        contract::heads_to_field(self.amplitude.view(), self.phase.view())
    }
}

/// Wall-clock seconds of each stage of one frame.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct FrameTimings {
    /// Hologram CNN (input packing + tract).
    pub cnn_s: f64,
    /// Heads → field and offset propagation (Eq. 6), colours in parallel.
    pub offset_s: f64,
    /// Pre-filter CNN (0 without one).
    pub prefilter_s: f64,
    /// Double phase encoding (with its pre-filter, if any) and the look-up table, colours in parallel.
    pub encoding_s: f64,
    /// On the GPU backend: the GPU's whole frame (both CNNs and the optics in one submission, with the
    /// downloads); the stage fields above are then 0 but `cnn_s`, which holds the input packing on the CPU.
    /// `holo bench --backend gpu` times the GPU stages one by one. 0 on the CPU backend.
    pub gpu_s: f64,
    /// The whole frame (in a stream: from the end of the previous frame, i.e. the frame period).
    pub total_s: f64,
}

/// One frame's SLM patterns, owned by the session and overwritten by the next frame.
#[derive(Debug, Clone)]
pub struct SlmFrame {
    /// 8-bit SLM codes `[3, H, W]` (R, G, B; one plane per laser, field-sequential), through the display
    /// calibration's look-up tables ([`HologramPipeline::with_calibration`]; the linear one without).
    pub codes: Array3<u8>,
    /// The double phase pattern `[3, H, W]` in radians, `[0, 2π)`.
    pub phase: Array3<f32>,
    /// The global amplitude normaliser `a` of Eq. 7 (see [`crate::encoding::DoublePhase`]).
    pub amplitude_scale: f32,
    /// Per-channel mean phase removed before encoding (radians).
    pub mean_phase: [f32; 3],
    /// Stage timings.
    pub timings: FrameTimings,
    /// Which backend computed this frame: [`Backend::Cpu`] or [`Backend::Gpu`].
    pub backend: Backend,
}

/// Which backend a [`HologramSession`] runs and why ([`HologramSession::backend_report`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BackendReport {
    /// What the configuration asked for.
    pub requested: Backend,
    /// What runs the frames now: [`Backend::Cpu`] or [`Backend::Gpu`].
    pub active: Backend,
    /// Why, in words (e.g. "no hardware GPU adapter: …", "self-check passed", "GPU failed mid-stream: …").
    pub reason: String,
    /// The GPU adapter, "name (api, type)", where one was used or tried.
    pub adapter: Option<String>,
    /// The GPU CNNs' arithmetic ("f32" or "f16"), where the GPU runs.
    pub gpu_precision: Option<String>,
    /// The first frame's comparison of the GPU against the CPU ([`Backend::Auto`] only).
    pub self_check: Option<SelfCheck>,
}

/// The first-frame comparison of [`Backend::Auto`]: the GPU's SLM codes against the CPU's for the same frame.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SelfCheck {
    /// Codes compared (`3·H·W`).
    pub codes: usize,
    /// Codes whose cyclic difference exceeds 1 (one LUT step, a rounding tie or float rounding).
    pub codes_off_by_more_than_one: usize,
    /// Largest cyclic code difference.
    pub max_code_difference: u8,
    /// Whether the GPU is kept: at most [`SELF_CHECK_MAX_FRACTION`] of the codes off by more than one.
    pub passed: bool,
}

/// The largest fraction of SLM codes that may differ from the CPU's by more than one step in the self-check of
/// [`Backend::Auto`] (f32 GPUs measure below 1e-3 on real frames, docs/GPU.md).
pub const SELF_CHECK_MAX_FRACTION: f64 = 0.01;

impl SelfCheck {
    /// Compares two code planes of the same shape.
    pub fn compare(gpu: &Array3<u8>, cpu: &Array3<u8>) -> Self {
        let mut off = 0;
        let mut max = 0u8;
        for (&g, &c) in gpu.iter().zip(cpu.iter()) {
            let d = g.wrapping_sub(c).min(c.wrapping_sub(g));
            max = max.max(d);
            if d > 1 {
                off += 1;
            }
        }
        let codes = cpu.len();
        Self {
            codes,
            codes_off_by_more_than_one: off,
            max_code_difference: max,
            passed: gpu.shape() == cpu.shape()
                && (off as f64) <= SELF_CHECK_MAX_FRACTION * codes as f64,
        }
    }
}

/// What a colour worker does next (see [`ColourState::run`]).
#[derive(Debug, Clone, Copy)]
enum Task {
    /// Heads → field, offset propagation, then the pre-filter input or pass 1 of the encoding.
    Midpoint { prefilter: bool },
    /// Pre-filter output `(Re, Im)` → field, then pass 1 of the encoding.
    Filtered,
    /// Pass 2 of the encoding and the LUT.
    Encode {
        mean_phase: f32,
        amplitude_scale: f32,
    },
}

/// Everything one colour channel reuses between frames.
#[derive(Debug)]
struct ColourState {
    /// Two real planes of this colour (`[H, W]`), written by the session: the midpoint heads (amplitude,
    /// phase) before [`Task::Midpoint`]; with a pre-filter, `(Re H, Im H)` of the offset hologram after it
    /// (the pre-filter's input) and the pre-filter's output `(Re H', Im H')` before [`Task::Filtered`].
    planes: [Vec<f32>; 2],
    field: Vec<Complex32>,
    plan: SpectralPlan,
    /// Offset transfer function with the carrier removed (Eq. 6); `None` at 0 m.
    transfer: Option<Vec<Complex32>>,
    scratch: Scratch,
    encoder: ChannelEncoder,
    phase: Vec<f32>,
    codes: Vec<u8>,
    stats: ChannelStats,
    /// This colour (0 = R) and the session's `(height, width)`.
    colour: usize,
    size: (usize, usize),
    /// The display calibration whose look-up table turns `phase` into `codes` (`None`: linear).
    calibration: Option<Arc<DisplayCalibration>>,
}

impl ColourState {
    fn run(&mut self, task: Task) -> Result<()> {
        match task {
            Task::Midpoint { prefilter } => {
                self.heads_to_field();
                if let Some(t) = &self.transfer {
                    self.plan.apply(&mut self.field, t, &mut self.scratch)?;
                }
                if prefilter {
                    // Pre-filter input (docs/CONVENTIONS.md §7.2, format 2): Re H and Im H, into the two
                    // planes.
                    let [re, im] = &mut self.planes;
                    for ((r, i), v) in re.iter_mut().zip(im.iter_mut()).zip(&self.field) {
                        *r = v.re;
                        *i = v.im;
                    }
                } else {
                    self.stats = self.encoder.analyse(&mut self.field, &mut self.phase)?;
                }
                Ok(())
            }
            Task::Filtered => {
                let [re, im] = &self.planes;
                for ((f, &r), &i) in self.field.iter_mut().zip(re).zip(im) {
                    *f = Complex32::new(r, i);
                }
                self.stats = self.encoder.analyse(&mut self.field, &mut self.phase)?;
                Ok(())
            }
            Task::Encode {
                mean_phase,
                amplitude_scale,
            } => {
                self.encoder.encode(
                    &self.field,
                    &mut self.phase,
                    &mut self.codes,
                    mean_phase,
                    amplitude_scale,
                )?;
                if let Some(lut) = calibrated_lut(self.calibration.as_ref(), self.colour) {
                    let (h, w) = self.size;
                    lut.apply(h, w, &self.phase, &mut self.codes)?;
                }
                Ok(())
            }
        }
    }

    fn heads_to_field(&mut self) {
        let [amp, phs] = &self.planes;
        for ((f, &a), &p) in self.field.iter_mut().zip(amp).zip(phs) {
            *f = head_to_phasor(a, p);
        }
    }
}

/// What a worker hands back: the colour's state and the task's result.
type Reply = (Box<ColourState>, Result<()>);

/// The mailboxes shared by a session and its colour workers, guarded by one mutex.
#[derive(Debug, Default)]
struct Mailboxes {
    /// The task and state waiting for worker `c`.
    tasks: [Option<(Task, Box<ColourState>)>; 3],
    /// What worker `c` handed back.
    replies: [Option<Reply>; 3],
    /// Set when the session drops its workers: the worker loops end.
    closed: bool,
}

#[derive(Debug, Default)]
struct Shared {
    boxes: std::sync::Mutex<Mailboxes>,
    /// Signalled when a task is posted or the workers are closed.
    task_posted: std::sync::Condvar,
    /// Signalled when a reply is posted.
    reply_posted: std::sync::Condvar,
}

impl Shared {
    /// Locks the mailboxes. No code panics while holding the lock (tasks run outside it, under
    /// `catch_unwind`), so a poisoned lock still holds consistent mailboxes.
    fn lock(&self) -> std::sync::MutexGuard<'_, Mailboxes> {
        self.boxes.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// Three persistent threads, one per colour. A task moves a colour's state to its worker and back through
/// fixed mailboxes under a mutex and two condition variables (futex-based: waiting allocates nothing). Neither
/// a rayon pool (whose injector queue allocates a block every 63 jobs submitted from outside the pool) nor
/// `std::sync::mpsc` (whose waker lists allocate the first time a given thread blocks on a channel, so
/// whether the warm-up frame allocates them depends on timing) would keep a frame allocation-free.
#[derive(Debug)]
struct ColourWorkers {
    shared: Arc<Shared>,
    handles: Vec<JoinHandle<()>>,
}

impl ColourWorkers {
    fn start() -> Result<Self> {
        let shared = Arc::new(Shared::default());
        let mut workers = Self {
            shared: shared.clone(),
            handles: Vec::new(),
        };
        for c in 0..3 {
            let shared = shared.clone();
            let handle = std::thread::Builder::new()
                .name(format!("tensorholo-colour-{c}"))
                .spawn(move || Self::worker_loop(c, &shared))
                // Dropping `workers` closes the mailboxes and joins the workers already started.
                .map_err(|e| invalid("threads", format!("cannot start a colour worker: {e}")))?;
            workers.handles.push(handle);
        }
        Ok(workers)
    }

    fn worker_loop(c: usize, shared: &Shared) {
        loop {
            let (task, mut state) = {
                let mut boxes = shared.lock();
                loop {
                    if let Some(job) = boxes.tasks[c].take() {
                        break job;
                    }
                    if boxes.closed {
                        return;
                    }
                    boxes = shared
                        .task_posted
                        .wait(boxes)
                        .unwrap_or_else(|e| e.into_inner());
                }
            };
            let result = catch_unwind(AssertUnwindSafe(|| state.run(task))).unwrap_or_else(|_| {
                Err(HoloError::Internal(format!("colour worker {c} panicked")))
            });
            shared.lock().replies[c] = Some((state, result));
            shared.reply_posted.notify_all();
        }
    }

    /// Runs `task(c)` on each colour's state in parallel; the states come back in colour order. Returns the
    /// first error (in colour order) after all three have come back.
    fn run(
        &self,
        states: &mut [Option<Box<ColourState>>; 3],
        task: impl Fn(usize) -> Task,
    ) -> Result<()> {
        {
            let mut boxes = self.shared.lock();
            if boxes.closed || self.handles.len() != 3 || states.iter().any(Option::is_none) {
                return Err(lost_state());
            }
            for (c, slot) in states.iter_mut().enumerate() {
                let state = slot.take().ok_or_else(lost_state)?;
                boxes.tasks[c] = Some((task(c), state));
            }
        }
        self.shared.task_posted.notify_all();
        let mut boxes = self.shared.lock();
        while boxes.replies.iter().any(Option::is_none) {
            if self.handles.iter().any(|h| h.is_finished()) {
                return Err(lost_state());
            }
            boxes = self
                .shared
                .reply_posted
                .wait(boxes)
                .unwrap_or_else(|e| e.into_inner());
        }
        let mut first_err = None;
        for (slot, reply) in states.iter_mut().zip(boxes.replies.iter_mut()) {
            let (state, result) = reply.take().ok_or_else(lost_state)?;
            *slot = Some(state);
            if let (Err(e), None) = (result, &first_err) {
                first_err = Some(e);
            }
        }
        first_err.map_or(Ok(()), Err)
    }
}

fn lost_state() -> HoloError {
    HoloError::Internal("a colour worker of this session has stopped; create a new session".into())
}

impl Drop for ColourWorkers {
    fn drop(&mut self) {
        self.shared.lock().closed = true;
        self.shared.task_posted.notify_all();
        for h in self.handles.drain(..) {
            let _ = h.join();
        }
    }
}

/// The amplitude at or below which a frame counts as black and is refused
/// ([`HoloError::InvalidData`], [`check_not_black`]): that of sRGB code 1 of 255 (`√(1/255/12.92)` ≈ 0.0175), which
/// the eye cannot tell from 0.
pub const BLACK_FRAME_AMPLITUDE: f32 = 0.0175;

/// Refuses a frame whose brightest amplitude (over every colour, pixel and layer) is at most
/// [`BLACK_FRAME_AMPLITUDE`]: the CNN's output for a black frame is its own bias, not darkness (a 32×32 black
/// frame gives a midpoint hologram of peak amplitude 0.228 with the shipped 8-layer CNN, `sdk/tests/pipeline.rs`), which the double phase
/// encoding's normalisation (Eq. 7) would then show at full brightness.
///
/// Errors: [`HoloError::InvalidData`] saying the frame is black.
pub fn check_not_black(brightest_amplitude: f32) -> Result<()> {
    if brightest_amplitude <= BLACK_FRAME_AMPLITUDE {
        return Err(HoloError::InvalidData(format!(
            "the frame is black (brightest amplitude {brightest_amplitude:.4}, at most sRGB code 1 of 255): \
             there is nothing to display, and the CNN's output for it would be noise shown at full brightness"
        )));
    }
    Ok(())
}

/// Packs frames into the hologram CNN's input and runs it (one per thread in a stream).
#[derive(Debug, Clone)]
struct CnnStage {
    plan: ModelPlan,
    input: Array3<f32>,
    /// The display calibration whose laser intensity scale maps multiply the packed amplitudes.
    calibration: Option<Arc<DisplayCalibration>>,
}

impl CnnStage {
    fn run_frame(&mut self, frame: &RgbdFrame) -> Result<(Heads, f64)> {
        let t = Instant::now();
        self.pack_frame(frame)?;
        self.run(t)
    }

    /// Checks `frame` against the CNN and packs it into `self.input`.
    fn pack_frame(&mut self, frame: &RgbdFrame) -> Result<()> {
        let (c, h, w) = self.plan.input_dim();
        if c != 4 {
            return Err(invalid(
                "frame",
                format!(
                    "this hologram CNN takes a {}-layer LDI, not an RGB-D frame",
                    c / 4
                ),
            ));
        }
        check_size("RGB-D frame", frame.amplitude.dim(), (h, w))?;
        contract::pack_rgbd(frame, self.input.view_mut())?;
        self.scale_intensity();
        self.check_not_black()
    }

    /// Refuses a packed input whose amplitudes (every layer, after the intensity maps) are black
    /// ([`check_not_black`]).
    fn check_not_black(&self) -> Result<()> {
        let mut brightest = 0.0f32;
        for (i, plane) in self.input.outer_iter().enumerate() {
            if i % 4 != 3 {
                brightest = plane.iter().fold(brightest, |m, &a| m.max(a));
            }
        }
        check_not_black(brightest)
    }

    /// Multiplies each layer's colour-`c` amplitude by the calibration's intensity scale map of colour `c`
    /// (where it has one): the target the CNN sees is what the unevenly lit display can show.
    fn scale_intensity(&mut self) {
        let Some(cal) = &self.calibration else {
            return;
        };
        let layers = self.input.dim().0 / 4;
        for (c, col) in cal.colours.iter().enumerate() {
            let Some(scale) = &col.intensity_scale else {
                continue;
            };
            for k in 0..layers {
                // Invalid LDI points hold amplitude 0, which stays 0.
                let mut plane = self.input.index_axis_mut(Axis(0), 4 * k + c);
                plane.zip_mut_with(scale, |a, &s| *a *= s);
            }
        }
    }

    fn run_ldi(&mut self, ldi: &LayeredDepthImage) -> Result<(Heads, f64)> {
        let t = Instant::now();
        self.pack_ldi(ldi)?;
        self.run(t)
    }

    /// Checks `ldi` against the CNN and packs it into `self.input`.
    fn pack_ldi(&mut self, ldi: &LayeredDepthImage) -> Result<()> {
        let (c, h, w) = self.plan.input_dim();
        let want = c / 4;
        if ldi.num_layers() != want {
            return Err(invalid(
                "ldi",
                format!(
                    "this hologram CNN takes {want} layer(s), the LDI has {}",
                    ldi.num_layers()
                ),
            ));
        }
        check_size("LDI", (3, ldi.height(), ldi.width()), (h, w))?;
        contract::pack_ldi(ldi, self.input.view_mut())?;
        self.scale_intensity();
        self.check_not_black()
    }

    fn run(&mut self, t: Instant) -> Result<(Heads, f64)> {
        let (amplitude, phase) = self.plan.run_outputs(self.input.view())?;
        Ok((Heads { amplitude, phase }, t.elapsed().as_secs_f64()))
    }
}

fn check_size(what: &str, got: (usize, usize, usize), want: (usize, usize)) -> Result<()> {
    if (got.1, got.2) != want {
        return Err(HoloError::ShapeMismatch {
            what: format!("{what} vs the session's [H, W]"),
            expected: vec![want.0, want.1],
            got: vec![got.1, got.2],
        });
    }
    Ok(())
}

/// A hologram session for one resolution (see the [module docs](self)). Not `Sync`: one frame at a time;
/// a failed frame (wrong size, NaN) leaves the session usable.
#[derive(Debug)]
pub struct HologramSession {
    height: usize,
    width: usize,
    encoding: DoublePhaseMethod,
    offset_m: f64,
    cnn: CnnStage,
    prefilter: Option<ModelPlan>,
    prefilter_input: Array3<f32>,
    states: [Option<Box<ColourState>>; 3],
    workers: ColourWorkers,
    output: SlmFrame,
    last_heads: Option<Heads>,
    plan_report: PlanReport,
    backend: BackendReport,
    full_outputs: bool,
    /// The display calibration applied (look-up tables, intensity scale maps), and the wavelengths it must
    /// match.
    calibration: Option<Arc<DisplayCalibration>>,
    wavelengths_m: [f64; 3],
    /// The GPU frame while the GPU backend is active; `pending_check`: the self-check of [`Backend::Auto`]
    /// has yet to run.
    #[cfg(feature = "gpu")]
    gpu: Option<GpuState>,
}

#[cfg(feature = "gpu")]
#[derive(Debug)]
struct GpuState {
    frame: crate::gpu::session::GpuFrameSession,
    pending_check: bool,
}

/// Builds the GPU frame of `pipeline` when its backend asks for one: `(state, report)`.
fn choose_backend(
    pipeline: &HologramPipeline,
    height: usize,
    width: usize,
) -> Result<(BackendReportParts, Option<GpuSlot>)> {
    let requested = pipeline.config.backend;
    let cpu = |reason: String| BackendReportParts {
        requested,
        reason,
        adapter: None,
        gpu_precision: None,
    };
    if requested == Backend::Cpu {
        return Ok((cpu("CPU requested".into()), None));
    }
    #[cfg(not(feature = "gpu"))]
    {
        let _ = (height, width);
        if requested == Backend::Gpu {
            return Err(invalid(
                "backend",
                "this build has no GPU path (cargo feature `gpu` of tensorholo)",
            ));
        }
        Ok((
            cpu("this build has no GPU path (cargo feature `gpu`)".into()),
            None,
        ))
    }
    #[cfg(feature = "gpu")]
    {
        use crate::gpu::session::GpuFrameSession;
        use crate::gpu::{GpuContext, GpuOptions};
        let ctx = match &pipeline.gpu_context {
            Some(ctx) => Ok(ctx.clone()),
            None => GpuContext::shared(&GpuOptions {
                allow_software: requested == Backend::Gpu,
                name_contains: None,
            }),
        };
        let ctx = match (ctx, requested) {
            (Ok(ctx), _) => ctx,
            (Err(e), Backend::Gpu) => return Err(e),
            (Err(e), _) => return Ok((cpu(format!("no hardware GPU: {e}")), None)),
        };
        let info = ctx.info();
        let adapter = Some(format!(
            "{} ({}, {})",
            info.name, info.backend, info.device_type
        ));
        let wanted = pipeline.config.gpu_precision;
        let (precision, note) = if wanted == GpuPrecision::F16 && !info.shader_f16 {
            (
                GpuPrecision::F32,
                " (f16 asked, but the adapter has no SHADER_F16: f32)",
            )
        } else {
            (wanted, "")
        };
        match GpuFrameSession::new(&ctx, pipeline, height, width, precision) {
            Ok(frame) => Ok((
                BackendReportParts {
                    requested,
                    reason: if requested == Backend::Gpu {
                        format!("GPU requested{note}")
                    } else {
                        format!("GPU adapter found; first-frame self-check pending{note}")
                    },
                    adapter,
                    gpu_precision: Some(precision.name().into()),
                },
                Some(GpuState {
                    frame,
                    pending_check: requested == Backend::Auto,
                }),
            )),
            Err(e) if requested == Backend::Gpu => Err(e),
            Err(e) => {
                log::info!("GPU backend unavailable for {height}×{width}, using the CPU: {e}");
                Ok((
                    BackendReportParts {
                        adapter,
                        ..cpu(format!("the GPU path cannot run this session: {e}"))
                    },
                    None,
                ))
            }
        }
    }
}

#[cfg(feature = "gpu")]
type GpuSlot = GpuState;
#[cfg(not(feature = "gpu"))]
type GpuSlot = std::convert::Infallible;

/// A [`BackendReport`] before the session knows what runs.
struct BackendReportParts {
    requested: Backend,
    reason: String,
    adapter: Option<String>,
    gpu_precision: Option<String>,
}

impl HologramSession {
    fn new(pipeline: &HologramPipeline, height: usize, width: usize) -> Result<Self> {
        // Before any allocation: a session holds several [3, H, W] complex fields and the CNN's activations.
        if height == 0
            || width == 0
            || height.saturating_mul(width) > crate::generator::MAX_HOLOGRAM_PIXELS
        {
            return Err(invalid(
                "size",
                format!(
                    "{height}×{width}: a session needs 1 to {} pixels (8192×8192)",
                    crate::generator::MAX_HOLOGRAM_PIXELS
                ),
            ));
        }
        let calibration = pipeline.calibration.clone();
        if let Some(cal) = &calibration {
            cal.check_size(height, width)?;
        }
        let (parts, gpu) = choose_backend(pipeline, height, width)?;
        let backend = BackendReport {
            requested: parts.requested,
            active: if gpu.is_some() {
                Backend::Gpu
            } else {
                Backend::Cpu
            },
            reason: parts.reason,
            adapter: parts.adapter,
            gpu_precision: if gpu.is_some() {
                parts.gpu_precision
            } else {
                None
            },
            self_check: None,
        };
        log::info!(
            "backend for {height}×{width}: {} ({})",
            backend.active,
            backend.reason
        );
        #[cfg(not(feature = "gpu"))]
        let _ = gpu;
        let request = PlanRequest {
            layout: pipeline.config.cnn_layout,
            threads: pipeline.config.cnn_threads,
        };
        let (hologram, plan_report) = pipeline.hologram.tuned_plan(height, width, request)?;
        let prefilter = match &pipeline.prefilter {
            Some(p) => {
                let plan = p.plan(height, width)?;
                Some(match plan_report.threads {
                    Some(t) => plan.with_threads(t)?,
                    None => plan,
                })
            }
            None => None,
        };
        let cfg = &pipeline.config;
        let encoding = pipeline.encoding();
        let props = cfg.optics.propagators(height, width, cfg.options)?;
        let n = height * width;
        let mut states: [Option<Box<ColourState>>; 3] = [None, None, None];
        for (colour, (slot, prop)) in states.iter_mut().zip(&props).enumerate() {
            let transfer = if cfg.offset_m != 0.0 {
                Some(
                    prop.transfer_function(cfg.offset_m, Carrier::Remove)?
                        .values()
                        .to_vec(),
                )
            } else {
                None
            };
            *slot = Some(Box::new(ColourState {
                planes: [vec![0.0; n], vec![0.0; n]],
                field: vec![Complex32::default(); n],
                plan: prop.plan().clone(),
                transfer,
                scratch: prop.plan().scratch(),
                encoder: ChannelEncoder::new(height, width, encoding)?,
                phase: vec![0.0; n],
                codes: vec![0; n],
                stats: ChannelStats::default(),
                colour,
                size: (height, width),
                calibration: calibration.clone(),
            }));
        }
        let (c, _, _) = hologram.input_dim();
        Ok(Self {
            height,
            width,
            encoding,
            offset_m: cfg.offset_m,
            cnn: CnnStage {
                plan: hologram,
                input: Array3::zeros((c, height, width)),
                calibration: calibration.clone(),
            },
            prefilter_input: Array3::zeros((
                if prefilter.is_some() { 6 } else { 0 },
                height,
                width,
            )),
            prefilter,
            states,
            workers: ColourWorkers::start()?,
            output: SlmFrame {
                codes: Array3::zeros((3, height, width)),
                phase: Array3::zeros((3, height, width)),
                amplitude_scale: 0.0,
                mean_phase: [0.0; 3],
                timings: FrameTimings::default(),
                backend: Backend::Cpu,
            },
            last_heads: None,
            plan_report,
            backend,
            full_outputs: true,
            calibration,
            wavelengths_m: cfg.optics.wavelengths_m,
            #[cfg(feature = "gpu")]
            gpu,
        })
    }

    /// Replaces the display calibration of this session's next frames (`None`: an ideal SLM, linear look-up
    /// tables and no intensity scaling), e.g. after recalibrating the bench, without rebuilding the session.
    /// See [`HologramPipeline::with_calibration`].
    ///
    /// Errors: [`HoloError::ShapeMismatch`] if the calibration is for another SLM size;
    /// [`HoloError::InvalidParameter`] if its wavelengths differ from the display's by more than 1 nm. The
    /// session keeps its calibration on error.
    pub fn set_calibration(&mut self, calibration: Option<Arc<DisplayCalibration>>) -> Result<()> {
        if let Some(cal) = &calibration {
            cal.check_size(self.height, self.width)?;
            check_calibration_wavelengths(cal, &self.wavelengths_m)?;
        }
        for slot in &mut self.states {
            slot.as_mut().ok_or_else(lost_state)?.calibration = calibration.clone();
        }
        self.cnn.calibration = calibration.clone();
        self.calibration = calibration;
        Ok(())
    }

    /// The display calibration this session applies, if any.
    pub fn calibration(&self) -> Option<&Arc<DisplayCalibration>> {
        self.calibration.as_ref()
    }

    /// Which backend runs this session's frames, and why ([`Backend`]).
    pub fn backend_report(&self) -> &BackendReport {
        &self.backend
    }

    /// The GPU frame while the GPU backend is active (for `holo bench --backend gpu`: its stages' work and
    /// timings).
    #[cfg(feature = "gpu")]
    pub fn gpu_frame(&self) -> Option<&crate::gpu::session::GpuFrameSession> {
        self.gpu.as_ref().map(|g| &g.frame)
    }

    /// The GPU frame, mutable (for [`crate::gpu::session::GpuFrameSession::preview`]).
    #[cfg(feature = "gpu")]
    pub fn gpu_frame_mut(&mut self) -> Option<&mut crate::gpu::session::GpuFrameSession> {
        self.gpu.as_mut().map(|g| &mut g.frame)
    }

    /// Whether GPU frames also download the double phase pattern ([`SlmFrame::phase`]) and the CNN heads
    /// ([`HologramSession::last_heads`]); on by default. Off, a GPU frame downloads only the codes and the
    /// normaliser (what an SLM needs): `phase` and `last_heads` then keep older values. No effect on the CPU.
    pub fn set_full_outputs(&mut self, full: bool) {
        self.full_outputs = full;
    }

    /// How the hologram CNN's plan was chosen: layout, threads, and the autotuning timings
    /// ([`HologramModel::tuned_plan`]). The pre-filter CNN runs channels-first with the same threads.
    pub fn plan_report(&self) -> &PlanReport {
        &self.plan_report
    }

    /// `(height, width)` of this session's frames.
    pub fn size(&self) -> (usize, usize) {
        (self.height, self.width)
    }

    /// The SLM offset `s` in metres.
    pub fn offset_m(&self) -> f64 {
        self.offset_m
    }

    /// The double phase method (plain after a pre-filter CNN).
    pub fn encoding(&self) -> DoublePhaseMethod {
        self.encoding
    }

    /// Whether a pre-filter CNN runs between offset propagation and double phase encoding (DDPM).
    pub fn has_prefilter(&self) -> bool {
        self.prefilter.is_some()
    }

    /// The output of the last successful frame (codes all zero before the first).
    pub fn output(&self) -> &SlmFrame {
        &self.output
    }

    /// The hologram CNN heads of the last successful frame (the midpoint hologram; [`Heads::to_field`]).
    pub fn last_heads(&self) -> Option<&Heads> {
        self.last_heads.as_ref()
    }

    /// Renders one RGB-D frame (`[3, H, W]` amplitude and `[H, W]` normalised depth at the session's size)
    /// into SLM patterns.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for a frame of another size; [`HoloError::InvalidData`] for
    /// non-finite values or a black frame (every amplitude ≤ [`BLACK_FRAME_AMPLITUDE`]: the CNN would
    /// only show its bias); [`HoloError::InvalidParameter`] if the CNN takes an LDI; tract failures
    /// ([`HoloError::ModelRun`]). The session stays usable after an error.
    pub fn render(&mut self, frame: &RgbdFrame) -> Result<&SlmFrame> {
        #[cfg(feature = "gpu")]
        if self.gpu.is_some() {
            let t = Instant::now();
            self.cnn.pack_frame(frame)?;
            return self.render_packed_on_gpu(t);
        }
        let (heads, cnn_s) = self.cnn.run_frame(frame)?;
        self.encode_heads(heads, cnn_s)
    }

    /// The GPU frame of the CNN input packed in `self.cnn.input` (packing started at `t`): runs it on the GPU,
    /// with the first-frame self-check of [`Backend::Auto`]; on a GPU failure, re-renders it on the CPU and
    /// stays there.
    #[cfg(feature = "gpu")]
    fn render_packed_on_gpu(&mut self, t: Instant) -> Result<&SlmFrame> {
        let Some(gpu) = self.gpu.as_mut() else {
            return Err(HoloError::Internal("no GPU state".into()));
        };
        // The CPU path catches NaN/∞ in the CNN's heads; a GPU's max() may silently skip NaN, so check the
        // input here (4 values per pixel, well under a millisecond at 1080p).
        if self.cnn.input.iter().any(|v| !v.is_finite()) {
            return Err(HoloError::InvalidData(
                "the RGB-D frame holds NaN or infinite values".into(),
            ));
        }
        let cnn_s = t.elapsed().as_secs_f64();
        let t_gpu = Instant::now();
        // A calibrated look-up table runs on the CPU, on the downloaded double phase pattern.
        let calibrated = self
            .calibration
            .as_ref()
            .is_some_and(|c| c.has_calibrated_lut());
        let full = self.full_outputs || gpu.pending_check || calibrated;
        match gpu.frame.run(self.cnn.input.view(), &mut self.output, full) {
            Ok(heads) => {
                if calibrated {
                    apply_calibrated_luts(self.calibration.as_ref(), &mut self.output)?;
                }
                let gpu_s = t_gpu.elapsed().as_secs_f64();
                self.output.backend = Backend::Gpu;
                self.output.timings = FrameTimings {
                    cnn_s,
                    gpu_s,
                    total_s: t.elapsed().as_secs_f64(),
                    ..FrameTimings::default()
                };
                if heads.is_some() {
                    self.last_heads = heads;
                }
                if gpu.pending_check {
                    self.self_check()?;
                }
                Ok(&self.output)
            }
            Err(HoloError::Gpu(e)) => {
                log::warn!("GPU frame failed ({e}); this frame and the next run on the CPU");
                self.gpu = None;
                self.backend.active = Backend::Cpu;
                self.backend.gpu_precision = None;
                self.backend.reason = format!("GPU failed mid-stream, CPU since: {e}");
                let (heads, cnn_s) = self.cnn.run(t)?;
                self.encode_heads(heads, cnn_s)
            }
            // Bad data (e.g. a hologram that is zero everywhere) is the frame's fault, not the GPU's.
            Err(e) => Err(e),
        }
    }

    /// The self-check of [`Backend::Auto`] after the GPU rendered the first frame into `self.output`: renders
    /// it on the CPU too, compares the codes ([`SelfCheck`]), and keeps the GPU (and its output) only if they
    /// agree; otherwise the CPU's output stands and the session stays on the CPU.
    #[cfg(feature = "gpu")]
    fn self_check(&mut self) -> Result<()> {
        let gpu_output = self.output.clone();
        let gpu_heads = self.last_heads.take();
        let (heads, cnn_s) = self.cnn.run(Instant::now())?;
        self.encode_heads(heads, cnn_s)?;
        let check = SelfCheck::compare(&gpu_output.codes, &self.output.codes);
        self.backend.self_check = Some(check);
        if check.passed {
            self.backend.reason = format!(
                "GPU self-check passed ({} of {} codes off by more than one step)",
                check.codes_off_by_more_than_one, check.codes
            );
            self.output = gpu_output;
            self.last_heads = gpu_heads;
            if let Some(g) = self.gpu.as_mut() {
                g.pending_check = false;
            }
        } else {
            self.backend.reason = format!(
                "GPU self-check failed ({} of {} codes off by more than one step, max {}): CPU",
                check.codes_off_by_more_than_one, check.codes, check.max_code_difference
            );
            self.backend.active = Backend::Cpu;
            self.backend.gpu_precision = None;
            self.gpu = None;
        }
        log::info!("{}", self.backend.reason);
        Ok(())
    }

    /// Renders a layered depth image (the LDI-input CNN of the paper; layers `[r, g, b, d]` each).
    ///
    /// Errors: as [`HologramSession::render`], and [`HoloError::InvalidParameter`] if the number of layers is
    /// not the CNN's.
    pub fn render_ldi(&mut self, ldi: &LayeredDepthImage) -> Result<&SlmFrame> {
        #[cfg(feature = "gpu")]
        if self.gpu.is_some() {
            let t = Instant::now();
            self.cnn.pack_ldi(ldi)?;
            return self.render_packed_on_gpu(t);
        }
        let (heads, cnn_s) = self.cnn.run_ldi(ldi)?;
        self.encode_heads(heads, cnn_s)
    }

    /// Runs the stages after the hologram CNN on `heads` (midpoint hologram): offset propagation, pre-filter
    /// CNN, double phase encoding and LUT. `cnn_s` is recorded as the CNN time of this frame.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for heads of another size; [`HoloError::InvalidData`] for
    /// non-finite heads or a hologram that is zero everywhere.
    pub fn encode_heads(&mut self, heads: Heads, cnn_s: f64) -> Result<&SlmFrame> {
        let t0 = Instant::now();
        self.propagate_to_slm(&heads)?;
        let offset_s = t0.elapsed().as_secs_f64();
        let t = Instant::now();
        self.run_prefilter()?;
        let prefilter_s = if self.prefilter.is_some() {
            t.elapsed().as_secs_f64()
        } else {
            0.0
        };
        let t = Instant::now();
        self.encode()?;
        let encoding_s = t.elapsed().as_secs_f64();
        self.output.timings = FrameTimings {
            cnn_s,
            offset_s,
            prefilter_s,
            encoding_s,
            gpu_s: 0.0,
            total_s: cnn_s + t0.elapsed().as_secs_f64(),
        };
        self.output.backend = Backend::Cpu;
        self.last_heads = Some(heads);
        Ok(&self.output)
    }

    /// Stage 2 on its own (no heap allocation after the first frame): copies the midpoint `heads` into the
    /// colour states; the workers convert them to the field, propagate it to the SLM (Eq. 6, carrier removed)
    /// and either prepare the pre-filter input or run pass 1 of the double phase encoding. Follow with
    /// [`HologramSession::run_prefilter`] and [`HologramSession::encode`] ([`HologramSession::encode_heads`]
    /// does all three).
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for heads of another size; [`HoloError::InvalidData`] for
    /// non-finite values.
    pub fn propagate_to_slm(&mut self, heads: &Heads) -> Result<()> {
        let want = [3, self.height, self.width];
        for head in [&heads.amplitude, &heads.phase] {
            if head.shape() != want {
                return Err(HoloError::ShapeMismatch {
                    what: "midpoint heads vs the session's [3, H, W]".into(),
                    expected: want.to_vec(),
                    got: head.shape().to_vec(),
                });
            }
        }
        let non_finite = heads
            .amplitude
            .iter()
            .chain(heads.phase.iter())
            .any(|v| !v.is_finite());
        if non_finite {
            return Err(HoloError::InvalidData(
                "midpoint heads hold NaN or infinite values".into(),
            ));
        }
        self.load_planes(heads.amplitude.view(), heads.phase.view())?;
        let prefilter = self.prefilter.is_some();
        self.workers
            .run(&mut self.states, |_| Task::Midpoint { prefilter })
    }

    /// Copies channel `c` of `first` and `second` (`[3, H, W]`) into colour `c`'s two planes.
    fn load_planes(&mut self, first: ArrayView3<f32>, second: ArrayView3<f32>) -> Result<()> {
        for (c, slot) in self.states.iter_mut().enumerate() {
            let st = slot.as_mut().ok_or_else(lost_state)?;
            copy_channel(first, c, &mut st.planes[0]);
            copy_channel(second, c, &mut st.planes[1]);
        }
        Ok(())
    }

    /// Stage 3 on its own: the pre-filter CNN (allocates inside tract), if the session has one: packs
    /// `[Re H, Im H]` of the offset hologram (`docs/CONVENTIONS.md` §7.2, format 2), runs it and lets the
    /// workers turn its outputs `(Re H', Im H')` into the filtered field and run pass 1 of the encoding. A
    /// no-op without a pre-filter.
    ///
    /// Errors: tract failures ([`HoloError::ModelRun`]); call after [`HologramSession::propagate_to_slm`].
    pub fn run_prefilter(&mut self) -> Result<()> {
        let Some(plan) = &self.prefilter else {
            return Ok(());
        };
        for (c, slot) in self.states.iter().enumerate() {
            let st = slot.as_ref().ok_or_else(lost_state)?;
            contract::pack_prefilter_colour(
                c,
                &st.planes[0],
                &st.planes[1],
                self.prefilter_input.view_mut(),
            )?;
        }
        let (real, imag) = plan.run_outputs(self.prefilter_input.view())?;
        self.load_planes(real.view(), imag.view())?;
        self.workers.run(&mut self.states, |_| Task::Filtered)
    }

    /// Stage 4 on its own (no heap allocation after the first frame): the global normaliser, pass 2 of the
    /// double phase encoding (Eq. 7) and the LUT on the workers; the colour planes are copied into
    /// [`HologramSession::output`] (timings are not updated).
    ///
    /// Errors: [`HoloError::InvalidData`] if the hologram is zero everywhere.
    pub fn encode(&mut self) -> Result<&SlmFrame> {
        let mut stats = [ChannelStats::default(); 3];
        for (s, slot) in stats.iter_mut().zip(&self.states) {
            *s = slot.as_ref().ok_or_else(lost_state)?.stats;
        }
        let (a, mean) = normaliser(&stats, self.height * self.width)?;
        self.workers.run(&mut self.states, |c| Task::Encode {
            mean_phase: mean[c],
            amplitude_scale: a,
        })?;
        for (c, slot) in self.states.iter().enumerate() {
            let st = slot.as_ref().ok_or_else(lost_state)?;
            fill_channel(&mut self.output.phase, c, &st.phase);
            fill_channel(&mut self.output.codes, c, &st.codes);
        }
        self.output.amplitude_scale = a;
        self.output.mean_phase = mean;
        Ok(&self.output)
    }

    /// Renders a sequence, overlapping the hologram CNN of frame `n + 1` (on a second thread) with the optics
    /// of frame `n`. `sink(index, frame)` receives each result in order; an error from a frame, the source or
    /// the sink stops the stream and is returned. Outputs equal [`HologramSession::render`]'s bit for bit;
    /// `timings.total_s` is the frame period (time since the previous frame was delivered).
    ///
    /// Errors: the first error of the source, a frame (as [`HologramSession::render`]) or the sink.
    pub fn render_stream<I, F>(&mut self, frames: I, mut sink: F) -> Result<usize>
    where
        I: IntoIterator<Item = Result<RgbdFrame>>,
        I::IntoIter: Send,
        F: FnMut(usize, &SlmFrame) -> Result<()>,
    {
        let tagged = frames.into_iter().enumerate();
        self.render_stream_each(tagged, |i, out| sink(i, out?))
    }

    /// As [`HologramSession::render_stream`], but a failed frame does not stop the stream: each item of
    /// `frames` is `(tag, frame or error)`, and `sink(tag, result)` receives every item in order, with the
    /// frame's SLM patterns or its error (a conversion error from the source, a CNN or encoding error). Only
    /// an error returned by `sink` stops the stream. The session stays usable after a failed frame.
    ///
    /// Returns the number of items delivered. Errors: the first error `sink` returns.
    pub fn render_stream_each<T, I, F>(&mut self, frames: I, mut sink: F) -> Result<usize>
    where
        T: Send,
        I: IntoIterator<Item = (T, Result<RgbdFrame>)>,
        I::IntoIter: Send,
        F: FnMut(T, Result<&SlmFrame>) -> Result<()>,
    {
        let frames = frames.into_iter();
        #[cfg(feature = "gpu")]
        if self.gpu.is_some() {
            // The GPU runs whole frames; the CPU only packs inputs, so frames go one after another.
            let mut count = 0;
            let mut last = Instant::now();
            for (tag, frame) in frames {
                count += 1;
                match frame.and_then(|f| self.render(&f).map(drop)) {
                    Ok(()) => {
                        let now = Instant::now();
                        self.output.timings.total_s = (now - last).as_secs_f64();
                        last = now;
                        sink(tag, Ok(&self.output))?;
                    }
                    Err(e) => sink(tag, Err(e))?,
                }
            }
            return Ok(count);
        }
        let mut cnn = self.cnn.clone();
        std::thread::scope(|scope| {
            let (tx, rx) = sync_channel::<(T, Result<(Heads, f64)>)>(1);
            scope.spawn(move || {
                for (tag, frame) in frames {
                    let out = frame.and_then(|f| cnn.run_frame(&f));
                    if tx.send((tag, out)).is_err() {
                        break;
                    }
                }
            });
            let mut count = 0;
            let mut last = Instant::now();
            for (tag, item) in rx {
                let encoded =
                    item.and_then(|(heads, cnn_s)| self.encode_heads(heads, cnn_s).map(drop));
                count += 1;
                match encoded {
                    Ok(()) => {
                        let now = Instant::now();
                        self.output.timings.total_s = (now - last).as_secs_f64();
                        last = now;
                        sink(tag, Ok(&self.output))?;
                    }
                    Err(e) => sink(tag, Err(e))?,
                }
            }
            Ok(count)
        })
    }
}

/// Replaces `out.codes` by the calibrated look-up tables' codes of `out.phase` (colours with a linear table
/// keep theirs).
#[cfg(feature = "gpu")]
fn apply_calibrated_luts(cal: Option<&Arc<DisplayCalibration>>, out: &mut SlmFrame) -> Result<()> {
    let (_, h, w) = out.codes.dim();
    for c in 0..3 {
        let Some(lut) = calibrated_lut(cal, c) else {
            continue;
        };
        let phase = out.phase.index_axis(Axis(0), c);
        let mut codes = out.codes.index_axis_mut(Axis(0), c);
        match (phase.as_slice(), codes.as_slice_mut()) {
            (Some(p), Some(k)) => lut.apply(h, w, p, k)?,
            _ => return Err(HoloError::Internal("SLM frame not contiguous".into())),
        }
    }
    Ok(())
}

/// Copies channel `c` of a `[C, H, W]` array into `out` (`H·W` values).
fn copy_channel(a: ArrayView3<f32>, c: usize, out: &mut [f32]) {
    let lane = a.index_axis(Axis(0), c);
    match lane.as_slice() {
        Some(src) => out.copy_from_slice(src),
        None => out.iter_mut().zip(lane.iter()).for_each(|(o, v)| *o = *v),
    }
}

/// Writes `src` (`H·W` values) into channel `c` of a standard-layout `[C, H, W]` array.
fn fill_channel<T: Copy>(a: &mut Array3<T>, c: usize, src: &[T]) {
    let mut lane = a.index_axis_mut(Axis(0), c);
    match lane.as_slice_mut() {
        Some(dst) => dst.copy_from_slice(src),
        None => lane.iter_mut().zip(src).for_each(|(o, v)| *o = *v),
    }
}

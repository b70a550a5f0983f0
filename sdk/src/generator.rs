//! The SDK as a phone app calls it (`docs/CONVENTIONS.md` §7; paper Fig. 3): camera-buffer frames in, SLM
//! patterns out, through one thread-safe [`HologramGenerator`].
//!
//! - [`GeneratorConfig`]: the hologram (SLM) resolution, the shipped CNNs by name ([`ModelSelection`]), the
//!   display and how camera frames fit it. Every field but `width` and `height` has a default.
//! - [`HologramGenerator`]: owns the pipeline and one [`HologramSession`] for the configured resolution
//!   behind a lock (`Send + Sync`: any thread may call it; calls run one at a time). Returns owned
//!   [`SlmPatterns`]; [`HologramGenerator::preview`] simulates what a viewer sees at a chosen depth.
//! - [`HologramStream`]: video. [`HologramStream::push`] never blocks: a bounded queue drops the oldest
//!   frame when full (camera semantics) and counts the drops; a worker thread runs the session's
//!   [`HologramSession::render_stream_each`] (the CNN of frame `n + 1` overlaps the optics of frame `n`) and
//!   hands results to a [`StreamListener`] in frame order. The metric depth range of the first frame is kept
//!   for the whole stream unless the configuration fixes one, so the volume does not breathe.
//!
//! The bindings (`bindings/`, crate `tensorholo-ffi`) are one-line wrappers over this module.

use std::collections::VecDeque;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Instant;

use ndarray::{Array3, ArrayView3, Axis};

use crate::cnn::{
    CnnEngine, CnnLayout, ConvAlgorithm, PlanReport, SavedPlans, ThreadCount, MAX_CNN_THREADS,
};
use crate::color::amplitude_to_srgb8;
use crate::display::DisplayProfile;
use crate::encoding::{DoublePhaseMethod, LinearLut};
use crate::error::{invalid, HoloError, Result};
use crate::model::{HologramModel, ModelConfig, ModelKind, Precision};
use crate::optics::{focal_stack, post_encoding_midpoint, OpticalSetup, PropagationOptions};
use crate::pipeline::{
    Backend, BackendReport, FrameTimings, GpuPrecision, HologramPipeline, HologramSession,
    ModelSelection, PipelineConfig, PrefilterMode, PrefilterSource, SlmFrame,
};
use crate::scene::{
    ldi_from_camera_frames, CameraFrame, CameraFrameBuf, CameraFrameReport, DepthMapping,
    DepthRange, Fit, FrameOptions, RgbdFrame,
};
use crate::slm::DisplayCalibration;

/// The largest hologram a generator makes: the session's limit, now [`crate::pipeline::MAX_HOLOGRAM_PIXELS`]
/// (this path is kept for one release).
pub use crate::pipeline::MAX_HOLOGRAM_PIXELS;
/// The default capacity of a [`HologramStream`]'s queue: one frame waiting while one is converted and one
/// runs through the CNN.
pub const DEFAULT_STREAM_CAPACITY: usize = 2;

/// Everything a [`HologramGenerator`] needs. Build with [`GeneratorConfig::new`] and change the fields
/// you need; [`GeneratorConfig::validate`] says what is wrong.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct GeneratorConfig {
    /// Hologram (SLM) width in pixels.
    pub width: usize,
    /// Hologram (SLM) height in pixels.
    pub height: usize,
    /// The shipped CNNs: RGB-D or LDI input, layers 8/15/30, precision, pre-filter Auto/Off/Required
    /// (default RGB-D, 8, f32, Auto).
    pub models: ModelSelection,
    /// Distance `s` from the midpoint hologram to the SLM in metres (Eq. 6; default 6e-3; shipped
    /// pre-filters exist for 6e-3 and 12e-3).
    pub offset_m: f64,
    /// CNN threads ([`ThreadCount::Auto`] by default: the cores the CPU reports).
    pub threads: ThreadCount,
    /// CNN memory layout of tract ([`CnnLayout::Auto`] by default: the plan table's).
    pub layout: CnnLayout,
    /// CPU CNN engine ([`CnnEngine::Auto`] by default: the plan table's, the native kernels wherever they
    /// run the models).
    pub engine: CnnEngine,
    /// Time the CNN candidates (engines, each layer's kernel row, threads) when the generator is made, instead
    /// of taking the plan table's (the default, `false`: the same SLM codes on every run). Save the result
    /// ([`GeneratorInfo::plan`], [`PlanReport::saved`]) and give it as `saved_plans` on later runs to repeat
    /// it without timing.
    pub tune: bool,
    /// CNN plans saved from an earlier (tuned) generator ([`PlanReport::saved`], read back with
    /// [`SavedPlans::from_json`]): repeated without timing, so every run gives the same SLM codes. `None`
    /// (the default): the plan table, or a timing with `tune`. Refused with `tune`, and at creation when
    /// made for another kernel ISA level than this CPU's.
    #[serde(serialize_with = "saved_source")]
    pub saved_plans: Option<Arc<SavedPlans>>,
    /// How camera frames fit the hologram ([`Fit::Crop`] by default).
    pub fit: Fit,
    /// Wavelengths (R, G, B), pixel pitch and volume depth, all in metres (the paper's display: 638, 520,
    /// 450 nm, 8 µm, 6 mm).
    pub optics: OpticalSetup,
    /// Angular spectrum options (padding, band limit).
    pub options: PropagationOptions,
    /// Double phase method where no pre-filter CNN runs (AA-DPM by default).
    pub encoding: DoublePhaseMethod,
    /// Metric depth range mapped to the 3D volume (`None`: 1st/99th percentiles of each frame's valid
    /// depths; a stream keeps its first frame's).
    pub depth_range: Option<DepthRange>,
    /// Metric depth → normalised depth mapping (linear in diopters by default).
    pub depth_mapping: DepthMapping,
    /// Where frames are computed ([`Backend::Auto`] by default: the phone's GPU where it passes a
    /// first-frame self-check against the CPU, else the CPU; [`GeneratorInfo::backend`] says which).
    pub backend: Backend,
    /// The GPU CNNs' arithmetic ([`GpuPrecision::Auto`] by default: f16 where the GPU has it, which halves
    /// their memory; docs/GPU.md).
    pub gpu_precision: GpuPrecision,
    /// Largest relative spread (a fraction: 0.01 = 1 %) of the per-colour depth scales accepted when the
    /// CNNs were trained for another, Fresnel-equivalent display (`docs/DISPLAYS.md`,
    /// [`crate::display::DisplayMapping`]); `None` (the default): the serving rule's, whose estimated cost
    /// stays within 0.3 dB of the model's own score. A value wider than the rule's is reported as "widened"
    /// in [`GeneratorInfo::display_mapping`].
    pub wavelength_ratio_tolerance: Option<f64>,
}

/// [`GeneratorConfig::saved_plans`] in reports: the plans' origin, or null.
fn saved_source<S: serde::Serializer>(
    plans: &Option<Arc<SavedPlans>>,
    s: S,
) -> std::result::Result<S::Ok, S::Error> {
    match plans {
        Some(p) => s.serialize_some(&p.origin),
        None => s.serialize_none(),
    }
}

impl GeneratorConfig {
    /// The defaults for a `width × height` hologram: the shipped 8-layer f32 CNN, its pre-filter where it
    /// helps (Auto), SLM 6 mm from the midpoint hologram, autotuned CNN plan, centred crop, automatic depth
    /// range, the paper's display.
    pub fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            models: ModelSelection::default(),
            offset_m: 6e-3,
            threads: ThreadCount::Auto,
            layout: CnnLayout::Auto,
            engine: CnnEngine::Auto,
            tune: false,
            saved_plans: None,
            fit: Fit::default(),
            optics: OpticalSetup::default(),
            options: PropagationOptions::default(),
            encoding: DoublePhaseMethod::default(),
            depth_range: None,
            depth_mapping: DepthMapping::default(),
            backend: Backend::default(),
            gpu_precision: GpuPrecision::default(),
            wavelength_ratio_tolerance: None,
        }
    }

    /// The defaults of [`GeneratorConfig::new`] for the display a profile describes (`docs/DISPLAYS.md`):
    /// `width`/`height` from its `resolution` (`[height, width]` pixels), `optics` from
    /// [`DisplayProfile::optics`] (wavelengths, pitch and volume depth in metres) and `offset_m` from
    /// [`DisplayProfile::default_offset_m`] (the first of `offsets_m`). The profile's `calibration` file is
    /// not read here: load it and pass it to [`HologramGenerator::set_calibration`].
    ///
    /// Errors: none here (a profile from [`DisplayProfile::from_json_str`] or [`DisplayProfile::new`] is
    /// valid); whether the shipped CNNs serve the display (one depth scale `σ` for the three lasers, volume
    /// and offsets `σ`·6 mm) is checked when the generator is made, as [`HologramGenerator::new`].
    pub fn for_display(profile: &DisplayProfile) -> Self {
        let [height, width] = profile.resolution;
        Self {
            optics: profile.optics(),
            offset_m: profile.default_offset_m(),
            ..Self::new(width, height)
        }
    }

    /// Checks everything that needs no model: non-zero sizes within [`MAX_HOLOGRAM_PIXELS`] whose RGBA
    /// outputs (`width · height · 4` bytes) fit in a `u32`, a finite non-negative offset, valid optics and
    /// depth range, a thread count within [`MAX_CNN_THREADS`] and a finite wavelength ratio tolerance ≥ 0.
    ///
    /// Errors: [`HoloError::InvalidParameter`] naming the field.
    pub fn validate(&self) -> Result<()> {
        if self.width == 0 || self.height == 0 {
            return Err(invalid(
                "width/height",
                format!(
                    "the hologram needs a non-zero size, got {}×{}",
                    self.width, self.height
                ),
            ));
        }
        let pixels = self
            .width
            .checked_mul(self.height)
            .filter(|&p| p <= MAX_HOLOGRAM_PIXELS);
        let rgba_fits = pixels
            .and_then(|p| p.checked_mul(4))
            .is_some_and(|b| b <= u32::MAX as usize);
        if pixels.is_none() || !rgba_fits {
            return Err(invalid(
                "width/height",
                format!(
                    "{}×{} is larger than the {MAX_HOLOGRAM_PIXELS} pixels a generator makes",
                    self.width, self.height
                ),
            ));
        }
        if !(self.offset_m.is_finite() && self.offset_m >= 0.0) {
            return Err(invalid(
                "offset_m",
                format!("must be finite and ≥ 0 metres, got {}", self.offset_m),
            ));
        }
        self.optics.validate()?;
        if let Some(r) = &self.depth_range {
            r.validate()?;
        }
        if let ThreadCount::Fixed(n) = self.threads {
            if n == 0 || n > MAX_CNN_THREADS {
                return Err(invalid(
                    "threads",
                    format!("0 (automatic) to {} threads, got {n}", MAX_CNN_THREADS),
                ));
            }
        }
        if self.tune && self.saved_plans.is_some() {
            return Err(invalid(
                "tune",
                "saved plans and a new tuning were both asked for: give one",
            ));
        }
        if let Some(p) = &self.saved_plans {
            p.validate()?;
        }
        if let Some(t) = self.wavelength_ratio_tolerance {
            if !(t.is_finite() && t >= 0.0) {
                return Err(invalid(
                    "wavelength_ratio_tolerance",
                    format!("must be a finite fraction ≥ 0 (0.01 = 1 %), got {t}"),
                ));
            }
        }
        Ok(())
    }

    /// The pipeline part of this configuration.
    pub fn pipeline_config(&self) -> PipelineConfig {
        PipelineConfig {
            optics: self.optics,
            options: self.options,
            offset_m: self.offset_m,
            encoding: self.encoding,
            cnn_layout: self.layout,
            cnn_engine: self.engine,
            cnn_threads: self.threads,
            cnn_conv: ConvAlgorithm::Auto,
            cnn_tune: self.tune,
            backend: self.backend,
            gpu_precision: self.gpu_precision,
            wavelength_ratio_tolerance: self.wavelength_ratio_tolerance,
        }
    }

    /// The camera-frame conversion part of this configuration.
    pub fn frame_options(&self) -> FrameOptions {
        FrameOptions {
            fit: self.fit,
            range: self.depth_range,
            mapping: self.depth_mapping,
        }
    }
}

/// Seconds of each stage of one frame through a [`HologramGenerator`].
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct PatternTimings {
    /// Camera buffers → RGB-D frame at the hologram resolution (decode, rotate, fill, fit).
    pub convert_s: f64,
    /// The session's stages (CNN, offset, pre-filter, encoding; `total_s` is their sum, or the frame period in
    /// a stream).
    pub frame: FrameTimings,
}

impl PatternTimings {
    /// The median of each stage over `timings` ([`FrameTimings::median`] for the session's stages).
    pub fn median(timings: &[PatternTimings]) -> PatternTimings {
        let frames: Vec<FrameTimings> = timings.iter().map(|t| t.frame).collect();
        let mut convert: Vec<f64> = timings.iter().map(|t| t.convert_s).collect();
        convert.sort_by(f64::total_cmp);
        PatternTimings {
            convert_s: convert.get(convert.len() / 2).copied().unwrap_or(0.0),
            frame: FrameTimings::median(&frames),
        }
    }
}

/// What [`HologramGenerator::benchmark`] measured.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct GeneratorBenchmark {
    /// Frames timed (after one warm-up frame).
    pub frames: usize,
    /// The median of each stage ([`PatternTimings::median`]).
    pub median: PatternTimings,
    /// Frames per second of one frame after another: `1 / (convert_s + total_s)` of the medians; 0 where
    /// that time is 0.
    pub fps: f64,
}

/// One frame's SLM patterns, owned by the caller: three 8-bit planes, one per laser (field-sequential
/// colour), code `c` displaying phase `2π·c/256` (linear look-up table).
#[derive(Debug, Clone, PartialEq)]
pub struct SlmPatterns {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `[3, H, W]` codes (R, G, B), row-major.
    pub codes: Array3<u8>,
    /// Global amplitude normaliser of Eq. 7 (for simulating what the SLM shows).
    pub amplitude_scale: f32,
    /// Metric depth range used for this frame (`None` for relative depth).
    pub depth_range: Option<DepthRange>,
    /// Stage timings.
    pub timings: PatternTimings,
}

impl SlmPatterns {
    fn from_frame(out: &SlmFrame, convert_s: f64, depth_range: Option<DepthRange>) -> Self {
        let (_, height, width) = out.codes.dim();
        Self {
            width,
            height,
            codes: out.codes.clone(),
            amplitude_scale: out.amplitude_scale,
            depth_range,
            timings: PatternTimings {
                convert_s,
                frame: out.timings,
            },
        }
    }

    /// The 32-bit frame colour-sequential SLM drivers take over HDMI/DisplayPort ([`pack_rgba`]):
    /// `[H, W, 4]` bytes, one laser's pattern per colour channel, alpha 255.
    pub fn to_rgba(&self) -> Vec<u8> {
        pack_rgba(self.codes.view())
    }
}

/// Interleaves SLM codes `[3, H, W]` (R, G, B) into the 32-bit frame colour-sequential SLM drivers take over
/// HDMI: `[H, W, 4]` bytes, row-major, the red laser's pattern in R, green in G, blue in B, alpha 255.
pub fn pack_rgba(codes: ArrayView3<u8>) -> Vec<u8> {
    let (c, h, w) = codes.dim();
    let mut out = vec![255u8; h * w * 4];
    for ch in 0..c.min(3) {
        let plane = codes.index_axis(Axis(0), ch);
        match plane.as_slice() {
            Some(src) => interleave(&mut out, ch, src),
            None => interleave(&mut out, ch, &plane.iter().copied().collect::<Vec<_>>()),
        }
    }
    out
}

/// As [`pack_rgba`] from three row-major planes of `width · height` codes each (red, green, blue).
///
/// Errors: [`HoloError::InvalidParameter`] (`planes`) if the planes differ in length.
pub fn pack_rgba_planes(red: &[u8], green: &[u8], blue: &[u8]) -> Result<Vec<u8>> {
    if red.len() != green.len() || red.len() != blue.len() {
        return Err(invalid(
            "planes",
            format!(
                "the red, green and blue planes hold {}, {} and {} codes; they must be equal",
                red.len(),
                green.len(),
                blue.len()
            ),
        ));
    }
    let mut out = vec![255u8; red.len() * 4];
    for (ch, plane) in [red, green, blue].into_iter().enumerate() {
        interleave(&mut out, ch, plane);
    }
    Ok(out)
}

/// Writes `plane` into byte `ch` of every 4-byte pixel of `out`.
fn interleave(out: &mut [u8], ch: usize, plane: &[u8]) {
    for (px, &v) in out.chunks_exact_mut(4).zip(plane) {
        px[ch] = v;
    }
}

/// A simulated view of the SLM patterns ([`HologramGenerator::preview`]): `[H, W, 4]` sRGB bytes, alpha 255.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Preview {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `[H, W, 4]` RGBA8 bytes, row-major, sRGB.
    pub rgba: Vec<u8>,
}

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
}

/// Receives a [`HologramStream`]'s results, in frame order, on the stream's worker thread.
pub trait StreamListener: Send {
    /// The patterns of frame `index` (the value [`HologramStream::push`] returned for it).
    fn on_patterns(&mut self, index: u64, patterns: SlmPatterns);
    /// Frame `index` failed (bad buffers, all depth invalid, …); the stream goes on with the next frame.
    fn on_error(&mut self, index: u64, error: HoloError);
}

/// RGB-D camera frames → SLM patterns with the shipped CNNs (see the [module docs](self)).
#[derive(Debug)]
pub struct HologramGenerator {
    config: GeneratorConfig,
    pipeline: HologramPipeline,
    session: Mutex<HologramSession>,
    /// The display calibration of new sessions and streams ([`HologramGenerator::set_calibration`]).
    calibration: Mutex<Option<Arc<DisplayCalibration>>>,
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
        let expected = ModelConfig {
            optics: pipeline_config.optics,
            offset_m: pipeline_config.offset_m,
            input_layers: 1,
            wavelength_ratio_tolerance: pipeline_config.wavelength_ratio_tolerance,
        };
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
    pub fn with_pipeline(config: GeneratorConfig, pipeline: HologramPipeline) -> Result<Self> {
        config.validate()?;
        let pipeline = match &config.saved_plans {
            Some(plans) => pipeline.with_saved_plans(plans.clone())?,
            None => pipeline,
        };
        let calibration = pipeline.calibration().cloned();
        let session = open_session(&pipeline, &config, calibration.clone())?;
        Ok(Self {
            config,
            pipeline,
            session: Mutex::new(session),
            calibration: Mutex::new(calibration),
        })
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
        let mut current = lock_calibration(&self.calibration);
        self.session()?.set_calibration(calibration.clone())?;
        *current = calibration;
        Ok(())
    }

    /// The display calibration applied, if any.
    pub fn calibration(&self) -> Option<Arc<DisplayCalibration>> {
        lock_calibration(&self.calibration).clone()
    }

    /// Renders the built-in test scene ([`crate::scene::procedural::default_scene`]) `frames` times after one
    /// warm-up frame, at this generator's resolution, and returns the median stage timings: what an app shows
    /// as its device's speed.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`frames`) for 0 frames; as [`HologramGenerator::render_rgbd`].
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
    pub fn config(&self) -> &GeneratorConfig {
        &self.config
    }

    /// The session, recreated if a panic poisoned its lock (so a bug in one call cannot lose the generator).
    fn session(&self) -> Result<MutexGuard<'_, HologramSession>> {
        match self.session.lock() {
            Ok(g) => Ok(g),
            Err(poisoned) => {
                let mut g = poisoned.into_inner();
                *g = open_session(&self.pipeline, &self.config, self.calibration())?;
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
    pub fn convert(&self, frame: &CameraFrame) -> Result<(RgbdFrame, CameraFrameReport)> {
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
    pub fn render(&self, frame: &CameraFrame) -> Result<SlmPatterns> {
        let t = Instant::now();
        let (rgbd, report) = self.convert(frame)?;
        let convert_s = t.elapsed().as_secs_f64();
        let mut session = self.session()?;
        let out = session.render(&rgbd)?;
        Ok(SlmPatterns::from_frame(out, convert_s, report.range_used))
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
    pub fn render_ldi(&self, layers: &[CameraFrame]) -> Result<SlmPatterns> {
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
    pub fn render_rgbd(&self, frame: &RgbdFrame) -> Result<SlmPatterns> {
        let mut session = self.session()?;
        let out = session.render(frame)?;
        Ok(SlmPatterns::from_frame(out, 0.0, None))
    }

    /// What a viewer sees of `patterns` focused at normalised depth `focus` ∈ [0, 1] (0 = near): the phase
    /// the SLM displays for the 8-bit codes (through the calibrated curves of
    /// [`HologramGenerator::set_calibration`], else [`LinearLut::phase`]; quantisation included), as a phase-only
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
        let phase = match (&calibration, calibrated) {
            (Some(cal), true) => crate::slm::displayed_phase(cal.luts(), patterns.codes.view())?,
            _ => patterns.codes.mapv(|c| LinearLut.phase(c)),
        };
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
    pub fn preview(&self, frame: &CameraFrame, focus: f32) -> Result<Preview> {
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
        let (plan, backend) = {
            let session = self.session()?;
            (
                session.plan_report().clone(),
                session.backend_report().clone(),
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
        })
    }

    /// Starts a video stream whose results go to `listener` ([`HologramStream`]); its queue holds
    /// `capacity` frames (≥ 1; [`DEFAULT_STREAM_CAPACITY`]). The stream has its own session (the CNN plans
    /// and the autotuning result are shared with this generator's), so [`HologramGenerator::render`] stays
    /// available meanwhile.
    ///
    /// Errors: [`HoloError::InvalidParameter`] for a capacity of 0; as [`HologramPipeline::session`].
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
        let session = open_session(&pipeline, &self.config, self.calibration())?;
        HologramStream::start(session, self.config.clone(), listener, capacity)
    }
}

/// An amplitude image `[3, H, W]` as sRGB RGBA8 for the screen.
fn preview_image(amp: &Array3<f32>) -> Preview {
    let (_, height, width) = amp.dim();
    let mut rgba = vec![255u8; height * width * 4];
    for c in 0..3 {
        for (px, &a) in rgba
            .chunks_exact_mut(4)
            .zip(amp.index_axis(Axis(0), c).iter())
        {
            px[c] = amplitude_to_srgb8(a.max(0.0));
        }
    }
    Preview {
        width,
        height,
        rgba,
    }
}

/// A session for `config`'s size with `calibration` that downloads only what [`SlmPatterns`] holds (codes and
/// normaliser) from the GPU.
fn open_session(
    pipeline: &HologramPipeline,
    config: &GeneratorConfig,
    calibration: Option<Arc<DisplayCalibration>>,
) -> Result<HologramSession> {
    let mut session = pipeline.session(config.height, config.width)?;
    session.set_full_outputs(false);
    session.set_calibration(calibration)?;
    Ok(session)
}

/// The calibration slot; it holds a plain `Option<Arc>`, consistent whatever a panicking thread did.
fn lock_calibration(
    slot: &Mutex<Option<Arc<DisplayCalibration>>>,
) -> MutexGuard<'_, Option<Arc<DisplayCalibration>>> {
    slot.lock().unwrap_or_else(|e| e.into_inner())
}

/// The queue between [`HologramStream::push`] and the worker.
#[derive(Debug, Default)]
struct Queue {
    frames: VecDeque<(u64, CameraFrameBuf)>,
    next_index: u64,
    dropped: u64,
    closed: bool,
}

#[derive(Debug, Default)]
struct Shared {
    queue: Mutex<Queue>,
    ready: Condvar,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Queue> {
        // The queue's critical sections cannot panic; recover it rather than propagate poison.
        self.queue.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The next frame, waiting for one; `None` once closed and drained.
    fn pop(&self) -> Option<(u64, CameraFrameBuf)> {
        let mut q = self.lock();
        loop {
            if let Some(f) = q.frames.pop_front() {
                return Some(f);
            }
            if q.closed {
                return None;
            }
            q = self.ready.wait(q).unwrap_or_else(|p| p.into_inner());
        }
    }
}

/// A video stream of camera frames (see the [module docs](self)); made by [`HologramGenerator::stream`].
/// Dropping it closes it.
#[derive(Debug)]
pub struct HologramStream {
    shared: Arc<Shared>,
    capacity: usize,
    worker: Mutex<Option<JoinHandle<()>>>,
}

impl HologramStream {
    fn start(
        mut session: HologramSession,
        config: GeneratorConfig,
        listener: Box<dyn StreamListener>,
        capacity: usize,
    ) -> Result<Self> {
        let shared = Arc::new(Shared::default());
        let source = Arc::clone(&shared);
        let worker = std::thread::Builder::new()
            .name("tensorholo-stream".into())
            .spawn(move || {
                let mut listener = listener;
                let mut options = config.frame_options();
                let run = catch_unwind(AssertUnwindSafe(|| {
                    // The CNN thread converts frames (the first auto range is locked for the rest); each
                    // frame's range and conversion time travel to the sink in its tag.
                    let frames = std::iter::from_fn(|| {
                        let (index, buf) = source.pop()?;
                        let t = Instant::now();
                        let converted = buf.view().to_rgbd(config.height, config.width, &options);
                        let convert_s = t.elapsed().as_secs_f64();
                        let range = converted.as_ref().ok().and_then(|(_, r)| r.range_used);
                        if options.range.is_none() {
                            options.range = range;
                        }
                        Some(((index, range, convert_s), converted.map(|(frame, _)| frame)))
                    });
                    session.render_stream_each(frames, |(index, range, convert_s), result| {
                        match result {
                            Ok(out) => listener
                                .on_patterns(index, SlmPatterns::from_frame(out, convert_s, range)),
                            Err(e) => listener.on_error(index, e),
                        }
                        Ok(())
                    })
                }));
                let failure = match run {
                    Ok(Ok(_)) => None,
                    Ok(Err(e)) => Some(e),
                    Err(_) => Some(HoloError::Internal("the stream's worker panicked".into())),
                };
                if let Some(e) = failure {
                    let index = source.lock().next_index;
                    listener.on_error(index, e);
                }
            })
            .map_err(|e| HoloError::Internal(format!("cannot start the stream's worker: {e}")))?;
        Ok(Self {
            shared,
            capacity,
            worker: Mutex::new(Some(worker)),
        })
    }

    /// Queues a frame and returns its index (0, 1, 2… in push order). Never blocks on the hologram: when
    /// the queue is full, the oldest waiting frame is dropped ([`HologramStream::dropped_frames`] counts
    /// them) and its index is never delivered.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`stream`) after [`HologramStream::close`].
    pub fn push(&self, frame: CameraFrameBuf) -> Result<u64> {
        let mut q = self.shared.lock();
        if q.closed {
            return Err(invalid("stream", "this stream is closed; start a new one"));
        }
        let index = q.next_index;
        q.next_index += 1;
        q.frames.push_back((index, frame));
        while q.frames.len() > self.capacity {
            q.frames.pop_front();
            q.dropped += 1;
        }
        drop(q);
        self.shared.ready.notify_one();
        Ok(index)
    }

    /// Frames dropped so far because the queue was full.
    pub fn dropped_frames(&self) -> u64 {
        self.shared.lock().dropped
    }

    /// Frames pushed so far.
    pub fn pushed_frames(&self) -> u64 {
        self.shared.lock().next_index
    }

    /// Stops accepting frames, lets the worker finish the frames already queued, and waits for it: after
    /// `close` returns, the listener is called no more. Calling it again does nothing.
    pub fn close(&self) {
        self.shared.lock().closed = true;
        self.shared.ready.notify_all();
        let handle = self.worker.lock().unwrap_or_else(|p| p.into_inner()).take();
        if let Some(h) = handle {
            // The worker catches its own panics; a join error cannot carry anything more.
            let _ = h.join();
        }
    }

    /// Whether [`HologramStream::close`] was called.
    pub fn is_closed(&self) -> bool {
        self.shared.lock().closed
    }
}

impl Drop for HologramStream {
    fn drop(&mut self) {
        self.close();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rgba_packs_one_laser_per_channel() {
        let codes = Array3::from_shape_fn((3, 2, 3), |(c, y, x)| (c * 100 + y * 10 + x) as u8);
        let rgba = pack_rgba(codes.view());
        assert_eq!(rgba.len(), 2 * 3 * 4);
        let planes: Vec<Vec<u8>> = (0..3)
            .map(|c| codes.index_axis(Axis(0), c).iter().copied().collect())
            .collect();
        assert_eq!(
            pack_rgba_planes(&planes[0], &planes[1], &planes[2]).unwrap(),
            rgba
        );
        assert!(pack_rgba_planes(&planes[0], &planes[1][1..], &planes[2]).is_err());
        // A non-contiguous view packs the same codes.
        let reversed = codes.slice(ndarray::s![.., .., ..;-1]);
        let packed = pack_rgba(reversed);
        assert_eq!(
            &packed[..4],
            [codes[[0, 0, 2]], codes[[1, 0, 2]], codes[[2, 0, 2]], 255]
        );
        for y in 0..2 {
            for x in 0..3 {
                let px = &rgba[(y * 3 + x) * 4..][..4];
                assert_eq!(
                    px,
                    [codes[[0, y, x]], codes[[1, y, x]], codes[[2, y, x]], 255]
                );
            }
        }
    }

    #[test]
    fn config_refuses_what_cannot_work() {
        assert!(GeneratorConfig::new(64, 48).validate().is_ok());
        let bad = |f: fn(&mut GeneratorConfig)| {
            let mut c = GeneratorConfig::new(64, 48);
            f(&mut c);
            c.validate().unwrap_err()
        };
        let name = |e: HoloError| match e {
            HoloError::InvalidParameter { name, .. } => name,
            e => panic!("unexpected {e}"),
        };
        assert_eq!(name(bad(|c| c.width = 0)), "width/height");
        assert_eq!(name(bad(|c| c.height = usize::MAX)), "width/height");
        assert_eq!(
            name(bad(|c| {
                c.width = 9000;
                c.height = 9000;
            })),
            "width/height"
        );
        assert_eq!(name(bad(|c| c.offset_m = f64::NAN)), "offset_m");
        assert_eq!(name(bad(|c| c.offset_m = -1e-3)), "offset_m");
        assert_eq!(
            name(bad(|c| c.threads = ThreadCount::Fixed(100_000))),
            "threads"
        );
        assert!(matches!(
            bad(|c| c.optics.pixel_pitch_m = f64::NAN),
            HoloError::InvalidParameter { .. }
        ));
        assert!(matches!(
            bad(|c| c.depth_range = Some(DepthRange {
                z_near_m: 2.0,
                z_far_m: 1.0
            })),
            HoloError::InvalidParameter { .. }
        ));
    }

    /// A 4 µm SLM at the paper's lasers: σ = (4/8)² = 0.25, so a 1.5 mm volume and 1.5 mm offsets.
    const PROFILE_4UM: &str = r#"{
        "name": "4 µm test SLM",
        "pixel_pitch_m": 4e-6,
        "resolution": [48, 64],
        "wavelengths_m": [638e-9, 520e-9, 450e-9],
        "volume_depth_m": 1.5e-3,
        "offsets_m": [1.5e-3, 3e-3]
    }"#;

    #[test]
    fn for_display_takes_size_optics_and_offset_from_the_profile() {
        let profile = DisplayProfile::from_json_str(PROFILE_4UM).unwrap();
        let c = GeneratorConfig::for_display(&profile);
        assert_eq!((c.width, c.height), (64, 48));
        assert_eq!(
            c.optics,
            OpticalSetup {
                wavelengths_m: [638e-9, 520e-9, 450e-9],
                pixel_pitch_m: 4e-6,
                volume_depth_m: 1.5e-3,
            }
        );
        assert_eq!(c.offset_m, 1.5e-3);
        assert_eq!(c.wavelength_ratio_tolerance, None);
        // Everything else is GeneratorConfig::new's.
        let want = GeneratorConfig {
            optics: c.optics,
            offset_m: c.offset_m,
            ..GeneratorConfig::new(64, 48)
        };
        assert_eq!(c, want);
        c.validate().unwrap();
        assert_eq!(c.pipeline_config().wavelength_ratio_tolerance, None);
    }

    #[test]
    fn a_bad_wavelength_ratio_tolerance_is_named() {
        for t in [f64::NAN, -0.01, f64::INFINITY] {
            let mut c = GeneratorConfig::new(64, 48);
            c.wavelength_ratio_tolerance = Some(t);
            assert!(
                matches!(
                    c.validate(),
                    Err(HoloError::InvalidParameter {
                        name: "wavelength_ratio_tolerance",
                        ..
                    })
                ),
                "{t}"
            );
        }
    }

    /// Small and deterministic: one thread, the native engine, the CPU.
    #[cfg(feature = "embedded-models")]
    fn quick(mut c: GeneratorConfig) -> GeneratorConfig {
        c.threads = ThreadCount::Fixed(1);
        c.engine = CnnEngine::Native;
        c.backend = Backend::Cpu;
        c
    }

    /// The shipped 8 µm CNNs drive the 4 µm SLM of a profile: a frame renders, the 6 mm pre-filter serves
    /// the 1.5 mm offset, and the info's display mapping says σ = 0.25.
    #[cfg(feature = "embedded-models")]
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
    #[cfg(feature = "embedded-models")]
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

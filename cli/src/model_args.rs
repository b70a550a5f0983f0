//! The model flags `holo render`, `holo video` and `holo bench` share ([`ModelArgs`]: the CNNs, their engine
//! and threads, the display, the encoding, the viewer's aberration) and how they become a pipeline
//! ([`ModelArgs::pipeline`]). Every rule is the SDK's (which CNN serves a display, which pre-filter, which
//! aberration applies); this file maps flags onto the SDK's values and says what was chosen.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use serde_json::json;
use tensorholo::cnn::{CnnEngine, CnnLayout, CnnOptions, ThreadCount};
use tensorholo::display::{AberrationProfile, AberrationSource, DisplayProfile, Prescription};
use tensorholo::model::{HologramModel, ModelKind, Precision, SceneInput};
use tensorholo::pipeline::{
    Backend, GpuPrecision, HologramPipeline, PipelineConfig, PrefilterMode, PrefilterSource,
};

/// Weight formats selectable on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PrecisionArg {
    /// 32-bit float.
    F32,
    /// int8 QOperator (`QLinearConv`, real int8 kernels in tract).
    Int8Qop,
    /// int8 QDQ (quantise/dequantise around float convolutions).
    Int8Qdq,
}

impl From<PrecisionArg> for Precision {
    fn from(p: PrecisionArg) -> Self {
        match p {
            PrecisionArg::F32 => Precision::F32,
            PrecisionArg::Int8Qop => Precision::Int8QOperator,
            PrecisionArg::Int8Qdq => Precision::Int8Qdq,
        }
    }
}

/// Where frames are computed ([`Backend`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum BackendArg {
    /// The GPU where a hardware adapter exists and the first frame agrees with the CPU, else the CPU.
    Auto,
    /// tract and rustfft on the CPU (the reference).
    Cpu,
    /// WGSL compute shaders through wgpu (Vulkan/Metal), any adapter including a software one (lavapipe).
    Gpu,
}

impl From<BackendArg> for Backend {
    fn from(b: BackendArg) -> Self {
        match b {
            BackendArg::Auto => Backend::Auto,
            BackendArg::Cpu => Backend::Cpu,
            BackendArg::Gpu => Backend::Gpu,
        }
    }
}

/// GPU CNN arithmetic ([`GpuPrecision`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum GpuPrecisionArg {
    /// f16 where the adapter has SHADER_F16, else f32.
    Auto,
    /// f32 storage and arithmetic.
    F32,
    /// f16 activations and products, f32 sums.
    F16,
}

impl From<GpuPrecisionArg> for GpuPrecision {
    fn from(p: GpuPrecisionArg) -> Self {
        match p {
            GpuPrecisionArg::Auto => GpuPrecision::Auto,
            GpuPrecisionArg::F32 => GpuPrecision::F32,
            GpuPrecisionArg::F16 => GpuPrecision::F16,
        }
    }
}

/// CNN memory layouts selectable on the command line ([`CnnLayout`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LayoutArg {
    /// Time both layouts on this machine when the session is created and keep the faster.
    Auto,
    /// Channels first, as in the ONNX file (tract's direct spatial convolution).
    Nchw,
    /// Channels last (tract's lazy im2col and matrix product; not for int8-qop files).
    Nhwc,
}

impl From<LayoutArg> for CnnLayout {
    fn from(l: LayoutArg) -> Self {
        match l {
            LayoutArg::Auto => CnnLayout::Auto,
            LayoutArg::Nchw => CnnLayout::ChannelsFirst,
            LayoutArg::Nhwc => CnnLayout::ChannelsLast,
        }
    }
}

/// CPU CNN engines selectable on the command line ([`CnnEngine`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum EngineArg {
    /// Time the engines when the session is created and keep the faster (tract is not timed where the native engine runs its x86-64 SIMD rows, which outrun it; int8 QOperator files: tract).
    Auto,
    /// tensorholo's own direct 3×3 convolution kernels (f32 and int8 QDQ models; SIMD chosen from the CPU at
    /// run time).
    Native,
    /// tract (every model file, int8 included).
    Tract,
}

impl From<EngineArg> for CnnEngine {
    fn from(e: EngineArg) -> Self {
        match e {
            EngineArg::Auto => CnnEngine::Auto,
            EngineArg::Native => CnnEngine::Native,
            EngineArg::Tract => CnnEngine::Tract,
        }
    }
}

/// The int8 form `--int8` selects: the SDK's ([`tensorholo::model::DEFAULT_INT8`]).
pub const DEFAULT_INT8: Precision = tensorholo::model::DEFAULT_INT8;

fn parse_layers(s: &str) -> std::result::Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(n @ (8 | 15 | 30)) => Ok(n),
        _ => Err(format!(
            "the shipped hologram CNNs have 8, 15 or 30 layers, not `{s}`"
        )),
    }
}

/// Which CNNs to run: shared by `render`, `video` and `bench`.
#[derive(Debug, Args)]
pub struct ModelArgs {
    /// Hologram CNN depth (shipped models: 8, 15 or 30 convolution layers).
    #[arg(long, default_value_t = 8, value_parser = parse_layers)]
    pub layers: usize,
    /// Distance s from the midpoint hologram to the SLM plane in millimetres (paper: 0, 6 or 12; shipped
    /// pre-filter CNNs exist for 6 and 12) [default: 6, or the first offset of the --display profile].
    #[arg(long, allow_hyphen_values = true)]
    pub offset_mm: Option<f64>,
    /// Run the int8 models (the form the benchmarks found fastest within 0.5 dB; see --precision).
    #[arg(long, conflicts_with = "precision")]
    pub int8: bool,
    /// Weight format of the shipped models.
    #[arg(long, value_enum)]
    pub precision: Option<PrecisionArg>,
    /// Hologram CNN ONNX file to use instead of the shipped one (metadata must match the optics).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Pre-filter CNN ONNX file for --offset-mm (implies --prefilter).
    #[arg(long, conflicts_with = "no_prefilter")]
    pub prefilter_model: Option<PathBuf>,
    /// Require the shipped DDPM pre-filter CNN of --offset-mm (6 or 12 mm; an error otherwise). By default it
    /// runs where one is shipped and no --encoding is given, the one trained on the holograms of the chosen CNN
    /// depth (8, 15 or 30 layers; the LDI CNN takes the 8-layer one): the CNN's hologram is offset,
    /// pre-filtered and encoded with plain double phase (paper Eq. 6–7), above AA-DPM on the test split
    /// (models/MODEL_CARD.md).
    #[arg(long, conflicts_with_all = ["no_prefilter", "encoding"])]
    pub prefilter: bool,
    /// Encode the CNN's hologram with --encoding (AA-DPM by default) instead of the DDPM pre-filter CNN.
    #[arg(long)]
    pub no_prefilter: bool,
    /// Threads of the CNNs; 0 (the default) = the cores the CPU reports (with --tune: the fastest of 1, half
    /// and all cores). The three colours of the optics always run in parallel.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u32).range(0..=256))]
    pub threads: u32,
    /// Engine of the CPU CNNs: auto takes the plan table's (the native kernels wherever they run the models;
    /// int8 QOperator files run on tract), or with --tune times them; report.json's cnn_plan gives the
    /// choice, why, each layer's kernel row and any timing.
    #[arg(long, value_enum, default_value_t = EngineArg::Auto)]
    pub engine: EngineArg,
    /// Memory layout tract runs the hologram CNN in: auto takes the plan table's (nchw on x86-64, nhwc on
    /// aarch64), or with --tune times both; nhwc is not for int8-qop.
    #[arg(long, value_enum, default_value_t = LayoutArg::Auto)]
    pub layout: LayoutArg,
    #[command(flatten)]
    pub plans: crate::args::PlanArgs,
    /// Where frames are computed: auto uses a hardware GPU (Vulkan, Metal) when the first frame agrees with
    /// the CPU (a software Vulkan such as lavapipe only with `gpu`); report.json says which ran and why.
    #[arg(long, value_enum, default_value_t = BackendArg::Auto)]
    pub backend: BackendArg,
    /// The GPU CNNs' arithmetic: auto (f16 where the adapter has it), f32, or f16 activations (half the
    /// memory; f32 where the adapter lacks f16).
    #[arg(long, value_enum, default_value_t = GpuPrecisionArg::Auto)]
    pub gpu_precision: GpuPrecisionArg,
    /// Display calibration file (.holocal, from `holo calibrate lut`): the SLM's per-colour look-up tables
    /// (phase → code) and laser intensity map (docs/CALIBRATION.md). Frames must have its SLM size; its
    /// wavelengths must be the optics'. Without it: the linear look-up table of an ideal SLM.
    #[arg(long, visible_alias = "lut")]
    pub calibration: Option<PathBuf>,
    /// Largest spread of the three lasers' depth scales (a fraction: 0.01 = 1 %) accepted when the models
    /// were trained for another, Fresnel-equivalent display (docs/DISPLAYS.md). Default: the serving rule's
    /// for the model (an estimated cost within 0.3 dB of its model-card score: about 1.8–2 %); wider than
    /// that, report.json's display_mapping says "widened" and gives the estimated cost.
    #[arg(long)]
    pub wavelength_ratio_tolerance: Option<f64>,
    /// Aberration file (tensorholo.aberration, docs/ABERRATION.md; `holo calibrate aberration` or a
    /// prescription writes one): the viewer's eyes or the display optics, corrected in every frame with the
    /// shipped CNNs (the coefficients at the midpoint plane multiply the hologram's spectrum; exact where they
    /// are the same at every distance, report.json gives the residual otherwise). Overrides the --display
    /// profile's `aberration`. On the CPU and the GPU alike; frames encode with --encoding (AA-DPM by
    /// default): the DDPM pre-filters were trained on uncorrected fields.
    #[arg(long, conflicts_with = "prefilter")]
    pub aberration: Option<PathBuf>,
    /// The viewer's spectacle prescription, corrected in every frame as an aberration file is:
    /// SPHERE or SPHERE,CYLINDER,AXIS in dioptres and degrees, ophthalmic conventions (a myope's sphere is negative;
    /// the axis is counterclockwise from the horizontal as the viewer sees the image), e.g.
    /// --prescription=-2.00,-0.75,30. Overrides the --display profile's `prescription`
    /// (docs/ABERRATION.md, "A viewer's prescription").
    #[arg(long, allow_hyphen_values = true, conflicts_with_all = ["aberration", "prefilter"])]
    pub prescription: Option<String>,
    /// Focal length of the display's eyepiece in millimetres, for --prescription (the viewer's pupil sits at
    /// its back focal plane) and --fovea-deg (degrees of visual angle); default: the paper's 21 mm.
    #[arg(long)]
    pub eyepiece_mm: Option<f64>,
    #[command(flatten)]
    pub fovea: crate::fovea::FoveaArgs,
    #[command(flatten)]
    pub encoding: crate::args::EncodingArgs,
    #[command(flatten)]
    pub optics: crate::args::OpticsArgs,
}

impl ModelArgs {
    /// `--threads`, or the cores the CPU reports for 0.
    pub fn thread_count(&self) -> usize {
        match self.threads {
            0 => tensorholo::cnn::default_threads(),
            n => n as usize,
        }
    }

    /// The input files (`--model`, `--prefilter-model`, `--calibration`) for the output guard
    /// ([`crate::output::guard`]).
    pub fn guard_inputs(&self) -> Vec<crate::output::Input<'_>> {
        [
            ("--model", &self.model),
            ("--prefilter-model", &self.prefilter_model),
            ("--calibration", &self.calibration),
            ("--aberration", &self.aberration),
        ]
        .into_iter()
        .filter_map(|(flag, p)| Some(crate::output::Input::file(flag, p.as_deref()?)))
        .chain(self.optics.guard_input())
        .chain(self.plans.guard_input())
        .collect()
    }

    /// Reads the `--display` profile, if given (see [`crate::args::OpticsArgs::profile`]): once per command,
    /// passed to [`ModelArgs::profile_files`] and [`ModelArgs::pipeline`].
    pub fn profile(&self) -> Result<Option<DisplayProfile>> {
        self.optics.profile()
    }

    /// The files `profile` (the `--display` profile) names, its calibration and aberration file, as
    /// `(what, path)` for the output guard.
    pub fn profile_files(profile: Option<&DisplayProfile>) -> Vec<(&'static str, PathBuf)> {
        let Some(p) = profile else {
            return Vec::new();
        };
        [
            ("--display's calibration", &p.calibration),
            ("--display's aberration", &p.aberration),
        ]
        .into_iter()
        .filter_map(|(what, f)| Some((what, f.clone()?)))
        .collect()
    }

    /// The aberration correction of this run, as `(what, json, profile)`: `--aberration` or `--prescription`,
    /// else the profile's `aberration` or `prescription` (the SDK's rule, [`AberrationSource::select`]); `None`
    /// without one.
    fn aberration(
        &self,
        profile: Option<&DisplayProfile>,
        optics: &tensorholo::optics::OpticalSetup,
    ) -> Result<Option<(String, serde_json::Value, AberrationProfile)>> {
        let given = match (&self.aberration, &self.prescription) {
            (Some(path), _) => Some(AberrationSource::File(path.clone())),
            (None, Some(text)) => Some(AberrationSource::Prescription(parse_prescription(
                text,
                self.eyepiece_mm,
            )?)),
            (None, None) => None,
        };
        let by_flag = given.is_some();
        let Some(source) = AberrationSource::select(given, profile) else {
            return Ok(None);
        };
        let what = match (&source, by_flag) {
            (AberrationSource::File(path), true) => format!("--aberration {}", path.display()),
            (AberrationSource::File(path), false) => {
                format!("the --display profile's aberration {}", path.display())
            }
            (_, true) => "--prescription".to_string(),
            (_, false) => "the --display profile's prescription".to_string(),
        };
        let json = source.to_json();
        let resolved = source.resolve(optics).with_context(|| match &source {
            AberrationSource::File(_) => format!("cannot use {what}"),
            _ => what.clone(),
        })?;
        Ok(Some((what, json, resolved)))
    }

    /// The offset in millimetres: `--offset-mm`, else the profile's first offset, else 6.
    pub fn offset_mm(&self, profile: Option<&DisplayProfile>) -> f64 {
        self.offset_mm
            .or_else(|| profile.map(|p| p.default_offset_m() * 1e3))
            .unwrap_or(6.0)
    }

    /// The selected weight format.
    pub fn precision(&self) -> Precision {
        match (self.int8, self.precision) {
            (true, _) => DEFAULT_INT8,
            (false, Some(p)) => p.into(),
            (false, None) => Precision::F32,
        }
    }

    /// The pre-filter mode the flags ask for: `--no-prefilter` or an explicit `--encoding` → off,
    /// `--prefilter` → required, otherwise the SDK's automatic rule
    /// ([`HologramPipeline::with_shipped_prefilter`]).
    pub fn prefilter_mode(&self) -> PrefilterMode {
        if self.no_prefilter || self.encoding.encoding.is_some() {
            PrefilterMode::Off
        } else if self.prefilter {
            PrefilterMode::Required
        } else {
            PrefilterMode::Auto
        }
    }

    /// Loads the models for scenes of `input` (an RGB-D image or a layered depth image) and builds the
    /// pipeline; also returns a JSON description of what was loaded. `profile` is the `--display` profile the
    /// command read ([`ModelArgs::profile`]). Flags become the SDK's values ([`ModelArgs::config`]); which CNNs,
    /// pre-filter and aberration apply is the SDK's rule ([`ModelArgs::load`], [`ModelArgs::extras`]).
    pub fn pipeline(
        &self,
        input: SceneInput,
        profile: Option<&DisplayProfile>,
    ) -> Result<(HologramPipeline, serde_json::Value)> {
        let config = self.config(profile)?;
        let t = Instant::now();
        let pipeline = self.load(input, config, profile)?;
        let (pipeline, calibration, aberration) = self.extras(pipeline, profile)?;
        if pipeline.prefilter_model().is_none() {
            log::info!(
                "encoding without a pre-filter CNN: {}",
                pipeline.prefilter_reason()
            );
        }
        let mut info = self.describe(&pipeline, profile);
        info["calibration"] = json!(pipeline.calibration().map(|c| json!({
            "file": calibration.as_deref().map(crate::output::path_text),
            "summary": c.summary(),
        })));
        info["aberration"] = json!(aberration);
        info["load_s"] = json!(t.elapsed().as_secs_f64());
        Ok((pipeline, info))
    }

    /// The pipeline configuration the flags, the environment's CNN options
    /// ([`crate::args::cnn_options_from_env`]) and `profile` give. Errors: a bad offset or optical setup, a
    /// bad environment value.
    fn config(&self, profile: Option<&DisplayProfile>) -> Result<PipelineConfig> {
        let offset_mm = self.offset_mm(profile);
        crate::args::check_offset_mm(offset_mm)?;
        if self.eyepiece_mm.is_some()
            && self.prescription.is_none()
            && self.fovea.fovea_deg.is_none()
            && self.fovea.gaze.is_none()
        {
            bail!("--eyepiece-mm applies to --prescription and to --gaze/--fovea-deg: give one of them");
        }
        if let (Some(given), Some(p)) = (self.offset_mm, profile) {
            offset_against_profile(given, p);
        }
        let (_, encoding) = self.encoding.method(crate::args::Encoding::AaDpm);
        Ok(PipelineConfig {
            optics: self.optics.setup(profile)?,
            options: self.optics.options(),
            offset_m: offset_mm * 1e-3,
            encoding,
            backend: self.backend.into(),
            gpu_precision: self.gpu_precision.into(),
            wavelength_ratio_tolerance: self.wavelength_ratio_tolerance,
            foveation: self.fovea.options(self.eyepiece_mm)?,
            cnn: CnnOptions {
                layout: self.layout.into(),
                engine: self.engine.into(),
                threads: ThreadCount::from_count(self.threads as usize),
                tune: self.plans.tune,
                ..crate::args::cnn_options_from_env()?
            },
        })
    }

    /// The hologram CNN (`--model`'s file, which must take `input`, or the shipped one of `--layers`) and its
    /// pre-filter (`--prefilter-model`'s file, or the shipped one as [`ModelArgs::prefilter_mode`] says): the
    /// SDK's one rule ([`HologramPipeline::with_prefilter`]: a given pre-filter is used or refused, never
    /// dropped). Errors name the file or the shipped model, with what would serve the display.
    fn load(
        &self,
        input: SceneInput,
        config: PipelineConfig,
        profile: Option<&DisplayProfile>,
    ) -> Result<HologramPipeline> {
        let precision = self.precision();
        let expected = config.model_config(input.input_layers());
        let asked = crate::display::Requested {
            optics: &config.optics,
            offset_m: config.offset_m,
            tolerance: config.wavelength_ratio_tolerance,
            profile: self.optics.display.as_deref().zip(profile),
        };
        let hint = |what: String| {
            let asked = &asked;
            move |e| crate::display::with_serving_hint(e, &what, asked)
        };
        let hologram = match &self.model {
            Some(p) => HologramModel::from_path(p, ModelKind::Hologram, &expected)
                .map_err(hint(format!("--model {}", p.display())))?,
            None => tensorholo::model::embedded::scene_hologram_model(
                input,
                self.layers,
                precision,
                &expected,
            )
            .map_err(hint(format!("loading the shipped {input} hologram CNN")))?,
        };
        let source = match &self.prefilter_model {
            Some(p) => PrefilterSource::Given(Arc::new(
                HologramModel::from_path(p, ModelKind::PreFilter, &expected)
                    .map_err(hint(format!("--prefilter-model {}", p.display())))?,
            )),
            None => PrefilterSource::Shipped(self.prefilter_mode()),
        };
        let what = match &self.prefilter_model {
            Some(p) => format!("--prefilter-model {}", p.display()),
            None => "the pre-filter CNN".into(),
        };
        HologramPipeline::with_prefilter(Arc::new(hologram), source, precision, config)
            .map_err(hint(what))
    }

    /// `pipeline` with the saved plans (`--tuning`), the display calibration (`--calibration`, else the
    /// profile's) and the aberration correction ([`ModelArgs::aberration`]) applied; also the calibration file
    /// and the aberration's report entry. Errors name the flag or file at fault.
    fn extras(
        &self,
        mut pipeline: HologramPipeline,
        profile: Option<&DisplayProfile>,
    ) -> Result<(HologramPipeline, Option<PathBuf>, Option<serde_json::Value>)> {
        if let Some(plans) = self.plans.saved()? {
            pipeline = pipeline.with_saved_plans(plans)?;
        }
        let calibration = self
            .calibration
            .clone()
            .or_else(|| profile.and_then(|p| p.calibration.clone()));
        if let Some(path) = &calibration {
            let cal = tensorholo::slm::DisplayCalibration::read(path)?;
            log::info!("display calibration {}: {}", path.display(), cal.summary());
            pipeline = pipeline
                .with_calibration(Arc::new(cal))
                .with_context(|| format!("--calibration {}", path.display()))?;
        }
        let optics = pipeline.config().optics;
        let Some((what, mut source, aberration)) = self.aberration(profile, &optics)? else {
            return Ok((pipeline, calibration, None));
        };
        let given = self.prefilter || self.prefilter_model.is_some();
        pipeline = pipeline
            .with_aberration(Arc::new(aberration))
            .with_context(|| {
                if given {
                    format!(
                        "{what} with --prefilter/--prefilter-model (drop it: the pipeline then \
                         encodes with AA-DPM)"
                    )
                } else {
                    what.clone()
                }
            })?;
        let report = pipeline.aberration_report();
        if let Some(r) = &report {
            log::info!("aberration correction ({what}): {r}");
        }
        source["applied"] = json!(report);
        Ok((pipeline, calibration, Some(source)))
    }

    /// What was loaded, for report.json: the CNNs' source, precision and metadata, the engine settings, the
    /// encoding, the display and its mapping (the calibration, the aberration and the load time are added by
    /// [`ModelArgs::pipeline`]).
    fn describe(
        &self,
        pipeline: &HologramPipeline,
        profile: Option<&DisplayProfile>,
    ) -> serde_json::Value {
        let model = |m: &Arc<HologramModel>| {
            let md = m.metadata();
            json!({
                "layers": md.layers,
                "input_layers": md.input_layers,
                "offset_m": md.offset_m,
                "precision": md.precision,
                "trained_resolution": md.trained_resolution,
                "training_commit": md.training_commit,
                "macs_per_pixel": md.macs_per_pixel(),
                "hologram_layers": md.hologram_layers,
            })
        };
        let cnn = &pipeline.config().cnn;
        json!({
            "source": match (&self.model, &self.prefilter_model) {
                (None, None) => "shipped (embedded)".to_string(),
                (m, p) => {
                    let name = |f: &Option<PathBuf>| {
                        f.as_deref().map_or("none".to_string(), crate::output::path_text)
                    };
                    format!("files: {} {}", name(m), name(p))
                }
            },
            "precision": self.precision(),
            "prefilter_reason": pipeline.prefilter_reason(),
            "cnn_threads": self.threads,
            "cnn_layout": cnn.layout,
            "cnn_engine": cnn.engine,
            "cnn_conv": cnn.algorithm,
            "cnn_plans": match (&self.plans.tuning, self.plans.tune) {
                (Some(f), _) => json!({ "source": "saved", "file": crate::output::path_text(f) }),
                (None, true) => json!({ "source": "tune" }),
                (None, false) => json!({ "source": "table" }),
            },
            "hologram_cnn": model(pipeline.hologram_model()),
            "prefilter_cnn": pipeline.prefilter_model().map(model),
            "encoding": pipeline.encoding(),
            "display": self.optics.display.as_deref().map(crate::output::path_text),
            "display_name": profile.and_then(|p| p.name.clone()),
            "display_mapping": pipeline.display_mapping_description(),
            // The same as numbers: σ, the spread, the ceiling and the estimated cost (dB), the volume fit.
            "display_mapping_detail": pipeline.display_mapping(),
        })
    }
}

/// `--prescription SPHERE[,CYLINDER,AXIS]` (dioptres, degrees) behind an eyepiece of `eyepiece_mm`
/// millimetres (21 by default).
fn parse_prescription(text: &str, eyepiece_mm: Option<f64>) -> Result<Prescription> {
    let numbers = text
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<std::result::Result<Vec<f64>, _>>()
        .map_err(|_| {
            anyhow::anyhow!(
                "--prescription {text:?}: expected SPHERE or SPHERE,CYLINDER,AXIS (dioptres, dioptres, \
                 degrees), e.g. --prescription=-2.00,-0.75,30"
            )
        })?;
    let (sphere, cylinder, axis) = match numbers[..] {
        [s] => (s, 0.0, None),
        [s, c, a] => (s, c, Some(a)),
        _ => bail!(
            "--prescription {text:?}: give SPHERE or SPHERE,CYLINDER,AXIS (3 values with a cylinder: its \
             axis is needed), got {} values",
            numbers.len()
        ),
    };
    let mut rx = Prescription::new(sphere, cylinder, axis)
        .with_context(|| format!("--prescription {text}"))?;
    if let Some(mm) = eyepiece_mm {
        rx.eyepiece_focal_m = mm * 1e-3;
        rx.validate().context("--eyepiece-mm")?;
    }
    Ok(rx)
}

/// Warns where `--offset-mm` (millimetres) is none of the `--display` profile's offsets (metres): the
/// profile's offsets in millimetres, and the one meant where the flag was given the metres' number.
fn offset_against_profile(given_mm: f64, profile: &DisplayProfile) {
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1e-12);
    if profile.offsets_m.iter().any(|&o| close(o * 1e3, given_mm)) {
        return;
    }
    let list = profile
        .offsets_m
        .iter()
        .map(|o| format!("{}", (o * 1e12).round() / 1e9))
        .collect::<Vec<_>>()
        .join(", ");
    let meant = profile
        .offsets_m
        .iter()
        .find(|&&o| o != 0.0 && close(o, given_mm))
        .map_or(String::new(), |o| {
            format!(
                "; --offset-mm is in millimetres, the profile's offsets_m in metres: its {o} m is \
                 --offset-mm {}",
                (o * 1e12).round() / 1e9
            )
        });
    log::warn!(
        "--offset-mm {given_mm} is none of the display profile's offsets ({list} mm){meant}"
    );
}

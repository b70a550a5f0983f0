//! `holo render`: the real-time pipeline on one RGB-D frame with the shipped (or given) CNNs: hologram CNN →
//! offset propagation → pre-filter CNN → double phase → SLM codes, plus previews, timings and, with
//! `--evaluate`, the Table 2 scores against an SM-LBM ground truth of the same input.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use serde_json::json;
use tensorholo::cnn::{CnnEngine, CnnLayout, CnnOptions, ThreadCount};
use tensorholo::display::{AberrationProfile, AberrationSource, DisplayProfile, Prescription};
use tensorholo::evaluation::{focal_depths, table2};
use tensorholo::model::{contract, HologramModel, ModelKind, Precision, SceneInput};
use tensorholo::optics::{focal_stack, post_encoding_midpoint};
use tensorholo::pipeline::{
    AberrationReport, Backend, BackendReport, FrameTimings, GpuPrecision, Heads, HologramPipeline,
    PipelineConfig, PrefilterMode, PrefilterSource, SlmFrame,
};
use tensorholo::reference::{channel_means, preview_depths, ReferencePipeline};
use tensorholo::scene::RgbdFrame;
use tensorholo::synthesis::SmLbm;

use crate::args::Scene;

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
    /// its back focal plane; default: the paper's 21 mm).
    #[arg(long, requires = "prescription")]
    pub eyepiece_mm: Option<f64>,
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

    /// The `--display` profile, if given (see [`crate::args::OpticsArgs::profile`]).
    pub fn profile(&self) -> Result<Option<DisplayProfile>> {
        self.optics.profile()
    }

    /// The files the `--display` profile names (its calibration and aberration file, where the flags do not
    /// override them), as `(what, path)` for the output guard. A bad profile is an error here, before
    /// anything is written.
    pub fn profile_files(&self) -> Result<Vec<(&'static str, PathBuf)>> {
        let Some(p) = self.profile()? else {
            return Ok(Vec::new());
        };
        Ok([
            ("--display's calibration", p.calibration),
            ("--display's aberration", p.aberration),
        ]
        .into_iter()
        .filter_map(|(what, f)| Some((what, f?)))
        .collect())
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
    /// pipeline; also returns a JSON description of what was loaded.
    ///
    /// The hologram CNN: `--model`'s file (it must take `input`), or the shipped one of `--layers` for
    /// `input`. The pre-filter CNN: `--prefilter-model`'s file, or the shipped one as
    /// [`ModelArgs::prefilter_mode`] says; the rule is the SDK's (the CLI and the bindings share it).
    pub fn pipeline(&self, input: SceneInput) -> Result<(HologramPipeline, serde_json::Value)> {
        let profile = self.profile()?;
        let offset_mm = self.offset_mm(profile.as_ref());
        crate::args::check_offset_mm(offset_mm)?;
        if let (Some(given), Some(p)) = (self.offset_mm, profile.as_ref()) {
            offset_against_profile(given, p);
        }
        let (_, encoding) = self.encoding.method(crate::args::Encoding::AaDpm);
        let config = PipelineConfig {
            optics: self.optics.setup()?,
            options: self.optics.options(),
            offset_m: offset_mm * 1e-3,
            encoding,
            backend: self.backend.into(),
            gpu_precision: self.gpu_precision.into(),
            wavelength_ratio_tolerance: self.wavelength_ratio_tolerance,
            cnn: CnnOptions {
                layout: self.layout.into(),
                engine: self.engine.into(),
                threads: ThreadCount::from_count(self.threads as usize),
                tune: self.plans.tune,
                ..crate::args::cnn_options_from_env()?
            },
        };
        let precision = self.precision();
        let t = Instant::now();
        let expected = config.model_config(input.input_layers());
        let asked = crate::display::Requested {
            optics: &config.optics,
            offset_m: config.offset_m,
            tolerance: config.wavelength_ratio_tolerance,
            profile: self.optics.display.as_deref().zip(profile.as_ref()),
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
        // The SDK's one rule: a given pre-filter is used or refused (e.g. at 0 mm), never dropped.
        let source = match &self.prefilter_model {
            Some(p) => PrefilterSource::Given(Arc::new(
                HologramModel::from_path(p, ModelKind::PreFilter, &expected)
                    .map_err(hint(format!("--prefilter-model {}", p.display())))?,
            )),
            None => PrefilterSource::Shipped(self.prefilter_mode()),
        };
        let mut pipeline =
            HologramPipeline::with_prefilter(Arc::new(hologram), source, precision, config)
                .map_err(hint(match &self.prefilter_model {
                    Some(p) => format!("--prefilter-model {}", p.display()),
                    None => "the pre-filter CNN".into(),
                }))?;
        let calibration = self
            .calibration
            .clone()
            .or_else(|| profile.as_ref().and_then(|p| p.calibration.clone()));
        if let Some(plans) = self.plans.saved()? {
            pipeline = pipeline.with_saved_plans(plans)?;
        }
        if let Some(path) = &calibration {
            let cal = tensorholo::slm::DisplayCalibration::read(path)?;
            log::info!("display calibration {}: {}", path.display(), cal.summary());
            pipeline = pipeline
                .with_calibration(Arc::new(cal))
                .with_context(|| format!("--calibration {}", path.display()))?;
        }
        let mut aberration = None;
        if let Some((what, mut source, profile)) =
            self.aberration(profile.as_ref(), &config.optics)?
        {
            if self.prefilter && !pipeline.corrected_by_cnn() {
                bail!(
                    "{what}: --prefilter requires the DDPM pre-filter CNN, which was trained on uncorrected \
                     fields and falls below AA-DPM on corrected ones (docs/ABERRATION.md); drop --prefilter"
                );
            }
            let profile = Arc::new(profile);
            let report = if pipeline.corrected_by_cnn() {
                AberrationReport::by_cnn(&profile, config.offset_m)
            } else {
                AberrationReport::new(&profile, &config.optics, config.offset_m)
            };
            log::info!("aberration correction ({what}): {report}");
            pipeline = pipeline
                .with_aberration(profile)
                .with_context(|| what.clone())?;
            source["applied"] = json!(report);
            aberration = Some(source);
        }
        if pipeline.prefilter_model().is_none() {
            log::info!(
                "encoding without a pre-filter CNN: {}",
                pipeline.prefilter_reason()
            );
        }
        let describe = |m: &std::sync::Arc<HologramModel>| {
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
        let info = json!({
            "source": match (&self.model, &self.prefilter_model) {
                (None, None) => "shipped (embedded)".to_string(),
                (m, p) => {
                    let name = |f: &Option<PathBuf>| {
                        f.as_deref().map_or("none".to_string(), crate::output::path_text)
                    };
                    format!("files: {} {}", name(m), name(p))
                }
            },
            "precision": precision,
            "prefilter_reason": pipeline.prefilter_reason(),
            "cnn_threads": self.threads,
            "cnn_layout": pipeline.config().cnn.layout,
            "cnn_engine": pipeline.config().cnn.engine,
            "cnn_conv": pipeline.config().cnn.algorithm,
            "cnn_plans": match (&self.plans.tuning, self.plans.tune) {
                (Some(f), _) => json!({ "source": "saved", "file": crate::output::path_text(f) }),
                (None, true) => json!({ "source": "tune" }),
                (None, false) => json!({ "source": "table" }),
            },
            "hologram_cnn": describe(pipeline.hologram_model()),
            "prefilter_cnn": pipeline.prefilter_model().map(describe),
            "encoding": pipeline.encoding(),
            "calibration": pipeline.calibration().map(|c| json!({
                "file": calibration.as_deref().map(crate::output::path_text),
                "summary": c.summary(),
            })),
            "aberration": aberration,
            "display": self.optics.display.as_deref().map(crate::output::path_text),
            "display_name": profile.as_ref().and_then(|p| p.name.clone()),
            "display_mapping": pipeline.display_mapping_description(),
            // The same as numbers: σ, the spread, the ceiling and the estimated cost (dB), the volume fit.
            "display_mapping_detail": pipeline.display_mapping(),
            "load_s": t.elapsed().as_secs_f64(),
        });
        Ok((pipeline, info))
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

/// Arguments of `holo render`.
#[derive(Debug, Args)]
#[command(after_long_help = format!("{EXAMPLES}\n\n{}", crate::output::OUTPUTS_HELP))]
pub struct RenderArgs {
    #[command(flatten)]
    scene: crate::args::SceneArgs,
    #[command(flatten)]
    model: ModelArgs,
    /// Timed repetitions of the frame after the first (warm-up) one; report.json gives their medians.
    #[arg(long, default_value_t = 3)]
    repeat: usize,
    /// Also compute the SM-LBM ground truth of the input (--levels planes) and score the CNN's midpoint
    /// hologram and what the SLM shows with the paper's Table 2 protocol (PSNR/SSIM of the amplitude and of
    /// a 15 + 5-depth focal stack), next to SM-LBM + the same double phase method without CNN.
    #[arg(long)]
    evaluate: bool,
    /// SM-LBM depth planes of the --evaluate ground truth.
    #[arg(long, default_value_t = 2048)]
    levels: usize,
    /// Also write cnn_input.npy: the hologram CNN's input, float32 [4·L, H, W] (per input layer R, G, B
    /// amplitude then normalised depth, 0 = near; docs/CONVENTIONS.md §7), e.g. to calibrate int8 files on
    /// real frames (`python -m tensorholo_training.export --calib-npy`).
    #[arg(long)]
    save_cnn_input: bool,
    #[command(flatten)]
    refine: crate::refine::RefineArgs,
    /// Output folder (created if missing). Files of the same names in it are replaced; inputs never are.
    #[arg(long)]
    out: PathBuf,
}

const EXAMPLES: &str = "\
Examples:
  holo render --out out/render
      shipped 8-layer CNN on the built-in scene (384x384), SLM 6 mm away, shipped 6 mm pre-filter CNN (DDPM)
  holo render --no-prefilter --out out/aadpm
      the same encoded with AA-DPM instead of the pre-filter CNN (non-learned; faster)
  holo render --layers 30 --int8 --offset-mm 12 --evaluate --out out/render30
      the 30-layer int8 model, scored against the SM-LBM ground truth
  holo render --rgb derived_rgb_576x768.png --depth disparity_aux_576x768.jpg \\
      --depth-encoding iphone-disparity --out out/vase
  holo render --ldi out/ldi_test0 --depth-encoding relative16 --evaluate --out out/ldi
      a layered depth image (rgb_K.png, depth_K.png, front first) with the shipped LDI CNN, scored
      against the SM-LBM of all its layers
  holo render --model my.onnx --prefilter-model my.prefilter.onnx --out out/mine
  holo render --display lcos_3.74um.json --out out/lcos
      a display profile (docs/DISPLAYS.md): the shipped 8 µm models serve it at the mapped volume and offset";

/// Runs `holo render`.
pub fn run(args: &RenderArgs) -> Result<()> {
    let t_all = Instant::now();
    let refine = args.refine.request(false)?;
    // A bad display profile stops the command before anything is written; the files it names are inputs too.
    let profile_files = args.model.profile_files()?;
    let mut inputs = args.scene.guard_inputs();
    inputs.extend(args.model.guard_inputs());
    inputs.extend(
        profile_files
            .iter()
            .map(|(what, f)| crate::output::Input::file(what, f)),
    );
    crate::output::guard("--out", &args.out, &inputs)?;
    let t = Instant::now();
    let (scene, source) = args.scene.load()?;
    let load_s = t.elapsed().as_secs_f64();
    // A display no model serves stops the command before anything is written too; an earlier run's report
    // in the folder goes, so that it is not taken for this run's.
    let (pipeline, models) =
        crate::output::before_writing(&args.out, args.model.pipeline(scene.input()))?;
    crate::output::prepare(&args.out, &inputs)?;
    let (h, w) = scene.size();
    // What runs: the model file's own depth and precision (a --model file need not match --layers/--precision).
    let cnn = pipeline.hologram_model().metadata();
    log::info!(
        "{h}×{w} frame ({}), {}-layer {} CNN {}, offset {} mm, {}",
        source["kind"].as_str().unwrap_or("?"),
        cnn.layers,
        scene.input(),
        cnn.precision,
        pipeline.config().offset_m * 1e3,
        if pipeline.prefilter_model().is_some() {
            "pre-filter CNN + DPM (DDPM)".to_string()
        } else {
            format!("{:?}", pipeline.encoding())
        }
    );
    let t = Instant::now();
    let mut session = pipeline
        .session(h, w)
        .map_err(|e| args.model.plans.blame(e))?;
    let session_s = t.elapsed().as_secs_f64();
    args.model
        .plans
        .write_tuning(&args.out, session.plan_report())?;
    let what = || match args.scene.inputs().as_slice() {
        [] => "the built-in scene".to_string(),
        files => files
            .iter()
            .map(|f| format!("`{}`", f.display()))
            .collect::<Vec<_>>()
            .join(" + "),
    };
    let mut render = || -> Result<FrameTimings> {
        let out = match &scene {
            Scene::Frame(frame) => session.render(frame),
            Scene::Ldi(ldi) => session.render_ldi(ldi),
        };
        Ok(out.with_context(what)?.timings)
    };
    let first = render()?;
    let mut timed = Vec::new();
    for _ in 0..args.repeat {
        timed.push(render()?);
    }
    let med = FrameTimings::median(&timed);
    let fps = if med.total_s > 0.0 {
        1.0 / med.total_s
    } else {
        0.0
    };
    if med.gpu_s > 0.0 {
        // On the GPU the stages run in one submission: the CPU checks (or packs) the input, the GPU does the rest.
        log::info!(
            "session {:.0} ms; first frame {:.0} ms; then (median of {}) input {:.1} ms (CPU: checks, packing where needed), GPU \
             {:.1} ms (upload, both CNNs, optics, encoding, download; `holo bench --backend gpu` times each \
             stage), total {:.1} ms ({fps:.2} FPS)",
            session_s * 1e3,
            first.total_s * 1e3,
            timed.len(),
            med.cnn_s * 1e3,
            med.gpu_s * 1e3,
            med.total_s * 1e3,
        );
    } else {
        log::info!(
            "session {:.0} ms; first frame {:.0} ms; then (median of {}) CNN {:.1} ms, offset {:.1} ms, \
             pre-filter {:.1} ms, encoding {:.1} ms, total {:.1} ms ({fps:.2} FPS)",
            session_s * 1e3,
            first.total_s * 1e3,
            timed.len(),
            med.cnn_s * 1e3,
            med.offset_s * 1e3,
            med.prefilter_s * 1e3,
            med.encoding_s * 1e3,
            med.total_s * 1e3,
        );
    }
    // The peak up to here: the inputs, the session and its frames (the previews' share is reported apart).
    let frames_peak = crate::memory::peak_rss_mib();
    // The previews and reconstructions below need only the last frame: the session's buffers go first.
    let (plan_report, backend_report) = (
        session.plan_report().clone(),
        session.backend_report().clone(),
    );
    let (mut out, heads) = session.into_last_frame();
    let heads = heads.context("no frame rendered")?;
    let refined = match refine {
        Some(request) => {
            let mut refiner = crate::refine::frame_refiner(
                request,
                &pipeline,
                &backend_report,
                args.model.thread_count(),
            )?;
            let midpoint = heads.to_field()?;
            let r = refiner.refine(
                &scene.layers(),
                Some(midpoint.view()),
                out.codes.view(),
                &mut crate::refine::log_progress(request.options.iterations),
            )?;
            let report = crate::refine::report(&refiner, &r);
            let (target_s, iterations_s) = (r.target_s, r.report.iterations_s);
            crate::refine::apply(r, &mut out);
            Some((report, target_s, iterations_s))
        }
        None => None,
    };
    write_outputs(
        args,
        &pipeline,
        LastFrame {
            out: &out,
            heads,
            backend: &backend_report,
        },
        &scene,
        source,
        models,
        |report| {
            report["cnn_plan"] = json!(plan_report);
            report["timings_s"] = json!({
                "load": load_s,
                "session_setup": session_s,
                "first_frame": first,
                "median": med,
                "repeats": timed,
                "fps_median": if med.total_s > 0.0 { 1.0 / med.total_s } else { 0.0 },
            });
            if let Some((refine, target_s, iterations_s)) = &refined {
                report["timings_s"]["refine_target_s"] = json!(target_s);
                report["timings_s"]["refine_iterations_s"] = json!(iterations_s);
                report["refine"] = refine.clone();
            }
            report["frames_peak_rss_mib"] = json!(frames_peak);
        },
    )?;
    log::info!(
        "wrote {} in {:.1} s",
        args.out.display(),
        t_all.elapsed().as_secs_f64()
    );
    Ok(())
}

/// What [`write_outputs`] needs of a session that has ended ([`tensorholo::pipeline::HologramSession::into_last_frame`]).
struct LastFrame<'a> {
    out: &'a SlmFrame,
    heads: Heads,
    backend: &'a BackendReport,
}

/// Previews, midpoint, codes, optional evaluation and report.json of the session's last frame.
fn write_outputs(
    args: &RenderArgs,
    pipeline: &HologramPipeline,
    last: LastFrame<'_>,
    scene: &Scene,
    source: serde_json::Value,
    models: serde_json::Value,
    add: impl FnOnce(&mut serde_json::Value),
) -> Result<()> {
    let cfg = pipeline.config();
    let out = last.out;
    let front = scene.front();
    let frame: &RgbdFrame = &front;
    let midpoint = last.heads.to_field()?;
    drop(last.heads);
    let t = Instant::now();
    let displayed = post_encoding_midpoint(
        out.phase.view(),
        out.amplitude_scale,
        &cfg.optics,
        cfg.offset_m,
        cfg.options,
    )?;
    let depths = preview_depths(frame.depth.iter());
    let focus = focal_stack(
        displayed.view(),
        &cfg.optics,
        0.0,
        &depths,
        cfg.options,
        false,
    )?;
    // The displayed field is kept only for the evaluation (50 MB at 1080p).
    let displayed = args.evaluate.then_some(displayed);
    let ideal = focal_stack(
        midpoint.view(),
        &cfg.optics,
        0.0,
        &depths,
        cfg.options,
        false,
    )?;
    let reconstruction_s = t.elapsed().as_secs_f64();
    let images = crate::output::Images {
        codes: out.codes.view(),
        midpoint: midpoint.view(),
        focus: &focus,
        ideal: Some(&ideal),
        depths: &depths,
    };
    let focus_stats = crate::output::write_images(&args.out, &images, &cfg.optics, frame)?;
    if args.save_cnn_input {
        let layers = pipeline.hologram_model().metadata().input_layers;
        let mut x = ndarray::Array3::<f32>::zeros((4 * layers, frame.height(), frame.width()));
        match scene {
            Scene::Frame(f) if layers == 1 => contract::pack_rgbd(f, x.view_mut())?,
            Scene::Frame(f) => contract::pack_ldi(&f.clone().into(), x.view_mut())?,
            Scene::Ldi(ldi) => contract::pack_ldi(ldi, x.view_mut())?,
        }
        tensorholo::io::write_f32_npy(&args.out.join("cnn_input.npy"), x.view())?;
    }
    let evaluation = match &displayed {
        Some(displayed) => Some(evaluate(
            args, pipeline, scene, frame, &midpoint, displayed,
        )?),
        None => None,
    };
    let amp = midpoint.mapv(|v| v.norm());
    let mut report = json!({
        "tensorholo_version": env!("CARGO_PKG_VERSION"),
        "command": crate::output::command_line(),
        "input": source,
        "size": [frame.height(), frame.width()],
        "models": models,
        "pipeline": cfg,
        // Which backend ran the frame (every stage: the GPU path runs the whole frame, or none of it) and why.
        "backend": last.backend,
        "frame_backend": out.backend,
        "reconstruction_s": reconstruction_s,
        "statistics": {
            "scene_mean_amplitude_rgb": channel_means(&frame.amplitude),
            "midpoint_mean_amplitude_rgb": channel_means(&amp),
            "midpoint_max_amplitude": amp.iter().copied().fold(0.0f32, f32::max),
            "double_phase_amplitude_scale": out.amplitude_scale,
            "double_phase_mean_phase_rad": out.mean_phase,
            "focus": focus_stats,
        },
        "evaluation": evaluation,
    });
    add(&mut report);
    // The whole run's peak resident memory (session, previews, report images), and what the previews and
    // report images add over the frames' peak (`frames_peak_rss_mib`, set by `add`): scripts/memory-guard.sh.
    let peak = crate::memory::peak_rss_mib();
    report["peak_rss_mib"] = json!(peak);
    let frames = report["frames_peak_rss_mib"].as_f64();
    if let (Some(all), Some(frames)) = (peak, frames) {
        report["previews_added_mib"] = json!((all - frames).max(0.0));
        log::info!(
            "peak resident memory {all:.0} MiB: {frames:.0} MiB up to the last frame, the previews and report \
             images {:.0} MiB more",
            (all - frames).max(0.0)
        );
    }
    crate::args::write_json(&args.out.join("report.json"), &report)
}

/// The Table 2 scores of the CNN midpoint hologram, of what the SLM shows, and of SM-LBM + the same
/// encoding without CNN, all against the SM-LBM ground truth of the input (every layer of an LDI); focal
/// depths from `front`, the scene's front layer.
fn evaluate(
    args: &RenderArgs,
    pipeline: &HologramPipeline,
    scene: &Scene,
    front: &RgbdFrame,
    midpoint: &ndarray::Array3<num_complex::Complex32>,
    displayed: &ndarray::Array3<num_complex::Complex32>,
) -> Result<serde_json::Value> {
    let cfg = pipeline.config();
    let t = Instant::now();
    let reference = ReferencePipeline {
        synthesis: SmLbm {
            levels: args.levels,
            setup: cfg.optics,
            options: cfg.options,
            silhouette_masks: true,
        },
        offset_m: cfg.offset_m,
        encoding: cfg.encoding,
    };
    log::info!(
        "--evaluate: SM-LBM ground truth with {} planes ...",
        args.levels
    );
    let gt = reference.run(&scene.layers(), &|_, _| {})?;
    let reference_displayed = post_encoding_midpoint(
        gt.double_phase.phase.view(),
        gt.double_phase.amplitude_scale,
        &cfg.optics,
        cfg.offset_m,
        cfg.options,
    )?;
    let depths = focal_depths(front.depth.view(), 200, 15, 5, 0)?;
    let score = |pred: &ndarray::Array3<num_complex::Complex32>| {
        table2(
            pred.view(),
            gt.midpoint.view(),
            &cfg.optics,
            cfg.options,
            &depths,
        )
    };
    let cnn = score(midpoint)?;
    let shown = score(displayed)?;
    let reference_shown = score(&reference_displayed)?;
    // On another display than the model's own, what the mapping itself costs: SM-LBM of the same scene at
    // the model's training display (what a perfect model computes; the SDK shows it on this display as
    // is), scored at this display. The ceiling any mapped model reaches (docs/DISPLAYS.md).
    let mapping = pipeline.display_mapping();
    let mapping_ceiling = if mapping.is_identity() {
        None
    } else {
        let trained = SmLbm {
            levels: args.levels,
            setup: mapping.trained,
            options: cfg.options,
            silhouette_masks: true,
        }
        .synthesize(&scene.layers(), &|_, _| {})?;
        Some(score(&trained)?)
    };
    log::info!(
        "Table 2 vs SM-LBM ({} planes): CNN midpoint {:.2} dB / SSIM {:.3} (focal stack {:.2} dB / {:.3}); \
         displayed {:.2} dB (focal stack {:.2} dB); SM-LBM + {:?} displayed {:.2} dB (focal stack {:.2} dB)",
        args.levels,
        cnn.psnr_amp,
        cnn.ssim_amp,
        cnn.psnr_fs,
        cnn.ssim_fs,
        shown.psnr_amp,
        shown.psnr_fs,
        cfg.encoding,
        reference_shown.psnr_amp,
        reference_shown.psnr_fs
    );
    Ok(json!({
        "ground_truth": {
            "method": match scene {
                Scene::Frame(_) => "SM-LBM (Eq. 1-4) of the RGB-D input",
                Scene::Ldi(_) => "SM-LBM (Eq. 1-4) of every layer of the LDI input",
            },
            "levels": args.levels,
        },
        "focal_depths": depths,
        "cnn_midpoint": cnn,
        "displayed": shown,
        "smlbm_encoded_displayed": {"encoding": cfg.encoding, "scores": reference_shown},
        // Present on another display than the model's training display: SM-LBM at the training display,
        // shown on this one, against SM-LBM at this one.
        "mapping_ceiling": mapping_ceiling,
        "seconds": t.elapsed().as_secs_f64(),
    }))
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

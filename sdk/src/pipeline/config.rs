//! The pipeline's configuration: display and encoding settings ([`PipelineConfig`]), where frames run
//! ([`Backend`], [`GpuPrecision`]) and the size limit of a session ([`MAX_HOLOGRAM_PIXELS`]). Imports nothing
//! of the pipeline: every executor may read it.

use crate::cnn::CnnOptions;
use crate::encoding::DoublePhaseMethod;
use crate::error::{invalid, HoloError, Result};
use crate::foveation::FoveationOptions;
use crate::model::ModelConfig;
use crate::optics::{OpticalSetup, PropagationOptions};

/// The largest hologram a session (and so a generator) makes, in pixels (`width · height`): 8192 × 8192, four
/// times a 4K SLM. Above it the buffers of one session (≈ 200 bytes a pixel) would not fit a phone. Checked
/// before anything is allocated ([`super::HologramPipeline::session`]).
pub const MAX_HOLOGRAM_PIXELS: usize = crate::display::MAX_SLM_PIXELS;

/// Where a [`HologramSession`](crate::pipeline::HologramSession) computes its frames.
///
/// - [`Backend::Cpu`]: the CPU CNN engine (native or tract, [`crate::cnn`]) and rustfft for the optics (the
///   reference).
/// - [`Backend::Gpu`]: the whole frame in WGSL compute shaders through wgpu (Metal on iOS, Vulkan on Android
///   and Linux; cargo feature `gpu`, module `gpu`), any adapter including a software one. Session creation
///   fails with [`HoloError::Gpu`] where there is none.
/// - [`Backend::Auto`] (the default): the GPU where a hardware adapter exists, the session can be built on it
///   and its first frame passes a self-check against the CPU path; otherwise the CPU. The reason is logged and
///   kept in [`HologramSession::backend_report`](crate::pipeline::HologramSession::backend_report). On desktop Linux without a GPU device node (`/dev/dri/
///   renderD*`, `/dev/nvidia0`, `/dev/dxg`) the drivers are not even loaded: only a software adapter could
///   answer, and loading Mesa's costs about 50 MiB that stays resident.
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
    pub(crate) fn name(self) -> &'static str {
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
    /// Hidden activations stored as f16 (half the memory and traffic), products and sums in f32; the
    /// network's input and output stay f32. Needs the device's `SHADER_F16` (f32 without it). Within 4.1e-4
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

    #[cfg(feature = "gpu")]
    /// What runs on an adapter with (`shader_f16`) or without f16 shaders: [`GpuPrecision::F32`] or
    /// [`GpuPrecision::F16`].
    pub(crate) fn resolve(self, shader_f16: bool) -> Self {
        match self {
            Self::F16 | Self::Auto if shader_f16 => Self::F16,
            _ => Self::F32,
        }
    }
}

/// Display and encoding settings of a [`HologramPipeline`](crate::pipeline::HologramPipeline).
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
    /// How the CPU CNNs run ([`CnnOptions`]: engine, layout, threads, algorithm, tuning, strips, slabs and the
    /// kernels' instruction set; the default: every decision the plan table's, on the cores the CPU reports).
    pub cnn: CnnOptions,
    /// Where sessions compute their frames ([`Backend`]; default [`Backend::Auto`]).
    pub backend: Backend,
    /// The GPU CNNs' arithmetic (default [`GpuPrecision::Auto`]: f16 where the adapter has it); f16 falls back
    /// to f32 on an adapter without `SHADER_F16` (the backend report says so).
    pub gpu_precision: GpuPrecision,
    /// Largest relative spread (a fraction: 0.01 = 1 %) of the per-colour depth scales accepted when the
    /// models were trained for another, Fresnel-equivalent display (`docs/DISPLAYS.md`,
    /// [`crate::display::DisplayMapping`]); `None` (the default): the serving rule's, the spread whose
    /// estimated cost stays within [`crate::display::MAPPING_COST_BUDGET_DB`] of the model's own score. A
    /// wider value shows in [`HologramPipeline::display_mapping`](crate::pipeline::HologramPipeline::display_mapping).
    pub wavelength_ratio_tolerance: Option<f64>,
    /// Foveated frames ([`HologramSession::render_foveated`](crate::pipeline::HologramSession::render_foveated),
    /// `docs/FOVEATION.md`): the fovea, its blend band and the periphery's blur; `None` (the default): a
    /// session plans no tile and renders full frames only.
    pub foveation: Option<FoveationOptions>,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            optics: OpticalSetup::default(),
            options: PropagationOptions::default(),
            offset_m: 0.0,
            encoding: DoublePhaseMethod::default(),
            cnn: CnnOptions::default(),
            backend: Backend::default(),
            gpu_precision: GpuPrecision::default(),
            wavelength_ratio_tolerance: None,
            foveation: None,
        }
    }
}

impl PipelineConfig {
    /// What the models of a session with this configuration must have been trained for: this display
    /// (`optics`), this offset and wavelength tolerance, and `input_layers` (1 for RGB-D, 5 for a layered depth
    /// image), as [`crate::model::HologramModel::from_path`] and the shipped models check it.
    pub fn model_config(&self, input_layers: usize) -> ModelConfig {
        ModelConfig {
            optics: self.optics,
            offset_m: self.offset_m,
            input_layers,
            wavelength_ratio_tolerance: self.wavelength_ratio_tolerance,
        }
    }
}

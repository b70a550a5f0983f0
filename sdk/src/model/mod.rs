//! The CNNs of Tensor Holography V2 (`docs/CONVENTIONS.md` §7, paper Fig. 3): the hologram CNN (RGB-D or
//! LDI → midpoint hologram) and the DDPM pre-filter CNN (offset hologram → filtered offset hologram, Eq. 6).
//!
//! A [`HologramModel`] is loaded once from an ONNX file written by `training/tensorholo_training/export.py`:
//!
//! 1. the protobuf is decoded with the SDK's own reader of the ONNX schema (`model/onnx.rs`; a truncated or
//!    corrupt file → [`HoloError::ModelLoad`](crate::HoloError));
//! 2. its `tensorholo.*` `metadata_props` are parsed into [`ModelMetadata`] and checked against a
//!    [`ModelConfig`] (wavelengths, pitch, volume depth, offset, input layers → a mismatch is
//!    [`HoloError::ModelMetadata`](crate::HoloError) naming the key, the file's value and the expected one);
//! 3. its graph inputs/outputs are checked against the contract (hologram CNN: `rgbd` `[1,4L,H,W]` →
//!    `amplitude`, `phase` `[1,3,H,W]`; pre-filter (format 2): `slm_field` `[1,6,H,W]` = `[Re H, Im H]` →
//!    `real`, `imag` `[1,3,H,W]`; f32 → otherwise [`HoloError::ModelContract`](crate::HoloError));
//! 4. the engines read it: the native CPU engine and the GPU path through [`CnnWeights`] (the graph read as
//!    the TensorHolo residual CNN, `model/graph.rs`); with the cargo feature `tract` (on by default), tract
//!    also types and declutters it once, keeping `H`, `W` symbolic (`model/tract.rs`).
//!
//! Without `tract`, a file that is not the TensorHolo residual CNN (and every int8 QOperator file) is refused
//! at load with a [`HoloError::ModelContract`](crate::HoloError) naming the feature: the native engine and the
//! GPU run the shipped models and any file of their architecture.
//!
//! With `tract`, `HologramModel::plan` binds `H`, `W` to one resolution and optimises (codegen) the graph for
//! it; plans are cached per resolution inside the model, because tract's symbolic plan runs 6–11× slower than
//! a concretised one. int8 files: QOperator (`QLinearConv`, conv-only) and QDQ (`QuantizeLinear`/
//! `DequantizeLinear` around float `Conv`) both load; value-info hints are ignored when tract parses because
//! tract 0.23 refuses the QDQ file's quantised value infos otherwise.

pub mod contract;
#[cfg(feature = "embedded-models")]
pub mod embedded;
pub mod graph;
mod metadata;
mod network;
pub(crate) mod onnx;
#[cfg(feature = "tract")]
mod tract;
#[cfg(feature = "tract")]
mod tract_model;
pub(crate) mod tuning;

/// The scene representation a hologram CNN takes (`tensorholo.input_layers`, `docs/CONVENTIONS.md` §7.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum SceneInput {
    /// An RGB-D image, `[4, H, W]` (one layer: R, G, B amplitude, depth).
    #[default]
    Rgbd,
    /// A layered depth image of up to [`LDI_INPUT_LAYERS`] layers front to back, `[4·5, H, W]` (paper Fig. 1;
    /// fewer layers are padded with empty ones).
    Ldi,
}

/// Layers of the LDI input the shipped LDI hologram CNNs take (the paper's 5).
pub const LDI_INPUT_LAYERS: usize = 5;

impl SceneInput {
    /// `L` of the CNN input `[4·L, H, W]`: 1 or [`LDI_INPUT_LAYERS`].
    pub fn input_layers(self) -> usize {
        match self {
            Self::Rgbd => 1,
            Self::Ldi => LDI_INPUT_LAYERS,
        }
    }

    /// The name in shipped file names (`holo8_rgbd.onnx`, `holo8_ldi.onnx`): `rgbd` or `ldi`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Rgbd => "rgbd",
            Self::Ldi => "ldi",
        }
    }
}

impl std::fmt::Display for SceneInput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// How a model file stores its weights (`training/tensorholo_training/export.py`). All forms take and
/// return f32 at the boundary (`docs/CONVENTIONS.md` §7).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Precision {
    /// 32-bit float weights and activations (`NAME.onnx`).
    F32,
    /// int8 QOperator form: `QLinearConv` with int8 weights and uint8 activations, residual adds in float
    /// (`NAME.int8-qop.onnx`; tract runs real int8 kernels).
    Int8QOperator,
    /// int8 QDQ form: `QuantizeLinear`/`DequantizeLinear` pairs around float `Conv` (`NAME.int8-qdq.onnx`;
    /// tract 0.23 computes in f32 with the quantisation error). The shipped pre-filters' are mixed precision:
    /// their first and last convolutions keep f32 weights (metadata `tensorholo.int8_float_convs`,
    /// `docs/CONVENTIONS.md` §7).
    Int8Qdq,
}

impl Precision {
    /// All forms, f32 first.
    pub const ALL: [Precision; 3] = [Self::F32, Self::Int8QOperator, Self::Int8Qdq];

    /// The file-name suffix before `.onnx` (`""`, `".int8-qop"`, `".int8-qdq"`).
    pub fn file_suffix(self) -> &'static str {
        match self {
            Self::F32 => "",
            Self::Int8QOperator => ".int8-qop",
            Self::Int8Qdq => ".int8-qdq",
        }
    }

    /// The form a model's `tensorholo.precision` metadata names ([`ModelMetadata::precision`]: `f32`,
    /// `int8-qoperator-conv`, `int8-qdq-conv`); `None` for another value.
    pub fn from_metadata(value: &str) -> Option<Self> {
        match value {
            "f32" => Some(Self::F32),
            "int8-qoperator-conv" => Some(Self::Int8QOperator),
            "int8-qdq-conv" => Some(Self::Int8Qdq),
            _ => None,
        }
    }

    /// Short name: `f32`, `int8-qop`, `int8-qdq`.
    pub fn name(self) -> &'static str {
        match self {
            Self::F32 => "f32",
            Self::Int8QOperator => "int8-qop",
            Self::Int8Qdq => "int8-qdq",
        }
    }
}

/// The int8 form apps get when they ask for "int8": the QDQ form, the fastest int8 form that loses at most
/// 0.5 dB against f32 (`docs/BENCHMARKS.md`, `models/MODEL_CARD.md`). `holo --int8` and the bindings'
/// `Precision.Int8` both mean this.
pub const DEFAULT_INT8: Precision = Precision::Int8Qdq;

impl std::fmt::Display for Precision {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The memory layout tract runs a CNN in. The ONNX files are always channels-first `[1, C, H, W]`
/// (`docs/CONVENTIONS.md` §7) and a plan takes and returns `[C, H, W]` arrays in every layout; only tract's
/// internal graph differs (`HologramModel::plan_with_layout` (feature `tract`)).
///
/// Which layout is faster depends on the CPU and the frame size (`docs/BENCHMARKS.md`: on one 2-core Xeon
/// channels-first won at large frames, on another channels-last was 2.2× faster at 384×384), so the default
/// is [`CnnLayout::Auto`]: the candidates are timed on the machine at session creation
/// (`HologramModel::tuned_plan` (feature `tract`)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum CnnLayout {
    /// Time both layouts on this machine at the real resolution and keep the faster
    /// (`HologramModel::tuned_plan` (feature `tract`)); a plan never runs in `Auto` itself.
    #[default]
    Auto,
    /// Channels first (NCHW), as in the file. tract 0.23 runs the 3×3 convolutions as its direct spatial
    /// convolution (a filter along W, four output channels at a time) where the rows are ≥ 128 pixels wide.
    ChannelsFirst,
    /// Channels last (NHWC): the whole graph is moved by tract's axis-change propagation, and the
    /// convolutions run as a lazy im2col (one gather per output pixel of 3 contiguous runs of 3·C values)
    /// feeding tract's matrix-product kernels, after an explicit zero `Pad`. f32 and int8 QDQ files (float
    /// convolutions); tract 0.23 does not move a quantised `QLinearConv` nor the pre-filter graph, so those
    /// files in this layout are an error (and `Auto` skips it for them).
    ChannelsLast,
}

impl CnnLayout {
    /// The two concrete layouts, channels-first first.
    pub const ALL: [CnnLayout; 2] = [Self::ChannelsFirst, Self::ChannelsLast];

    /// Short name: `auto`, `nchw`, `nhwc`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::ChannelsFirst => "nchw",
            Self::ChannelsLast => "nhwc",
        }
    }
}

impl std::fmt::Display for CnnLayout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The engine that runs a session's CNNs on the CPU
/// ([`PipelineConfig::cnn_engine`](crate::pipeline::PipelineConfig::cnn_engine)).
///
/// - [`CnnEngine::Native`]: our direct 3×3 convolution kernels (`tensorholo-kernels`: AVX-512, AVX2+FMA,
///   NEON or portable scalar rows, chosen at run time from the CPU's features), row bands on the plan's own
///   threads. f32 files (agree with tract to float rounding) and int8 QDQ files (u8 × s8 kernels, each layer's
///   convolution, ReLU, residual and requantisation fused; a mixed-precision file's f32 first and last layers
///   on the f32 kernels: within the models' int8 tolerance of tract's node-by-node execution;
///   `sdk/src/cnn/tests.rs`).
/// - [`CnnEngine::Tract`]: tract's optimised plans (any file that passes the contract, int8 included).
/// - [`CnnEngine::Auto`] (the default): where the native engine can run the file, both are timed at session
///   creation on this machine ([`timing_resolution`]) and the faster runs; int8 QOperator files run on
///   tract. The choice and the timings are in [`PlanReport`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum CnnEngine {
    /// Time both engines where the native one can run the file; keep the faster.
    #[default]
    Auto,
    /// Our direct-convolution kernels (an error at session creation for a file they cannot run).
    Native,
    /// tract.
    Tract,
}

impl CnnEngine {
    /// Short name: `auto`, `native`, `tract`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Native => "native",
            Self::Tract => "tract",
        }
    }

    /// Parses [`CnnEngine::name`]. Errors: [`crate::HoloError::InvalidParameter`] (`engine`) naming the
    /// choices.
    pub fn parse(name: &str) -> crate::error::Result<Self> {
        match name {
            "auto" => Ok(Self::Auto),
            "native" => Ok(Self::Native),
            "tract" => Ok(Self::Tract),
            other => Err(crate::error::invalid(
                "engine",
                format!("unknown CNN engine `{other}` (auto, native or tract)"),
            )),
        }
    }
}

impl std::fmt::Display for CnnEngine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

pub use contract::{head_to_phasor, heads_to_field};
pub use graph::{CnnOutput, CnnQuant, CnnWeights, ConvLayer, LayerQuant, QuantGrid};
pub use metadata::{
    ModelConfig, ModelKind, ModelMetadata, FORMAT_VERSION, METADATA_PREFIX,
    PREFILTER_FORMAT_VERSION,
};
pub use network::{HologramModel, MAX_CNN_THREADS};
#[cfg(feature = "tract")]
pub use tract::{set_cnn_threads, ModelPlan, NodeTiming};
pub use tuning::{
    auto_thread_candidates, timing_resolution, PlanReport, PlanRequest, PlanTiming, ThreadCount,
    TUNE_MIN_ROWS, TUNE_PIXELS,
};

//! The CNNs of Tensor Holography V2 as files (`docs/CONVENTIONS.md` §7, paper Fig. 3): the hologram CNN
//! (RGB-D or LDI → midpoint hologram) and the DDPM pre-filter CNN (offset hologram → filtered offset hologram,
//! Eq. 6). Engine-neutral: what runs them is [`crate::cnn`] (the CPU engines) or the GPU.
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
//! 4. the engines read it: the native CPU engine and the GPU path through `CnnWeights` (the graph read as
//!    the TensorHolo residual CNN, `model/graph.rs`, cached in the model); tract (cargo feature `tract`) from
//!    the file's bytes, in its own per-model cache (`cnn/tract/`).
//!
//! Which engine can run a file is the engines' answer, asked when a pipeline is made
//! ([`crate::cnn::check_runnable`]): a build without tract refuses there a file that is not the TensorHolo
//! residual CNN (and every int8 QOperator file), naming the feature.
//!
//! Files: `onnx` (the schema's fields the SDK reads), `metadata` (the `tensorholo.*` keys and the display
//! check), `network` ([`HologramModel`]), `graph` (`CnnWeights`), `contract` (input packing, heads → field),
//! `embedded` (the shipped files).

pub mod contract;
#[cfg(feature = "embedded-models")]
pub mod embedded;
pub(crate) mod graph;
mod metadata;
pub(crate) mod network;
pub(crate) mod onnx;

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
    pub(crate) fn name(self) -> &'static str {
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
    pub(crate) fn file_suffix(self) -> &'static str {
        match self {
            Self::F32 => "",
            Self::Int8QOperator => ".int8-qop",
            Self::Int8Qdq => ".int8-qdq",
        }
    }

    /// The form a model's `tensorholo.precision` metadata names ([`ModelMetadata::precision`]: `f32`,
    /// `int8-qoperator-conv`, `int8-qdq-conv`); `None` for another value.
    pub(crate) fn from_metadata(value: &str) -> Option<Self> {
        match value {
            "f32" => Some(Self::F32),
            "int8-qoperator-conv" => Some(Self::Int8QOperator),
            "int8-qdq-conv" => Some(Self::Int8Qdq),
            _ => None,
        }
    }

    /// Short name: `f32`, `int8-qop`, `int8-qdq`.
    pub(crate) fn name(self) -> &'static str {
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

pub use contract::{head_to_phasor, heads_to_field};
pub(crate) use graph::{CnnOutput, CnnQuant, CnnWeights, ConvLayer, LayerQuant, QuantGrid};
pub use metadata::{
    ModelConfig, ModelKind, ModelMetadata, FORMAT_VERSION, METADATA_PREFIX,
    PREFILTER_FORMAT_VERSION,
};
pub use network::HologramModel;

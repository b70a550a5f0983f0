//! The CNNs of Tensor Holography V2 run with tract (`DESIGN.md` §3, paper Fig. 3): the hologram CNN
//! (RGB-D or LDI → midpoint hologram) and the DDPM pre-filter CNN (offset hologram → filtered offset
//! hologram, Eq. 6).
//!
//! A [`HologramModel`] is loaded once from an ONNX file written by `training/tensorholo_training/export.py`:
//!
//! 1. the protobuf is decoded (a truncated or corrupt file → [`HoloError::ModelLoad`](crate::HoloError));
//! 2. its `tensorholo.*` `metadata_props` are parsed into [`ModelMetadata`] and checked against a
//!    [`ModelConfig`] (wavelengths, pitch, volume depth, offset, input layers → a mismatch is
//!    [`HoloError::ModelMetadata`](crate::HoloError) naming the key, the file's value and the expected one);
//! 3. its graph inputs/outputs are checked against the contract (`rgbd` `[1,4L,H,W]` or `slm_field`
//!    `[1,6,H,W]`; `amplitude`, `phase` `[1,3,H,W]`; f32 → otherwise
//!    [`HoloError::ModelContract`](crate::HoloError));
//! 4. tract types it and declutters it once, keeping `H`, `W` symbolic.
//!
//! [`HologramModel::plan`] then binds `H`, `W` to one resolution and optimises (codegen) the graph for it;
//! plans are cached per resolution inside the model, because tract's symbolic plan runs 6–11× slower than a
//! concretised one. int8 files: QOperator (`QLinearConv`, conv-only) and QDQ (`QuantizeLinear`/
//! `DequantizeLinear` around float `Conv`) both load; value-info hints are ignored when parsing because
//! tract 0.23 refuses the QDQ file's quantised value infos otherwise.

mod metadata;
mod network;

pub use metadata::{ModelConfig, ModelKind, ModelMetadata, FORMAT_VERSION, METADATA_PREFIX};
pub use network::{head_to_phasor, heads_to_field, HologramModel, ModelPlan};

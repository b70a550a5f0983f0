//! The shipped CNNs of `models/` (see `models/MODEL_CARD.md`), compiled into the library behind the default
//! cargo feature `embedded-models`: RGB-D hologram CNNs with 8, 15 and 30 layers (midpoint hologram, any
//! SLM offset) and DDPM pre-filter CNNs for offsets of 6 and 12 mm, each in f32 and two int8 forms.
//! Build with `--no-default-features` to leave them out (≈3 MB) and load files with
//! [`HologramModel::from_path`](super::HologramModel::from_path) instead.

use super::{HologramModel, ModelConfig, ModelKind, Precision};
use crate::error::{invalid, Result};

macro_rules! shipped {
    ($($name:literal),* $(,)?) => {
        &[$(($name, include_bytes!(concat!(env!("CARGO_MANIFEST_DIR"), "/../models/", $name)))),*]
    };
}

/// Every embedded file: `(file name in models/, bytes)`.
pub const FILES: &[(&str, &[u8])] = shipped![
    "holo8_rgbd.onnx",
    "holo8_rgbd.int8-qop.onnx",
    "holo8_rgbd.int8-qdq.onnx",
    "holo15_rgbd.onnx",
    "holo15_rgbd.int8-qop.onnx",
    "holo15_rgbd.int8-qdq.onnx",
    "holo30_rgbd.onnx",
    "holo30_rgbd.int8-qop.onnx",
    "holo30_rgbd.int8-qdq.onnx",
    "prefilter_6mm.onnx",
    "prefilter_6mm.int8-qop.onnx",
    "prefilter_6mm.int8-qdq.onnx",
    "prefilter_12mm.onnx",
    "prefilter_12mm.int8-qop.onnx",
    "prefilter_12mm.int8-qdq.onnx",
];

/// Layer counts of the shipped hologram CNNs.
pub const LAYERS: [usize; 3] = [8, 15, 30];
/// SLM offsets (millimetres) of the shipped pre-filter CNNs.
pub const PREFILTER_OFFSETS_MM: [u32; 2] = [6, 12];

fn find(name: &str) -> Option<&'static [u8]> {
    FILES.iter().find(|(n, _)| *n == name).map(|(_, b)| *b)
}

/// File name in `models/` of the shipped RGB-D hologram CNN with `layers` layers in `precision`.
pub fn hologram_file(layers: usize, precision: Precision) -> String {
    format!("holo{layers}_rgbd{}.onnx", precision.file_suffix())
}

/// File name in `models/` of the shipped pre-filter CNN for an offset of `offset_mm` millimetres.
pub fn prefilter_file(offset_mm: u32, precision: Precision) -> String {
    format!("prefilter_{offset_mm}mm{}.onnx", precision.file_suffix())
}

/// The ONNX bytes of the shipped RGB-D hologram CNN with `layers` ∈ {8, 15, 30} layers.
///
/// Errors: [`HoloError::InvalidParameter`](crate::HoloError) for another layer count.
pub fn hologram_cnn(layers: usize, precision: Precision) -> Result<&'static [u8]> {
    find(&hologram_file(layers, precision)).ok_or_else(|| {
        invalid(
            "layers",
            format!("the shipped hologram CNNs have {LAYERS:?} layers, not {layers}"),
        )
    })
}

/// The ONNX bytes of the shipped pre-filter CNN for an SLM offset of `offset_mm` ∈ {6, 12} millimetres.
///
/// Errors: [`HoloError::InvalidParameter`](crate::HoloError) for another offset.
pub fn prefilter_cnn(offset_mm: u32, precision: Precision) -> Result<&'static [u8]> {
    find(&prefilter_file(offset_mm, precision)).ok_or_else(|| {
        invalid(
            "offset_mm",
            format!("the shipped pre-filter CNNs are for {PREFILTER_OFFSETS_MM:?} mm, not {offset_mm} mm"),
        )
    })
}

/// Loads the shipped RGB-D hologram CNN with `layers` ∈ {8, 15, 30} layers in `precision`, checked against
/// `expected` like any file ([`HologramModel::from_bytes`]); errors name the embedded file.
///
/// Errors: as [`hologram_cnn`] and [`HologramModel::from_bytes`].
pub fn hologram_model(
    layers: usize,
    precision: Precision,
    expected: &ModelConfig,
) -> Result<HologramModel> {
    HologramModel::from_named_bytes(
        hologram_cnn(layers, precision)?,
        &hologram_file(layers, precision),
        ModelKind::Hologram,
        expected,
    )
}

/// Loads the shipped pre-filter CNN for an SLM offset of `offset_mm` ∈ {6, 12} millimetres in `precision`,
/// checked against `expected` (its `offset_m` must be that offset); errors name the embedded file.
///
/// Errors: as [`prefilter_cnn`] and [`HologramModel::from_bytes`].
pub fn prefilter_model(
    offset_mm: u32,
    precision: Precision,
    expected: &ModelConfig,
) -> Result<HologramModel> {
    HologramModel::from_named_bytes(
        prefilter_cnn(offset_mm, precision)?,
        &prefilter_file(offset_mm, precision),
        ModelKind::PreFilter,
        expected,
    )
}

//! The `tensorholo.*` ONNX `metadata_props` of an exported CNN (`docs/CONVENTIONS.md` §7.3) and their check
//! against the SDK's configuration.
//!
//! Written by `training/tensorholo_training/export.py` (`model_metadata`): `kind` (`hologram-cnn` or
//! `prefilter-cnn`), `layers`, `wavelengths_m` (comma-separated R,G,B), `pixel_pitch_m`, `volume_depth_m`,
//! `offset_m`, `input_layers`, `trained_resolution` (`HxW`), `training_commit`, plus `precision`, `channels`,
//! `format_version` and `io`.

use std::collections::BTreeMap;
use std::fmt;

use crate::error::{HoloError, Result};
use crate::optics::OpticalSetup;

/// Prefix of every key the SDK reads from an ONNX file's `metadata_props`.
pub const METADATA_PREFIX: &str = "tensorholo.";

/// The newest metadata format version this SDK understands (`tensorholo.format_version`). Version 2 changed
/// the pre-filter's I/O to Cartesian `[Re H, Im H]` (outputs `real`, `imag`); hologram CNNs are the same in
/// versions 1 and 2.
pub const FORMAT_VERSION: u32 = 2;

/// The oldest format version of a pre-filter file this SDK runs (the amplitude/phase pre-filter of version 1
/// is refused: its input and outputs mean something else).
pub const PREFILTER_FORMAT_VERSION: u32 = 2;

/// Relative tolerance when comparing the file's physical quantities (metres) with the configuration's:
/// the exporter writes Python `repr(float)` (exact round trip), so only decimal-input noise is tolerated.
const REL_TOL: f64 = 1e-6;

/// Which of the two CNNs of the pipeline (`docs/CONVENTIONS.md` §7, paper Fig. 3) a file holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ModelKind {
    /// The hologram CNN: input `rgbd` `[1, 4·L, H, W]`, outputs the midpoint hologram as `amplitude` and
    /// `phase` `[1, 3, H, W]` (metadata `tensorholo.kind = hologram-cnn`).
    Hologram,
    /// The DDPM pre-filter CNN (Eq. 6): input `slm_field` `[1, 6, H, W]` = `[Re H, Im H]` of the offset
    /// hologram (R, G, B each, midpoint amplitude units), outputs `real` and `imag` `[1, 3, H, W]` of the
    /// filtered field (`tensorholo.kind = prefilter-cnn`, format version 2).
    PreFilter,
}

impl ModelKind {
    /// The `tensorholo.kind` value of this kind: `hologram-cnn` or `prefilter-cnn`.
    pub fn metadata_name(self) -> &'static str {
        match self {
            ModelKind::Hologram => "hologram-cnn",
            ModelKind::PreFilter => "prefilter-cnn",
        }
    }

    /// The name of the network's single input in the ONNX graph: `rgbd` or `slm_field`.
    pub fn input_name(self) -> &'static str {
        match self {
            ModelKind::Hologram => "rgbd",
            ModelKind::PreFilter => "slm_field",
        }
    }

    /// The names of the network's two outputs, in order: `["amplitude", "phase"]` (the heads of the midpoint
    /// hologram) or `["real", "imag"]` (the filtered SLM-plane field).
    pub fn output_names(self) -> [&'static str; 2] {
        match self {
            ModelKind::Hologram => ["amplitude", "phase"],
            ModelKind::PreFilter => ["real", "imag"],
        }
    }

    /// Parses a `tensorholo.kind` value; `None` if unknown.
    pub fn from_metadata_name(s: &str) -> Option<Self> {
        match s {
            "hologram-cnn" => Some(ModelKind::Hologram),
            "prefilter-cnn" => Some(ModelKind::PreFilter),
            _ => None,
        }
    }
}

impl fmt::Display for ModelKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.metadata_name())
    }
}

/// What the SDK expects of a CNN file: the display it drives and the pipeline settings the network was
/// trained for. A file whose metadata disagrees is refused ([`ModelMetadata::check`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelConfig {
    /// Wavelengths, pixel pitch and volume depth (compared with `tensorholo.wavelengths_m`, `pixel_pitch_m`,
    /// `volume_depth_m`, relative tolerance 1e-6).
    pub optics: OpticalSetup,
    /// Hologram-plane offset `s` in metres (Eq. 6; `tensorholo.offset_m`), e.g. 0, 6e-3 or 12e-3.
    pub offset_m: f64,
    /// `L`: 1 for RGB-D input, 5 for a layered depth image (`tensorholo.input_layers`). For a pre-filter,
    /// that of the hologram CNN it was trained with.
    pub input_layers: usize,
}

impl Default for ModelConfig {
    /// The paper's display (638/520/450 nm, 8 µm, 6 mm volume), 6 mm offset, RGB-D input.
    fn default() -> Self {
        Self {
            optics: OpticalSetup::default(),
            offset_m: 6e-3,
            input_layers: 1,
        }
    }
}

/// The parsed `tensorholo.*` metadata of one CNN file (`docs/CONVENTIONS.md` §7.3).
#[derive(Debug, Clone, PartialEq)]
pub struct ModelMetadata {
    /// `tensorholo.kind`.
    pub kind: ModelKind,
    /// `tensorholo.layers`: number of convolution layers (8, 15 or 30 for the hologram CNN, 8 for the
    /// pre-filter).
    pub layers: usize,
    /// `tensorholo.channels`: filters per hidden layer (24 / 8), if present.
    pub channels: Option<usize>,
    /// `tensorholo.wavelengths_m`: R, G, B wavelengths in metres.
    pub wavelengths_m: [f64; 3],
    /// `tensorholo.pixel_pitch_m`, metres.
    pub pixel_pitch_m: f64,
    /// `tensorholo.volume_depth_m`, metres.
    pub volume_depth_m: f64,
    /// `tensorholo.offset_m`, metres.
    pub offset_m: f64,
    /// `tensorholo.input_layers`: `L` (the input has `4·L` channels for a hologram CNN).
    pub input_layers: usize,
    /// `tensorholo.trained_resolution` (`HxW`): `[height, width]` of the training crops.
    pub trained_resolution: [usize; 2],
    /// `tensorholo.training_commit`: git commit of the training code.
    pub training_commit: String,
    /// `tensorholo.precision`: `f32`, `int8-qoperator-conv` or `int8-qdq-conv` (`f32` when absent).
    pub precision: String,
    /// `tensorholo.format_version` (1 when absent; 2 is required of a pre-filter).
    pub format_version: u32,
    /// `tensorholo.io`: the one-line I/O statement, if present.
    pub io: Option<String>,
    /// `tensorholo.hologram_layers` of a pre-filter: the depth of the hologram CNN whose offset holograms it
    /// was trained on (it is known to help that CNN; `holo render` runs it by default only with it), if
    /// present.
    pub hologram_layers: Option<usize>,
    /// Every `metadata_props` entry of the file, prefixed or not (for display and forward compatibility).
    pub raw: BTreeMap<String, String>,
}

fn bad(key: &str, found: impl Into<String>, expected: impl Into<String>) -> HoloError {
    HoloError::ModelMetadata {
        key: format!("{METADATA_PREFIX}{key}"),
        found: found.into(),
        expected: expected.into(),
    }
}

fn parse<T: std::str::FromStr>(key: &str, value: &str, what: &str) -> Result<T> {
    value.trim().parse().map_err(|_| bad(key, value, what))
}

fn parse_metres(key: &str, value: &str) -> Result<f64> {
    let v: f64 = parse(key, value, "a finite non-negative length in metres")?;
    if !v.is_finite() || v < 0.0 {
        return Err(bad(key, value, "a finite non-negative length in metres"));
    }
    Ok(v)
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= REL_TOL * a.abs().max(b.abs())
}

impl ModelMetadata {
    /// Parses `metadata_props` (key → value, as stored in the file).
    ///
    /// Errors: [`HoloError::ModelMetadata`] naming the first required key that is missing (found
    /// `<missing>`) or unparsable, a `format_version` newer than [`FORMAT_VERSION`], or a pre-filter older
    /// than [`PREFILTER_FORMAT_VERSION`] (the amplitude/phase pre-filter of format 1).
    pub fn from_props(raw: BTreeMap<String, String>) -> Result<Self> {
        let get = |key: &str| -> Result<&str> {
            raw.get(&format!("{METADATA_PREFIX}{key}"))
                .map(String::as_str)
                .ok_or_else(|| {
                    bad(
                        key,
                        "<missing>",
                        "present (written by tensorholo_training.export)",
                    )
                })
        };
        let opt = |key: &str| {
            raw.get(&format!("{METADATA_PREFIX}{key}"))
                .map(String::as_str)
        };
        let format_version = match opt("format_version") {
            None => 1,
            Some(v) => parse("format_version", v, "an integer")?,
        };
        if format_version > FORMAT_VERSION {
            return Err(bad(
                "format_version",
                format_version.to_string(),
                format!("≤ {FORMAT_VERSION} (this SDK is older than the file)"),
            ));
        }
        let kind_s = get("kind")?;
        let kind = ModelKind::from_metadata_name(kind_s)
            .ok_or_else(|| bad("kind", kind_s, "`hologram-cnn` or `prefilter-cnn`"))?;
        if kind == ModelKind::PreFilter && format_version < PREFILTER_FORMAT_VERSION {
            return Err(bad(
                "format_version",
                format_version.to_string(),
                format!(
                    "≥ {PREFILTER_FORMAT_VERSION} for a pre-filter: this file is the old amplitude/phase \
                     pre-filter; retrain and export it with the current training package \
                     ([Re H, Im H] in, `real`/`imag` out)"
                ),
            ));
        }
        let layers: usize = parse("layers", get("layers")?, "a positive integer")?;
        let channels = match opt("channels") {
            None => None,
            Some(v) => Some(parse("channels", v, "a positive integer")?),
        };
        let wl_s = get("wavelengths_m")?;
        let wl: Vec<f64> = wl_s
            .split(',')
            .map(|w| parse_metres("wavelengths_m", w))
            .collect::<Result<_>>()
            .map_err(|_| {
                bad(
                    "wavelengths_m",
                    wl_s,
                    "three comma-separated wavelengths in metres (R,G,B)",
                )
            })?;
        let wavelengths_m: [f64; 3] = wl.try_into().map_err(|_| {
            bad(
                "wavelengths_m",
                wl_s,
                "three comma-separated wavelengths in metres (R,G,B)",
            )
        })?;
        let input_layers: usize =
            parse("input_layers", get("input_layers")?, "a positive integer")?;
        let res_s = get("trained_resolution")?;
        let res: Option<[usize; 2]> = res_s
            .split_once('x')
            .and_then(|(h, w)| Some([h.trim().parse().ok()?, w.trim().parse().ok()?]));
        let trained_resolution =
            res.ok_or_else(|| bad("trained_resolution", res_s, "`HxW`, e.g. `384x384`"))?;
        let md = Self {
            kind,
            layers,
            channels,
            wavelengths_m,
            pixel_pitch_m: parse_metres("pixel_pitch_m", get("pixel_pitch_m")?)?,
            volume_depth_m: parse_metres("volume_depth_m", get("volume_depth_m")?)?,
            offset_m: parse_metres("offset_m", get("offset_m")?)?,
            input_layers,
            trained_resolution,
            training_commit: get("training_commit")?.to_string(),
            precision: opt("precision").unwrap_or("f32").to_string(),
            format_version,
            io: opt("io").map(str::to_string),
            hologram_layers: match opt("hologram_layers") {
                None => None,
                Some(v) => Some(parse("hologram_layers", v, "a positive integer")?),
            },
            raw: BTreeMap::new(),
        };
        if md.layers < 2 {
            return Err(bad("layers", md.layers.to_string(), "≥ 2"));
        }
        if md.input_layers == 0 {
            return Err(bad("input_layers", "0", "≥ 1"));
        }
        Ok(Self { raw, ..md })
    }

    /// Multiply-accumulates per output pixel of the residual CNN of `docs/CONVENTIONS.md` §7.1 (3×3
    /// convolutions: input → `channels`, `layers − 2` hidden `channels → channels`, and the last layer from
    /// `channels` plus the network input to 6 outputs): 147,528 for the 30-layer RGB-D hologram CNN, 33,480
    /// for 8 layers, 4,644 for the pre-filter's correction CNN (its fixed AA-DPM blur adds `6 · taps²`, 150
    /// with 5 taps, not counted). `None` without `tensorholo.channels`. FLOPs per frame = `2 · MAC · H · W`.
    pub fn macs_per_pixel(&self) -> Option<u64> {
        let c = self.channels? as u64;
        let i = self.input_channels() as u64;
        let l = self.layers.max(2) as u64;
        Some(9 * (i * c + (l - 2) * c * c + (c + i) * 6))
    }

    /// Channels of the network input: `4·L` for a hologram CNN, 6 for a pre-filter (`docs/CONVENTIONS.md` §7).
    pub fn input_channels(&self) -> usize {
        match self.kind {
            ModelKind::Hologram => 4 * self.input_layers,
            ModelKind::PreFilter => 6,
        }
    }

    /// Checks the file against the expected kind and configuration.
    ///
    /// Errors: [`HoloError::ModelMetadata`] naming the first mismatching key, the file's value and the
    /// expected one (kind, each wavelength, pitch, volume depth, offset, input layers). A hologram CNN whose
    /// `offset_m` is 0 (trained for the midpoint hologram alone) matches any offset; a pre-filter's
    /// `input_layers` is not checked (it sees the offset hologram, not the scene).
    pub fn check(&self, kind: ModelKind, expected: &ModelConfig) -> Result<()> {
        if self.kind != kind {
            return Err(bad("kind", self.kind.metadata_name(), kind.metadata_name()));
        }
        let fmt3 = |w: &[f64; 3]| format!("{},{},{}", w[0], w[1], w[2]);
        let wl = expected.optics.wavelengths_m;
        if !self
            .wavelengths_m
            .iter()
            .zip(&wl)
            .all(|(a, b)| close(*a, *b))
        {
            return Err(bad("wavelengths_m", fmt3(&self.wavelengths_m), fmt3(&wl)));
        }
        let checks = [
            (
                "pixel_pitch_m",
                self.pixel_pitch_m,
                expected.optics.pixel_pitch_m,
            ),
            (
                "volume_depth_m",
                self.volume_depth_m,
                expected.optics.volume_depth_m,
            ),
        ];
        for (key, found, want) in checks {
            if !close(found, want) {
                return Err(bad(key, found.to_string(), want.to_string()));
            }
        }
        // A hologram CNN trained for the midpoint alone (stage 1, `offset_m = 0`) serves every offset; one
        // fine-tuned jointly with a pre-filter (stage 2 of the paper) only that pre-filter's offset.
        if (kind == ModelKind::PreFilter || self.offset_m != 0.0)
            && !close(self.offset_m, expected.offset_m)
        {
            return Err(bad(
                "offset_m",
                self.offset_m.to_string(),
                expected.offset_m.to_string(),
            ));
        }
        // The pre-filter sees the offset hologram, whatever input the hologram CNN had.
        if kind == ModelKind::Hologram && self.input_layers != expected.input_layers {
            return Err(bad(
                "input_layers",
                self.input_layers.to_string(),
                expected.input_layers.to_string(),
            ));
        }
        Ok(())
    }
}

//! The `tensorholo.*` ONNX `metadata_props` of an exported CNN (`docs/CONVENTIONS.md` §7.3) and their check
//! against the SDK's configuration.
//!
//! Written by `training/tensorholo_training/export.py` (`model_metadata`): `kind` (`hologram-cnn` or
//! `prefilter-cnn`), `layers`, `wavelengths_m` (comma-separated R,G,B), `pixel_pitch_m`, `volume_depth_m`,
//! `offset_m`, `input_layers`, `trained_resolution` (`HxW`), `training_commit`, plus `precision`, `channels`,
//! `format_version` and `io`.

use std::collections::BTreeMap;
use std::fmt;

use crate::display::AberrationProfile;
use crate::display::{close, sig, DisplayMapping, DisplayRefusal, NearestDisplay, VolumeFit};
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

/// Test-split focal-stack PSNR (dB) of the shipped hologram CNNs on their model card (models/MODEL_CARD.md,
/// "Quality"), by `(layers, input_layers)`: what the serving rule of [`crate::display::DisplayMapping`] holds
/// a mapping's error against (f32; int8 within 0.1 dB). A file of another shape is held against the best of
/// them.
const CARD_SCORES_DB: [((usize, usize), f64); 4] = [
    ((8, 1), 28.08),
    ((15, 1), 28.47),
    ((30, 1), 29.02),
    ((8, 5), 28.26),
];

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
    pub(crate) fn metadata_name(self) -> &'static str {
        match self {
            ModelKind::Hologram => "hologram-cnn",
            ModelKind::PreFilter => "prefilter-cnn",
        }
    }

    /// The name of the network's single input in the ONNX graph: `rgbd` or `slm_field`.
    pub(crate) fn input_name(self) -> &'static str {
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
    pub(crate) fn from_metadata_name(s: &str) -> Option<Self> {
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
/// trained for. A file whose metadata disagrees is refused (`ModelMetadata::check`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelConfig {
    /// The display: wavelengths, pixel pitch and volume depth. The model's `tensorholo.wavelengths_m`,
    /// `pixel_pitch_m` and `volume_depth_m` must describe it or a Fresnel-equivalent display
    /// ([`DisplayMapping`]: one depth scale `σ` for the three colours within the tolerance, a volume up to
    /// `σ·V`).
    pub optics: OpticalSetup,
    /// Hologram-plane offset `s'` in metres (Eq. 6) on this display, e.g. 0, 6e-3 or 12e-3 at 8 µm; a model
    /// trained at offset `s` (`tensorholo.offset_m`) serves `s' = σ·s`.
    pub offset_m: f64,
    /// `L`: 1 for RGB-D input, 5 for a layered depth image (`tensorholo.input_layers`). For a pre-filter,
    /// that of the hologram CNN it was trained with.
    pub input_layers: usize,
    /// Largest relative spread (a fraction: 0.01 = 1 %) of the per-colour depth scales of a
    /// Fresnel-equivalent display that `ModelMetadata::check` accepts ([`DisplayMapping`]); `None` (the
    /// default): the serving rule's for this model, the spread whose estimated cost stays within
    /// [`crate::display::MAPPING_COST_BUDGET_DB`] ([`crate::display::rule_tolerance`] of its model-card
    /// score). A value wider than the rule's is reported ([`DisplayMapping::widened`]).
    pub wavelength_ratio_tolerance: Option<f64>,
}

impl Default for ModelConfig {
    /// The paper's display (638/520/450 nm, 8 µm, 6 mm volume), 6 mm offset, RGB-D input.
    fn default() -> Self {
        Self {
            optics: OpticalSetup::default(),
            offset_m: 6e-3,
            input_layers: 1,
            wavelength_ratio_tolerance: None,
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
    /// `tensorholo.aberration`: the aberrations (a `tensorholo.aberration` JSON text, `docs/ABERRATION.md`)
    /// whose correction the network learned from an aberration-corrected dataset (paper Eq. 5,
    /// `holo dataset --aberration`, `training/retrain.sh --display` with a profile's `aberration`); `None`:
    /// trained on uncorrected holograms (the shipped CNNs). Such a network corrects them itself, so a pipeline
    /// runs it only with the same profile and applies no correction kernel on top
    /// (`HologramPipeline::with_aberration`).
    pub aberration: Option<AberrationProfile>,
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
            aberration: match opt("aberration") {
                None => None,
                Some(v) => Some(
                    AberrationProfile::from_json_str(v, "tensorholo.aberration").map_err(|e| {
                        bad(
                            "aberration",
                            format!("{} ({e})", v.chars().take(80).collect::<String>()),
                            "a tensorholo.aberration JSON text",
                        )
                    })?,
                ),
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
    pub(crate) fn input_channels(&self) -> usize {
        match self.kind {
            ModelKind::Hologram => 4 * self.input_layers,
            ModelKind::PreFilter => 6,
        }
    }

    /// The display this file was trained for: `tensorholo.wavelengths_m`, `pixel_pitch_m`,
    /// `volume_depth_m`.
    pub(crate) fn optics(&self) -> OpticalSetup {
        OpticalSetup {
            wavelengths_m: self.wavelengths_m,
            pixel_pitch_m: self.pixel_pitch_m,
            volume_depth_m: self.volume_depth_m,
        }
    }

    /// A short name for messages: "the 8-layer hologram CNN" or "the 8-layer pre-filter CNN".
    pub(crate) fn describe(&self) -> String {
        match self.kind {
            ModelKind::Hologram => format!("the {}-layer hologram CNN", self.layers),
            ModelKind::PreFilter => format!("the {}-layer pre-filter CNN", self.layers),
        }
    }

    /// The test-split focal-stack PSNR (dB) on the model card of the shipped CNN of this shape (a
    /// pre-filter: of the hologram CNN it was trained with), or the best shipped one's for another shape:
    /// the score the serving rule holds a display mapping's error against.
    pub(crate) fn card_score_db(&self) -> f64 {
        let shape = match self.kind {
            ModelKind::Hologram => (self.layers, self.input_layers),
            ModelKind::PreFilter => (self.hologram_layers.unwrap_or(8), 1),
        };
        let best = CARD_SCORES_DB.iter().map(|&(_, s)| s).fold(0.0, f64::max);
        CARD_SCORES_DB
            .iter()
            .find(|&&(k, _)| k == shape)
            .map_or(best, |&(_, s)| s)
    }

    /// Checks the file against the expected kind and configuration, and returns how the model's training
    /// display maps onto the configured one ([`DisplayMapping`]; `σ = 1` for the paper's display).
    ///
    /// The optics need not be equal: the model serves any Fresnel-equivalent display (`docs/DISPLAYS.md`):
    /// one whose per-colour depth scales `σ_c = (λ_c/λ'_c)·(p'/p)²` agree within the tolerance (the serving
    /// rule's by default: an estimated cost within 0.3 dB of [`ModelMetadata::card_score_db`]), whose volume
    /// is at most `σ·V` and its 1 % rounding (a smaller one is served on part of the model's volume), whose
    /// offset is `σ·s` (relative 1e-6) and whose non-paraxial residual is at most
    /// [`crate::display::MAX_NONPARAXIAL_RESIDUAL_RAD`].
    ///
    /// Errors: [`HoloError::DisplayNotServed`] for a display this model does not serve, naming the key
    /// (`wavelengths_m` with the colour off and the cost; `volume_depth_m` with the largest volume served;
    /// `offset_m` with the offset that would serve; `pixel_pitch_m` for a residual above the bound) and what
    /// would serve; [`HoloError::ModelMetadata`] for another kind or input layers;
    /// [`HoloError::InvalidParameter`] for an invalid configuration or metadata optics. A hologram CNN whose
    /// `offset_m` is 0 (trained for the midpoint hologram alone) matches any offset; a pre-filter's
    /// `input_layers` is not checked (it sees the offset hologram, not the scene).
    pub(crate) fn check(&self, kind: ModelKind, expected: &ModelConfig) -> Result<DisplayMapping> {
        if self.kind != kind {
            return Err(bad("kind", self.kind.metadata_name(), kind.metadata_name()));
        }
        let mapping = DisplayMapping::compute(
            &self.optics(),
            &expected.optics,
            expected.offset_m,
            expected.wavelength_ratio_tolerance,
            self.card_score_db(),
        )?;
        let refuse = |r: DisplayRefusal| Err(HoloError::DisplayNotServed(Box::new(r)));
        // Lasers that do not scale alike are named first (no volume or offset would fix them), then a
        // volume deeper than σ·V (a pitch changed alone lands here), and only then the offset.
        let lasers_or_volume = mapping.spread() > mapping.tolerance * (1.0 + 1e-9)
            || mapping.volume == VolumeFit::TooDeep;
        if lasers_or_volume {
            if let Some(r) = mapping.refusal(&self.describe()) {
                return refuse(r);
            }
        }
        // A hologram CNN trained for the midpoint alone (stage 1, `offset_m = 0`) serves every offset; one
        // fine-tuned jointly with a pre-filter (stage 2 of the paper) only that pre-filter's offset.
        let served_offset_m = mapping.scale * self.offset_m;
        if (kind == ModelKind::PreFilter || self.offset_m != 0.0)
            && !close(served_offset_m, expected.offset_m)
        {
            return refuse(DisplayRefusal {
                key: format!("{METADATA_PREFIX}offset_m"),
                found: self.offset_m.to_string(),
                expected: if mapping.is_identity() {
                    format!("an offset of {} m", expected.offset_m)
                } else {
                    format!(
                        "{} m on the training display (the offset that serves {} m on this display is σ·{} m = {} m)",
                        sig(expected.offset_m / mapping.scale),
                        expected.offset_m,
                        self.offset_m,
                        sig(served_offset_m)
                    )
                },
                nearest: Some(NearestDisplay::new(
                    &OpticalSetup {
                        volume_depth_m: mapping.running_volume_depth_m(),
                        ..expected.optics
                    },
                    served_offset_m,
                    1.0,
                )),
                tolerance: None,
            });
        }
        if let Some(r) = mapping.refusal(&self.describe()) {
            return refuse(r);
        }
        // The pre-filter sees the offset hologram, whatever input the hologram CNN had.
        if kind == ModelKind::Hologram && self.input_layers != expected.input_layers {
            return Err(bad(
                "input_layers",
                self.input_layers.to_string(),
                expected.input_layers.to_string(),
            ));
        }
        Ok(mapping)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PAPER: [f64; 3] = [638e-9, 520e-9, 450e-9];

    fn display(pitch: f64, volume: f64) -> OpticalSetup {
        OpticalSetup {
            wavelengths_m: PAPER,
            pixel_pitch_m: pitch,
            volume_depth_m: volume,
        }
    }

    fn metadata(kind: ModelKind, offset_m: f64) -> ModelMetadata {
        let mut raw = BTreeMap::new();
        for (k, v) in [
            ("kind", kind.metadata_name()),
            ("layers", "8"),
            ("wavelengths_m", "6.38e-07,5.2e-07,4.5e-07"),
            ("pixel_pitch_m", "8e-06"),
            ("volume_depth_m", "0.006"),
            ("input_layers", "1"),
            ("trained_resolution", "384x384"),
            ("training_commit", "test"),
            ("format_version", "2"),
        ] {
            raw.insert(format!("{METADATA_PREFIX}{k}"), v.to_string());
        }
        raw.insert(format!("{METADATA_PREFIX}offset_m"), offset_m.to_string());
        ModelMetadata::from_props(raw).unwrap()
    }

    fn config(optics: OpticalSetup, offset_m: f64) -> ModelConfig {
        ModelConfig {
            optics,
            offset_m,
            ..ModelConfig::default()
        }
    }

    fn key(e: HoloError) -> String {
        match e {
            HoloError::DisplayNotServed(r) => r.key,
            other => panic!("expected a display refusal, got {other}"),
        }
    }

    #[test]
    fn the_aberration_key_is_parsed_and_a_bad_one_is_refused_naming_it() {
        let md = metadata(ModelKind::Hologram, 0.0);
        assert!(md.aberration.is_none());
        let mut raw = md.raw.clone();
        let key = format!("{METADATA_PREFIX}aberration");
        raw.insert(
            key.clone(),
            r#"{"format":"tensorholo.aberration","version":1,"samples":[{"distance_m":0.0,"coefficients":{"focus":0.5}}]}"#
                .into(),
        );
        let md = ModelMetadata::from_props(raw.clone()).unwrap();
        let a = md.aberration.unwrap();
        assert_eq!(a.coefficients(0.0, 1).focus, 0.5);
        raw.insert(
            key.clone(),
            r#"{"format":"tensorholo.aberration","version":1,"samples":[]}"#.into(),
        );
        match ModelMetadata::from_props(raw) {
            Err(HoloError::ModelMetadata { key: k, .. }) => assert_eq!(k, key),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn paper_display_is_the_identity() {
        let m = metadata(ModelKind::PreFilter, 6e-3)
            .check(ModelKind::PreFilter, &ModelConfig::default())
            .unwrap();
        assert_eq!(m.scale, 1.0);
        assert!(m.is_identity());
        assert_eq!(m.residual_rad, 0.0);
        assert_eq!(m.spread(), 0.0);
        assert!(!m.widened);
    }

    #[test]
    fn four_micron_display_serves_quarter_volume_and_offset() {
        let md = metadata(ModelKind::PreFilter, 6e-3);
        let m = md
            .check(ModelKind::PreFilter, &config(display(4e-6, 1.5e-3), 1.5e-3))
            .unwrap();
        assert!((m.scale - 0.25).abs() < 1e-15);
        assert!((m.trained_offset_m - 6e-3).abs() < 1e-15);
        assert!(
            m.residual_rad > 0.05 && m.residual_rad < 0.1,
            "{}",
            m.residual_rad
        );
        let text = m.description(&md.describe());
        assert!(text.contains("serves 4 µm with a 1.5 mm volume"), "{text}");
        assert!(text.contains("offset 1.5 mm ↔ 6 mm"), "{text}");
        // The unmapped offset is refused, naming what would serve.
        let e = md
            .check(ModelKind::PreFilter, &config(display(4e-6, 1.5e-3), 6e-3))
            .unwrap_err();
        assert!(e.to_string().contains("offset_m"), "{e}");
    }

    #[test]
    fn a_deeper_volume_is_refused_and_others_are_served() {
        let md = metadata(ModelKind::Hologram, 0.0);
        let at =
            |volume: f64| md.check(ModelKind::Hologram, &config(display(3.74e-6, volume), 0.0));
        let e = at(1.5e-3).unwrap_err();
        let text = e.to_string();
        assert!(text.contains("σ·V = 1.3113375 mm"), "{text}");
        assert!(text.contains("up to 1.32445088 mm"), "{text}");
        assert!(text.contains("not 1.5 mm"), "{text}");
        let HoloError::DisplayNotServed(r) = &e else {
            panic!("{e}")
        };
        assert!((r.nearest.unwrap().volume_depth_m - 1.3113375e-3).abs() < 1e-12);
        assert_eq!(key(e), "tensorholo.volume_depth_m");
        assert_eq!(at(1.3113375e-3).unwrap().volume, VolumeFit::Mapped);
        // A rounded 1.3 mm (0.86 % under σ·V) runs at σ·V; 1 mm on 76 % of the model's volume.
        let m = at(1.3e-3).unwrap();
        assert_eq!(
            m.volume,
            VolumeFit::Rounded {
                requested_m: 1.3e-3
            }
        );
        assert_eq!(m.running_volume_depth_m(), m.served_volume_depth_m());
        assert!(
            m.description("x").contains("served at 1.3113375 mm"),
            "{}",
            m.description("x")
        );
        let m = at(1e-3).unwrap();
        assert!((m.depth_fraction() - 1e-3 / 1.3113375e-3).abs() < 1e-12);
        assert_eq!(m.running_volume_depth_m(), 1e-3);
    }

    #[test]
    fn lasers_are_served_while_their_cost_is_within_the_budget() {
        let md = metadata(ModelKind::Hologram, 0.0);
        let check = |green: f64, tolerance: Option<f64>| {
            let mut optics = display(8e-6, 6e-3);
            optics.wavelengths_m[1] = green;
            // σ = √(σ_min·σ_max); the volume follows it.
            let m = DisplayMapping::compute(&md.optics(), &optics, 6e-3, Some(1.0), 28.08).unwrap();
            optics.volume_depth_m = m.served_volume_depth_m();
            let mut cfg = config(optics, 6e-3);
            cfg.wavelength_ratio_tolerance = tolerance;
            md.check(ModelKind::Hologram, &cfg)
        };
        // The most common green, 532 nm, by the rule: served, at a cost under the budget.
        let m = check(532e-9, None).unwrap();
        assert!(m.tolerance_from_rule && !m.widened);
        assert!(m.spread() > 0.011 && m.spread() < 0.0116, "{}", m.spread());
        assert!(m.cost_db > 0.0 && m.cost_db < 0.15, "{}", m.cost_db);
        assert!(
            m.description("x").contains("the rule's"),
            "{}",
            m.description("x")
        );
        // Given a tighter tolerance, the same lasers are refused, naming green and the tolerance that serves.
        let e = check(532e-9, Some(0.005)).unwrap_err();
        let text = e.to_string();
        assert!(
            text.contains("green") && text.contains("wavelength_ratio_tolerance"),
            "{text}"
        );
        let HoloError::DisplayNotServed(r) = &e else {
            panic!("{e}")
        };
        let (t, cost) = r.tolerance.unwrap();
        check(532e-9, Some(t)).unwrap();
        assert!((cost - m.cost_db).abs() < 1e-3, "{cost} vs {}", m.cost_db);
        assert_eq!(key(e), "tensorholo.wavelengths_m");
        // A green 8 % off costs more than the budget: refused by the rule, served when widened.
        let e = check(561.6e-9, None).unwrap_err();
        assert!(e.to_string().contains("above the 0.3 dB budget"), "{e}");
        let m = check(561.6e-9, Some(0.05)).unwrap();
        assert!(m.widened && m.cost_db > 0.3, "{}", m.cost_db);
        assert!(m.description("x").contains("widened"));
    }

    #[test]
    fn too_fine_a_pitch_is_refused_by_the_residual() {
        let s: f64 = (1.5e-6f64 / 8e-6).powi(2);
        let e = metadata(ModelKind::Hologram, 0.0)
            .check(
                ModelKind::Hologram,
                &config(display(1.5e-6, 6e-3 * s), 6e-3 * s),
            )
            .unwrap_err();
        assert!(e.to_string().contains("non-paraxial"), "{e}");
        assert_eq!(key(e), "tensorholo.pixel_pitch_m");
    }
}

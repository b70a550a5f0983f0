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

/// Default largest relative spread of the per-colour depth scales `σ_c = (λ_c/λ'_c)·(p'/p)²` of a
/// Fresnel-equivalent display ([`DisplayMapping`]): 0.5 %. A colour whose `σ_c` is off the common `σ` by `ε`
/// focuses its depth planes `ε·|z'|` away from the others' (0.5 % of 0.66 mm is 3 µm on a 3.74 µm SLM, a tenth
/// of its depth of focus `p'²/λ'`); in phase that is `ε·π·λ'·z'/(4·p'²)` rad at the band edge, 0.35 rad for
/// red at the paper's outermost depth (9 mm at 8 µm). Equal lasers give 0 %; a 532 nm green laser with the
/// paper's red and blue gives 1.15 % and is refused unless the tolerance is widened
/// ([`ModelConfig::wavelength_ratio_tolerance`]). Measured (`scripts/display-mismatch.sh`, docs/DISPLAYS.md
/// "What a laser-ratio mismatch costs"): at 0.5 % a perfect model reaches 51.4 dB through the mapping, 20 dB
/// above the paper's best CNN (29.6 dB, Table 2), so the mapping adds 0.03 dB of loss.
pub const DEFAULT_WAVELENGTH_RATIO_TOLERANCE: f64 = 0.005;

/// Largest non-paraxial residual (radians) accepted between a model's training display and a
/// Fresnel-equivalent one ([`DisplayMapping::residual_rad`]): 0.25 rad (λ/25 of wavefront). The paper's lasers
/// give 0.084 rad (red) at 4 µm, 0.101 rad at 3.74 µm and 0.016 rad at 6.4 µm for the 8 µm / 6 mm models at
/// the 6 mm pre-filter's offset (0.141 and 0.168 rad at 12 mm); it grows as `(1/σ − 1)·|z|`, so pitches below
/// about 2.5 µm (6 mm offset) or 3.2 µm (12 mm) are refused.
pub const MAX_NONPARAXIAL_RESIDUAL_RAD: f64 = 0.25;

/// Frequency samples of the band `[0, 1/(2p')]` on which [`nonparaxial_residual_rad`] evaluates.
const RESIDUAL_SAMPLES: usize = 1024;

/// `x` rounded to 9 significant digits for messages (1.3113375000000003 → 1.3113375).
fn sig(x: f64) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let scale = 10f64.powi(8 - x.abs().log10().floor() as i32);
    (x * scale).round() / scale
}

/// Names of the colours R, G, B for messages.
const COLOUR: [&str; 3] = ["red", "green", "blue"];

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
    /// The display: wavelengths, pixel pitch and volume depth. The model's `tensorholo.wavelengths_m`,
    /// `pixel_pitch_m` and `volume_depth_m` must describe it or a Fresnel-equivalent display
    /// ([`DisplayMapping`]: one depth scale `σ` for the three colours, volume `σ·V` to a relative 1e-6).
    pub optics: OpticalSetup,
    /// Hologram-plane offset `s'` in metres (Eq. 6) on this display, e.g. 0, 6e-3 or 12e-3 at 8 µm; a model
    /// trained at offset `s` (`tensorholo.offset_m`) serves `s' = σ·s`.
    pub offset_m: f64,
    /// `L`: 1 for RGB-D input, 5 for a layered depth image (`tensorholo.input_layers`). For a pre-filter,
    /// that of the hologram CNN it was trained with.
    pub input_layers: usize,
    /// Largest relative spread (a fraction: 0.005 = 0.5 %) of the per-colour depth scales of a
    /// Fresnel-equivalent display that [`ModelMetadata::check`] accepts ([`DisplayMapping`]); default
    /// [`DEFAULT_WAVELENGTH_RATIO_TOLERANCE`]. A wider value is reported ([`DisplayMapping::widened`]).
    pub wavelength_ratio_tolerance: f64,
}

impl Default for ModelConfig {
    /// The paper's display (638/520/450 nm, 8 µm, 6 mm volume), 6 mm offset, RGB-D input.
    fn default() -> Self {
        Self {
            optics: OpticalSetup::default(),
            offset_m: 6e-3,
            input_layers: 1,
            wavelength_ratio_tolerance: DEFAULT_WAVELENGTH_RATIO_TOLERANCE,
        }
    }
}

/// Exact angular-spectrum phase with the carrier removed (paper Eq. 2 and Eq. 6, `docs/CONVENTIONS.md` §5.2):
/// `2π·z·(√(1/λ² − f²) − 1/λ)` radians at radial frequency `f` (cycles per metre), computed as
/// `−2π·z·f²/(√(1/λ² − f²) + 1/λ)` (no cancellation). `None` for an evanescent `f ≥ 1/λ`.
pub fn carrier_free_phase_rad(wavelength_m: f64, distance_m: f64, f: f64) -> Option<f64> {
    let inv = 1.0 / wavelength_m;
    let arg = inv * inv - f * f;
    (arg > 0.0).then(|| -2.0 * std::f64::consts::PI * distance_m * f * f / (arg.sqrt() + inv))
}

/// The non-paraxial residual (radians) of serving a display with the model of another: the largest
/// `|φ'(f') − φ(f'·p'/p)|` over `f' ∈ [0, 1/(2p')]` (the user grid's Nyquist band along an axis), where
/// `φ'` is [`carrier_free_phase_rad`] at the user's `(λ', z')` and `φ` the training display's at `(λ, z)`,
/// evaluated at the same frequency index `k` of both grids (`f = k/(N·p)`). Paraxially both are
/// `−π·λ·z·f²` and cancel when `λ'·z'/p'² = λ·z/p²`; what remains is the `f⁴` term and beyond.
///
/// Lengths in metres. Returns `f64::INFINITY` when a frequency of either grid is evanescent.
pub fn nonparaxial_residual_rad(
    trained_pitch_m: f64,
    trained_wavelength_m: f64,
    trained_distance_m: f64,
    pitch_m: f64,
    wavelength_m: f64,
    distance_m: f64,
) -> f64 {
    let nyquist = 0.5 / pitch_m;
    let mut worst = 0.0f64;
    for i in 0..=RESIDUAL_SAMPLES {
        let f_user = nyquist * i as f64 / RESIDUAL_SAMPLES as f64;
        let f_train = f_user * pitch_m / trained_pitch_m;
        match (
            carrier_free_phase_rad(wavelength_m, distance_m, f_user),
            carrier_free_phase_rad(trained_wavelength_m, trained_distance_m, f_train),
        ) {
            (Some(a), Some(b)) => worst = worst.max((a - b).abs()),
            _ => return f64::INFINITY,
        }
    }
    worst
}

/// The end of every refusal of [`DisplayMapping::refusal`]: where a model for the display as it is comes
/// from.
pub const RETRAIN_HINT: &str = "; to serve this display as it is, retrain for it (docs/DISPLAYS.md, \"Retraining for another display\")";

/// How a model trained for one display serves another, Fresnel-equivalent one (`docs/DISPLAYS.md`).
///
/// On the SLM's grid (pitch `p`) the carrier-free angular-spectrum transfer function (Eq. 2, Eq. 6) is
/// paraxially `exp(−i·π·λ·z·f²)` with `f = k/(N·p)`: it depends on the display only through `λ·z/p²` per
/// colour. A model trained at `(p, λ_c, V, s)` therefore serves `(p', λ'_c)` when the depth scale
/// `σ_c = (λ_c/λ'_c)·(p'/p)²` is one `σ` for the three colours: volume `V' = σ·V`, offsets `s' = σ·s`, and
/// every depth `z' = σ·z`. Built by [`DisplayMapping::compute`]; [`ModelMetadata::check`] accepts a model
/// through it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct DisplayMapping {
    /// The display the model was trained for (`tensorholo.*`).
    pub trained: OpticalSetup,
    /// The display it serves (the user's).
    pub display: OpticalSetup,
    /// `σ`, the common depth scale: the geometric midpoint `√(min σ_c · max σ_c)` of the per-colour scales
    /// (1 for the training display itself).
    pub scale: f64,
    /// Per-colour scales `σ_c = (λ_c/λ'_c)·(p'/p)²`, R, G, B.
    pub colour_scales: [f64; 3],
    /// Per-colour mismatch `100·(σ_c/σ − 1)` in percent, R, G, B.
    pub ratio_mismatch_pct: [f64; 3],
    /// The accepted spread (fraction) [`ModelConfig::wavelength_ratio_tolerance`].
    pub tolerance: f64,
    /// True when that tolerance is wider than [`DEFAULT_WAVELENGTH_RATIO_TOLERANCE`].
    pub widened: bool,
    /// The user's largest `|z'|` in metres: half the served volume `σ·V/2` plus the user's `|s'|`.
    pub max_distance_m: f64,
    /// The user's offset `s'` in metres and the training display's equivalent `s'/σ`.
    pub offset_m: f64,
    /// `s'/σ`: the offset on the training display that the user's offset corresponds to, metres.
    pub trained_offset_m: f64,
    /// Per-colour non-paraxial residual in radians ([`nonparaxial_residual_rad`] at `z = max_distance_m/σ`
    /// on the training display and `z' = σ_c·z` on the user's), R, G, B.
    pub colour_residual_rad: [f64; 3],
    /// The largest of [`DisplayMapping::colour_residual_rad`], radians.
    pub residual_rad: f64,
}

impl DisplayMapping {
    /// The mapping from the `trained` display (the model's metadata) to `display` at the user's offset
    /// `offset_m` (metres), accepting a per-colour scale spread up to `tolerance` (a fraction). Computes
    /// only; [`DisplayMapping::refusal`] says whether a model may be served.
    ///
    /// Errors: [`HoloError::InvalidParameter`] for a non-finite or non-positive pitch, wavelength or volume
    /// (`pixel_pitch_m`, `wavelength_m`, `volume_depth_m`), a non-finite offset (`offset_m`) or a tolerance
    /// that is negative or not finite (`wavelength_ratio_tolerance`).
    pub fn compute(
        trained: &OpticalSetup,
        display: &OpticalSetup,
        offset_m: f64,
        tolerance: f64,
    ) -> Result<Self> {
        trained.validate()?;
        display.validate()?;
        if !offset_m.is_finite() {
            return Err(crate::error::invalid(
                "offset_m",
                format!("must be finite, got {offset_m}"),
            ));
        }
        if !(tolerance.is_finite() && tolerance >= 0.0) {
            return Err(crate::error::invalid(
                "wavelength_ratio_tolerance",
                format!("must be a finite fraction ≥ 0 (0.005 = 0.5 %), got {tolerance}"),
            ));
        }
        let pitch2 = (display.pixel_pitch_m / trained.pixel_pitch_m).powi(2);
        let colour_scales: [f64; 3] =
            std::array::from_fn(|c| trained.wavelengths_m[c] / display.wavelengths_m[c] * pitch2);
        let (lo, hi) = colour_scales
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(lo, hi), &s| {
                (lo.min(s), hi.max(s))
            });
        // Exactly the per-colour scale when the three agree (no rounding from the square root).
        let scale = if lo == hi { lo } else { (lo * hi).sqrt() };
        let ratio_mismatch_pct = colour_scales.map(|s| 100.0 * (s / scale - 1.0));
        let max_distance_m = 0.5 * scale * trained.volume_depth_m + offset_m.abs();
        let z_trained = max_distance_m / scale;
        let colour_residual_rad: [f64; 3] = std::array::from_fn(|c| {
            nonparaxial_residual_rad(
                trained.pixel_pitch_m,
                trained.wavelengths_m[c],
                z_trained,
                display.pixel_pitch_m,
                display.wavelengths_m[c],
                colour_scales[c] * z_trained,
            )
        });
        Ok(Self {
            trained: *trained,
            display: *display,
            scale,
            colour_scales,
            ratio_mismatch_pct,
            tolerance,
            widened: tolerance > DEFAULT_WAVELENGTH_RATIO_TOLERANCE,
            max_distance_m,
            offset_m,
            trained_offset_m: offset_m / scale,
            colour_residual_rad,
            residual_rad: colour_residual_rad.iter().fold(0.0, |a, &b| a.max(b)),
        })
    }

    /// The volume depth (metres) this mapping serves: `σ·V`.
    pub fn served_volume_depth_m(&self) -> f64 {
        self.scale * self.trained.volume_depth_m
    }

    /// True for the training display itself (`σ = 1` and the same wavelengths, to a relative 1e-6).
    pub fn is_identity(&self) -> bool {
        close(self.display.pixel_pitch_m, self.trained.pixel_pitch_m)
            && self
                .display
                .wavelengths_m
                .iter()
                .zip(&self.trained.wavelengths_m)
                .all(|(a, b)| close(*a, *b))
    }

    /// The largest per-colour spread `|σ_c/σ − 1|` as a fraction.
    pub fn spread(&self) -> f64 {
        self.ratio_mismatch_pct
            .iter()
            .fold(0.0f64, |a, &b| a.max(b.abs()))
            / 100.0
    }

    /// Why the model cannot serve the display, if it cannot: the colour whose scale is off by more than the
    /// tolerance (`tensorholo.wavelengths_m`), a residual above [`MAX_NONPARAXIAL_RESIDUAL_RAD`]
    /// (`tensorholo.pixel_pitch_m`) or a volume other than `σ·V` (`tensorholo.volume_depth_m`).
    /// `model` names the model in the message (e.g. "the 8-layer hologram CNN").
    ///
    /// Errors: none; returns the [`HoloError::ModelMetadata`] to report.
    pub fn refusal(&self, model: &str) -> Option<HoloError> {
        let t = &self.trained;
        let d = &self.display;
        let nm = |w: &[f64; 3]| format!("{:.1}/{:.1}/{:.1} nm", w[0] * 1e9, w[1] * 1e9, w[2] * 1e9);
        let spread = self.spread();
        if spread > self.tolerance * (1.0 + 1e-9) {
            // The odd one out: the colour farthest from the median scale.
            let mut sorted = self.colour_scales;
            sorted.sort_by(f64::total_cmp);
            let median = sorted[1];
            let c = (0..3)
                .max_by(|&a, &b| {
                    (self.colour_scales[a] - median)
                        .abs()
                        .total_cmp(&(self.colour_scales[b] - median).abs())
                })
                .unwrap_or(0);
            return Some(bad(
                "wavelengths_m",
                nm(&t.wavelengths_m),
                format!(
                    "lasers that scale depths alike on this {} µm display: {model} (trained at {} µm, {}) scales {} {:.1} nm → {:.1} nm by σ = {:.5}, the others by {:.5}–{:.5} ({:+.2} % off the common σ = {:.5}; tolerance {:.2} %{})",
                    d.pixel_pitch_m * 1e6,
                    t.pixel_pitch_m * 1e6,
                    nm(&t.wavelengths_m),
                    COLOUR[c],
                    t.wavelengths_m[c] * 1e9,
                    d.wavelengths_m[c] * 1e9,
                    self.colour_scales[c],
                    (0..3)
                        .filter(|&o| o != c)
                        .map(|o| self.colour_scales[o])
                        .fold(f64::INFINITY, f64::min),
                    (0..3)
                        .filter(|&o| o != c)
                        .map(|o| self.colour_scales[o])
                        .fold(0.0, f64::max),
                    self.ratio_mismatch_pct[c],
                    self.scale,
                    self.tolerance * 100.0,
                    if self.widened { ", widened" } else { "" }
                ) + RETRAIN_HINT,
            ));
        }
        if self.residual_rad > MAX_NONPARAXIAL_RESIDUAL_RAD {
            let c = (0..3)
                .max_by(|&a, &b| {
                    self.colour_residual_rad[a].total_cmp(&self.colour_residual_rad[b])
                })
                .unwrap_or(0);
            return Some(bad(
                "pixel_pitch_m",
                t.pixel_pitch_m.to_string(),
                format!(
                    "a display the paraxial mapping holds for: {model} (trained at {} µm) on this {} µm display leaves a non-paraxial phase residual of {:.3} rad ({}, |z'| up to {:.3} mm) above the bound of {MAX_NONPARAXIAL_RESIDUAL_RAD} rad",
                    t.pixel_pitch_m * 1e6,
                    d.pixel_pitch_m * 1e6,
                    self.colour_residual_rad[c],
                    COLOUR[c],
                    self.max_distance_m * 1e3
                ) + RETRAIN_HINT,
            ));
        }
        let served = self.served_volume_depth_m();
        if !close(served, d.volume_depth_m) {
            return Some(bad(
                "volume_depth_m",
                t.volume_depth_m.to_string(),
                format!(
                    "a volume that maps onto this display: {model} trained at {} µm, {}, {} mm volume serves this {} µm display with a {} mm volume ({} m, σ = {}), not {} mm",
                    sig(t.pixel_pitch_m * 1e6),
                    nm(&t.wavelengths_m),
                    sig(t.volume_depth_m * 1e3),
                    sig(d.pixel_pitch_m * 1e6),
                    sig(served * 1e3),
                    sig(served),
                    sig(self.scale),
                    sig(d.volume_depth_m * 1e3)
                ) + RETRAIN_HINT,
            ));
        }
        None
    }

    /// One line for logs and reports, e.g. "the 8-layer hologram CNN (trained at 8 µm, 6 mm volume) serves
    /// 4 µm with a 1.5 mm volume (σ = 0.25); offset 1.5 mm ↔ 6 mm trained; wavelength mismatch 0.00 %
    /// (tolerance 0.50 %); non-paraxial residual 0.084 rad (bound 0.25 rad)".
    pub fn description(&self, model: &str) -> String {
        let g = sig;
        format!(
            "{model} (trained at {} µm, {} mm volume) serves {} µm with a {} mm volume (σ = {:.6}); offset {} mm ↔ {} mm trained; wavelength mismatch {:.2} % (tolerance {:.2} %{}); non-paraxial residual {:.3} rad (bound {MAX_NONPARAXIAL_RESIDUAL_RAD} rad)",
            g(self.trained.pixel_pitch_m * 1e6),
            g(self.trained.volume_depth_m * 1e3),
            g(self.display.pixel_pitch_m * 1e6),
            g(self.served_volume_depth_m() * 1e3),
            self.scale,
            g(self.offset_m * 1e3),
            g(self.trained_offset_m * 1e3),
            self.spread() * 100.0,
            self.tolerance * 100.0,
            if self.widened { ", widened" } else { "" },
            self.residual_rad,
        )
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

    /// The display this file was trained for: `tensorholo.wavelengths_m`, `pixel_pitch_m`,
    /// `volume_depth_m`.
    pub fn optics(&self) -> OpticalSetup {
        OpticalSetup {
            wavelengths_m: self.wavelengths_m,
            pixel_pitch_m: self.pixel_pitch_m,
            volume_depth_m: self.volume_depth_m,
        }
    }

    /// A short name for messages: "the 8-layer hologram CNN" or "the 8-layer pre-filter CNN".
    pub fn describe(&self) -> String {
        match self.kind {
            ModelKind::Hologram => format!("the {}-layer hologram CNN", self.layers),
            ModelKind::PreFilter => format!("the {}-layer pre-filter CNN", self.layers),
        }
    }

    /// Checks the file against the expected kind and configuration, and returns how the model's training
    /// display maps onto the configured one ([`DisplayMapping`]; `σ = 1` for the paper's display).
    ///
    /// The optics need not be equal: the model serves any Fresnel-equivalent display (`docs/DISPLAYS.md`),
    /// one whose per-colour depth scales `σ_c = (λ_c/λ'_c)·(p'/p)²` agree within
    /// [`ModelConfig::wavelength_ratio_tolerance`], whose volume is `σ·V` (relative 1e-6), whose offset is
    /// `σ·s` (relative 1e-6) and whose non-paraxial residual is at most [`MAX_NONPARAXIAL_RESIDUAL_RAD`].
    ///
    /// Errors: [`HoloError::ModelMetadata`] naming the first mismatching key, the file's value and what was
    /// expected (kind; `wavelengths_m` with the colour whose scale is off; `pixel_pitch_m` for a residual
    /// above the bound; `volume_depth_m` with the volume that would be served; offset; input layers);
    /// [`HoloError::InvalidParameter`] for an invalid configuration or metadata optics. A hologram CNN whose
    /// `offset_m` is 0 (trained for the midpoint hologram alone) matches any offset; a pre-filter's
    /// `input_layers` is not checked (it sees the offset hologram, not the scene).
    pub fn check(&self, kind: ModelKind, expected: &ModelConfig) -> Result<DisplayMapping> {
        if self.kind != kind {
            return Err(bad("kind", self.kind.metadata_name(), kind.metadata_name()));
        }
        let mapping = DisplayMapping::compute(
            &self.optics(),
            &expected.optics,
            expected.offset_m,
            expected.wavelength_ratio_tolerance,
        )?;
        // Lasers that do not scale alike are named first (no volume or offset would fix them), then a
        // volume other than σ·V (a pitch changed alone lands here), and only then the offset.
        if mapping.spread() > mapping.tolerance * (1.0 + 1e-9)
            || !close(
                mapping.served_volume_depth_m(),
                expected.optics.volume_depth_m,
            )
        {
            if let Some(e) = mapping.refusal(&self.describe()) {
                return Err(e);
            }
        }
        // A hologram CNN trained for the midpoint alone (stage 1, `offset_m = 0`) serves every offset; one
        // fine-tuned jointly with a pre-filter (stage 2 of the paper) only that pre-filter's offset.
        let served_offset_m = mapping.scale * self.offset_m;
        if (kind == ModelKind::PreFilter || self.offset_m != 0.0)
            && !close(served_offset_m, expected.offset_m)
        {
            return Err(bad(
                "offset_m",
                self.offset_m.to_string(),
                if mapping.is_identity() {
                    expected.offset_m.to_string()
                } else {
                    format!(
                        "{} (the offset that serves {} m on this display is σ·{} m = {} m)",
                        sig(expected.offset_m / mapping.scale),
                        expected.offset_m,
                        self.offset_m,
                        sig(served_offset_m)
                    )
                },
            ));
        }
        if let Some(e) = mapping.refusal(&self.describe()) {
            return Err(e);
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
    use crate::optics::{Carrier, PropagationOptions, Propagator};

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
            HoloError::ModelMetadata { key, .. } => key,
            other => panic!("expected a metadata error, got {other}"),
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
    fn wrong_volume_is_refused_with_the_served_volume() {
        let e = metadata(ModelKind::Hologram, 0.0)
            .check(ModelKind::Hologram, &config(display(3.74e-6, 1.5e-3), 0.0))
            .unwrap_err();
        let text = e.to_string();
        assert!(text.contains("1.3113375 mm volume"), "{text}");
        assert!(text.contains("not 1.5 mm"), "{text}");
        assert_eq!(key(e), "tensorholo.volume_depth_m");
        metadata(ModelKind::Hologram, 0.0)
            .check(
                ModelKind::Hologram,
                &config(display(3.74e-6, 1.3113375e-3), 1.3113375e-3),
            )
            .unwrap();
    }

    #[test]
    fn unequal_laser_ratio_names_the_colour_until_widened() {
        let mut optics = display(8e-6, 6e-3);
        optics.wavelengths_m[1] = 532e-9;
        let md = metadata(ModelKind::Hologram, 0.0);
        let e = md
            .check(ModelKind::Hologram, &config(optics, 6e-3))
            .unwrap_err();
        let text = e.to_string();
        assert!(text.contains("green"), "{text}");
        assert_eq!(key(e), "tensorholo.wavelengths_m");
        // σ = √(σ_min·σ_max); the volume must follow it.
        let mut cfg = config(optics, 6e-3);
        cfg.wavelength_ratio_tolerance = 0.03;
        let m = DisplayMapping::compute(&md.optics(), &optics, 6e-3, 0.03).unwrap();
        cfg.optics.volume_depth_m = m.served_volume_depth_m();
        let m = md.check(ModelKind::Hologram, &cfg).unwrap();
        assert!(m.widened);
        assert!(m.spread() > 0.01 && m.spread() < 0.013, "{}", m.spread());
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

    #[test]
    fn bad_tolerance_is_a_typed_error() {
        let d = display(8e-6, 6e-3);
        for t in [-0.1, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                DisplayMapping::compute(&d, &d, 0.0, t),
                Err(HoloError::InvalidParameter {
                    name: "wavelength_ratio_tolerance",
                    ..
                })
            ));
        }
    }

    /// The residual against both transfer functions of the optics module on a 1 × N grid: the same
    /// frequency index `k` of both grids, the largest phase difference over the band.
    #[test]
    fn residual_matches_the_sampled_transfer_functions() {
        let n = 256;
        for (pitch, offset) in [
            (4e-6, 6e-3),
            (3.74e-6, 6e-3),
            (3.74e-6, 12e-3),
            (6.4e-6, 6e-3),
        ] {
            let s = (pitch / 8e-6f64).powi(2);
            let user = display(pitch, 6e-3 * s);
            let m =
                DisplayMapping::compute(&display(8e-6, 6e-3), &user, offset * s, 0.005).unwrap();
            let mut worst = 0.0f64;
            for (c, &l) in PAPER.iter().enumerate() {
                let z = m.max_distance_m / m.scale;
                let tf = |p: f64, z: f64| {
                    Propagator::new(1, n, p, l, PropagationOptions::default())
                        .unwrap()
                        .transfer_function(z, Carrier::Remove)
                        .unwrap()
                };
                let (a, b) = (tf(pitch, m.colour_scales[c] * z), tf(8e-6, z));
                let direct = a
                    .values()
                    .iter()
                    .zip(b.values())
                    .map(|(x, y)| (x * y.conj()).arg().abs() as f64)
                    .fold(0.0, f64::max);
                assert!(
                    (direct - m.colour_residual_rad[c]).abs() < 1e-3,
                    "{pitch} {c}: {direct} vs {}",
                    m.colour_residual_rad[c]
                );
                worst = worst.max(direct);
            }
            assert!(
                worst > 0.0 && worst < MAX_NONPARAXIAL_RESIDUAL_RAD,
                "{worst}"
            );
            eprintln!(
                "{pitch} m, offset {offset} m: residual {:?} rad",
                m.colour_residual_rad
            );
        }
    }
}

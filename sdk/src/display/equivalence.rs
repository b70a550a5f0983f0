//! Fresnel equivalence: how a model trained for one display serves another (`docs/DISPLAYS.md`), what the
//! mapping costs, and the rules that decide whether it serves.
//!
//! On the SLM's grid (pitch `p`) the carrier-free angular-spectrum transfer function (Eq. 2, Eq. 6) is
//! paraxially `exp(−i·π·λ·z·f²)` with `f = k/(N·p)`: it depends on the display only through `λ·z/p²` per
//! colour. A model trained at `(p, λ_c, V, s)` therefore serves `(p', λ'_c)` when the depth scale
//! `σ_c = (λ_c/λ'_c)·(p'/p)²` is one `σ` for the three colours: volume `V' = σ·V`, offsets `s' = σ·s`, and
//! every depth `z' = σ·z` ([`DisplayMapping`]).
//!
//! The rules ([`DisplayMapping::refusal`]):
//! - **lasers** whose `σ_c` differ: served while the mapping's error keeps what the viewer sees within
//!   [`MAPPING_COST_BUDGET_DB`] of what the model gives on its own display ([`mapping_cost_db`]: errors add in
//!   power; the mapping's ceiling [`predicted_ceiling_db`] from the measured curve; the model's score from its
//!   test split). That sets the default tolerance per model ([`rule_tolerance`]); a caller may give another.
//! - **volume**: within [`VOLUME_ROUNDING`] of `σ·V`, served at `σ·V`; smaller, served by mapping the scene's
//!   depths into the part of the model's volume it needs ([`VolumeFit::Partial`]); deeper, refused.
//! - **the non-paraxial residual** the mapping leaves (`nonparaxial_residual_rad`): at most
//!   [`MAX_NONPARAXIAL_RESIDUAL_RAD`].
//!
//! Every refusal says what would serve ([`DisplayRefusal`], defined with the error that carries it): the
//! nearest display this model serves, the tolerance that would serve it and its cost, and retraining.
//! Imports only `optics` and `error`.

use crate::error::{invalid, DisplayRefusal, NearestDisplay, Result};
use crate::optics::{carrier_free_phase_rad, OpticalSetup};

/// How much a mapping may cost what the viewer sees, in dB, against what the model gives on its own display.
pub const MAPPING_COST_BUDGET_DB: f64 = 0.3;

/// The mapping's ceiling at a 1 % laser spread, dB (focal-stack PSNR of SM-LBM at the model's display shown
/// on the user's, against SM-LBM at the user's): the fit `45.7 − 20·log10(ε / 1 %)` of
/// `scripts/display-mismatch.sh`'s measurements (built-in scene, 384², 2048 planes: 57.67 / 51.68 / 45.72 /
/// 39.84 / 34.10 dB at 0.25 / 0.5 / 1 / 1.98 / 3.92 %, within 0.3 dB of the fit; docs/DISPLAYS.md).
pub const CEILING_AT_1PCT_DB: f64 = 45.7;

/// How far (a fraction) the volume may be from `σ·V` and still be served at `σ·V`: 1 %.
pub const VOLUME_ROUNDING: f64 = 0.01;

/// The largest non-paraxial residual, in radians, that the mapping may leave: λ/25 of wavefront at the
/// band edge and the outermost depth.
pub const MAX_NONPARAXIAL_RESIDUAL_RAD: f64 = 0.25;

/// A laser spread below this (a fraction) is the rounding of wavelengths written in decimal (520e-9 against
/// 5.2e-7), not a mismatch: no cost, an infinite ceiling.
pub const SPREAD_NOISE: f64 = 1e-9;

/// Frequencies sampled over the Nyquist band by `nonparaxial_residual_rad`.
const RESIDUAL_SAMPLES: usize = 1024;
/// Relative tolerance of "the same length" (volumes, offsets, pitches).
const REL_TOL: f64 = 1e-6;
/// Names of the colours R, G, B for messages.
const COLOUR: [&str; 3] = ["red", "green", "blue"];

/// The mapping's predicted ceiling in dB at a relative laser spread `spread` (a fraction;
/// [`DisplayMapping::spread`]): [`CEILING_AT_1PCT_DB`] less 6 dB per doubling of the spread (the mapping's
/// error grows linearly with it); infinite at 0 (and below [`SPREAD_NOISE`], rounding of the wavelengths).
pub fn predicted_ceiling_db(spread: f64) -> f64 {
    if spread <= SPREAD_NOISE {
        f64::INFINITY
    } else {
        CEILING_AT_1PCT_DB - 20.0 * (spread / 0.01).log10()
    }
}

/// What a mapping whose own error is `ceiling_db` below the signal costs a model that scores `score_db` on
/// its own display, in dB: errors add in power, `10·log10(1 + 10^((score − ceiling)/10))`; 0 for an infinite
/// ceiling.
pub fn mapping_cost_db(score_db: f64, ceiling_db: f64) -> f64 {
    if !ceiling_db.is_finite() {
        return 0.0;
    }
    10.0 * (1.0 + 10f64.powf((score_db - ceiling_db) / 10.0)).log10()
}

/// The largest laser spread (a fraction) whose predicted cost ([`mapping_cost_db`] at
/// [`predicted_ceiling_db`]) stays within [`MAPPING_COST_BUDGET_DB`] for a model scoring `score_db`: the
/// default tolerance of that model (1.83 % for 29.02 dB, the 30-layer CNN's test-split focal-stack PSNR).
pub fn rule_tolerance(score_db: f64) -> f64 {
    // The ceiling must lie `margin` dB above the score: 11.46 dB for 0.3 dB.
    let margin = -10.0 * (10f64.powf(MAPPING_COST_BUDGET_DB / 10.0) - 1.0).log10();
    0.01 * 10f64.powf((CEILING_AT_1PCT_DB - score_db - margin) / 20.0)
}

/// The non-paraxial residual (radians) of serving a display with the model of another: the largest
/// `|φ'(f') − φ(f'·p'/p)|` over `f' ∈ [0, 1/(2p')]` (the user grid's Nyquist band along an axis), where
/// `φ'` is the carrier-free transfer phase (`optics::carrier_free_phase_rad`) at the user's `(λ', z')` and `φ` the
/// training display's at `(λ, z)`, at the same frequency index of both grids. Paraxially both are
/// `−π·λ·z·f²` and cancel when `λ'·z'/p'² = λ·z/p²`; what remains is the `f⁴` term and beyond.
///
/// Lengths in metres. Returns `f64::INFINITY` when a frequency of either grid is evanescent.
pub(crate) fn nonparaxial_residual_rad(
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
            carrier_free_phase_rad(wavelength_m, distance_m, f_user * f_user),
            carrier_free_phase_rad(trained_wavelength_m, trained_distance_m, f_train * f_train),
        ) {
            (Some(a), Some(b)) => worst = worst.max((a - b).abs()),
            _ => return f64::INFINITY,
        }
    }
    worst
}

/// How the configured volume relates to the volume the model serves, `σ·V`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(rename_all = "kebab-case", tag = "fit")]
pub enum VolumeFit {
    /// `σ·V` itself (to a relative 1e-6).
    Mapped,
    /// Within [`VOLUME_ROUNDING`] of `σ·V`: served at `σ·V` (the pipeline runs with it).
    Rounded {
        /// The volume asked for, metres.
        requested_m: f64,
    },
    /// Smaller than `σ·V`: the scene's depths are mapped into the central `fraction` of the model's volume
    /// (normalised depth `d` → `0.5 + (d − 0.5)·fraction`), so that they span the volume asked for.
    Partial {
        /// The volume asked for over `σ·V`, in (0, 1).
        fraction: f64,
    },
    /// Deeper than `σ·V` plus the rounding: refused.
    TooDeep,
}

/// How a model trained for one display serves another, Fresnel-equivalent one (see [the module](crate::display)).
/// Built by [`DisplayMapping::compute`]; `ModelMetadata::check` accepts a model through it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct DisplayMapping {
    /// The display the model was trained for (`tensorholo.*`).
    pub trained: OpticalSetup,
    /// The display it serves (the caller's, as given).
    pub display: OpticalSetup,
    /// `σ`, the common depth scale: the geometric midpoint `√(min σ_c · max σ_c)` of the per-colour scales
    /// (1 for the training display itself).
    pub scale: f64,
    /// Per-colour scales `σ_c = (λ_c/λ'_c)·(p'/p)²`, R, G, B.
    pub colour_scales: [f64; 3],
    /// Per-colour mismatch `100·(σ_c/σ − 1)` in percent, R, G, B.
    pub ratio_mismatch_pct: [f64; 3],
    /// The accepted laser spread (a fraction): the caller's, or the rule's for this model's score.
    pub tolerance: f64,
    /// True when `tolerance` is the rule's ([`rule_tolerance`] of `score_db`), not a caller's.
    pub tolerance_from_rule: bool,
    /// True when the caller's tolerance is wider than the rule's.
    pub widened: bool,
    /// The model's score on its own display, dB (test-split focal-stack PSNR on its model card).
    pub score_db: f64,
    /// The mapping's predicted ceiling, dB ([`predicted_ceiling_db`] at the spread; infinite at 0).
    pub ceiling_db: f64,
    /// The mapping's estimated cost, dB ([`mapping_cost_db`] of `score_db` and `ceiling_db`).
    pub cost_db: f64,
    /// How the configured volume relates to `σ·V`.
    pub volume: VolumeFit,
    /// The user's largest `|z'|` in metres: half the served volume `σ·V/2` plus the user's `|s'|`.
    pub max_distance_m: f64,
    /// The user's offset `s'` in metres.
    pub offset_m: f64,
    /// `s'/σ`: the offset on the training display that the user's offset corresponds to, metres.
    pub trained_offset_m: f64,
    /// Per-colour non-paraxial residual in radians (`nonparaxial_residual_rad` at `z = max_distance_m/σ`
    /// on the training display and `z' = σ_c·z` on the user's), R, G, B.
    pub colour_residual_rad: [f64; 3],
    /// The largest of [`DisplayMapping::colour_residual_rad`], radians.
    pub residual_rad: f64,
}

impl NearestDisplay {
    /// The display's optics: wavelengths, pitch, volume (metres).
    pub fn optics(&self) -> OpticalSetup {
        OpticalSetup {
            wavelengths_m: self.wavelengths_m,
            pixel_pitch_m: self.pixel_pitch_m,
            volume_depth_m: self.volume_depth_m,
        }
    }

    /// `optics` at offset `offset_m` (metres), the display's other offsets scaled by `offsets_scale`.
    pub(crate) fn new(optics: &OpticalSetup, offset_m: f64, offsets_scale: f64) -> Self {
        Self {
            wavelengths_m: optics.wavelengths_m,
            pixel_pitch_m: optics.pixel_pitch_m,
            volume_depth_m: optics.volume_depth_m,
            offset_m,
            offsets_scale,
        }
    }
}

/// `x` rounded to nine significant digits, for messages (`1.3113375e-3`, not `0.0013113375000000001`).
pub(crate) fn sig(x: f64) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let scale = 10f64.powi(8 - x.abs().log10().floor() as i32);
    (x * scale).round() / scale
}

/// `a` and `b` agree to a relative [`REL_TOL`].
pub(crate) fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= REL_TOL * a.abs().max(b.abs())
}

impl DisplayMapping {
    /// The mapping from the `trained` display (the model's metadata) to `display` at the user's offset
    /// `offset_m` (metres), for a model scoring `score_db` on its own display. `tolerance`: the largest
    /// accepted laser spread (a fraction), `None` for the rule's ([`rule_tolerance`]). Computes only;
    /// [`DisplayMapping::refusal`] says whether the model may serve.
    ///
    /// Errors: [`crate::HoloError::InvalidParameter`] for a non-finite or non-positive pitch, wavelength or
    /// volume, a non-finite offset (`offset_m`), a tolerance that is negative or not finite
    /// (`wavelength_ratio_tolerance`), a non-finite score (`score_db`), or a mapping whose scale or
    /// distances overflow (`pixel_pitch_m`).
    pub fn compute(
        trained: &OpticalSetup,
        display: &OpticalSetup,
        offset_m: f64,
        tolerance: Option<f64>,
        score_db: f64,
    ) -> Result<Self> {
        trained.validate()?;
        display.validate()?;
        if !offset_m.is_finite() {
            return Err(invalid(
                "offset_m",
                format!("must be finite, got {offset_m}"),
            ));
        }
        if let Some(t) = tolerance {
            if !(t.is_finite() && t >= 0.0) {
                return Err(invalid(
                    "wavelength_ratio_tolerance",
                    format!("must be a finite fraction ≥ 0 (0.01 = 1 %), got {t}"),
                ));
            }
        }
        if !score_db.is_finite() {
            return Err(invalid(
                "score_db",
                format!("must be finite, got {score_db}"),
            ));
        }
        let pitch2 = (display.pixel_pitch_m / trained.pixel_pitch_m).powi(2);
        let colour_scales: [f64; 3] =
            std::array::from_fn(|c| trained.wavelengths_m[c] / display.wavelengths_m[c] * pitch2);
        if colour_scales.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(invalid(
                "pixel_pitch_m",
                format!(
                    "the display ({} m pitch) and the model's ({} m) give no finite depth scale",
                    display.pixel_pitch_m, trained.pixel_pitch_m
                ),
            ));
        }
        let (lo, hi) = colour_scales
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(lo, hi), &s| {
                (lo.min(s), hi.max(s))
            });
        // Exactly the per-colour scale when the three agree (no rounding from the square root).
        let scale = if lo == hi { lo } else { (lo * hi).sqrt() };
        let ratio_mismatch_pct = colour_scales.map(|s| {
            let m = s / scale - 1.0;
            if m.abs() <= SPREAD_NOISE {
                0.0
            } else {
                100.0 * m
            }
        });
        let spread = ratio_mismatch_pct
            .iter()
            .fold(0.0f64, |a, &b| a.max(b.abs()))
            / 100.0;
        let served = scale * trained.volume_depth_m;
        let volume = volume_fit(display.volume_depth_m, served);
        let max_distance_m = 0.5 * served + offset_m.abs();
        if !max_distance_m.is_finite() {
            return Err(invalid(
                "pixel_pitch_m",
                format!("the mapped volume ({served} m) is not finite"),
            ));
        }
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
        let rule = rule_tolerance(score_db);
        let ceiling_db = predicted_ceiling_db(spread);
        Ok(Self {
            trained: *trained,
            display: *display,
            scale,
            colour_scales,
            ratio_mismatch_pct,
            tolerance: tolerance.unwrap_or(rule),
            tolerance_from_rule: tolerance.is_none(),
            widened: tolerance.is_some_and(|t| t > rule),
            score_db,
            ceiling_db,
            cost_db: mapping_cost_db(score_db, ceiling_db),
            volume,
            max_distance_m,
            offset_m,
            trained_offset_m: offset_m / scale,
            colour_residual_rad,
            residual_rad: colour_residual_rad.iter().fold(0.0, |a, &b| a.max(b)),
        })
    }

    /// The volume depth (metres) the model serves through this mapping: `σ·V`.
    pub fn served_volume_depth_m(&self) -> f64 {
        self.scale * self.trained.volume_depth_m
    }

    /// The volume the pipeline runs with: `σ·V` where the configured volume is within the rounding of it,
    /// the configured one otherwise.
    pub(crate) fn running_volume_depth_m(&self) -> f64 {
        match self.volume {
            VolumeFit::Rounded { .. } => self.served_volume_depth_m(),
            _ => self.display.volume_depth_m,
        }
    }

    /// The factor the scene's normalised depths are scaled by about 0.5 before the CNN sees them: the
    /// fraction of the model's volume a smaller volume uses ([`VolumeFit::Partial`]), 1 otherwise.
    pub fn depth_fraction(&self) -> f64 {
        match self.volume {
            VolumeFit::Partial { fraction } => fraction,
            _ => 1.0,
        }
    }

    /// The largest volume this model serves on this display: `σ·V` and the rounding above it, metres.
    pub(crate) fn largest_volume_m(&self) -> f64 {
        self.served_volume_depth_m() * (1.0 + VOLUME_ROUNDING)
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

    /// The nearest display whose lasers scale depths alike: the colours off the median scale `σ_m` moved to
    /// `λ_c·(p'/p)²/σ_m` (two lasers that agree keep their wavelengths; the odd one moves), the volume
    /// `σ_m·V` and the offset scaled alike (`s'·σ_m/σ`).
    fn nearest_lasers(&self) -> NearestDisplay {
        let pitch2 = (self.display.pixel_pitch_m / self.trained.pixel_pitch_m).powi(2);
        let mut sorted = self.colour_scales;
        sorted.sort_by(f64::total_cmp);
        let median = sorted[1];
        let optics = OpticalSetup {
            wavelengths_m: std::array::from_fn(|c| {
                if close(self.colour_scales[c], median) {
                    self.display.wavelengths_m[c]
                } else {
                    self.trained.wavelengths_m[c] * pitch2 / median
                }
            }),
            pixel_pitch_m: self.display.pixel_pitch_m,
            volume_depth_m: median * self.trained.volume_depth_m,
        };
        NearestDisplay::new(
            &optics,
            self.offset_m * median / self.scale,
            median / self.scale,
        )
    }

    /// Why the model cannot serve the display, if it cannot, and what would: lasers whose spread exceeds the
    /// tolerance (`tensorholo.wavelengths_m`: the colour farthest off, the spread's cost, the tolerance that
    /// would serve it), a volume deeper than `σ·V` and its rounding (`tensorholo.volume_depth_m`, naming the
    /// largest served), or a residual above [`MAX_NONPARAXIAL_RESIDUAL_RAD`] (`tensorholo.pixel_pitch_m`).
    /// `model` names the model in the message (e.g. "the 8-layer hologram CNN").
    pub fn refusal(&self, model: &str) -> Option<DisplayRefusal> {
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
            let others = (0..3).filter(|&o| o != c).map(|o| self.colour_scales[o]);
            let (olo, ohi) = others.fold((f64::INFINITY, 0.0f64), |(a, b), s| (a.min(s), b.max(s)));
            // Just over the spread, so that the suggested value serves it.
            let needed = (spread * 1.0001 * 1e6).ceil() / 1e6;
            return Some(DisplayRefusal {
                key: "tensorholo.wavelengths_m".into(),
                found: nm(&t.wavelengths_m),
                expected: format!(
                    "lasers that scale depths alike on this {} µm display: {model} (trained at {} µm, {}) scales {} {:.1} nm → {:.1} nm by σ = {:.5}, the others by {:.5}–{:.5} ({:+.2} % off the common σ = {:.5}); a {:.2} % spread costs an estimated {:.2} dB (mapping ceiling {:.1} dB against the model's {:.2} dB), above the {MAPPING_COST_BUDGET_DB} dB budget (tolerance {:.2} %{})",
                    sig(d.pixel_pitch_m * 1e6),
                    sig(t.pixel_pitch_m * 1e6),
                    nm(&t.wavelengths_m),
                    COLOUR[c],
                    t.wavelengths_m[c] * 1e9,
                    d.wavelengths_m[c] * 1e9,
                    self.colour_scales[c],
                    olo,
                    ohi,
                    self.ratio_mismatch_pct[c],
                    self.scale,
                    spread * 100.0,
                    self.cost_db,
                    self.ceiling_db,
                    self.score_db,
                    self.tolerance * 100.0,
                    if self.tolerance_from_rule {
                        ", the rule's"
                    } else {
                        ", given"
                    }
                ),
                nearest: Some(self.nearest_lasers()),
                tolerance: Some((needed, mapping_cost_db(self.score_db, predicted_ceiling_db(spread)))),
            });
        }
        if self.volume == VolumeFit::TooDeep {
            let served = self.served_volume_depth_m();
            return Some(DisplayRefusal {
                key: "tensorholo.volume_depth_m".into(),
                found: t.volume_depth_m.to_string(),
                expected: format!(
                    "a volume this model serves: {model} trained at {} µm, {}, {} mm volume serves this {} µm display with volumes up to {} mm (σ·V = {} mm, σ = {}, and {} % above it), not {} mm",
                    sig(t.pixel_pitch_m * 1e6),
                    nm(&t.wavelengths_m),
                    sig(t.volume_depth_m * 1e3),
                    sig(d.pixel_pitch_m * 1e6),
                    sig(self.largest_volume_m() * 1e3),
                    sig(served * 1e3),
                    sig(self.scale),
                    VOLUME_ROUNDING * 100.0,
                    sig(d.volume_depth_m * 1e3)
                ),
                nearest: Some(NearestDisplay::new(
                    &OpticalSetup {
                        volume_depth_m: served,
                        ..*d
                    },
                    self.offset_m,
                    1.0,
                )),
                tolerance: None,
            });
        }
        if self.residual_rad > MAX_NONPARAXIAL_RESIDUAL_RAD {
            let c = (0..3)
                .max_by(|&a, &b| {
                    self.colour_residual_rad[a].total_cmp(&self.colour_residual_rad[b])
                })
                .unwrap_or(0);
            // The nearest display: the same, at offset 0, where that leaves a residual within the bound.
            let at_zero = Self::compute(t, d, 0.0, Some(self.tolerance), self.score_db).ok();
            let nearest = at_zero
                .filter(|m| self.offset_m != 0.0 && m.residual_rad <= MAX_NONPARAXIAL_RESIDUAL_RAD);
            return Some(DisplayRefusal {
                key: "tensorholo.pixel_pitch_m".into(),
                found: t.pixel_pitch_m.to_string(),
                expected: format!(
                    "a display the paraxial mapping holds for: {model} (trained at {} µm) on this {} µm display leaves a non-paraxial phase residual of {:.3} rad ({}, |z'| up to {:.3} mm) above the bound of {MAX_NONPARAXIAL_RESIDUAL_RAD} rad",
                    sig(t.pixel_pitch_m * 1e6),
                    sig(d.pixel_pitch_m * 1e6),
                    self.colour_residual_rad[c],
                    COLOUR[c],
                    self.max_distance_m * 1e3
                ),
                nearest: nearest.map(|m| {
                    NearestDisplay::new(
                        &OpticalSetup {
                            volume_depth_m: m.running_volume_depth_m(),
                            ..*d
                        },
                        0.0,
                        1.0,
                    )
                }),
                tolerance: None,
            });
        }
        None
    }

    /// One line for logs and reports, e.g. "the 8-layer hologram CNN (trained at 8 µm, 6 mm volume) serves
    /// 4 µm with a 1.5 mm volume (σ = 0.250000); offset 1.5 mm ↔ 6 mm trained; wavelength mismatch 0.00 %
    /// (tolerance 1.83 %, the rule's); mapping ceiling ∞, estimated cost 0.00 dB; non-paraxial residual
    /// 0.084 rad (bound 0.25 rad)".
    pub fn description(&self, model: &str) -> String {
        let g = sig;
        let volume = match self.volume {
            VolumeFit::Mapped | VolumeFit::TooDeep => String::new(),
            VolumeFit::Rounded { requested_m } => format!(
                " ({} mm asked for, within {} % of it: served at {} mm)",
                g(requested_m * 1e3),
                VOLUME_ROUNDING * 100.0,
                g(self.served_volume_depth_m() * 1e3)
            ),
            VolumeFit::Partial { fraction } => format!(
                "; the scene's {} mm volume uses the central {:.1} % of it",
                g(self.display.volume_depth_m * 1e3),
                fraction * 100.0
            ),
        };
        let ceiling = if self.ceiling_db.is_finite() {
            format!("{:.1} dB", self.ceiling_db)
        } else {
            "∞".to_string()
        };
        format!(
            "{model} (trained at {} µm, {} mm volume) serves {} µm with a {} mm volume (σ = {:.6}){volume}; offset {} mm ↔ {} mm trained; wavelength mismatch {:.2} % (tolerance {:.2} %{}); mapping ceiling {ceiling}, estimated cost {:.2} dB (budget {MAPPING_COST_BUDGET_DB} dB against the model's {:.2} dB); non-paraxial residual {:.3} rad (bound {MAX_NONPARAXIAL_RESIDUAL_RAD} rad)",
            g(self.trained.pixel_pitch_m * 1e6),
            g(self.trained.volume_depth_m * 1e3),
            g(self.display.pixel_pitch_m * 1e6),
            g(self.served_volume_depth_m() * 1e3),
            self.scale,
            g(self.offset_m * 1e3),
            g(self.trained_offset_m * 1e3),
            self.spread() * 100.0,
            self.tolerance * 100.0,
            if self.tolerance_from_rule {
                ", the rule's"
            } else if self.widened {
                ", widened"
            } else {
                ", given"
            },
            self.cost_db,
            self.score_db,
            self.residual_rad,
        )
    }
}

/// How a configured volume `requested` relates to the served `σ·V` (`served`).
fn volume_fit(requested: f64, served: f64) -> VolumeFit {
    if close(requested, served) {
        VolumeFit::Mapped
    } else if (requested / served - 1.0).abs() <= VOLUME_ROUNDING {
        VolumeFit::Rounded {
            requested_m: requested,
        }
    } else if requested < served {
        VolumeFit::Partial {
            fraction: requested / served,
        }
    } else {
        VolumeFit::TooDeep
    }
}

#[cfg(test)]
mod tests;

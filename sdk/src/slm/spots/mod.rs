//! The display's aberration calibrated from camera captures of focused spots (paper Methods, "Compensating
//! hardware imperfection", Eq. 14–19), by phase diversity: the paper's user calibration ("adjust the
//! coefficients until the camera images a tightly focused spot at `d`"), automated. Feature `research`.
//!
//! **Patterns** (`SpotPlan::pattern_codes`): for each colour, each signed distance `d` (metres, SLM →
//! focus, positive along the light, `docs/ABERRATION.md` "Distance") and each known diversity phase `D_k`
//! (`diversity_set`: none, focus `±δ`, vertical and oblique astigmatism `+δ`, `δ = 2 rad`
//! ([`DIVERSITY_RAD`])), the SLM pattern whose field at `d` has the spectrum `circ(ρ ≤ 1)·exp(i·D_k)`: that
//! spectrum (centred on the SLM) propagated by `−d` with the angular spectrum method ([`crate::optics`],
//! carrier removed, no padding or band limit, so that the display's propagation by `d` returns it exactly),
//! then plain double phase encoded (Eq. 7) and written as 8-bit codes of the linear look-up table
//! (`code = 256·φ/2π`). The user shows each pattern and photographs the focal plane at `d` through the
//! display's optics.
//!
//! **Model** (`model::SpotModel`): what the camera sees is `I_k = |F⁻¹{circ(ρ)·exp(i(Z_a + D_k + tilt))}|²`,
//! `Z_a` the display's aberration at `d` (Eq. 14–18), on an `n × n` window ([`SpotPlan::window_px`]) of camera
//! pixels, integrated over each pixel. `camera_scale = S` ([`SpotPlan::camera_scale`]) is the number of
//! camera pixels per SLM pixel pitch in the focal plane (the camera's magnification over its pixel pitch
//! times the SLM's pitch); the pupil edge `ρ = 1` then lies `n/(2S)` frequency bins from the window's centre.
//!
//! **Fit** (`fit::fit_distance`): per distance, the spot is found in the sum of its captures (the peak of a
//! blurred copy), the same `n × n` window is cut from every capture, and the five coefficients plus the
//! spot's two-pixel position (the tip/tilt, shared by the distance's captures) minimise the captures'
//! residual, each capture fitted with its own exposure and black level in closed form (least squares of
//! `a·I_k + b`), saturated pixels left out; Nelder–Mead (argmin) from deterministic starts.
//!
//! **Colours without captures** (`wavelength_scaled`): an aberration of refractive optics is an optical
//! path difference `W(u)` that does not depend on `λ` (dispersion neglected), a function of the ray angle
//! `u = λ·f`; with `ρ = |f|/f_N` for every colour (one pitch), the phase `2π·W(λ·f_N·ρ)/λ` of a quadratic
//! term `w₂·u²` is `2π·w₂·f_N²·λ·ρ²` and of a cubic one `w₃·u³` is `2π·w₃·f_N³·λ²·ρ³`: focus and astigmatism
//! scale with `λ_c/λ_ref`, coma with `(λ_c/λ_ref)²` (coma's `−2ρ` tilt part changes the spot's position
//! only). A colour without captures takes the fitted colour of nearest wavelength, so scaled.
//!
//! **Simulation** ([`simulate`]): a display with hidden random aberrations and a camera that differs from
//! the model's discretisation, to try the loop without hardware.

pub mod fit;
pub(crate) mod model;
mod patterns;
pub mod simulate;
pub mod windows;

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{invalid, HoloError, Result};
use crate::optics::{OpticalSetup, ZernikeCoefficients};

pub(crate) use patterns::fft2;

pub use fit::{fit_captures, FitOptions, FitReport};

/// Value of `plan.json`'s `format` field.
pub const PLAN_FORMAT: &str = "tensorholo.aberration-plan";
/// Version of the plan format this build reads and writes.
pub const PLAN_VERSION: u32 = 1;
/// The plan's file name in the patterns folder.
pub const PLAN_FILE: &str = "plan.json";
/// The simulated display's truth in a captures folder (a `tensorholo.aberration` file).
pub const HIDDEN_FILE: &str = "hidden.json";
/// The diversity amplitude `δ` in radians at the pupil edge.
pub const DIVERSITY_RAD: f64 = 2.0;
/// The largest `|distance|` in metres a plan accepts.
pub const MAX_DISTANCE_M: f64 = 1.0;
/// The smallest sub-hologram radius in SLM pixels, `|d|·tan(asin(λ/2p))/p`, a plan accepts: nearer the SLM
/// (`d = 0`: a spot on the SLM itself) the double phase encoding's leak through the Fourier filter outweighs
/// the spot.
pub const MIN_SUBHOLOGRAM_PX: f64 = 4.0;
/// The largest `|coefficient|` of a diversity phase, radians at the pupil edge: 4π (two waves). Phase diversity
/// uses a wave or less (the default [`DIVERSITY_RAD`]); beyond two waves the spot spreads past the fitted
/// window and the fit sees only its tails.
pub const MAX_DIVERSITY_RAD: f64 = 4.0 * std::f64::consts::PI;
/// Default camera pixels per SLM pixel pitch at the focal plane.
pub const DEFAULT_CAMERA_SCALE: f64 = 4.0;
/// Default side of the fitted window in camera pixels.
pub const DEFAULT_WINDOW_PX: usize = 64;
/// Colour names in files and plans (R, G, B).
pub const COLOURS: [&str; 3] = ["red", "green", "blue"];

/// The diversity phases `D_k` (Zernike coefficients, radians at `ρ = 1`) for amplitude `delta`: `k = 0` none,
/// `1` focus `+δ`, `2` focus `−δ`, `3` vertical astigmatism `+δ`, `4` oblique astigmatism `+δ`. The focus
/// pair tells `±a3` apart (the twin image of a pupil phase `φ(ρ, θ)` is `−φ(ρ, θ + π)`); the astigmatic
/// ones do the same for `a4`, `a5`.
pub(crate) fn diversity_set(delta: f64) -> Vec<ZernikeCoefficients> {
    let z = ZernikeCoefficients::ZERO;
    vec![
        z,
        ZernikeCoefficients { focus: delta, ..z },
        ZernikeCoefficients { focus: -delta, ..z },
        ZernikeCoefficients {
            astigmatism_vertical: delta,
            ..z
        },
        ZernikeCoefficients {
            astigmatism_oblique: delta,
            ..z
        },
    ]
}

/// The coefficients of wavelength `from_m` carried to wavelength `to_m` (metres) by the rule of the module
/// docs: focus and astigmatism times `to/from`, coma times `(to/from)²`.
pub(crate) fn wavelength_scaled(
    z: &ZernikeCoefficients,
    from_m: f64,
    to_m: f64,
) -> ZernikeCoefficients {
    let r = to_m / from_m;
    let a = z.to_array();
    ZernikeCoefficients::from_array([a[0] * r, a[1] * r, a[2] * r, a[3] * r * r, a[4] * r * r])
}

/// A spot calibration plan (`plan.json` in the patterns folder): the display, the colours, distances and
/// diversities, and the camera's sampling. File names follow from it (`SpotPlan::pattern_name`,
/// [`SpotPlan::capture_name`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpotPlan {
    /// [`PLAN_FORMAT`].
    pub format: String,
    /// [`PLAN_VERSION`].
    pub version: u32,
    /// SLM size `[height, width]` in pixels.
    pub slm_size: [usize; 2],
    /// SLM pixel pitch in metres.
    pub pixel_pitch_m: f64,
    /// Laser wavelengths R, G, B in metres.
    pub wavelengths_m: [f64; 3],
    /// Colours with patterns (`red`, `green`, `blue`; at least one, no repeat).
    pub colours: Vec<String>,
    /// Focus distances `d` in metres (signed, strictly increasing, `|d| ≤ 1 m`).
    pub distances_m: Vec<f64>,
    /// Diversity phases `D_k` (radians at `ρ = 1`), `diversity_set` by default.
    pub diversities: Vec<ZernikeCoefficients>,
    /// Camera pixels per SLM pixel pitch at the focal plane (`S`; the pupil spans `window_px/(2S)` bins).
    pub camera_scale: f64,
    /// Side `n` of the fitted window in camera pixels (even).
    pub window_px: usize,
}

impl SpotPlan {
    /// A plan for an SLM of `slm_size` `[height, width]` and the display `setup` (its pitch and wavelengths),
    /// the colours `colours` (indices 0–2), `distances_m` (sorted here), the default diversities and the
    /// camera's `camera_scale` and `window_px`.
    ///
    /// Errors: as [`SpotPlan::validate`].
    pub fn new(
        slm_size: [usize; 2],
        setup: &OpticalSetup,
        colours: &[usize],
        mut distances_m: Vec<f64>,
        camera_scale: f64,
        window_px: usize,
    ) -> Result<Self> {
        distances_m.sort_by(f64::total_cmp);
        let plan = Self {
            format: PLAN_FORMAT.into(),
            version: PLAN_VERSION,
            slm_size,
            pixel_pitch_m: setup.pixel_pitch_m,
            wavelengths_m: setup.wavelengths_m,
            colours: colours
                .iter()
                .map(|&c| COLOURS.get(c).copied().unwrap_or("?").to_string())
                .collect(),
            distances_m,
            diversities: diversity_set(DIVERSITY_RAD),
            camera_scale,
            window_px,
        };
        plan.validate()?;
        Ok(plan)
    }

    /// Checks every field. Errors: [`HoloError::InvalidParameter`] naming the field: another `format` or
    /// `version`, an empty SLM, a pitch or wavelength out of [`crate::optics::PITCH_RANGE_M`] /
    /// [`crate::optics::WAVELENGTH_RANGE_M`], an unknown or repeated colour, no distance, a non-finite
    /// distance or one beyond ±[`MAX_DISTANCE_M`], one so near the SLM that the spot's sub-hologram is
    /// smaller than [`MIN_SUBHOLOGRAM_PX`], unsorted or repeated distances, no diversity or a
    /// non-finite one, and a camera scale or window the model refuses (`SpotModel::new`).
    pub fn validate(&self) -> Result<()> {
        if self.format != PLAN_FORMAT {
            return Err(invalid(
                "format",
                format!("expected `{PLAN_FORMAT}`, got `{}`", self.format),
            ));
        }
        if self.version != PLAN_VERSION {
            return Err(invalid(
                "version",
                format!(
                    "unknown plan version {} (this build reads version {PLAN_VERSION})",
                    self.version
                ),
            ));
        }
        let [h, w] = self.slm_size;
        if h == 0
            || w == 0
            || h.max(w) > crate::display::MAX_SLM_SIDE
            || h.saturating_mul(w) > crate::display::MAX_SLM_PIXELS
        {
            return Err(invalid(
                "slm_size",
                format!(
                    "must be 1–{} pixels a side and at most {} pixels (8192 × 8192, as a display \
                     profile), got [{h}, {w}]",
                    crate::display::MAX_SLM_SIDE,
                    crate::display::MAX_SLM_PIXELS
                ),
            ));
        }
        OpticalSetup {
            wavelengths_m: self.wavelengths_m,
            pixel_pitch_m: self.pixel_pitch_m,
            volume_depth_m: 1e-3,
        }
        .validate()?;
        self.colour_indices()?;
        if self.distances_m.is_empty() {
            return Err(invalid("distances_m", "needs at least one distance"));
        }
        for &d in &self.distances_m {
            if !(d.is_finite() && d.abs() <= MAX_DISTANCE_M) {
                return Err(invalid(
                    "distances_m",
                    format!("{d} m is not a finite distance within ±{MAX_DISTANCE_M} m"),
                ));
            }
        }
        for &c in &self.colour_indices()? {
            let sin = self.wavelengths_m[c] / (2.0 * self.pixel_pitch_m);
            let px_per_m =
                sin.min(0.99) / (1.0 - sin.min(0.99).powi(2)).sqrt() / self.pixel_pitch_m;
            // The model takes the whole pupil: a sub-hologram wider than the SLM would be cut by its edge.
            if let Some(&d) = self
                .distances_m
                .iter()
                .find(|d| 2.0 * d.abs() * px_per_m > h.min(w) as f64)
            {
                return Err(invalid(
                    "distances_m",
                    format!(
                        "at {:+.3} mm the {} spot's sub-hologram is {:.0} SLM pixels across, more than the \
                         {h} × {w} SLM: the SLM's edge would cut the spot's pupil (|d| ≤ {:.3} mm here, or \
                         a larger SLM size)",
                        d * 1e3,
                        COLOURS[c],
                        2.0 * d.abs() * px_per_m,
                        h.min(w) as f64 / (2.0 * px_per_m) * 1e3
                    ),
                ));
            }
            if let Some(&d) = self
                .distances_m
                .iter()
                .find(|d| d.abs() * px_per_m < MIN_SUBHOLOGRAM_PX)
            {
                return Err(invalid(
                    "distances_m",
                    format!(
                        "at {:+.3} mm the {} spot's sub-hologram has a radius of {:.1} SLM pixels; the double \
                         phase encoding needs at least {MIN_SUBHOLOGRAM_PX} (|d| ≥ {:.3} mm here)",
                        d * 1e3,
                        COLOURS[c],
                        d.abs() * px_per_m,
                        MIN_SUBHOLOGRAM_PX / px_per_m * 1e3
                    ),
                ));
            }
        }
        if let Some(w) = self.distances_m.windows(2).find(|w| w[0] >= w[1]) {
            return Err(invalid(
                "distances_m",
                format!(
                    "must be strictly increasing, got {} m then {} m",
                    w[0], w[1]
                ),
            ));
        }
        if self.diversities.is_empty() {
            return Err(invalid("diversities", "needs at least one diversity phase"));
        }
        if let Some((k, _)) = self.diversities.iter().enumerate().find(|(_, d)| {
            d.to_array()
                .iter()
                .any(|v| !(v.is_finite() && v.abs() <= MAX_DIVERSITY_RAD))
        }) {
            return Err(invalid(
                "diversities",
                format!(
                    "diversity {k} has a coefficient beyond ±{MAX_DIVERSITY_RAD:.2} rad (4π, two waves at \
                     the pupil edge) or not finite: {:?}",
                    self.diversities[k].to_array()
                ),
            ));
        }
        model::SpotModel::new(self.window_px, self.camera_scale).map(|_| ())
    }

    /// The plan's colours as indices 0–2 (R, G, B). Errors: [`HoloError::InvalidParameter`] (`colours`) for
    /// none, an unknown name or a repeat.
    pub(crate) fn colour_indices(&self) -> Result<Vec<usize>> {
        if self.colours.is_empty() {
            return Err(invalid("colours", "needs at least one of red, green, blue"));
        }
        let mut out = Vec::new();
        for name in &self.colours {
            let c = COLOURS.iter().position(|c| c == name).ok_or_else(|| {
                invalid(
                    "colours",
                    format!("unknown colour `{name}` (red, green or blue)"),
                )
            })?;
            if out.contains(&c) {
                return Err(invalid("colours", format!("`{name}` is listed twice")));
            }
            out.push(c);
        }
        Ok(out)
    }

    /// The pattern file of colour `c` (0–2), distance index `i` and diversity `k`:
    /// `pattern_<colour>_d<i>_k<k>.png`.
    pub(crate) fn pattern_name(c: usize, i: usize, k: usize) -> String {
        format!("pattern_{}_d{i}_k{k}.png", COLOURS[c.min(2)])
    }

    /// The capture file of the same: `capture_<colour>_d<i>_k<k>.png` (8/16-bit grey or RGB PNG).
    pub fn capture_name(c: usize, i: usize, k: usize) -> String {
        format!("capture_{}_d{i}_k{k}.png", COLOURS[c.min(2)])
    }

    /// Reads and checks `dir/plan.json` through the SDK's bounded reader ([`crate::io::read_text`]: at most
    /// [`crate::io::MAX_TEXT_BYTES`], a folder or a device refused). Errors: those of [`crate::io::read_text`]
    /// naming the file (unreadable, too large, not a regular file, not UTF-8), [`HoloError::InvalidData`]
    /// naming it and the key path (`diversities[2].focus`) for bad JSON, or the field [`SpotPlan::validate`]
    /// refuses.
    pub fn load(dir: &Path) -> Result<Self> {
        let path = dir.join(PLAN_FILE);
        let text = crate::io::read_text(&path)?;
        Self::from_json_str(&text, &path.display().to_string())
    }

    /// Parses and checks a plan's JSON text (`plan.json`); `source` names it in errors.
    ///
    /// Errors: [`HoloError::InvalidData`] naming `source` and the key path (`diversities[2].focus`) for bad
    /// JSON (not one object, an unknown, missing or repeated key, a wrong type), or the field
    /// [`SpotPlan::validate`] refuses.
    pub fn from_json_str(text: &str, source: &str) -> Result<Self> {
        let bad = |e: String| HoloError::InvalidData(format!("plan `{source}`: {e}"));
        let plan: Self =
            crate::io::parse_json_object(text, "a spot plan").map_err(|e| bad(e.to_string()))?;
        plan.validate().map_err(|e| bad(e.to_string()))?;
        Ok(plan)
    }

    /// Writes `dir/plan.json` (pretty JSON; atomically). Errors: [`HoloError::Io`] naming the file.
    pub(crate) fn save(&self, dir: &Path) -> Result<()> {
        let text = serde_json::to_string_pretty(self)
            .map_err(|e| HoloError::Internal(format!("plan to JSON: {e}")))?;
        crate::io::write_atomic(&dir.join(PLAN_FILE), text.as_bytes())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::fft::signed_index;
    use num_complex::Complex64;

    fn plan() -> SpotPlan {
        SpotPlan::new(
            [48, 64],
            &OpticalSetup::default(),
            &[1],
            vec![3e-3, -2e-3],
            2.0,
            32,
        )
        .unwrap()
    }

    /// The plan is read through the bounded reader: a plan that is a link to `/dev/zero` is refused at once
    /// (it was read until memory ran out), and one over `MAX_TEXT_BYTES` is refused naming the limit; a saved
    /// plan still reads back.
    #[cfg(unix)]
    #[test]
    fn a_plan_is_read_within_the_text_limit() {
        let dir = tempfile::tempdir().unwrap();
        plan().save(dir.path()).unwrap();
        assert_eq!(SpotPlan::load(dir.path()).unwrap().slm_size, [48, 64]);
        let path = dir.path().join(PLAN_FILE);
        std::fs::remove_file(&path).unwrap();
        std::os::unix::fs::symlink("/dev/zero", &path).unwrap();
        let e = SpotPlan::load(dir.path()).unwrap_err().to_string();
        assert!(e.contains(PLAN_FILE), "{e}");
        std::fs::remove_file(&path).unwrap();
        let big = format!(
            "{{\"pad\": \"{}\"}}",
            " ".repeat(crate::io::MAX_TEXT_BYTES as usize)
        );
        std::fs::write(&path, big).unwrap();
        let e = SpotPlan::load(dir.path()).unwrap_err().to_string();
        assert!(e.contains(PLAN_FILE) && e.contains("input limit"), "{e}");
    }

    /// A write that fails after the patterns (here at `plan.json`, a folder in the way) leaves none of them;
    /// what was in the folder before stays.
    #[test]
    fn a_failed_pattern_write_leaves_nothing_behind() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("patterns");
        std::fs::create_dir_all(out.join(PLAN_FILE)).unwrap();
        assert!(plan().write_patterns(&out, &|_, _| {}).is_err());
        let left: Vec<_> = std::fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(
            left,
            [std::ffi::OsString::from(PLAN_FILE)],
            "only what was there"
        );
        let fresh = dir.path().join("fresh");
        let n = plan().write_patterns(&fresh, &|_, _| {}).unwrap();
        assert_eq!(std::fs::read_dir(&fresh).unwrap().count(), n + 1);
    }

    #[test]
    fn a_pattern_focuses_its_diversity_pupil_at_its_distance() {
        let p = plan();
        let [h, w] = p.slm_size;
        // The SLM's field (linear LUT, Fourier filter ρ ≤ 1), propagated by d: a spot at the centre.
        let codes = p.pattern_codes(1, 1, 0).unwrap();
        let mut u: Vec<Complex64> = codes
            .iter()
            .map(|&c| Complex64::from_polar(1.0, std::f64::consts::TAU * c as f64 / 256.0))
            .collect();
        fft2(&mut u, h, w, false);
        let lambda = p.wavelengths_m[1];
        for (i, v) in u.iter_mut().enumerate() {
            let (fx, fy) = (
                signed_index(i % w, w) as f64 / (w as f64 * p.pixel_pitch_m),
                signed_index(i / w, h) as f64 / (h as f64 * p.pixel_pitch_m),
            );
            let f2 = fx * fx + fy * fy;
            let fn2 = (0.5 / p.pixel_pitch_m).powi(2);
            *v *= if f2 <= fn2 {
                let ph =
                    crate::optics::carrier_free_phase_rad(lambda, p.distances_m[1], f2).unwrap();
                Complex64::from_polar(1.0, ph)
            } else {
                Complex64::default()
            };
        }
        fft2(&mut u, h, w, true);
        let i: Vec<f64> = u.iter().map(|v| v.norm_sqr()).collect();
        let peak = i.iter().cloned().fold(0.0, f64::max);
        let at = i[(h / 2) * w + w / 2];
        assert_eq!(at, peak, "the spot is at the SLM's centre");
        let total: f64 = i.iter().sum();
        // The double phase encoding's leak through the filter is a faint background (a 16-px sub-hologram on
        // a 48×64 panel): the spot still holds far more than its share.
        assert!(peak / total > 0.03, "focused: {}", peak / total);
    }

    #[test]
    fn plans_round_trip_and_bad_fields_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let p = plan();
        assert_eq!(p.distances_m, vec![-2e-3, 3e-3], "sorted");
        p.save(dir.path()).unwrap();
        assert_eq!(SpotPlan::load(dir.path()).unwrap(), p);
        let text = std::fs::read_to_string(dir.path().join(PLAN_FILE)).unwrap();
        for (from, to, field) in [
            ("\"version\": 1", "\"version\": 7", "version"),
            ("-0.002", "-1.5", "distances_m"),
            ("-0.002", "0.0", "sub-hologram"),
            ("-0.002", "NaN", "plan"),
            ("\"green\"", "\"mauve\"", "colours"),
            (
                "\"camera_scale\": 2.0",
                "\"camera_scale\": 0.0",
                "camera_scale",
            ),
        ] {
            assert!(text.contains(from), "{from}");
            std::fs::write(dir.path().join(PLAN_FILE), text.replace(from, to)).unwrap();
            let e = SpotPlan::load(dir.path()).unwrap_err().to_string();
            assert!(e.contains(field) && e.contains(PLAN_FILE), "{e}");
        }
    }

    #[test]
    fn the_wavelength_rule_scales_quadratic_terms_linearly_and_coma_quadratically() {
        let z = ZernikeCoefficients::from_array([1.0, 1.0, 1.0, 1.0, 1.0]);
        let s = wavelength_scaled(&z, 500e-9, 600e-9).to_array();
        for (a, e) in s.iter().zip([1.2, 1.2, 1.2, 1.44, 1.44]) {
            assert!((a - e).abs() < 1e-12);
        }
    }
}

//! Display profiles: one JSON file per holographic display (SLM pitch and resolution, laser wavelengths,
//! volume, offsets, calibration, the viewer's aberrations), read by `holo --display FILE` and by apps (`docs/DISPLAYS.md`).
//!
//! ```json
//! {
//!   "name": "HOLOEYE PLUTO (paper)",
//!   "pixel_pitch_m": 8e-6,
//!   "resolution": [1080, 1920],
//!   "wavelengths_m": [638e-9, 520e-9, 450e-9],
//!   "volume_depth_m": 6e-3,
//!   "offsets_m": [6e-3, 12e-3, 0.0],
//!   "calibration": "pluto.holocal",
//!   "prescription": {"sphere_d": -2.0, "cylinder_d": -0.75, "axis_deg": 30}
//! }
//! ```
//!
//! Keys are SI units (`docs/CONVENTIONS.md` §1); unknown keys are refused (a typo never falls back to a
//! default), and every error names its key.

use std::path::{Path, PathBuf};

use super::prescription::Prescription;
use crate::error::{HoloError, NearestDisplay, Result};
use crate::optics::{OpticalSetup, MAX_VOLUME_DEPTH_M, PITCH_RANGE_M};

/// Shortest laser wavelength a profile may give, metres (the visible band).
pub const MIN_WAVELENGTH_M: f64 = 380e-9;
/// Longest laser wavelength a profile may give, metres.
pub const MAX_WAVELENGTH_M: f64 = 780e-9;

/// The most pixels an SLM of a profile may have: 8192 × 8192, four times a 4K SLM (what a session makes,
/// `crate::pipeline::MAX_HOLOGRAM_PIXELS`, and `--size`).
pub const MAX_SLM_PIXELS: usize = 8192 * 8192;
/// The most pixels a side of a profile's SLM may have (what `holo calibrate` takes).
pub const MAX_SLM_SIDE: usize = 16_384;
/// The most offsets a profile may list.
pub const MAX_OFFSETS: usize = 64;
pub use crate::optics::MAX_OFFSET_M;

/// Every key of a profile, for messages.
const KEYS: &str =
    "name, pixel_pitch_m, resolution, wavelengths_m, volume_depth_m, offsets_m, calibration, \
                    aberration, prescription";

/// A holographic display, as a profile file describes it (`docs/DISPLAYS.md`).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DisplayProfile {
    /// `name`: free text for reports, if given.
    pub name: Option<String>,
    /// `pixel_pitch_m`: SLM pixel pitch in metres (finite, > 0).
    pub pixel_pitch_m: f64,
    /// `resolution`: SLM size `[height, width]` in pixels (each ≥ 1).
    pub resolution: [usize; 2],
    /// `wavelengths_m`: laser wavelengths R, G, B in metres, each within 380–780 nm.
    pub wavelengths_m: [f64; 3],
    /// `volume_depth_m`: depth of the 3D volume in metres (finite, > 0), centred on the midpoint hologram.
    pub volume_depth_m: f64,
    /// `offsets_m`: hologram-plane offsets `s` in metres (Eq. 6; finite, non-empty); the first is the default.
    pub offsets_m: Vec<f64>,
    /// `calibration`: the display's `.holocal` file ([`crate::slm::DisplayCalibration`]), resolved against
    /// the profile's folder ([`DisplayProfile::from_path`]); `None` for an ideal SLM.
    pub calibration: Option<PathBuf>,
    /// `aberration`: the viewer's or the optics' aberration file (`tensorholo.aberration`,
    /// [`crate::display::AberrationProfile`], `docs/ABERRATION.md`) that sessions correct,
    /// resolved against the profile's folder like `calibration`; `None`: an ideal eye behind ideal optics.
    /// Set it in code with [`DisplayProfile::with_aberration_file`].
    pub aberration: Option<PathBuf>,
    /// `prescription`: the viewer's spectacle prescription ([`Prescription`]: sphere, cylinder, axis, the
    /// eyepiece), corrected like an aberration file; `None`: none. At most one of `aberration` and
    /// `prescription`. Set it in code with [`DisplayProfile::with_prescription`].
    pub prescription: Option<Prescription>,
}

/// The file as serde reads it: every key optional and untyped, so that each error can name its key.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawProfile {
    name: Option<serde_json::Value>,
    pixel_pitch_m: Option<serde_json::Value>,
    resolution: Option<serde_json::Value>,
    wavelengths_m: Option<serde_json::Value>,
    volume_depth_m: Option<serde_json::Value>,
    offsets_m: Option<serde_json::Value>,
    calibration: Option<serde_json::Value>,
    aberration: Option<serde_json::Value>,
    /// Its own text, parsed strictly (`io::parse_json_object`): a key given twice inside it is
    /// refused, as at the top level (a `serde_json::Value` would keep the last).
    prescription: Option<Box<serde_json::value::RawValue>>,
}

fn err(key: &'static str, reason: impl Into<String>) -> HoloError {
    HoloError::InvalidParameter {
        name: key,
        reason: format!("display profile key `{key}`: {}", reason.into()),
    }
}

fn required(key: &'static str, v: Option<serde_json::Value>) -> Result<serde_json::Value> {
    v.filter(|v| !v.is_null())
        .ok_or_else(|| err(key, "missing (required)"))
}

fn number(key: &'static str, v: &serde_json::Value) -> Result<f64> {
    v.as_f64()
        .ok_or_else(|| err(key, format!("must be a number, got {v}")))
}

/// Checks `x` lies within `[lo, hi]` (metres).
fn within(key: &'static str, x: f64, (lo, hi): (f64, f64)) -> Result<f64> {
    if !(lo..=hi).contains(&x) {
        return Err(err(key, format!("{x} m is outside {lo}–{hi} m")));
    }
    Ok(x)
}

fn positive(key: &'static str, x: f64) -> Result<f64> {
    if !(x.is_finite() && x > 0.0) {
        return Err(err(
            key,
            format!("must be a finite positive number, got {x}"),
        ));
    }
    Ok(x)
}

fn array<'a>(
    key: &'static str,
    v: &'a serde_json::Value,
    what: &str,
) -> Result<&'a Vec<serde_json::Value>> {
    v.as_array()
        .ok_or_else(|| err(key, format!("must be an array {what}, got {v}")))
}

/// A JSON error of a profile's text as the user sees it: the key at fault and where, in the profile's terms
/// (a key given twice, an unknown key, text after the object, a text that is not an object, a value that
/// cannot be read), never the parser's own type names.
fn json_error(text: &str, e: &serde_json::Error) -> HoloError {
    let msg = e.to_string();
    let at = format!("line {}, column {}", e.line(), e.column());
    // serde_json's wording, less its position (given once, as `at`).
    let bare = msg
        .rsplit_once(" at line ")
        .map_or(msg.as_str(), |(m, _)| m);
    let named = |k: &str| KEYS.split(", ").find(|&known| known == k);
    if let Some(rest) = bare.strip_prefix("unknown field ") {
        let key = rest.split('`').nth(1).unwrap_or(rest);
        return err(
            "display profile",
            format!("unknown key `{key}` at {at} (the keys are {KEYS}; a typo is never read as a default)"),
        );
    }
    if let Some(rest) = bare.strip_prefix("duplicate field ") {
        let key = rest.trim_matches('`');
        return err(
            named(key).unwrap_or("display profile"),
            format!("`{key}` is given twice (again at {at}): give each key once"),
        );
    }
    let first = text.trim_start().chars().next();
    if first != Some('{') && first.is_some() {
        let got = match first {
            Some('[') => "an array",
            Some('"') => "a string",
            Some('t' | 'f') => "a boolean",
            Some('n') => "null",
            Some(c) if c == '-' || c.is_ascii_digit() => "a number",
            _ => "another value",
        };
        return err(
            "display profile",
            format!("must be one JSON object {{…}} of the keys {KEYS}, got {got}"),
        );
    }
    if bare.starts_with("trailing characters") {
        return err(
            "display profile",
            format!("text after the profile's closing brace, at {at}: a file holds one profile"),
        );
    }
    if e.is_eof() {
        return err(
            "display profile",
            format!("the text ends before the profile does ({at}): a brace, bracket or string is not closed"),
        );
    }
    match key_before(text, e.line(), e.column()) {
        Some(k) => match named(&k) {
            Some(known) => err(known, format!("{bare} at {at}")),
            None => err("display profile", format!("key `{k}`: {bare} at {at}")),
        },
        None => err(
            "display profile",
            format!("not a JSON object of the keys {KEYS}: {bare} at {at}"),
        ),
    }
}

/// The key whose value is at `line`/`column` (1-based, serde_json's position) of `text`: the last
/// `"key":` before it, for syntax errors such as a number out of range (`1e999`).
fn key_before(text: &str, line: usize, column: usize) -> Option<String> {
    let offset: usize = text
        .split_inclusive('\n')
        .take(line.saturating_sub(1))
        .map(str::len)
        .sum::<usize>()
        + column;
    let head = text.get(..offset.min(text.len()))?;
    let colon = head.rfind(':')?;
    let before = head[..colon].trim_end().strip_suffix('"')?;
    let start = before.rfind('"')?;
    Some(before[start + 1..].to_string())
}

impl DisplayProfile {
    /// Parses a profile from JSON text; a relative `calibration` path stays relative (to the current
    /// directory). [`DisplayProfile::from_path`] resolves it against the profile's folder instead.
    ///
    /// Errors: [`HoloError::InvalidParameter`] whose `name` is the key at fault and whose reason says what
    /// is wrong: a missing key (`pixel_pitch_m`, `resolution`, `wavelengths_m`, `volume_depth_m`,
    /// `offsets_m`), a non-finite or non-positive pitch, volume or wavelength, a wavelength outside
    /// 380–780 nm, an array of the wrong length (`resolution`: 2, `wavelengths_m`: 3, `offsets_m`: ≥ 1), a
    /// non-integer resolution, a non-finite offset, an unknown key (`name` = `display profile`, the reason
    /// names it), or text that is not a JSON object (`name` = `display profile`, with the line).
    pub fn from_json_str(text: &str) -> Result<Self> {
        Self::parse(text, None)
    }

    /// Reads a profile file (JSON, as [`DisplayProfile::from_json_str`]); a relative `calibration` path is
    /// resolved against the folder of `path`.
    ///
    /// Errors: [`HoloError::Io`] if the file cannot be read; as [`DisplayProfile::from_json_str`], the
    /// reason prefixed with the file name.
    pub fn from_path(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let text = crate::io::read_text(path)?;
        let base = path.parent().unwrap_or_else(|| Path::new(""));
        Self::parse(&text, Some(base)).map_err(|e| match e {
            HoloError::InvalidParameter { name, reason } => HoloError::InvalidParameter {
                name,
                reason: format!("{}: {reason}", path.display()),
            },
            other => other,
        })
    }

    fn parse(text: &str, base: Option<&Path>) -> Result<Self> {
        // A UTF-8 byte-order mark (some editors write one) is not part of the profile.
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let raw: RawProfile = serde_json::from_str(text).map_err(|e| json_error(text, &e))?;
        let name = match raw.name.filter(|v| !v.is_null()) {
            None => None,
            Some(v) => Some(
                v.as_str()
                    .ok_or_else(|| err("name", format!("must be a string, got {v}")))?
                    .to_string(),
            ),
        };
        let pixel_pitch_m = number(
            "pixel_pitch_m",
            &required("pixel_pitch_m", raw.pixel_pitch_m)?,
        )?;
        let res = required("resolution", raw.resolution)?;
        let resolution = array("resolution", &res, "[height, width] in pixels")?
            .iter()
            .map(|v| {
                v.as_u64()
                    .and_then(|n| usize::try_from(n).ok())
                    .ok_or_else(|| {
                        err(
                            "resolution",
                            format!("[height, width] must be positive integers, got {v}"),
                        )
                    })
            })
            .collect::<Result<Vec<_>>>()?;
        let wl = required("wavelengths_m", raw.wavelengths_m)?;
        let wavelengths_m = array("wavelengths_m", &wl, "[R, G, B] in metres")?
            .iter()
            .map(|v| number("wavelengths_m", v))
            .collect::<Result<Vec<_>>>()?;
        let volume_depth_m = number(
            "volume_depth_m",
            &required("volume_depth_m", raw.volume_depth_m)?,
        )?;
        let off = required("offsets_m", raw.offsets_m)?;
        let offsets_m = array("offsets_m", &off, "of offsets in metres")?
            .iter()
            .map(|v| number("offsets_m", v))
            .collect::<Result<Vec<_>>>()?;
        let file = |key: &'static str, v: Option<serde_json::Value>| -> Result<Option<PathBuf>> {
            let Some(v) = v.filter(|v| !v.is_null()) else {
                return Ok(None);
            };
            let s = v
                .as_str()
                .ok_or_else(|| err(key, format!("must be a file path, got {v}")))?;
            let p = PathBuf::from(s);
            Ok(Some(match base {
                Some(b) if p.is_relative() && !s.is_empty() => b.join(p),
                _ => p,
            }))
        };
        let calibration = file("calibration", raw.calibration)?;
        let aberration = file("aberration", raw.aberration)?;
        let prescription = match raw.prescription.filter(|v| v.get().trim() != "null") {
            None => None,
            Some(v) => Some(
                crate::io::parse_json_object::<Prescription>(v.get(), "the prescription").map_err(
                    |e| {
                        let at = if e.path.is_empty() {
                            String::new()
                        } else {
                            format!("at `prescription.{}`: ", e.path)
                        };
                        err(
                            "prescription",
                            format!(
                                "{at}{} (expected {{\"sphere_d\": D, \"cylinder_d\": D, \"axis_deg\": \
                                 degrees, \"eyepiece_focal_m\": metres}}, docs/ABERRATION.md)",
                                e.reason
                            ),
                        )
                    },
                )?,
            ),
        };
        Self::new(
            name,
            pixel_pitch_m,
            &resolution,
            &wavelengths_m,
            volume_depth_m,
            offsets_m,
            calibration,
        )?
        .with_aberration_file(aberration)?
        .with_prescription(prescription)
    }

    /// This profile with the viewer's prescription `prescription` (`None`: none), checked as
    /// [`DisplayProfile::validate`] checks it.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`prescription`) for a bad prescription (the reason names its
    /// field) or a profile that also has an aberration file.
    pub fn with_prescription(mut self, prescription: Option<Prescription>) -> Result<Self> {
        self.prescription = prescription;
        self.validate()?;
        Ok(self)
    }

    /// This profile with the aberration file `path` (`None`: none), checked as
    /// [`DisplayProfile::validate`] checks it.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`aberration`) for an empty path.
    pub fn with_aberration_file(mut self, path: Option<PathBuf>) -> Result<Self> {
        self.aberration = path;
        self.validate()?;
        Ok(self)
    }

    /// A profile from its values (what [`DisplayProfile::from_json_str`] reads, for apps and bindings that
    /// build one in code): the arrays' lengths are checked here, then [`DisplayProfile::validate`].
    /// Lengths in metres, `resolution` as `[height, width]` pixels, `wavelengths_m` as `[R, G, B]`.
    ///
    /// Errors: [`HoloError::InvalidParameter`] naming the key: `resolution` not 2 values, `wavelengths_m`
    /// not 3, `offsets_m` empty; as [`DisplayProfile::validate`].
    pub fn new(
        name: Option<String>,
        pixel_pitch_m: f64,
        resolution: &[usize],
        wavelengths_m: &[f64],
        volume_depth_m: f64,
        offsets_m: Vec<f64>,
        calibration: Option<PathBuf>,
    ) -> Result<Self> {
        let resolution: [usize; 2] = resolution.try_into().map_err(|_| {
            err(
                "resolution",
                format!(
                    "must have 2 elements [height, width] in pixels, got {}",
                    resolution.len()
                ),
            )
        })?;
        let wavelengths_m: [f64; 3] = wavelengths_m.try_into().map_err(|_| {
            err(
                "wavelengths_m",
                format!(
                    "must have 3 elements [R, G, B] in metres, got {}",
                    wavelengths_m.len()
                ),
            )
        })?;
        let profile = Self {
            name,
            pixel_pitch_m,
            resolution,
            wavelengths_m,
            volume_depth_m,
            offsets_m,
            calibration,
            aberration: None,
            prescription: None,
        };
        profile.validate()?;
        Ok(profile)
    }

    /// Checks the values (the one place a profile's rules live; [`DisplayProfile::from_json_str`] and
    /// [`DisplayProfile::new`] call it): a finite positive `pixel_pitch_m` and `volume_depth_m`, a
    /// `resolution` of at least 1×1, `wavelengths_m` within 380–780 nm (metres, not nanometres), a non-empty
    /// `offsets_m` of finite values, and non-empty `calibration` and `aberration` paths where given.
    ///
    /// Errors: [`HoloError::InvalidParameter`] whose `name` is the key at fault; the reason names it too.
    pub fn validate(&self) -> Result<()> {
        positive("pixel_pitch_m", self.pixel_pitch_m)?;
        within("pixel_pitch_m", self.pixel_pitch_m, PITCH_RANGE_M)?;
        if self.resolution.contains(&0) {
            return Err(err(
                "resolution",
                format!(
                    "[height, width] must be positive integers, got {:?}",
                    self.resolution
                ),
            ));
        }
        let [h, w] = self.resolution;
        if h.max(w) > MAX_SLM_SIDE || h.saturating_mul(w) > MAX_SLM_PIXELS {
            return Err(err(
                "resolution",
                format!(
                    "{h}×{w} is above the largest SLM a session makes: {MAX_SLM_SIDE} pixels a side and \
                     {MAX_SLM_PIXELS} pixels in all (8192 × 8192, four times a 4K SLM; as --size)"
                ),
            ));
        }
        for (&x, colour) in self.wavelengths_m.iter().zip(["R", "G", "B"]) {
            positive("wavelengths_m", x)?;
            if !(MIN_WAVELENGTH_M..=MAX_WAVELENGTH_M).contains(&x) {
                return Err(err(
                    "wavelengths_m",
                    format!(
                        "{colour} is {x} m ({:.1} nm), outside 380–780 nm (metres, not nanometres)",
                        x * 1e9
                    ),
                ));
            }
        }
        positive("volume_depth_m", self.volume_depth_m)?;
        within(
            "volume_depth_m",
            self.volume_depth_m,
            (0.0, MAX_VOLUME_DEPTH_M),
        )?;
        if self.offsets_m.is_empty() {
            return Err(err("offsets_m", "must not be empty (of offsets in metres)"));
        }
        if self.offsets_m.len() > MAX_OFFSETS {
            return Err(err(
                "offsets_m",
                format!(
                    "holds {} offsets, more than the {MAX_OFFSETS} a profile may list",
                    self.offsets_m.len()
                ),
            ));
        }
        if let Some(x) = self.offsets_m.iter().find(|x| !x.is_finite()) {
            return Err(err("offsets_m", format!("must be finite, got {x}")));
        }
        if let Some(x) = self.offsets_m.iter().find(|x| x.abs() > MAX_OFFSET_M) {
            return Err(err(
                "offsets_m",
                format!("{x} m is farther than {MAX_OFFSET_M} m from the midpoint hologram"),
            ));
        }
        if self
            .calibration
            .as_ref()
            .is_some_and(|p| p.as_os_str().is_empty())
        {
            return Err(err("calibration", "must be a file path, got an empty one"));
        }
        if self
            .aberration
            .as_ref()
            .is_some_and(|p| p.as_os_str().is_empty())
        {
            return Err(err("aberration", "must be a file path, got an empty one"));
        }
        if let Some(p) = &self.prescription {
            if self.aberration.is_some() {
                return Err(err(
                    "prescription",
                    "give `aberration` (a file) or `prescription`, not both",
                ));
            }
            p.validate()
                .map_err(|e| err("prescription", e.to_string()))?;
        }
        Ok(())
    }

    /// The display's optics: wavelengths, pitch and volume depth (metres).
    pub fn optics(&self) -> OpticalSetup {
        OpticalSetup {
            wavelengths_m: self.wavelengths_m,
            pixel_pitch_m: self.pixel_pitch_m,
            volume_depth_m: self.volume_depth_m,
        }
    }

    /// The default offset `s` in metres: the first of `offsets_m`.
    pub fn default_offset_m(&self) -> f64 {
        self.offsets_m.first().copied().unwrap_or(0.0)
    }

    /// This profile for the display `nearest` (e.g. the nearest display a model serves,
    /// [`crate::display::DisplayRefusal::nearest`]): its pitch, lasers and volume, its offset first and the
    /// profile's other offsets scaled by its `offsets_scale` (less any equal to the first).
    pub fn with_display(&self, nearest: &NearestDisplay) -> Self {
        let mut offsets_m = vec![nearest.offset_m];
        offsets_m.extend(
            self.offsets_m
                .iter()
                .skip(1)
                .map(|&s| s * nearest.offsets_scale)
                .filter(|&s| s != nearest.offset_m),
        );
        Self {
            pixel_pitch_m: nearest.pixel_pitch_m,
            wavelengths_m: nearest.wavelengths_m,
            volume_depth_m: nearest.volume_depth_m,
            offsets_m,
            ..self.clone()
        }
    }

    /// The profile as the JSON file [`DisplayProfile::from_json_str`] reads (the optional keys only where
    /// set; a calibration path as given).
    pub fn to_json(&self) -> String {
        // Twelve significant digits: no float noise of a computed value (0.0146484375, not
        // 0.014648437500000005), and far finer than the SDK's relative 1e-6 comparisons.
        let r = |x: f64| {
            if x == 0.0 || !x.is_finite() {
                return x;
            }
            let scale = 10f64.powi(11 - x.abs().log10().floor() as i32);
            (x * scale).round() / scale
        };
        let mut v = serde_json::Map::new();
        if let Some(n) = &self.name {
            v.insert("name".into(), n.clone().into());
        }
        v.insert("pixel_pitch_m".into(), r(self.pixel_pitch_m).into());
        v.insert("resolution".into(), serde_json::json!(self.resolution));
        v.insert(
            "wavelengths_m".into(),
            serde_json::json!(self.wavelengths_m.map(r)),
        );
        v.insert("volume_depth_m".into(), r(self.volume_depth_m).into());
        let offsets: Vec<f64> = self.offsets_m.iter().map(|&s| r(s)).collect();
        v.insert("offsets_m".into(), serde_json::json!(offsets));
        for (key, file) in [
            ("calibration", &self.calibration),
            ("aberration", &self.aberration),
        ] {
            if let Some(f) = file {
                v.insert(key.into(), f.to_string_lossy().into_owned().into());
            }
        }
        if let Some(p) = &self.prescription {
            v.insert("prescription".into(), serde_json::json!(p));
        }
        // Plain numbers and strings: serialising cannot fail.
        serde_json::to_string_pretty(&serde_json::Value::Object(v)).unwrap_or_default() + "\n"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"{
        "name": "test 4 µm",
        "pixel_pitch_m": 4e-6,
        "resolution": [1080, 1920],
        "wavelengths_m": [638e-9, 520e-9, 450e-9],
        "volume_depth_m": 1.5e-3,
        "offsets_m": [1.5e-3, 3e-3],
        "calibration": "slm.holocal"
    }"#;

    /// `GOOD` with `key`'s line replaced (or removed where `value` is `None`).
    fn with(key: &str, value: Option<&str>) -> String {
        GOOD.lines()
            .filter_map(|l| {
                if l.trim_start().starts_with(&format!("\"{key}\"")) {
                    let comma = if l.trim_end().ends_with(',') { "," } else { "" };
                    value.map(|v| format!("\"{key}\": {v}{comma}"))
                } else {
                    Some(l.to_string())
                }
            })
            .collect::<Vec<_>>()
            .join("\n")
            .replace(",\n    }", "\n    }")
    }

    /// The error's key and message.
    fn fails(text: &str) -> (&'static str, String) {
        match DisplayProfile::from_json_str(text) {
            Err(e @ HoloError::InvalidParameter { name, .. }) => (name, e.to_string()),
            other => panic!("expected InvalidParameter, got {other:?}"),
        }
    }

    #[test]
    fn good_profile() {
        let p = DisplayProfile::from_json_str(GOOD).unwrap();
        assert_eq!(p.name.as_deref(), Some("test 4 µm"));
        assert_eq!(p.resolution, [1080, 1920]);
        assert_eq!(p.default_offset_m(), 1.5e-3);
        assert_eq!(
            p.optics(),
            OpticalSetup {
                wavelengths_m: [638e-9, 520e-9, 450e-9],
                pixel_pitch_m: 4e-6,
                volume_depth_m: 1.5e-3
            }
        );
        assert_eq!(p.calibration, Some(PathBuf::from("slm.holocal")));
    }

    #[test]
    fn calibration_is_resolved_against_the_profile_folder() {
        let dir = std::env::temp_dir().join(format!("tensorholo-profile-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("display.json");
        std::fs::write(&file, GOOD).unwrap();
        let p = DisplayProfile::from_path(&file).unwrap();
        assert_eq!(p.calibration, Some(dir.join("slm.holocal")));
        assert_eq!(p.aberration, None);
        // The aberration file likewise; written back and read again, the same profile; empty: refused.
        let with_aberration = GOOD.replacen("{", r#"{ "aberration": "eye.json","#, 1);
        std::fs::write(&file, &with_aberration).unwrap();
        let p = DisplayProfile::from_path(&file).unwrap();
        assert_eq!(p.aberration, Some(dir.join("eye.json")));
        assert_eq!(DisplayProfile::from_json_str(&p.to_json()).unwrap(), p);
        let empty = GOOD.replacen("{", r#"{ "aberration": "","#, 1);
        match DisplayProfile::from_json_str(&empty) {
            Err(HoloError::InvalidParameter { name, .. }) => assert_eq!(name, "aberration"),
            other => panic!("{other:?}"),
        }
        // A prescription: read, written back the same; refused with an aberration file or without an axis.
        let rx = GOOD.replacen(
            "{",
            r#"{ "prescription": {"sphere_d": -2, "cylinder_d": -0.75, "axis_deg": 30},"#,
            1,
        );
        let p = DisplayProfile::from_json_str(&rx).unwrap();
        assert_eq!(p.prescription.unwrap().cylinder_d, -0.75);
        assert_eq!(DisplayProfile::from_json_str(&p.to_json()).unwrap(), p);
        for (bad, says) in [
            (
                rx.replacen("{", r#"{ "aberration": "eye.json","#, 1),
                "not both",
            ),
            (rx.replace(r#", "axis_deg": 30"#, ""), "axis_deg"),
            (rx.replace("sphere_d", "sphere"), "sphere"),
            // A key given twice inside the object is refused as at the top level (not the last one taken).
            (
                rx.replace(r#""axis_deg": 30"#, r#""axis_deg": 30, "sphere_d": -6"#),
                "duplicate field `sphere_d`",
            ),
            // The wrong type names the key and the object expected, not a Rust type.
            (
                rx.replace(
                    r#"{"sphere_d": -2, "cylinder_d": -0.75, "axis_deg": 30}"#,
                    r#""-2 -0.75 x 30""#,
                ),
                "must be one JSON object",
            ),
            (
                rx.replace(r#""axis_deg": 30"#, r#""axis_deg": "30""#),
                "at `prescription.axis_deg`",
            ),
        ] {
            match DisplayProfile::from_json_str(&bad) {
                Err(HoloError::InvalidParameter { name, reason }) => {
                    assert_eq!(name, "prescription");
                    assert!(reason.contains(says), "{reason}");
                    assert!(!reason.contains("struct"), "{reason}");
                }
                other => panic!("{other:?}"),
            }
        }
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(matches!(
            DisplayProfile::from_path(dir.join("absent.json")),
            Err(HoloError::Io { .. })
        ));
    }

    #[test]
    fn optional_keys_may_be_absent() {
        let text = with("calibration", None);
        let text = text.replace("\"name\": \"test 4 µm\",", "");
        let p = DisplayProfile::from_json_str(&text).unwrap();
        assert_eq!((p.name, p.calibration), (None, None));
    }

    #[test]
    fn missing_keys_are_named() {
        for key in [
            "pixel_pitch_m",
            "resolution",
            "wavelengths_m",
            "volume_depth_m",
            "offsets_m",
        ] {
            let (name, msg) = fails(&with(key, None));
            assert_eq!(name, key, "{msg}");
            assert!(msg.contains("missing"), "{msg}");
        }
    }

    #[test]
    fn non_positive_and_non_finite_values_are_named() {
        for (key, v) in [
            ("pixel_pitch_m", "0"),
            ("pixel_pitch_m", "-4e-6"),
            ("pixel_pitch_m", "1e999"),
            ("volume_depth_m", "0.0"),
            ("volume_depth_m", "-1e999"),
            ("volume_depth_m", "\"1.5e-3\""),
            ("wavelengths_m", "[638e-9, 0, 450e-9]"),
            ("wavelengths_m", "[638e-9, 520e-9, 1e999]"),
            ("offsets_m", "[1e999]"),
            ("resolution", "[0, 1920]"),
            ("resolution", "[1080.5, 1920]"),
        ] {
            let (name, msg) = fails(&with(key, Some(v)));
            assert_eq!(name, key, "{key}: {v}: {msg}");
            assert!(msg.contains(key), "{msg}");
        }
    }

    #[test]
    fn wrong_array_lengths_are_named() {
        for (key, v) in [
            ("resolution", "[1080]"),
            ("resolution", "[1080, 1920, 3]"),
            ("wavelengths_m", "[638e-9, 520e-9]"),
            ("wavelengths_m", "[638e-9, 520e-9, 450e-9, 405e-9]"),
            ("offsets_m", "[]"),
            ("offsets_m", "1.5e-3"),
        ] {
            let (name, msg) = fails(&with(key, Some(v)));
            assert_eq!(name, key, "{key}: {v}: {msg}");
        }
    }

    #[test]
    fn wavelengths_outside_the_visible_band_are_refused() {
        for v in [
            "[638, 520, 450]",
            "[638e-9, 520e-9, 370e-9]",
            "[800e-9, 520e-9, 450e-9]",
        ] {
            let (name, msg) = fails(&with("wavelengths_m", Some(v)));
            assert_eq!(name, "wavelengths_m", "{msg}");
            assert!(msg.contains("380–780 nm"), "{msg}");
        }
        // The band's edges are in it.
        DisplayProfile::from_json_str(&with("wavelengths_m", Some("[780e-9, 520e-9, 380e-9]")))
            .unwrap();
    }

    #[test]
    fn unknown_keys_are_refused_by_name() {
        let text = GOOD.replace("\"pixel_pitch_m\"", "\"pixel_pich_m\"");
        let (name, msg) = fails(&text);
        assert_eq!(name, "display profile");
        assert!(msg.contains("pixel_pich_m"), "{msg}");
        let text = GOOD.replace("\"name\":", "\"pitch_um\": 4, \"name\":");
        let (_, msg) = fails(&text);
        assert!(msg.contains("pitch_um"), "{msg}");
    }

    /// A profile built in code (what the bindings do with a record) follows the file's rules, by key.
    #[test]
    fn new_checks_what_the_file_checks() {
        let good = DisplayProfile::from_json_str(GOOD).unwrap();
        let built = DisplayProfile::new(
            good.name.clone(),
            4e-6,
            &[1080, 1920],
            &[638e-9, 520e-9, 450e-9],
            1.5e-3,
            vec![1.5e-3, 3e-3],
            Some(PathBuf::from("slm.holocal")),
        )
        .unwrap();
        assert_eq!(built, good);
        let key = |r: Result<DisplayProfile>| match r {
            Err(e @ HoloError::InvalidParameter { name, .. }) => {
                assert!(e.to_string().contains(name), "{e}");
                name
            }
            other => panic!("expected InvalidParameter, got {other:?}"),
        };
        let with = |f: &dyn Fn(&mut DisplayProfile)| {
            let mut p = good.clone();
            f(&mut p);
            key(p.validate().map(|()| p))
        };
        assert_eq!(with(&|p| p.pixel_pitch_m = -4e-6), "pixel_pitch_m");
        assert_eq!(with(&|p| p.pixel_pitch_m = f64::NAN), "pixel_pitch_m");
        assert_eq!(with(&|p| p.resolution = [0, 1920]), "resolution");
        assert_eq!(with(&|p| p.wavelengths_m[1] = 520.0), "wavelengths_m");
        assert_eq!(with(&|p| p.volume_depth_m = 0.0), "volume_depth_m");
        assert_eq!(with(&|p| p.offsets_m.clear()), "offsets_m");
        assert_eq!(with(&|p| p.offsets_m[0] = f64::INFINITY), "offsets_m");
        // Bounds shared with --size and the optics: nothing that overflows after the check.
        assert_eq!(with(&|p| p.pixel_pitch_m = 1e308), "pixel_pitch_m");
        assert_eq!(with(&|p| p.pixel_pitch_m = 1e-310), "pixel_pitch_m");
        assert_eq!(
            with(&|p| p.resolution = [1_000_000, 1_000_000]),
            "resolution"
        );
        assert_eq!(with(&|p| p.resolution = [50_000, 50_000]), "resolution");
        assert_eq!(with(&|p| p.resolution = [1, 20_000]), "resolution");
        assert_eq!(with(&|p| p.volume_depth_m = 2.0), "volume_depth_m");
        assert_eq!(with(&|p| p.offsets_m = vec![1e-3; 65]), "offsets_m");
        assert_eq!(with(&|p| p.offsets_m[0] = -2.0), "offsets_m");
        p_ok(&good, |p| p.resolution = [8192, 8192]);
        p_ok(&good, |p| p.offsets_m = vec![1e-3; 64]);
        assert_eq!(
            with(&|p| p.calibration = Some(PathBuf::new())),
            "calibration"
        );
        let new = |res: &[usize], wl: &[f64]| {
            DisplayProfile::new(None, 4e-6, res, wl, 1.5e-3, vec![1.5e-3], None)
        };
        let rgb = [638e-9, 520e-9, 450e-9];
        assert_eq!(key(new(&[1080], &rgb)), "resolution");
        assert_eq!(key(new(&[1080, 1920, 3], &rgb)), "resolution");
        assert_eq!(key(new(&[1080, 1920], &rgb[..2])), "wavelengths_m");
    }

    #[test]
    fn not_an_object_is_an_error() {
        for text in ["", "[]", "{", "42"] {
            let (name, _) = fails(text);
            assert_eq!(name, "display profile");
        }
    }

    fn p_ok(good: &DisplayProfile, f: impl Fn(&mut DisplayProfile)) {
        let mut p = good.clone();
        f(&mut p);
        p.validate().unwrap();
    }

    /// The profile's structure errors name what is wrong and where, never the parser's type names: a key
    /// given twice, a top-level array, text after the object, an unclosed object; a byte-order mark is
    /// accepted.
    #[test]
    fn structure_errors_say_what_and_where() {
        let dup = GOOD.replacen(
            "\"volume_depth_m\": 1.5e-3,",
            "\"volume_depth_m\": 1.5e-3, \"volume_depth_m\": 2e-3,",
            1,
        );
        let (key, msg) = fails(&dup);
        assert_eq!(key, "volume_depth_m", "{msg}");
        assert!(msg.contains("given twice (again at line"), "{msg}");
        for (text, needle) in [
            (
                format!("[{GOOD}]"),
                "must be one JSON object {…} of the keys",
            ),
            (
                format!("{GOOD} x"),
                "text after the profile's closing brace, at line",
            ),
            (
                format!("{GOOD} {{}}"),
                "text after the profile's closing brace",
            ),
            (
                GOOD.trim_end().trim_end_matches('}').to_string(),
                "the text ends before the profile does",
            ),
            ("\"just text\"".to_string(), "got a string"),
        ] {
            let (key, msg) = fails(&text);
            assert_eq!(key, "display profile", "{msg}");
            assert!(msg.contains(needle), "{needle}: {msg}");
            assert!(
                !msg.contains("RawProfile") && !msg.contains("struct"),
                "{msg}"
            );
        }
        let bom = format!("\u{feff}{GOOD}");
        assert_eq!(
            DisplayProfile::from_json_str(&bom).unwrap(),
            DisplayProfile::from_json_str(GOOD).unwrap()
        );
    }
}

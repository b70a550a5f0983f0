//! The calibrated aberrations of a display or a viewer: [`AberrationProfile`], Zernike coefficients
//! ([`ZernikeCoefficients`], Eq. 14–18) per signed focus distance and colour, interpolated piecewise linearly in
//! between, and its JSON file (`tensorholo.aberration`, `docs/ABERRATION.md`; a spectacle prescription converts
//! to one, [`AberrationProfile::from_prescription`]); and [`AberrationSource`], the one rule for which
//! aberration a session corrects (an explicit file, measured profile or prescription before the display
//! profile's own), used by `holo` and the bindings alike.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::prescription::Prescription;
use super::profile::DisplayProfile;
use crate::error::{invalid, HoloError, Result};
use crate::optics::{OpticalSetup, ZernikeCoefficients, MAX_COEFFICIENT_RAD};

/// Value of an aberration file's `format` field.
pub const ABERRATION_FORMAT: &str = "tensorholo.aberration";
/// Version of the aberration file format this build reads and writes.
pub const ABERRATION_FORMAT_VERSION: u32 = 1;

/// One calibration point of an [`AberrationProfile`]: the coefficients measured with the focus at signed
/// distance `distance_m` from the SLM plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AberrationSample {
    /// Signed distance in metres from the SLM plane to the focus, positive along the light (toward the
    /// viewer; `docs/CONVENTIONS.md` §4). A 3D image behind the SLM has `d < 0`.
    pub distance_m: f64,
    /// Coefficients for R, G, B (one set may serve all three).
    pub coefficients: [ZernikeCoefficients; 3],
}

/// The calibrated aberrations of a display: Zernike coefficients ([`ZernikeCoefficients`], radians) at several
/// signed focus distances, per colour, interpolated piecewise linearly in distance and clamped outside the
/// calibrated range (paper Methods: "parameters can be piecewise linearly interpolated").
///
/// Stored as JSON (`docs/ABERRATION.md`):
///
/// ```json
/// {
///   "format": "tensorholo.aberration",
///   "version": 1,
///   "wavelengths_m": [638e-9, 520e-9, 450e-9],
///   "pixel_pitch_m": 8e-6,
///   "samples": [
///     {"distance_m": -0.003, "coefficients": {"focus": 0.5, "astigmatism_vertical": 1.2}},
///     {"distance_m": 0.003, "per_colour": [{"focus": 0.6}, {"focus": 0.5}, {"focus": 0.4}]}
///   ]
/// }
/// ```
///
/// `wavelengths_m` and `pixel_pitch_m` are optional; when present they are checked against the display
/// (`AberrationProfile::check_setup`). Each sample has either `coefficients` (all colours) or `per_colour`
/// (R, G, B).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "ProfileFile", into = "ProfileFile")]
pub struct AberrationProfile {
    wavelengths_m: Option<[f64; 3]>,
    pixel_pitch_m: Option<f64>,
    samples: Vec<AberrationSample>,
}

/// The JSON form of a sample.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct SampleFile {
    distance_m: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    coefficients: Option<ZernikeCoefficients>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    per_colour: Option<[ZernikeCoefficients; 3]>,
}

/// The JSON form of a profile.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ProfileFile {
    format: String,
    version: u32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    wavelengths_m: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pixel_pitch_m: Option<f64>,
    samples: Vec<SampleFile>,
}

impl TryFrom<ProfileFile> for AberrationProfile {
    type Error = HoloError;

    fn try_from(f: ProfileFile) -> Result<Self> {
        let bad = |m: String| HoloError::InvalidData(m);
        if f.format != ABERRATION_FORMAT {
            return Err(bad(format!(
                "format is `{}`, expected `{ABERRATION_FORMAT}`",
                f.format
            )));
        }
        if f.version != ABERRATION_FORMAT_VERSION {
            return Err(bad(format!(
                "version is {}, this build reads version {ABERRATION_FORMAT_VERSION}",
                f.version
            )));
        }
        if let Some(w) = f.samples.windows(2).find(|w| {
            w[0].distance_m.is_finite()
                && w[1].distance_m.is_finite()
                && w[0].distance_m >= w[1].distance_m
        }) {
            return Err(bad(format!(
                "samples must be sorted by strictly increasing distance_m, got {} m then {} m",
                w[0].distance_m, w[1].distance_m
            )));
        }
        let samples = f
            .samples
            .into_iter()
            .enumerate()
            .map(|(i, s)| {
                let coefficients = match (s.coefficients, s.per_colour) {
                    (Some(c), None) => [c; 3],
                    (None, Some(p)) => p,
                    _ => {
                        return Err(bad(format!(
                            "sample {i} needs exactly one of `coefficients` (all colours) and \
                             `per_colour` ([R, G, B])"
                        )))
                    }
                };
                Ok(AberrationSample {
                    distance_m: s.distance_m,
                    coefficients,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let mut profile = Self::new(samples)?;
        if let Some(w) = f.wavelengths_m {
            if !w.iter().all(|v| v.is_finite() && *v > 0.0) {
                return Err(bad(format!(
                    "wavelengths_m must be finite and positive, got {w:?}"
                )));
            }
            profile.wavelengths_m = Some(w);
        }
        if let Some(p) = f.pixel_pitch_m {
            if !(p.is_finite() && p > 0.0) {
                return Err(bad(format!(
                    "pixel_pitch_m must be finite and positive, got {p}"
                )));
            }
            profile.pixel_pitch_m = Some(p);
        }
        Ok(profile)
    }
}

impl From<AberrationProfile> for ProfileFile {
    fn from(p: AberrationProfile) -> Self {
        ProfileFile {
            format: ABERRATION_FORMAT.into(),
            version: ABERRATION_FORMAT_VERSION,
            wavelengths_m: p.wavelengths_m,
            pixel_pitch_m: p.pixel_pitch_m,
            samples: p
                .samples
                .iter()
                .map(|s| {
                    let [r, g, b] = s.coefficients;
                    let same = r == g && g == b;
                    SampleFile {
                        distance_m: s.distance_m,
                        coefficients: same.then_some(r),
                        per_colour: (!same).then_some(s.coefficients),
                    }
                })
                .collect(),
        }
    }
}

impl AberrationProfile {
    /// A profile from calibration samples, sorted by distance here.
    ///
    /// Errors: [`HoloError::InvalidData`] for no sample, a non-finite distance or coefficient, or two samples
    /// at the same distance.
    pub fn new(mut samples: Vec<AberrationSample>) -> Result<Self> {
        if samples.is_empty() {
            return Err(HoloError::InvalidData(
                "an aberration profile needs at least one sample".into(),
            ));
        }
        for (i, s) in samples.iter().enumerate() {
            if !s.distance_m.is_finite() {
                return Err(HoloError::InvalidData(format!(
                    "sample {i}: distance_m must be finite, got {}",
                    s.distance_m
                )));
            }
            for (c, k) in s.coefficients.iter().enumerate() {
                if k.to_array().iter().any(|a| !a.is_finite()) {
                    return Err(HoloError::InvalidData(format!(
                        "sample {i} (distance {} m), colour {}: coefficients must be finite, got {k:?}",
                        s.distance_m,
                        ["R", "G", "B"][c]
                    )));
                }
                let names = [
                    "focus",
                    "astigmatism_vertical",
                    "astigmatism_oblique",
                    "coma_horizontal",
                    "coma_vertical",
                ];
                if let Some((name, a)) = names
                    .iter()
                    .zip(k.to_array())
                    .find(|(_, a)| a.abs() > MAX_COEFFICIENT_RAD)
                {
                    return Err(HoloError::InvalidData(format!(
                        "sample {i} (distance {} m), colour {}: {name} = {a} rad is beyond ±{MAX_COEFFICIENT_RAD} \
                         rad at the pupil edge (no SLM grid samples it; a unit error?)",
                        s.distance_m,
                        ["R", "G", "B"][c]
                    )));
                }
            }
        }
        samples.sort_by(|a, b| a.distance_m.total_cmp(&b.distance_m));
        if let Some(w) = samples
            .windows(2)
            .find(|w| w[0].distance_m == w[1].distance_m)
        {
            return Err(HoloError::InvalidData(format!(
                "two samples at distance {} m",
                w[0].distance_m
            )));
        }
        Ok(Self {
            wavelengths_m: None,
            pixel_pitch_m: None,
            samples,
        })
    }

    /// One set of coefficients for every colour at every distance.
    pub fn uniform(coefficients: ZernikeCoefficients) -> Self {
        Self {
            wavelengths_m: None,
            pixel_pitch_m: None,
            samples: vec![AberrationSample {
                distance_m: 0.0,
                coefficients: [coefficients; 3],
            }],
        }
    }

    /// The profile that shows the hologram as `prescription`'s spectacle lens would let the viewer see it,
    /// on `optics`' display (its lasers and pitch recorded): per colour the coefficients of
    /// `Prescription::zernike`, the same at every distance (the lens sits at the viewer's pupil, so the
    /// real-time correction is exact; `docs/ABERRATION.md`, "A viewer's prescription").
    ///
    /// Errors: as [`Prescription::validate`].
    pub fn from_prescription(prescription: &Prescription, optics: &OpticalSetup) -> Result<Self> {
        prescription.validate()?;
        let coefficients = std::array::from_fn(|c| {
            ZernikeCoefficients::from_array(
                prescription.zernike(optics.wavelengths_m[c], optics.pixel_pitch_m),
            )
        });
        Ok(Self::new(vec![AberrationSample {
            distance_m: 0.0,
            coefficients,
        }])?
        .with_display(optics.wavelengths_m, optics.pixel_pitch_m))
    }

    /// Records the display the profile was calibrated for (R, G, B wavelengths and pixel pitch, metres), which
    /// `AberrationProfile::check_setup` then compares with the display in use.
    pub fn with_display(mut self, wavelengths_m: [f64; 3], pixel_pitch_m: f64) -> Self {
        self.wavelengths_m = Some(wavelengths_m);
        self.pixel_pitch_m = Some(pixel_pitch_m);
        self
    }

    /// The calibration samples, sorted by increasing distance.
    pub fn samples(&self) -> &[AberrationSample] {
        &self.samples
    }

    /// R, G, B wavelengths (metres) the profile was calibrated for, if recorded.
    pub fn wavelengths_m(&self) -> Option<[f64; 3]> {
        self.wavelengths_m
    }

    /// Pixel pitch (metres) the profile was calibrated for, if recorded.
    pub fn pixel_pitch_m(&self) -> Option<f64> {
        self.pixel_pitch_m
    }

    /// Whether every coefficient of every sample is zero.
    pub(crate) fn is_zero(&self) -> bool {
        self.samples
            .iter()
            .all(|s| s.coefficients.iter().all(ZernikeCoefficients::is_zero))
    }

    /// Whether `other` describes the same aberrations: the same distances (within 1 nm) and coefficients
    /// (within 10⁻⁶ rad) in every colour. The recorded display (lasers, pitch) is not compared.
    pub fn same_aberrations(&self, other: &Self) -> bool {
        self.samples.len() == other.samples.len()
            && self.samples.iter().zip(&other.samples).all(|(a, b)| {
                (a.distance_m - b.distance_m).abs() <= 1e-9
                    && a.coefficients.iter().zip(&b.coefficients).all(|(x, y)| {
                        x.to_array()
                            .iter()
                            .zip(y.to_array())
                            .all(|(u, v)| (u - v).abs() <= 1e-6)
                    })
            })
    }

    /// A one-line description for messages: the calibrated distances and the largest coefficient, e.g.
    /// `3 distances, −3 to 3 mm, largest |coefficient| 1.2 rad (green astigmatism_vertical at 0 mm)`.
    pub(crate) fn describe(&self) -> String {
        const NAMES: [&str; 5] = [
            "focus",
            "astigmatism_vertical",
            "astigmatism_oblique",
            "coma_horizontal",
            "coma_vertical",
        ];
        let mut largest = (0.0f64, "", 0usize, 0.0f64);
        for s in &self.samples {
            for (c, k) in s.coefficients.iter().enumerate() {
                for (j, a) in k.to_array().iter().enumerate() {
                    if a.abs() > largest.0.abs() {
                        largest = (*a, ["red", "green", "blue"][c], j, s.distance_m);
                    }
                }
            }
        }
        let (first, last) = (
            self.samples[0].distance_m * 1e3,
            self.samples[self.samples.len() - 1].distance_m * 1e3,
        );
        let span = if self.samples.len() == 1 {
            format!("1 distance, {first} mm")
        } else {
            format!("{} distances, {first} to {last} mm", self.samples.len())
        };
        if largest.0 == 0.0 {
            return format!("{span}, all coefficients 0");
        }
        format!(
            "{span}, largest |coefficient| {:.3} rad ({} {} at {} mm)",
            largest.0.abs(),
            largest.1,
            NAMES[largest.2],
            largest.3 * 1e3
        )
    }

    /// The coefficients of colour `channel` (0 = R, 1 = G, 2 = B) at signed distance `distance_m` (metres from
    /// the SLM plane to the focus, positive along the light): piecewise linear between the calibrated
    /// distances, constant (clamped) outside them. A `channel` above 2 is read as 2.
    pub fn coefficients(&self, distance_m: f64, channel: usize) -> ZernikeCoefficients {
        let c = channel.min(2);
        let s = &self.samples;
        let first = &s[0];
        let last = &s[s.len() - 1];
        if distance_m.is_nan() || distance_m <= first.distance_m {
            return first.coefficients[c];
        }
        if distance_m >= last.distance_m {
            return last.coefficients[c];
        }
        let i = s.partition_point(|x| x.distance_m <= distance_m);
        let (a, b) = (&s[i - 1], &s[i]);
        let t = (distance_m - a.distance_m) / (b.distance_m - a.distance_m);
        a.coefficients[c].lerp(&b.coefficients[c], t)
    }

    /// Checks the recorded wavelengths and pitch, if any, against `setup` (relative tolerance 10⁻⁶).
    ///
    /// Errors: [`HoloError::InvalidParameter`] naming the quantity, the profile's value and the display's.
    pub(crate) fn check_setup(&self, setup: &OpticalSetup) -> Result<()> {
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * b.abs();
        if let Some(w) = self.wavelengths_m {
            if !w
                .iter()
                .zip(&setup.wavelengths_m)
                .all(|(a, b)| close(*a, *b))
            {
                return Err(invalid(
                    "wavelengths_m",
                    format!(
                        "the aberration profile was calibrated for {w:?} m, the display uses {:?} m",
                        setup.wavelengths_m
                    ),
                ));
            }
        }
        if let Some(p) = self.pixel_pitch_m {
            if !close(p, setup.pixel_pitch_m) {
                return Err(invalid(
                    "pixel_pitch_m",
                    format!(
                        "the aberration profile was calibrated for {p} m, the display uses {} m",
                        setup.pixel_pitch_m
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Parses the JSON form (`docs/ABERRATION.md`); `source` names the input in error messages.
    ///
    /// Errors: [`HoloError::InvalidData`] naming `source`, the key path (`samples[0].per_colour`, through
    /// `io::parse_json_object`) and what is wrong: not one JSON object of this form, another format
    /// or version, no sample, non-finite values, duplicate distances, a sample with both or neither of
    /// `coefficients` and `per_colour`, an array of the wrong length, a key given twice.
    pub fn from_json_str(text: &str, source: &str) -> Result<Self> {
        crate::io::parse_json_object::<Self>(text, "an aberration profile").map_err(|e| {
            HoloError::InvalidData(format!(
                "`{source}` is not a valid aberration profile ({ABERRATION_FORMAT} version \
                 {ABERRATION_FORMAT_VERSION}, docs/ABERRATION.md): {e}"
            ))
        })
    }

    /// Reads a profile file.
    ///
    /// Errors: [`HoloError::Io`] if unreadable; as [`AberrationProfile::from_json_str`] otherwise.
    pub fn load(path: &Path) -> Result<Self> {
        let text = crate::io::read_text(path)?;
        Self::from_json_str(&text, &path.display().to_string())
    }

    /// The JSON form (pretty-printed), which [`AberrationProfile::from_json_str`] reads back.
    pub fn to_json_string(&self) -> String {
        serde_json::to_string_pretty(self).expect("a profile always serialises")
    }

    /// Writes the JSON form to `path`, atomically ([`crate::io::write_atomic`]: a temporary file renamed over
    /// `path`, so a reader never sees half a file, and a symbolic link at `path` is replaced, not followed: the
    /// file it pointed to is left as it was).
    ///
    /// Errors: [`HoloError::Io`] naming `path`.
    pub fn save(&self, path: &Path) -> Result<()> {
        crate::io::write_atomic(path, (self.to_json_string() + "\n").as_bytes())
    }
}

/// Where the aberration a session corrects comes from: a measured profile (a `tensorholo.aberration` file, or
/// one already read) or a viewer's spectacle prescription, converted on the display in use
/// ([`AberrationProfile::from_prescription`]).
#[derive(Debug, Clone, PartialEq)]
pub enum AberrationSource {
    /// A `tensorholo.aberration` file, read by [`AberrationSource::resolve`].
    File(PathBuf),
    /// A measured profile already read ([`AberrationProfile::load`], [`AberrationProfile::from_json_str`]).
    Measured(AberrationProfile),
    /// A spectacle prescription.
    Prescription(Prescription),
}

impl AberrationSource {
    /// The SDK's one rule for which aberration a session corrects, used by `holo` and the bindings alike: what
    /// the caller gave (`given`: a flag, a generator configuration's field) before the display profile's own
    /// (`AberrationSource::of_profile`); `None` without either. A caller gives at most one source, and a
    /// profile has at most one (`AberrationSource::from_either`, [`DisplayProfile::with_prescription`]).
    pub fn select(given: Option<Self>, profile: Option<&DisplayProfile>) -> Option<Self> {
        given.or_else(|| profile.and_then(Self::of_profile))
    }

    /// A display profile's own aberration: its `aberration` file, else its `prescription`; `None` without
    /// either.
    pub(crate) fn of_profile(profile: &DisplayProfile) -> Option<Self> {
        match (&profile.aberration, profile.prescription) {
            (Some(path), _) => Some(Self::File(path.clone())),
            (None, Some(rx)) => Some(Self::Prescription(rx)),
            (None, None) => None,
        }
    }

    /// The source of a configuration that carries a prescription and a measured profile side by side (a
    /// generator's, the bindings'): the one given, or `None`.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`prescription`) when both are given.
    pub(crate) fn from_either(
        prescription: Option<Prescription>,
        measured: Option<AberrationProfile>,
    ) -> Result<Option<Self>> {
        match (prescription, measured) {
            (Some(_), Some(_)) => Err(invalid(
                "prescription",
                "a prescription and an aberration profile were both given: give one",
            )),
            (Some(rx), None) => Ok(Some(Self::Prescription(rx))),
            (None, Some(p)) => Ok(Some(Self::Measured(p))),
            (None, None) => Ok(None),
        }
    }

    /// The profile a session on `optics`' display corrects: the file read, the measured profile, or the
    /// prescription's coefficients on these lasers and this pixel pitch.
    ///
    /// Errors: as [`AberrationProfile::load`] for a file, [`AberrationProfile::from_prescription`] for a
    /// prescription.
    pub fn resolve(&self, optics: &OpticalSetup) -> Result<AberrationProfile> {
        match self {
            Self::File(path) => AberrationProfile::load(path),
            Self::Measured(p) => Ok(p.clone()),
            Self::Prescription(rx) => AberrationProfile::from_prescription(rx, optics),
        }
    }

    /// The source for a report: `{"file": PATH}`, `{"prescription": {...}}` or `{"measured": true}`.
    pub fn to_json(&self) -> serde_json::Value {
        match self {
            Self::File(path) => serde_json::json!({ "file": path.to_string_lossy() }),
            Self::Measured(_) => serde_json::json!({ "measured": true }),
            Self::Prescription(rx) => serde_json::json!({ "prescription": rx }),
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Two samples (4 mm and −2 mm, focus and vertical coma), for the tests of every module that applies a
    /// profile.
    pub(crate) fn two_point_profile() -> AberrationProfile {
        let at = |focus: f64, coma: f64| ZernikeCoefficients {
            focus,
            coma_vertical: coma,
            ..ZernikeCoefficients::ZERO
        };
        AberrationProfile::new(vec![
            AberrationSample {
                distance_m: 0.004,
                coefficients: [at(3.0, 1.0), at(3.0, 1.0), at(3.0, 1.0)],
            },
            AberrationSample {
                distance_m: -0.002,
                coefficients: [at(1.0, 0.0), at(2.0, 0.0), at(1.0, 0.0)],
            },
            AberrationSample {
                distance_m: 0.0,
                coefficients: [at(-1.0, 0.0), at(0.0, 0.0), at(0.0, 0.0)],
            },
        ])
        .expect("valid profile")
    }

    /// `save` writes atomically and replaces a symbolic link at its path instead of writing through it: the
    /// unrelated file the link pointed to keeps its bytes, and the saved file reads back as the profile.
    #[cfg(unix)]
    #[test]
    fn save_replaces_a_link_at_its_path_and_leaves_the_linked_file_alone() {
        let dir = tempfile::tempdir().unwrap();
        let unrelated = dir.path().join("unrelated.txt");
        std::fs::write(&unrelated, "keep me").unwrap();
        let out = dir.path().join("eye.json");
        std::os::unix::fs::symlink(&unrelated, &out).unwrap();
        let profile = two_point_profile();
        profile.save(&out).unwrap();
        assert_eq!(std::fs::read_to_string(&unrelated).unwrap(), "keep me");
        assert!(!std::fs::symlink_metadata(&out)
            .unwrap()
            .file_type()
            .is_symlink());
        let back = AberrationProfile::load(&out).unwrap();
        assert!(back.same_aberrations(&profile));
        // No temporary file left beside it.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
    }

    /// Coefficients beyond ±MAX_COEFFICIENT_RAD are refused naming the sample, the colour and the term (1e20
    /// rendered silently and 1e308 overflowed to NaN before); the bound itself is accepted.
    #[test]
    fn huge_coefficients_are_refused_naming_the_term() {
        let profile = |a: f64| {
            AberrationProfile::new(vec![AberrationSample {
                distance_m: 0.0,
                coefficients: [
                    ZernikeCoefficients::ZERO,
                    ZernikeCoefficients {
                        coma_vertical: a,
                        ..ZernikeCoefficients::ZERO
                    },
                    ZernikeCoefficients::ZERO,
                ],
            }])
        };
        for a in [1e20, -1e308, MAX_COEFFICIENT_RAD * 1.001] {
            let e = profile(a).unwrap_err().to_string();
            assert!(
                e.contains("sample 0") && e.contains("colour G") && e.contains("coma_vertical"),
                "{e}"
            );
        }
        assert!(profile(MAX_COEFFICIENT_RAD).is_ok());
        assert!(profile(-250.0).is_ok());
    }

    #[test]
    fn coefficients_are_piecewise_linear_in_distance_and_clamped() {
        let p = two_point_profile();
        assert_eq!(p.samples()[0].distance_m, -0.002, "sorted by distance");
        let focus = |d: f64, c: usize| p.coefficients(d, c).focus;
        assert!((focus(-0.001, 0) - 0.0).abs() < 1e-12);
        assert!((focus(-0.0015, 0) - 0.5).abs() < 1e-12);
        assert!((focus(-0.001, 1) - 1.0).abs() < 1e-12, "green has its own");
        assert!((focus(0.001, 0) - 0.0).abs() < 1e-12);
        assert!((focus(0.003, 0) - 2.0).abs() < 1e-12);
        assert!((p.coefficients(0.003, 0).coma_vertical - 0.75).abs() < 1e-12);
        assert_eq!(focus(-0.5, 0), 1.0, "clamped below");
        assert_eq!(focus(0.5, 2), 3.0, "clamped above");
        assert_eq!(focus(0.004, 0), 3.0);
        assert_eq!(focus(f64::NAN, 0), 1.0);
        assert_eq!(p.coefficients(0.0, 7), p.coefficients(0.0, 2));
    }

    #[test]
    fn json_round_trip_and_per_colour_or_shared_coefficients() {
        let p = two_point_profile().with_display([638e-9, 520e-9, 450e-9], 8e-6);
        let text = p.to_json_string();
        assert!(text.contains("\"per_colour\""), "{text}");
        assert!(text.contains("\"coefficients\""), "{text}");
        let back = AberrationProfile::from_json_str(&text, "memory").expect("reads back");
        assert_eq!(back, p);
        back.check_setup(&OpticalSetup::default())
            .expect("same display");
        let other = OpticalSetup {
            pixel_pitch_m: 6.4e-6,
            ..OpticalSetup::default()
        };
        assert!(matches!(
            back.check_setup(&other),
            Err(HoloError::InvalidParameter {
                name: "pixel_pitch_m",
                ..
            })
        ));
        let minimal = r#"{"format": "tensorholo.aberration", "version": 1,
            "samples": [{"distance_m": 0.001, "coefficients": {"focus": 0.25}}]}"#;
        let m = AberrationProfile::from_json_str(minimal, "m").expect("minimal file");
        assert_eq!(m.coefficients(-1.0, 1).focus, 0.25);
        assert_eq!(m.coefficients(-1.0, 1).astigmatism_vertical, 0.0);
    }

    #[test]
    fn bad_files_are_errors_naming_the_file_and_the_problem() {
        let head = r#""format": "tensorholo.aberration", "version": 1"#;
        let cases = [
            ("not json", "text that is not JSON".to_string()),
            (&*Box::leak(format!("[{{{head}, \"samples\": []}}]").into_boxed_str()), "must be one JSON object".into()),
            // Four colours where `per_colour` holds R, G, B: the key path and the reason, not "trailing characters".
            (
                &*Box::leak(format!(r#"{{{head}, "samples": [{{"distance_m": 0.001, "per_colour": [{{}}, {{}}, {{}}, {{}}]}}]}}"#).into_boxed_str()),
                "at `samples[0].per_colour`: more entries".into(),
            ),
            (
                &*Box::leak(format!(r#"{{{head}, "samples": [{{"distance_m": "1 mm", "coefficients": {{}}}}]}}"#).into_boxed_str()),
                "at `samples[0].distance_m`: invalid type: string".into(),
            ),
            (
                &*Box::leak(format!(r#"{{{head}, "samples": [{{"distance_m": 0.001, "coefficients": {{"focus": 1, "focus": 2}}}}]}}"#).into_boxed_str()),
                "at `samples[0].coefficients`: duplicate field `focus`".into(),
            ),
            (
                r#"{"format": "other", "version": 1, "samples": [{"distance_m": 0, "coefficients": {}}]}"#,
                "format is `other`".into(),
            ),
            (
                r#"{"format": "tensorholo.aberration", "version": 2, "samples": [{"distance_m": 0, "coefficients": {}}]}"#,
                "version is 2".into(),
            ),
            (&*Box::leak(format!("{{{head}, \"samples\": []}}").into_boxed_str()), "at least one sample".into()),
            (
                &*Box::leak(format!(r#"{{{head}, "samples": [{{"distance_m": 0.002, "coefficients": {{}}}}, {{"distance_m": 0.001, "coefficients": {{}}}}]}}"#).into_boxed_str()),
                "strictly increasing".into(),
            ),
            (
                &*Box::leak(format!(r#"{{{head}, "samples": [{{"distance_m": 0.001, "coefficients": {{}}}}, {{"distance_m": 0.001, "coefficients": {{}}}}]}}"#).into_boxed_str()),
                "strictly increasing".into(),
            ),
            (
                &*Box::leak(format!(r#"{{{head}, "samples": [{{"distance_m": 0.001}}]}}"#).into_boxed_str()),
                "exactly one of".into(),
            ),
            (
                &*Box::leak(format!(r#"{{{head}, "samples": [{{"distance_m": 0.001, "coefficients": {{"focs": 1}}}}]}}"#).into_boxed_str()),
                "unknown field".into(),
            ),
            (
                &*Box::leak(format!(r#"{{{head}, "samples": [{{"distance_m": 1e999, "coefficients": {{}}}}]}}"#).into_boxed_str()),
                "".into(),
            ),
            (
                &*Box::leak(format!(r#"{{{head}, "pixel_pitch_m": -1, "samples": [{{"distance_m": 0, "coefficients": {{}}}}]}}"#).into_boxed_str()),
                "pixel_pitch_m".into(),
            ),
        ];
        for (text, what) in cases {
            match AberrationProfile::from_json_str(text, "bad.json") {
                Err(HoloError::InvalidData(m)) => {
                    assert!(m.contains("bad.json") && m.contains(&what), "{text}: {m}")
                }
                other => panic!("{text}: expected InvalidData, got {other:?}"),
            }
        }
        let nan = AberrationProfile::new(vec![AberrationSample {
            distance_m: 0.0,
            coefficients: [ZernikeCoefficients {
                focus: f64::NAN,
                ..ZernikeCoefficients::ZERO
            }; 3],
        }]);
        assert!(matches!(nan, Err(HoloError::InvalidData(m)) if m.contains("finite")));
        let missing = AberrationProfile::load(Path::new("/nonexistent/aberration.json"));
        assert!(matches!(missing, Err(HoloError::Io { .. })));
    }

    /// The one rule: what the caller gave before the profile's own; a profile's file before its prescription
    /// (the profile keeps at most one); a prescription and a measured profile together refused; a
    /// prescription resolves to its coefficients on the display in use.
    #[test]
    fn the_source_rule_takes_the_callers_before_the_profiles() {
        let rx = Prescription::new(-2.0, -0.75, Some(30.0)).unwrap();
        let measured = two_point_profile();
        let json = r#"{"pixel_pitch_m": 8e-6, "resolution": [48, 64], "wavelengths_m": [638e-9, 520e-9, 450e-9],
            "volume_depth_m": 6e-3, "offsets_m": [6e-3]}"#;
        let plain = DisplayProfile::from_json_str(json).unwrap();
        let with_rx = plain.clone().with_prescription(Some(rx)).unwrap();
        let with_file = plain
            .clone()
            .with_aberration_file(Some("eyes.json".into()))
            .unwrap();
        assert_eq!(AberrationSource::select(None, Some(&plain)), None);
        assert_eq!(
            AberrationSource::select(None, Some(&with_rx)),
            Some(AberrationSource::Prescription(rx))
        );
        assert_eq!(
            AberrationSource::select(None, Some(&with_file)),
            Some(AberrationSource::File("eyes.json".into()))
        );
        let given = AberrationSource::Measured(measured.clone());
        assert_eq!(
            AberrationSource::select(Some(given.clone()), Some(&with_rx)),
            Some(given)
        );
        let both = AberrationSource::from_either(Some(rx), Some(measured.clone()));
        assert!(matches!(
            both,
            Err(HoloError::InvalidParameter {
                name: "prescription",
                ..
            })
        ));
        let optics = OpticalSetup::default();
        assert_eq!(
            AberrationSource::Prescription(rx).resolve(&optics).unwrap(),
            AberrationProfile::from_prescription(&rx, &optics).unwrap()
        );
        assert_eq!(
            AberrationSource::from_either(None, Some(measured.clone()))
                .unwrap()
                .unwrap()
                .resolve(&optics)
                .unwrap(),
            measured
        );
    }
}

//! Aberration correction (paper Methods, "Compensating hardware imperfection", Eq. 14–19, and the
//! aberration-corrected SM-LBM of Eq. 5).
//!
//! The display's aberrations are modelled, per signed focus distance `d`, by five Zernike polynomials on the
//! SLM's pupil ([`ZernikeCoefficients`], Eq. 14–18), calibrated at a few distances and interpolated piecewise
//! linearly in between ([`AberrationProfile`], a JSON file, format in `docs/ABERRATION.md`).
//!
//! Two equivalent forms of the correction kernel `Φ_d` exist:
//!
//! - **Eq. 19, as the paper words it**: the ideal sub-hologram `φ⁰_d` that focuses a plane wave to `d`,
//!   multiplied by `exp(i·ΣZ_j)`, gives the corrected sub-hologram `φ_d` ([`corrected_subhologram`]); its point
//!   spread function is `PSF_d = ASM(φ_d, d)` ([`psf`]) and `Φ_d = F(PSF_d)`
//!   ([`amplitude_transfer_function_from_subhologram`]).
//! - **Frequency domain**, used for synthesis: `Φ_d(fx, fy) = circ(ρ ≤ 1)·exp(i·ΣZ_j(ρ, θ))` with
//!   `ρ = |f|/f_N`, `f_N = 1/(2p)` the SLM's Nyquist frequency (its maximum diffraction angle) and
//!   `θ = atan2(fy, fx)` ([`amplitude_transfer_function`]).
//!
//! They agree because the Zernike polynomials of Eq. 19 are evaluated at the normalised polar coordinates of
//! the **local spatial frequency** of `φ⁰_d` at each sub-hologram point, `f = −(x, y)/(λ·d)`: by stationary
//! phase, the plane wave of frequency `f` leaving the sub-hologram comes from the point `(x, y) = −λ·d·f`, so
//! the sub-hologram's phase at that point becomes the spectrum's phase at `f` (checked by the tests; the
//! residual is of order `λ·|∇Z|²/(4π·d·tan²α)`, small once the sub-hologram spans several Fresnel zones).
//!
//! [`AberrationCorrectedSmLbm`] applies `Φ_{d_N}` to the occlusion-processed content of every depth plane
//! separately (Eq. 5), at the cost of `G·(G + 1)/2` propagations per colour for `G` non-empty planes instead of
//! `G`.

use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

use ndarray::{Array2, Array3};
use num_complex::Complex32;
use serde::{Deserialize, Serialize};

use super::sm_lbm::{GapPropagation, SceneLayer, SmLbm};
use crate::display::Prescription;
use crate::error::{invalid, HoloError, Result};
use crate::optics::{par_channels, Carrier, PropagationOptions, Propagator, SpectralPlan};
use crate::optics::{propagation::check_positive, OpticalSetup};

/// Value of an aberration file's `format` field.
pub const ABERRATION_FORMAT: &str = "tensorholo.aberration";
/// Version of the aberration file format this build reads and writes.
pub const ABERRATION_FORMAT_VERSION: u32 = 1;
/// The largest magnitude of a Zernike coefficient, radians at the pupil edge: 10⁴. The correction kernel
/// `e^{iΣZ}` is sampled on the frequency grid, where the focus term's phase changes by `8|a|/N` between
/// neighbouring bins at the pupil edge (`N` bins across the grid); beyond `π` it aliases. At the largest SLM
/// side the SDK accepts (8192 pixels) that is `|a| ≈ 3.2·10³`, so no grid samples a larger coefficient, while
/// the strongest prescription the SDK converts stays far below (about 35 rad per colour on an 8 µm display,
/// 2.2·10³ at 1 µm). Larger values are a unit or typing error (or overflow to NaN in the kernel).
pub const MAX_COEFFICIENT_RAD: f64 = 1e4;

/// The five Zernike coefficients of the paper's aberration model (Eq. 14–18), in radians of phase at the
/// pupil edge (`ρ = 1`): the paper's `a3d … a7d` at one focus distance `d` and one wavelength.
///
/// In JSON every field is optional (default 0) and unknown fields are refused.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ZernikeCoefficients {
    /// `a3`, focus: `Z3 = a3·(2ρ² − 1)` (Eq. 14).
    pub focus: f64,
    /// `a4`, vertical astigmatism: `Z4 = a4·ρ²·cos 2θ` (Eq. 15).
    pub astigmatism_vertical: f64,
    /// `a5`, oblique astigmatism: `Z5 = a5·ρ²·sin 2θ` (Eq. 16).
    pub astigmatism_oblique: f64,
    /// `a6`, horizontal coma: `Z6 = a6·(3ρ² − 2)·ρ·cos θ` (Eq. 17).
    pub coma_horizontal: f64,
    /// `a7`, vertical coma: `Z7 = a7·(3ρ² − 2)·ρ·sin θ` (Eq. 18).
    pub coma_vertical: f64,
}

impl ZernikeCoefficients {
    /// All coefficients zero (no aberration).
    pub const ZERO: Self = Self {
        focus: 0.0,
        astigmatism_vertical: 0.0,
        astigmatism_oblique: 0.0,
        coma_horizontal: 0.0,
        coma_vertical: 0.0,
    };

    /// The coefficients `[a3, a4, a5, a6, a7]`.
    pub fn to_array(&self) -> [f64; 5] {
        [
            self.focus,
            self.astigmatism_vertical,
            self.astigmatism_oblique,
            self.coma_horizontal,
            self.coma_vertical,
        ]
    }

    /// Coefficients from `[a3, a4, a5, a6, a7]`.
    pub fn from_array(a: [f64; 5]) -> Self {
        Self {
            focus: a[0],
            astigmatism_vertical: a[1],
            astigmatism_oblique: a[2],
            coma_horizontal: a[3],
            coma_vertical: a[4],
        }
    }

    /// Whether every coefficient is zero.
    pub fn is_zero(&self) -> bool {
        self.to_array().iter().all(|&a| a == 0.0)
    }

    /// `self + t·(other − self)`, coefficient by coefficient.
    pub fn lerp(&self, other: &Self, t: f64) -> Self {
        let (a, b) = (self.to_array(), other.to_array());
        Self::from_array(std::array::from_fn(|j| a[j] + t * (b[j] - a[j])))
    }

    /// The aberration phase in radians, `Σ_j Z_j(ρ, θ)` of Eq. 14–18, at normalised polar radius `rho`
    /// (1 at the pupil edge) and azimuth `theta` (radians, from the `+x` axis toward `+y`):
    /// `a3(2ρ²−1) + a4ρ²cos2θ + a5ρ²sin2θ + a6(3ρ²−2)ρcosθ + a7(3ρ²−2)ρsinθ`.
    pub fn phase(&self, rho: f64, theta: f64) -> f64 {
        let (s, c) = theta.sin_cos();
        self.phase_xy(rho * c, rho * s)
    }

    /// [`ZernikeCoefficients::phase`] in Cartesian pupil coordinates `(ρ·cos θ, ρ·sin θ)` (no trigonometry).
    pub fn phase_xy(&self, rx: f64, ry: f64) -> f64 {
        let r2 = rx * rx + ry * ry;
        let coma = 3.0 * r2 - 2.0;
        self.focus * (2.0 * r2 - 1.0)
            + self.astigmatism_vertical * (rx * rx - ry * ry)
            + self.astigmatism_oblique * (2.0 * rx * ry)
            + self.coma_horizontal * coma * rx
            + self.coma_vertical * coma * ry
    }
}

impl std::ops::Neg for ZernikeCoefficients {
    type Output = Self;

    /// The opposite aberration (its correction).
    fn neg(self) -> Self {
        Self::from_array(self.to_array().map(|a| -a))
    }
}

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
/// ([`AberrationProfile::check_setup`]). Each sample has either `coefficients` (all colours) or `per_colour`
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
    /// [`Prescription::zernike`], the same at every distance (the lens sits at the viewer's pupil, so the
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
    /// [`AberrationProfile::check_setup`] then compares with the display in use.
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
    pub fn is_zero(&self) -> bool {
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
    pub fn describe(&self) -> String {
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
    pub fn check_setup(&self, setup: &OpticalSetup) -> Result<()> {
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
    /// [`crate::io::parse_json_object`]) and what is wrong: not one JSON object of this form, another format
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

/// Checks pitch, wavelength and focus distance of the Eq. 19 functions.
fn check_subhologram_args(
    height: usize,
    width: usize,
    pixel_pitch_m: f64,
    wavelength_m: f64,
    distance_m: f64,
) -> Result<()> {
    check_positive("pixel_pitch_m", pixel_pitch_m)?;
    check_positive("wavelength_m", wavelength_m)?;
    if height == 0 || width == 0 {
        return Err(invalid(
            "field size",
            format!("height and width must be ≥ 1, got {height}×{width}"),
        ));
    }
    if !(distance_m.is_finite() && distance_m != 0.0) {
        return Err(invalid(
            "distance_m",
            format!("must be finite and non-zero, got {distance_m}"),
        ));
    }
    if wavelength_m >= 2.0 * pixel_pitch_m {
        return Err(invalid(
            "wavelength_m",
            format!("must be below twice the pixel pitch ({pixel_pitch_m} m), got {wavelength_m}"),
        ));
    }
    Ok(())
}

/// Radius in metres of the ideal sub-hologram focusing to `distance_m`: `R_d = |d|·tan(asin(λ/(2p)))`, the
/// cone of the SLM's maximum diffraction angle.
pub fn subhologram_radius_m(pixel_pitch_m: f64, wavelength_m: f64, distance_m: f64) -> f64 {
    distance_m.abs() * (wavelength_m / (2.0 * pixel_pitch_m)).asin().tan()
}

/// The corrected sub-hologram `φ_d` of Eq. 19, `[height, width]`: the ideal sub-hologram `φ⁰_d` that focuses a
/// plane wave of `wavelength_m` to signed distance `distance_m` (metres, positive along the light; negative:
/// a diverging wave from a virtual focus behind the SLM), times `exp(i·ΣZ_j(ρ, θ))` of `coefficients`
/// (Eq. 14–18).
///
/// `φ⁰_d = exp(−iπ·r²/(λ·d))` inside the aperture of radius [`subhologram_radius_m`] (the SLM's maximum
/// diffraction cone), zero outside, centred on pixel `(width/2, height/2)` (pixel `(x, y)` at
/// `((x − width/2)·p, (y − height/2)·p)`), i.e. zero-padded to the frame. `ρ, θ` are the normalised polar
/// coordinates of the local spatial frequency of `φ⁰_d` at `(x, y)`, `f = −(x, y)/(λ·d)`: `ρ = |f|/f_N` with
/// `f_N = 1/(2p)`, `θ = atan2(fy, fx)` (module docs: this makes Eq. 19 agree with the frequency-domain form
/// [`amplitude_transfer_function`]). An aperture larger than the frame is clipped by it.
///
/// Errors: [`HoloError::InvalidParameter`] for a zero size, a non-positive pitch or wavelength, a wavelength
/// of at least twice the pitch, or a zero or non-finite distance.
pub fn corrected_subhologram(
    height: usize,
    width: usize,
    pixel_pitch_m: f64,
    wavelength_m: f64,
    distance_m: f64,
    coefficients: &ZernikeCoefficients,
) -> Result<Array2<Complex32>> {
    check_subhologram_args(height, width, pixel_pitch_m, wavelength_m, distance_m)?;
    let p = pixel_pitch_m;
    let radius = subhologram_radius_m(p, wavelength_m, distance_m);
    let lambda_d = wavelength_m * distance_m;
    // ρ-vector = f / f_N = −(x, y)·2p/(λd).
    let to_rho = -2.0 * p / lambda_d;
    let (cy, cx) = ((height / 2) as f64, (width / 2) as f64);
    Ok(Array2::from_shape_fn((height, width), |(row, col)| {
        let (x, y) = ((col as f64 - cx) * p, (row as f64 - cy) * p);
        let r2 = x * x + y * y;
        if r2 > radius * radius {
            return Complex32::new(0.0, 0.0);
        }
        let phase =
            -std::f64::consts::PI * r2 / lambda_d + coefficients.phase_xy(x * to_rho, y * to_rho);
        let (s, c) = phase.sin_cos();
        Complex32::new(c as f32, s as f32)
    }))
}

/// The point spread function `PSF_d = ASM(φ_d, d)` `[height, width]` of the corrected sub-hologram
/// ([`corrected_subhologram`]) at its focus (paper text after Eq. 19), with the angular spectrum method of
/// [`crate::optics::Propagator`] (no padding, the on-axis carrier `exp(i·2π·d/λ)` removed, Eq. 6). The spot
/// sits at pixel `(width/2, height/2)`.
///
/// Errors: as [`corrected_subhologram`].
pub fn psf(
    height: usize,
    width: usize,
    pixel_pitch_m: f64,
    wavelength_m: f64,
    distance_m: f64,
    coefficients: &ZernikeCoefficients,
) -> Result<Array2<Complex32>> {
    let mut field = corrected_subhologram(
        height,
        width,
        pixel_pitch_m,
        wavelength_m,
        distance_m,
        coefficients,
    )?;
    let prop = Propagator::new(
        height,
        width,
        pixel_pitch_m,
        wavelength_m,
        PropagationOptions::default(),
    )?;
    let slice = field
        .as_slice_mut()
        .expect("a fresh array is in standard layout");
    prop.propagate_by(slice, distance_m, Carrier::Remove)?;
    Ok(field)
}

/// Copies a multiplier of an unpadded plan (transposed `[width, height]`, FFT order) into a `[height, width]`
/// array in FFT order (row = `ky` bin, column = `kx` bin, as `numpy.fft.fft2`).
fn plan_layout_to_array(plan: &SpectralPlan, values: &[Complex32]) -> Array2<Complex32> {
    let (h, w) = plan.computational_shape();
    Array2::from_shape_fn((h, w), |(ky, kx)| values[kx * h + ky])
}

/// Divides `values` by their mean magnitude over the bins where `inside` holds.
fn normalise_in_pupil(values: &mut [Complex32], inside: impl Fn(usize) -> bool) {
    let (sum, n) = values
        .iter()
        .enumerate()
        .filter(|(i, _)| inside(*i))
        .fold((0.0f64, 0usize), |(s, n), (_, v)| {
            (s + v.norm() as f64, n + 1)
        });
    if n > 0 && sum > 0.0 {
        let k = (n as f64 / sum) as f32;
        values.iter_mut().for_each(|v| *v *= k);
    }
}

/// Whether bin `(kx, ky)` (signed indices) of a `[ch, cw]` grid at pitch `p` lies in the pupil `ρ ≤ 1`, and its
/// pupil coordinates `(ρx, ρy) = (fx, fy)/f_N`.
fn pupil_coordinates(kx: i64, ky: i64, ch: usize, cw: usize) -> (f64, f64) {
    // fx = kx/(cw·p), f_N = 1/(2p): ρx = 2kx/cw, independent of the pitch.
    (2.0 * kx as f64 / cw as f64, 2.0 * ky as f64 / ch as f64)
}

/// The frequency-domain correction kernel of `coefficients` on `plan`'s computational grid, in the plan's
/// spectrum layout (transposed, FFT order, no normalisation): `circ(ρ ≤ 1)·exp(i·ΣZ_j(ρ, θ))`.
pub(crate) fn pupil_multiplier(
    plan: &SpectralPlan,
    coefficients: &ZernikeCoefficients,
) -> Vec<Complex32> {
    let mut out = Vec::with_capacity(plan.spectrum_len());
    fill_pupil_multiplier(plan, coefficients, 1.0, &mut out);
    out
}

/// [`pupil_multiplier`] times `scale`, written into `out` (no allocation when it has the capacity): the
/// real-time pipeline's correction kernel (`scale`: the inverse transform's normalisation where no transfer
/// function carries it).
pub(crate) fn fill_pupil_multiplier(
    plan: &SpectralPlan,
    coefficients: &ZernikeCoefficients,
    scale: f32,
    out: &mut Vec<Complex32>,
) {
    let (ch, cw) = plan.computational_shape();
    plan.fill_multiplier(out, |kx, ky| {
        let (rx, ry) = pupil_coordinates(kx, ky, ch, cw);
        if rx * rx + ry * ry > 1.0 {
            return Complex32::new(0.0, 0.0);
        }
        let (s, c) = coefficients.phase_xy(rx, ry).sin_cos();
        Complex32::new(c as f32 * scale, s as f32 * scale)
    })
}

/// The frequency-domain amplitude transfer function `Φ(fx, fy) = circ(ρ ≤ 1)·exp(i·ΣZ_j(ρ, θ))` `[height,
/// width]` in FFT order (row `ky`, column `kx`, frequencies `fx = kx/(width·p)`, `fy = ky/(height·p)` as
/// `numpy.fft.fftfreq`), with `ρ = |f|/f_N`, `f_N = 1/(2p)` and `θ = atan2(fy, fx)`: the form of Eq. 5's
/// kernel that [`AberrationCorrectedSmLbm`] uses. Unit magnitude inside the pupil. Independent of the pitch
/// and wavelength: the coefficients are radians at the pupil edge.
///
/// Errors: [`HoloError::InvalidParameter`] for a zero size.
pub fn amplitude_transfer_function(
    height: usize,
    width: usize,
    coefficients: &ZernikeCoefficients,
) -> Result<Array2<Complex32>> {
    let plan = SpectralPlan::new(height, width, crate::optics::Padding::None)?;
    Ok(plan_layout_to_array(
        &plan,
        &pupil_multiplier(&plan, coefficients),
    ))
}

/// The amplitude transfer function as the paper computes it after Eq. 19, `Φ_d = F(PSF_d) = F(ASM(φ_d, d))`,
/// `[height, width]` in the layout of [`amplitude_transfer_function`], normalised to unit mean magnitude
/// inside the pupil `ρ ≤ 1` and with the constant phase `−i·sign(d)` of the Fresnel transform of `φ⁰_d`
/// removed, so that it compares directly with [`amplitude_transfer_function`] (equal up to the
/// stationary-phase residual and the ringing of the aperture's edge).
///
/// Errors: as [`corrected_subhologram`].
pub fn amplitude_transfer_function_from_subhologram(
    height: usize,
    width: usize,
    pixel_pitch_m: f64,
    wavelength_m: f64,
    distance_m: f64,
    coefficients: &ZernikeCoefficients,
) -> Result<Array2<Complex32>> {
    let field = psf(
        height,
        width,
        pixel_pitch_m,
        wavelength_m,
        distance_m,
        coefficients,
    )?;
    let plan = SpectralPlan::new(height, width, crate::optics::Padding::None)?;
    let mut scratch = plan.scratch();
    let mut spectrum = vec![Complex32::default(); plan.spectrum_len()];
    plan.forward(
        field.as_slice().expect("standard layout"),
        &mut spectrum,
        &mut scratch,
    )?;
    // The sub-hologram is centred on pixel (width/2, height/2), not on pixel 0: undo that shift's linear phase,
    // and the Fresnel transform's constant −i·sign(d).
    let (cy, cx) = ((height / 2) as f64, (width / 2) as f64);
    let fresnel = Complex32::new(0.0, distance_m.signum() as f32);
    let shift = plan.build_multiplier(|kx, ky| {
        let phase = std::f64::consts::TAU
            * (kx as f64 * cx / width as f64 + ky as f64 * cy / height as f64);
        let (s, c) = phase.sin_cos();
        Complex32::new(c as f32, s as f32) * fresnel
    });
    let inside = pupil_multiplier(&plan, &ZernikeCoefficients::ZERO);
    for (v, m) in spectrum.iter_mut().zip(&shift) {
        *v *= m;
    }
    normalise_in_pupil(&mut spectrum, |i| inside[i].re > 0.5);
    Ok(plan_layout_to_array(&plan, &spectrum))
}

/// The aberration correction of Eq. 5 besides the SM-LBM settings: the calibrated profile and where the SLM is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AberrationCorrection {
    /// Calibrated Zernike coefficients per focus distance and colour.
    pub profile: AberrationProfile,
    /// Signed distance `s` in metres from the midpoint plane to the SLM plane (the pipeline's offset,
    /// `docs/CONVENTIONS.md` §4). A depth plane at `z_N` is corrected with the coefficients at
    /// `d_N = z_N − s`, its signed distance from the SLM plane.
    pub slm_offset_m: f64,
}

/// The aberration-corrected silhouette-mask layer-based method (paper Eq. 5 and the text around it).
///
/// For the content of every non-empty depth plane `N` separately: start from the plane's own field (Eq. 1,
/// Maimone et al.'s initial phase, as [`SmLbm`]), propagate it toward the viewer through every nearer non-empty
/// plane applying only that plane's silhouette mask (occlusion, Eq. 3, without the addition term of Eq. 4),
/// propagate the result back to plane `N` (the occlusion-processed `L′_N`), multiply its spectrum by the
/// correction kernel `Φ_{d_N}` (Eq. 5; frequency-domain form, [`amplitude_transfer_function`]) with the
/// coefficients of [`AberrationProfile::coefficients`] at `d_N = z_N − s`, propagate it to the midpoint plane
/// `z = 0`, and sum over `N`.
///
/// Cost: `G·(G + 1)/2` propagations per colour for `G` non-empty planes (the paper's `N²/2`) instead of `G`
/// ([`AberrationCorrectedSmLbm::propagation_count`]); without silhouette masks every plane is independent and
/// the cost is `G`. Memory: three `[H, W]` fields per colour, whatever `G`. Colours run in parallel; the planes
/// of one colour run in order, so results are deterministic.
///
/// `Φ` is zero outside the pupil `ρ ≤ 1` (the SLM's diffraction cone), so even with zero coefficients the
/// result is plain SM-LBM band-limited to that circle.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AberrationCorrectedSmLbm {
    /// Planes, display geometry, propagation options and silhouette masks, as for [`SmLbm`].
    pub base: SmLbm,
    /// The correction.
    pub correction: AberrationCorrection,
}

impl AberrationCorrectedSmLbm {
    /// The propagation count of a scene with `nonempty_planes` non-empty planes: `G·(G + 1)/2` with silhouette
    /// masks, `G` without. Saturates instead of overflowing.
    pub fn propagations_for(&self, nonempty_planes: usize) -> usize {
        let g = nonempty_planes;
        if self.base.silhouette_masks {
            g.saturating_mul(g.saturating_add(1)) / 2
        } else {
            g
        }
    }

    /// The most propagations per colour any scene can need: [`Self::propagations_for`]`(levels)`.
    pub fn worst_case_propagation_count(&self) -> usize {
        self.propagations_for(self.base.levels)
    }

    /// Number of angular-spectrum propagations per colour that [`AberrationCorrectedSmLbm::synthesize`]
    /// performs on `layers` (`G·(G + 1)/2` for `G` non-empty planes, with silhouette masks).
    ///
    /// Errors: as [`AberrationCorrectedSmLbm::synthesize`].
    pub fn propagation_count(&self, layers: &[SceneLayer]) -> Result<usize> {
        Ok(self.propagations_for(self.base.propagation_count(layers)?))
    }

    /// Checks the configuration: the SM-LBM settings, a finite offset, and the profile's recorded display
    /// against the setup.
    ///
    /// Errors: [`HoloError::InvalidParameter`].
    pub fn validate(&self) -> Result<()> {
        self.base.validate()?;
        crate::optics::check_offset("slm_offset_m", self.correction.slm_offset_m)?;
        self.correction.profile.check_setup(&self.base.setup)
    }

    /// Computes the aberration-corrected midpoint hologram `[3, H, W]` (R, G, B, complex) of a scene given as
    /// layers (front to back), Eq. 5.
    ///
    /// `progress(done, total)` is called after every propagation (from worker threads; colours run in
    /// parallel), `total = 3 ·` [`AberrationCorrectedSmLbm::propagation_count`].
    ///
    /// Errors: those of [`SmLbm::synthesize`]; [`HoloError::InvalidParameter`] for a non-finite offset or a
    /// profile calibrated for another display ([`AberrationProfile::check_setup`]).
    pub fn synthesize(
        &self,
        layers: &[SceneLayer],
        progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<Array3<Complex32>> {
        self.validate()?;
        let base = &self.base;
        let (h, w, planes) = base.bucket(layers)?;
        let props = base.setup.propagators(h, w, base.options)?;
        let groups = planes.groups.len();
        let total = 3 * self.propagations_for(groups) as u64;
        let done = AtomicU64::new(0);
        let tick = || {
            let d = done.fetch_add(1, Ordering::Relaxed) + 1;
            progress(d, total);
        };
        let z_of = |g: usize| base.setup.depth_to_z(base.plane_depth(planes.groups[g].0));
        let mut out = Array3::<Complex32>::zeros((3, h, w));
        par_channels(&mut out, |c, acc| {
            let prop = &props[c];
            let plan = prop.plan();
            let lambda = prop.wavelength_m();
            let mut scratch = plan.scratch();
            let mut gaps = GapPropagation::new(prop, base.plane_spacing_m());
            let mut work = vec![Complex32::default(); h * w];
            // With masks every plane's content ends at the nearest non-empty plane: one transfer function to z = 0.
            let to_midpoint_from_nearest = if base.silhouette_masks {
                Some(prop.transfer_function(-z_of(groups - 1), Carrier::Keep)?)
            } else {
                None
            };
            for n in 0..groups {
                let (level, _, _) = planes.groups[n];
                work.fill(Complex32::default());
                let initial = base.initial_phase(level, lambda);
                for &(p, a) in planes.points_of(n) {
                    work[p as usize] = initial * a[c];
                }
                // Occlusion by every nearer plane: propagate, mask, add nothing (Eq. 4 without its addition).
                let mut last = n;
                if base.silhouette_masks {
                    for m in n + 1..groups {
                        gaps.propagate(
                            &mut work,
                            planes.groups[m - 1].0 - planes.groups[m].0,
                            &mut scratch,
                        )?;
                        for &(p, _) in planes.points_of(m) {
                            work[p as usize] = Complex32::default();
                        }
                        last = m;
                        tick();
                    }
                }
                // Back to plane N (−(z_last − z_N)), Φ_{d_N} (Eq. 5), on to z = 0 (−z_N): the three spectral
                // multipliers commute and the two propagations compose, so they are one multiply by
                // Φ_{d_N}·H(−z_last) with one FFT pair. (With Matsushima's band limit, the limit is that of the
                // combined distance.)
                let d_n = z_of(n) - self.correction.slm_offset_m;
                let coefficients = self.correction.profile.coefficients(d_n, c);
                let mut multiplier = pupil_multiplier(plan, &coefficients);
                let own_tf;
                let tf = match &to_midpoint_from_nearest {
                    Some(tf) => tf,
                    None => {
                        own_tf = prop.transfer_function(-z_of(last), Carrier::Keep)?;
                        &own_tf
                    }
                };
                for (m, t) in multiplier.iter_mut().zip(tf.values()) {
                    *m *= t;
                }
                plan.apply(&mut work, &multiplier, &mut scratch)?;
                for (a, v) in acc.iter_mut().zip(&work) {
                    *a += v;
                }
                tick();
            }
            Ok(())
        })?;
        Ok(out)
    }
}

impl SmLbm {
    /// This configuration with the aberration correction of Eq. 5 ([`AberrationCorrectedSmLbm`]).
    pub fn with_aberration(self, correction: AberrationCorrection) -> AberrationCorrectedSmLbm {
        AberrationCorrectedSmLbm {
            base: self,
            correction,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{Array2, Array3, Axis};
    use std::f64::consts::PI;

    fn sample_coefficients() -> ZernikeCoefficients {
        ZernikeCoefficients {
            focus: 1.0,
            astigmatism_vertical: 1.5,
            astigmatism_oblique: -0.8,
            coma_horizontal: 0.6,
            coma_vertical: -0.5,
        }
    }

    #[test]
    fn phase_is_the_sum_of_eq_14_to_18() {
        let k = sample_coefficients();
        for &(rho, theta) in &[(0.0, 0.0), (0.3, 1.1), (0.9, -2.5), (1.0, PI / 2.0)] {
            let expected = 1.0 * (2.0 * rho * rho - 1.0) + 1.5 * rho * rho * (2.0 * theta).cos()
                - 0.8 * rho * rho * (2.0 * theta).sin()
                + 0.6 * (3.0 * rho * rho - 2.0) * rho * theta.cos()
                - 0.5 * (3.0 * rho * rho - 2.0) * rho * theta.sin();
            assert!((k.phase(rho, theta) - expected).abs() < 1e-12);
        }
        assert_eq!((-k).phase(0.7, 0.3), -k.phase(0.7, 0.3));
    }

    fn two_point_profile() -> AberrationProfile {
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

    /// Normalised correlation |<a, b>| / (|a|·|b|) and mean absolute wrapped phase difference over `mask`.
    fn compare(a: &Array2<Complex32>, b: &Array2<Complex32>, mask: &Array2<bool>) -> (f64, f64) {
        let (mut dot, mut na, mut nb, mut dphi, mut n) =
            (num_complex::Complex64::default(), 0.0, 0.0, 0.0, 0.0);
        for ((x, y), m) in a.iter().zip(b).zip(mask) {
            if !m {
                continue;
            }
            let (x, y) = (
                num_complex::Complex64::new(x.re as f64, x.im as f64),
                num_complex::Complex64::new(y.re as f64, y.im as f64),
            );
            dot += x * y.conj();
            na += x.norm_sqr();
            nb += y.norm_sqr();
            dphi += (x * y.conj()).arg().abs();
            n += 1.0;
        }
        (dot.norm() / (na * nb).sqrt(), dphi / n)
    }

    #[test]
    fn eq_19_subhologram_route_agrees_with_the_frequency_domain_kernel() {
        let n = 128;
        let (p, lambda) = (8e-6, 520e-9);
        let k = sample_coefficients();
        let freq = amplitude_transfer_function(n, n, &k).unwrap();
        let inner = Array2::from_shape_fn((n, n), |(ky, kx)| {
            let s = |k: usize| crate::optics::fft::signed_index(k, n) as f64 * 2.0 / n as f64;
            s(kx).hypot(s(ky)) < 0.8
        });
        // Measured (128², 8 µm, 520 nm, these coefficients): correlation 0.923 / 0.945 / 0.964 / 0.967 /
        // 0.977 / 0.978 / 0.987 and mean |Δφ| 0.32 / 0.25 / 0.17 / 0.17 / 0.13 / 0.13 / 0.09 rad at
        // 3 / 4 / −4 / 6 / −6 / 8 / 12 mm: the stationary-phase residual, which falls as 1/|d|.
        for (d, min_corr, max_dphi) in [
            (3e-3, 0.91, 0.35),
            (4e-3, 0.93, 0.28),
            (-4e-3, 0.95, 0.2),
            (6e-3, 0.96, 0.2),
            (-6e-3, 0.97, 0.15),
            (12e-3, 0.98, 0.1),
        ] {
            let from_sub =
                amplitude_transfer_function_from_subhologram(n, n, p, lambda, d, &k).unwrap();
            let (corr, dphi) = compare(&from_sub, &freq, &inner);
            eprintln!("d = {d}: correlation {corr:.4}, mean |Δφ| {dphi:.3} rad");
            assert!(corr > min_corr && dphi < max_dphi, "d = {d}: {corr} {dphi}");
            // The opposite aberration is far off: the comparison can fail.
            let wrong = amplitude_transfer_function(n, n, &-k).unwrap();
            let (corr, _) = compare(&from_sub, &wrong, &inner);
            assert!(corr < 0.5, "d = {d}: {corr}");
        }
    }

    #[test]
    fn bad_subhologram_arguments_are_errors() {
        let k = ZernikeCoefficients::ZERO;
        assert!(corrected_subhologram(8, 8, 8e-6, 520e-9, 0.0, &k).is_err());
        assert!(corrected_subhologram(8, 8, 8e-6, 520e-9, f64::NAN, &k).is_err());
        assert!(corrected_subhologram(0, 8, 8e-6, 520e-9, 1e-3, &k).is_err());
        assert!(corrected_subhologram(8, 8, -8e-6, 520e-9, 1e-3, &k).is_err());
        assert!(corrected_subhologram(8, 8, 8e-6, 20e-6, 1e-3, &k).is_err());
    }

    /// Far amplitude, far depth, near amplitude, near depth, near validity.
    type Scene = (
        Array3<f32>,
        Array2<f32>,
        Array3<f32>,
        Array2<f32>,
        Array2<bool>,
    );

    /// The layers of [`scene`]: the near disc (amplitude `near`, depth `nd`, validity `disc`) in front of the
    /// far plane (amplitude `far`, depth `fd`).
    fn two_layers<'a>(
        near: &'a Array3<f32>,
        nd: &'a Array2<f32>,
        disc: &'a Array2<bool>,
        far: &'a Array3<f32>,
        fd: &'a Array2<f32>,
    ) -> [SceneLayer<'a>; 2] {
        [
            SceneLayer {
                amplitude: near.view(),
                depth: nd.view(),
                valid: Some(disc.view()),
            },
            SceneLayer {
                amplitude: far.view(),
                depth: fd.view(),
                valid: None,
            },
        ]
    }

    /// A small two-layer scene: a textured far plane and a nearer disc that hides part of it.
    fn scene(n: usize) -> Scene {
        let far_amp = Array3::from_shape_fn((3, n, n), |(c, y, x)| {
            0.5 + 0.4 * ((x as f32 * 0.7 + c as f32).sin() * (y as f32 * 0.45).cos())
        });
        let far_depth = Array2::from_elem((n, n), 0.8f32);
        let c = n as f32 / 2.0;
        let disc = Array2::from_shape_fn((n, n), |(y, x)| {
            (x as f32 - c).hypot(y as f32 - c) < n as f32 / 4.0
        });
        let near_amp =
            Array3::from_shape_fn((3, n, n), |(c, y, x)| 0.3 + 0.1 * ((x + y + c) % 3) as f32);
        let near_depth = Array2::from_elem((n, n), 0.2f32);
        (far_amp, far_depth, near_amp, near_depth, disc)
    }

    fn base(levels: usize) -> SmLbm {
        SmLbm {
            levels,
            ..SmLbm::default()
        }
    }

    fn max_abs_diff(a: &Array3<Complex32>, b: &Array3<Complex32>) -> (f32, f32) {
        let d = a
            .iter()
            .zip(b)
            .map(|(x, y)| (x - y).norm())
            .fold(0.0, f32::max);
        let m = b.iter().map(|v| v.norm()).fold(0.0, f32::max);
        (d, m)
    }

    /// `field` with Φ of `coefficients` applied per colour (unpadded plan).
    fn apply_kernel(
        field: &Array3<Complex32>,
        coefficients: [ZernikeCoefficients; 3],
    ) -> Array3<Complex32> {
        let (_, h, w) = field.dim();
        let plan = SpectralPlan::new(h, w, crate::optics::Padding::None).unwrap();
        let mut out = field.clone();
        for (c, mut lane) in out.axis_iter_mut(Axis(0)).enumerate() {
            let norm = 1.0 / plan.spectrum_len() as f32;
            let m: Vec<Complex32> = pupil_multiplier(&plan, &coefficients[c])
                .into_iter()
                .map(|v| v * norm)
                .collect();
            plan.apply(lane.as_slice_mut().unwrap(), &m, &mut plan.scratch())
                .unwrap();
        }
        out
    }

    #[test]
    fn zero_coefficients_give_plain_sm_lbm_band_limited_to_the_pupil() {
        let n = 48;
        let (fa, fd, na, nd, disc) = scene(n);
        let layers = two_layers(&na, &nd, &disc, &fa, &fd);
        let sm = base(16);
        let plain = apply_kernel(
            &sm.synthesize(&layers, &|_, _| {}).unwrap(),
            [ZernikeCoefficients::ZERO; 3],
        );
        let corrected = sm.with_aberration(AberrationCorrection {
            profile: AberrationProfile::uniform(ZernikeCoefficients::ZERO),
            slm_offset_m: 6e-3,
        });
        assert_eq!(corrected.propagation_count(&layers).unwrap(), 3);
        let calls = AtomicU64::new(0);
        let out = corrected
            .synthesize(&layers, &|done, total| {
                calls.fetch_add(1, Ordering::Relaxed);
                assert!(done <= total && total == 9);
            })
            .unwrap();
        assert_eq!(calls.load(Ordering::Relaxed), 9);
        let (d, m) = max_abs_diff(&out, &plain);
        assert!(d < 1e-5 * m, "max difference {d} of max {m}");
        // Band-limited indeed: differs from the unfiltered SM-LBM.
        let (d, m) = max_abs_diff(&out, &sm.synthesize(&layers, &|_, _| {}).unwrap());
        assert!(d > 1e-3 * m);
    }

    #[test]
    fn each_plane_gets_the_kernel_of_its_own_distance_after_occlusion() {
        // Eq. 5 by superposition: the far plane's occluded content with Φ(d_far) plus the near plane's content
        // with Φ(d_near). An occluder without content is a valid point of amplitude 0 (SmLbm's Eq. 3 rule).
        let n = 48;
        let (fa, fd, na, nd, disc) = scene(n);
        let zero_near = Array3::<f32>::zeros((3, n, n));
        let zero_far = Array3::<f32>::zeros((3, n, n));
        let layers = |near: &Array3<f32>, far: &Array3<f32>| -> Vec<Array3<f32>> {
            vec![near.clone(), far.clone()]
        };
        let make = |amps: &[Array3<f32>]| -> Array3<Complex32> {
            let ls = two_layers(&amps[0], &nd, &disc, &amps[1], &fd);
            base(11).synthesize(&ls, &|_, _| {}).unwrap()
        };
        let s = 2e-3;
        let setup = OpticalSetup::default();
        let (z_near, z_far) = (setup.depth_to_z(0.2), setup.depth_to_z(0.8));
        let profile = two_point_profile();
        let k_of = |z: f64| std::array::from_fn(|c| profile.coefficients(z - s, c));
        let expected = apply_kernel(&make(&layers(&zero_near, &fa)), k_of(z_far))
            + apply_kernel(&make(&layers(&na, &zero_far)), k_of(z_near));
        let ls = two_layers(&na, &nd, &disc, &fa, &fd);
        let out = base(11)
            .with_aberration(AberrationCorrection {
                profile: profile.clone(),
                slm_offset_m: s,
            })
            .synthesize(&ls, &|_, _| {})
            .unwrap();
        let (d, m) = max_abs_diff(&out, &expected);
        assert!(d < 1e-5 * m, "max difference {d} of max {m}");
        // The kernels differ per plane: one kernel for both is measurably different.
        let one = apply_kernel(&make(&layers(&na, &fa)), k_of(z_near));
        let (d, m) = max_abs_diff(&out, &one);
        assert!(d > 1e-2 * m, "{d} vs {m}");
    }

    #[test]
    fn without_masks_planes_are_independent_and_cost_one_propagation_each() {
        let n = 32;
        let (fa, fd, na, nd, disc) = scene(n);
        let ls = two_layers(&na, &nd, &disc, &fa, &fd);
        let sm = SmLbm {
            silhouette_masks: false,
            ..base(9)
        };
        let plain = apply_kernel(
            &sm.synthesize(&ls, &|_, _| {}).unwrap(),
            [ZernikeCoefficients::ZERO; 3],
        );
        let c = sm.with_aberration(AberrationCorrection {
            profile: AberrationProfile::uniform(ZernikeCoefficients::ZERO),
            slm_offset_m: 0.0,
        });
        assert_eq!(c.propagation_count(&ls).unwrap(), 2);
        let (d, m) = max_abs_diff(&c.synthesize(&ls, &|_, _| {}).unwrap(), &plain);
        assert!(d < 1e-5 * m, "{d} {m}");
    }

    #[test]
    fn propagation_counts_grow_as_g_squared_over_two() {
        let c = base(2048).with_aberration(AberrationCorrection {
            profile: AberrationProfile::uniform(ZernikeCoefficients::ZERO),
            slm_offset_m: 0.0,
        });
        assert_eq!(c.propagations_for(1), 1);
        assert_eq!(c.propagations_for(4), 10);
        assert_eq!(c.worst_case_propagation_count(), 2048 * 2049 / 2);
        assert_eq!(c.propagations_for(usize::MAX), usize::MAX / 2);
    }

    #[test]
    fn a_profile_for_another_display_or_a_bad_offset_is_refused() {
        let (fa, fd, ..) = scene(16);
        let ls = [SceneLayer {
            amplitude: fa.view(),
            depth: fd.view(),
            valid: None,
        }];
        let c = base(4).with_aberration(AberrationCorrection {
            profile: AberrationProfile::uniform(ZernikeCoefficients::ZERO)
                .with_display([640e-9, 520e-9, 450e-9], 8e-6),
            slm_offset_m: 0.0,
        });
        assert!(matches!(
            c.synthesize(&ls, &|_, _| {}),
            Err(HoloError::InvalidParameter {
                name: "wavelengths_m",
                ..
            })
        ));
        let c = base(4).with_aberration(AberrationCorrection {
            profile: AberrationProfile::uniform(ZernikeCoefficients::ZERO),
            slm_offset_m: f64::INFINITY,
        });
        assert!(c.synthesize(&ls, &|_, _| {}).is_err());
    }
}

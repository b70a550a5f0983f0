//! A viewer's spectacle prescription ([`Prescription`]: sphere and cylinder in dioptres, axis in degrees, the
//! ophthalmic convention) and the Zernike coefficients that correct it for a viewer behind the display's
//! eyepiece (`docs/ABERRATION.md`, "A viewer's prescription").
//!
//! **Viewer model.** The eyepiece (focal length `f_e`, the paper's 21 mm by default) puts the Fourier plane of
//! hologram space at its exit pupil, where the viewer's eye sits: a hologram frequency `f` crosses the pupil at
//! `r = λ·f_e·f`. A thin spectacle lens of power `P` (dioptres) there adds `−π·P·|r|²/λ = −π·λ·f_e²·P·|f|²`.
//! The prescription's lens has power `S` in every meridian plus `C` across its axis, so its pupil phase is
//! `−k·ρ²·(S + C·sin²(θ − θ_axis))` with `ρ = |f|/f_N`, `f_N = 1/(2p)` and `k = π·λ·f_e²·f_N²`. The display
//! shows the hologram as the lens would let the eye see it: it applies the lens's phase, which in Zernike terms
//! (Eq. 14–16, the piston dropped) is
//!
//! - `focus = −k·(S + C/2)/2`,
//! - `astigmatism_vertical = +k·C/2·cos 2θ_axis`,
//! - `astigmatism_oblique = +k·C/2·sin 2θ_axis`.
//!
//! **Signs.** A myope's sphere is negative (a diverging lens), as on a spectacle prescription. The axis is the
//! ophthalmic one: degrees from the image's horizontal, counterclockwise as the viewer sees the image (0–180°).
//! The SDK's frequency `fy` runs along rows, downward, so `θ_axis = −axis`: `sin 2θ_axis = −sin 2·axis`.
//! Without a mirror in the display's optics the viewer sees the SLM image upright; with one, give
//! `180° − axis`. `sdk/tests/aberration_realtime.rs` fails when any of these signs flips.

use serde::{Deserialize, Serialize};

use crate::error::{invalid, Result};

/// Focal length of the paper's eyepiece (metres): the default viewer model.
pub const DEFAULT_EYEPIECE_FOCAL_M: f64 = 21e-3;

/// The largest sphere a prescription may give, dioptres (either sign).
pub const MAX_SPHERE_D: f64 = 20.0;

/// The largest cylinder a prescription may give, dioptres (either sign).
pub const MAX_CYLINDER_D: f64 = 10.0;

/// Eyepiece focal lengths accepted, metres.
pub const EYEPIECE_FOCAL_RANGE_M: (f64, f64) = (1e-3, 1.0);

/// A viewer's spectacle prescription and the eyepiece the viewer looks through (see the module docs).
///
/// In JSON (a display profile's `prescription`): `{"sphere_d": -2.0, "cylinder_d": -1.0, "axis_deg": 30}`,
/// `eyepiece_focal_m` optional (21 mm), unknown keys refused.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Prescription {
    /// Sphere `S`, dioptres (negative for a myope), at most [`MAX_SPHERE_D`] in magnitude.
    pub sphere_d: f64,
    /// Cylinder `C`, dioptres (either sign), at most [`MAX_CYLINDER_D`] in magnitude; 0 without astigmatism.
    #[serde(default)]
    pub cylinder_d: f64,
    /// The cylinder's axis, degrees in `[0, 180]`, counterclockwise from the horizontal as the viewer sees
    /// the image; required with a cylinder.
    #[serde(default)]
    pub axis_deg: Option<f64>,
    /// The eyepiece's focal length `f_e`, metres (default [`DEFAULT_EYEPIECE_FOCAL_M`]).
    #[serde(default = "default_eyepiece")]
    pub eyepiece_focal_m: f64,
}

fn default_eyepiece() -> f64 {
    DEFAULT_EYEPIECE_FOCAL_M
}

impl Prescription {
    /// A prescription behind the paper's 21 mm eyepiece, checked ([`Prescription::validate`]).
    ///
    /// Errors: as [`Prescription::validate`].
    pub fn new(sphere_d: f64, cylinder_d: f64, axis_deg: Option<f64>) -> Result<Self> {
        let p = Self {
            sphere_d,
            cylinder_d,
            axis_deg,
            eyepiece_focal_m: DEFAULT_EYEPIECE_FOCAL_M,
        };
        p.validate()?;
        Ok(p)
    }

    /// Checks the values.
    ///
    /// Errors: [`crate::HoloError::InvalidParameter`] naming the field: `sphere_d` or `cylinder_d` not finite
    /// or above [`MAX_SPHERE_D`] / [`MAX_CYLINDER_D`] in magnitude; `axis_deg` missing with a cylinder,
    /// not finite or outside 0–180°; `eyepiece_focal_m` outside [`EYEPIECE_FOCAL_RANGE_M`].
    pub fn validate(&self) -> Result<()> {
        let bounded = |name: &'static str, x: f64, max: f64| {
            if !(x.is_finite() && x.abs() <= max) {
                return Err(invalid(
                    name,
                    format!("must be a finite number of dioptres within ±{max}, got {x}"),
                ));
            }
            Ok(())
        };
        bounded("sphere_d", self.sphere_d, MAX_SPHERE_D)?;
        bounded("cylinder_d", self.cylinder_d, MAX_CYLINDER_D)?;
        match self.axis_deg {
            None if self.cylinder_d != 0.0 => {
                return Err(invalid(
                    "axis_deg",
                    format!(
                        "a cylinder ({} D) needs its axis, degrees 0–180 counterclockwise from the \
                         horizontal as the viewer sees the image",
                        self.cylinder_d
                    ),
                ))
            }
            Some(a) if !(0.0..=180.0).contains(&a) => {
                return Err(invalid(
                    "axis_deg",
                    format!("must be within 0–180°, got {a}"),
                ))
            }
            _ => {}
        }
        let (lo, hi) = EYEPIECE_FOCAL_RANGE_M;
        if !(lo..=hi).contains(&self.eyepiece_focal_m) {
            return Err(invalid(
                "eyepiece_focal_m",
                format!(
                    "must be within {lo}–{hi} m, got {} (metres, not millimetres)",
                    self.eyepiece_focal_m
                ),
            ));
        }
        Ok(())
    }

    /// The Zernike coefficients `[a3, a4, a5, a6, a7]` (focus, vertical and oblique astigmatism, the two
    /// comas: radians at the pupil edge, Eq. 14–18) that apply this prescription's lens for wavelength
    /// `wavelength_m` on an SLM of pitch `pixel_pitch_m` (metres; see the module docs for the formula).
    pub(crate) fn zernike(&self, wavelength_m: f64, pixel_pitch_m: f64) -> [f64; 5] {
        let f_n = 1.0 / (2.0 * pixel_pitch_m);
        let k = std::f64::consts::PI
            * wavelength_m
            * self.eyepiece_focal_m
            * self.eyepiece_focal_m
            * f_n
            * f_n;
        // θ_axis = −axis: the image's up is −fy.
        let two_theta = -2.0 * self.axis_deg.unwrap_or(0.0).to_radians();
        let half_c = k * self.cylinder_d / 2.0;
        [
            -k * (self.sphere_d + self.cylinder_d / 2.0) / 2.0,
            half_c * two_theta.cos(),
            half_c * two_theta.sin(),
            0.0,
            0.0,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::HoloError;

    fn name(e: HoloError) -> &'static str {
        match e {
            HoloError::InvalidParameter { name, .. } => name,
            other => panic!("{other}"),
        }
    }

    #[test]
    fn bad_prescriptions_are_refused_naming_the_field() {
        assert_eq!(
            name(Prescription::new(-21.0, 0.0, None).unwrap_err()),
            "sphere_d"
        );
        assert_eq!(
            name(Prescription::new(f64::NAN, 0.0, None).unwrap_err()),
            "sphere_d"
        );
        assert_eq!(
            name(Prescription::new(0.0, 11.0, Some(10.0)).unwrap_err()),
            "cylinder_d"
        );
        assert_eq!(
            name(Prescription::new(-2.0, -1.0, None).unwrap_err()),
            "axis_deg"
        );
        assert_eq!(
            name(Prescription::new(-2.0, -1.0, Some(181.0)).unwrap_err()),
            "axis_deg"
        );
        assert_eq!(
            name(Prescription::new(-2.0, -1.0, Some(-5.0)).unwrap_err()),
            "axis_deg"
        );
        let mut p = Prescription::new(-2.0, 0.0, None).unwrap();
        p.eyepiece_focal_m = 21.0;
        assert_eq!(name(p.validate().unwrap_err()), "eyepiece_focal_m");
        let json: std::result::Result<Prescription, _> =
            serde_json::from_str(r#"{"sphere_d": -2, "cyl": -1}"#);
        assert!(json.unwrap_err().to_string().contains("cyl"));
    }

    #[test]
    fn a_sphere_is_focus_and_a_cylinder_splits_into_focus_and_astigmatism() {
        let (lambda, pitch) = (520e-9, 8e-6);
        let k = std::f64::consts::PI * lambda * 21e-3 * 21e-3 / (4.0 * pitch * pitch);
        // −1 D of sphere: focus +k/2 (a diverging lens), no astigmatism.
        let z = Prescription::new(-1.0, 0.0, None)
            .unwrap()
            .zernike(lambda, pitch);
        assert!((z[0] - k / 2.0).abs() < 1e-12 && z[1] == 0.0 && z[2] == 0.0);
        // +2 D of cylinder at 90°: power across the axis, along the image's x: −k·ρ²·cos²θ·2.
        let z = Prescription::new(0.0, 2.0, Some(90.0))
            .unwrap()
            .zernike(lambda, pitch);
        assert!((z[0] + k / 2.0).abs() < 1e-12);
        assert!((z[1] + k).abs() < 1e-12 && z[2].abs() < 1e-12);
        // At 45° counterclockwise as seen (image up = −fy): the oblique term is −k·C/2.
        let z = Prescription::new(0.0, 2.0, Some(45.0))
            .unwrap()
            .zernike(lambda, pitch);
        assert!(z[1].abs() < 1e-12 && (z[2] + k).abs() < 1e-12);
    }
}

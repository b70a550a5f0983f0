//! [`Foveation`] and [`Gaze`]: gaze-contingent holograms (`docs/FOVEATION.md`) as records: the 3D CNN where
//! the viewer looks, the paper's 2D hologram with synthetic blur elsewhere.

use tensorholo::display::DEFAULT_EYEPIECE_FOCAL_M;
use tensorholo::foveation::{FoveaRadius, FoveationOptions};

/// How a generator foveates its frames ([`HologramGenerator::render_foveated`](crate::HologramGenerator::render_foveated);
/// `docs/FOVEATION.md`). The defaults: a 5° fovea behind the paper's 21 mm eyepiece (about 230 pixels of an
/// 8 µm SLM), a 16-pixel blend band, the periphery blurred by a quarter of the diffraction cone's defocus.
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct Foveation {
    /// The fovea's radius in degrees of visual angle (eccentricity) behind the eyepiece, `0 ≤ R < 90`
    /// (default 5); not read when `radius_px` is given.
    #[uniffi(default = 5.0)]
    pub radius_deg: f64,
    /// The eyepiece's focal length in metres (default 0.021, the paper's): `R_px = f·tan(R)/p`.
    #[uniffi(default = 0.021)]
    pub eyepiece_focal_m: f64,
    /// The fovea's radius in hologram pixels instead (≥ 0); `None` (default): `radius_deg`.
    #[uniffi(default = None)]
    pub radius_px: Option<f64>,
    /// The blend band's width in pixels outside the fovea (≥ 1, default 16).
    #[uniffi(default = 16.0)]
    pub band_px: f64,
    /// The periphery's blur scale κ, a fraction of the λ/(2p) diffraction cone's defocus (≥ 0, default
    /// 0.25; 0: no blur).
    #[uniffi(default = 0.25)]
    pub blur_scale: f64,
}

impl Default for Foveation {
    fn default() -> Self {
        FoveationOptions::default().into()
    }
}

impl From<Foveation> for FoveationOptions {
    fn from(f: Foveation) -> Self {
        Self {
            radius: match f.radius_px {
                Some(pixels) => FoveaRadius::Pixels { pixels },
                None => FoveaRadius::Degrees {
                    degrees: f.radius_deg,
                    eyepiece_focal_m: f.eyepiece_focal_m,
                },
            },
            band_px: f.band_px,
            blur_scale: f.blur_scale,
        }
    }
}

impl From<FoveationOptions> for Foveation {
    fn from(o: FoveationOptions) -> Self {
        let (radius_deg, eyepiece_focal_m, radius_px) = match o.radius {
            FoveaRadius::Degrees {
                degrees,
                eyepiece_focal_m,
            } => (degrees, eyepiece_focal_m, None),
            FoveaRadius::Pixels { pixels } => (5.0, DEFAULT_EYEPIECE_FOCAL_M, Some(pixels)),
        };
        Self {
            radius_deg,
            eyepiece_focal_m,
            radius_px,
            band_px: o.band_px,
            blur_scale: o.blur_scale,
        }
    }
}

/// Where the viewer looks, for one frame: a point of the hologram in pixels of its `width × height` (after
/// the camera frame's fit; `(0, 0)` the top-left pixel's centre, x right, y down), and the eye tracker's
/// vergence depth in metres where it has one. An iOS app maps ARKit's `lookAtPoint` or a touch point to the
/// hologram's pixels; an OpenXR app its eye-gaze pose (`docs/FOVEATION.md`, "Passing the gaze").
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct Gaze {
    /// Column, pixels (`-0.5 ≤ x ≤ width − 0.5`).
    pub x: f64,
    /// Row, pixels (`-0.5 ≤ y ≤ height − 0.5`).
    pub y: f64,
    /// The depth the viewer focuses at: the signed distance in metres from the midpoint hologram's plane,
    /// positive towards the viewer (the volume's near end at `+volume_depth_m/2`; beyond it, its nearer end).
    /// `None` (default): the scene's depth at the gaze point (the median of a 17 × 17 window).
    #[uniffi(default = None)]
    pub depth_m: Option<f64>,
}

impl From<Gaze> for tensorholo::foveation::Gaze {
    fn from(g: Gaze) -> Self {
        Self {
            x: g.x,
            y: g.y,
            depth_m: g.depth_m,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tensorholo::foveation::{DEFAULT_BAND_PX, DEFAULT_BLUR_SCALE};

    #[test]
    fn the_records_defaults_are_the_cores_and_round_trip() {
        let core = FoveationOptions::default();
        let record = Foveation::default();
        assert_eq!(
            (record.band_px, record.blur_scale, record.radius_px),
            (DEFAULT_BAND_PX, DEFAULT_BLUR_SCALE, None)
        );
        assert_eq!(FoveationOptions::from(record), core);
        let pixels = Foveation {
            radius_px: Some(90.0),
            ..record
        };
        assert_eq!(
            FoveationOptions::from(pixels).radius,
            FoveaRadius::Pixels { pixels: 90.0 }
        );
        assert_eq!(Foveation::from(FoveationOptions::from(pixels)), pixels);
    }
}

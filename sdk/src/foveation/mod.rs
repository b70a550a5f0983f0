//! Gaze-contingent (foveated) holograms: the 3D hologram CNN only where the viewer looks, a 2D hologram with
//! synthetic blur elsewhere — the paper's "foveation-guided holographic rendering" (Discussion), made exact
//! inside the fovea (`docs/FOVEATION.md`).
//!
//! A frame is split by its distance `r` (pixels) from the gaze point:
//!
//! - **fovea**, `r ≤ R`: the hologram CNN's midpoint hologram, exactly the full frame's. The CNN runs on a tile
//!   centred on the gaze, of the fovea, its blend band and a margin of the CNN's receptive field (one pixel a
//!   3 × 3 convolution: a tile's pixels further than that from its edge are computed as in the whole frame);
//! - **band**, `R < r < R + B`: a linear blend `w·U_cnn + (1 − w)·U_2D` with `w = (R + B − r)/B`;
//! - **periphery**, `r ≥ R + B`: the paper's 2D hologram with synthetic blur: the colour image's amplitude,
//!   blurred per pixel by a square of the area of a disc of radius
//!   `κ·|d − d_g|·V·λ/(2p²)` pixels (`d` the pixel's normalised depth, `d_g` the gaze's, `V` the volume
//!   depth, `λ` the colour's wavelength, `p` the pixel pitch; `κ = 1` would be the `λ/(2p)` diffraction cone),
//!   placed at the midpoint plane with one constant phase per colour: the phase that best aligns the CNN's
//!   field in the band with the image's amplitude there (`arg Σ_band U_cnn·A`), so that the blend has no dark
//!   ring.
//!
//! The rest of the frame (offset propagation, pre-filter, double phase encoding) runs on the composed
//! midpoint hologram as on a full frame. The double phase normaliser follows a rule that does not depend on
//! the gaze ([`FOVEATED_NORMALISER_GAIN`]): the display's brightness does not jump when the eyes move.
//!
//! Geometry: behind an eyepiece of focal length `f`, an SLM pixel of pitch `p` subtends `p/f` radians at the
//! centre of the view, so a fovea of `R` degrees is `R_px = f·tan(R)/p` pixels (5° behind the paper's 21 mm
//! eyepiece on an 8 µm SLM: 229 pixels).

mod gaze;
mod geometry;
mod periphery;

pub use gaze::{Gaze, GAZE_DEPTH_WINDOW_PX};

pub(crate) use geometry::TileGeometry;
/// The GPU's foveated frame clamps its blur as the CPU's periphery does.
#[cfg(feature = "gpu")]
pub(crate) use periphery::half_width;
pub(crate) use periphery::{gaze_depth, row_span, ColourInputs, FrameInputs, Periphery};

use crate::display::{DEFAULT_EYEPIECE_FOCAL_M, EYEPIECE_FOCAL_RANGE_M};
use crate::error::{invalid, Result};

/// The blur scale `κ` of the periphery's synthetic blur by default: the fraction of the `λ/(2p)` diffraction
/// cone's defocus that matches the CNN's own (smooth-phase) defocus (`docs/FOVEATION.md`, "The periphery").
pub const DEFAULT_BLUR_SCALE: f64 = 0.25;

/// The blend band's width by default, pixels (`docs/FOVEATION.md`, "The seam").
pub const DEFAULT_BAND_PX: f64 = 16.0;

/// The double phase normaliser of a foveated frame, as a multiple of the frame's largest amplitude (over the
/// three colours, after a calibration's intensity maps): `a = gain · max A`. The full frame's normaliser is the
/// largest `|H|` of the field at the SLM, which depends on the CNN's field everywhere; a foveated frame's
/// field holds the CNN's only in the fovea, and its own largest `|H|` would follow the gaze (the whole display
/// brightening by 8–39 % as the fovea moves off a bright region). This rule reads the frame alone: two gazes
/// on one frame give the same normaliser, bit for bit. The gain is the largest ratio of the full frame's
/// normaliser to `max A` measured on the real frames of the tests (`docs/FOVEATION.md`, "The normaliser"), so
/// the fovea clips no more than a bright full frame would.
pub const FOVEATED_NORMALISER_GAIN: f32 = 1.25;

/// The size of the fovea: an angle of view behind the display's eyepiece, or pixels of the SLM.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(tag = "unit", rename_all = "kebab-case")]
pub enum FoveaRadius {
    /// Degrees of visual angle (eccentricity) seen through an eyepiece of focal length `eyepiece_focal_m`
    /// (metres): `R_px = f·tan(R)/p`.
    Degrees {
        /// Eccentricity of the fovea's edge, degrees (`0 ≤ R < 90`).
        degrees: f64,
        /// The eyepiece's focal length, metres (the paper's 21 mm: [`DEFAULT_EYEPIECE_FOCAL_M`]).
        eyepiece_focal_m: f64,
    },
    /// The radius in SLM pixels (`≥ 0`).
    Pixels {
        /// Radius, pixels.
        pixels: f64,
    },
}

/// How a session foveates its frames ([`crate::pipeline::PipelineConfig::foveation`];
/// [`crate::pipeline::HologramSession::render_foveated`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct FoveationOptions {
    /// The fovea's radius `R` (default 5° behind the paper's 21 mm eyepiece).
    pub radius: FoveaRadius,
    /// The blend band's width `B` in pixels, outside the fovea (from `R` to `R + B`; default
    /// [`DEFAULT_BAND_PX`], `≥ 1`): narrower bands let the periphery's light reach into the fovea.
    pub band_px: f64,
    /// The periphery's blur scale `κ` (default [`DEFAULT_BLUR_SCALE`], `≥ 0`; 0: no blur).
    pub blur_scale: f64,
}

impl Default for FoveationOptions {
    fn default() -> Self {
        Self {
            radius: FoveaRadius::Degrees {
                degrees: 5.0,
                eyepiece_focal_m: DEFAULT_EYEPIECE_FOCAL_M,
            },
            band_px: DEFAULT_BAND_PX,
            blur_scale: DEFAULT_BLUR_SCALE,
        }
    }
}

impl FoveationOptions {
    /// Checks the options (a session checks them when it is made).
    ///
    /// Errors: [`crate::HoloError::InvalidParameter`] naming `fovea_radius` (negative, not finite, 90° or
    /// more), `eyepiece_focal_m` (outside [`EYEPIECE_FOCAL_RANGE_M`]), `band_px` (under 1 or not finite) or
    /// `blur_scale` (negative or not finite).
    pub fn check(&self) -> Result<()> {
        if !(self.band_px.is_finite() && self.band_px >= 1.0) {
            return Err(invalid(
                "band_px",
                format!(
                    "the blend band must be at least 1 pixel wide (16 by default), got {}",
                    self.band_px
                ),
            ));
        }
        if !(self.blur_scale.is_finite() && self.blur_scale >= 0.0) {
            return Err(invalid(
                "blur_scale",
                format!("must be finite and ≥ 0, got {}", self.blur_scale),
            ));
        }
        match self.radius {
            FoveaRadius::Pixels { pixels } => {
                if !(pixels.is_finite() && pixels >= 0.0) {
                    return Err(invalid(
                        "fovea_radius",
                        format!(
                            "the fovea's radius in pixels must be finite and ≥ 0, got {pixels}"
                        ),
                    ));
                }
                Ok(())
            }
            FoveaRadius::Degrees {
                degrees,
                eyepiece_focal_m,
            } => {
                if !(degrees.is_finite() && (0.0..90.0).contains(&degrees)) {
                    return Err(invalid(
                        "fovea_radius",
                        format!("the fovea's radius in degrees must lie in [0, 90), got {degrees}"),
                    ));
                }
                let (lo, hi) = EYEPIECE_FOCAL_RANGE_M;
                if !(lo..=hi).contains(&eyepiece_focal_m) {
                    return Err(invalid(
                        "eyepiece_focal_m",
                        format!(
                            "the eyepiece's focal length must lie in [{lo}, {hi}] m, got {eyepiece_focal_m}"
                        ),
                    ));
                }
                Ok(())
            }
        }
    }

    /// The fovea's radius in pixels on an SLM of pitch `pixel_pitch_m` (metres), and in degrees where the
    /// options give an angle. Errors: as [`FoveationOptions::check`].
    pub(crate) fn radius_px(&self, pixel_pitch_m: f64) -> Result<(f64, Option<f64>)> {
        self.check()?;
        Ok(match self.radius {
            FoveaRadius::Pixels { pixels } => (pixels, None),
            FoveaRadius::Degrees {
                degrees,
                eyepiece_focal_m,
            } => (
                eyepiece_focal_m * degrees.to_radians().tan() / pixel_pitch_m,
                Some(degrees),
            ),
        })
    }
}

/// How the gaze's depth of a foveated frame was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum GazeDepthSource {
    /// Given with the gaze ([`Gaze::depth_m`]).
    Given,
    /// The median depth of the window around the gaze point ([`GAZE_DEPTH_WINDOW_PX`]).
    Scene,
}

/// What the last foveated frame did ([`crate::pipeline::HologramSession::fovea_report`]; report.json's
/// `fovea` section).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct FoveaReport {
    /// The gaze as given.
    pub gaze: Gaze,
    /// The gaze's normalised depth `d_g ∈ [0, 1]` (0 = near) the periphery is sharp at.
    pub gaze_depth: f64,
    /// Where `gaze_depth` came from.
    pub gaze_depth_source: GazeDepthSource,
    /// The fovea's radius `R`, pixels.
    pub radius_px: f64,
    /// The fovea's radius in degrees, where the options give an angle.
    pub radius_deg: Option<f64>,
    /// The blend band's width `B`, pixels.
    pub band_px: f64,
    /// The hologram CNN's receptive radius (pixels): the tile's margin beyond the band.
    pub cnn_margin_px: usize,
    /// The hologram CNN's tile `[y, x, height, width]` (pixels; the same size for every gaze, placed inside
    /// the frame).
    pub tile: [usize; 4],
    /// The share of the frame's pixels the hologram CNN ran on (`1` where the fovea covers the frame).
    pub cnn_share: f64,
    /// Whether the frame was rendered in full, as [`crate::pipeline::HologramSession::render`] renders it: the
    /// fovea covered the whole frame, or the hologram CNN's tile is the whole frame (nothing to save).
    pub covers_frame: bool,
    /// The constant phase of each colour's periphery (radians): the band's phase.
    pub periphery_phase_rad: [f32; 3],
}

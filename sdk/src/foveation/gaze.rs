//! [`Gaze`]: where the viewer looks in one frame, and the window of the scene's depth at the gaze point.

use crate::error::{invalid, Result};

/// Where the viewer looks in one frame ([`crate::pipeline::HologramSession::render_foveated`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Gaze {
    /// Column of the gaze point on the output frame, pixels: 0 is the centre of the leftmost pixel, x runs
    /// right; `[−0.5, W − 0.5]` (the frame's area).
    pub x: f64,
    /// Row of the gaze point, pixels: 0 is the centre of the top pixel, y runs down; `[−0.5, H − 0.5]`.
    pub y: f64,
    /// The depth the viewer focuses at (an eye tracker's vergence, brought into hologram space): the signed
    /// distance in metres from the midpoint plane, positive towards the viewer, as the focal planes of
    /// `docs/CONVENTIONS.md` §4 (`z(d) = (0.5 − d)·V`: the near end of the volume at `+V/2`); depths beyond
    /// the volume are taken at its nearer end. `None`: the scene's depth at the gaze point, the median
    /// normalised depth of the pixels within [`GAZE_DEPTH_WINDOW_PX`] of it (robust to an edge under the
    /// gaze and to a few invalid pixels).
    pub depth_m: Option<f64>,
}

/// Half-width in pixels of the square window whose median depth is the gaze's depth when the gaze gives
/// none ([`Gaze::depth_m`]): a 17 × 17 window, 0.15° behind the 21 mm eyepiece, about the eye's fixation
/// error.
pub const GAZE_DEPTH_WINDOW_PX: usize = 8;

impl Gaze {
    /// Checks the gaze against a `height × width` frame (as
    /// [`crate::pipeline::HologramSession::render_foveated`] does before anything else).
    ///
    /// Errors: [`crate::HoloError::InvalidParameter`] naming `gaze` (a coordinate not finite or outside the
    /// frame) or `gaze_depth_m` (not finite).
    pub fn check(&self, height: usize, width: usize) -> Result<()> {
        for (name, v, n) in [("x", self.x, width), ("y", self.y, height)] {
            if !v.is_finite() {
                return Err(invalid(
                    "gaze",
                    format!("the gaze's {name} must be finite, got {v}"),
                ));
            }
            if v < -0.5 || v > n as f64 - 0.5 {
                return Err(invalid(
                    "gaze",
                    format!(
                        "the gaze's {name} = {v} lies outside the frame ({} pixels: −0.5 to {})",
                        n,
                        n as f64 - 0.5
                    ),
                ));
            }
        }
        if let Some(d) = self.depth_m {
            if !d.is_finite() {
                return Err(invalid(
                    "gaze_depth_m",
                    format!("the gaze's depth must be finite metres, got {d}"),
                ));
            }
        }
        Ok(())
    }
}

//! [`OpticalSetup`]: the display's geometry (wavelengths, pixel pitch, volume depth), its valid ranges and
//! the checks of an SLM offset.

use super::propagation::{check_positive, PropagationOptions, Propagator};
use crate::error::{invalid, Result};

/// The display geometry of `docs/CONVENTIONS.md` §3: laser wavelengths, SLM pixel pitch and the depth of the
/// 3D volume centred on the midpoint hologram. `Default` is the paper's setup (638/520/450 nm, 8 µm, 6 mm).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct OpticalSetup {
    /// Wavelengths in metres of the R, G, B lasers.
    pub wavelengths_m: [f64; 3],
    /// SLM pixel pitch in metres.
    pub pixel_pitch_m: f64,
    /// Depth of the 3D volume in metres; normalised depth `d ∈ [0,1]` spans it, centred on the midpoint plane.
    pub volume_depth_m: f64,
}

impl Default for OpticalSetup {
    fn default() -> Self {
        Self {
            wavelengths_m: [638e-9, 520e-9, 450e-9],
            pixel_pitch_m: 8e-6,
            volume_depth_m: 6e-3,
        }
    }
}

impl OpticalSetup {
    /// Checks every field is finite, positive and within the physical bounds of a holographic display
    /// ([`PITCH_RANGE_M`], [`WAVELENGTH_RANGE_M`], [`MAX_VOLUME_DEPTH_M`]): a subnormal or astronomic value
    /// is a typo, and would make every product of it (depth scales, transfer functions) overflow or vanish.
    ///
    /// Errors: [`HoloError::InvalidParameter`](crate::HoloError::InvalidParameter) naming the offending field and its bounds.
    pub fn validate(&self) -> Result<()> {
        for w in self.wavelengths_m {
            check_positive("wavelength_m", w)?;
            check_within("wavelength_m", w, WAVELENGTH_RANGE_M, "m")?;
        }
        check_positive("pixel_pitch_m", self.pixel_pitch_m)?;
        check_within("pixel_pitch_m", self.pixel_pitch_m, PITCH_RANGE_M, "m")?;
        check_positive("volume_depth_m", self.volume_depth_m)?;
        check_within(
            "volume_depth_m",
            self.volume_depth_m,
            (0.0, MAX_VOLUME_DEPTH_M),
            "m",
        )
    }

    /// Axial position in metres, relative to the midpoint plane, of normalised depth `d` (0 = near):
    /// `z(d) = (0.5 − d) · volume_depth` (`docs/CONVENTIONS.md` §4; near points are on the viewer's side,
    /// `z > 0`).
    pub fn depth_to_z(&self, d: f64) -> f64 {
        (0.5 - d) * self.volume_depth_m
    }

    /// One [`Propagator`] per colour for `[height, width]` fields.
    ///
    /// Errors: as [`Propagator::new`].
    pub fn propagators(
        &self,
        height: usize,
        width: usize,
        options: PropagationOptions,
    ) -> Result<Vec<Propagator>> {
        self.validate()?;
        self.wavelengths_m
            .iter()
            .map(|&l| Propagator::new(height, width, self.pixel_pitch_m, l, options))
            .collect()
    }

    /// The propagator of colour `colour` (0 R, 1 G, 2 B) on `height × width` fields ([`Propagator::new`] at
    /// this pitch and the colour's wavelength; the setup itself is not validated).
    ///
    /// Errors: as [`Propagator::new`].
    pub(crate) fn propagator(
        &self,
        colour: usize,
        (height, width): (usize, usize),
        options: PropagationOptions,
    ) -> Result<Propagator> {
        Propagator::new(
            height,
            width,
            self.pixel_pitch_m,
            self.wavelengths_m[colour],
            options,
        )
    }
}

/// The pixel pitches a display may have, metres: 0.1 µm to 1 mm (SLMs are 1–20 µm).
pub const PITCH_RANGE_M: (f64, f64) = (1e-7, 1e-3);
/// The wavelengths a display may use, metres: 100 nm to 10 µm (lasers of the visible band are 380–780 nm;
/// profiles hold them to that, `crate::display`).
pub const WAVELENGTH_RANGE_M: (f64, f64) = (1e-7, 1e-5);
/// The deepest volume a display may have, metres: 1 m (the paper's is 6 mm).
pub const MAX_VOLUME_DEPTH_M: f64 = 1.0;
/// The farthest the SLM may sit from the midpoint hologram, metres (either side): 1 m, as deep as the deepest
/// volume (the paper's offsets are millimetres). A display profile's `offsets_m`, a session's `offset_m` and
/// an aberration correction's `slm_offset_m` are held to it.
pub const MAX_OFFSET_M: f64 = 1.0;

/// Checks an SLM offset `offset_m` (metres from the midpoint hologram): finite and within ±[`MAX_OFFSET_M`].
///
/// Errors: [`HoloError::InvalidParameter`](crate::HoloError::InvalidParameter) naming `name`, the value and the bound.
pub fn check_offset(name: &'static str, offset_m: f64) -> Result<()> {
    if !(offset_m.is_finite() && offset_m.abs() <= MAX_OFFSET_M) {
        // 1e308 in scientific notation, not 309 digits.
        let got = if offset_m.abs() < 1e6 {
            offset_m.to_string()
        } else {
            format!("{offset_m:e}")
        };
        return Err(invalid(
            name,
            format!(
                "the SLM's offset from the midpoint hologram must be a finite distance within \
                 ±{MAX_OFFSET_M} m, got {got} m"
            ),
        ));
    }
    Ok(())
}

/// Checks `value` lies within `[lo, hi]` (`unit` for the message). Errors: [`HoloError::InvalidParameter`](crate::HoloError::InvalidParameter)
/// naming `name` and the bounds.
fn check_within(name: &'static str, value: f64, (lo, hi): (f64, f64), unit: &str) -> Result<()> {
    if (lo..=hi).contains(&value) {
        return Ok(());
    }
    Err(crate::error::invalid(
        name,
        format!("{value} {unit} is outside {lo}–{hi} {unit}"),
    ))
}

//! Command-line flags shared by several subcommands.

use anyhow::{bail, Result};
use clap::Args;
use tensorholo::optics::{OpticalSetup, PropagationOptions};

/// Display geometry and angular-spectrum options (`DESIGN.md` §2), shared by `reference`, `encode` and
/// `dataset`.
#[derive(Debug, Args)]
pub struct OpticsArgs {
    /// Zero-pad propagations to 2H x 2W (linear convolution; 4x slower).
    #[arg(long)]
    pub pad: bool,
    /// Band-limit transfer functions (Matsushima & Shimobaba 2009).
    #[arg(long)]
    pub band_limit: bool,
    /// SLM pixel pitch in metres.
    #[arg(long, default_value_t = 8e-6)]
    pub pitch_m: f64,
    /// Laser wavelengths in metres, R,G,B.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, default_values_t = [638e-9, 520e-9, 450e-9])]
    pub wavelengths_m: Vec<f64>,
    /// Depth of the 3D volume in metres, centred on the midpoint hologram.
    #[arg(long, default_value_t = 6e-3)]
    pub volume_depth_m: f64,
}

impl OpticsArgs {
    /// The validated optical setup. Errors: not exactly 3 wavelengths, or a non-positive value.
    pub fn setup(&self) -> Result<OpticalSetup> {
        let [r, g, b] = self.wavelengths_m[..] else {
            bail!(
                "--wavelengths-m needs 3 comma-separated values (R,G,B), got {}",
                self.wavelengths_m.len()
            );
        };
        let setup = OpticalSetup {
            wavelengths_m: [r, g, b],
            pixel_pitch_m: self.pitch_m,
            volume_depth_m: self.volume_depth_m,
        };
        setup.validate()?;
        Ok(setup)
    }

    /// Padding and band-limit options.
    pub fn options(&self) -> PropagationOptions {
        PropagationOptions {
            pad: self.pad,
            band_limit: self.band_limit,
        }
    }
}

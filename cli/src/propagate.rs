//! `holo propagate`: the angular spectrum method on a `.npy` field, for interoperability checks.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Args;
use ndarray::Axis;
use tensorholo::io::{ensure_not_input, read_complex_npy, write_complex_npy};
use tensorholo::optics::{Carrier, PropagationOptions, Propagator};

/// Arguments of `holo propagate`.
#[derive(Debug, Args)]
pub struct PropagateArgs {
    /// Input complex field: .npy complex64 or complex128, shape [C, H, W] or [H, W].
    #[arg(long)]
    input: PathBuf,
    /// Propagation distance in metres (positive = along the light).
    #[arg(long, allow_hyphen_values = true)]
    distance_m: f64,
    /// Wavelength(s) in metres: one for every channel, or one per channel (comma-separated, R,G,B order).
    #[arg(long, value_delimiter = ',', required = true)]
    wavelength_m: Vec<f64>,
    /// Pixel pitch in metres (e.g. 8e-6).
    #[arg(long)]
    pitch_m: f64,
    /// Zero-pad to 2H x 2W (linear instead of circular convolution).
    #[arg(long)]
    pad: bool,
    /// Apply the Matsushima-Shimobaba band limit to the transfer function.
    #[arg(long)]
    band_limit: bool,
    /// Multiply by exp(-i 2 pi z / lambda), the carrier removal of offset propagation (paper Eq. 6).
    #[arg(long)]
    remove_carrier: bool,
    /// Output .npy (complex64, [C, H, W]). Never one of the inputs.
    #[arg(long)]
    output: PathBuf,
}

/// Runs `holo propagate`.
pub fn run(args: &PropagateArgs) -> Result<()> {
    crate::output::guard(
        "--output",
        &args.output,
        &[crate::output::Input::file("--input", &args.input)],
    )?;
    ensure_not_input(&args.output, &[&args.input])?;
    let mut field = read_complex_npy(&args.input)?;
    let (c, h, w) = field.dim();
    let wavelengths = match args.wavelength_m.len() {
        1 => vec![args.wavelength_m[0]; c],
        n if n == c => args.wavelength_m.clone(),
        n => bail!("--wavelength-m has {n} values but the field has {c} channels: give 1 or {c}"),
    };
    let options = PropagationOptions {
        pad: args.pad,
        band_limit: args.band_limit,
    };
    let carrier = if args.remove_carrier {
        Carrier::Remove
    } else {
        Carrier::Keep
    };
    for (k, mut channel) in field.axis_iter_mut(Axis(0)).enumerate() {
        let prop = Propagator::new(h, w, args.pitch_m, wavelengths[k], options)?;
        let slice = channel.as_slice_mut().context("field is not contiguous")?;
        prop.propagate_by(slice, args.distance_m, carrier)?;
    }
    write_complex_npy(&args.output, field.view())?;
    log::info!(
        "propagated {c}×{h}×{w} field by {} m → {}",
        args.distance_m,
        args.output.display()
    );
    Ok(())
}

//! `holo encode`: offset propagation, double phase encoding and the simulated post-encoding midpoint hologram
//! of a complex `.npy` field, so that other implementations (the PyTorch training code) can be checked
//! against the SDK on the same input ("one physics, checked twice").

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Args;
use ndarray::{Array4, Axis};
use serde_json::json;
use tensorholo::encoding::double_phase_encode;
use tensorholo::io::{ensure_not_input, read_complex_npy, write_complex_npy, write_f32_npy};
use tensorholo::optics::{focal_stack, propagate_colour, simulate_phase_only, Carrier};

/// Arguments of `holo encode`.
#[derive(Debug, Args)]
#[command(after_long_help = EXAMPLES)]
pub struct EncodeArgs {
    /// Input midpoint hologram: .npy complex64 or complex128, shape [3, H, W] (R, G, B).
    #[arg(long)]
    input: PathBuf,
    /// Distance s from the midpoint hologram to the SLM plane in millimetres (paper: 0, 6 or 12).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    offset_mm: f64,
    #[command(flatten)]
    encoding: crate::args::EncodingArgs,
    #[command(flatten)]
    optics: crate::args::OpticsArgs,
    /// Normalised depths (0 = near, 1 = far) of the focal stacks, comma-separated.
    #[arg(long, value_delimiter = ',', default_values_t = [0.0, 0.5, 1.0])]
    depths: Vec<f64>,
    /// Output folder (created if missing). Files of the same names in it are replaced; the input never is.
    #[arg(long)]
    out: PathBuf,
}

const EXAMPLES: &str = "\
Examples:
  holo encode --input out/default/midpoint.npy --offset-mm 6 --encoding dpm --out out/encoded
  holo encode --input field.npy --encoding aa-dpm --aa-sigma-px 1.0 --depths 0.2,0.8 --out out/aa

Outputs in --out:
  slm_field.npy            complex64 [3, H, W]  ASM(H_mid, s) * exp(-i 2 pi s / lambda) (Eq. 6; the input if s = 0)
  phase.npy                float32 [3, H, W]    double phase pattern in [0, 2 pi) (Eq. 7, after the pre-filter)
  post_midpoint.npy        complex64 [3, H, W]  Fourier filter (Eq. 8-9) then ASM(., -s) * exp(+i 2 pi s / lambda)
                                                (Eq. 10): the post-encoding midpoint hologram, amplitude ~ A / a
  focal_stack.npy          float32 [D, 3, H, W] |ASM(post_midpoint, z(d))| at --depths (carrier removed)
  target_focal_stack.npy   float32 [D, 3, H, W] |ASM(input, z(d))| at --depths
  encode.json              parameters, amplitude normaliser a, per-channel mean phase";

const OUTPUTS: [&str; 6] = [
    "slm_field.npy",
    "phase.npy",
    "post_midpoint.npy",
    "focal_stack.npy",
    "target_focal_stack.npy",
    "encode.json",
];

/// Stacks per-depth `[3, H, W]` amplitudes into `[D, 3, H, W]`.
fn stack(planes: &[ndarray::Array3<f32>]) -> Result<Array4<f32>> {
    let views: Vec<_> = planes.iter().map(|p| p.view()).collect();
    Ok(ndarray::stack(Axis(0), &views)?)
}

/// Runs `holo encode`.
pub fn run(args: &EncodeArgs) -> Result<()> {
    crate::output::guard(
        "--out",
        &args.out,
        &std::iter::once(crate::output::Input::file("--input", &args.input))
            .chain(args.optics.guard_input())
            .collect::<Vec<_>>(),
    )?;
    crate::args::check_offset_mm(args.offset_mm)?;
    if args.depths.is_empty() {
        bail!("--depths needs at least one normalised depth in [0, 1]");
    }
    let setup = args.optics.setup(args.optics.profile()?.as_ref())?;
    let (name, method) = args.encoding.method(crate::args::Encoding::Dpm);
    let options = args.optics.options();
    let offset_m = args.offset_mm * 1e-3;
    for name in OUTPUTS {
        ensure_not_input(&args.out.join(name), &[&args.input])?;
    }

    let midpoint = read_complex_npy(&args.input)?;
    let (c, h, w) = midpoint.dim();
    if c != 3 {
        bail!(
            "{} has {c} channels: holo encode needs a colour hologram [3, H, W] (R, G, B)",
            args.input.display()
        );
    }
    let in_file = || format!("encoding `{}`", args.input.display());
    let mut slm_field = midpoint.clone();
    if offset_m != 0.0 {
        propagate_colour(&mut slm_field, &setup, offset_m, Carrier::Remove, options)
            .with_context(in_file)?;
    }
    let encoded = double_phase_encode(slm_field.view(), &method).with_context(in_file)?;
    let post = simulate_phase_only(encoded.phase.view(), &setup, offset_m, options)?;
    let post_stack = focal_stack(post.view(), &setup, 0.0, &args.depths, options, false)?;
    let target_stack = focal_stack(midpoint.view(), &setup, 0.0, &args.depths, options, false)?;

    crate::output::start_run(&args.out, &[], Some(&args.out.join("encode.json")))?;
    let path = |name: &str| -> PathBuf { args.out.join(name) };
    write_complex_npy(&path("slm_field.npy"), slm_field.view())?;
    write_f32_npy(&path("phase.npy"), encoded.phase.view())?;
    write_complex_npy(&path("post_midpoint.npy"), post.view())?;
    write_f32_npy(&path("focal_stack.npy"), stack(&post_stack)?.view())?;
    write_f32_npy(
        &path("target_focal_stack.npy"),
        stack(&target_stack)?.view(),
    )?;
    let report = json!({
        "tensorholo_version": env!("CARGO_PKG_VERSION"),
        "command": crate::output::command_line(),
        "input": crate::output::path_text(&args.input),
        "size": [h, w],
        "setup": setup,
        "offset_m": offset_m,
        "method": method,
        "propagation": options,
        "depths": args.depths,
        "amplitude_scale": encoded.amplitude_scale,
        "mean_phase_rad": encoded.mean_phase,
    });
    crate::args::write_json(&path("encode.json"), &report)?;
    log::info!(
        "encoded {c}×{h}×{w} hologram (offset {} mm, {:?}) → {}",
        args.offset_mm,
        name,
        args.out.display()
    );
    Ok(())
}

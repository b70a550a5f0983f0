//! `holo compare`: how far apart two output folders of `holo render` / `holo reference` are (the same
//! command run on two machines, e.g. x86-64 and an aarch64 build under qemu or on a board): the midpoint
//! hologram, the SLM codes (cyclic: code 255 and 0 are neighbours) and the simulated reconstructions. A NaN
//! or infinite value in either midpoint hologram is reported and the command fails: the outputs differ.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use tensorholo::io::read_complex_npy;

use crate::output::FOCUS;

/// Arguments of `holo compare`.
#[derive(Debug, Args)]
#[command(
    after_long_help = "Example (docs/GUIDE.md \"ARM and phones\"): the same render on x86-64 and on aarch64 under qemu:\n  \
    holo render --rgb c.png --depth d.png --depth-encoding tum --out out/x86\n  \
    qemu-aarch64 -L /usr/aarch64-linux-gnu target/aarch64-unknown-linux-gnu/release/holo render … --out out/arm\n  \
    holo compare out/x86 out/arm --max-code-fraction 0.001"
)]
pub struct CompareArgs {
    /// Output folder of the reference run.
    a: PathBuf,
    /// Output folder of the other run (same command, same input).
    b: PathBuf,
    /// Fail (exit 1) if more than this fraction of SLM codes differ, or any by more than one step.
    #[arg(long)]
    max_code_fraction: Option<f64>,
}

/// The 8-bit samples of `name` in both folders (grey for SLM patterns, RGB for reconstructions); an error if
/// either is unreadable or the two sizes differ.
fn load_pair(args: &CompareArgs, name: &str, grey: bool) -> Result<(Vec<u8>, Vec<u8>)> {
    let load = |dir: &Path| -> Result<image::DynamicImage> {
        let path = dir.join(name);
        image::open(&path).with_context(|| format!("reading {}", path.display()))
    };
    let (a, b) = (load(&args.a)?, load(&args.b)?);
    if (a.width(), a.height()) != (b.width(), b.height()) {
        bail!(
            "{name}: {}×{} vs {}×{}",
            a.width(),
            a.height(),
            b.width(),
            b.height()
        );
    }
    let samples = |img: image::DynamicImage| {
        if grey {
            img.into_luma8().into_raw()
        } else {
            img.into_rgb8().into_raw()
        }
    };
    Ok((samples(a), samples(b)))
}

/// Runs `holo compare`.
pub fn run(args: &CompareArgs) -> Result<()> {
    let (ma, mb) = (
        read_complex_npy(&args.a.join("midpoint.npy"))?,
        read_complex_npy(&args.b.join("midpoint.npy"))?,
    );
    if ma.dim() != mb.dim() {
        bail!(
            "midpoint holograms differ in shape: {:?} vs {:?}",
            ma.dim(),
            mb.dim()
        );
    }
    // NaN or ∞ in either hologram is a difference, never hidden by `max` (which skips NaN).
    let not_finite = |m: &ndarray::Array3<num_complex::Complex32>| {
        m.iter()
            .filter(|v| !(v.re.is_finite() && v.im.is_finite()))
            .count()
    };
    let (bad_a, bad_b) = (not_finite(&ma), not_finite(&mb));
    if bad_a + bad_b > 0 {
        println!(
            "midpoint hologram {:?}: {bad_a} value(s) NaN or infinite in {}, {bad_b} in {}",
            ma.dim(),
            args.a.display(),
            args.b.display()
        );
        bail!(
            "the midpoint holograms hold NaN or infinite values ({bad_a} in {}, {bad_b} in {}): the outputs \
             differ, whatever else agrees",
            args.a.display(),
            args.b.display()
        );
    }
    let scale = ma.iter().fold(0.0f32, |m, v| m.max(v.norm()));
    let max_diff = ma
        .iter()
        .zip(mb.iter())
        .fold(0.0f32, |m, (x, y)| m.max((x - y).norm()));
    println!(
        "midpoint hologram {:?}: max |Δ| / max |h| = {:.2e}",
        ma.dim(),
        max_diff / scale.max(f32::MIN_POSITIVE)
    );

    let (mut changed, mut total, mut max_step) = (0usize, 0usize, 0u8);
    for name in ["phase_r.png", "phase_g.png", "phase_b.png"] {
        let (a, b) = load_pair(args, name, true)?;
        let steps: Vec<u8> = a
            .iter()
            .zip(&b)
            .map(|(x, y)| x.wrapping_sub(*y).min(y.wrapping_sub(*x)))
            .collect();
        let n = steps.iter().filter(|&&s| s != 0).count();
        let m = steps.iter().copied().max().unwrap_or(0);
        println!(
            "SLM codes {name}: {n} of {} differ, by at most {m}",
            steps.len()
        );
        (changed, total, max_step) = (changed + n, total + steps.len(), max_step.max(m));
    }
    for name in FOCUS {
        let (a, b) = load_pair(args, name, false)?;
        let n = a.iter().zip(&b).filter(|(x, y)| x != y).count();
        let m = a
            .iter()
            .zip(&b)
            .map(|(x, y)| x.abs_diff(*y))
            .max()
            .unwrap_or(0);
        println!(
            "reconstruction {name}: {n} of {} 8-bit values differ, by at most {m}",
            a.len()
        );
    }
    if let Some(limit) = args.max_code_fraction {
        let fraction = changed as f64 / total.max(1) as f64;
        if fraction > limit || max_step > 1 {
            bail!("{changed} of {total} SLM codes differ ({fraction:.2e} > {limit:e}) or one by more than 1 ({max_step})");
        }
    }
    Ok(())
}

//! `holo calibrate`: the display calibration of paper Methods (Eq. 12–13) on a bench: the 256 test patterns,
//! a per-pixel look-up table from the camera captures, its curves for inspection, and a simulated SLM to try
//! it all without hardware (`docs/CALIBRATION.md`).

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use tensorholo::slm::calibrate::{calibrate, calibration_pattern, CalibrationOptions};
use tensorholo::slm::captures::{Crop, PngCaptureDir};
use tensorholo::slm::file::COLOUR_NAMES;
use tensorholo::slm::lut::CODES;
use tensorholo::slm::simulate::SimulatedSlm;
use tensorholo::slm::{DisplayCalibration, LutRepresentation, PhaseLut};

use crate::args::parse_size;

/// `holo calibrate` subcommands.
#[derive(Debug, Args)]
pub struct CalibrateArgs {
    #[command(subcommand)]
    command: CalibrateCommand,
}

#[derive(Debug, Subcommand)]
enum CalibrateCommand {
    /// Write the 256 calibration patterns pattern_000.png … pattern_255.png: in every 2×2 block, top-left and
    /// bottom-right at code k, the other two at code 0.
    Patterns {
        /// SLM size HEIGHTxWIDTH (e.g. 1080x1920).
        #[arg(long, value_parser = parse_size)]
        size: (usize, usize),
        /// Output folder (created).
        #[arg(long)]
        out: PathBuf,
    },
    /// Compute the per-pixel look-up table from camera captures (capture_000.png … capture_255.png per colour;
    /// 8/16-bit grey or RGB PNG, focused on the SLM) and write a display calibration file. Colours without
    /// captures keep the linear LUT.
    Lut {
        /// Captures of the red laser.
        #[arg(long)]
        red: Option<PathBuf>,
        /// Captures of the green laser.
        #[arg(long)]
        green: Option<PathBuf>,
        /// Captures of the blue laser.
        #[arg(long)]
        blue: Option<PathBuf>,
        /// SLM size HEIGHTxWIDTH.
        #[arg(long, value_parser = parse_size)]
        size: (usize, usize),
        /// The SLM's area in the captures: x,y,width,height in camera pixels (default: the whole capture).
        #[arg(long)]
        crop: Option<String>,
        /// Tile side in SLM pixels (even; 0 = automatic: 4–16 px by SLM size, 12.5 MB at 1080p).
        #[arg(long, default_value_t = 0)]
        tile: usize,
        /// `tiled` (per-pixel) or `global` (the panel's mean curve).
        #[arg(long, default_value = "tiled")]
        representation: String,
        /// Output calibration file (.holocal).
        #[arg(long)]
        out: PathBuf,
    },
    /// Write a colour's fitted response as float32 .npy [H, W, 256]: the phase in radians that code k displays,
    /// relative to code 0, at each pixel.
    Curves {
        /// Calibration file.
        file: PathBuf,
        /// red, green or blue.
        #[arg(long)]
        color: String,
        /// Output .npy.
        #[arg(long)]
        out: PathBuf,
    },
    /// Write the captures of a simulated SLM (spatially varying response, Gaussian beam, noise, dust; camera at
    /// 2× resolution) into OUT/red, OUT/green, OUT/blue, to try `holo calibrate lut` without hardware.
    Simulate {
        /// SLM size HEIGHTxWIDTH.
        #[arg(long, value_parser = parse_size, default_value = "128x128")]
        size: (usize, usize),
        /// Seed of the panel's response fields, noise and dust.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
    },
}

fn colour_index(name: &str) -> Result<usize> {
    COLOUR_NAMES
        .iter()
        .position(|c| *c == name)
        .with_context(|| format!("--color {name}: expected red, green or blue"))
}

/// Runs `holo calibrate …`.
pub fn run(args: &CalibrateArgs) -> Result<()> {
    match &args.command {
        CalibrateCommand::Patterns { size, out } => {
            std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
            for k in 0..CODES {
                let p = calibration_pattern(size.0, size.1, k as u8);
                tensorholo::io::save_u8_png(&out.join(format!("pattern_{k:03}.png")), p.view())?;
            }
            eprintln!(
                "wrote 256 patterns ({}×{}) to {}",
                size.0,
                size.1,
                out.display()
            );
            Ok(())
        }
        CalibrateCommand::Lut {
            red,
            green,
            blue,
            size,
            crop,
            tile,
            representation,
            out,
        } => {
            let crop: Option<Crop> = crop.as_deref().map(str::parse).transpose()?;
            if red.is_none() && green.is_none() && blue.is_none() {
                bail!(
                    "give the captures of at least one colour: --red DIR, --green DIR, --blue DIR"
                );
            }
            for dir in [red, green, blue].into_iter().flatten() {
                tensorholo::io::ensure_not_input(out, &[dir.as_path()])?;
            }
            let mut cal = DisplayCalibration::linear(size.0, size.1)?;
            let options = CalibrationOptions {
                tile: *tile,
                ..CalibrationOptions::default()
            };
            for (c, dir) in [red, green, blue].into_iter().enumerate() {
                let Some(dir) = dir else { continue };
                let stack = PngCaptureDir::open(dir, *size, crop)?;
                let name = COLOUR_NAMES[c];
                let progress = |d: u64, t: u64| {
                    if d.is_multiple_of(64) {
                        eprintln!("{name}: {d}/{t} captures read");
                    }
                };
                let (tiles, report) = calibrate(&stack, &options, &progress)
                    .with_context(|| format!("calibrating {name} from {}", dir.display()))?;
                eprintln!(
                    "{name}: {} tiles of {}×{} px, ranges {:.3}–{:.3} rad, {:.2} % of pixels unusable, {} tiles filled",
                    report.tiles,
                    tiles.tile().0,
                    tiles.tile().1,
                    report.range_rad[0],
                    report.range_rad[1],
                    100.0 * report.unusable_fraction,
                    report.filled_tiles
                );
                let repr = match representation.as_str() {
                    "tiled" => LutRepresentation::Tiled(tiles),
                    "global" => LutRepresentation::Global(tiles.mean_curve()),
                    other => bail!("--representation {other}: expected tiled or global"),
                };
                cal.colours[c].lut = PhaseLut::new(repr);
            }
            cal.notes = format!(
                "holo calibrate lut, tensorholo {}",
                env!("CARGO_PKG_VERSION")
            );
            cal.write(out)?;
            eprintln!("wrote {}", out.display());
            Ok(())
        }
        CalibrateCommand::Curves { file, color, out } => {
            let c = colour_index(color)?;
            tensorholo::io::ensure_not_input(out, &[file.as_path()])?;
            let cal = DisplayCalibration::read(file)?;
            let (h, w) = (cal.height, cal.width);
            let lut = &cal.colours[c].lut;
            let row = w * CODES;
            tensorholo::io::write_f32_npy_streaming(out, &[h, w, CODES], row, |start, buf| {
                let y = start / row;
                match lut.representation() {
                    LutRepresentation::Tiled(t) => t.curves_of_rows(y..y + 1, buf),
                    _ => {
                        for (i, v) in buf.iter_mut().enumerate() {
                            *v = lut.displayed_phase(y, (i / CODES) % w, (i % CODES) as u8)?;
                        }
                        Ok(())
                    }
                }
            })?;
            eprintln!("wrote {} ([{h}, {w}, 256] float32, radians)", out.display());
            Ok(())
        }
        CalibrateCommand::Simulate { size, seed, out } => {
            let sim = SimulatedSlm::new(size.0, size.1, *seed);
            sim.validate()?;
            for (c, name) in COLOUR_NAMES.iter().enumerate() {
                sim.write_captures(c, &out.join(name), &|_, _| {})?;
            }
            let json = serde_json::to_string_pretty(&sim)?;
            tensorholo::io::write_atomic(&out.join("simulator.json"), json.as_bytes())?;
            eprintln!(
                "wrote 3 × 256 captures of a simulated {}×{} SLM to {} (parameters in simulator.json)",
                size.0,
                size.1,
                out.display()
            );
            Ok(())
        }
    }
}

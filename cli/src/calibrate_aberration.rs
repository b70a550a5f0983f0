//! `holo calibrate aberration`: the display's aberration (paper Eq. 14–19) from camera captures of focused
//! spots, by phase diversity (`docs/ABERRATION.md`, "Calibration from captures"): the test patterns, a
//! simulated display and camera to try it, and the fit into a `tensorholo.aberration` file.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use tensorholo::display::AberrationProfile;
use tensorholo::optics::OpticalSetup;
use tensorholo::slm::spots::simulate::{simulate_captures, SimulateOptions};
use tensorholo::slm::spots::{
    fit_captures, FitOptions, SpotPlan, COLOURS, DEFAULT_CAMERA_SCALE, DEFAULT_WINDOW_PX,
    HIDDEN_FILE,
};

use crate::args::parse_size;
use crate::output::{guard, Input};

/// `holo calibrate aberration` subcommands.
#[derive(Debug, Args)]
pub struct AberrationArgs {
    #[command(subcommand)]
    command: AberrationCommand,
}

#[derive(Debug, Subcommand)]
enum AberrationCommand {
    /// Write the spot patterns (pattern_COLOUR_dI_kK.png, 8-bit codes of the linear look-up table) and
    /// plan.json: per colour and distance, a spot focused at the distance with each of 5 diversity phases
    /// (none, focus ±2 rad, vertical and oblique astigmatism +2 rad). Show each and photograph the focal plane
    /// at its distance as capture_COLOUR_dI_kK.png.
    Patterns {
        /// Display profile (JSON, docs/DISPLAYS.md): SLM size, pitch and wavelengths.
        #[arg(long, value_name = "FILE")]
        display: Option<PathBuf>,
        /// SLM size HEIGHTxWIDTH with the paper's optics (8 µm, 638/520/450 nm) [default: the --display
        /// profile's resolution].
        #[arg(long, value_parser = parse_size)]
        size: Option<(usize, usize)>,
        /// Focus distances in millimetres, signed (SLM → focus, positive toward the viewer), |d| ≤ 1000.
        #[arg(
            long,
            value_delimiter = ',',
            allow_hyphen_values = true,
            default_value = "-3,3"
        )]
        distances_mm: Vec<f64>,
        /// Colours to calibrate (red, green, blue); the others are derived from the nearest wavelength.
        #[arg(long, value_delimiter = ',', default_value = "red,green,blue")]
        colours: Vec<String>,
        /// Camera pixels per SLM pixel pitch in the focal plane (magnification × SLM pitch / camera pitch).
        #[arg(long, default_value_t = DEFAULT_CAMERA_SCALE)]
        camera_scale: f64,
        /// Side of the window around the spot that the fit models, in camera pixels (even).
        #[arg(long, default_value_t = DEFAULT_WINDOW_PX)]
        window_px: usize,
        /// Output folder (created).
        #[arg(long)]
        out: PathBuf,
    },
    /// Simulate a display with a hidden random aberration and its camera: the captures of every pattern of
    /// --patterns into --out, and the truth as hidden.json (a tensorholo.aberration file).
    Simulate {
        /// The folder `holo calibrate aberration patterns` wrote.
        #[arg(long)]
        patterns: PathBuf,
        /// Seed of the hidden aberration, spot positions, exposures and noise.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Largest |coefficient| of the hidden aberration, radians at the pupil edge (0–3).
        #[arg(long, default_value_t = 1.0)]
        max_rad: f64,
        /// Camera read noise, standard deviation in units of full scale.
        #[arg(long, default_value_t = 0.005)]
        noise: f64,
        /// Camera full well in electrons at full scale (shot noise; 0: none).
        #[arg(long, default_value_t = 10_000.0)]
        full_well: f64,
        /// Bit depth of the capture PNGs: 8 or 16.
        #[arg(long, default_value_t = 8)]
        bit_depth: u8,
        /// Camera frame side in pixels [default: 1.5× the plan's window].
        #[arg(long, default_value_t = 0)]
        frame_px: usize,
        /// Output folder (created).
        #[arg(long)]
        out: PathBuf,
    },
    /// Fit the five Zernike coefficients per colour and distance from the captures and write the aberration
    /// file (tensorholo.aberration, docs/ABERRATION.md). Prints the coefficients and residuals; with a
    /// simulation's hidden.json in --captures, the error against it.
    Fit {
        /// The folder `holo calibrate aberration patterns` wrote (its plan.json).
        #[arg(long)]
        patterns: PathBuf,
        /// The folder of the captures (capture_COLOUR_dI_kK.png).
        #[arg(long)]
        captures: PathBuf,
        /// Nelder–Mead iterations per run.
        #[arg(long, default_value_t = FitOptions::default().max_iters)]
        max_iters: u64,
        /// Output aberration file (.json).
        #[arg(long)]
        out: PathBuf,
    },
}

/// Runs `holo calibrate aberration …`.
pub fn run(args: &AberrationArgs) -> Result<()> {
    match &args.command {
        AberrationCommand::Patterns {
            display,
            size,
            distances_mm,
            colours,
            camera_scale,
            window_px,
            out,
        } => {
            let inputs: Vec<Input> = display
                .as_deref()
                .map(|d| Input::file("--display", d))
                .into_iter()
                .collect();
            guard("--out", out, &inputs)?;
            let profile = display
                .as_deref()
                .map(crate::args::read_profile)
                .transpose()?;
            let (setup, slm) = match (&profile, size) {
                (_, Some(s)) if profile.is_none() => (OpticalSetup::default(), [s.0, s.1]),
                (Some(p), s) => (
                    OpticalSetup {
                        wavelengths_m: p.wavelengths_m,
                        pixel_pitch_m: p.pixel_pitch_m,
                        volume_depth_m: p.volume_depth_m,
                    },
                    s.map_or(p.resolution, |s| [s.0, s.1]),
                ),
                _ => bail!("give the SLM: --size HEIGHTxWIDTH or --display PROFILE.json"),
            };
            let colours: Vec<usize> = colours
                .iter()
                .map(|name| {
                    COLOURS.iter().position(|c| c == name).with_context(|| {
                        format!("--colours: unknown colour `{name}` (red, green, blue)")
                    })
                })
                .collect::<Result<_>>()?;
            let distances_m = distances_mm.iter().map(|d| d * 1e-3).collect();
            let plan = SpotPlan::new(
                slm,
                &setup,
                &colours,
                distances_m,
                *camera_scale,
                *window_px,
            )
            .context("--distances-mm, --colours, --camera-scale, --window-px")?;
            let n = plan.write_patterns(out, &|d, t| {
                if d % 10 == 0 || d == t {
                    eprintln!("patterns: {d}/{t}");
                }
            })?;
            eprintln!(
                "wrote {n} patterns ({}×{}) and plan.json to {}; photograph each at its distance as \
                 capture_<colour>_d<i>_k<k>.png",
                slm[0],
                slm[1],
                out.display()
            );
            Ok(())
        }
        AberrationCommand::Simulate {
            patterns,
            seed,
            max_rad,
            noise,
            full_well,
            bit_depth,
            frame_px,
            out,
        } => {
            guard("--out", out, &[Input::folder("--patterns", patterns)])?;
            let plan = SpotPlan::load(patterns).context("--patterns")?;
            let options = SimulateOptions {
                seed: *seed,
                max_rad: *max_rad,
                noise: *noise,
                full_well: *full_well,
                bit_depth: *bit_depth,
                frame_px: *frame_px,
            };
            simulate_captures(&plan, patterns, out, &options, &|d, t| {
                if d % 10 == 0 || d == t {
                    eprintln!("captures: {d}/{t}");
                }
            })?;
            eprintln!(
                "wrote the simulated captures and {HIDDEN_FILE} (the hidden aberration) to {}",
                out.display()
            );
            Ok(())
        }
        AberrationCommand::Fit {
            patterns,
            captures,
            max_iters,
            out,
        } => {
            guard(
                "--out",
                out,
                &[
                    Input::folder("--patterns", patterns),
                    Input::folder("--captures", captures),
                ],
            )?;
            let plan = SpotPlan::load(patterns).context("--patterns")?;
            if *max_iters == 0 {
                bail!("--max-iters must be at least 1");
            }
            let options = FitOptions {
                max_iters: *max_iters,
            };
            let report = fit_captures(&plan, captures, &options, &|line| eprintln!("fit: {line}"))?;
            let hidden_path = captures.join(HIDDEN_FILE);
            let hidden = if hidden_path.is_file() {
                Some(AberrationProfile::load(&hidden_path)?)
            } else {
                None
            };
            println!(
                "{:<18} {:>11} {:>8} {:>8} {:>8} {:>8} {:>8} {:>9}{}",
                "colour",
                "distance_mm",
                "focus",
                "astig_v",
                "astig_o",
                "coma_h",
                "coma_v",
                "residual",
                if hidden.is_some() {
                    "  max_error_vs_hidden"
                } else {
                    ""
                }
            );
            for (c, fit) in report.colours.iter().enumerate() {
                let name = match fit.derived_from {
                    Some(from) => format!("{} (from {})", COLOURS[c], COLOURS[from]),
                    None => COLOURS[c].to_string(),
                };
                for f in &fit.distances {
                    let a = f.coefficients.to_array();
                    let error = hidden.as_ref().map_or(String::new(), |h| {
                        let truth = h.coefficients(f.distance_m, c).to_array();
                        let e = a
                            .iter()
                            .zip(truth)
                            .map(|(x, t)| (x - t).abs())
                            .fold(0.0, f64::max);
                        format!("  {e:.4}")
                    });
                    println!(
                        "{name:<18} {:>11.3} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>9.4}{error}",
                        f.distance_m * 1e3,
                        a[0],
                        a[1],
                        a[2],
                        a[3],
                        a[4],
                        f.residual
                    );
                }
            }
            for (c, fit) in report.colours.iter().enumerate() {
                for f in fit
                    .distances
                    .iter()
                    .filter(|f| fit.fitted && f.residual > 0.5)
                {
                    eprintln!(
                        "warning: {} at {:+.3} mm fits poorly (residual {:.2}): check that the spot is in focus \
                         and inside the captures, and --camera-scale",
                        COLOURS[c],
                        f.distance_m * 1e3,
                        f.residual
                    );
                }
            }
            report.profile.save(out)?;
            eprintln!("wrote {}", out.display());
            Ok(())
        }
    }
}

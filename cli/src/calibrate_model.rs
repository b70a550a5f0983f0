//! `holo calibrate model`: a display model (source, crosstalk, phase response, zero order, aberration) fitted
//! from camera captures, for the refinement (`holo render --refine N --display-model MODEL`): the test
//! patterns and capture plan, a simulated display to try it without hardware, and the fit
//! (docs/CALIBRATION.md, "The display model").

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use tensorholo::optics::OpticalSetup;
use tensorholo::slm::model::{DisplayModel, COLOUR_KEYS};
use tensorholo::slm::model_captures::{
    capture_patterns, simulate_display, ManifestEntry, ManifestFile, CAPTURES_FORMAT,
    CAPTURES_VERSION,
};
use tensorholo::slm::model_fit::{fit, FitOptions};
use tensorholo::slm::simulate::write_grey_png;
use tensorholo::slm::{DisplayCalibration, LutRepresentation};

use crate::args::parse_size;
use crate::output::{guard, Input};

/// `holo calibrate model` subcommands.
#[derive(Debug, Args)]
pub struct ModelArgs {
    #[command(subcommand)]
    command: ModelCommand,
}

/// The SLM, colours and distances of a capture plan.
#[derive(Debug, Args)]
struct PlanArgs {
    /// Display profile (JSON, docs/DISPLAYS.md): SLM size, pitch and wavelengths.
    #[arg(long, value_name = "FILE")]
    display: Option<PathBuf>,
    /// SLM size HEIGHTxWIDTH with the paper's optics (8 µm, 638/520/450 nm) [default: the --display
    /// profile's resolution].
    #[arg(long, value_parser = parse_size)]
    size: Option<(usize, usize)>,
    /// Colours to capture (red, green, blue).
    #[arg(long, value_delimiter = ',', default_value = "green")]
    colours: Vec<String>,
    /// Camera focus distances in millimetres, signed (SLM → focal plane, the refinement's `z_d − s`).
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        default_value = "-9,-6,-3"
    )]
    distances_mm: Vec<f64>,
    /// Seed of the random-code patterns.
    #[arg(long, default_value_t = 7)]
    pattern_seed: u64,
}

#[derive(Debug, Subcommand)]
enum ModelCommand {
    /// Write the 8 test patterns (pattern_0.png … pattern_7.png, 8-bit codes: random codes, a smooth phase,
    /// 1-pixel checkerboards, gratings), the manifest without captures (manifest.json, for the bench to fill
    /// in) and capture_plan.txt.
    Patterns {
        #[command(flatten)]
        plan: PlanArgs,
        /// Output folder (created).
        #[arg(long)]
        out: PathBuf,
    },
    /// Simulate a display with hidden parameters drawn from ranges (docs/CALIBRATION.md) and its captures
    /// of the 8 patterns: the patterns, 16-bit captures, manifest.json and the hidden parameters as
    /// hidden.json (a tensorholo.display-model file) in --out.
    Simulate {
        #[command(flatten)]
        plan: PlanArgs,
        /// Seed of the hidden parameters and the noise.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Camera noise, standard deviation in units of full scale.
        #[arg(long, default_value_t = 0.01)]
        noise: f32,
        /// Output folder (created).
        #[arg(long)]
        out: PathBuf,
    },
    /// Fit the display model to the captures of a manifest (tensorholo.captures) by Levenberg–Marquardt and
    /// write it (tensorholo.display-model, any file name). Prints the residual per capture; with --truth (a
    /// simulation's hidden.json) the error of each part against it.
    Fit {
        /// The capture manifest (JSON; paths relative to its folder).
        #[arg(long)]
        captures: PathBuf,
        /// Display profile: pitch and wavelengths (and the SLM size, checked against the patterns').
        #[arg(long, value_name = "FILE")]
        display: Option<PathBuf>,
        /// SLM size HEIGHTxWIDTH, checked against the patterns'.
        #[arg(long, value_parser = parse_size)]
        size: Option<(usize, usize)>,
        /// A simulation's hidden parameters (tensorholo.display-model).
        #[arg(long)]
        truth: Option<PathBuf>,
        /// A display calibration (.holocal, `holo calibrate lut`): its calibrated look-up tables, global or per
        /// pixel, are the model's phase response, held while the other parts are fitted (colours with the
        /// linear table fit one curve).
        #[arg(long, value_name = "FILE")]
        calibration: Option<PathBuf>,
        /// Levenberg–Marquardt iterations at most.
        #[arg(long, default_value_t = FitOptions::default().iterations)]
        iterations: usize,
        /// Crosstalk kernel side: 1 (none), 3 or 5.
        #[arg(long, default_value_t = 3)]
        kernel: usize,
        /// Output model file.
        #[arg(long)]
        out: PathBuf,
    },
}

/// Writes a display model to `path` atomically (its JSON form, `tensorholo.display-model`): indented for
/// reading, or compact where a colour's response is per pixel (at 1080p its tiles' curves are about 20 MB of
/// numbers a colour compact, more than twice that indented, one number a line).
fn save_model(path: &Path, model: &DisplayModel) -> Result<()> {
    let per_pixel = model
        .colours
        .iter()
        .any(|c| matches!(c.response, Some(LutRepresentation::Tiled(_))));
    let text = if per_pixel {
        serde_json::to_string(model)?
    } else {
        serde_json::to_string_pretty(model)?
    } + "\n";
    tensorholo::io::write_atomic(path, text.as_bytes())?;
    Ok(())
}

/// Writes a capture manifest of `entries` to `path` atomically.
fn write_manifest(path: &Path, entries: &[ManifestEntry]) -> Result<()> {
    let file = ManifestFile {
        format: CAPTURES_FORMAT.into(),
        version: CAPTURES_VERSION,
        captures: entries.to_vec(),
    };
    tensorholo::io::write_atomic(
        path,
        (serde_json::to_string_pretty(&file)? + "\n").as_bytes(),
    )?;
    Ok(())
}

/// The optics and SLM size of `--display` / `--size`.
fn optics_of(
    display: Option<&Path>,
    size: Option<(usize, usize)>,
) -> Result<(OpticalSetup, Option<[usize; 2]>)> {
    let profile = display.map(crate::args::read_profile).transpose()?;
    Ok(match profile {
        Some(p) => {
            let slm = size.map_or(p.resolution, |s| [s.0, s.1]);
            if size.is_some_and(|s| [s.0, s.1] != p.resolution) {
                bail!(
                    "--size {}x{} differs from the --display profile's resolution {}x{}",
                    slm[0],
                    slm[1],
                    p.resolution[0],
                    p.resolution[1]
                );
            }
            (
                OpticalSetup {
                    wavelengths_m: p.wavelengths_m,
                    pixel_pitch_m: p.pixel_pitch_m,
                    volume_depth_m: p.volume_depth_m,
                },
                Some(slm),
            )
        }
        None => (OpticalSetup::default(), size.map(|s| [s.0, s.1])),
    })
}

/// The optics, SLM size and the plan's `(pattern, colour, distance_m)` entries.
type Resolved = (OpticalSetup, [usize; 2], Vec<(usize, usize, f64)>);

impl PlanArgs {
    /// Refuses an `--out` that would overwrite or sit among the inputs.
    fn guard(&self, out: &Path) -> Result<()> {
        let inputs: Vec<Input> = self
            .display
            .as_deref()
            .map(|d| Input::file("--display", d))
            .into_iter()
            .collect();
        guard("--out", out, &inputs)
    }

    /// The optics, SLM size, colours, distances (m) and the manifest entries `(pattern, colour, distance)`.
    fn resolve(&self) -> Result<Resolved> {
        let (setup, slm) = optics_of(self.display.as_deref(), self.size)?;
        let slm = slm.context("give the SLM: --size HEIGHTxWIDTH or --display PROFILE.json")?;
        let colours: Vec<usize> = self
            .colours
            .iter()
            .map(|name| {
                COLOUR_KEYS.iter().position(|c| c == name).with_context(|| {
                    format!("--colours: unknown colour `{name}` (red, green, blue)")
                })
            })
            .collect::<Result<_>>()?;
        if let Some(d) = self
            .distances_mm
            .iter()
            .find(|d| !d.is_finite() || d.abs() > 1000.0)
        {
            bail!("--distances-mm: {d} mm; give finite distances within ±1000 mm");
        }
        let plan = (0..8)
            .flat_map(|p| {
                colours
                    .iter()
                    .flat_map(move |&c| self.distances_mm.iter().map(move |&d| (p, c, d * 1e-3)))
            })
            .collect();
        Ok((setup, slm, plan))
    }

    /// Writes the patterns and returns the manifest entries (`capture` named where `captures`).
    fn write_patterns(
        &self,
        out: &Path,
        slm: [usize; 2],
        plan: &[(usize, usize, f64)],
        captures: bool,
    ) -> Result<(Vec<ndarray::Array2<u8>>, Vec<ManifestEntry>)> {
        std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
        let patterns = capture_patterns(slm[0], slm[1], self.pattern_seed);
        for (k, p) in patterns.iter().enumerate() {
            tensorholo::io::save_u8_png(&out.join(format!("pattern_{k}.png")), p.view())?;
        }
        let entries = plan
            .iter()
            .enumerate()
            .map(|(i, &(p, c, d))| ManifestEntry {
                pattern: format!("pattern_{p}.png"),
                colour: COLOUR_KEYS[c].into(),
                distance_m: d,
                capture: captures.then(|| format!("capture_{i:02}.png")),
            })
            .collect();
        Ok((patterns, entries))
    }
}

/// Runs `holo calibrate model …`.
pub fn run(args: &ModelArgs) -> Result<()> {
    match &args.command {
        ModelCommand::Patterns { plan, out } => {
            plan.guard(out)?;
            let (_, slm, entries) = plan.resolve()?;
            let (_, manifest) = plan.write_patterns(out, slm, &entries, false)?;
            write_manifest(&out.join("manifest.json"), &manifest)?;
            let mut text = format!(
                "Capture plan for a {}x{} SLM ({} captures). For each line: show the pattern on the SLM with the \
                 colour's laser, focus the camera at the distance (signed, SLM -> focal plane), register the \
                 image to the SLM's pixel grid (docs/CALIBRATION.md), keep one exposure for the whole set with \
                 no pixel at full scale, and save it as an 8- or 16-bit grey PNG of the pattern's size; then add \
                 its name as \"capture\" to the entry of manifest.json.\n",
                slm[0],
                slm[1],
                manifest.len()
            );
            for (i, e) in manifest.iter().enumerate() {
                text += &format!(
                    "{i:2}: {} {} at {:+.2} mm -> capture_{i:02}.png\n",
                    e.pattern,
                    e.colour,
                    e.distance_m * 1e3
                );
            }
            tensorholo::io::write_atomic(&out.join("capture_plan.txt"), text.as_bytes())?;
            eprintln!(
                "wrote 8 patterns, manifest.json and capture_plan.txt ({} captures) to {}",
                manifest.len(),
                out.display()
            );
            Ok(())
        }
        ModelCommand::Simulate {
            plan,
            seed,
            noise,
            out,
        } => {
            plan.guard(out)?;
            if !(noise.is_finite() && (0.0..=0.5).contains(noise)) {
                bail!("--noise {noise}: give 0 to 0.5 (of full scale)");
            }
            let (setup, slm, entries) = plan.resolve()?;
            let (patterns, manifest) = plan.write_patterns(out, slm, &entries, true)?;
            let sim = simulate_display(slm, &setup, &patterns, &entries, *noise, *seed)?;
            let (captures, gain, truth) = (sim.captures, sim.gain, sim.truth);
            for (e, img) in manifest.iter().zip(&captures) {
                let name = e.capture.as_deref().expect("named");
                write_grey_png(&out.join(name), img.view(), 16)?;
            }
            write_manifest(&out.join("manifest.json"), &manifest)?;
            save_model(&out.join("hidden.json"), &truth)?;
            eprintln!(
                "wrote {} captures of a simulated {}x{} display (gain {gain:.4}, noise {noise}), manifest.json and \
                 its hidden parameters hidden.json to {}",
                captures.len(),
                slm[0],
                slm[1],
                out.display()
            );
            Ok(())
        }
        ModelCommand::Fit {
            captures,
            display,
            size,
            truth,
            calibration,
            iterations,
            kernel,
            out,
        } => {
            let mut inputs = vec![Input::file("--captures", captures)];
            inputs.extend(display.as_deref().map(|d| Input::file("--display", d)));
            inputs.extend(truth.as_deref().map(|t| Input::file("--truth", t)));
            inputs.extend(
                calibration
                    .as_deref()
                    .map(|c| Input::file("--calibration", c)),
            );
            guard("--out", out, &inputs)?;
            let (setup, slm) = optics_of(display.as_deref(), *size)?;
            let truth = truth
                .as_deref()
                .map(DisplayModel::load)
                .transpose()
                .context("--truth")?;
            let responses = match calibration.as_deref() {
                None => Default::default(),
                Some(path) => {
                    let cal = DisplayCalibration::read(path).context("--calibration")?;
                    cal.luts().map(|lut| match lut.representation() {
                        LutRepresentation::Linear => None,
                        r => Some(r.clone()),
                    })
                }
            };
            let options = FitOptions {
                setup,
                iterations: *iterations,
                kernel_side: *kernel,
                truth,
                responses,
            };
            let t = std::time::Instant::now();
            let report = fit(captures, &options).context("--captures")?;
            if let Some(s) = slm.filter(|s| *s != report.model.slm_size) {
                bail!(
                    "--size/--display: the SLM is {}x{}, the manifest's patterns {}x{}",
                    s[0],
                    s[1],
                    report.model.slm_size[0],
                    report.model.slm_size[1]
                );
            }
            for r in &report.residuals {
                eprintln!(
                    "{}: residual {:.5} (RMS, of full scale; the ideal display {:.5})",
                    r.capture, r.rms, r.ideal_rms
                );
            }
            if let Some(g) = report.gain {
                let powers: Vec<String> = COLOUR_KEYS
                    .iter()
                    .zip(&report.power)
                    .filter_map(|(k, p)| p.map(|p| format!("{k} {p:.4}")))
                    .collect();
                eprintln!(
                    "the set's gain {g:.5} (of full scale per unit intensity); each colour's source power \
                     against the brightest's: {}",
                    powers.join(", ")
                );
            }
            for w in &report.warnings {
                log::warn!("{w}");
            }
            for e in &report.truth_errors {
                eprintln!("{}: {} {:.5}", e.part, e.measure, e.error);
            }
            save_model(out, &report.model)?;
            eprintln!(
                "fitted {} captures in {:.2} s; wrote the display model {}",
                report.residuals.len(),
                t.elapsed().as_secs_f64(),
                out.display()
            );
            Ok(())
        }
    }
}

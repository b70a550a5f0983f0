//! `holo calibrate`: the display calibration of paper Methods (Eq. 12–13) on a bench: the 256 test patterns,
//! a per-pixel look-up table from the camera captures, the laser intensity map from diffuser captures, its
//! curves for inspection, the deep-black test of Fig. 11, and a simulated SLM to try it all without hardware
//! (`docs/CALIBRATION.md`).

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use tensorholo::display::DisplayProfile;
use tensorholo::optics::OpticalSetup;
use tensorholo::slm::calibrate::{calibrate, calibration_pattern, CalibrationOptions};
use tensorholo::slm::captures::{read_png_downsampled, Crop, PngCaptureDir};
use tensorholo::slm::file::COLOUR_NAMES;
use tensorholo::slm::intensity::{intensity_scale_map, IntensityFloor};
use tensorholo::slm::lut::CODES;
use tensorholo::slm::simulate::{write_grey_png, SimulatedSlm};
use tensorholo::slm::{
    black_test_codes, displayed_phase, filtered_intensity, DisplayCalibration, LutRepresentation,
    PhaseCurve, PhaseLut,
};

use crate::args::parse_size;
use crate::output::{guard, Input};

/// The `--red`, `--green`, `--blue` inputs that are given, as guard inputs of `kind`.
fn colour_inputs<'a>(
    paths: [&'a Option<PathBuf>; 3],
    folder: bool,
) -> impl Iterator<Item = Input<'a>> {
    ["--red", "--green", "--blue"]
        .into_iter()
        .zip(paths)
        .filter_map(move |(flag, p)| {
            let p = p.as_deref()?;
            Some(if folder {
                Input::folder(flag, p)
            } else {
                Input::file(flag, p)
            })
        })
}

/// The SLM a calibration is for: its size from `--size` or a display profile's `resolution`.
#[derive(Debug, Args)]
struct SlmArgs {
    /// Display profile (JSON, docs/DISPLAYS.md): the SLM size (`resolution`) and, where the command stores
    /// them, the lasers (`wavelengths_m`); --size and --wavelengths-m override its values.
    #[arg(long, value_name = "FILE")]
    display: Option<PathBuf>,
    /// SLM size HEIGHTxWIDTH (e.g. 1080x1920) [default: the --display profile's resolution].
    #[arg(long, value_parser = parse_size)]
    size: Option<(usize, usize)>,
}

/// The SLM the flags describe, its `--display` profile read once ([`SlmArgs::read`]).
struct Slm {
    profile: Option<DisplayProfile>,
    /// `--size`, else the profile's resolution, `(height, width)`.
    size: (usize, usize),
}

impl Slm {
    /// The lasers: `flag` (`--wavelengths-m`) if given, else the profile's, else the paper's.
    fn wavelengths_m(&self, flag: &Option<Vec<f64>>) -> Vec<f64> {
        match (flag, &self.profile) {
            (Some(w), _) => w.clone(),
            (None, Some(p)) => p.wavelengths_m.to_vec(),
            (None, None) => OpticalSetup::default().wavelengths_m.to_vec(),
        }
    }
}

impl SlmArgs {
    /// Reads the `--display` profile, if given, once, and the SLM size: `--size`, else the profile's
    /// resolution. Errors: unreadable or a bad profile (naming the key; an error even where --size overrides
    /// its resolution), or no size.
    fn read(&self) -> Result<Slm> {
        let profile = self
            .display
            .as_deref()
            .map(crate::args::read_profile)
            .transpose()?;
        let size = match (self.size, &profile) {
            (Some(s), _) => s,
            (None, Some(p)) => (p.resolution[0], p.resolution[1]),
            (None, None) => {
                bail!("give the SLM size: --size HEIGHTxWIDTH or --display PROFILE.json")
            }
        };
        Ok(Slm { profile, size })
    }

    /// The profile file as a guard input (it is read, never written).
    fn guard_input(&self) -> Option<Input<'_>> {
        Some(Input::file("--display", self.display.as_deref()?))
    }
}

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
        #[command(flatten)]
        slm: SlmArgs,
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
        #[command(flatten)]
        slm: SlmArgs,
        /// The SLM's area in the captures: x,y,width,height in camera pixels (default: the whole capture).
        #[arg(long)]
        crop: Option<String>,
        /// Tile side in SLM pixels (even; 0 = automatic: 4–16 px by SLM size, 12.5 MB at 1080p).
        #[arg(long, default_value_t = 0)]
        tile: usize,
        /// `tiled` (per-pixel) or `global` (the panel's mean curve).
        #[arg(long, default_value = "tiled")]
        representation: String,
        /// The lasers' wavelengths in metres, R,G,B (stored in the file; the pipeline refuses a calibration
        /// more than 1 nm from its optics) [default: 6.38e-7,5.2e-7,4.5e-7, or the --display profile's].
        #[arg(long, value_delimiter = ',')]
        wavelengths_m: Option<Vec<f64>>,
        /// Output calibration file (.holocal).
        #[arg(long)]
        out: PathBuf,
    },
    /// Write a calibration with one look-up table for the whole panel per colour, from the SLM maker's table
    /// (CSV rows `code,phase_rad`) or the gamma/range model φ(k) = range·(k/255)^gamma; colours without
    /// either keep the linear table. For panels without a per-pixel calibration yet.
    Global {
        #[command(flatten)]
        slm: SlmArgs,
        /// CSV tables of the red, green and blue lasers (`code,phase_rad`, 256 rows).
        #[arg(long)]
        red_csv: Option<PathBuf>,
        /// See --red-csv.
        #[arg(long)]
        green_csv: Option<PathBuf>,
        /// See --red-csv.
        #[arg(long)]
        blue_csv: Option<PathBuf>,
        /// The gamma model's phase at code 255 in radians, for the colours without a CSV (with --gamma).
        #[arg(long, requires = "gamma")]
        range_rad: Option<f32>,
        /// The gamma model's exponent (with --range-rad).
        #[arg(long, requires = "range_rad")]
        gamma: Option<f32>,
        /// The lasers' wavelengths in metres, R,G,B [default: 6.38e-7,5.2e-7,4.5e-7, or the --display
        /// profile's].
        #[arg(long, value_delimiter = ',')]
        wavelengths_m: Option<Vec<f64>>,
        /// Output calibration file (.holocal).
        #[arg(long)]
        out: PathBuf,
    },
    /// Add laser intensity maps to a calibration from diffuser captures (the SLM replaced by a diffuser, one
    /// PNG per laser, 8/16-bit grey or RGB, the beam's peak below full scale): 5×5 median, then the amplitude
    /// scale that flattens the display's brightness to a floor of the beam (docs/CALIBRATION.md). Writes a
    /// new file; --base is never modified.
    Intensity {
        /// Diffuser capture of the red laser.
        #[arg(long)]
        red: Option<PathBuf>,
        /// Diffuser capture of the green laser.
        #[arg(long)]
        green: Option<PathBuf>,
        /// Diffuser capture of the blue laser.
        #[arg(long)]
        blue: Option<PathBuf>,
        /// The calibration to add the maps to (its look-up tables and other maps are kept). Without it: linear
        /// look-up tables of --size or the --display profile's resolution.
        #[arg(long, required_unless_present_any = ["size", "display"], conflicts_with_all = ["size", "display"])]
        base: Option<PathBuf>,
        #[command(flatten)]
        slm: SlmArgs,
        /// The SLM's area in the captures: x,y,width,height in camera pixels (default: the whole capture).
        #[arg(long)]
        crop: Option<String>,
        /// Flatten the display to this percentile (0–100) of the filtered beam intensity; brighter pixels are
        /// dimmed to it, dimmer ones keep their amplitude.
        #[arg(long, default_value_t = 5.0)]
        floor_percentile: f32,
        /// Output calibration file (.holocal).
        #[arg(long)]
        out: PathBuf,
    },
    /// Write the deep-black test of paper Fig. 11 through a calibration's look-up tables (black_r.png,
    /// black_g.png, black_b.png: the double phase encoding of a black target, to display and photograph)
    /// and black.json: the black level and contrast the calibration's own curves predict for it and for the
    /// linear look-up table.
    Black {
        /// Calibration file.
        file: PathBuf,
        /// Output folder (created).
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
    /// The display's aberration (paper Eq. 14–19) from camera captures of focused spots (phase diversity):
    /// patterns, a simulated display and camera, and the fit into a tensorholo.aberration file
    /// (docs/ABERRATION.md, "Calibration from captures").
    Aberration(crate::calibrate_aberration::AberrationArgs),
    /// A display model (source, SLM crosstalk, phase response, zero order, aberration) fitted from camera
    /// captures, for `--refine N --display-model MODEL`: patterns and a capture plan, a simulated display,
    /// and the fit (docs/CALIBRATION.md, "The display model").
    Model(crate::calibrate_model::ModelArgs),
    /// Write the captures of a simulated SLM (spatially varying response, Gaussian beam, noise, dust; camera at
    /// 2× resolution) into OUT/red, OUT/green, OUT/blue, and its diffuser captures (the beam alone) as
    /// OUT/diffuser_red.png …, to try `holo calibrate lut` and `holo calibrate intensity` without hardware.
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
        CalibrateCommand::Patterns { slm, out } => {
            let inputs: Vec<Input> = slm.guard_input().into_iter().collect();
            guard("--out", out, &inputs)?;
            let size = slm.read()?.size;
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
            slm,
            crop,
            tile,
            representation,
            wavelengths_m,
            out,
        } => {
            let slm_read = slm.read()?;
            let size = &slm_read.size;
            let wavelengths_m = &slm_read.wavelengths_m(wavelengths_m);
            let crop: Option<Crop> = crop.as_deref().map(str::parse).transpose()?;
            if red.is_none() && green.is_none() && blue.is_none() {
                bail!(
                    "give the captures of at least one colour: --red DIR, --green DIR, --blue DIR"
                );
            }
            // Captures are folders: the calibration file may be neither one nor inside one.
            let inputs: Vec<Input> = colour_inputs([red, green, blue], true)
                .chain(slm.guard_input())
                .collect();
            guard("--out", out, &inputs)?;
            let mut cal = DisplayCalibration::linear(size.0, size.1)?;
            set_wavelengths(&mut cal, wavelengths_m)?;
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
        CalibrateCommand::Intensity {
            red,
            green,
            blue,
            base,
            slm,
            crop,
            floor_percentile,
            out,
        } => intensity(
            [red, green, blue],
            base.as_deref(),
            slm,
            crop.as_deref(),
            *floor_percentile,
            out,
        ),
        CalibrateCommand::Black { file, out } => black(file, out),
        CalibrateCommand::Global {
            slm,
            red_csv,
            green_csv,
            blue_csv,
            range_rad,
            gamma,
            wavelengths_m,
            out,
        } => {
            let csvs = [red_csv, green_csv, blue_csv];
            let inputs: Vec<Input> = ["--red-csv", "--green-csv", "--blue-csv"]
                .into_iter()
                .zip(csvs)
                .filter_map(|(flag, c)| Some(Input::file(flag, c.as_deref()?)))
                .chain(slm.guard_input())
                .collect();
            guard("--out", out, &inputs)?;
            let slm = slm.read()?;
            let mut cal = DisplayCalibration::linear(slm.size.0, slm.size.1)?;
            set_wavelengths(&mut cal, &slm.wavelengths_m(wavelengths_m))?;
            let model = match (range_rad, gamma) {
                (Some(r), Some(g)) => Some(PhaseCurve::gamma(*r, *g)?),
                _ => None,
            };
            for (c, csv) in csvs.into_iter().enumerate() {
                let curve = match csv {
                    Some(path) => {
                        let text = tensorholo::io::read_text(path)?;
                        PhaseCurve::from_csv(&text, &path.display().to_string())?
                    }
                    None => match &model {
                        Some(m) => m.clone(),
                        None => continue,
                    },
                };
                cal.colours[c].lut = PhaseLut::new(LutRepresentation::Global(curve));
            }
            cal.notes = format!(
                "holo calibrate global, tensorholo {}",
                env!("CARGO_PKG_VERSION")
            );
            cal.write(out)?;
            eprintln!("wrote {} ({})", out.display(), cal.summary());
            Ok(())
        }
        CalibrateCommand::Curves { file, color, out } => {
            let c = colour_index(color)?;
            guard("--out", out, &[Input::file("FILE", file)])?;
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
        CalibrateCommand::Aberration(args) => crate::calibrate_aberration::run(args),
        CalibrateCommand::Model(args) => crate::calibrate_model::run(args),
        CalibrateCommand::Simulate { size, seed, out } => {
            let sim = SimulatedSlm::new(size.0, size.1, *seed);
            sim.validate()?;
            for (c, name) in COLOUR_NAMES.iter().enumerate() {
                sim.write_captures(c, &out.join(name), &|_, _| {})?;
                let beam = sim.diffuser_capture(c)?;
                write_grey_png(&out.join(format!("diffuser_{name}.png")), beam.view(), 16)?;
            }
            let json = serde_json::to_string_pretty(&sim)?;
            tensorholo::io::write_atomic(&out.join("simulator.json"), json.as_bytes())?;
            eprintln!(
                "wrote 3 × 256 captures and 3 diffuser captures of a simulated {}×{} SLM to {} (parameters in \
                 simulator.json)",
                size.0,
                size.1,
                out.display()
            );
            Ok(())
        }
    }
}

/// `holo calibrate intensity`.
fn intensity(
    captures: [&Option<PathBuf>; 3],
    base: Option<&std::path::Path>,
    slm: &SlmArgs,
    crop: Option<&str>,
    floor_percentile: f32,
    out: &std::path::Path,
) -> Result<()> {
    let mut inputs: Vec<Input> = colour_inputs(captures, false).collect();
    inputs.extend(base.map(|b| Input::file("--base", b)));
    inputs.extend(slm.guard_input());
    guard("--out", out, &inputs)?;
    let crop: Option<Crop> = crop.map(str::parse).transpose()?;
    if captures.iter().all(|c| c.is_none()) {
        bail!("give the diffuser capture of at least one colour: --red FILE, --green FILE, --blue FILE");
    }
    let mut cal = match base {
        Some(b) => DisplayCalibration::read(b)?,
        None => {
            let (h, w) = slm.read()?.size;
            DisplayCalibration::linear(h, w)?
        }
    };
    let (h, w) = (cal.height, cal.width);
    for (c, capture) in captures.into_iter().enumerate() {
        let Some(path) = capture else { continue };
        let mut beam = vec![0f32; h * w];
        let mut clipped = vec![false; h * w];
        read_png_downsampled(path, (h, w), crop, &mut beam, &mut clipped)?;
        let beam = ndarray::Array2::from_shape_vec((h, w), beam)?;
        let (map, floor) =
            intensity_scale_map(beam.view(), IntensityFloor::Percentile(floor_percentile))
                .with_context(|| format!("{} capture {}", COLOUR_NAMES[c], path.display()))?;
        let kept = map.iter().map(|&s| (s * s) as f64).sum::<f64>() / map.len() as f64;
        eprintln!(
            "{}: display flattened to {:.1} % of the beam's peak; {:.0} % of the light kept on a white target",
            COLOUR_NAMES[c],
            100.0 * floor,
            100.0 * kept
        );
        cal.colours[c].intensity_scale = Some(map);
    }
    cal.write(out)?;
    eprintln!("wrote {} ({})", out.display(), cal.summary());
    Ok(())
}

/// `holo calibrate black`.
fn black(file: &std::path::Path, out: &std::path::Path) -> Result<()> {
    guard("--out", out, &[Input::file("FILE", file)])?;
    let cal = DisplayCalibration::read(file)?;
    let (h, w) = (cal.height, cal.width);
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let luts = cal.luts();
    let linear = PhaseLut::linear();
    let calibrated = black_test_codes(luts, h, w)?;
    let uncalibrated = black_test_codes([&linear; 3], h, w)?;
    // What the calibrated panel shows for each set of codes, by its own measured curves.
    let shown = |codes: &ndarray::Array3<u8>| -> Result<[f64; 3]> {
        Ok(filtered_intensity(
            displayed_phase(codes.view(), Some(&cal))?.view(),
        )?)
    };
    let (with, without) = (shown(&calibrated)?, shown(&uncalibrated)?);
    let mut report = serde_json::Map::new();
    for (c, name) in COLOUR_NAMES.iter().enumerate() {
        let file = format!("black_{}.png", &name[..1]);
        tensorholo::io::save_u8_png(&out.join(&file), calibrated.index_axis(ndarray::Axis(0), c))?;
        eprintln!(
            "{name}: predicted black level {:.2e} (contrast {:.0}:1) with the calibration, {:.2e} ({:.0}:1) \
             with the linear look-up table",
            with[c],
            1.0 / with[c],
            without[c],
            1.0 / without[c]
        );
        report.insert(
            name.to_string(),
            serde_json::json!({
                "pattern": file,
                "black_level_calibrated": with[c],
                "black_level_linear_lut": without[c],
                "contrast_calibrated": 1.0 / with[c],
                "contrast_linear_lut": 1.0 / without[c],
            }),
        );
    }
    report.insert("calibration".into(), cal.summary().into());
    report.insert(
        "note".into(),
        "black levels predicted by the calibration's own curves (Eq. 8-9 Fourier filter), relative to a \
         uniform pattern; photograph the patterns to measure the panel's"
            .into(),
    );
    let json = serde_json::to_string_pretty(&serde_json::Value::Object(report))?;
    tensorholo::io::write_atomic(&out.join("black.json"), json.as_bytes())?;
    eprintln!(
        "wrote black_r.png, black_g.png, black_b.png and black.json to {}",
        out.display()
    );
    Ok(())
}

/// `--wavelengths-m R,G,B` into `cal`.
fn set_wavelengths(cal: &mut DisplayCalibration, wavelengths_m: &[f64]) -> Result<()> {
    let [r, g, b] = wavelengths_m[..] else {
        bail!("--wavelengths-m needs 3 comma-separated values (R,G,B)");
    };
    for (col, wl) in cal.colours.iter_mut().zip([r, g, b]) {
        if !(wl > 0.0 && wl < 1e-5) {
            bail!("--wavelengths-m: {wl} m is not a laser wavelength in metres");
        }
        col.wavelength_m = wl;
    }
    Ok(())
}

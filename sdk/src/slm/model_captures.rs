//! The captures a display model is fitted from (docs/CALIBRATION.md "The display model"): the manifest
//! (`tensorholo.captures`), its test patterns, and captures of a simulated display with hidden parameters,
//! to try the fit without hardware.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use ndarray::Array2;
use num_complex::Complex32;
use serde::{Deserialize, Serialize};

use super::model::{
    capture_multiplier, intensity_of, ColourDisplay, ColourRuntime, Crosstalk, DisplayModel,
    SourceField, COLOUR_KEYS,
};
use crate::error::{HoloError, Result};
use crate::optics::{OpticalSetup, PropagationOptions, ZernikeCoefficients};
use crate::slm::captures::{png_size, read_png_downsampled};
use crate::slm::{LutRepresentation, PhaseCurve};
use crate::splitmix::SplitMix64;

/// Value of a capture manifest's `format` field.
pub const CAPTURES_FORMAT: &str = "tensorholo.captures";
/// Version of the capture manifest format.
pub const CAPTURES_VERSION: u32 = 1;
/// The largest share of a capture's pixels at full scale the fit accepts: 1 % (fewer are left out of it).
pub const MAX_SATURATED: f64 = 0.01;

/// One entry of a capture manifest: paths relative to the manifest's folder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ManifestEntry {
    /// The SLM's 8-bit codes, a grey PNG `[H, W]`.
    pub pattern: String,
    /// `red`, `green` or `blue`.
    pub colour: String,
    /// Signed distance in metres from the SLM to the camera's focal plane (`docs/CONVENTIONS.md` §4).
    pub distance_m: f64,
    /// The capture, an 8- or 16-bit grey PNG `[H, W]` linear in intensity (absent in a plan to fill in).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub capture: Option<String>,
}

/// A capture manifest (`tensorholo.captures` version 1, docs/CALIBRATION.md): what a bench writes, and what
/// `holo calibrate model patterns` writes without the `capture` entries.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ManifestFile {
    /// [`CAPTURES_FORMAT`].
    pub format: String,
    /// [`CAPTURES_VERSION`].
    pub version: u32,
    /// The entries.
    pub captures: Vec<ManifestEntry>,
}

/// One capture as the fit reads it.
#[derive(Debug, Clone)]
pub(crate) struct Capture {
    /// The manifest's name of the capture file.
    pub name: String,
    /// Index into [`CaptureSet::patterns`].
    pub pattern: usize,
    /// Channel (0 R, 1 G, 2 B).
    pub colour: usize,
    /// Signed distance SLM → focal plane, metres.
    pub distance_m: f64,
    /// Intensity in units of full scale, `[H, W]` row-major.
    pub intensity: Vec<f32>,
    /// Pixels the fit uses (those not at full scale).
    pub valid: Vec<bool>,
}

/// A manifest's patterns and captures, checked and read.
#[derive(Debug, Clone)]
pub(crate) struct CaptureSet {
    /// The SLM size `(height, width)`, that of every pattern.
    pub size: (usize, usize),
    /// The patterns' codes, `[H, W]` row-major each.
    pub patterns: Vec<Vec<u8>>,
    /// The captures.
    pub captures: Vec<Capture>,
}

fn entry_error(i: usize, what: &str, why: impl std::fmt::Display) -> HoloError {
    HoloError::InvalidData(format!("capture manifest `captures[{i}]` ({what}): {why}"))
}

/// Reads a grey PNG `path` of `size` (or any size when `None`) as intensities in `[0, 1]` and its full-scale
/// flags.
fn read_grey(
    path: &Path,
    size: Option<(usize, usize)>,
) -> Result<(usize, usize, Vec<f32>, Vec<bool>)> {
    let (h, w) = png_size(path)?;
    if let Some(s) = size.filter(|&s| s != (h, w)) {
        return Err(HoloError::ShapeMismatch {
            what: format!("`{}` vs its pattern", path.display()),
            expected: vec![s.0, s.1],
            got: vec![h, w],
        });
    }
    let mut out = vec![0.0; h * w];
    let mut clipped = vec![false; h * w];
    read_png_downsampled(path, (h, w), None, &mut out, &mut clipped)?;
    Ok((h, w, out, clipped))
}

impl CaptureSet {
    /// Reads the manifest `path` (`tensorholo.captures` version 1, docs/CALIBRATION.md), its patterns and
    /// captures (paths relative to its folder). Entries without a capture are skipped.
    ///
    /// Errors: [`HoloError::Io`] for an unreadable manifest; [`HoloError::InvalidData`] for another format,
    /// no capture at all, and each bad entry, naming it (`captures[3]`) and its file: a missing or unreadable
    /// file, an unknown colour, a non-finite distance, the same pattern, colour and distance twice, one
    /// capture file in two entries, patterns of different sizes, a capture of another size than its pattern,
    /// a saturated capture (more than [`MAX_SATURATED`] of its pixels at full scale).
    pub(crate) fn read(path: &Path) -> Result<Self> {
        let text = crate::io::read_text(path)?;
        let file: ManifestFile = crate::io::parse_json_object(&text, "a capture manifest")
            .map_err(|e| {
                HoloError::InvalidData(format!(
                    "`{}` is not a capture manifest ({CAPTURES_FORMAT} version {CAPTURES_VERSION}): {e}",
                    path.display()
                ))
            })?;
        if file.format != CAPTURES_FORMAT || file.version != CAPTURES_VERSION {
            return Err(HoloError::InvalidData(format!(
                "`{}`: format `{}` version {}, expected {CAPTURES_FORMAT} version {CAPTURES_VERSION}",
                path.display(),
                file.format,
                file.version
            )));
        }
        let dir = path.parent().unwrap_or(Path::new("."));
        let mut set = CaptureSet {
            size: (0, 0),
            patterns: Vec::new(),
            captures: Vec::new(),
        };
        let mut pattern_index: HashMap<PathBuf, usize> = HashMap::new();
        let mut seen: HashMap<(usize, usize, u64), usize> = HashMap::new();
        let mut files: HashMap<PathBuf, usize> = HashMap::new();
        for (i, e) in file.captures.iter().enumerate() {
            let colour = COLOUR_KEYS
                .iter()
                .position(|&k| k == e.colour)
                .ok_or_else(|| {
                    entry_error(
                        i,
                        &e.pattern,
                        format!("colour `{}`: red, green or blue", e.colour),
                    )
                })?;
            if !e.distance_m.is_finite() {
                return Err(entry_error(
                    i,
                    &e.pattern,
                    format!("distance_m {} is not finite", e.distance_m),
                ));
            }
            let pattern_path = crate::io::resolve(&dir.join(&e.pattern));
            let p = match pattern_index.get(&pattern_path) {
                Some(&p) => p,
                None => {
                    let (h, w, v, _) = read_grey(&pattern_path, None)
                        .map_err(|err| entry_error(i, &e.pattern, err))?;
                    if set.patterns.is_empty() {
                        set.size = (h, w);
                    } else if set.size != (h, w) {
                        return Err(entry_error(
                            i,
                            &e.pattern,
                            format!(
                                "pattern of {h}×{w}, the manifest's first is {}×{}: one SLM size per manifest",
                                set.size.0, set.size.1
                            ),
                        ));
                    }
                    set.patterns
                        .push(v.iter().map(|&x| (x * 255.0).round() as u8).collect());
                    pattern_index.insert(pattern_path, set.patterns.len() - 1);
                    set.patterns.len() - 1
                }
            };
            if let Some(j) = seen.insert((p, colour, e.distance_m.to_bits()), i) {
                return Err(entry_error(
                    i,
                    &e.pattern,
                    format!(
                        "the same pattern, colour and distance as captures[{j}]: each pattern appears once \
                         per distance and colour"
                    ),
                ));
            }
            let Some(name) = &e.capture else { continue };
            let capture_path = crate::io::resolve(&dir.join(name));
            if let Some(j) = files.insert(capture_path.clone(), i) {
                return Err(entry_error(
                    i,
                    name,
                    format!("the capture file of captures[{j}] too: one file per entry"),
                ));
            }
            let (_, _, intensity, clipped) = read_grey(&capture_path, Some(set.size))
                .map_err(|err| entry_error(i, name, err))?;
            let saturated = clipped.iter().filter(|&&c| c).count();
            if saturated as f64 > MAX_SATURATED * clipped.len() as f64 {
                return Err(entry_error(
                    i,
                    name,
                    format!(
                        "{saturated} of {} pixels at full scale (more than {} %): shorten the exposure",
                        clipped.len(),
                        MAX_SATURATED * 100.0
                    ),
                ));
            }
            set.captures.push(Capture {
                name: name.clone(),
                pattern: p,
                colour,
                distance_m: e.distance_m,
                intensity,
                valid: clipped.iter().map(|&c| !c).collect(),
            });
        }
        if set.captures.is_empty() {
            return Err(HoloError::InvalidData(format!(
                "`{}` lists no capture: fill in the `capture` entries",
                path.display()
            )));
        }
        Ok(set)
    }
}

/// The 8 test patterns `[height, width]` that determine every part of a display model from 3 distances:
/// random codes (two seeds from `seed`), a smooth phase, two 1-pixel checkerboards (0/128 and 64/224),
/// 1-pixel gratings along rows and along columns (0/128 and 0/160), and a blazed grating of period 8.
pub fn capture_patterns(height: usize, width: usize, seed: u64) -> Vec<Array2<u8>> {
    let mut rng = SplitMix64::new(seed);
    let mut random =
        || Array2::from_shape_simple_fn((height, width), || (rng.next_f64() * 256.0) as u8);
    let (a, b) = (random(), random());
    let f =
        |g: &dyn Fn(usize, usize) -> u8| Array2::from_shape_fn((height, width), |(i, j)| g(i, j));
    let smooth = f(&|i, j| {
        let (x, y) = (j as f64 / width as f64, i as f64 / height as f64);
        (127.5
            + 120.0
                * (std::f64::consts::TAU * (x + 0.5 * y)).sin()
                * (std::f64::consts::PI * y).cos()) as u8
    });
    vec![
        a,
        b,
        smooth,
        f(&|i, j| if (i + j) % 2 == 0 { 0 } else { 128 }),
        f(&|i, j| if (i + j) % 2 == 0 { 64 } else { 224 }),
        f(&|_, j| if j % 2 == 0 { 0 } else { 128 }),
        f(&|i, _| if i % 2 == 0 { 0 } else { 160 }),
        f(&|_, j| ((j % 8) * 32) as u8),
    ]
}

/// A simulated display's hidden parameters for colour `colour` of an SLM of `size` `[height, width]`, drawn
/// with `seed` from the ranges of docs/CALIBRATION.md: a Gaussian beam (centre within ±0.2, waist 1.3–2.0 of
/// the half-width; its wavefront tilted by ±0.5 rad toward each edge, curved by ±0.8 rad at the edges and
/// ±0.2 rad more along one axis than the other), a response `2π·(s·x + r₂·x(1−x) + r₃·(−2x³ + 3x² − x))` (`s` 0.92–1.08, `r₂` ±0.25, `r₃`
/// ±0.15), crosstalk of 1.5–4 % to each horizontal and 1–3 % to each vertical neighbour (0–0.5 % diagonal, a
/// kernel summing to 1), a zero order of modulus 0.03–0.08 and a focus and astigmatism of ±0.4 rad each.
pub(crate) fn draw_display(size: [usize; 2], colour: usize, seed: u64) -> DisplayModel {
    let mut rng = SplitMix64::new(seed ^ 0x5eed_d15b);
    let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.next_f64();
    let (x0, y0, w) = (u(-0.2, 0.2), u(-0.2, 0.2), u(1.3, 2.0));
    let w2 = w * w;
    let (s, r2, r3) = (u(0.92, 1.08), u(-0.25, 0.25), u(-0.15, 0.15));
    let (h, v, d) = (u(0.015, 0.04), u(0.01, 0.03), u(0.0, 0.005));
    let (zm, za) = (u(0.03, 0.08), u(0.0, std::f64::consts::TAU));
    let (tx, ty, curve, twist) = (u(-0.5, 0.5), u(-0.5, 0.5), u(-0.8, 0.8), u(-0.2, 0.2));
    let aberration = ZernikeCoefficients {
        focus: u(-0.4, 0.4),
        astigmatism_vertical: u(-0.4, 0.4),
        astigmatism_oblique: u(-0.4, 0.4),
        ..Default::default()
    };
    let mut model = DisplayModel {
        slm_size: size,
        ..Default::default()
    };
    model.colours[colour] = ColourDisplay {
        source: Some(SourceField {
            log_amplitude: [2.0 * x0 / w2, 2.0 * y0 / w2, -1.0 / w2, -1.0 / w2, 0.0],
            phase_rad: [tx, ty, curve + twist, curve - twist, 0.0],
        }),
        response: Some(LutRepresentation::Global(
            response_curve(s, r2, r3).expect("the drawn ranges keep the curve monotone"),
        )),
        crosstalk: Some(Crosstalk {
            size: [3, 3],
            weights: vec![d, v, d, h, 1.0 - 2.0 * (h + v) - 4.0 * d, h, d, v, d],
        }),
        zero_order: Some([zm * za.cos(), zm * za.sin()]),
        aberration: Some(aberration),
    };
    model
}

/// The response basis at `x = k/256`: `[x, x(1−x), −2x³ + 3x² − x]` times `2π`.
pub(crate) fn response_basis(k: usize) -> [f64; 3] {
    let x = k as f64 / 256.0;
    let t = std::f64::consts::TAU;
    [
        t * x,
        t * x * (1.0 - x),
        t * (-2.0 * x * x * x + 3.0 * x * x - x),
    ]
}

/// The curve `s·b₀ + r₂·b₁ + r₃·b₂` ([`response_basis`]).
///
/// Errors: as `PhaseCurve::new` (a curve that decreases).
pub(crate) fn response_curve(s: f64, r2: f64, r3: f64) -> Result<PhaseCurve> {
    let phases: Vec<f32> = (0..256)
        .map(|k| {
            let b = response_basis(k);
            (s * b[0] + r2 * b[1] + r3 * b[2]) as f32
        })
        .collect();
    PhaseCurve::new(&phases)
}

/// A per-pixel response over an SLM of `[height, width]` in tiles of `tile` pixels: the curve of
/// [`response_curve`] whose `s` runs from 0.9 at the top left to 1.1 at the bottom right and whose `r₂` turns
/// from −0.2 to 0.2 across the rows (a panel whose cell gap varies).
#[cfg(test)]
pub(crate) fn varying_response(height: usize, width: usize, tile: usize) -> LutRepresentation {
    let (rows, cols) = (height.div_ceil(tile), width.div_ceil(tile));
    let curves = (0..rows * cols)
        .map(|t| {
            let (y, x) = ((t / cols) as f64, (t % cols) as f64);
            let (fy, fx) = (y / (rows - 1).max(1) as f64, x / (cols - 1).max(1) as f64);
            response_curve(0.9 + 0.1 * (fy + fx), 0.4 * fx - 0.2, 0.0).expect("monotone")
        })
        .collect();
    LutRepresentation::Tiled(
        crate::slm::TiledCurves::new(height, width, tile, tile, curves).expect("a valid tiling"),
    )
}

/// Captures `[H, W]` of `model`'s display on `setup` for each `(pattern index, colour, distance_m)` of
/// `plan`, with one gain for the set (the brightest pixel at 0.85 of full scale) and Gaussian noise of
/// standard deviation `noise` (of full scale) from `seed`, clamped to `[0, 1]`. Returns the captures and the
/// gain.
///
/// Errors: [`HoloError::ShapeMismatch`] for patterns of another size than the model's; those of the
/// propagation.
pub(crate) fn simulate_captures(
    model: &DisplayModel,
    setup: &OpticalSetup,
    patterns: &[Array2<u8>],
    plan: &[(usize, usize, f64)],
    noise: f32,
    seed: u64,
) -> Result<(Vec<Array2<f32>>, f64)> {
    let [h, w] = model.slm_size;
    let mut out = Vec::with_capacity(plan.len());
    let mut field = Vec::new();
    let mut unit = vec![Complex32::new(0.0, 0.0); h * w];
    for &(p, colour, distance_m) in plan {
        let pattern = patterns.get(p).ok_or_else(|| {
            HoloError::InvalidData(format!("the plan names pattern {p} of {}", patterns.len()))
        })?;
        model.check_size(pattern.dim().0, pattern.dim().1)?;
        let part = &model.colours[colour];
        let mut runtime = ColourRuntime::new(part, h, w);
        let drive: Vec<f32> = pattern.iter().map(|&c| f32::from(c)).collect();
        runtime.forward(&drive, &mut unit);
        let (prop, m) = capture_multiplier(
            setup,
            PropagationOptions::default(),
            colour,
            (h, w),
            distance_m,
            part.aberration.as_ref(),
        )?;
        out.push(intensity_of(&prop, &m, &unit, &mut field));
    }
    let peak = out.iter().flatten().fold(0.0f32, |a, &b| a.max(b));
    let gain = if peak > 0.0 {
        0.85 / f64::from(peak)
    } else {
        1.0
    };
    let mut rng = SplitMix64::new(seed);
    let captures = out
        .into_iter()
        .map(|v| {
            let a = v
                .into_iter()
                .map(|x| (x * gain as f32 + noise * gaussian(&mut rng)).clamp(0.0, 1.0))
                .collect();
            Array2::from_shape_vec((h, w), a).expect("the grid's size")
        })
        .collect();
    Ok((captures, gain))
}

/// A simulated display and its captures ([`simulate_display`]).
#[derive(Debug, Clone)]
pub struct SimulatedCaptures {
    /// The hidden parameters: per colour of the plan, parts drawn from the ranges of docs/CALIBRATION.md
    /// (seed `seed + colour`); the other colours ideal.
    pub truth: DisplayModel,
    /// Per plan entry the capture `[H, W]`, in units of full scale.
    pub captures: Vec<Array2<f32>>,
    /// The set's gain `g` (the brightest pixel at 0.85 of full scale).
    pub gain: f64,
}

/// Captures of a simulated display of SLM size `size` `[height, width]` on `setup`, its hidden parameters
/// drawn with `seed` for each colour `plan` names (the ranges of docs/CALIBRATION.md), for each
/// `(pattern index, colour, distance_m)` of `plan`: one gain for the set, Gaussian noise of standard deviation
/// `noise` (of full scale), clamped to `[0, 1]`.
///
/// Errors: [`HoloError::InvalidData`] for a plan naming a pattern that is not there, a colour above 2, a
/// non-finite distance or noise; [`HoloError::ShapeMismatch`] for patterns of another size; those of the
/// propagation.
pub fn simulate_display(
    size: [usize; 2],
    setup: &OpticalSetup,
    patterns: &[Array2<u8>],
    plan: &[(usize, usize, f64)],
    noise: f32,
    seed: u64,
) -> Result<SimulatedCaptures> {
    if plan.iter().any(|e| e.1 > 2 || !e.2.is_finite()) || !noise.is_finite() {
        return Err(HoloError::InvalidData(
            "the simulated plan's colours are 0 to 2, its distances and noise finite".into(),
        ));
    }
    let mut truth = DisplayModel {
        slm_size: size,
        ..Default::default()
    };
    for c in 0..3 {
        if plan.iter().any(|e| e.1 == c) {
            truth.colours[c] =
                draw_display(size, c, seed.wrapping_add(c as u64)).colours[c].clone();
        }
    }
    let (captures, gain) = simulate_captures(&truth, setup, patterns, plan, noise, seed)?;
    Ok(SimulatedCaptures {
        truth,
        captures,
        gain,
    })
}

/// A standard normal deviate (Box–Muller).
fn gaussian(rng: &mut SplitMix64) -> f32 {
    let u1 = rng.next_f64().max(1e-300);
    let u2 = rng.next_f64();
    ((-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()) as f32
}

#[cfg(test)]
mod tests;

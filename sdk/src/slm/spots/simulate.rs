//! A simulated display with a hidden aberration and its camera, to try the spot calibration without
//! hardware (paper Eq. 14–19).
//!
//! **Display.** Each pattern PNG is read back as the SLM shows it (linear look-up table, phase `2π·code/256`),
//! Fourier filtered (`ρ ≤ 1`, Eq. 8–9), given the hidden aberration `exp(i·ΣZ_j(ρ, θ))` of its colour and
//! distance, and propagated by `d` (angular spectrum, carrier removed): the focal plane's spectrum `U`.
//!
//! **Camera.** Not the fit's discretisation: the focal field is evaluated by a direct (matrix) Fourier sum
//! of `U` at 2× the camera's sampling, `camera_scale` camera pixels per SLM pitch, its intensity binned 2×2
//! into camera pixels of a `frame_px × frame_px` frame in which the spot lands at a random sub-pixel position
//! (the same for the captures of one distance). Each capture gets its own exposure (its peak at 0.55–1.15 of
//! full scale, so some saturate), the distance a black level of 0.01–0.05, then Gaussian noise of variance
//! `noise² + signal/full_well` (read noise and shot noise, full-scale units), and quantisation to 8 or 16
//! bits with saturation at full scale.
//!
//! **Truth.** Per distance, the first colour of the plan has coefficients uniform in `±max_rad`; the others
//! follow by `super::wavelength_scaled`. Written as `hidden.json` (a `tensorholo.aberration` file).

use std::f64::consts::TAU;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use ndarray::Array2;
use num_complex::Complex64;
use rayon::prelude::*;

use super::{fft2, wavelength_scaled, SpotPlan, HIDDEN_FILE};
use crate::display::{AberrationProfile, AberrationSample};
use crate::error::{invalid, HoloError, Result};
use crate::optics::carrier_free_phase_rad;
use crate::optics::fft::signed_index;
use crate::optics::ZernikeCoefficients;
use crate::slm::simulate::write_grey_png;
use crate::splitmix::{splitmix64, SplitMix64};

/// The simulated camera and the hidden aberration's size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimulateOptions {
    /// Seed of the hidden coefficients, the spot positions, exposures and noise.
    pub seed: u64,
    /// Largest `|coefficient|` of the hidden aberration, radians at `ρ = 1` (0–3).
    pub max_rad: f64,
    /// Read noise, standard deviation in units of full scale (0–0.5).
    pub noise: f64,
    /// Full-well capacity in electrons at full scale (shot noise); 0: none.
    pub full_well: f64,
    /// PNG bit depth of the captures: 8 or 16.
    pub bit_depth: u8,
    /// Side of the camera frame in pixels (≥ the plan's window; 0: 1.5× the window).
    pub frame_px: usize,
}

impl Default for SimulateOptions {
    fn default() -> Self {
        Self {
            seed: 1,
            max_rad: 1.0,
            noise: 0.005,
            full_well: 10_000.0,
            bit_depth: 8,
            frame_px: 0,
        }
    }
}

impl SimulateOptions {
    /// Checks the fields. Errors: [`HoloError::InvalidParameter`] naming the field.
    pub(crate) fn validate(&self, window_px: usize) -> Result<()> {
        if !(self.max_rad.is_finite() && (0.0..=3.0).contains(&self.max_rad)) {
            return Err(invalid(
                "max_rad",
                format!("must lie within 0–3 rad, got {}", self.max_rad),
            ));
        }
        if !(self.noise.is_finite() && (0.0..=0.5).contains(&self.noise)) {
            return Err(invalid(
                "noise",
                format!("must lie within 0–0.5 of full scale, got {}", self.noise),
            ));
        }
        if !(self.full_well.is_finite() && self.full_well >= 0.0) {
            return Err(invalid(
                "full_well",
                format!("must be ≥ 0 electrons, got {}", self.full_well),
            ));
        }
        if self.bit_depth != 8 && self.bit_depth != 16 {
            return Err(invalid(
                "bit_depth",
                format!("must be 8 or 16, got {}", self.bit_depth),
            ));
        }
        let frame = self.frame(window_px);
        if frame < window_px || frame > 4096 {
            return Err(invalid(
                "frame_px",
                format!("must lie within the window ({window_px}) and 4096 pixels, got {frame}"),
            ));
        }
        Ok(())
    }

    fn frame(&self, window_px: usize) -> usize {
        if self.frame_px == 0 {
            window_px + window_px / 2
        } else {
            self.frame_px
        }
    }
}

/// Gaussian deviate (Box–Muller) from a SplitMix64 stream.
fn gaussian(rng: &mut SplitMix64) -> f64 {
    let u1 = 1.0 - rng.next_f64();
    let u2 = rng.next_f64();
    (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
}

/// The hidden aberration of the simulated display for `plan` (module docs), with the plan's display.
///
/// Errors: as [`AberrationProfile::new`] (none for a valid plan).
pub(crate) fn hidden_profile(
    plan: &SpotPlan,
    seed: u64,
    max_rad: f64,
) -> Result<AberrationProfile> {
    let reference = plan.colour_indices()?[0];
    let mut rng = SplitMix64::new(splitmix64(seed ^ 0x5EED_AB3E));
    let samples = plan
        .distances_m
        .iter()
        .map(|&d| {
            let z = ZernikeCoefficients::from_array(std::array::from_fn(|_| {
                max_rad * (2.0 * rng.next_f64() - 1.0)
            }));
            AberrationSample {
                distance_m: d,
                coefficients: std::array::from_fn(|c| {
                    wavelength_scaled(&z, plan.wavelengths_m[reference], plan.wavelengths_m[c])
                }),
            }
        })
        .collect();
    Ok(AberrationProfile::new(samples)?.with_display(plan.wavelengths_m, plan.pixel_pitch_m))
}

/// Reads a pattern PNG as 8-bit codes `[height, width]`. Errors: [`HoloError::Image`] naming the file,
/// [`HoloError::InvalidData`] naming it for another size than the plan's SLM.
fn read_pattern(path: &Path, size: [usize; 2]) -> Result<Array2<u8>> {
    let img = image::open(path)
        .map_err(|source| HoloError::Image {
            path: path.to_path_buf(),
            source,
        })?
        .to_luma8();
    let (w, h) = img.dimensions();
    if [h as usize, w as usize] != size {
        return Err(HoloError::InvalidData(format!(
            "pattern `{}` is {w}×{h} pixels, the plan's SLM {}×{}",
            path.display(),
            size[1],
            size[0]
        )));
    }
    Array2::from_shape_vec((h as usize, w as usize), img.into_raw())
        .map_err(|e| HoloError::Internal(format!("pattern buffer: {e}")))
}

/// The focal plane's spectrum `U` `[h, w]` (FFT order) of `codes` shown at wavelength `lambda` (metres)
/// through the Fourier filter and the aberration `z`, propagated by `d` metres.
fn focal_spectrum(
    codes: &Array2<u8>,
    pitch: f64,
    lambda: f64,
    d: f64,
    z: &ZernikeCoefficients,
) -> Vec<Complex64> {
    let (h, w) = codes.dim();
    let mut u: Vec<Complex64> = codes
        .iter()
        .map(|&c| Complex64::from_polar(1.0, TAU * c as f64 / 256.0))
        .collect();
    fft2(&mut u, h, w, false);
    let f_n = 0.5 / pitch;
    for (i, v) in u.iter_mut().enumerate() {
        let fx = signed_index(i % w, w) as f64 / (w as f64 * pitch);
        let fy = signed_index(i / w, h) as f64 / (h as f64 * pitch);
        let (rx, ry) = (fx / f_n, fy / f_n);
        let f2 = fx * fx + fy * fy;
        *v = match carrier_free_phase_rad(lambda, d, f2) {
            Some(p) if rx * rx + ry * ry <= 1.0 => {
                *v * Complex64::from_polar(1.0, p + z.phase_xy(rx, ry))
            }
            _ => Complex64::default(),
        };
    }
    u
}

/// The camera's intensity `[frame, frame]` (arbitrary units) of the focal spectrum `u` `[h, w]`, the SLM's
/// centre imaged at camera pixel `(cx, cy)`, `scale` camera pixels per SLM pitch, sampled 2× finer and
/// binned 2×2.
///
/// Memory besides the result: `h × 2·frame` complex values (the transform along rows) and a few rows; the
/// phase factors are made one row or column at a time and the fine field one row at a time (a 4096-pixel
/// frame of a 1080-row SLM: 141 MiB, where the whole fine field and both factor tables took 1.5 GiB).
fn camera_intensity(
    u: &[Complex64],
    h: usize,
    w: usize,
    scale: f64,
    frame: usize,
    centre: (f64, f64),
) -> Vec<f64> {
    let fine = 2 * frame;
    // Fine sample j sits at camera coordinate (j + 0.5)/2, i.e. SLM coordinate centre_slm + (that − c)/scale;
    // frequency index k of an axis of `len` samples contributes e^{2πi·f_k·x_j}.
    let coords = |c: f64, centre_slm: f64| -> Vec<f64> {
        (0..fine)
            .map(|j| centre_slm + ((j as f64 + 0.5) / 2.0 - c) / scale)
            .collect()
    };
    let factor = |k: usize, len: usize, x: f64| {
        Complex64::from_polar(1.0, TAU * (signed_index(k, len) as f64 / len as f64) * x)
    };
    let (xs, ys) = (
        coords(centre.0, (w / 2) as f64),
        coords(centre.1, (h / 2) as f64),
    );
    // Along rows: g[ky][j] = Σ_kx u[ky][kx]·e^{2πi f_kx x_j}, summed in increasing kx as before.
    let mut g = vec![Complex64::default(); h * fine];
    let mut ex = vec![Complex64::default(); fine];
    for kx in 0..w {
        if (0..h).all(|ky| u[ky * w + kx] == Complex64::default()) {
            continue;
        }
        for (e, &x) in ex.iter_mut().zip(&xs) {
            *e = factor(kx, w, x);
        }
        for ky in 0..h {
            let v = u[ky * w + kx];
            if v == Complex64::default() {
                continue;
            }
            for (o, e) in g[ky * fine..(ky + 1) * fine].iter_mut().zip(&ex) {
                *o += v * e;
            }
        }
    }
    // Down columns, one fine row at a time, binned 2×2 into the camera's pixels.
    let mut img = vec![0f64; frame * frame];
    let mut row = vec![Complex64::default(); fine];
    for (i, &y) in ys.iter().enumerate() {
        row.fill(Complex64::default());
        for ky in 0..h {
            let e = factor(ky, h, y);
            for (o, v) in row.iter_mut().zip(&g[ky * fine..(ky + 1) * fine]) {
                *o += e * v;
            }
        }
        let out = &mut img[(i / 2) * frame..(i / 2 + 1) * frame];
        for (x, v) in row.iter().enumerate() {
            out[x / 2] += 0.25 * v.norm_sqr();
        }
    }
    img
}

/// Bytes one simulated capture holds at its peak: the focal spectrum and the row transform (complex), the
/// intensity (f64), the noisy capture (f32) and its PNG samples.
fn capture_bytes(slm: [usize; 2], frame: usize) -> usize {
    let [h, w] = slm;
    16 * h * w + 16 * h * 2 * frame + (8 + 4 + 2) * frame * frame
}

/// The memory simulated captures may hold at once: captures run in parallel up to the session's threads, as
/// many as fit (at least one).
const SIMULATE_BUDGET_BYTES: usize = 1 << 30;

/// Simulates the captures of every pattern of `plan` (read from `patterns`) into `out` (created) under the
/// names the plan expects ([`SpotPlan::capture_name`]), and writes `out/hidden.json`. `progress(done,
/// total)` after each capture. Returns the hidden profile. Every pattern is read and checked before anything
/// is written. Deterministic for a seed (captures run in parallel, each from its own random stream).
///
/// Errors: [`HoloError::InvalidParameter`] for bad options; a missing or unreadable pattern
/// ([`HoloError::Image`]) or one of another size ([`HoloError::InvalidData`]), naming the file; write
/// errors naming the file.
pub fn simulate_captures(
    plan: &SpotPlan,
    patterns: &Path,
    out: &Path,
    options: &SimulateOptions,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<AberrationProfile> {
    plan.validate()?;
    options.validate(plan.window_px)?;
    let hidden = hidden_profile(plan, options.seed, options.max_rad)?;
    let frame = options.frame(plan.window_px);
    let colours = plan.colour_indices()?;
    let mut jobs = Vec::new();
    for &c in &colours {
        for i in 0..plan.distances_m.len() {
            for k in 0..plan.diversities.len() {
                let codes = read_pattern(
                    &patterns.join(SpotPlan::pattern_name(c, i, k)),
                    plan.slm_size,
                )?;
                jobs.push((c, i, k, codes));
            }
        }
    }
    std::fs::create_dir_all(out).map_err(|source| HoloError::Io {
        path: out.to_path_buf(),
        source,
    })?;
    let done = AtomicUsize::new(0);
    let total = jobs.len();
    // As many captures at once as the budget holds (a 4096-pixel frame of a 1080 × 1920 SLM: ~400 MiB each).
    let at_once = (SIMULATE_BUDGET_BYTES / capture_bytes(plan.slm_size, frame))
        .clamp(1, rayon::current_num_threads());
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(at_once)
        .build()
        .map_err(|e| HoloError::Internal(format!("capture simulation threads: {e}")))?;
    pool.install(|| {
        jobs.par_iter().try_for_each(|(c, i, k, codes)| {
            let (c, i, k) = (*c, *i, *k);
            let d = plan.distances_m[i];
            let z = hidden.samples()[i].coefficients[c];
            let u = focal_spectrum(codes, plan.pixel_pitch_m, plan.wavelengths_m[c], d, &z);
            // The spot's position and black level: per colour and distance.
            let mut place = SplitMix64::new(splitmix64(
                options.seed ^ (((c * 64 + i) as u64) << 20) ^ 0x0B1A_5ED0,
            ));
            let margin = (frame - plan.window_px) as f64 / 2.0;
            let centre = (
                frame as f64 / 2.0 + margin * (2.0 * place.next_f64() - 1.0) * 0.9,
                frame as f64 / 2.0 + margin * (2.0 * place.next_f64() - 1.0) * 0.9,
            );
            let black = 0.01 + 0.04 * place.next_f64();
            let img = camera_intensity(
                &u,
                plan.slm_size[0],
                plan.slm_size[1],
                plan.camera_scale,
                frame,
                centre,
            );
            let peak = img.iter().cloned().fold(0.0, f64::max);
            let mut rng = SplitMix64::new(splitmix64(
                options.seed ^ ((((c * 64 + i) * 64 + k) as u64) << 24) ^ 0x00CA_3E4A,
            ));
            let exposure = (0.55 + 0.6 * rng.next_f64()) / peak.max(f64::MIN_POSITIVE);
            let captured = Array2::from_shape_fn((frame, frame), |(y, x)| {
                let s = exposure * img[y * frame + x];
                let var = options.noise * options.noise
                    + if options.full_well > 0.0 {
                        s / options.full_well
                    } else {
                        0.0
                    };
                (black + s + var.sqrt() * gaussian(&mut rng)) as f32
            });
            write_grey_png(
                &out.join(SpotPlan::capture_name(c, i, k)),
                captured.view(),
                options.bit_depth,
            )?;
            progress(done.fetch_add(1, Ordering::Relaxed) + 1, total);
            Ok::<(), HoloError>(())
        })
    })?;
    hidden.save(&out.join(HIDDEN_FILE))?;
    Ok(hidden)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::OpticalSetup;
    use crate::slm::spots::{fit_captures, FitOptions};

    /// The loop: noisy simulated captures (8-bit, read and shot noise, saturation, random spot positions)
    /// → the fit recovers the hidden coefficients, 5 terms × 3 distances.
    #[test]
    fn the_fit_recovers_the_hidden_aberration_from_noisy_captures() {
        let dir = tempfile::tempdir().unwrap();
        let (patterns, captures) = (dir.path().join("patterns"), dir.path().join("captures"));
        let plan = SpotPlan::new(
            [64, 64],
            &OpticalSetup::default(),
            &[1],
            vec![-4e-3, 3e-3, 6e-3],
            2.0,
            32,
        )
        .unwrap();
        plan.write_patterns(&patterns, &|_, _| {}).unwrap();
        let options = SimulateOptions {
            seed: 7,
            ..SimulateOptions::default()
        };
        let t = std::time::Instant::now();
        let hidden = simulate_captures(&plan, &patterns, &captures, &options, &|_, _| {}).unwrap();
        let t_sim = t.elapsed();
        let t = std::time::Instant::now();
        let report = fit_captures(&plan, &captures, &FitOptions::default(), &|_| {}).unwrap();
        let t_fit = t.elapsed();
        let mut worst: f64 = 0.0;
        for (i, s) in hidden.samples().iter().enumerate() {
            for c in 0..3 {
                let got = report.profile.samples()[i].coefficients[c].to_array();
                let want = s.coefficients[c].to_array();
                let err = got
                    .iter()
                    .zip(want)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max);
                eprintln!(
                    "d {:+.1} mm colour {c}: hidden {want:.3?} fitted {got:.3?} max error {err:.3} rad, residual {:.4}",
                    s.distance_m * 1e3,
                    report.colours[1].distances[i].residual
                );
                if c == 1 {
                    worst = worst.max(err);
                }
            }
        }
        eprintln!(
            "simulated in {t_sim:?}, fitted in {t_fit:?}; worst error (green) {worst:.4} rad"
        );
        assert!(worst < 0.1, "worst coefficient error {worst} rad");
        // Deterministic: the same captures give the same bits.
        let again = fit_captures(&plan, &captures, &FitOptions::default(), &|_| {}).unwrap();
        assert_eq!(
            again.profile.to_json_string(),
            report.profile.to_json_string()
        );
    }
}

//! A simulated phase-only SLM and the camera that calibrates it: a spatially varying nonlinear response, a
//! non-uniform laser beam, camera noise and dust, at a camera resolution above the SLM's. It is the test bench
//! of [`super::calibrate`] (and of `holo calibrate simulate`), and the "true" display of the deep-black test
//! (paper Fig. 11, [`super::filtered_intensity`] of [`super::black_test_codes`]).
//!
//! Response of pixel `(y, x)` to code `k` at colour `c`: `φ(k) = R_c(y, x)·(k/255)^γ_c(y, x)` radians, with
//! `R` and `γ` smooth fields around each colour's nominal range and gamma. A capture of pattern `k`
//! ([`super::calibrate::calibration_pattern`]) sees, per 2×2 block, `I = B(y, x)·(b + (1 − b)·cos²(φ(k)/2))` (the Fourier
//! filter averages the block's two phases), where `B` is a Gaussian beam, `b` stray light; each camera pixel
//! adds Gaussian noise, dust specks of 5×5 camera pixels dim it, and the result is quantised to the camera's
//! bit depth.

use std::f64::consts::TAU as TAU64;
use std::path::Path;

use ndarray::{Array2, ArrayView2};

use super::calibrate::CaptureStack;
use super::captures::{capture_name, downsample};
use super::lut::{PhaseCurve, CODES};
use crate::error::{invalid, HoloError, Result};
use crate::splitmix::{splitmix64, SplitMix64};

/// One colour's nominal response and how much it varies across the panel.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ResponseModel {
    /// Nominal phase of code 255 (radians).
    pub range_rad: f64,
    /// Nominal gamma of `φ(k) = R·(k/255)^γ`.
    pub gamma: f64,
    /// Relative variation of the range across the panel (peak, e.g. 0.1 = ±10 %).
    pub range_variation: f64,
    /// Relative variation of gamma across the panel (peak).
    pub gamma_variation: f64,
}

/// A simulated SLM with its calibration camera (module docs).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SimulatedSlm {
    /// SLM height in pixels.
    pub height: usize,
    /// SLM width in pixels.
    pub width: usize,
    /// Response per colour (R, G, B).
    pub response: [ResponseModel; 3],
    /// Camera pixels per SLM pixel along each axis (≥ 1).
    pub camera_scale: usize,
    /// Peak beam intensity as a fraction of the camera's full scale.
    pub peak: f64,
    /// Beam intensity at the panel's corners relative to its peak (Gaussian fall-off).
    pub corner_falloff: f64,
    /// Stray light `b` as a fraction of the beam.
    pub stray_light: f64,
    /// Camera noise: standard deviation as a fraction of full scale.
    pub noise: f64,
    /// Number of 5×5 dust specks (camera pixels) on the optics.
    pub dust_specks: usize,
    /// Transmission of a dust speck.
    pub dust_transmission: f64,
    /// Camera bit depth: 8 or 16.
    pub bit_depth: u8,
    /// Seed of the response fields, noise and dust.
    pub seed: u64,
}

impl SimulatedSlm {
    /// A panel like the paper's: ranges 2.0π (638 nm), 2.45π (520 nm), 2.8π (450 nm) at code 255 — the phase
    /// of a liquid-crystal cell scales with `1/λ` — gammas 1.3–1.1, each varying ±8 % (range) and ±15 %
    /// (gamma) across the panel; camera at 2× the SLM's resolution, 16-bit, noise 0.3 % of full scale,
    /// beam falling to 55 % at the corners, 1 % stray light, 12 dust specks.
    pub fn new(height: usize, width: usize, seed: u64) -> Self {
        let model = |range_pi: f64, gamma: f64| ResponseModel {
            range_rad: range_pi * std::f64::consts::PI,
            gamma,
            range_variation: 0.08,
            gamma_variation: 0.15,
        };
        Self {
            height,
            width,
            response: [model(2.0, 1.3), model(2.45, 1.2), model(2.8, 1.1)],
            camera_scale: 2,
            peak: 0.8,
            corner_falloff: 0.55,
            stray_light: 0.01,
            noise: 0.003,
            dust_specks: 12,
            dust_transmission: 0.3,
            bit_depth: 16,
            seed,
        }
    }

    /// Checks the parameters.
    ///
    /// Errors: [`HoloError::InvalidParameter`] naming the first bad one.
    pub fn validate(&self) -> Result<()> {
        if self.height < 2 || self.width < 2 || self.height > 8192 || self.width > 8192 {
            return Err(invalid(
                "size",
                format!(
                    "SLM must be 2–8192 pixels a side, got {}×{}",
                    self.height, self.width
                ),
            ));
        }
        if !(1..=8).contains(&self.camera_scale) {
            return Err(invalid(
                "camera_scale",
                format!("must lie in 1..=8, got {}", self.camera_scale),
            ));
        }
        if !matches!(self.bit_depth, 8 | 16) {
            return Err(invalid(
                "bit_depth",
                format!("8 or 16, got {}", self.bit_depth),
            ));
        }
        for m in &self.response {
            let ok = m.range_rad > 0.0
                && m.range_rad * (1.0 + m.range_variation) < 16.0
                && m.gamma > 0.1
                && m.gamma < 10.0
                && (0.0..0.9).contains(&m.range_variation)
                && (0.0..0.9).contains(&m.gamma_variation);
            if !ok {
                return Err(invalid(
                    "response",
                    format!("{m:?} is outside the supported ranges"),
                ));
            }
        }
        for (name, v) in [
            ("peak", self.peak),
            ("corner_falloff", self.corner_falloff),
            ("stray_light", self.stray_light),
            ("dust_transmission", self.dust_transmission),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(invalid(name, format!("must lie in [0, 1], got {v}")));
            }
        }
        if !(0.0..0.5).contains(&self.noise) {
            return Err(invalid(
                "noise",
                format!("must lie in [0, 0.5), got {}", self.noise),
            ));
        }
        Ok(())
    }

    /// A smooth field in `[−1, 1]` over normalised coordinates, different per (`salt`, seed).
    fn field(&self, salt: u64, v: f64, u: f64) -> f64 {
        let r =
            |i: u64| (splitmix64(self.seed ^ (salt * 16 + i)) >> 11) as f64 / (1u64 << 53) as f64;
        let (a, b, c, d) = (r(0) * TAU64, r(1) * TAU64, 0.5 + r(2), 0.5 + r(3));
        0.6 * (TAU64 * (c * u + 0.3 * v) + a).sin() + 0.4 * (TAU64 * (0.4 * u - d * v) + b).cos()
    }

    /// Range and gamma of colour `colour` at SLM coordinates `(y, x)` (fractional pixels allowed).
    fn params(&self, colour: usize, y: f64, x: f64) -> (f64, f64) {
        let m = &self.response[colour];
        let (v, u) = (y / self.height as f64, x / self.width as f64);
        let range =
            m.range_rad * (1.0 + m.range_variation * self.field(2 * colour as u64 + 1, v, u));
        let gamma = m.gamma * (1.0 + m.gamma_variation * self.field(2 * colour as u64 + 2, v, u));
        (range, gamma)
    }

    /// The true response of pixel `(y, x)`, colour `colour` (0 = R): phase in radians of each code.
    ///
    /// Errors: [`HoloError::InvalidParameter`] for a pixel or colour outside the panel.
    pub fn true_curve(&self, colour: usize, y: usize, x: usize) -> Result<PhaseCurve> {
        if colour > 2 || y >= self.height || x >= self.width {
            return Err(invalid(
                "pixel",
                format!("colour {colour}, ({y}, {x}) is outside the panel"),
            ));
        }
        let (range, gamma) = self.params(colour, y as f64 + 0.5, x as f64 + 0.5);
        let p: Vec<f32> = (0..CODES)
            .map(|k| (range * (k as f64 / 255.0).powf(gamma)) as f32)
            .collect();
        PhaseCurve::new(&p)
    }

    /// The phases the panel displays for `codes` `[3, height, width]` (radians, each pixel's own response).
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for codes of another size.
    pub fn display(&self, codes: ndarray::ArrayView3<u8>) -> Result<ndarray::Array3<f32>> {
        if codes.dim() != (3, self.height, self.width) {
            return Err(HoloError::ShapeMismatch {
                what: "codes vs the simulated SLM".into(),
                expected: vec![3, self.height, self.width],
                got: codes.shape().to_vec(),
            });
        }
        Ok(ndarray::Array3::from_shape_fn(codes.dim(), |(c, y, x)| {
            let (range, gamma) = self.params(c, y as f64 + 0.5, x as f64 + 0.5);
            (range * (codes[[c, y, x]] as f64 / 255.0).powf(gamma)) as f32
        }))
    }

    /// The beam's relative intensity at camera pixel `(cy, cx)`.
    fn beam(&self, cy: f64, cx: f64, ch: f64, cw: f64) -> f64 {
        let (dy, dx) = (cy / ch - 0.45, cx / cw - 0.55);
        let corner2 = 0.55f64.powi(2) + 0.55f64.powi(2);
        (self.corner_falloff.max(1e-6).ln() * (dy * dy + dx * dx) / corner2).exp()
    }

    /// Capture of calibration pattern `k` for colour `colour`: `[height·s, width·s]` camera intensities in
    /// units of full scale, clipped to `[0, 1]` and quantised to the bit depth.
    ///
    /// Errors: [`HoloError::InvalidParameter`] as [`SimulatedSlm::validate`] or for a colour above 2.
    pub fn capture(&self, colour: usize, k: usize) -> Result<Array2<f32>> {
        self.validate()?;
        if colour > 2 || k >= CODES {
            return Err(invalid("capture", format!("colour {colour}, code {k}")));
        }
        let s = self.camera_scale;
        let (ch, cw) = (self.height * s, self.width * s);
        // Per 2×2 block: the phase of code k at the block centre.
        let block_phase = |by: usize, bx: usize| {
            let (range, gamma) = self.params(colour, (2 * by) as f64 + 1.0, (2 * bx) as f64 + 1.0);
            range * (k as f64 / 255.0).powf(gamma)
        };
        let (bh, bw) = (self.height.div_ceil(2), self.width.div_ceil(2));
        let modulation: Vec<f64> = (0..bh * bw)
            .map(|i| {
                let c = (block_phase(i / bw, i % bw) / 2.0).cos();
                self.stray_light + (1.0 - self.stray_light) * c * c
            })
            .collect();
        let mut dust_rng = SplitMix64::new(self.seed ^ 0xD057 ^ (colour as u64) << 40);
        let specks: Vec<(usize, usize)> = (0..self.dust_specks)
            .map(|_| (dust_rng.below(0, ch), dust_rng.below(0, cw)))
            .collect();
        let mut noise_rng = SplitMix64::new(splitmix64(
            self.seed ^ ((colour * CODES + k) as u64 + 1) << 20,
        ));
        let levels = if self.bit_depth == 8 { 255.0 } else { 65535.0 };
        let mut img = Array2::<f32>::zeros((ch, cw));
        for ((cy, cx), v) in img.indexed_iter_mut() {
            let (y, x) = (cy / s, cx / s);
            let mut i = self.peak
                * self.beam(cy as f64 + 0.5, cx as f64 + 0.5, ch as f64, cw as f64)
                * modulation[(y / 2) * bw + x / 2];
            if specks
                .iter()
                .any(|&(sy, sx)| sy.abs_diff(cy) <= 2 && sx.abs_diff(cx) <= 2)
            {
                i *= self.dust_transmission;
            }
            // Box–Muller.
            let (u1, u2) = (noise_rng.next_f64().max(1e-300), noise_rng.next_f64());
            i += self.noise * (-2.0 * u1.ln()).sqrt() * (TAU64 * u2).cos();
            *v = ((i.clamp(0.0, 1.0) * levels).round() / levels) as f32;
        }
        Ok(img)
    }

    /// The diffuser capture of the laser intensity calibration for `colour`: the beam (with dust, noise) at
    /// camera resolution, in units of full scale.
    ///
    /// Errors: as [`SimulatedSlm::capture`].
    pub fn diffuser_capture(&self, colour: usize) -> Result<Array2<f32>> {
        let mut sim = self.clone();
        sim.stray_light = 1.0; // modulation 1 everywhere: the beam alone
        sim.capture(colour, 0)
    }

    /// Writes the 256 captures of `colour` as `capture_000.png` … into `dir` (8- or 16-bit grey PNG), creating
    /// the folder.
    ///
    /// Errors: [`HoloError::Io`] / [`HoloError::Image`] naming the file.
    pub fn write_captures(
        &self,
        colour: usize,
        dir: &Path,
        progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<()> {
        std::fs::create_dir_all(dir).map_err(|source| HoloError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        use rayon::prelude::*;
        let done = std::sync::atomic::AtomicU64::new(0);
        (0..CODES).into_par_iter().try_for_each(|k| {
            let img = self.capture(colour, k)?;
            write_grey_png(&dir.join(capture_name(k)), img.view(), self.bit_depth)?;
            progress(
                done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1,
                CODES as u64,
            );
            Ok(())
        })
    }

    /// The calibration stack of `colour` in memory (captures generated on demand), for tests and benchmarks.
    pub fn stack(&self, colour: usize) -> SimulatedStack<'_> {
        SimulatedStack { slm: self, colour }
    }
}

/// Writes intensities in `[0, 1]` as an 8- or 16-bit grey PNG.
///
/// Errors: [`HoloError::Image`] / [`HoloError::Io`] naming `path`.
pub fn write_grey_png(path: &Path, img: ArrayView2<f32>, bit_depth: u8) -> Result<()> {
    let (h, w) = img.dim();
    let (bytes, color) = if bit_depth == 8 {
        (
            img.iter()
                .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
                .collect::<Vec<u8>>(),
            image::ExtendedColorType::L8,
        )
    } else {
        (
            img.iter()
                .flat_map(|v| ((v.clamp(0.0, 1.0) * 65535.0).round() as u16).to_ne_bytes())
                .collect(),
            image::ExtendedColorType::L16,
        )
    };
    crate::io::save_png(path, &bytes, w as u32, h as u32, color)
}

/// The in-memory capture stack of one colour of a [`SimulatedSlm`].
#[derive(Debug, Clone, Copy)]
pub struct SimulatedStack<'a> {
    slm: &'a SimulatedSlm,
    colour: usize,
}

impl CaptureStack for SimulatedStack<'_> {
    fn slm_size(&self) -> (usize, usize) {
        (self.slm.height, self.slm.width)
    }

    fn name(&self, k: usize) -> String {
        format!("simulated capture {k}")
    }

    fn read(&self, k: usize, out: &mut [f32], clipped: &mut [bool]) -> Result<()> {
        let img = self.slm.capture(self.colour, k)?;
        downsample(img.view(), (self.slm.height, self.slm.width), out, clipped)
    }
}

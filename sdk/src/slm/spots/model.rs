//! The forward model of a spot capture (paper Eq. 14–18): the intensity a camera focused at the spot's plane
//! records for a pupil `circ(ρ ≤ 1)·exp(i·(Z_a + D_k + tilt))`, on an `n × n` window of camera pixels.

use std::f64::consts::{PI, TAU};
use std::sync::Arc;

use num_complex::Complex64;
use rustfft::{Fft, FftPlanner};

use crate::error::{invalid, Result};
use crate::optics::ZernikeCoefficients;

/// Sub-samples per bin side for the pupil edge's anti-aliasing (the fraction of each bin inside `ρ ≤ 1`).
const EDGE_SUBSAMPLES: usize = 4;

/// One frequency bin inside the pupil.
#[derive(Debug, Clone, Copy)]
struct PupilBin {
    /// Row-major index `ky·n + kx` in FFT order.
    index: usize,
    /// Normalised pupil coordinates `ρ·cos θ`, `ρ·sin θ`.
    rx: f64,
    ry: f64,
    /// Signed bin indices (cycles per window).
    kx: f64,
    ky: f64,
    /// The fraction of the bin inside `ρ ≤ 1` (amplitude).
    weight: f64,
}

/// The camera's view of a focused spot: `I = |F⁻¹{P(ρ)·exp(i(Z_a + D_k + tilt))}|²` on an `n × n` window
/// (`[n, n]`, row `y`, column `x`), integrated over each camera pixel (its box MTF `sinc(kx/n)·sinc(ky/n)` on
/// the intensity's spectrum), normalised to unit sum over the periodic window (Parseval: the pupil's energy).
///
/// Sampling: `camera_scale = S` camera pixels per SLM pixel pitch at the focal plane, so the window's
/// frequency bin is `S/(n·p)` cycles per metre and the pupil edge `ρ = 1` (`f_N = 1/(2p)`) lies at
/// `n/(2S)` bins. The spot's centre is `(n/2 + tx, n/2 + ty)` pixels (`tx`, `ty`: the tip/tilt, in camera
/// pixels); `ρ = |f|/f_N`, `θ = atan2(fy, fx)` as in `docs/ABERRATION.md`.
#[derive(Clone)]
pub struct SpotModel {
    n: usize,
    camera_scale: f64,
    pupil: Vec<PupilBin>,
    /// Σ weight² · n²: the normalisation to unit energy.
    energy: f64,
    mtf: Vec<f64>,
    forward: Arc<dyn Fft<f64>>,
    inverse: Arc<dyn Fft<f64>>,
}

impl std::fmt::Debug for SpotModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SpotModel")
            .field("n", &self.n)
            .field("camera_scale", &self.camera_scale)
            .finish()
    }
}

/// Scratch buffers of `SpotModel::intensity` (one per thread).
#[derive(Debug, Clone)]
pub struct ModelScratch {
    field: Vec<Complex64>,
    fft: Vec<Complex64>,
}

impl SpotModel {
    /// The model of an `n × n` window (`n` even, 8–1024) at `camera_scale` camera pixels per SLM pitch
    /// (finite, ≥ 0.5), whose pupil radius `n/(2·camera_scale)` must be at least 2 bins and below `n/2`.
    ///
    /// Errors: [`crate::HoloError::InvalidParameter`] naming `window_px` or `camera_scale`.
    pub(crate) fn new(n: usize, camera_scale: f64) -> Result<Self> {
        if !(8..=1024).contains(&n) || !n.is_multiple_of(2) {
            return Err(invalid(
                "window_px",
                format!("must be even and within 8–1024, got {n}"),
            ));
        }
        if !(camera_scale.is_finite() && camera_scale >= 0.5) {
            return Err(invalid(
                "camera_scale",
                format!(
                    "must be a finite number ≥ 0.5 camera pixels per SLM pixel, got {camera_scale}"
                ),
            ));
        }
        let radius = n as f64 / (2.0 * camera_scale);
        if radius < 2.0 || radius >= n as f64 / 2.0 {
            return Err(invalid(
                "camera_scale",
                format!(
                    "the pupil spans {radius:.2} bins of the {n}-pixel window (window_px/(2·camera_scale)); it \
                     must lie within 2 and {} (a camera scale above 1 and at most window_px/4)",
                    n / 2
                ),
            ));
        }
        let signed = |k: usize| {
            if k < n / 2 {
                k as f64
            } else {
                k as f64 - n as f64
            }
        };
        let mut pupil = Vec::new();
        let sub = EDGE_SUBSAMPLES as f64;
        for ky in 0..n {
            for kx in 0..n {
                let (fx, fy) = (signed(kx), signed(ky));
                let mut inside = 0usize;
                for sy in 0..EDGE_SUBSAMPLES {
                    for sx in 0..EDGE_SUBSAMPLES {
                        let x = (fx + (sx as f64 + 0.5) / sub - 0.5) / radius;
                        let y = (fy + (sy as f64 + 0.5) / sub - 0.5) / radius;
                        inside += usize::from(x * x + y * y <= 1.0);
                    }
                }
                if inside > 0 {
                    pupil.push(PupilBin {
                        index: ky * n + kx,
                        rx: fx / radius,
                        ry: fy / radius,
                        kx: fx,
                        ky: fy,
                        weight: inside as f64 / (sub * sub),
                    });
                }
            }
        }
        let energy = pupil.iter().map(|b| b.weight * b.weight).sum::<f64>() * (n * n) as f64;
        let sinc = |k: f64| {
            let x = PI * k / n as f64;
            if x == 0.0 {
                1.0
            } else {
                x.sin() / x
            }
        };
        let mtf = (0..n * n)
            .map(|i| sinc(signed(i % n)) * sinc(signed(i / n)))
            .collect();
        let mut planner = FftPlanner::new();
        Ok(Self {
            n,
            camera_scale,
            pupil,
            energy,
            mtf,
            forward: planner.plan_fft_forward(n),
            inverse: planner.plan_fft_inverse(n),
        })
    }

    /// The window side `n` in camera pixels.
    pub(crate) fn window_px(&self) -> usize {
        self.n
    }

    /// The pupil radius in frequency bins of the window, `n/(2·camera_scale)` (what the tests check the
    /// simulated spot against).
    #[cfg(test)]
    pub(crate) fn pupil_radius_bins(&self) -> f64 {
        self.n as f64 / (2.0 * self.camera_scale)
    }

    /// Fresh scratch buffers for [`SpotModel::intensity`].
    pub(crate) fn scratch(&self) -> ModelScratch {
        let len = self.n * self.n;
        ModelScratch {
            field: vec![Complex64::default(); len],
            fft: vec![Complex64::default(); self.n.max(self.forward.get_inplace_scratch_len())],
        }
    }

    /// The model intensity `[n, n]` (row-major into `out`, unit sum) for the pupil phase `phase`
    /// (aberration plus diversity, radians at `ρ = 1`) and the spot's offset `(tx, ty)` from the window's
    /// centre in camera pixels.
    ///
    /// Errors: [`crate::HoloError::InvalidParameter`] if `out` is not `n·n` long.
    pub(crate) fn intensity(
        &self,
        phase: &ZernikeCoefficients,
        shift: (f64, f64),
        scratch: &mut ModelScratch,
        out: &mut [f64],
    ) -> Result<()> {
        let n = self.n;
        if out.len() != n * n {
            return Err(invalid(
                "out",
                format!("must hold {}×{} values, got {}", n, n, out.len()),
            ));
        }
        let (cx, cy) = (n as f64 / 2.0 + shift.0, n as f64 / 2.0 + shift.1);
        let field = &mut scratch.field;
        field.fill(Complex64::default());
        for b in &self.pupil {
            let p = phase.phase_xy(b.rx, b.ry) - TAU * (b.kx * cx + b.ky * cy) / n as f64;
            field[b.index] = Complex64::from_polar(b.weight, p);
        }
        self.fft2(field, &mut scratch.fft, false);
        let norm = 1.0 / self.energy;
        for v in field.iter_mut() {
            *v = Complex64::new(v.norm_sqr() * norm, 0.0);
        }
        // The pixel's box: the intensity's spectrum times the box MTF (DC kept: the sum is unchanged).
        self.fft2(field, &mut scratch.fft, true);
        let inv = 1.0 / (n * n) as f64;
        for (v, m) in field.iter_mut().zip(&self.mtf) {
            *v *= m * inv;
        }
        self.fft2(field, &mut scratch.fft, false);
        for (o, v) in out.iter_mut().zip(field.iter()) {
            *o = v.re;
        }
        Ok(())
    }

    /// In-place unnormalised 2D FFT of an `[n, n]` buffer (`forward`: `e^{−i…}`, else `e^{+i…}`).
    fn fft2(&self, buf: &mut [Complex64], scratch: &mut Vec<Complex64>, forward: bool) {
        let n = self.n;
        let fft = if forward {
            &self.forward
        } else {
            &self.inverse
        };
        let need = fft.get_inplace_scratch_len().max(n);
        if scratch.len() < need {
            scratch.resize(need, Complex64::default());
        }
        fft.process_with_scratch(buf, &mut scratch[..fft.get_inplace_scratch_len()]);
        transpose_square(buf, n);
        fft.process_with_scratch(buf, &mut scratch[..fft.get_inplace_scratch_len()]);
        transpose_square(buf, n);
    }
}

/// Transposes a square `[n, n]` buffer in place.
fn transpose_square(buf: &mut [Complex64], n: usize) {
    for y in 0..n {
        for x in y + 1..n {
            buf.swap(y * n + x, x * n + y);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn render(model: &SpotModel, z: ZernikeCoefficients, shift: (f64, f64)) -> Vec<f64> {
        let mut out = vec![0.0; model.n * model.n];
        model
            .intensity(&z, shift, &mut model.scratch(), &mut out)
            .unwrap();
        out
    }

    fn centroid(img: &[f64], n: usize) -> (f64, f64) {
        let s: f64 = img.iter().sum();
        let x = img
            .iter()
            .enumerate()
            .map(|(i, v)| (i % n) as f64 * v)
            .sum::<f64>()
            / s;
        let y = img
            .iter()
            .enumerate()
            .map(|(i, v)| (i / n) as f64 * v)
            .sum::<f64>()
            / s;
        (x, y)
    }

    #[test]
    fn zero_aberration_is_a_symmetric_airy_spot_with_its_first_dark_ring_where_predicted() {
        let (n, s) = (64, 4.0);
        let m = SpotModel::new(n, s).unwrap();
        let img = render(&m, ZernikeCoefficients::ZERO, (0.0, 0.0));
        let c = n / 2;
        let peak = img[c * n + c];
        assert_eq!(
            img.iter().cloned().fold(f64::MIN, f64::max),
            peak,
            "peak at the centre"
        );
        for dy in -10i64..=10 {
            for dx in -10i64..=10 {
                let at =
                    |x: i64, y: i64| img[(c as i64 + y) as usize * n + (c as i64 + x) as usize];
                let v = at(dx, dy);
                for w in [at(-dx, -dy), at(dy, dx), at(-dx, dy)] {
                    assert!((v - w).abs() <= 1e-9 * peak, "({dx},{dy}): {v} vs {w}");
                }
            }
        }
        // Airy's first zero: 3.8317/(2π) · n / radius = 0.61·2S pixels (4.88 px here).
        let r0 = 3.8317 / TAU * n as f64 / m.pupil_radius_bins();
        let ring = |r: f64| {
            let k = 64;
            (0..k)
                .map(|i| {
                    let t = TAU * i as f64 / k as f64;
                    let (x, y) = (c as f64 + r * t.cos(), c as f64 + r * t.sin());
                    img[y.round() as usize * n + x.round() as usize]
                })
                .sum::<f64>()
                / k as f64
        };
        assert!(
            ring(r0) < 0.03 * peak,
            "dark ring {} of peak {peak}",
            ring(r0)
        );
        assert!(ring(r0 * 0.5) > 0.3 * peak);
        assert!(
            ring(r0 * 1.35) > ring(r0),
            "a bright ring follows the dark one"
        );
    }

    #[test]
    fn energy_is_conserved_parseval() {
        let m = SpotModel::new(64, 4.0).unwrap();
        for z in [
            ZernikeCoefficients::ZERO,
            ZernikeCoefficients::from_array([1.2, -0.7, 0.4, 0.9, -1.1]),
        ] {
            let sum: f64 = render(&m, z, (3.3, -1.7)).iter().sum();
            assert!((sum - 1.0).abs() < 1e-9, "{sum}");
        }
        // Without the MTF: Σ|E|² = n²·Σ|P|² exactly; the MTF's DC is 1, so the sum above is that energy.
        assert_eq!(m.mtf[0], 1.0);
    }

    #[test]
    fn a_pure_tilt_shifts_the_spot_by_the_predicted_pixels() {
        let n = 64;
        let m = SpotModel::new(n, 4.0).unwrap();
        let base = render(&m, ZernikeCoefficients::ZERO, (0.0, 0.0));
        let moved = render(&m, ZernikeCoefficients::ZERO, (5.0, -3.0));
        for y in 0..n {
            for x in 0..n {
                let src = ((y + 3) % n) * n + (x + n - 5) % n;
                assert!((moved[y * n + x] - base[src]).abs() < 1e-12);
            }
        }
        let (cx, cy) = centroid(&render(&m, ZernikeCoefficients::ZERO, (2.25, 1.5)), n);
        assert!(
            (cx - 34.25).abs() < 0.02 && (cy - 33.5).abs() < 0.02,
            "{cx} {cy}"
        );
    }

    #[test]
    fn the_sign_of_the_focus_diversity_distinguishes_plus_and_minus_focus() {
        let m = SpotModel::new(64, 4.0).unwrap();
        let focus = |a| ZernikeCoefficients {
            focus: a,
            ..ZernikeCoefficients::ZERO
        };
        let peak = |z| render(&m, z, (0.0, 0.0))[32 * 64 + 32];
        // Without diversity, ±a3 give the same image (the twin image); with +δ one of them is refocused.
        let (plus, minus) = (
            render(&m, focus(1.0), (0.0, 0.0)),
            render(&m, focus(-1.0), (0.0, 0.0)),
        );
        let diff: f64 = plus.iter().zip(&minus).map(|(a, b)| (a - b).abs()).sum();
        assert!(diff < 1e-9, "±a3 alike without diversity: {diff}");
        let delta = -1.0;
        assert!(peak(focus(1.0 + delta)) > 2.0 * peak(focus(-1.0 + delta)));
        assert!(peak(focus(-1.0 - delta)) > 2.0 * peak(focus(1.0 - delta)));
    }

    #[test]
    fn bad_sizes_are_refused_naming_the_field() {
        let e = SpotModel::new(63, 4.0).unwrap_err().to_string();
        assert!(e.contains("window_px"), "{e}");
        let e = SpotModel::new(64, f64::NAN).unwrap_err().to_string();
        assert!(e.contains("camera_scale"), "{e}");
        let e = SpotModel::new(64, 30.0).unwrap_err().to_string();
        assert!(e.contains("camera_scale"), "{e}");
    }
}

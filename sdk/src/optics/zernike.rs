//! The viewer's or the display's aberrations as Zernike terms and the pupil kernel they make (paper Methods,
//! "Compensating hardware imperfection", Eq. 14–19).
//!
//! [`ZernikeCoefficients`] are the five terms of Eq. 14–18 at one focus distance and wavelength. Two equivalent
//! forms of the correction kernel `Φ_d` exist:
//!
//! - **Eq. 19, as the paper words it**: the ideal sub-hologram `φ⁰_d` that focuses a plane wave to `d`,
//!   multiplied by `exp(i·ΣZ_j)`, gives the corrected sub-hologram `φ_d` ([`corrected_subhologram`]); its point
//!   spread function is `PSF_d = ASM(φ_d, d)` ([`psf`]) and `Φ_d = F(PSF_d)`
//!   ([`amplitude_transfer_function_from_subhologram`]).
//! - **Frequency domain**, used for synthesis and the real-time correction: `Φ_d(fx, fy) = circ(ρ ≤ 1)·exp(i·ΣZ_j(ρ, θ))`
//!   with `ρ = |f|/f_N`, `f_N = 1/(2p)` the SLM's Nyquist frequency (its maximum diffraction angle) and
//!   `θ = atan2(fy, fx)` ([`amplitude_transfer_function`]).
//!
//! They agree because the Zernike polynomials of Eq. 19 are evaluated at the normalised polar coordinates of
//! the **local spatial frequency** of `φ⁰_d` at each sub-hologram point, `f = −(x, y)/(λ·d)`: by stationary
//! phase, the plane wave of frequency `f` leaving the sub-hologram comes from the point `(x, y) = −λ·d·f`, so
//! the sub-hologram's phase at that point becomes the spectrum's phase at `f` (checked by the tests; the
//! residual is of order `λ·|∇Z|²/(4π·d·tan²α)`, small once the sub-hologram spans several Fresnel zones).
//!
//! Where the terms come from lives in `display` (the calibrated profile per distance and colour, its file, a
//! spectacle prescription); who applies the kernel lives in `synthesis` (the aberration-corrected SM-LBM, Eq. 5)
//! and `pipeline` (the running session's correction).

use ndarray::Array2;
use num_complex::Complex32;
use serde::{Deserialize, Serialize};

use super::propagation::check_positive;
use super::propagation::{Carrier, PropagationOptions, Propagator, SpectralPlan};
#[cfg(doc)]
use crate::error::HoloError;
use crate::error::{invalid, Result};

/// The largest magnitude of a Zernike coefficient, radians at the pupil edge: 10⁴. The correction kernel
/// `e^{iΣZ}` is sampled on the frequency grid, where the focus term's phase changes by `8|a|/N` between
/// neighbouring bins at the pupil edge (`N` bins across the grid); beyond `π` it aliases. At the largest SLM
/// side the SDK accepts (8192 pixels) that is `|a| ≈ 3.2·10³`, so no grid samples a larger coefficient, while
/// the strongest prescription the SDK converts stays far below (about 35 rad per colour on an 8 µm display,
/// 2.2·10³ at 1 µm). Larger values are a unit or typing error (or overflow to NaN in the kernel).
pub const MAX_COEFFICIENT_RAD: f64 = 1e4;

/// The five Zernike coefficients of the paper's aberration model (Eq. 14–18), in radians of phase at the
/// pupil edge (`ρ = 1`): the paper's `a3d … a7d` at one focus distance `d` and one wavelength.
///
/// In JSON every field is optional (default 0) and unknown fields are refused.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ZernikeCoefficients {
    /// `a3`, focus: `Z3 = a3·(2ρ² − 1)` (Eq. 14).
    pub focus: f64,
    /// `a4`, vertical astigmatism: `Z4 = a4·ρ²·cos 2θ` (Eq. 15).
    pub astigmatism_vertical: f64,
    /// `a5`, oblique astigmatism: `Z5 = a5·ρ²·sin 2θ` (Eq. 16).
    pub astigmatism_oblique: f64,
    /// `a6`, horizontal coma: `Z6 = a6·(3ρ² − 2)·ρ·cos θ` (Eq. 17).
    pub coma_horizontal: f64,
    /// `a7`, vertical coma: `Z7 = a7·(3ρ² − 2)·ρ·sin θ` (Eq. 18).
    pub coma_vertical: f64,
}

impl ZernikeCoefficients {
    /// All coefficients zero (no aberration).
    pub const ZERO: Self = Self {
        focus: 0.0,
        astigmatism_vertical: 0.0,
        astigmatism_oblique: 0.0,
        coma_horizontal: 0.0,
        coma_vertical: 0.0,
    };

    /// The coefficients `[a3, a4, a5, a6, a7]`.
    pub fn to_array(&self) -> [f64; 5] {
        [
            self.focus,
            self.astigmatism_vertical,
            self.astigmatism_oblique,
            self.coma_horizontal,
            self.coma_vertical,
        ]
    }

    /// Coefficients from `[a3, a4, a5, a6, a7]`.
    pub(crate) fn from_array(a: [f64; 5]) -> Self {
        Self {
            focus: a[0],
            astigmatism_vertical: a[1],
            astigmatism_oblique: a[2],
            coma_horizontal: a[3],
            coma_vertical: a[4],
        }
    }

    /// Whether every coefficient is zero.
    pub(crate) fn is_zero(&self) -> bool {
        self.to_array().iter().all(|&a| a == 0.0)
    }

    /// `self + t·(other − self)`, coefficient by coefficient.
    pub(crate) fn lerp(&self, other: &Self, t: f64) -> Self {
        let (a, b) = (self.to_array(), other.to_array());
        Self::from_array(std::array::from_fn(|j| a[j] + t * (b[j] - a[j])))
    }

    /// The aberration phase in radians, `Σ_j Z_j(ρ, θ)` of Eq. 14–18, at normalised polar radius `rho`
    /// (1 at the pupil edge) and azimuth `theta` (radians, from the `+x` axis toward `+y`):
    /// `a3(2ρ²−1) + a4ρ²cos2θ + a5ρ²sin2θ + a6(3ρ²−2)ρcosθ + a7(3ρ²−2)ρsinθ`.
    pub fn phase(&self, rho: f64, theta: f64) -> f64 {
        let (s, c) = theta.sin_cos();
        self.phase_xy(rho * c, rho * s)
    }

    /// [`ZernikeCoefficients::phase`] in Cartesian pupil coordinates `(ρ·cos θ, ρ·sin θ)` (no trigonometry).
    pub(crate) fn phase_xy(&self, rx: f64, ry: f64) -> f64 {
        let r2 = rx * rx + ry * ry;
        let coma = 3.0 * r2 - 2.0;
        self.focus * (2.0 * r2 - 1.0)
            + self.astigmatism_vertical * (rx * rx - ry * ry)
            + self.astigmatism_oblique * (2.0 * rx * ry)
            + self.coma_horizontal * coma * rx
            + self.coma_vertical * coma * ry
    }
}

impl std::ops::Neg for ZernikeCoefficients {
    type Output = Self;

    /// The opposite aberration (its correction).
    fn neg(self) -> Self {
        Self::from_array(self.to_array().map(|a| -a))
    }
}
/// Checks pitch, wavelength and focus distance of the Eq. 19 functions.
fn check_subhologram_args(
    height: usize,
    width: usize,
    pixel_pitch_m: f64,
    wavelength_m: f64,
    distance_m: f64,
) -> Result<()> {
    check_positive("pixel_pitch_m", pixel_pitch_m)?;
    check_positive("wavelength_m", wavelength_m)?;
    if height == 0 || width == 0 {
        return Err(invalid(
            "field size",
            format!("height and width must be ≥ 1, got {height}×{width}"),
        ));
    }
    if !(distance_m.is_finite() && distance_m != 0.0) {
        return Err(invalid(
            "distance_m",
            format!("must be finite and non-zero, got {distance_m}"),
        ));
    }
    if wavelength_m >= 2.0 * pixel_pitch_m {
        return Err(invalid(
            "wavelength_m",
            format!("must be below twice the pixel pitch ({pixel_pitch_m} m), got {wavelength_m}"),
        ));
    }
    Ok(())
}

/// Radius in metres of the ideal sub-hologram focusing to `distance_m`: `R_d = |d|·tan(asin(λ/(2p)))`, the
/// cone of the SLM's maximum diffraction angle.
pub fn subhologram_radius_m(pixel_pitch_m: f64, wavelength_m: f64, distance_m: f64) -> f64 {
    distance_m.abs() * (wavelength_m / (2.0 * pixel_pitch_m)).asin().tan()
}

/// The corrected sub-hologram `φ_d` of Eq. 19, `[height, width]`: the ideal sub-hologram `φ⁰_d` that focuses a
/// plane wave of `wavelength_m` to signed distance `distance_m` (metres, positive along the light; negative:
/// a diverging wave from a virtual focus behind the SLM), times `exp(i·ΣZ_j(ρ, θ))` of `coefficients`
/// (Eq. 14–18).
///
/// `φ⁰_d = exp(−iπ·r²/(λ·d))` inside the aperture of radius [`subhologram_radius_m`] (the SLM's maximum
/// diffraction cone), zero outside, centred on pixel `(width/2, height/2)` (pixel `(x, y)` at
/// `((x − width/2)·p, (y − height/2)·p)`), i.e. zero-padded to the frame. `ρ, θ` are the normalised polar
/// coordinates of the local spatial frequency of `φ⁰_d` at `(x, y)`, `f = −(x, y)/(λ·d)`: `ρ = |f|/f_N` with
/// `f_N = 1/(2p)`, `θ = atan2(fy, fx)` (module docs: this makes Eq. 19 agree with the frequency-domain form
/// [`amplitude_transfer_function`]). An aperture larger than the frame is clipped by it.
///
/// Errors: [`HoloError::InvalidParameter`] for a zero size, a non-positive pitch or wavelength, a wavelength
/// of at least twice the pitch, or a zero or non-finite distance.
pub fn corrected_subhologram(
    height: usize,
    width: usize,
    pixel_pitch_m: f64,
    wavelength_m: f64,
    distance_m: f64,
    coefficients: &ZernikeCoefficients,
) -> Result<Array2<Complex32>> {
    check_subhologram_args(height, width, pixel_pitch_m, wavelength_m, distance_m)?;
    let p = pixel_pitch_m;
    let radius = subhologram_radius_m(p, wavelength_m, distance_m);
    let lambda_d = wavelength_m * distance_m;
    // ρ-vector = f / f_N = −(x, y)·2p/(λd).
    let to_rho = -2.0 * p / lambda_d;
    let (cy, cx) = ((height / 2) as f64, (width / 2) as f64);
    Ok(Array2::from_shape_fn((height, width), |(row, col)| {
        let (x, y) = ((col as f64 - cx) * p, (row as f64 - cy) * p);
        let r2 = x * x + y * y;
        if r2 > radius * radius {
            return Complex32::new(0.0, 0.0);
        }
        let phase =
            -std::f64::consts::PI * r2 / lambda_d + coefficients.phase_xy(x * to_rho, y * to_rho);
        let (s, c) = phase.sin_cos();
        Complex32::new(c as f32, s as f32)
    }))
}

/// The point spread function `PSF_d = ASM(φ_d, d)` `[height, width]` of the corrected sub-hologram
/// ([`corrected_subhologram`]) at its focus (paper text after Eq. 19), with the angular spectrum method of
/// [`Propagator`] (no padding, the on-axis carrier `exp(i·2π·d/λ)` removed, Eq. 6). The spot
/// sits at pixel `(width/2, height/2)`.
///
/// Errors: as [`corrected_subhologram`].
pub fn psf(
    height: usize,
    width: usize,
    pixel_pitch_m: f64,
    wavelength_m: f64,
    distance_m: f64,
    coefficients: &ZernikeCoefficients,
) -> Result<Array2<Complex32>> {
    let mut field = corrected_subhologram(
        height,
        width,
        pixel_pitch_m,
        wavelength_m,
        distance_m,
        coefficients,
    )?;
    let prop = Propagator::new(
        height,
        width,
        pixel_pitch_m,
        wavelength_m,
        PropagationOptions::default(),
    )?;
    let slice = field
        .as_slice_mut()
        .expect("a fresh array is in standard layout");
    prop.propagate_by(slice, distance_m, Carrier::Remove)?;
    Ok(field)
}

/// Copies a multiplier of an unpadded plan (transposed `[width, height]`, FFT order) into a `[height, width]`
/// array in FFT order (row = `ky` bin, column = `kx` bin, as `numpy.fft.fft2`).
fn plan_layout_to_array(plan: &SpectralPlan, values: &[Complex32]) -> Array2<Complex32> {
    let (h, w) = plan.computational_shape();
    Array2::from_shape_fn((h, w), |(ky, kx)| values[kx * h + ky])
}

/// Divides `values` by their mean magnitude over the bins where `inside` holds.
fn normalise_in_pupil(values: &mut [Complex32], inside: impl Fn(usize) -> bool) {
    let (sum, n) = values
        .iter()
        .enumerate()
        .filter(|(i, _)| inside(*i))
        .fold((0.0f64, 0usize), |(s, n), (_, v)| {
            (s + v.norm() as f64, n + 1)
        });
    if n > 0 && sum > 0.0 {
        let k = (n as f64 / sum) as f32;
        values.iter_mut().for_each(|v| *v *= k);
    }
}

/// Whether bin `(kx, ky)` (signed indices) of a `[ch, cw]` grid at pitch `p` lies in the pupil `ρ ≤ 1`, and its
/// pupil coordinates `(ρx, ρy) = (fx, fy)/f_N`.
fn pupil_coordinates(kx: i64, ky: i64, ch: usize, cw: usize) -> (f64, f64) {
    // fx = kx/(cw·p), f_N = 1/(2p): ρx = 2kx/cw, independent of the pitch.
    (2.0 * kx as f64 / cw as f64, 2.0 * ky as f64 / ch as f64)
}

/// The frequency-domain correction kernel of `coefficients` on `plan`'s computational grid, in the plan's
/// spectrum layout (transposed, FFT order, no normalisation): `circ(ρ ≤ 1)·exp(i·ΣZ_j(ρ, θ))`.
pub(crate) fn pupil_multiplier(
    plan: &SpectralPlan,
    coefficients: &ZernikeCoefficients,
) -> Vec<Complex32> {
    let mut out = Vec::with_capacity(plan.spectrum_len());
    fill_pupil_multiplier(plan, coefficients, 1.0, &mut out);
    out
}

/// [`pupil_multiplier`] times `scale`, written into `out` (no allocation when it has the capacity): the
/// real-time pipeline's correction kernel (`scale`: the inverse transform's normalisation where no transfer
/// function carries it).
pub(crate) fn fill_pupil_multiplier(
    plan: &SpectralPlan,
    coefficients: &ZernikeCoefficients,
    scale: f32,
    out: &mut Vec<Complex32>,
) {
    let (ch, cw) = plan.computational_shape();
    plan.fill_multiplier(out, |kx, ky| {
        let (rx, ry) = pupil_coordinates(kx, ky, ch, cw);
        if rx * rx + ry * ry > 1.0 {
            return Complex32::new(0.0, 0.0);
        }
        let (s, c) = coefficients.phase_xy(rx, ry).sin_cos();
        Complex32::new(c as f32 * scale, s as f32 * scale)
    })
}

/// The frequency-domain amplitude transfer function `Φ(fx, fy) = circ(ρ ≤ 1)·exp(i·ΣZ_j(ρ, θ))` `[height,
/// width]` in FFT order (row `ky`, column `kx`, frequencies `fx = kx/(width·p)`, `fy = ky/(height·p)` as
/// `numpy.fft.fftfreq`), with `ρ = |f|/f_N`, `f_N = 1/(2p)` and `θ = atan2(fy, fx)`: the form of Eq. 5's
/// kernel that [`crate::synthesis::AberrationCorrectedSmLbm`] uses. Unit magnitude inside the pupil. Independent of the pitch
/// and wavelength: the coefficients are radians at the pupil edge.
///
/// Errors: [`HoloError::InvalidParameter`] for a zero size.
pub fn amplitude_transfer_function(
    height: usize,
    width: usize,
    coefficients: &ZernikeCoefficients,
) -> Result<Array2<Complex32>> {
    let plan = SpectralPlan::new(height, width, super::propagation::Padding::None)?;
    Ok(plan_layout_to_array(
        &plan,
        &pupil_multiplier(&plan, coefficients),
    ))
}

/// The amplitude transfer function as the paper computes it after Eq. 19, `Φ_d = F(PSF_d) = F(ASM(φ_d, d))`,
/// `[height, width]` in the layout of [`amplitude_transfer_function`], normalised to unit mean magnitude
/// inside the pupil `ρ ≤ 1` and with the constant phase `−i·sign(d)` of the Fresnel transform of `φ⁰_d`
/// removed, so that it compares directly with [`amplitude_transfer_function`] (equal up to the
/// stationary-phase residual and the ringing of the aperture's edge).
///
/// Errors: as [`corrected_subhologram`].
pub fn amplitude_transfer_function_from_subhologram(
    height: usize,
    width: usize,
    pixel_pitch_m: f64,
    wavelength_m: f64,
    distance_m: f64,
    coefficients: &ZernikeCoefficients,
) -> Result<Array2<Complex32>> {
    let field = psf(
        height,
        width,
        pixel_pitch_m,
        wavelength_m,
        distance_m,
        coefficients,
    )?;
    let plan = SpectralPlan::new(height, width, super::propagation::Padding::None)?;
    let mut scratch = plan.scratch();
    let mut spectrum = vec![Complex32::default(); plan.spectrum_len()];
    plan.forward(
        field.as_slice().expect("standard layout"),
        &mut spectrum,
        &mut scratch,
    )?;
    // The sub-hologram is centred on pixel (width/2, height/2), not on pixel 0: undo that shift's linear phase,
    // and the Fresnel transform's constant −i·sign(d).
    let (cy, cx) = ((height / 2) as f64, (width / 2) as f64);
    let fresnel = Complex32::new(0.0, distance_m.signum() as f32);
    let shift = plan.build_multiplier(|kx, ky| {
        let phase = std::f64::consts::TAU
            * (kx as f64 * cx / width as f64 + ky as f64 * cy / height as f64);
        let (s, c) = phase.sin_cos();
        Complex32::new(c as f32, s as f32) * fresnel
    });
    let inside = pupil_multiplier(&plan, &ZernikeCoefficients::ZERO);
    for (v, m) in spectrum.iter_mut().zip(&shift) {
        *v *= m;
    }
    normalise_in_pupil(&mut spectrum, |i| inside[i].re > 0.5);
    Ok(plan_layout_to_array(&plan, &spectrum))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// Five non-zero terms, for the tests of every module that applies them.
    pub(crate) fn sample_coefficients() -> ZernikeCoefficients {
        ZernikeCoefficients {
            focus: 1.0,
            astigmatism_vertical: 1.5,
            astigmatism_oblique: -0.8,
            coma_horizontal: 0.6,
            coma_vertical: -0.5,
        }
    }

    #[test]
    fn phase_is_the_sum_of_eq_14_to_18() {
        let k = sample_coefficients();
        for &(rho, theta) in &[(0.0, 0.0), (0.3, 1.1), (0.9, -2.5), (1.0, PI / 2.0)] {
            let expected = 1.0 * (2.0 * rho * rho - 1.0) + 1.5 * rho * rho * (2.0 * theta).cos()
                - 0.8 * rho * rho * (2.0 * theta).sin()
                + 0.6 * (3.0 * rho * rho - 2.0) * rho * theta.cos()
                - 0.5 * (3.0 * rho * rho - 2.0) * rho * theta.sin();
            assert!((k.phase(rho, theta) - expected).abs() < 1e-12);
        }
        assert_eq!((-k).phase(0.7, 0.3), -k.phase(0.7, 0.3));
    }

    /// Normalised correlation |<a, b>| / (|a|·|b|) and mean absolute wrapped phase difference over `mask`.
    fn compare(a: &Array2<Complex32>, b: &Array2<Complex32>, mask: &Array2<bool>) -> (f64, f64) {
        let (mut dot, mut na, mut nb, mut dphi, mut n) =
            (num_complex::Complex64::default(), 0.0, 0.0, 0.0, 0.0);
        for ((x, y), m) in a.iter().zip(b).zip(mask) {
            if !m {
                continue;
            }
            let (x, y) = (
                num_complex::Complex64::new(x.re as f64, x.im as f64),
                num_complex::Complex64::new(y.re as f64, y.im as f64),
            );
            dot += x * y.conj();
            na += x.norm_sqr();
            nb += y.norm_sqr();
            dphi += (x * y.conj()).arg().abs();
            n += 1.0;
        }
        (dot.norm() / (na * nb).sqrt(), dphi / n)
    }

    #[test]
    fn eq_19_subhologram_route_agrees_with_the_frequency_domain_kernel() {
        let n = 128;
        let (p, lambda) = (8e-6, 520e-9);
        let k = sample_coefficients();
        let freq = amplitude_transfer_function(n, n, &k).unwrap();
        let inner = Array2::from_shape_fn((n, n), |(ky, kx)| {
            let s = |k: usize| crate::optics::fft::signed_index(k, n) as f64 * 2.0 / n as f64;
            s(kx).hypot(s(ky)) < 0.8
        });
        // Measured (128², 8 µm, 520 nm, these coefficients): correlation 0.923 / 0.945 / 0.964 / 0.967 /
        // 0.977 / 0.978 / 0.987 and mean |Δφ| 0.32 / 0.25 / 0.17 / 0.17 / 0.13 / 0.13 / 0.09 rad at
        // 3 / 4 / −4 / 6 / −6 / 8 / 12 mm: the stationary-phase residual, which falls as 1/|d|.
        for (d, min_corr, max_dphi) in [
            (3e-3, 0.91, 0.35),
            (4e-3, 0.93, 0.28),
            (-4e-3, 0.95, 0.2),
            (6e-3, 0.96, 0.2),
            (-6e-3, 0.97, 0.15),
            (12e-3, 0.98, 0.1),
        ] {
            let from_sub =
                amplitude_transfer_function_from_subhologram(n, n, p, lambda, d, &k).unwrap();
            let (corr, dphi) = compare(&from_sub, &freq, &inner);
            eprintln!("d = {d}: correlation {corr:.4}, mean |Δφ| {dphi:.3} rad");
            assert!(corr > min_corr && dphi < max_dphi, "d = {d}: {corr} {dphi}");
            // The opposite aberration is far off: the comparison can fail.
            let wrong = amplitude_transfer_function(n, n, &-k).unwrap();
            let (corr, _) = compare(&from_sub, &wrong, &inner);
            assert!(corr < 0.5, "d = {d}: {corr}");
        }
    }

    #[test]
    fn bad_subhologram_arguments_are_errors() {
        let k = ZernikeCoefficients::ZERO;
        assert!(corrected_subhologram(8, 8, 8e-6, 520e-9, 0.0, &k).is_err());
        assert!(corrected_subhologram(8, 8, 8e-6, 520e-9, f64::NAN, &k).is_err());
        assert!(corrected_subhologram(0, 8, 8e-6, 520e-9, 1e-3, &k).is_err());
        assert!(corrected_subhologram(8, 8, -8e-6, 520e-9, 1e-3, &k).is_err());
        assert!(corrected_subhologram(8, 8, 8e-6, 20e-6, 1e-3, &k).is_err());
    }
}

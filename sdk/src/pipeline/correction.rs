//! The viewer's aberration correction in the real-time frame ([`AberrationReport`], `PupilCorrection`):
//! the correction kernel `Φ = circ(ρ ≤ 1)·exp(i·ΣZ_j(ρ, θ))` of the aberration-corrected SM-LBM (paper Eq. 5,
//! [`crate::optics::zernike::amplitude_transfer_function`]) multiplied onto the spectrum of the CNN's
//! midpoint hologram, in the same spectral pass as the offset propagation's transfer function (Eq. 6):
//! `H_SLM = F⁻¹{F{H_mid}·Φ·T_s}`.
//!
//! This is exact when the coefficients are the same at every focus distance: an aberration at the viewer's
//! pupil, onto which the eyepiece images the Fourier plane of hologram space (the paper's Fig. 8 cylindrical
//! lens, a spectacle prescription). Then the corrected hologram of Eq. 5, which applies `Φ_{d_N}` to each depth
//! plane's content before summing, equals `Φ` applied to the sum: the midpoint hologram the shipped CNN
//! predicts. Coefficients that change with distance are applied at one distance, the midpoint plane's
//! `d = −s` (the volume's centre: `d_N = z_N − s` at `z_N = 0`, `docs/CONVENTIONS.md` §4), and
//! [`AberrationReport::residual_rms_rad`] says how much phase that leaves uncorrected over the volume.

use num_complex::Complex32;
use serde::Serialize;

use crate::display::AberrationProfile;
use crate::optics::zernike::fill_pupil_multiplier;
use crate::optics::ZernikeCoefficients;
use crate::optics::{OpticalSetup, SpectralPlan};

/// Depth planes over the volume at which [`AberrationReport::residual_rms_rad`] compares the calibrated
/// coefficients with the applied ones.
pub const RESIDUAL_PLANES: usize = 33;

/// Samples per side of the square grid whose points inside the unit pupil average the residual phase.
const PUPIL_GRID: usize = 64;

/// What a session's aberration correction applies, and what it leaves (see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AberrationReport {
    /// Signed distance `d` in metres from the SLM plane to the focus whose coefficients are applied: the
    /// midpoint plane's, `−s` (`s`: the session's offset).
    pub distance_m: f64,
    /// The applied coefficients per colour (R, G, B), radians at the pupil edge (Eq. 14–18).
    pub coefficients: [ZernikeCoefficients; 3],
    /// Per colour, the RMS in radians, over [`RESIDUAL_PLANES`] planes evenly spread across the volume
    /// (`z ∈ [−V/2, V/2]`, `d = z − s`) and over the unit pupil, of the phase `ΣZ_j` of the calibrated
    /// coefficients at `d` minus the applied ones: 0 when the coefficients are the same at every distance.
    pub residual_rms_rad: [f64; 3],
    /// Whether the correction is exact (every residual is 0).
    pub exact: bool,
    /// Whether the hologram CNN applies the correction itself, at every distance (it was trained for these
    /// aberrations, metadata `tensorholo.aberration`): no kernel multiplies its hologram, and the residual is
    /// 0 (what the CNN learned of Eq. 5 is measured by its evaluation, not here).
    pub by_cnn: bool,
}

impl AberrationReport {
    /// The report of `profile` applied at the midpoint plane of a session with offset `offset_m` (metres)
    /// on a display with `optics` (its volume depth bounds the residual's planes).
    pub(crate) fn new(profile: &AberrationProfile, optics: &OpticalSetup, offset_m: f64) -> Self {
        let distance_m = -offset_m;
        let coefficients = [0, 1, 2].map(|c| profile.coefficients(distance_m, c));
        let residual_rms_rad = [0, 1, 2].map(|c| {
            let mut sum = 0.0;
            let mut n = 0usize;
            for k in 0..RESIDUAL_PLANES {
                let z = optics.volume_depth_m * (k as f64 / (RESIDUAL_PLANES - 1) as f64 - 0.5);
                let at = profile.coefficients(z - offset_m, c).to_array();
                let applied = coefficients[c].to_array();
                let delta =
                    ZernikeCoefficients::from_array([0, 1, 2, 3, 4].map(|j| at[j] - applied[j]));
                if delta.is_zero() {
                    n += pupil_points();
                    continue;
                }
                for_each_pupil_point(|rx, ry| {
                    sum += delta.phase_xy(rx, ry).powi(2);
                    n += 1;
                });
            }
            (sum / n.max(1) as f64).sqrt()
        });
        Self {
            distance_m,
            coefficients,
            exact: residual_rms_rad.iter().all(|&r| r == 0.0),
            residual_rms_rad,
            by_cnn: false,
        }
    }

    /// The report of a session whose hologram CNN corrects `profile` itself ([`AberrationReport::by_cnn`]):
    /// the coefficients at the midpoint plane for reference, no residual.
    pub(crate) fn by_cnn(profile: &AberrationProfile, offset_m: f64) -> Self {
        let distance_m = -offset_m;
        Self {
            distance_m,
            coefficients: [0, 1, 2].map(|c| profile.coefficients(distance_m, c)),
            residual_rms_rad: [0.0; 3],
            exact: true,
            by_cnn: true,
        }
    }
}

impl std::fmt::Display for AberrationReport {
    /// The report in words, as `holo` logs it and the bindings' `GeneratorInfo::aberration` gives it: who
    /// corrects, the distance whose coefficients are applied, and the residual per colour (R/G/B, radians RMS).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let r = self.residual_rms_rad;
        if self.by_cnn {
            write!(
                f,
                "by the hologram CNN, trained for these aberrations (at every distance)"
            )
        } else if self.exact {
            write!(
                f,
                "the coefficients at d = {} m, exact (the same at every distance)",
                self.distance_m
            )
        } else {
            write!(
                f,
                "the coefficients at d = {} m; {:.3}/{:.3}/{:.3} rad RMS left uncorrected over the volume (R/G/B)",
                self.distance_m, r[0], r[1], r[2]
            )
        }
    }
}

/// Calls `f(ρx, ρy)` at the points of a [`PUPIL_GRID`]² grid (cell centres over `[−1, 1]²`) inside the unit
/// pupil.
fn for_each_pupil_point(mut f: impl FnMut(f64, f64)) {
    let step = 2.0 / PUPIL_GRID as f64;
    for i in 0..PUPIL_GRID {
        let ry = -1.0 + (i as f64 + 0.5) * step;
        for j in 0..PUPIL_GRID {
            let rx = -1.0 + (j as f64 + 0.5) * step;
            if rx * rx + ry * ry <= 1.0 {
                f(rx, ry);
            }
        }
    }
}

fn pupil_points() -> usize {
    let mut n = 0;
    for_each_pupil_point(|_, _| n += 1);
    n
}

/// The correction kernels the colour workers multiply their spectra by: one buffer in the session's spectrum
/// layout per distinct set of coefficients (one for a profile the same in every colour: 16.6 MB at 1080p),
/// shared by the colours that use it.
#[derive(Debug)]
pub(super) struct PupilCorrection {
    kernels: Vec<Vec<Complex32>>,
    of_colour: [usize; 3],
}

impl PupilCorrection {
    /// The kernels of `coefficients` (R, G, B) on `plan`'s grid, each scaled by `scale` (the inverse
    /// transform's normalisation where no transfer function carries it), reusing `reuse`'s buffers: no
    /// allocation when it holds as many kernels of this size.
    pub(super) fn build(
        plan: &SpectralPlan,
        coefficients: &[ZernikeCoefficients; 3],
        scale: f32,
        reuse: Option<Self>,
    ) -> Self {
        let mut distinct: Vec<ZernikeCoefficients> = Vec::with_capacity(3);
        let of_colour = coefficients.map(|c| match distinct.iter().position(|d| *d == c) {
            Some(i) => i,
            None => {
                distinct.push(c);
                distinct.len() - 1
            }
        });
        let mut kernels = reuse.map(|r| r.kernels).unwrap_or_default();
        kernels.truncate(distinct.len());
        kernels.resize_with(distinct.len(), Vec::new);
        for (kernel, c) in kernels.iter_mut().zip(&distinct) {
            fill_pupil_multiplier(plan, c, scale, kernel);
        }
        Self { kernels, of_colour }
    }

    /// Colour `colour`'s kernel (0 = R), in the plan's spectrum layout.
    pub(super) fn kernel(&self, colour: usize) -> &[Complex32] {
        &self.kernels[self.of_colour[colour.min(2)]]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::display::AberrationSample;

    fn astigmatism(a: f64) -> ZernikeCoefficients {
        ZernikeCoefficients {
            astigmatism_vertical: a,
            ..ZernikeCoefficients::ZERO
        }
    }

    #[test]
    fn a_uniform_profile_is_exact_and_a_varying_one_reports_its_analytic_residual() {
        let optics = OpticalSetup::default();
        let uniform = AberrationProfile::uniform(astigmatism(2.0));
        let r = AberrationReport::new(&uniform, &optics, 6e-3);
        assert!(r.exact && r.residual_rms_rad == [0.0; 3]);
        assert_eq!(r.distance_m, -6e-3);
        assert_eq!(r.coefficients[1], astigmatism(2.0));

        // Astigmatism growing linearly with d: a(d) = g·(d + 6 mm) around the applied a(−6 mm) = 0. Over the
        // volume the difference is g·z for z uniform in [−V/2, V/2], and ρ²·cos 2θ has mean square 1/6 over the
        // unit disc, so the RMS is |g|·V/√12·√(1/6) (the 33 planes' mean of z² is V²/12·(33+1)/(33−1)).
        let (g, v) = (400.0, optics.volume_depth_m);
        let sample = |d: f64| AberrationSample {
            distance_m: d,
            coefficients: [astigmatism(g * (d + 6e-3)); 3],
        };
        let varying = AberrationProfile::new(vec![sample(-0.1), sample(0.1)]).unwrap();
        let r = AberrationReport::new(&varying, &optics, 6e-3);
        assert!(!r.exact);
        assert!(r.coefficients[0].astigmatism_vertical.abs() < 1e-12);
        let planes = RESIDUAL_PLANES as f64;
        let expected = g * v * ((planes + 1.0) / (planes - 1.0) / 12.0 / 6.0).sqrt();
        for got in r.residual_rms_rad {
            assert!((got / expected - 1.0).abs() < 0.01, "{got} vs {expected}");
        }
    }

    #[test]
    fn colours_with_the_same_coefficients_share_one_kernel_and_a_rebuild_reuses_the_buffers() {
        let plan = SpectralPlan::new(8, 12, crate::optics::Padding::None).unwrap();
        let a = astigmatism(1.0);
        let b = astigmatism(-1.0);
        let one = PupilCorrection::build(&plan, &[a, a, a], 1.0, None);
        assert_eq!(one.kernels.len(), 1);
        let ptr = one.kernels[0].as_ptr();
        let two = PupilCorrection::build(&plan, &[a, b, a], 0.5, Some(one));
        assert_eq!(two.kernels.len(), 2);
        assert_eq!(two.kernels[0].as_ptr(), ptr);
        assert_eq!(two.kernel(0), two.kernel(2));
        assert_ne!(two.kernel(0), two.kernel(1));
        // The kernel is the conjugate of the opposite coefficients', scaled.
        for (x, y) in two.kernel(0).iter().zip(two.kernel(1)) {
            assert!((x - y.conj()).norm() < 1e-6);
            assert!(x.norm() == 0.0 || (x.norm() - 0.5).abs() < 1e-6);
        }
    }
}

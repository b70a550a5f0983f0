//! The aberration-corrected SM-LBM (paper Eq. 5): [`AberrationCorrectedSmLbm`] applies the correction kernel
//! `Φ_{d_N}` ([`crate::optics::zernike`], Eq. 14–19) of a calibrated [`AberrationProfile`] ([`crate::display`])
//! to the occlusion-processed content of every depth plane separately, at the cost of `G·(G + 1)/2`
//! propagations per colour for `G` non-empty planes instead of `G`.

use std::sync::atomic::{AtomicU64, Ordering};

use ndarray::Array3;
use num_complex::Complex32;
use serde::{Deserialize, Serialize};

use super::sm_lbm::{GapPropagation, SceneLayer, SmLbm};
use crate::display::AberrationProfile;
#[cfg(doc)]
use crate::error::HoloError;
use crate::error::Result;
use crate::optics::zernike::pupil_multiplier;
use crate::optics::{par_channels, Carrier};

/// The aberration correction of Eq. 5 besides the SM-LBM settings: the calibrated profile and where the SLM is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AberrationCorrection {
    /// Calibrated Zernike coefficients per focus distance and colour.
    pub profile: AberrationProfile,
    /// Signed distance `s` in metres from the midpoint plane to the SLM plane (the pipeline's offset,
    /// `docs/CONVENTIONS.md` §4). A depth plane at `z_N` is corrected with the coefficients at
    /// `d_N = z_N − s`, its signed distance from the SLM plane.
    pub slm_offset_m: f64,
}

/// The aberration-corrected silhouette-mask layer-based method (paper Eq. 5 and the text around it).
///
/// For the content of every non-empty depth plane `N` separately: start from the plane's own field (Eq. 1,
/// Maimone et al.'s initial phase, as [`SmLbm`]), propagate it toward the viewer through every nearer non-empty
/// plane applying only that plane's silhouette mask (occlusion, Eq. 3, without the addition term of Eq. 4),
/// propagate the result back to plane `N` (the occlusion-processed `L′_N`), multiply its spectrum by the
/// correction kernel `Φ_{d_N}` (Eq. 5; frequency-domain form, [`crate::optics::zernike::amplitude_transfer_function`]) with the
/// coefficients of [`AberrationProfile::coefficients`] at `d_N = z_N − s`, propagate it to the midpoint plane
/// `z = 0`, and sum over `N`.
///
/// Cost: `G·(G + 1)/2` propagations per colour for `G` non-empty planes (the paper's `N²/2`) instead of `G`
/// ([`AberrationCorrectedSmLbm::propagation_count`]); without silhouette masks every plane is independent and
/// the cost is `G`. Memory: three `[H, W]` fields per colour, whatever `G`. Colours run in parallel; the planes
/// of one colour run in order, so results are deterministic.
///
/// `Φ` is zero outside the pupil `ρ ≤ 1` (the SLM's diffraction cone), so even with zero coefficients the
/// result is plain SM-LBM band-limited to that circle.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AberrationCorrectedSmLbm {
    /// Planes, display geometry, propagation options and silhouette masks, as for [`SmLbm`].
    pub base: SmLbm,
    /// The correction.
    pub correction: AberrationCorrection,
}

impl AberrationCorrectedSmLbm {
    /// The propagation count of a scene with `nonempty_planes` non-empty planes: `G·(G + 1)/2` with silhouette
    /// masks, `G` without. Saturates instead of overflowing.
    pub(crate) fn propagations_for(&self, nonempty_planes: usize) -> usize {
        let g = nonempty_planes;
        if self.base.silhouette_masks {
            g.saturating_mul(g.saturating_add(1)) / 2
        } else {
            g
        }
    }

    /// The most propagations per colour any scene can need: `Self::propagations_for``(levels)`.
    pub fn worst_case_propagation_count(&self) -> usize {
        self.propagations_for(self.base.levels)
    }

    /// Number of angular-spectrum propagations per colour that [`AberrationCorrectedSmLbm::synthesize`]
    /// performs on `layers` (`G·(G + 1)/2` for `G` non-empty planes, with silhouette masks).
    ///
    /// Errors: as [`AberrationCorrectedSmLbm::synthesize`].
    pub fn propagation_count(&self, layers: &[SceneLayer]) -> Result<usize> {
        Ok(self.propagations_for(self.base.propagation_count(layers)?))
    }

    /// Checks the configuration: the SM-LBM settings, a finite offset, and the profile's recorded display
    /// against the setup.
    ///
    /// Errors: [`HoloError::InvalidParameter`].
    pub(crate) fn validate(&self) -> Result<()> {
        self.base.validate()?;
        crate::optics::check_offset("slm_offset_m", self.correction.slm_offset_m)?;
        self.correction.profile.check_setup(&self.base.setup)
    }

    /// Computes the aberration-corrected midpoint hologram `[3, H, W]` (R, G, B, complex) of a scene given as
    /// layers (front to back), Eq. 5.
    ///
    /// `progress(done, total)` is called after every propagation (from worker threads; colours run in
    /// parallel), `total = 3 ·` [`AberrationCorrectedSmLbm::propagation_count`].
    ///
    /// Errors: those of [`SmLbm::synthesize`]; [`HoloError::InvalidParameter`] for a non-finite offset or a
    /// profile calibrated for another display (`AberrationProfile::check_setup`).
    pub fn synthesize(
        &self,
        layers: &[SceneLayer],
        progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<Array3<Complex32>> {
        self.validate()?;
        let base = &self.base;
        let (h, w, planes) = base.bucket(layers)?;
        let props = base.setup.propagators(h, w, base.options)?;
        let groups = planes.groups.len();
        let total = 3 * self.propagations_for(groups) as u64;
        let done = AtomicU64::new(0);
        let tick = || {
            let d = done.fetch_add(1, Ordering::Relaxed) + 1;
            progress(d, total);
        };
        let z_of = |g: usize| base.setup.depth_to_z(base.plane_depth(planes.groups[g].0));
        let mut out = Array3::<Complex32>::zeros((3, h, w));
        par_channels(&mut out, |c, acc| {
            let prop = &props[c];
            let plan = prop.plan();
            let lambda = prop.wavelength_m();
            let mut scratch = plan.scratch();
            let mut gaps = GapPropagation::new(prop, base.plane_spacing_m());
            let mut work = vec![Complex32::default(); h * w];
            // With masks every plane's content ends at the nearest non-empty plane: one transfer function to z = 0.
            let to_midpoint_from_nearest = if base.silhouette_masks {
                Some(prop.transfer_function(-z_of(groups - 1), Carrier::Keep)?)
            } else {
                None
            };
            for n in 0..groups {
                let (level, _, _) = planes.groups[n];
                work.fill(Complex32::default());
                let initial = base.initial_phase(level, lambda);
                for &(p, a) in planes.points_of(n) {
                    work[p as usize] = initial * a[c];
                }
                // Occlusion by every nearer plane: propagate, mask, add nothing (Eq. 4 without its addition).
                let mut last = n;
                if base.silhouette_masks {
                    for m in n + 1..groups {
                        gaps.propagate(
                            &mut work,
                            planes.groups[m - 1].0 - planes.groups[m].0,
                            &mut scratch,
                        )?;
                        for &(p, _) in planes.points_of(m) {
                            work[p as usize] = Complex32::default();
                        }
                        last = m;
                        tick();
                    }
                }
                // Back to plane N (−(z_last − z_N)), Φ_{d_N} (Eq. 5), on to z = 0 (−z_N): the three spectral
                // multipliers commute and the two propagations compose, so they are one multiply by
                // Φ_{d_N}·H(−z_last) with one FFT pair. (With Matsushima's band limit, the limit is that of the
                // combined distance.)
                let d_n = z_of(n) - self.correction.slm_offset_m;
                let coefficients = self.correction.profile.coefficients(d_n, c);
                let mut multiplier = pupil_multiplier(plan, &coefficients);
                let own_tf;
                let tf = match &to_midpoint_from_nearest {
                    Some(tf) => tf,
                    None => {
                        own_tf = prop.transfer_function(-z_of(last), Carrier::Keep)?;
                        &own_tf
                    }
                };
                for (m, t) in multiplier.iter_mut().zip(tf.values()) {
                    *m *= t;
                }
                plan.apply(&mut work, &multiplier, &mut scratch)?;
                for (a, v) in acc.iter_mut().zip(&work) {
                    *a += v;
                }
                tick();
            }
            Ok(())
        })?;
        Ok(out)
    }
}

impl SmLbm {
    /// This configuration with the aberration correction of Eq. 5 ([`AberrationCorrectedSmLbm`]).
    pub fn with_aberration(self, correction: AberrationCorrection) -> AberrationCorrectedSmLbm {
        AberrationCorrectedSmLbm {
            base: self,
            correction,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::display::aberration::tests::two_point_profile;
    use crate::error::HoloError;
    use crate::optics::{OpticalSetup, SpectralPlan, ZernikeCoefficients};
    use ndarray::{Array2, Axis};

    /// Far amplitude, far depth, near amplitude, near depth, near validity.
    type Scene = (
        Array3<f32>,
        Array2<f32>,
        Array3<f32>,
        Array2<f32>,
        Array2<bool>,
    );

    /// The layers of [`scene`]: the near disc (amplitude `near`, depth `nd`, validity `disc`) in front of the
    /// far plane (amplitude `far`, depth `fd`).
    fn two_layers<'a>(
        near: &'a Array3<f32>,
        nd: &'a Array2<f32>,
        disc: &'a Array2<bool>,
        far: &'a Array3<f32>,
        fd: &'a Array2<f32>,
    ) -> [SceneLayer<'a>; 2] {
        [
            SceneLayer {
                amplitude: near.view(),
                depth: nd.view(),
                valid: Some(disc.view()),
            },
            SceneLayer {
                amplitude: far.view(),
                depth: fd.view(),
                valid: None,
            },
        ]
    }

    /// A small two-layer scene: a textured far plane and a nearer disc that hides part of it.
    fn scene(n: usize) -> Scene {
        let far_amp = Array3::from_shape_fn((3, n, n), |(c, y, x)| {
            0.5 + 0.4 * ((x as f32 * 0.7 + c as f32).sin() * (y as f32 * 0.45).cos())
        });
        let far_depth = Array2::from_elem((n, n), 0.8f32);
        let c = n as f32 / 2.0;
        let disc = Array2::from_shape_fn((n, n), |(y, x)| {
            (x as f32 - c).hypot(y as f32 - c) < n as f32 / 4.0
        });
        let near_amp =
            Array3::from_shape_fn((3, n, n), |(c, y, x)| 0.3 + 0.1 * ((x + y + c) % 3) as f32);
        let near_depth = Array2::from_elem((n, n), 0.2f32);
        (far_amp, far_depth, near_amp, near_depth, disc)
    }

    fn base(levels: usize) -> SmLbm {
        SmLbm {
            levels,
            ..SmLbm::default()
        }
    }

    fn max_abs_diff(a: &Array3<Complex32>, b: &Array3<Complex32>) -> (f32, f32) {
        let d = a
            .iter()
            .zip(b)
            .map(|(x, y)| (x - y).norm())
            .fold(0.0, f32::max);
        let m = b.iter().map(|v| v.norm()).fold(0.0, f32::max);
        (d, m)
    }

    /// `field` with Φ of `coefficients` applied per colour (unpadded plan).
    fn apply_kernel(
        field: &Array3<Complex32>,
        coefficients: [ZernikeCoefficients; 3],
    ) -> Array3<Complex32> {
        let (_, h, w) = field.dim();
        let plan = SpectralPlan::new(h, w, crate::optics::Padding::None).unwrap();
        let mut out = field.clone();
        for (c, mut lane) in out.axis_iter_mut(Axis(0)).enumerate() {
            let norm = 1.0 / plan.spectrum_len() as f32;
            let m: Vec<Complex32> = pupil_multiplier(&plan, &coefficients[c])
                .into_iter()
                .map(|v| v * norm)
                .collect();
            plan.apply(lane.as_slice_mut().unwrap(), &m, &mut plan.scratch())
                .unwrap();
        }
        out
    }

    #[test]
    fn zero_coefficients_give_plain_sm_lbm_band_limited_to_the_pupil() {
        let n = 48;
        let (fa, fd, na, nd, disc) = scene(n);
        let layers = two_layers(&na, &nd, &disc, &fa, &fd);
        let sm = base(16);
        let plain = apply_kernel(
            &sm.synthesize(&layers, &|_, _| {}).unwrap(),
            [ZernikeCoefficients::ZERO; 3],
        );
        let corrected = sm.with_aberration(AberrationCorrection {
            profile: AberrationProfile::uniform(ZernikeCoefficients::ZERO),
            slm_offset_m: 6e-3,
        });
        assert_eq!(corrected.propagation_count(&layers).unwrap(), 3);
        let calls = AtomicU64::new(0);
        let out = corrected
            .synthesize(&layers, &|done, total| {
                calls.fetch_add(1, Ordering::Relaxed);
                assert!(done <= total && total == 9);
            })
            .unwrap();
        assert_eq!(calls.load(Ordering::Relaxed), 9);
        let (d, m) = max_abs_diff(&out, &plain);
        assert!(d < 1e-5 * m, "max difference {d} of max {m}");
        // Band-limited indeed: differs from the unfiltered SM-LBM.
        let (d, m) = max_abs_diff(&out, &sm.synthesize(&layers, &|_, _| {}).unwrap());
        assert!(d > 1e-3 * m);
    }

    #[test]
    fn each_plane_gets_the_kernel_of_its_own_distance_after_occlusion() {
        // Eq. 5 by superposition: the far plane's occluded content with Φ(d_far) plus the near plane's content
        // with Φ(d_near). An occluder without content is a valid point of amplitude 0 (SmLbm's Eq. 3 rule).
        let n = 48;
        let (fa, fd, na, nd, disc) = scene(n);
        let zero_near = Array3::<f32>::zeros((3, n, n));
        let zero_far = Array3::<f32>::zeros((3, n, n));
        let layers = |near: &Array3<f32>, far: &Array3<f32>| -> Vec<Array3<f32>> {
            vec![near.clone(), far.clone()]
        };
        let make = |amps: &[Array3<f32>]| -> Array3<Complex32> {
            let ls = two_layers(&amps[0], &nd, &disc, &amps[1], &fd);
            base(11).synthesize(&ls, &|_, _| {}).unwrap()
        };
        let s = 2e-3;
        let setup = OpticalSetup::default();
        let (z_near, z_far) = (setup.depth_to_z(0.2), setup.depth_to_z(0.8));
        let profile = two_point_profile();
        let k_of = |z: f64| std::array::from_fn(|c| profile.coefficients(z - s, c));
        let expected = apply_kernel(&make(&layers(&zero_near, &fa)), k_of(z_far))
            + apply_kernel(&make(&layers(&na, &zero_far)), k_of(z_near));
        let ls = two_layers(&na, &nd, &disc, &fa, &fd);
        let out = base(11)
            .with_aberration(AberrationCorrection {
                profile: profile.clone(),
                slm_offset_m: s,
            })
            .synthesize(&ls, &|_, _| {})
            .unwrap();
        let (d, m) = max_abs_diff(&out, &expected);
        assert!(d < 1e-5 * m, "max difference {d} of max {m}");
        // The kernels differ per plane: one kernel for both is measurably different.
        let one = apply_kernel(&make(&layers(&na, &fa)), k_of(z_near));
        let (d, m) = max_abs_diff(&out, &one);
        assert!(d > 1e-2 * m, "{d} vs {m}");
    }

    #[test]
    fn without_masks_planes_are_independent_and_cost_one_propagation_each() {
        let n = 32;
        let (fa, fd, na, nd, disc) = scene(n);
        let ls = two_layers(&na, &nd, &disc, &fa, &fd);
        let sm = SmLbm {
            silhouette_masks: false,
            ..base(9)
        };
        let plain = apply_kernel(
            &sm.synthesize(&ls, &|_, _| {}).unwrap(),
            [ZernikeCoefficients::ZERO; 3],
        );
        let c = sm.with_aberration(AberrationCorrection {
            profile: AberrationProfile::uniform(ZernikeCoefficients::ZERO),
            slm_offset_m: 0.0,
        });
        assert_eq!(c.propagation_count(&ls).unwrap(), 2);
        let (d, m) = max_abs_diff(&c.synthesize(&ls, &|_, _| {}).unwrap(), &plain);
        assert!(d < 1e-5 * m, "{d} {m}");
    }

    #[test]
    fn propagation_counts_grow_as_g_squared_over_two() {
        let c = base(2048).with_aberration(AberrationCorrection {
            profile: AberrationProfile::uniform(ZernikeCoefficients::ZERO),
            slm_offset_m: 0.0,
        });
        assert_eq!(c.propagations_for(1), 1);
        assert_eq!(c.propagations_for(4), 10);
        assert_eq!(c.worst_case_propagation_count(), 2048 * 2049 / 2);
        assert_eq!(c.propagations_for(usize::MAX), usize::MAX / 2);
    }

    #[test]
    fn a_profile_for_another_display_or_a_bad_offset_is_refused() {
        let (fa, fd, ..) = scene(16);
        let ls = [SceneLayer {
            amplitude: fa.view(),
            depth: fd.view(),
            valid: None,
        }];
        let c = base(4).with_aberration(AberrationCorrection {
            profile: AberrationProfile::uniform(ZernikeCoefficients::ZERO)
                .with_display([640e-9, 520e-9, 450e-9], 8e-6),
            slm_offset_m: 0.0,
        });
        assert!(matches!(
            c.synthesize(&ls, &|_, _| {}),
            Err(HoloError::InvalidParameter {
                name: "wavelengths_m",
                ..
            })
        ));
        let c = base(4).with_aberration(AberrationCorrection {
            profile: AberrationProfile::uniform(ZernikeCoefficients::ZERO),
            slm_offset_m: f64::INFINITY,
        });
        assert!(c.synthesize(&ls, &|_, _| {}).is_err());
    }
}

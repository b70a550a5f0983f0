//! The reference (non-learned) hologram pipeline: SM-LBM midpoint hologram (Eq. 1–4) → offset propagation
//! (Eq. 6) → double phase encoding (Eq. 7, plain, AA-DPM or BL-DPM) → 8-bit SLM codes (linear LUT) →
//! simulated focal stack (Eq. 8–10). This is the ground truth the CNNs learn and the baseline they beat.

use std::time::Instant;

use ndarray::{Array3, Axis};
use num_complex::Complex32;

use crate::display::AberrationProfile;
use crate::encoding::{double_phase_encode, phase_to_codes, DoublePhase, DoublePhaseMethod};
use crate::error::{invalid, Result};
use crate::optics::{focal_stack, post_encoding_midpoint, propagate_colour, Carrier};
use crate::synthesis::{AberrationCorrectedSmLbm, AberrationCorrection, SceneLayer, SmLbm};

/// Configuration of [`ReferencePipeline::run`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ReferencePipeline {
    /// Midpoint hologram synthesis (levels, display geometry, propagation options).
    pub synthesis: SmLbm,
    /// Signed distance `s` in metres from the midpoint plane to the SLM plane (`docs/CONVENTIONS.md` §4; the
    /// paper uses 0, 6 and 12 mm; `s > 0` puts the 3D image behind the hologram).
    pub offset_m: f64,
    /// Phase-only encoding.
    pub encoding: DoublePhaseMethod,
}

impl Default for ReferencePipeline {
    fn default() -> Self {
        Self {
            synthesis: SmLbm::default(),
            offset_m: 0.0,
            encoding: DoublePhaseMethod::default(),
        }
    }
}

/// Wall-clock seconds spent in each stage.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct StageTimings {
    /// SM-LBM midpoint hologram.
    pub synthesis_s: f64,
    /// Offset propagation to the SLM plane.
    pub offset_propagation_s: f64,
    /// Double phase encoding (with its pre-filter).
    pub encoding_s: f64,
    /// Phase → 8-bit codes.
    pub lut_s: f64,
}

/// Everything [`ReferencePipeline::run`] produces.
#[derive(Debug, Clone)]
pub struct ReferenceHologram {
    /// Midpoint hologram `[3, H, W]` (R, G, B, complex).
    pub midpoint: Array3<Complex32>,
    /// Phase-only SLM pattern and its amplitude normaliser.
    pub double_phase: DoublePhase,
    /// 8-bit SLM codes `[3, H, W]`, one plane per laser.
    pub codes: Array3<u8>,
    /// Stage timings.
    pub timings: StageTimings,
}

impl ReferencePipeline {
    /// Runs the pipeline on scene layers (an RGB-D image is one layer, an LDI several; see [`SceneLayer`]).
    /// `progress(done, total)` reports SM-LBM propagations.
    ///
    /// Errors: those of [`SmLbm::synthesize`], [`double_phase_encode`] and a non-finite offset.
    pub fn run(
        &self,
        layers: &[SceneLayer],
        progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<ReferenceHologram> {
        if !self.offset_m.is_finite() {
            return Err(invalid("offset_m", "must be finite"));
        }
        let t = Instant::now();
        let midpoint = self.synthesis.synthesize(layers, progress)?;
        self.encode_midpoint(midpoint, t.elapsed().as_secs_f64())
    }

    /// [`ReferencePipeline::run`] with the aberration-corrected SM-LBM of Eq. 5
    /// ([`AberrationCorrectedSmLbm`], `docs/ABERRATION.md`): `self.synthesis` with `profile`, the SLM plane at
    /// `self.offset_m`. Costs `G·(G + 1)/2` propagations per colour for `G` non-empty planes
    /// ([`AberrationCorrectedSmLbm::propagation_count`]); `progress(done, total)` reports them.
    ///
    /// Errors: those of [`ReferencePipeline::run`] and [`AberrationCorrectedSmLbm::synthesize`].
    pub fn run_aberration_corrected(
        &self,
        layers: &[SceneLayer],
        profile: &AberrationProfile,
        progress: &(dyn Fn(u64, u64) + Sync),
    ) -> Result<ReferenceHologram> {
        if !self.offset_m.is_finite() {
            return Err(invalid("offset_m", "must be finite"));
        }
        let t = Instant::now();
        let midpoint = self
            .aberration_corrected(profile)
            .synthesize(layers, progress)?;
        self.encode_midpoint(midpoint, t.elapsed().as_secs_f64())
    }

    /// The aberration-corrected synthesis [`ReferencePipeline::run_aberration_corrected`] uses.
    pub fn aberration_corrected(&self, profile: &AberrationProfile) -> AberrationCorrectedSmLbm {
        self.synthesis.with_aberration(AberrationCorrection {
            profile: profile.clone(),
            slm_offset_m: self.offset_m,
        })
    }

    /// The stages after synthesis: offset propagation, double phase, LUT.
    fn encode_midpoint(
        &self,
        midpoint: Array3<Complex32>,
        synthesis_s: f64,
    ) -> Result<ReferenceHologram> {
        let t = Instant::now();
        let mut slm_field = midpoint.clone();
        if self.offset_m != 0.0 {
            propagate_colour(
                &mut slm_field,
                &self.synthesis.setup,
                self.offset_m,
                Carrier::Remove,
                self.synthesis.options,
            )?;
        }
        let offset_propagation_s = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let double_phase = double_phase_encode(slm_field.view(), &self.encoding)?;
        let encoding_s = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let codes = phase_to_codes(double_phase.phase.view());
        let lut_s = t.elapsed().as_secs_f64();
        Ok(ReferenceHologram {
            midpoint,
            double_phase,
            codes,
            timings: StageTimings {
                synthesis_s,
                offset_propagation_s,
                encoding_s,
                lut_s,
            },
        })
    }

    /// Simulated amplitude reconstructions `[3, H, W]` of the phase-only pattern at normalised depths `depths`:
    /// Fourier filter at the SLM, propagation to `z(d)` (Eq. 8–10), rescaled by the encoding's amplitude
    /// normaliser so that they are comparable with the scene amplitude.
    ///
    /// Errors: as [`simulate_phase_only`](crate::optics::simulate_phase_only) and [`focal_stack`].
    pub fn reconstruct_phase_only(
        &self,
        hologram: &ReferenceHologram,
        depths: &[f64],
    ) -> Result<Vec<Array3<f32>>> {
        let setup = &self.synthesis.setup;
        let options = self.synthesis.options;
        let at_mid = post_encoding_midpoint(
            hologram.double_phase.phase.view(),
            hologram.double_phase.amplitude_scale,
            setup,
            self.offset_m,
            options,
        )?;
        focal_stack(at_mid.view(), setup, 0.0, depths, options, false)
    }

    /// Amplitude reconstructions `[3, H, W]` of the complex midpoint hologram at normalised depths `depths`
    /// (what an ideal complex-modulating display would show; the reference for encoding losses).
    ///
    /// Errors: as [`focal_stack`].
    pub fn reconstruct_complex(
        &self,
        hologram: &ReferenceHologram,
        depths: &[f64],
    ) -> Result<Vec<Array3<f32>>> {
        focal_stack(
            hologram.midpoint.view(),
            &self.synthesis.setup,
            0.0,
            depths,
            self.synthesis.options,
            false,
        )
    }
}

/// Normalised depths at which to preview a scene: the 5th, 50th and 95th percentiles of `depth` values
/// (near, mid, far), so that previews focus on content that exists.
pub fn preview_depths<'a>(depth: impl IntoIterator<Item = &'a f32>) -> [f64; 3] {
    let mut v: Vec<f32> = depth
        .into_iter()
        .copied()
        .filter(|d| d.is_finite())
        .collect();
    if v.is_empty() {
        return [0.0, 0.5, 1.0];
    }
    v.sort_by(f32::total_cmp);
    let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize] as f64;
    [q(0.05), q(0.5), q(0.95)]
}

/// Per-channel mean of a `[3, H, W]` array (for reports).
pub fn channel_means(a: &Array3<f32>) -> [f32; 3] {
    let mut m = [0.0; 3];
    for (c, ch) in a.axis_iter(Axis(0)).enumerate().take(3) {
        m[c] = ch.mean().unwrap_or(0.0);
    }
    m
}

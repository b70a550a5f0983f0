//! What changes on the SLM from one video frame to the next: the phase churn of consecutive 8-bit patterns
//! ([`phase_churn`]) and the alignment of each colour's global phase to the previous frame
//! ([`PhaseContinuity`]).
//!
//! A liquid-crystal SLM settles more slowly after a large phase swing than after a small one (Otón et al.,
//! "Dynamic response of liquid-crystal spatial light modulators", 2009), so the change between consecutive
//! patterns is worth counting. A global phase (the same offset at every pixel of one colour) changes nothing
//! the viewer sees (`|e^{iθ}·U| = |U|` at every plane), yet the CNN and the double phase encoding fix it anew
//! for every frame; shifting each colour's codes so that its global phase follows the previous frame's
//! removes that part of the churn. With the linear look-up table (`2π·c/256`) a shift of the codes by `s` is
//! exactly a global phase of `2π·s/256`; through a calibrated table it is not, so alignment is for the linear
//! table only.
//!
//! [`PhaseContinuity`] keeps a stream's temporal state (the last pattern sent, the churn so far, the
//! alignment and its rule): `holo video` and [`crate::generator::HologramStream`] both run their patterns
//! through it.

use ndarray::{Array3, ArrayView3, ArrayViewMut3, Axis};

use crate::error::{HoloError, Result};

/// The change between two consecutive SLM patterns, through the linear look-up table (code `c` ↔ phase
/// `2π·c/256`), each pixel's difference wrapped to `[−π, π]`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct PhaseChurn {
    /// Mean `|Δφ|` over every colour and pixel, radians (0 for identical patterns; π/2 for unrelated ones).
    pub mean_abs_rad: f64,
    /// The share of (colour, pixel) values whose `|Δφ|` exceeds π/2 (64 codes), `[0, 1]`.
    pub above_half_pi: f64,
}

/// The cyclic difference `b − a` of two codes, in codes, within `[−128, 127]`.
fn cyclic(a: u8, b: u8) -> i32 {
    let d = (i32::from(b) - i32::from(a)).rem_euclid(256);
    if d >= 128 {
        d - 256
    } else {
        d
    }
}

fn check_shapes(previous: &ArrayView3<u8>, current: &ArrayView3<u8>) -> Result<()> {
    if previous.dim() != current.dim() || previous.is_empty() {
        return Err(HoloError::ShapeMismatch {
            what: "consecutive SLM patterns [C, H, W]".into(),
            expected: previous.shape().to_vec(),
            got: current.shape().to_vec(),
        });
    }
    Ok(())
}

/// The phase churn from `previous` to `current` (8-bit codes `[C, H, W]`, e.g. `[3, H, W]` R, G, B).
///
/// Errors: [`HoloError::ShapeMismatch`] for patterns of different shapes or empty ones.
pub fn phase_churn(previous: ArrayView3<u8>, current: ArrayView3<u8>) -> Result<PhaseChurn> {
    check_shapes(&previous, &current)?;
    let (mut sum, mut above) = (0u64, 0u64);
    for (&a, &b) in previous.iter().zip(current.iter()) {
        let d = cyclic(a, b).unsigned_abs();
        sum += u64::from(d);
        above += u64::from(d > 64);
    }
    let n = previous.len() as f64;
    Ok(PhaseChurn {
        mean_abs_rad: sum as f64 / n * (std::f64::consts::TAU / 256.0),
        above_half_pi: above as f64 / n,
    })
}

/// Shifts each colour of `current` (codes `[C, H, W]`) by the whole number of codes that brings its global
/// phase closest to `previous`'s: `s_c = round(256/2π · arg Σ e^{i·2π(p − c)/256})` over the colour's pixels,
/// then `c ← (c + s_c) mod 256`. Through the linear look-up table this multiplies the colour's field by
/// `e^{i·2π·s_c/256}`: what the viewer sees is unchanged, the churn ([`phase_churn`]) falls. Returns the
/// shifts (codes, `0..256`).
///
/// Errors: [`HoloError::ShapeMismatch`] for patterns of different shapes or empty ones.
pub(crate) fn align_global_phase(
    previous: ArrayView3<u8>,
    mut current: ArrayViewMut3<u8>,
) -> Result<Vec<u8>> {
    check_shapes(&previous, &current.view())?;
    let step = std::f64::consts::TAU / 256.0;
    let mut shifts = Vec::with_capacity(current.len_of(Axis(0)));
    for (p, mut c) in previous.outer_iter().zip(current.outer_iter_mut()) {
        let (mut re, mut im) = (0.0f64, 0.0f64);
        for (&a, &b) in p.iter().zip(c.iter()) {
            let d = f64::from(cyclic(b, a)) * step;
            re += d.cos();
            im += d.sin();
        }
        let s = if re == 0.0 && im == 0.0 {
            0
        } else {
            ((im.atan2(re) / step).round() as i32).rem_euclid(256) as u8
        };
        if s != 0 {
            c.mapv_inplace(|v| v.wrapping_add(s));
        }
        shifts.push(s);
    }
    Ok(shifts)
}

/// What one frame of a stream changed on the SLM ([`PhaseContinuity::next`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TemporalStep {
    /// The churn from the previous pattern sent to this one (after the alignment, where it applies).
    pub churn: PhaseChurn,
    /// With the alignment: each colour's code shift (`0..256`) applied to this frame's codes.
    pub aligned_shift_codes: Option<Vec<u8>>,
}

/// A stream's churn over its frames ([`PhaseContinuity::summary`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct TemporalSummary {
    /// Frame-to-frame transitions counted (frames − 1).
    pub transitions: usize,
    /// The mean over the transitions of [`PhaseChurn::mean_abs_rad`], radians.
    pub mean_churn_rad: f64,
    /// The largest [`PhaseChurn::mean_abs_rad`], radians.
    pub max_churn_rad: f64,
    /// The mean of [`PhaseChurn::above_half_pi`], `[0, 1]`.
    pub mean_above_half_pi: f64,
    /// The largest [`PhaseChurn::above_half_pi`], `[0, 1]`.
    pub max_above_half_pi: f64,
    /// Whether each frame's global phase was aligned to the previous frame's.
    pub align_phase: bool,
}

/// The temporal state of a stream of SLM patterns: the last pattern sent, the churn so far and, where asked,
/// each colour's global phase aligned to the previous frame's (a whole-code shift per colour, through the
/// linear look-up table only). One per stream; [`PhaseContinuity::next`] on each frame's codes in order.
#[derive(Debug, Clone, Default)]
pub struct PhaseContinuity {
    align: bool,
    previous: Option<Array3<u8>>,
    transitions: usize,
    sum: (f64, f64),
    max: (f64, f64),
}

impl PhaseContinuity {
    /// A stream's state: `align_phase` to shift each frame's codes so that each colour's global phase follows
    /// the previous frame's; `calibrated_lut`: whether the codes go through a calibrated look-up table.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`align_phase`) for an alignment through a calibrated table,
    /// where a code shift is not a global phase.
    pub fn new(align_phase: bool, calibrated_lut: bool) -> Result<Self> {
        if align_phase && calibrated_lut {
            return Err(crate::error::invalid(
                "align_phase",
                "a code shift is a global phase only through the linear look-up table; these codes go through \
                 a display calibration's table",
            ));
        }
        Ok(Self {
            align: align_phase,
            ..Self::default()
        })
    }

    /// Takes the next frame's codes (`[C, H, W]`, the SLM pattern about to be sent): aligns them to the
    /// previous frame's where asked (in place), counts the churn from the previous frame and keeps them as
    /// the previous frame (its buffer reused). `None` for the first frame.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for codes of another shape than the previous frame's (the state
    /// is unchanged).
    pub fn next(&mut self, mut codes: ArrayViewMut3<u8>) -> Result<Option<TemporalStep>> {
        let step = match &self.previous {
            Some(p) => {
                let shifts = if self.align {
                    Some(align_global_phase(p.view(), codes.view_mut())?)
                } else {
                    None
                };
                let churn = phase_churn(p.view(), codes.view())?;
                self.transitions += 1;
                self.sum.0 += churn.mean_abs_rad;
                self.sum.1 += churn.above_half_pi;
                self.max.0 = self.max.0.max(churn.mean_abs_rad);
                self.max.1 = self.max.1.max(churn.above_half_pi);
                Some(TemporalStep {
                    churn,
                    aligned_shift_codes: shifts,
                })
            }
            None => None,
        };
        match &mut self.previous {
            Some(p) => p.assign(&codes),
            None => self.previous = Some(codes.to_owned()),
        }
        Ok(step)
    }

    /// The churn over the frames so far; `None` before the second frame.
    pub fn summary(&self) -> Option<TemporalSummary> {
        let n = self.transitions;
        (n > 0).then(|| TemporalSummary {
            transitions: n,
            mean_churn_rad: self.sum.0 / n as f64,
            max_churn_rad: self.max.0,
            mean_above_half_pi: self.sum.1 / n as f64,
            max_above_half_pi: self.max.1,
            align_phase: self.align,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::splitmix::SplitMix64;
    use ndarray::Array3;

    fn random(seed: u64) -> Array3<u8> {
        let mut rng = SplitMix64::new(seed);
        Array3::from_shape_fn((3, 9, 13), |_| (rng.next_f64() * 256.0) as u8)
    }

    #[test]
    fn churn_is_zero_for_a_still_pattern_and_counts_wrapped_differences() {
        let a = random(1);
        let c = phase_churn(a.view(), a.view()).unwrap();
        assert_eq!((c.mean_abs_rad, c.above_half_pi), (0.0, 0.0));
        // 255 → 1 is two codes, not 254; 0 → 128 is π (above π/2); 0 → 64 is exactly π/2 (not above).
        let p = Array3::from_shape_vec((1, 1, 3), vec![255u8, 0, 0]).unwrap();
        let q = Array3::from_shape_vec((1, 1, 3), vec![1u8, 128, 64]).unwrap();
        let c = phase_churn(p.view(), q.view()).unwrap();
        let step = std::f64::consts::TAU / 256.0;
        assert!((c.mean_abs_rad - (2.0 + 128.0 + 64.0) / 3.0 * step).abs() < 1e-12);
        assert!((c.above_half_pi - 1.0 / 3.0).abs() < 1e-12);
        // Unrelated patterns: about π/2 and a half.
        let c = phase_churn(random(2).view(), random(3).view()).unwrap();
        assert!(
            (c.mean_abs_rad - std::f64::consts::FRAC_PI_2).abs() < 0.15,
            "{c:?}"
        );
        assert!(phase_churn(a.view(), random(4).slice(ndarray::s![.., 1.., ..])).is_err());
    }

    #[test]
    fn alignment_undoes_a_global_phase_and_lowers_churn() {
        let a = random(5);
        // The same pattern with each colour's global phase moved (and a little noise on one pixel).
        let mut b = a.clone();
        for (c, shift) in [(0, 37u8), (1, 200), (2, 128)] {
            b.index_axis_mut(Axis(0), c)
                .mapv_inplace(|v| v.wrapping_add(shift));
        }
        b[[1, 4, 4]] = b[[1, 4, 4]].wrapping_add(90);
        let before = phase_churn(a.view(), b.view()).unwrap();
        let shifts = align_global_phase(a.view(), b.view_mut()).unwrap();
        assert_eq!(shifts, vec![219, 56, 128]); // −37, −200 and −128 codes, mod 256
        let after = phase_churn(a.view(), b.view()).unwrap();
        assert!(
            after.mean_abs_rad < 0.01 * before.mean_abs_rad,
            "{before:?} → {after:?}"
        );
        // What the viewer sees is the same: the displayed field's intensity at the midpoint plane (6 mm from
        // the SLM) of the aligned codes equals the unaligned one's to float rounding.
        let shown = |codes: &Array3<u8>| {
            let phase = codes.mapv(|c| crate::encoding::LinearLut.phase(c));
            crate::optics::simulate_phase_only(
                phase.view(),
                &crate::optics::OpticalSetup::default(),
                6e-3,
                crate::optics::PropagationOptions::default(),
            )
            .unwrap()
            .mapv(|v| v.norm_sqr())
        };
        let mut moved = b.clone();
        for (c, shift) in [(0, 77u8), (1, 3), (2, 250)] {
            moved
                .index_axis_mut(Axis(0), c)
                .mapv_inplace(|v| v.wrapping_add(shift));
        }
        let (i0, i1) = (shown(&b), shown(&moved));
        let peak = i0.iter().fold(0f32, |m, &v| m.max(v));
        let worst = i0
            .iter()
            .zip(i1.iter())
            .fold(0f32, |m, (a, b)| m.max((a - b).abs()));
        assert!(
            worst <= 1e-5 * peak,
            "intensity changed by {worst} of {peak}"
        );
        // A still pattern is left alone.
        let mut same = a.clone();
        assert_eq!(
            align_global_phase(a.view(), same.view_mut()).unwrap(),
            vec![0, 0, 0]
        );
        assert_eq!(same, a);
    }

    /// The stream's state: nothing for the first frame; each later frame's churn from the one before (as
    /// [`phase_churn`] counts it), aligned where asked; the summary's means and maxima; another shape refused
    /// with the state unchanged; alignment through a calibrated table refused.
    #[test]
    fn phase_continuity_counts_churn_and_aligns_frame_to_frame() {
        let frames = [random(11), random(12), random(13)];
        let mut plain = PhaseContinuity::new(false, true).unwrap();
        let mut churns = Vec::new();
        for (i, f) in frames.iter().enumerate() {
            let mut codes = f.clone();
            let step = plain.next(codes.view_mut()).unwrap();
            assert_eq!(codes, *f, "codes changed without alignment");
            match i {
                0 => assert!(step.is_none() && plain.summary().is_none()),
                _ => {
                    let want = phase_churn(frames[i - 1].view(), f.view()).unwrap();
                    assert_eq!(step.unwrap().churn, want);
                    churns.push(want);
                }
            }
        }
        let s = plain.summary().unwrap();
        assert_eq!(s.transitions, 2);
        assert!(
            (s.mean_churn_rad - (churns[0].mean_abs_rad + churns[1].mean_abs_rad) / 2.0).abs()
                < 1e-15
        );
        assert_eq!(
            s.max_churn_rad,
            churns[0].mean_abs_rad.max(churns[1].mean_abs_rad)
        );
        assert!(!s.align_phase);
        // Another shape: refused, the state kept.
        let mut small = Array3::<u8>::zeros((3, 2, 2));
        assert!(plain.next(small.view_mut()).is_err());
        assert_eq!(plain.summary().unwrap().transitions, 2);

        // Aligned: a frame that is the previous one with each colour's global phase moved comes back as it.
        let mut aligned = PhaseContinuity::new(true, false).unwrap();
        let mut first = frames[0].clone();
        aligned.next(first.view_mut()).unwrap();
        let mut moved = frames[0].clone();
        for (c, shift) in [(0, 9u8), (1, 100), (2, 250)] {
            moved
                .index_axis_mut(Axis(0), c)
                .mapv_inplace(|v| v.wrapping_add(shift));
        }
        let step = aligned.next(moved.view_mut()).unwrap().unwrap();
        assert_eq!(moved, frames[0]);
        assert_eq!(step.aligned_shift_codes, Some(vec![247, 156, 6]));
        assert_eq!(step.churn.mean_abs_rad, 0.0);
        assert!(aligned.summary().unwrap().align_phase);
        let e = PhaseContinuity::new(true, true).unwrap_err().to_string();
        assert!(e.contains("align_phase"), "{e}");
    }
}

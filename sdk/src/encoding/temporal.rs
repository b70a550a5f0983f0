//! What changes on the SLM from one video frame to the next: the phase churn of consecutive 8-bit patterns
//! ([`phase_churn`]) and the alignment of each colour's global phase to the previous frame
//! ([`align_global_phase`]).
//!
//! A liquid-crystal SLM settles more slowly after a large phase swing than after a small one (Otón et al.,
//! "Dynamic response of liquid-crystal spatial light modulators", 2009), so the change between consecutive
//! patterns is worth counting. A global phase (the same offset at every pixel of one colour) changes nothing
//! the viewer sees (`|e^{iθ}·U| = |U|` at every plane), yet the CNN and the double phase encoding fix it anew
//! for every frame; shifting each colour's codes so that its global phase follows the previous frame's
//! removes that part of the churn. With the linear look-up table (`2π·c/256`) a shift of the codes by `s` is
//! exactly a global phase of `2π·s/256`; through a calibrated table it is not, so alignment is for the linear
//! table only.

use ndarray::{ArrayView3, ArrayViewMut3, Axis};

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
pub fn align_global_phase(
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
}

//! Hologram quality with the protocol of the paper's Table 2: PSNR and SSIM of a predicted midpoint
//! hologram's amplitude against the ground truth (SM-LBM), and averaged over a focal stack of the 15 most
//! frequent depths of the scene plus 5 random ones (the dynamic focal stack of TensorHolo V1/V2).
//! The same protocol runs in `training/tensorholo_training/evaluate.py`; the 5 random depths come from
//! different random generators there (torch) and here (SplitMix64, Steele et al. 2014, whose outputs are
//! fixed by the algorithm), so per-scene figures differ slightly.

use crate::error::{invalid, Result};
use crate::metrics::{psnr, ssim_multichannel};
use crate::optics::{focal_stack, OpticalSetup, PropagationOptions};
use crate::refine::engine::Refiner;
use crate::refine::options::RefineOptions;
use crate::refine::target::{FocalTarget, PLANES_RANGE};
use crate::splitmix::SplitMix64;
use ndarray::{ArrayView2, ArrayView3};
use num_complex::Complex32;

/// Focal depths of a scene: a histogram of the normalised depth `depth` `[H, W]` in `bins` bins over
/// `[0, 1]`, bins sorted by count (descending, stable), one uniform jitter `u ∈ [0, 1)` for all bin
/// centres (`(index + u)/bins`), the `top` most populated bins plus `random` others drawn without
/// replacement from the rest (a partial Fisher–Yates shuffle). The jitter and the draws come from one
/// SplitMix64 stream seeded with `seed`, in that order. Paper: 200 bins, 15 + 5.
///
/// Returns `top + random` normalised depths in `[0, 1)`.
///
/// Errors: [`HoloError::InvalidParameter`](crate::HoloError) if `top + random > bins` or `bins == 0`;
/// [`HoloError::InvalidDepth`](crate::HoloError) for non-finite depths.
pub fn focal_depths(
    depth: ArrayView2<f32>,
    bins: usize,
    top: usize,
    random: usize,
    seed: u64,
) -> Result<Vec<f64>> {
    if bins == 0 || top.checked_add(random).is_none_or(|n| n > bins) {
        return Err(invalid(
            "bins",
            format!("need 0 < top + random ≤ bins, got {top} + {random} of {bins}"),
        ));
    }
    if depth.iter().any(|d| !d.is_finite()) {
        return Err(crate::HoloError::InvalidDepth(
            "focal depths: depth map holds NaN or infinite values".into(),
        ));
    }
    let mut hist = vec![0usize; bins];
    for &d in depth {
        // torch.histc: values outside [0, 1] are ignored; 1.0 falls into the last bin.
        if (0.0..=1.0).contains(&d) {
            hist[((d as f64 * bins as f64) as usize).min(bins - 1)] += 1;
        }
    }
    let mut order: Vec<usize> = (0..bins).collect();
    order.sort_by(|a, b| hist[*b].cmp(&hist[*a])); // stable
    let mut rng = SplitMix64::new(seed);
    let u = rng.next_f64();
    let mut rest = order.split_off(top);
    for i in 0..random {
        let j = rng.below(i, rest.len());
        rest.swap(i, j);
    }
    Ok(order
        .iter()
        .chain(&rest[..random])
        .map(|&i| (i as f64 + u) / bins as f64)
        .collect())
}

/// Table 2 figures of one scene (data range 1 on amplitudes, scikit-image definitions).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct Table2Scores {
    /// PSNR (dB) of the midpoint amplitude `|H|` `[3, H, W]` against the ground truth's.
    pub psnr_amp: f64,
    /// SSIM of the midpoint amplitude (mean over R, G, B).
    pub ssim_amp: f64,
    /// PSNR (dB) of the focal stack `|ASM(H, z(d))|`, mean over the focal depths.
    pub psnr_fs: f64,
    /// SSIM of the focal stack, mean over the focal depths.
    pub ssim_fs: f64,
}

/// Scores a predicted midpoint hologram `pred` against the ground truth `gt` (both complex `[3, H, W]`,
/// R, G, B, at the midpoint plane) with the Table 2 protocol at the normalised focal `depths`
/// ([`focal_depths`]).
///
/// Errors: shape mismatches, non-finite values, depths outside `[0, 1]` (as [`focal_stack`], [`psnr`],
/// [`ssim_multichannel`]); an empty `depths`.
pub fn table2(
    pred: ArrayView3<Complex32>,
    gt: ArrayView3<Complex32>,
    setup: &OpticalSetup,
    options: PropagationOptions,
    depths: &[f64],
) -> Result<Table2Scores> {
    if depths.is_empty() {
        return Err(invalid("depths", "need at least one focal depth"));
    }
    let (pa, ga) = (pred.mapv(|v| v.norm()), gt.mapv(|v| v.norm()));
    let psnr_amp = psnr(ga.view(), pa.view(), 1.0)? as f64;
    let ssim_amp = ssim_multichannel(ga.view(), pa.view(), 1.0)? as f64;
    let sp = focal_stack(pred, setup, 0.0, depths, options, false)?;
    let sg = focal_stack(gt, setup, 0.0, depths, options, false)?;
    let (mut psnr_fs, mut ssim_fs) = (0.0, 0.0);
    for (p, g) in sp.iter().zip(&sg) {
        psnr_fs += psnr(g.view(), p.view(), 1.0)? as f64;
        ssim_fs += ssim_multichannel(g.view(), p.view(), 1.0)? as f64;
    }
    let n = depths.len() as f64;
    Ok(Table2Scores {
        psnr_amp,
        ssim_amp,
        psnr_fs: psnr_fs / n,
        ssim_fs: ssim_fs / n,
    })
}

/// The PSNR in dB of what the SLM pattern `phase` `[3, H, W]` (radians, as displayed: not quantised) shows
/// against `target`'s focal stack (amplitudes, data range 1), each colour at its least-squares scale: the
/// focal-stack refinement's loss as a score ([`crate::refine::IterationRecord::psnr_db`]), for the display
/// `setup` with its SLM `offset_m` metres from the midpoint plane (`docs/REFINE.md`). Scoring a refinement at
/// [`crate::refine::held_out_depths`] measures it where its loss never looked. It runs the refinement's own
/// model (its plan for `target`, every core), without the gradient's buffers.
///
/// Errors: [`crate::HoloError::InvalidParameter`] for a padded propagation, a non-finite offset or an invalid
/// setup; [`crate::HoloError::ShapeMismatch`] for a pattern of another size than the target's;
/// [`crate::HoloError::InvalidData`] for a non-finite phase.
pub fn focal_psnr(
    phase: ArrayView3<f32>,
    setup: &OpticalSetup,
    propagation: PropagationOptions,
    offset_m: f64,
    target: FocalTarget,
) -> Result<f64> {
    let options = RefineOptions {
        iterations: 1,
        planes: target.depths().len().clamp(PLANES_RANGE.0, PLANES_RANGE.1),
        quantised: false,
        ..Default::default()
    };
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    Refiner::new(setup, propagation, offset_m, target, options, threads)?
        .score(phase)
        .map(|r| r.psnr_db)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{Array2, Array3};

    #[test]
    fn focal_depths_pick_the_most_populated_bins_first() {
        // 60 % of pixels at d = 0.25, 30 % at 0.7575, 10 % at 0.9025 (bins 50, 151, 180 of 200).
        let depth = Array2::from_shape_fn((10, 10), |(y, _)| match y {
            0..=5 => 0.25,
            6..=8 => 0.7575,
            _ => 0.9025,
        });
        let d = focal_depths(depth.view(), 200, 3, 5, 7).unwrap();
        assert_eq!(d.len(), 8);
        let bin = |v: f64| (v * 200.0) as usize;
        assert_eq!(bin(d[0]), 50);
        assert_eq!(bin(d[1]), 151);
        assert_eq!(bin(d[2]), 180);
        let mut rest: Vec<usize> = d[3..].iter().map(|&v| bin(v)).collect();
        rest.sort_unstable();
        rest.dedup();
        assert_eq!(rest.len(), 5, "random picks are distinct");
        assert!(rest.iter().all(|b| ![50, 151, 180].contains(b)));
        assert_eq!(d, focal_depths(depth.view(), 200, 3, 5, 7).unwrap());
        assert!(focal_depths(depth.view(), 10, 8, 5, 0).is_err());
        // A caller's counts that overflow when added are an error, not a wrap-around.
        assert!(focal_depths(depth.view(), 10, usize::MAX, 2, 0).is_err());
        assert!(focal_depths(depth.view(), 0, 0, 0, 0).is_err());
    }

    #[test]
    fn identical_holograms_score_perfectly_and_noise_lowers_the_scores() {
        let gt = Array3::from_shape_fn((3, 24, 24), |(c, y, x)| {
            Complex32::from_polar(0.3 + 0.02 * ((x + y + c) % 9) as f32, 0.1 * (x * y) as f32)
        });
        let depths = [0.1, 0.5, 0.9];
        let s = table2(
            gt.view(),
            gt.view(),
            &OpticalSetup::default(),
            Default::default(),
            &depths,
        )
        .unwrap();
        assert!(s.psnr_amp.is_infinite() || s.psnr_amp > 100.0);
        assert!((s.ssim_amp - 1.0).abs() < 1e-6 && (s.ssim_fs - 1.0).abs() < 1e-6);
        let noisy = gt.mapv(|v| v * 1.1);
        let n = table2(
            noisy.view(),
            gt.view(),
            &OpticalSetup::default(),
            Default::default(),
            &depths,
        )
        .unwrap();
        // 10 % amplitude error on amplitudes ≈ 0.3–0.46 → RMS ≈ 0.04 → ≈ 28 dB, identical on every plane
        // (propagation is linear).
        assert!((n.psnr_amp - n.psnr_fs).abs() < 0.5, "{n:?}");
        assert!(n.psnr_amp > 20.0 && n.psnr_amp < 35.0, "{n:?}");
        assert!(table2(
            gt.view(),
            gt.view(),
            &OpticalSetup::default(),
            Default::default(),
            &[]
        )
        .is_err());
    }
}

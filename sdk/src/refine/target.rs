//! What the refinement aims at: the amplitude focal stack of a target hologram at the loss planes
//! ([`FocalTarget`]), and the rule that places those planes and the held-out planes that score it
//! ([`loss_depths`], [`held_out_depths`]).

use ndarray::{Array3, ArrayView3};
use num_complex::Complex32;

use crate::error::{invalid, HoloError, Result};
use crate::optics::{focal_stack, OpticalSetup, PropagationOptions};

/// The fewest and most loss planes a refinement accepts: one plane is a 2D hologram; 64 planes of a 1080p
/// frame already hold 1.6 GB of target.
pub const PLANES_RANGE: (usize, usize) = (1, 64);

/// The normalised depths `d ∈ [0, 1]` (0 = near) of `planes` loss planes: evenly spaced over the whole
/// volume, both ends included, `d_k = k/(planes − 1)` (one plane: the midpoint plane, `d = 0.5`). The
/// rule of `docs/REFINE.md`: the loss sees the volume's ends and its middle, and every point of a scene lies
/// at most half a spacing from a loss plane.
///
/// Errors: [`HoloError::InvalidParameter`] (`planes`) outside [`PLANES_RANGE`].
pub fn loss_depths(planes: usize) -> Result<Vec<f64>> {
    check_planes(planes)?;
    if planes == 1 {
        return Ok(vec![0.5]);
    }
    Ok((0..planes)
        .map(|k| k as f64 / (planes - 1) as f64)
        .collect())
}

/// The normalised depths halfway between consecutive [`loss_depths`]`(planes)`: `planes − 1` planes the
/// loss never sees, where a refinement is scored (the protocol: 7 loss planes, 6 held-out planes).
/// For one loss plane, the volume's two ends.
///
/// Errors: as [`loss_depths`].
pub fn held_out_depths(planes: usize) -> Result<Vec<f64>> {
    check_planes(planes)?;
    if planes == 1 {
        return Ok(vec![0.0, 1.0]);
    }
    Ok((0..planes - 1)
        .map(|k| (k as f64 + 0.5) / (planes - 1) as f64)
        .collect())
}

fn check_planes(planes: usize) -> Result<()> {
    let (lo, hi) = PLANES_RANGE;
    if !(lo..=hi).contains(&planes) {
        return Err(invalid(
            "planes",
            format!("{planes} focal planes; the refinement takes {lo} to {hi}"),
        ));
    }
    Ok(())
}

/// A target focal stack: for each normalised depth `d` of `FocalTarget::depths`, the amplitude `[3, H, W]`
/// (R, G, B) the viewer should see when focused at `z(d) = (0.5 − d)·volume` (`docs/CONVENTIONS.md` §4).
/// Its scale is free: the loss fits one least-squares scale per colour (`docs/REFINE.md`).
#[derive(Debug, Clone, PartialEq)]
pub struct FocalTarget {
    depths: Vec<f64>,
    stack: Vec<Array3<f32>>,
}

impl FocalTarget {
    /// The focal stack of a target midpoint hologram `midpoint` `[3, H, W]` (complex, R, G, B, at the
    /// midpoint plane): `|ASM(H, z(d))|` at each of `depths` ([`focal_stack`], no aperture: the ideal
    /// hologram's image). The SM-LBM ground truth (paper Eq. 1–4) gives the default target; the CNN's own
    /// midpoint hologram a cheap one.
    ///
    /// Errors: those of [`focal_stack`] (shape, non-finite values, depths outside `[0, 1]`); an empty
    /// `depths`.
    pub fn from_midpoint(
        midpoint: ArrayView3<Complex32>,
        setup: &OpticalSetup,
        options: PropagationOptions,
        depths: &[f64],
    ) -> Result<Self> {
        if depths.is_empty() {
            return Err(invalid("depths", "need at least one focal plane"));
        }
        let stack = focal_stack(midpoint, setup, 0.0, depths, options, false)?;
        Self::from_stack(depths.to_vec(), stack)
    }

    /// A focal stack given plane by plane: `stack[k]` `[3, H, W]` (R, G, B amplitudes, ≥ 0) at normalised
    /// depth `depths[k]`.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`depths`) for an empty list, a count other than the stack's or
    /// a depth outside `[0, 1]`; [`HoloError::ShapeMismatch`] for planes of different shapes or not of three
    /// colours; [`HoloError::InvalidData`] for a negative or non-finite amplitude.
    pub fn from_stack(depths: Vec<f64>, stack: Vec<Array3<f32>>) -> Result<Self> {
        if depths.is_empty() || depths.len() != stack.len() {
            return Err(invalid(
                "depths",
                format!(
                    "{} depths for {} target planes: give one depth per plane, at least one",
                    depths.len(),
                    stack.len()
                ),
            ));
        }
        if let Some(d) = depths.iter().find(|d| !(0.0..=1.0).contains(*d)) {
            return Err(invalid(
                "depths",
                format!("normalised depths lie in [0, 1], got {d}"),
            ));
        }
        let dim = stack[0].dim();
        for (k, plane) in stack.iter().enumerate() {
            if plane.dim() != dim || dim.0 != 3 || dim.1 == 0 || dim.2 == 0 {
                return Err(HoloError::ShapeMismatch {
                    what: format!(
                        "target focal plane {k} (every plane [3, height, width], R, G, B)"
                    ),
                    expected: vec![3, dim.1.max(1), dim.2.max(1)],
                    got: plane.shape().to_vec(),
                });
            }
            if let Some(v) = plane.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
                return Err(HoloError::InvalidData(format!(
                    "target focal plane {k} holds the amplitude {v}: amplitudes are finite and ≥ 0"
                )));
            }
        }
        let stack = stack
            .into_iter()
            .map(|a| a.as_standard_layout().into_owned())
            .collect();
        Ok(Self { depths, stack })
    }

    /// The planes' normalised depths (0 = near).
    pub(crate) fn depths(&self) -> &[f64] {
        &self.depths
    }

    /// The amplitude of each plane, `[3, H, W]`, in the order of `FocalTarget::depths`.
    pub fn stack(&self) -> &[Array3<f32>] {
        &self.stack
    }

    /// The frame size `(H, W)`.
    pub(crate) fn size(&self) -> (usize, usize) {
        let (_, h, w) = self.stack[0].dim();
        (h, w)
    }

    /// Plane `k`'s colour `c` as one row-major `[H, W]` slice.
    pub(super) fn plane(&self, k: usize, c: usize) -> &[f32] {
        let (h, w) = self.size();
        let all = self.stack[k]
            .as_slice()
            .expect("planes are kept in standard layout");
        &all[c * h * w..(c + 1) * h * w]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loss_planes_span_the_volume_and_held_out_planes_lie_between_them() {
        assert_eq!(
            loss_depths(7).unwrap(),
            vec![0.0, 1.0 / 6.0, 2.0 / 6.0, 0.5, 4.0 / 6.0, 5.0 / 6.0, 1.0]
        );
        let held = held_out_depths(7).unwrap();
        assert_eq!(held.len(), 6);
        assert!((held[0] - 1.0 / 12.0).abs() < 1e-12 && (held[5] - 11.0 / 12.0).abs() < 1e-12);
        assert_eq!(loss_depths(1).unwrap(), vec![0.5]);
        assert_eq!(held_out_depths(1).unwrap(), vec![0.0, 1.0]);
        for bad in [0, 65] {
            let e = loss_depths(bad).unwrap_err().to_string();
            assert!(e.contains("planes") && e.contains("1 to 64"), "{e}");
        }
    }

    #[test]
    fn a_given_stack_is_checked_plane_by_plane() {
        let ok = || Array3::<f32>::from_elem((3, 4, 5), 0.5);
        assert!(FocalTarget::from_stack(vec![0.1, 0.9], vec![ok(), ok()]).is_ok());
        let e = FocalTarget::from_stack(vec![0.1], vec![ok(), ok()]).unwrap_err();
        assert!(
            e.to_string().contains("1 depths for 2 target planes"),
            "{e}"
        );
        let e = FocalTarget::from_stack(vec![0.1, 0.9], vec![ok(), Array3::zeros((3, 4, 6))])
            .unwrap_err();
        assert!(e.to_string().contains("target focal plane 1"), "{e}");
        let mut bad = ok();
        bad[[1, 2, 3]] = f32::NAN;
        let e = FocalTarget::from_stack(vec![0.5], vec![bad]).unwrap_err();
        assert!(e.to_string().contains("NaN"), "{e}");
        let e = FocalTarget::from_stack(vec![1.5], vec![ok()]).unwrap_err();
        assert!(e.to_string().contains("[0, 1]"), "{e}");
    }
}

//! Laser intensity calibration (paper Methods, "Compensating hardware imperfection"): the SLM is replaced by a
//! diffuser and the camera captures the beam; after a 5×5 median filter (dust on the optics makes pepper
//! noise) the map, normalised to its peak, scales the target amplitudes so that the display's brightness is
//! uniform where the beam allows it.
//!
//! The stored map is the amplitude scale `S(y, x) = min(1, √(floor / M(y, x)))` applied to the target
//! amplitude, where `M` is the filtered beam intensity relative to its peak and `floor` the relative intensity
//! the display is flattened to (by default the 5th percentile of `M`): displayed intensity `∝ M·(S·A)² =
//! floor·A²` wherever `M ≥ floor`; dimmer regions keep `S = 1` (a phase-only SLM cannot add light). The
//! optional smooth fit of the paper (a Gaussian mixture) is not needed for a map stored per pixel.

use ndarray::{Array2, ArrayView2};

use crate::error::{invalid, HoloError, Result};

/// The 5×5 median filter of `[height, width]` (borders use the part of the window inside the image).
pub(crate) fn median5(img: ArrayView2<f32>) -> Array2<f32> {
    let (h, w) = img.dim();
    let mut window = Vec::with_capacity(25);
    Array2::from_shape_fn((h, w), |(y, x)| {
        window.clear();
        for yy in y.saturating_sub(2)..(y + 3).min(h) {
            for xx in x.saturating_sub(2)..(x + 3).min(w) {
                window.push(img[[yy, xx]]);
            }
        }
        let mid = window.len() / 2;
        let (_, m, _) = window.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
        *m
    })
}

/// How the intensity map flattens the display.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub enum IntensityFloor {
    /// This percentile (0–100) of the normalised beam intensity.
    Percentile(f32),
    /// This relative intensity (0–1].
    Relative(f32),
}

impl Default for IntensityFloor {
    fn default() -> Self {
        Self::Percentile(5.0)
    }
}

/// The amplitude scale map `[height, width]` in `(0, 1]` from a diffuser capture already downsampled to the
/// SLM's resolution (module docs). Returns the map and the floor used (relative intensity).
///
/// Errors: [`HoloError::InvalidData`] for a capture with NaN/∞ or no light (peak ≤ 1e-4 of full scale), or
/// one whose median-filtered peak is at full scale over more than 1 % of the panel (saturated: the peak is
/// unknown); [`HoloError::InvalidParameter`] for a floor outside its range.
pub fn intensity_scale_map(
    capture: ArrayView2<f32>,
    floor: IntensityFloor,
) -> Result<(Array2<f32>, f32)> {
    if capture.iter().any(|v| !v.is_finite()) {
        return Err(HoloError::InvalidData(
            "the diffuser capture holds NaN or infinite values".into(),
        ));
    }
    let m = median5(capture);
    let peak = m.iter().cloned().fold(0f32, f32::max);
    if peak <= 1e-4 {
        return Err(HoloError::InvalidData(format!(
            "the diffuser capture is dark (peak {:.4} % of full scale): check the laser and the exposure",
            100.0 * peak
        )));
    }
    let at_full = m.iter().filter(|&&v| v >= 0.999).count();
    if at_full as f64 > 0.01 * m.len() as f64 {
        return Err(HoloError::InvalidData(format!(
            "the diffuser capture is saturated over {:.1} % of the panel: lower the exposure so that the beam's \
             peak is below full scale",
            100.0 * at_full as f64 / m.len() as f64
        )));
    }
    let rel = m.mapv(|v| (v / peak).max(0.0));
    let floor = match floor {
        IntensityFloor::Relative(f) if f > 0.0 && f <= 1.0 => f,
        IntensityFloor::Percentile(p) if (0.0..=100.0).contains(&p) => {
            let mut v: Vec<f32> = rel.iter().copied().collect();
            let i = ((p / 100.0) * (v.len() - 1) as f32).round() as usize;
            let (_, f, _) = v.select_nth_unstable_by(i, |a, b| a.total_cmp(b));
            f.max(1e-3)
        }
        other => {
            return Err(invalid(
                "floor",
                format!("{other:?}: percentile in [0, 100] or relative in (0, 1]"),
            ))
        }
    };
    Ok((
        rel.mapv(|v| if v <= floor { 1.0 } else { (floor / v).sqrt() }),
        floor,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_removes_specks_and_the_map_flattens_the_beam() {
        let (h, w) = (40, 60);
        let beam = Array2::from_shape_fn((h, w), |(y, x)| {
            let (dy, dx) = (y as f32 / h as f32 - 0.5, x as f32 / w as f32 - 0.5);
            0.8 * (-(dy * dy + dx * dx) * 3.0).exp()
        });
        let mut dusty = beam.clone();
        for (y, x) in [(10, 10), (30, 45)] {
            for yy in y..y + 2 {
                for xx in x..x + 2 {
                    dusty[[yy, xx]] = 0.0;
                }
            }
        }
        let m = median5(dusty.view());
        assert!(
            (m[[10, 10]] - beam[[10, 10]]).abs() < 0.02,
            "speck survived the median"
        );
        let (scale, floor) =
            intensity_scale_map(dusty.view(), IntensityFloor::Relative(0.6)).unwrap();
        assert_eq!(floor, 0.6);
        // Displayed intensity ∝ beam·scale² is flat (= floor·peak) wherever the beam is above the floor.
        let peak = 0.8;
        let mut flat = 0;
        for ((y, x), s) in scale.indexed_iter() {
            let b = beam[[y, x]];
            if b / peak > 0.62 && (y as i32 - 10).abs() > 4 && (y as i32 - 30).abs() > 4 {
                assert!(
                    (b * s * s / peak - 0.6).abs() < 0.03,
                    "({y},{x}): {}",
                    b * s * s / peak
                );
                flat += 1;
            }
            assert!(*s > 0.0 && *s <= 1.0);
        }
        assert!(flat > 500);
        assert!(
            intensity_scale_map(Array2::zeros((8, 8)).view(), IntensityFloor::default()).is_err()
        );
        assert!(
            intensity_scale_map(Array2::ones((8, 8)).view(), IntensityFloor::default())
                .unwrap_err()
                .to_string()
                .contains("saturated")
        );
    }
}

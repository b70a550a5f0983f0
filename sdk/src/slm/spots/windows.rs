//! Spot captures read, checked and cut to the fitted window (paper Eq. 14–19 calibration): the same
//! `n × n` window of every capture of one distance, around the spot of their sum.

use std::path::{Path, PathBuf};

use super::{SpotPlan, COLOURS};
use crate::error::{HoloError, Result};
use crate::slm::captures::{png_size, read_png_downsampled};

/// Below this peak-to-valley (fraction of full scale) a capture is "all black".
const MIN_CONTRAST: f32 = 0.02;
/// Above this fraction of saturated pixels a capture (or its window) is refused.
const MAX_SATURATED: f64 = 0.5;

/// One capture's `n × n` window: intensities in units of full scale and which pixels are usable.
#[derive(Debug, Clone)]
pub struct CaptureWindow {
    /// `[n, n]` row-major intensities (0–1).
    pub values: Vec<f64>,
    /// `[n, n]`: `false` where the camera saturated.
    pub valid: Vec<bool>,
}

/// Reads the captures of colour `c` at distance index `i` from `dir`, finds the spot in their sum (the peak of
/// a box-blurred copy), and cuts the same `n × n` window from each. Returns the windows and the window's
/// top-left corner `(x, y)` in the captures.
///
/// Errors ([`HoloError::InvalidData`] naming the file): a missing capture, captures of different sizes or
/// smaller than the window, an all-black capture, one with more than half of its pixels saturated; read
/// errors as [`read_png_downsampled`].
pub fn load_windows(
    plan: &SpotPlan,
    dir: &Path,
    c: usize,
    i: usize,
) -> Result<(Vec<CaptureWindow>, (usize, usize))> {
    let n = plan.window_px;
    let mut frames = Vec::new();
    let mut size = None;
    let mut first = PathBuf::new();
    for k in 0..plan.diversities.len() {
        let path = dir.join(SpotPlan::capture_name(c, i, k));
        if !path.is_file() {
            return Err(HoloError::InvalidData(format!(
                "missing capture `{}` ({} laser, distance {:+.3} mm, diversity {k})",
                path.display(),
                COLOURS[c],
                plan.distances_m[i] * 1e3
            )));
        }
        let (h, w) = png_size(&path)?;
        match size {
            None => {
                if h < n || w < n {
                    return Err(HoloError::InvalidData(format!(
                        "capture `{}` is {w}×{h} pixels, smaller than the plan's {n}×{n} window (window_px)",
                        path.display()
                    )));
                }
                size = Some((h, w));
                first = path.clone();
            }
            Some(s) if s != (h, w) => {
                return Err(HoloError::InvalidData(format!(
                    "capture `{}` is {w}×{h} pixels but `{}` is {}×{}: the captures of one distance must \
                     share the camera's frame",
                    path.display(),
                    first.display(),
                    s.1,
                    s.0
                )))
            }
            Some(_) => {}
        }
        let mut values = vec![0f32; h * w];
        let mut clipped = vec![false; h * w];
        read_png_downsampled(&path, (h, w), None, &mut values, &mut clipped)?;
        let saturated = clipped.iter().filter(|&&c| c).count() as f64 / clipped.len() as f64;
        if saturated > MAX_SATURATED {
            return Err(HoloError::InvalidData(format!(
                "capture `{}` is saturated ({:.0} % of its pixels at full scale): shorten the exposure",
                path.display(),
                saturated * 100.0
            )));
        }
        let (lo, hi) = values
            .iter()
            .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        if hi - lo < MIN_CONTRAST {
            return Err(HoloError::InvalidData(format!(
                "capture `{}` is all black (values {lo:.4}–{hi:.4} of full scale): no spot; check the laser \
                 and the exposure",
                path.display()
            )));
        }
        frames.push((path, values, clipped));
    }
    let (h, w) = size.ok_or_else(|| HoloError::InvalidData("the plan has no diversity".into()))?;
    // The spot: the peak of the summed captures, blurred by a box of ~2 SLM pixels.
    let mut sum = vec![0f64; h * w];
    for (_, v, _) in &frames {
        for (s, &x) in sum.iter_mut().zip(v) {
            *s += x as f64;
        }
    }
    let r = (plan.camera_scale.round() as usize).clamp(1, n / 4);
    let blurred = box_blur(&sum, h, w, r);
    let peak = blurred
        .iter()
        .enumerate()
        .fold((0, f64::MIN), |b, (j, &v)| if v > b.1 { (j, v) } else { b })
        .0;
    let x0 = (peak % w).saturating_sub(n / 2).min(w - n);
    let y0 = (peak / w).saturating_sub(n / 2).min(h - n);
    let mut windows = Vec::new();
    for (path, v, clip) in &frames {
        let mut values = Vec::with_capacity(n * n);
        let mut valid = Vec::with_capacity(n * n);
        for y in y0..y0 + n {
            for x in x0..x0 + n {
                values.push(v[y * w + x] as f64);
                valid.push(!clip[y * w + x]);
            }
        }
        let usable = valid.iter().filter(|&&b| b).count() as f64 / (n * n) as f64;
        if usable < 1.0 - MAX_SATURATED {
            return Err(HoloError::InvalidData(format!(
                "capture `{}`: {:.0} % of the spot's window is saturated: shorten the exposure",
                path.display(),
                (1.0 - usable) * 100.0
            )));
        }
        windows.push(CaptureWindow { values, valid });
    }
    Ok((windows, (x0, y0)))
}

/// A box blur of radius `r` (edges clamped), separable.
fn box_blur(img: &[f64], h: usize, w: usize, r: usize) -> Vec<f64> {
    let pass = |src: &[f64], len: usize, stride: usize, lines: usize, line_stride: usize| {
        let mut out = vec![0f64; src.len()];
        for l in 0..lines {
            for j in 0..len {
                let (a, b) = (j.saturating_sub(r), (j + r).min(len - 1));
                out[l * line_stride + j * stride] =
                    (a..=b).map(|t| src[l * line_stride + t * stride]).sum();
            }
        }
        out
    };
    let rows = pass(img, w, 1, h, w);
    pass(&rows, h, w, w, 1)
}

/// The spot's offset from the window's centre: the centroid of the summed windows above their median.
pub(crate) fn initial_offset(windows: &[CaptureWindow], n: usize) -> (f64, f64) {
    let mut sum = vec![0f64; n * n];
    for w in windows {
        for (s, v) in sum.iter_mut().zip(&w.values) {
            *s += v;
        }
    }
    let mut sorted = sum.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    let (mut t, mut sx, mut sy) = (0.0, 0.0, 0.0);
    for (j, v) in sum.iter().enumerate() {
        let v = (v - median).max(0.0);
        t += v;
        sx += v * (j % n) as f64;
        sy += v * (j / n) as f64;
    }
    if t <= 0.0 {
        return (0.0, 0.0);
    }
    let half = n as f64 / 2.0;
    (sx / t - half, sy / t - half)
}

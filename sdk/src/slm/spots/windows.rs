//! Spot captures read, checked and cut to the fitted window (paper Eq. 14–19 calibration): the same
//! `n × n` window of every capture of one distance, around the spot of their sum.

use std::path::{Path, PathBuf};

use super::{SpotPlan, COLOURS};
use crate::error::{HoloError, Result};
use crate::slm::captures::{check_capture_file, for_each_row, png_size};

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

/// The most cells of the grid on which a distance's captures are summed to find the spot: captures of up to
/// this many pixels are summed pixel by pixel; larger ones in square blocks of `b × b` pixels, `b` the
/// smallest that fits (a 36 MP capture in blocks of 6, 400 MP in blocks of 20). 8 bytes a cell: with the blur's
/// two copies, 24 MiB per distance fitted at once, whatever the camera's resolution.
pub const SPOT_GRID_CELLS: usize = 1 << 20;

/// The block side `b` for a `h × w` capture ([`SPOT_GRID_CELLS`]).
fn block_for(h: usize, w: usize) -> usize {
    (1..)
        .find(|&b| h.div_ceil(b) * w.div_ceil(b) <= SPOT_GRID_CELLS)
        .unwrap_or(1)
}

/// Reads the captures of colour `c` at distance index `i` from `dir`, finds the spot in their sum (the peak of
/// a box-blurred copy), and cuts the same `n × n` window from each. Returns the windows and the window's
/// top-left corner `(x, y)` in the captures.
///
/// Memory does not grow with the camera's resolution: each capture is decoded row by row twice, once into the
/// sum (on a grid of at most [`SPOT_GRID_CELLS`] cells: blocks of `b × b` pixels above it, the spot then
/// placed within `b/2` pixels, which the fit's offset absorbs) and for its saturation and contrast, once
/// to cut its window. Captures of up to [`SPOT_GRID_CELLS`] pixels give the windows a whole-frame sum would.
///
/// Errors ([`HoloError::InvalidData`] naming the file): a missing capture, one that is a folder or a device,
/// captures of different sizes or smaller than the window, an all-black capture, one with more than half of
/// its pixels saturated; read errors as [`crate::slm::captures::read_png_downsampled`].
pub(crate) fn load_windows(
    plan: &SpotPlan,
    dir: &Path,
    c: usize,
    i: usize,
) -> Result<(Vec<CaptureWindow>, (usize, usize))> {
    let n = plan.window_px;
    let mut paths = Vec::new();
    let mut size = None;
    for k in 0..plan.diversities.len() {
        let path = dir.join(SpotPlan::capture_name(c, i, k));
        check_capture_file(
            &path,
            &format!(
                "capture ({} laser, distance {:+.3} mm, diversity {k})",
                COLOURS[c],
                plan.distances_m[i] * 1e3
            ),
        )?;
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
            }
            Some(s) if s != (h, w) => {
                return Err(HoloError::InvalidData(format!(
                    "capture `{}` is {w}×{h} pixels but `{}` is {}×{}: the captures of one distance must \
                     share the camera's frame",
                    path.display(),
                    paths
                        .first()
                        .map_or(String::new(), |p: &PathBuf| p.display().to_string()),
                    s.1,
                    s.0
                )))
            }
            Some(_) => {}
        }
        paths.push(path);
    }
    let (h, w) = size.ok_or_else(|| HoloError::InvalidData("the plan has no diversity".into()))?;
    // Pass 1: the sum on the grid, each capture's saturation and contrast.
    let b = block_for(h, w);
    let (hc, wc) = (h.div_ceil(b), w.div_ceil(b));
    let mut sum = vec![0f64; hc * wc];
    for path in &paths {
        let (mut saturated, mut lo, mut hi) = (0usize, f32::MAX, f32::MIN);
        for_each_row(path, 0..w, |y, values, full| {
            saturated += full.iter().filter(|&&f| f).count();
            let line = &mut sum[(y / b) * wc..(y / b + 1) * wc];
            for (x, &v) in values.iter().enumerate() {
                lo = lo.min(v);
                hi = hi.max(v);
                line[x / b] += v as f64;
            }
            Ok(())
        })?;
        let saturated = saturated as f64 / (h * w) as f64;
        if saturated > MAX_SATURATED {
            return Err(HoloError::InvalidData(format!(
                "capture `{}` is saturated ({:.0} % of its pixels at full scale): shorten the exposure",
                path.display(),
                saturated * 100.0
            )));
        }
        if hi - lo < MIN_CONTRAST {
            return Err(HoloError::InvalidData(format!(
                "capture `{}` is all black (values {lo:.4}–{hi:.4} of full scale): no spot; check the laser \
                 and the exposure",
                path.display()
            )));
        }
    }
    // The spot: the peak of the summed captures, blurred by a box of ~2 SLM pixels (at least one cell).
    let r = (plan.camera_scale.round() as usize).clamp(1, n / 4);
    let blurred = box_blur(&sum, hc, wc, r.div_ceil(b));
    drop(sum);
    let peak = blurred
        .iter()
        .enumerate()
        .fold((0, f64::MIN), |b, (j, &v)| if v > b.1 { (j, v) } else { b })
        .0;
    // The peak cell's centre in camera pixels.
    let (cx, cy) = (
        ((peak % wc) * b + b / 2).min(w - 1),
        ((peak / wc) * b + b / 2).min(h - 1),
    );
    let x0 = cx.saturating_sub(n / 2).min(w - n);
    let y0 = cy.saturating_sub(n / 2).min(h - n);
    // Pass 2: each capture's window.
    let mut windows = Vec::new();
    for path in &paths {
        let mut values = Vec::with_capacity(n * n);
        let mut valid = Vec::with_capacity(n * n);
        for_each_row(path, x0..x0 + n, |y, v, full| {
            if (y0..y0 + n).contains(&y) {
                values.extend(v.iter().map(|&x| x as f64));
                valid.extend(full.iter().map(|&f| !f));
            }
            Ok(())
        })?;
        if values.len() != n * n {
            return Err(HoloError::InvalidData(format!(
                "capture `{}` changed while it was read (its window has {} of {} pixels)",
                path.display(),
                values.len(),
                n * n
            )));
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

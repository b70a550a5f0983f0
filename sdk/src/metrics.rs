//! Image quality metrics: PSNR and SSIM.
//!
//! Both follow scikit-image (`skimage.metrics`, checked against version 0.26 by the fixture
//! `sdk/tests/fixtures/metrics_fixture.json`, produced by `make_metrics_fixture.py` beside it):
//!
//! - [`psnr`] = `peak_signal_noise_ratio(reference, test, data_range=…)`;
//! - [`ssim`] = `structural_similarity(reference, test, data_range=…, gaussian_weights=True,
//!   sigma=1.5, use_sample_covariance=False)`, the parameters of Wang et al. 2004;
//! - [`ssim_multichannel`] = the same with `channel_axis=0` on a `[C, H, W]` stack.
//!
//! All statistics are accumulated in `f64`; the inputs are `f32` as everywhere in the SDK.

use ndarray::{ArrayView, ArrayView2, ArrayView3, Axis, Dimension};
use rayon::prelude::*;

use crate::error::{invalid, HoloError, Result};

/// Radius of the SSIM Gaussian window: scipy's `int(truncate·σ + 0.5)` with `truncate = 3.5`,
/// `σ = 1.5` (skimage's choice, giving the 11-tap window of Wang et al. 2004).
const SSIM_RADIUS: usize = 5;
/// Side of the SSIM window, `2·SSIM_RADIUS + 1 = 11` pixels.
const SSIM_WIN: usize = 2 * SSIM_RADIUS + 1;
/// Smallest image side SSIM accepts (its Gaussian window, 11 pixels).
pub const SSIM_WINDOW: usize = SSIM_WIN;
/// Standard deviation of the SSIM Gaussian window, in pixels.
const SSIM_SIGMA: f64 = 1.5;
/// SSIM stabilising constant factor for the means: `C1 = (K1·data_range)²`.
const SSIM_K1: f64 = 0.01;
/// SSIM stabilising constant factor for the (co)variances: `C2 = (K2·data_range)²`.
const SSIM_K2: f64 = 0.03;

/// Peak signal-to-noise ratio, in dB, of `test` against `reference`:
/// `10·log10(data_range² / MSE)` with the mean squared error taken over every element.
///
/// The two arrays may have any dimension and shape as long as the shapes are equal (e.g. `[H, W]`
/// or a `[C, H, W]` colour stack, which gives the PSNR over all channels together, as
/// scikit-image's `peak_signal_noise_ratio` does). `data_range` is the peak-to-peak range of the
/// signal (`1.0` for amplitudes or intensities in `[0, 1]`). The MSE is accumulated in `f64`.
///
/// Returns `f32::INFINITY` when the arrays are identical (MSE = 0).
///
/// # Errors
/// - [`HoloError::ShapeMismatch`] if the shapes differ;
/// - [`HoloError::InvalidData`] if the arrays are empty or hold a NaN or infinite value;
/// - [`HoloError::InvalidParameter`] (`data_range`) if `data_range` is not finite and `> 0`.
pub fn psnr<D: Dimension>(
    reference: ArrayView<f32, D>,
    test: ArrayView<f32, D>,
    data_range: f32,
) -> Result<f32> {
    check_data_range(data_range)?;
    check_same_shape("PSNR test vs reference", reference.shape(), test.shape())?;
    if reference.is_empty() {
        return Err(HoloError::InvalidData(
            "PSNR of empty arrays is undefined".into(),
        ));
    }
    check_finite("PSNR reference", &reference)?;
    check_finite("PSNR test", &test)?;

    let mut sum = 0.0f64;
    ndarray::Zip::from(&reference)
        .and(&test)
        .for_each(|&r, &t| {
            let d = f64::from(r) - f64::from(t);
            sum += d * d;
        });
    let mse = sum / reference.len() as f64;
    if mse == 0.0 {
        return Ok(f32::INFINITY);
    }
    let range = f64::from(data_range);
    Ok((10.0 * (range * range / mse).log10()) as f32)
}

/// Mean structural similarity (SSIM, Wang et al., *IEEE Trans. Image Process.* 13(4), 2004) of two
/// single-channel images of shape `[H, W]`.
///
/// Uses an 11×11 Gaussian window with σ = 1.5 pixels, `K1 = 0.01`, `K2 = 0.03`, population
/// (co)variances, and matches exactly scikit-image's
/// `structural_similarity(reference, test, data_range=data_range, gaussian_weights=True, sigma=1.5,
/// use_sample_covariance=False)`: local statistics from `scipy.ndimage.gaussian_filter`
/// (`truncate = 3.5`, i.e. radius 5), SSIM map cropped by 5 pixels on each side, then averaged.
/// Because of that crop, every pixel that is averaged has its whole window inside the image, so
/// the filter's border mode (`reflect` in skimage) never matters and the statistics are computed
/// as a separable "valid" convolution, in `f64`.
///
/// `data_range` is the peak-to-peak range of the signal (`1.0` for images in `[0, 1]`).
/// The result is 1 for identical images and lies in `[-1, 1]`.
///
/// # Errors
/// - [`HoloError::ShapeMismatch`] if the shapes differ, or if either side is smaller than the
///   11-pixel window;
/// - [`HoloError::InvalidData`] if a value is NaN or infinite;
/// - [`HoloError::InvalidParameter`] (`data_range`) if `data_range` is not finite and `> 0`.
pub fn ssim(reference: ArrayView2<f32>, test: ArrayView2<f32>, data_range: f32) -> Result<f32> {
    check_data_range(data_range)?;
    check_same_shape("SSIM test vs reference", reference.shape(), test.shape())?;
    check_ssim_size(reference.shape())?;
    check_finite("SSIM reference", &reference)?;
    check_finite("SSIM test", &test)?;
    Ok(ssim_plane(reference, test, f64::from(data_range)) as f32)
}

/// Mean SSIM of two colour stacks of shape `[C, H, W]`: the average over channels of [`ssim`] of
/// each `[H, W]` plane, as scikit-image's `structural_similarity(…, channel_axis=0)` with the
/// parameters of [`ssim`]. Channels are processed in parallel (rayon).
///
/// # Errors
/// As [`ssim`]; in addition [`HoloError::InvalidData`] if there are no channels (`C = 0`).
pub fn ssim_multichannel(
    reference: ArrayView3<f32>,
    test: ArrayView3<f32>,
    data_range: f32,
) -> Result<f32> {
    check_data_range(data_range)?;
    check_same_shape("SSIM test vs reference", reference.shape(), test.shape())?;
    let channels = reference.len_of(Axis(0));
    if channels == 0 {
        return Err(HoloError::InvalidData(
            "SSIM of a stack with no channel is undefined".into(),
        ));
    }
    check_ssim_size(&reference.shape()[1..])?;
    check_finite("SSIM reference", &reference)?;
    check_finite("SSIM test", &test)?;
    let range = f64::from(data_range);
    let total: f64 = (0..channels)
        .into_par_iter()
        .map(|c| {
            ssim_plane(
                reference.index_axis(Axis(0), c),
                test.index_axis(Axis(0), c),
                range,
            )
        })
        .collect::<Vec<f64>>()
        .iter()
        .sum();
    Ok((total / channels as f64) as f32)
}

/// `data_range` must be finite and strictly positive.
fn check_data_range(data_range: f32) -> Result<()> {
    if data_range.is_finite() && data_range > 0.0 {
        Ok(())
    } else {
        Err(invalid(
            "data_range",
            format!("must be finite and > 0 (peak-to-peak signal range), got {data_range}"),
        ))
    }
}

fn check_same_shape(what: &str, expected: &[usize], got: &[usize]) -> Result<()> {
    if expected == got {
        Ok(())
    } else {
        Err(HoloError::ShapeMismatch {
            what: what.to_string(),
            expected: expected.to_vec(),
            got: got.to_vec(),
        })
    }
}

/// Both image axes (`[H, W]`, the last two of `shape`) must hold the 11-pixel window.
fn check_ssim_size(hw: &[usize]) -> Result<()> {
    if hw.iter().all(|&n| n >= SSIM_WIN) {
        Ok(())
    } else {
        Err(HoloError::ShapeMismatch {
            what: format!("SSIM image (each side must be at least the {SSIM_WIN}-pixel window)"),
            expected: vec![SSIM_WIN; hw.len()],
            got: hw.to_vec(),
        })
    }
}

fn check_finite<D: Dimension>(what: &str, a: &ArrayView<f32, D>) -> Result<()> {
    match a.indexed_iter().find(|(_, v)| !v.is_finite()) {
        None => Ok(()),
        Some((idx, v)) => Err(HoloError::InvalidData(format!(
            "{what} holds a non-finite value {v} at index {idx:?}"
        ))),
    }
}

/// Normalised 1-D Gaussian taps, as scipy's `_gaussian_kernel1d(σ, 0, radius)`.
fn gaussian_taps() -> [f64; SSIM_WIN] {
    let mut w = [0.0f64; SSIM_WIN];
    let r = SSIM_RADIUS as f64;
    for (k, wk) in w.iter_mut().enumerate() {
        let x = k as f64 - r;
        *wk = (-0.5 / (SSIM_SIGMA * SSIM_SIGMA) * x * x).exp();
    }
    let sum: f64 = w.iter().sum();
    w.iter_mut().for_each(|v| *v /= sum);
    w
}

/// Output row `i` of the Gaussian filter of `map(x, y)` (vertical pass over input rows `i .. i + 11` into
/// `vert`, then [`horizontal`] into `out`). Generic over the map, so that each product gets its own loop.
fn filtered_row<F: Fn(f64, f64) -> f64>(
    x: ArrayView2<f32>,
    y: ArrayView2<f32>,
    i: usize,
    w: &[f64; SSIM_WIN],
    vert: &mut [f64],
    out: &mut [f64],
    map: F,
) {
    vert.fill(0.0);
    for (k, &wk) in w.iter().enumerate() {
        let (xr, yr) = (x.row(i + k), y.row(i + k));
        for (v, (&a, &b)) in vert.iter_mut().zip(xr.iter().zip(yr.iter())) {
            *v += wk * map(f64::from(a), f64::from(b));
        }
    }
    horizontal(out, vert, w);
}

/// One row of the horizontal pass: `out[j] = Σ_k w[k]·vert[j + k]`.
fn horizontal(out: &mut [f64], vert: &[f64], w: &[f64; SSIM_WIN]) {
    for (j, o) in out.iter_mut().enumerate() {
        *o = w
            .iter()
            .zip(&vert[j..j + SSIM_WIN])
            .map(|(wk, v)| wk * v)
            .sum();
    }
}

/// Mean SSIM of one validated plane pair, in `f64`, one output row at a time: the five Gaussian-filtered
/// maps (means of x, y, x², y², xy) are never held whole, so a 1080p plane takes a few rows of memory
/// rather than ~150 MB.
fn ssim_plane(x: ArrayView2<f32>, y: ArrayView2<f32>, data_range: f64) -> f64 {
    let w = gaussian_taps();
    let (h, wd) = x.dim();
    let (oh, ow) = (h - 2 * SSIM_RADIUS, wd - 2 * SSIM_RADIUS);
    let c1 = (SSIM_K1 * data_range).powi(2);
    let c2 = (SSIM_K2 * data_range).powi(2);
    let mut vert = vec![0.0f64; wd];
    // The five filtered rows: μx, μy, E[x²], E[y²], E[xy].
    let mut rows = [(); 5].map(|_| vec![0.0f64; ow]);
    let mut sum = 0.0f64;
    for i in 0..oh {
        let [r0, r1, r2, r3, r4] = &mut rows;
        filtered_row(x, y, i, &w, &mut vert, r0, |a, _| a);
        filtered_row(x, y, i, &w, &mut vert, r1, |_, b| b);
        filtered_row(x, y, i, &w, &mut vert, r2, |a, _| a * a);
        filtered_row(x, y, i, &w, &mut vert, r3, |_, b| b * b);
        filtered_row(x, y, i, &w, &mut vert, r4, |a, b| a * b);
        let [ux, uy, uxx, uyy, uxy] = &rows;
        for j in 0..ow {
            let (mx, my, mxx, myy, mxy) = (ux[j], uy[j], uxx[j], uyy[j], uxy[j]);
            let vx = mxx - mx * mx;
            let vy = myy - my * my;
            let vxy = mxy - mx * my;
            let a1 = 2.0 * mx * my + c1;
            let a2 = 2.0 * vxy + c2;
            let b1 = mx * mx + my * my + c1;
            let b2 = vx + vy + c2;
            sum += (a1 * a2) / (b1 * b2);
        }
    }
    sum / (oh * ow) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    /// Separable "valid" Gaussian filter: output `[H − 10, W − 10]`, element `(i, j)` is the window
    /// centred on input pixel `(i + 5, j + 5)`. Vertical pass first (scipy filters axis 0 first): the
    /// passes `ssim_plane` runs row by row, on a whole array.
    fn gaussian_valid(input: &Array2<f64>, w: &[f64; SSIM_WIN]) -> Array2<f64> {
        let (h, wd) = input.dim();
        let (oh, ow) = (h - 2 * SSIM_RADIUS, wd - 2 * SSIM_RADIUS);
        let mut out = Array2::<f64>::zeros((oh, ow));
        let mut vert = vec![0.0f64; wd];
        for (i, mut out_row) in out.outer_iter_mut().enumerate() {
            vert.fill(0.0);
            for (k, &wk) in w.iter().enumerate() {
                for (v, &x) in vert.iter_mut().zip(input.row(i + k)) {
                    *v += wk * x;
                }
            }
            horizontal(out_row.as_slice_mut().unwrap(), &vert, w);
        }
        out
    }

    #[test]
    fn gaussian_taps_are_normalised_and_symmetric() {
        let w = gaussian_taps();
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        for k in 0..SSIM_WIN {
            assert_eq!(w[k], w[SSIM_WIN - 1 - k]);
        }
        // Peak of the normalised σ = 1.5 kernel truncated at radius 5.
        assert!((w[SSIM_RADIUS] - 0.266_011).abs() < 1e-5);
    }

    #[test]
    fn gaussian_valid_preserves_constants() {
        let a = Array2::from_elem((13, 17), 0.25f64);
        let f = gaussian_valid(&a, &gaussian_taps());
        assert_eq!(f.dim(), (3, 7));
        assert!(f.iter().all(|v| (v - 0.25).abs() < 1e-15));
    }
}

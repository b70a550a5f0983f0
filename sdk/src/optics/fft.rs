//! Planned 2D FFT on row-major `[height, width]` complex buffers (rustfft), with the spectrum kept in
//! **transposed** layout `[width, height]` so that a spectral operation costs two transposes instead of four.

use std::sync::Arc;

use num_complex::Complex32;
use rustfft::{Fft, FftPlanner};

/// A 2D discrete Fourier transform of one size, planned once and applied many times.
///
/// - [`Fft2::forward`] transforms a row-major `[height, width]` buffer and writes its unnormalised spectrum to
///   a row-major `[width, height]` buffer (the transpose of the usual layout: element `[kx, ky]`).
/// - [`Fft2::inverse`] takes such a transposed spectrum back to a `[height, width]` buffer, **unnormalised**
///   (the caller folds the `1/(height·width)` factor into its spectral multiplier).
///
/// The caller owns the scratch space ([`Fft2::scratch_len`] complex values), so the hot path allocates nothing.
#[derive(Clone)]
pub struct Fft2 {
    height: usize,
    width: usize,
    row_forward: Arc<dyn Fft<f32>>,
    row_inverse: Arc<dyn Fft<f32>>,
    col_forward: Arc<dyn Fft<f32>>,
    col_inverse: Arc<dyn Fft<f32>>,
    scratch_len: usize,
}

impl std::fmt::Debug for Fft2 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Fft2")
            .field("height", &self.height)
            .field("width", &self.width)
            .finish()
    }
}

impl Fft2 {
    /// Plans the four 1D transforms of a `[height, width]` 2D FFT. Both sizes must be ≥ 1 (checked by callers).
    pub fn new(planner: &mut FftPlanner<f32>, height: usize, width: usize) -> Self {
        let row_forward = planner.plan_fft_forward(width);
        let row_inverse = planner.plan_fft_inverse(width);
        let col_forward = planner.plan_fft_forward(height);
        let col_inverse = planner.plan_fft_inverse(height);
        let scratch_len = [
            row_forward.get_inplace_scratch_len(),
            row_inverse.get_inplace_scratch_len(),
            col_forward.get_inplace_scratch_len(),
            col_inverse.get_inplace_scratch_len(),
        ]
        .into_iter()
        .max()
        .unwrap_or(0);
        Self {
            height,
            width,
            row_forward,
            row_inverse,
            col_forward,
            col_inverse,
            scratch_len,
        }
    }

    /// Rows of the spatial buffer.
    pub fn height(&self) -> usize {
        self.height
    }

    /// Columns of the spatial buffer.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Number of complex values of scratch that [`Fft2::forward`] and [`Fft2::inverse`] need.
    pub fn scratch_len(&self) -> usize {
        self.scratch_len
    }

    /// Forward DFT: `data` `[height, width]` (overwritten with intermediate row transforms) → `spectrum`
    /// `[width, height]` (transposed). Both slices must hold `height·width` values.
    pub fn forward(
        &self,
        data: &mut [Complex32],
        spectrum: &mut [Complex32],
        scratch: &mut [Complex32],
    ) {
        debug_assert_eq!(data.len(), self.height * self.width);
        debug_assert_eq!(spectrum.len(), self.height * self.width);
        let scratch = &mut scratch[..self.scratch_len];
        self.row_forward.process_with_scratch(data, scratch);
        transpose::transpose(data, spectrum, self.width, self.height);
        self.col_forward.process_with_scratch(spectrum, scratch);
    }

    /// Inverse DFT (unnormalised): transposed `spectrum` `[width, height]` (overwritten) → `data`
    /// `[height, width]`.
    pub fn inverse(
        &self,
        spectrum: &mut [Complex32],
        data: &mut [Complex32],
        scratch: &mut [Complex32],
    ) {
        debug_assert_eq!(data.len(), self.height * self.width);
        debug_assert_eq!(spectrum.len(), self.height * self.width);
        let scratch = &mut scratch[..self.scratch_len];
        self.col_inverse.process_with_scratch(spectrum, scratch);
        transpose::transpose(spectrum, data, self.height, self.width);
        self.row_inverse.process_with_scratch(data, scratch);
    }
}

/// Signed DFT frequency index of bin `k` of an `n`-point transform: `0, 1, …, ⌈n/2⌉−1, −⌊n/2⌋, …, −1`
/// (the order of `numpy.fft.fftfreq(n) · n`).
pub fn signed_index(k: usize, n: usize) -> i64 {
    if k < n.div_ceil(2) {
        k as i64
    } else {
        k as i64 - n as i64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn naive_dft2(data: &[Complex32], h: usize, w: usize) -> Vec<Complex32> {
        let mut out = vec![Complex32::new(0.0, 0.0); h * w];
        for ky in 0..h {
            for kx in 0..w {
                let mut acc = num_complex::Complex64::new(0.0, 0.0);
                for y in 0..h {
                    for x in 0..w {
                        let ang = -2.0
                            * std::f64::consts::PI
                            * ((ky * y) as f64 / h as f64 + (kx * x) as f64 / w as f64);
                        let v = data[y * w + x];
                        acc += num_complex::Complex64::new(v.re as f64, v.im as f64)
                            * num_complex::Complex64::from_polar(1.0, ang);
                    }
                }
                out[ky * w + kx] = Complex32::new(acc.re as f32, acc.im as f32);
            }
        }
        out
    }

    #[test]
    fn forward_matches_naive_dft_in_transposed_layout_and_inverse_undoes_it() {
        let (h, w) = (6, 10);
        let data: Vec<Complex32> = (0..h * w)
            .map(|i| Complex32::new((i as f32 * 0.37).sin(), (i as f32 * 0.11).cos() - 0.3))
            .collect();
        let mut planner = FftPlanner::new();
        let fft = Fft2::new(&mut planner, h, w);
        let mut scratch = vec![Complex32::default(); fft.scratch_len()];
        let mut work = data.clone();
        let mut spectrum = vec![Complex32::default(); h * w];
        fft.forward(&mut work, &mut spectrum, &mut scratch);
        let reference = naive_dft2(&data, h, w);
        for ky in 0..h {
            for kx in 0..w {
                let d = spectrum[kx * h + ky] - reference[ky * w + kx];
                assert!(d.norm() < 1e-4, "bin ({ky},{kx}) differs by {}", d.norm());
            }
        }
        let mut back = vec![Complex32::default(); h * w];
        fft.inverse(&mut spectrum, &mut back, &mut scratch);
        for (b, d) in back.iter().zip(&data) {
            assert!((b / (h * w) as f32 - d).norm() < 1e-5);
        }
    }

    #[test]
    fn signed_index_follows_fftfreq_order() {
        let even: Vec<i64> = (0..4).map(|k| signed_index(k, 4)).collect();
        assert_eq!(even, vec![0, 1, -2, -1]);
        let odd: Vec<i64> = (0..5).map(|k| signed_index(k, 5)).collect();
        assert_eq!(odd, vec![0, 1, 2, -2, -1]);
    }
}

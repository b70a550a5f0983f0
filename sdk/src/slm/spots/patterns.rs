//! The spot test patterns (paper Eq. 14–19 calibration): for each colour, distance and diversity, the SLM
//! codes that focus `circ(ρ ≤ 1)·exp(i·D_k)` at the distance (module docs of [`super`]).

use std::path::Path;

use ndarray::{Array2, Array3, Axis};
use num_complex::{Complex32, Complex64};
use rustfft::FftPlanner;

use super::SpotPlan;
use crate::encoding::{double_phase_encode, phase_to_codes, DoublePhaseMethod};
use crate::error::{invalid, HoloError, Result};
use crate::optics::fft::signed_index;
use crate::optics::zernike::amplitude_transfer_function;
use crate::optics::{Carrier, PropagationOptions, Propagator};

impl SpotPlan {
    /// The SLM codes `[height, width]` of colour `c`, distance index `i`, diversity `k` (module docs): the
    /// spot focused at `distances_m[i]` on the SLM's centre, its pupil phase `D_k`.
    ///
    /// Errors: [`HoloError::InvalidParameter`] for an index out of the plan, or as the propagator and the
    /// double phase encoding.
    pub(crate) fn pattern_codes(&self, c: usize, i: usize, k: usize) -> Result<Array2<u8>> {
        let [h, w] = self.slm_size;
        let (Some(&d), Some(div), Some(&lambda)) = (
            self.distances_m.get(i),
            self.diversities.get(k),
            self.wavelengths_m.get(c),
        ) else {
            return Err(invalid(
                "pattern",
                format!("no pattern ({c}, {i}, {k}) in the plan"),
            ));
        };
        let atf = amplitude_transfer_function(h, w, div)?;
        let mut spectrum: Vec<Complex64> = atf
            .indexed_iter()
            .map(|((ky, kx), v)| {
                // Centre the spot on the SLM: a shift by (w/2, h/2) pixels.
                let (fx, fy) = (signed_index(kx, w) as f64, signed_index(ky, h) as f64);
                let p = -std::f64::consts::TAU
                    * (fx * (w / 2) as f64 / w as f64 + fy * (h / 2) as f64 / h as f64);
                Complex64::new(v.re as f64, v.im as f64) * Complex64::from_polar(1.0, p)
            })
            .collect();
        fft2(&mut spectrum, h, w, true);
        let mut field: Vec<Complex32> = spectrum
            .iter()
            .map(|v| Complex32::new(v.re as f32, v.im as f32))
            .collect();
        let options = PropagationOptions {
            pad: false,
            band_limit: false,
        };
        Propagator::new(h, w, self.pixel_pitch_m, lambda, options)?.propagate_by(
            &mut field,
            -d,
            Carrier::Remove,
        )?;
        let mut stack = Array3::<Complex32>::zeros((3, h, w));
        for (o, v) in stack.index_axis_mut(Axis(0), c).iter_mut().zip(&field) {
            *o = *v;
        }
        let encoded = double_phase_encode(stack.view(), &DoublePhaseMethod::Plain)?;
        Ok(phase_to_codes(encoded.phase.index_axis(Axis(0), c)))
    }

    /// Writes every pattern of the plan and `plan.json` into `dir` (created), calling `progress(done,
    /// total)` after each. Returns the number of patterns. On an error nothing of the run stays: the patterns
    /// written are removed, and `dir` too where this call created it.
    ///
    /// Errors: as `SpotPlan::pattern_codes`; [`HoloError::Io`] / [`HoloError::Image`] naming the file.
    pub fn write_patterns(&self, dir: &Path, progress: &dyn Fn(usize, usize)) -> Result<usize> {
        let colours = self.colour_indices()?;
        let created = !dir.exists();
        std::fs::create_dir_all(dir).map_err(|source| HoloError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        let total = colours.len() * self.distances_m.len() * self.diversities.len();
        let mut written = Vec::with_capacity(total);
        let mut write = || -> Result<()> {
            for &c in &colours {
                for i in 0..self.distances_m.len() {
                    for k in 0..self.diversities.len() {
                        let codes = self.pattern_codes(c, i, k)?;
                        let path = dir.join(Self::pattern_name(c, i, k));
                        crate::io::save_u8_png(&path, codes.view())?;
                        written.push(path);
                        progress(written.len(), total);
                    }
                }
            }
            self.save(dir)
        };
        if let Err(e) = write() {
            for path in &written {
                let _ = crate::io::remove_output(path);
            }
            if created {
                let _ = std::fs::remove_dir(dir);
            }
            return Err(e);
        }
        Ok(total)
    }
}

/// In-place unnormalised 2D FFT of a row-major `[h, w]` buffer (`inverse`: `e^{+i…}`, else `e^{−i…}`).
pub(crate) fn fft2(buf: &mut [Complex64], h: usize, w: usize, inverse: bool) {
    let mut planner = FftPlanner::new();
    let (row, col) = if inverse {
        (planner.plan_fft_inverse(w), planner.plan_fft_inverse(h))
    } else {
        (planner.plan_fft_forward(w), planner.plan_fft_forward(h))
    };
    row.process(buf);
    let mut column = vec![Complex64::default(); h];
    for x in 0..w {
        for (y, v) in column.iter_mut().enumerate() {
            *v = buf[y * w + x];
        }
        col.process(&mut column);
        for (y, v) in column.iter().enumerate() {
            buf[y * w + x] = *v;
        }
    }
}

//! One colour channel's optics on its worker thread ([`ColourState`]): heads → field, the offset propagation
//! (Eq. 6, carrier removed), the pre-filter's planes, the two passes of the double phase encoding (Eq. 7) and
//! the look-up table. Allocation-free after the first frame.

use std::sync::Arc;

use ndarray::{Array3, ArrayView3, Axis};
use num_complex::Complex32;

use super::models::calibrated_lut;
use crate::encoding::{ChannelEncoder, ChannelStats};
use crate::error::Result;
use crate::model::contract::head_to_phasor;
use crate::optics::{EvenMultiplier, Scratch, SpectralPlan};
use crate::slm::DisplayCalibration;

/// What a colour worker does next (see [`ColourState::run`]).
#[derive(Debug, Clone, Copy)]
pub(super) enum Task {
    /// Heads → field, offset propagation, then the pre-filter input or pass 1 of the encoding.
    Midpoint { prefilter: bool },
    /// Pre-filter output `(Re, Im)` → field, then pass 1 of the encoding.
    Filtered,
    /// Pass 2 of the encoding and the LUT.
    Encode {
        mean_phase: f32,
        amplitude_scale: f32,
    },
}

/// The offset transfer function as stored: its even quarter (a function of the frequency radius: a quarter
/// of the memory, [`EvenMultiplier`]) or, should it not be even, in full.
#[derive(Debug)]
pub(super) enum Transfer {
    Even(EvenMultiplier),
    Full(Vec<Complex32>),
}

impl Transfer {
    /// The compact form of `full` (in `plan`'s spectrum layout) where it is even, else `full` itself.
    /// Errors: as [`EvenMultiplier::from_full`].
    pub(super) fn new(plan: &SpectralPlan, full: &[Complex32]) -> Result<Self> {
        Ok(match EvenMultiplier::from_full(plan, full)? {
            Some(even) => Self::Even(even),
            None => Self::Full(full.to_vec()),
        })
    }
}

/// Everything one colour channel reuses between frames.
#[derive(Debug)]
pub(super) struct ColourState {
    /// Two real planes of this colour (`[H, W]`), written by the session: the midpoint heads (amplitude,
    /// phase) before [`Task::Midpoint`]; with a pre-filter, `(Re H, Im H)` of the offset hologram after it
    /// (the pre-filter's input) and the pre-filter's output `(Re H', Im H')` before [`Task::Filtered`].
    pub(super) planes: [Vec<f32>; 2],
    pub(super) field: Vec<Complex32>,
    pub(super) plan: SpectralPlan,
    /// Offset transfer function with the carrier removed (Eq. 6); `None` at 0 m.
    pub(super) transfer: Option<Transfer>,
    pub(super) scratch: Scratch,
    pub(super) encoder: ChannelEncoder,
    pub(super) phase: Vec<f32>,
    pub(super) codes: Vec<u8>,
    pub(super) stats: ChannelStats,
    /// This colour (0 = R) and the session's `(height, width)`.
    pub(super) colour: usize,
    pub(super) size: (usize, usize),
    /// The display calibration whose look-up table turns `phase` into `codes` (`None`: linear).
    pub(super) calibration: Option<Arc<DisplayCalibration>>,
}

impl ColourState {
    pub(super) fn run(&mut self, task: Task) -> Result<()> {
        match task {
            Task::Midpoint { prefilter } => {
                self.heads_to_field();
                match &self.transfer {
                    Some(Transfer::Even(t)) => {
                        self.plan
                            .apply_even(&mut self.field, t, &mut self.scratch)?
                    }
                    Some(Transfer::Full(t)) => {
                        self.plan.apply(&mut self.field, t, &mut self.scratch)?
                    }
                    None => {}
                }
                if prefilter {
                    // Pre-filter input (docs/CONVENTIONS.md §7.2, format 2): Re H and Im H, into the two
                    // planes.
                    let [re, im] = &mut self.planes;
                    for ((r, i), v) in re.iter_mut().zip(im.iter_mut()).zip(&self.field) {
                        *r = v.re;
                        *i = v.im;
                    }
                } else {
                    self.stats = self.encoder.analyse(&mut self.field, &mut self.phase)?;
                }
                Ok(())
            }
            Task::Filtered => {
                let [re, im] = &self.planes;
                for ((f, &r), &i) in self.field.iter_mut().zip(re).zip(im) {
                    *f = Complex32::new(r, i);
                }
                self.stats = self.encoder.analyse(&mut self.field, &mut self.phase)?;
                Ok(())
            }
            Task::Encode {
                mean_phase,
                amplitude_scale,
            } => {
                self.encoder.encode(
                    &self.field,
                    &mut self.phase,
                    &mut self.codes,
                    mean_phase,
                    amplitude_scale,
                )?;
                if let Some(lut) = calibrated_lut(self.calibration.as_ref(), self.colour) {
                    let (h, w) = self.size;
                    lut.apply(h, w, &self.phase, &mut self.codes)?;
                }
                Ok(())
            }
        }
    }

    fn heads_to_field(&mut self) {
        let [amp, phs] = &self.planes;
        for ((f, &a), &p) in self.field.iter_mut().zip(amp).zip(phs) {
            *f = head_to_phasor(a, p);
        }
    }
}

/// Copies channel `c` of a `[C, H, W]` array into `out` (`H·W` values).
pub(super) fn copy_channel(a: ArrayView3<f32>, c: usize, out: &mut [f32]) {
    let lane = a.index_axis(Axis(0), c);
    match lane.as_slice() {
        Some(src) => out.copy_from_slice(src),
        None => out.iter_mut().zip(lane.iter()).for_each(|(o, v)| *o = *v),
    }
}

/// Writes `src` (`H·W` values) into channel `c` of a standard-layout `[C, H, W]` array.
pub(super) fn fill_channel<T: Copy>(a: &mut Array3<T>, c: usize, src: &[T]) {
    let mut lane = a.index_axis_mut(Axis(0), c);
    match lane.as_slice_mut() {
        Some(dst) => dst.copy_from_slice(src),
        None => lane.iter_mut().zip(src).for_each(|(o, v)| *o = *v),
    }
}

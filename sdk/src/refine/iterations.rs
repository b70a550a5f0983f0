//! A refinement's iterations on any device, the CPU's `Refiner` or a GPU upload, behind one trait
//! ([`Iterations`]), and what does not depend on the device, written here once ([`drive`]): the start
//! pattern's check, the loss record of each iteration, the cancellation and the wrap of the result to
//! `[0, 2π)`.

use std::f32::consts::TAU;
use std::ops::ControlFlow;
use std::time::Instant;

use ndarray::{ArrayView3, ArrayViewMut3};

use super::options::{IterationRecord, RefineReport};
use crate::error::{HoloError, Result};
use crate::optics::check_colour_stack;

/// A refinement's iterations on one device, from a start pattern to the refined one (unwrapped).
pub(crate) trait Iterations {
    /// The pattern's size `(H, W)`.
    fn size(&self) -> (usize, usize);

    /// Each colour's target energy `Σ_d ‖T_d‖²`, the number of values the loss sums over (`3·D·H·W`) and
    /// the iteration count: what a record needs.
    fn records(&self) -> ([f64; 3], usize, usize);

    /// Runs the iterations on `phase` (flat `[3, H, W]`, radians, left unwrapped), calling `sums(iteration,
    /// each colour's (A, B))` with the start's sums (iteration 0) and after every step; returns early, `Ok`,
    /// where `sums` breaks (the pattern is then partly refined: the caller drops it).
    ///
    /// Errors: the device's ([`HoloError::Gpu`]); [`HoloError::Internal`] for a lost buffer.
    fn run(
        &mut self,
        phase: &mut [f32],
        sums: &mut dyn FnMut(usize, [(f64, f64); 3]) -> ControlFlow<()>,
    ) -> Result<()>;
}

/// Refines `phase` `[3, H, W]` (radians) in place on `iterations`' device: checks the start, runs, records
/// each iteration's loss and PSNR (`progress` hears of each; `ControlFlow::Break(())` cancels, leaving
/// `phase` as it was), and wraps the result to `[0, 2π)`.
///
/// Errors: [`HoloError::ShapeMismatch`] for a pattern of another size; [`HoloError::InvalidData`] for a
/// non-finite phase; [`HoloError::Cancelled`] naming the iteration where `progress` stopped it; the
/// device's.
pub(crate) fn drive(
    iterations: &mut dyn Iterations,
    mut phase: ArrayViewMut3<f32>,
    progress: &mut dyn FnMut(&IterationRecord) -> ControlFlow<()>,
) -> Result<RefineReport> {
    check_start(iterations.size(), phase.view())?;
    let t = Instant::now();
    let (energy, count, total) = iterations.records();
    let mut work = phase.as_standard_layout().into_owned();
    let flat = work
        .as_slice_mut()
        .ok_or_else(|| HoloError::Internal("refinement phase not contiguous".into()))?;
    let mut history = Vec::with_capacity(total + 1);
    let mut stopped = None;
    iterations.run(flat, &mut |it, sums| {
        let record = loss_record(it, sums, &energy, count);
        history.push(record);
        let flow = progress(&record);
        if flow.is_break() {
            stopped = Some(it);
        }
        flow
    })?;
    if let Some(it) = stopped {
        return Err(HoloError::Cancelled(format!(
            "refinement stopped by its caller after {it} of {total} iterations; the pattern is unchanged"
        )));
    }
    phase.zip_mut_with(&work, |o, &p| {
        let w = p.rem_euclid(TAU);
        *o = if w >= TAU { 0.0 } else { w };
    });
    Ok(RefineReport {
        history,
        iterations_s: t.elapsed().as_secs_f64(),
    })
}

/// Checks a start pattern: `[3, H, W]` at the refinement's `size`, finite.
///
/// Errors: [`HoloError::ShapeMismatch`], [`HoloError::InvalidData`].
pub(crate) fn check_start(size: (usize, usize), phase: ArrayView3<f32>) -> Result<()> {
    let (h, w) = check_colour_stack("refinement start pattern", &phase)?;
    if (h, w) != size {
        return Err(HoloError::ShapeMismatch {
            what: "refinement start pattern vs its target".into(),
            expected: vec![3, size.0, size.1],
            got: vec![3, h, w],
        });
    }
    if let Some(v) = phase.iter().find(|v| !v.is_finite()) {
        return Err(HoloError::InvalidData(format!(
            "the refinement's start pattern holds {v}: phases are finite radians"
        )));
    }
    Ok(())
}

/// The record of an iteration from each colour's sums `(A, B)` (`L = Σ_c (E_c − A²/B)`, `E_c` the target's
/// energy) over `count` values.
pub(crate) fn loss_record(
    iteration: usize,
    sums: [(f64, f64); 3],
    energy: &[f64; 3],
    count: usize,
) -> IterationRecord {
    let loss: f64 = sums
        .iter()
        .zip(energy)
        .map(|(&(a, b), &e)| if b > 0.0 { (e - a * a / b).max(0.0) } else { e })
        .sum();
    let mse = loss / count as f64;
    IterationRecord {
        iteration,
        loss,
        psnr_db: if mse > 0.0 {
            -10.0 * mse.log10()
        } else {
            f64::INFINITY
        },
    }
}

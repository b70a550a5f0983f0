//! [`CnnPlan`]: one CNN at one resolution on the CPU, whatever engine computes it (the session's CNN stage
//! holds a `Box<dyn CnnPlan>` and never asks which), and the timing of one plan ([`time_plan`]).

use std::time::Instant;

use ndarray::{Array3, ArrayView3};

use super::tuning::fastest_run;
use crate::error::{HoloError, Result};

/// One CNN at one resolution, ready to run on the CPU (after tract's `Runtime → Runnable → State`: the plan
/// owns what a run reuses; [`CnnPlan::spawn`] gives another thread its own).
pub(crate) trait CnnPlan: std::fmt::Debug + Send {
    /// `(channels, height, width)` of the input `[C, H, W]` this plan takes.
    fn input_dim(&self) -> (usize, usize, usize);

    /// Runs the CNN on `input` `[C, H, W]` (f32, the contract's packing, `docs/CONVENTIONS.md` §7): its two
    /// outputs, `[3, H, W]` each (amplitude and phase heads of a hologram CNN; `Re` and `Im` of a
    /// pre-filter's filtered field).
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for an input of another shape; the engine's run errors
    /// ([`HoloError::ModelRun`]).
    fn run_outputs(&mut self, input: ArrayView3<f32>) -> Result<(Array3<f32>, Array3<f32>)>;

    /// [`run_outputs`](Self::run_outputs) on an input held plane by plane (`planes[c]`: channel `c`, `H·W`
    /// values, row-major), so that a caller whose channels live apart (the pre-filter's input, one colour per
    /// worker) need not gather them into a `[C, H, W]` array first. The native plans read the planes in
    /// place; the default gathers them (one allocation per call, as tract allocates anyway).
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for a plane count other than `C` or a plane of other than
    /// `H·W` values; as `run_outputs`.
    fn run_planes(&mut self, planes: &[&[f32]]) -> Result<(Array3<f32>, Array3<f32>)> {
        let dim = self.input_dim();
        check_planes(planes, dim)?;
        let (c, h, w) = dim;
        let mut input = Array3::<f32>::zeros((c, h, w));
        for (mut lane, p) in input.outer_iter_mut().zip(planes) {
            for (o, v) in lane.iter_mut().zip(p.iter()) {
                *o = *v;
            }
        }
        self.run_outputs(input.view())
    }

    /// [`run_planes`](Self::run_planes) writing the two outputs into the caller's six planes (`H·W` values
    /// each): `outputs[0..3]` the first output's channels (amplitude heads, or `Re`), `outputs[3..6]` the
    /// second's (phase heads, or `Im`), so that a session's CNN writes straight into its colour workers'
    /// planes (at 1080p, no 50 MB of output arrays per frame). The native plans write in place; the default
    /// copies `run_planes`' arrays.
    ///
    /// Errors: as `run_planes`; [`HoloError::ShapeMismatch`] for an output plane of other than `H·W`
    /// values.
    fn run_planes_into(&mut self, planes: &[&[f32]], outputs: [&mut [f32]; 6]) -> Result<()> {
        let (_, h, w) = self.input_dim();
        check_output_planes(&outputs, h * w)?;
        let (first, second) = self.run_planes(planes)?;
        let channels = first.outer_iter().chain(second.outer_iter());
        for (o, c) in outputs.into_iter().zip(channels) {
            for (d, v) in o.iter_mut().zip(c.iter()) {
                *d = *v;
            }
        }
        Ok(())
    }

    /// The same network for another thread (a stream's CNN thread): weights shared, run state its own.
    fn spawn(&self) -> Box<dyn CnnPlan>;
}

/// Checks an input given plane by plane against `(C, H, W)`. Errors: [`HoloError::ShapeMismatch`].
pub(crate) fn check_planes(planes: &[&[f32]], (c, h, w): (usize, usize, usize)) -> Result<()> {
    if planes.len() != c || planes.iter().any(|p| p.len() != h * w) {
        return Err(HoloError::ShapeMismatch {
            what: "CNN input planes (count, values per plane)".into(),
            expected: vec![c, h * w],
            got: vec![
                planes.len(),
                planes.iter().map(|p| p.len()).max().unwrap_or(0),
            ],
        });
    }
    Ok(())
}

/// Checks six output planes hold `hw` values each ([`CnnPlan::run_planes_into`]). Errors:
/// [`HoloError::ShapeMismatch`].
pub(crate) fn check_output_planes(outputs: &[&mut [f32]; 6], hw: usize) -> Result<()> {
    match outputs.iter().find(|p| p.len() != hw) {
        Some(p) => Err(HoloError::ShapeMismatch {
            what: "CNN output plane (values)".into(),
            expected: vec![hw],
            got: vec![p.len()],
        }),
        None => Ok(()),
    }
}

/// Fastest wall-clock seconds of one run of `plan` on a constant `[c, h, w]` input: the timing rule every
/// engine shares ([`fastest_run`]).
pub(crate) fn time_plan(plan: &mut dyn CnnPlan, c: usize, h: usize, w: usize) -> Result<f64> {
    let input = Array3::<f32>::from_elem((c, h, w), 0.5);
    fastest_run(|| {
        let t = Instant::now();
        plan.run_outputs(input.view())?;
        Ok(t.elapsed().as_secs_f64())
    })
}

//! The refinement on a GPU ([`GpuRefinement`], cargo feature `gpu`): the same model, loss, gradient and Adam
//! as [`Refiner::refine`], run by `crate::gpu::refine`'s WGSL kernels, behind the same
//! [`super::iterations::drive`] (start check, records, cancellation, wrap). What differs: the sums are f32 on
//! the GPU (f64 on the CPU), the progress callback hears of the iterations in batches (a cancellation takes
//! effect within `crate::gpu::refine::READ_BACK_EVERY` iterations), and the quantised evaluation knows the
//! linear look-up table only (a calibrated display refines on the CPU). Through a display model
//! (`Refiner::with_display_model`) the GPU runs the model's forward pass and its gradient (`refine.wgsl`'s
//! `model_` kernels: crosstalk and its adjoint, the response global or per pixel, source, zero order; the
//! aberration is in the loss planes' multipliers).

use std::ops::ControlFlow;

use ndarray::ArrayViewMut3;

use super::device::{DeviceIterations, Prepared, RefineDevice};
use super::engine::project_drive;
use super::engine::Refiner;
use super::iterations::{drive, Iterations};
use super::options::{IterationRecord, RefineReport};
use crate::error::{invalid, HoloError, Result};
use crate::gpu::refine::{GpuAdam, GpuDisplayColour, GpuDisplayModel, GpuRefineModel, GpuRefiner};
use crate::gpu::GpuContext;
use crate::slm::model::ColourRuntime;
use crate::slm::LutRepresentation;
use num_complex::Complex32;

/// A [`Refiner`]'s refinement uploaded to a GPU: its loss planes' multipliers, weights and target as they
/// are when [`Refiner::on_gpu`] makes it (a later target: `GpuRefinement::set_target`). Memory on the
/// GPU: per loss plane a complex multiplier and the target, 3 colours each, `W`, and seven complex and three
/// real `[3, H, W]` planes (384², 7 planes: 71 MB; 1080p: 1.0 GB); through a display model two complex and one
/// real plane more and the response's tiles (`crate::gpu::refine`).
pub struct GpuRefinement {
    inner: GpuRefiner,
    /// Through a display model: the phase is the drive (projected before the iterations).
    through_model: bool,
    iterations: usize,
    energy: [f64; 3],
    count: usize,
    size: (usize, usize),
}

impl std::fmt::Debug for GpuRefinement {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuRefinement")
            .field("size", &self.size)
            .field("iterations", &self.iterations)
            .finish_non_exhaustive()
    }
}

impl Refiner {
    /// This refinement on the GPU of `ctx` (see [`GpuRefinement`]).
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`calibration`) for a quantised refinement through a
    /// calibrated look-up table (the GPU knows the linear one); [`HoloError::Gpu`] for memory beyond the
    /// device's limits or a kernel that does not compile.
    pub fn on_gpu(&self, ctx: &GpuContext) -> Result<GpuRefinement> {
        if self.options.quantised
            && self
                .luts
                .iter()
                .any(|l| !matches!(l.representation(), LutRepresentation::Linear))
        {
            return Err(invalid(
                "calibration",
                "the GPU refinement evaluates through the linear look-up table; a calibrated display refines \
                 on the CPU",
            ));
        }
        let (h, w) = self.target.size();
        let display = self.gpu_display_model(h * w);
        let (rows, cols) = (
            self.plan.computational_shape().1,
            self.plan.computational_shape().0,
        );
        let isa = self.plan.fft().isa();
        let planes = self.target.depths().len();
        let multipliers: Vec<[Vec<_>; 3]> = (0..planes)
            .map(|d| std::array::from_fn(|c| self.colours[c].planes[d].full(rows, cols, isa)))
            .collect();
        let target = flat_target(self);
        let model = GpuRefineModel {
            plan: &self.plan,
            multipliers: &multipliers,
            weights: std::array::from_fn(|c| self.colours[c].weight.as_slice()),
            target: &target,
            display: display.as_ref(),
        };
        let o = self.options;
        let inner = GpuRefiner::new(
            ctx,
            &model,
            GpuAdam {
                step: o.step_rad,
                beta1: o.beta1,
                beta2: o.beta2,
                epsilon: o.epsilon,
                quantised: o.quantised,
            },
        )?;
        Ok(GpuRefinement {
            inner,
            through_model: display.is_some(),
            iterations: o.iterations,
            energy: self.target_energy,
            count: 3 * planes * h * w,
            size: (h, w),
        })
    }
}

impl Refiner {
    /// The display model's parts as the GPU's kernels read them (`n` pixels per colour), `None` for the ideal
    /// SLM (`Refiner::with_display_model` gives every colour a runtime, or none).
    fn gpu_display_model(&self, n: usize) -> Option<GpuDisplayModel> {
        let runtimes: Vec<&ColourRuntime> = self
            .display
            .iter()
            .map(Option::as_ref)
            .collect::<Option<_>>()?;
        let mut source = Vec::with_capacity(3 * n);
        let colours = std::array::from_fn(|c| {
            let parts = runtimes[c].plain_parts();
            match parts.source {
                Some(s) => source.extend_from_slice(s),
                None => source.extend(std::iter::repeat_n(Complex32::new(1.0, 0.0), n)),
            }
            GpuDisplayColour {
                curves: parts.curves,
                grid_cols: parts.grid_cols,
                rows: parts.rows,
                columns: parts.columns,
                kernel: parts.kernel,
                zero: parts.zero,
            }
        });
        Some(GpuDisplayModel { source, colours })
    }
}

/// `refiner`'s target amplitudes `[D, 3, H, W]`, flat.
fn flat_target(refiner: &Refiner) -> Vec<f32> {
    let (h, w) = refiner.target.size();
    let planes = refiner.target.depths().len();
    let mut target = Vec::with_capacity(planes * 3 * h * w);
    for d in 0..planes {
        for c in 0..3 {
            target.extend_from_slice(refiner.target.plane(d, c));
        }
    }
    target
}

impl GpuRefinement {
    /// As [`Refiner::refine`], on the GPU: refines `phase` `[3, H, W]` (radians) in place, wrapped to
    /// `[0, 2π)`, with `progress` hearing of the start and every iteration.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for another size; [`HoloError::InvalidData`] for a non-finite
    /// phase; [`HoloError::Cancelled`] when `progress` stopped it (the pattern unchanged); [`HoloError::Gpu`].
    pub fn refine(
        &mut self,
        phase: ArrayViewMut3<f32>,
        progress: &mut dyn FnMut(&IterationRecord) -> ControlFlow<()>,
    ) -> Result<RefineReport> {
        drive(self, phase, progress)
    }
}

impl Iterations for GpuRefinement {
    fn size(&self) -> (usize, usize) {
        self.size
    }

    fn records(&self) -> ([f64; 3], usize, usize) {
        (self.energy, self.count, self.iterations)
    }

    fn run(
        &mut self,
        phase: &mut [f32],
        sums: &mut dyn FnMut(usize, [(f64, f64); 3]) -> ControlFlow<()>,
    ) -> Result<()> {
        if self.through_model {
            project_drive(phase);
        }
        self.inner.refine(phase, self.iterations, sums)
    }
}

impl DeviceIterations for GpuRefinement {
    fn set_target(&mut self, refiner: &Refiner) -> Result<()> {
        self.inner.set_target(&flat_target(refiner))?;
        self.energy = refiner.target_energy;
        Ok(())
    }
}

impl RefineDevice for GpuContext {
    fn name(&self) -> String {
        self.info().name.clone()
    }

    fn prepare(&self, refiner: &Refiner) -> Result<Prepared> {
        match refiner.on_gpu(self) {
            Ok(g) => Ok(Prepared::Ready(Box::new(g))),
            Err(HoloError::InvalidParameter {
                name: "calibration",
                reason,
            }) => Ok(Prepared::Declined(reason)),
            Err(e) => Err(e),
        }
    }
}

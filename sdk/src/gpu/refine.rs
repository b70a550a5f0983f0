//! The focal-stack refinement on the GPU (`refine.wgsl`; the model and its analytic gradient are
//! `crate::refine::model`'s, docs/REFINE.md): the three colours at once, per iteration
//!
//! 1. `u = e^{iφ}` (`phasor`, through the linear look-up table when quantised);
//! 2. per loss plane `d`: `U_d = F⁻¹{m_d·F{u}}` (a spectral operation on a copy of `u`), the partial sums
//!    `(⟨|U_d|, T_d⟩, ‖U_d‖²)` per workgroup and `V_d = T_d·U_d/|U_d|` (`plane`), then the adjoint
//!    `F⁻¹{conj(m_d)·F{V_d}}` added to `acc` (`accumulate`): by linearity in space, where the CPU adds spectra;
//! 3. the sums reduced in a fixed order and `k = A/B` per colour (`reduce`);
//! 4. `F⁻¹{W·F{u}}` (one more spectral operation) and Adam's update (`adam`) with
//!    `g = 2k²·F⁻¹{W·F{u}} − 2k·acc`, `∂L/∂φ = Im(g·conj(u))`.
//!
//! One submission per iteration (Adam's bias corrections change), its sums read back for the iteration's
//! record. This module knows no refinement types: the caller (`crate::refine`) hands it the multipliers, the
//! weights and the target as plain arrays. Memory: per loss plane one multiplier (3 colours, complex) and the
//! target (3 colours), and eight `[3, H, W]` planes besides (at 384², 7 planes: 40 MB; at 1080p: 0.6 GB).

use std::ops::ControlFlow;

use bytemuck::{Pod, Zeroable};
use num_complex::Complex32;

use super::context::GpuContext;
use super::fft::{GpuMultiplier, GpuSpectralOp, GpuSpectralPlan};
use super::kernel::{grid_1d, Kernel};
use super::shaders;
use crate::error::{invalid, HoloError, Result};
use crate::optics::SpectralPlan;

/// `Params` of `refine.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub(crate) struct RefineParams {
    hw: u32,
    channels: u32,
    groups: u32,
    planes: u32,
    quantised: u32,
    step: f32,
    beta1: f32,
    beta2: f32,
    epsilon: f32,
    c1: f32,
    c2: f32,
    _pad: u32,
}

/// `PlaneParams` of `refine.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub(crate) struct PlaneParams {
    plane: u32,
    first: u32,
    _pad: [u32; 2],
}

/// Adam's settings of a GPU refinement (those of `crate::refine::RefineOptions`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct GpuAdam {
    /// Step size, radians.
    pub step: f32,
    /// Decay of the gradient's running mean.
    pub beta1: f32,
    /// Decay of the squared gradient's running mean.
    pub beta2: f32,
    /// Denominator guard.
    pub epsilon: f32,
    /// Evaluate at the phase the linear look-up table shows (straight-through gradient).
    pub quantised: bool,
}

/// What a GPU refinement is made of, as plain arrays (`[H, W]` frames, the spectral plan's layout for
/// multipliers and weights).
pub(crate) struct GpuRefineModel<'a> {
    /// The unpadded spectral plan of the frames.
    pub plan: &'a SpectralPlan,
    /// Per loss plane, per colour: `m_d`, every value (`SpectralPlan::spectrum_len`).
    pub multipliers: &'a [[Vec<Complex32>; 3]],
    /// Per colour: `W = N·Σ_d |m_d|²`.
    pub weights: [&'a [f32]; 3],
    /// The target amplitudes `[D, 3, H, W]`, flat.
    pub target: &'a [f32],
}

/// One iteration's sums per colour, `(⟨|U|, T⟩, ‖U‖²)` over the loss planes (f32 on the GPU).
pub(crate) type ColourSums = [(f64, f64); 3];

/// A refinement's buffers, kernels and bound operations on one GPU (see the module docs).
pub(crate) struct GpuRefiner {
    ctx: GpuContext,
    n: usize,
    planes: usize,
    params: wgpu::Buffer,
    phase: wgpu::Buffer,
    mean: wgpu::Buffer,
    square: wgpu::Buffer,
    unit: wgpu::Buffer,
    work: wgpu::Buffer,
    sums: wgpu::Buffer,
    staging: wgpu::Buffer,
    target: wgpu::Buffer,
    kernels: Kernels,
    groups: [u32; 3],
    /// Per plane: `U_d`, its adjoint, and the plane's `plane` and `accumulate` bind groups.
    forward: Vec<GpuSpectralOp>,
    adjoint: Vec<GpuSpectralOp>,
    plane_binds: Vec<wgpu::BindGroup>,
    accumulate_binds: Vec<wgpu::BindGroup>,
    weight_op: GpuSpectralOp,
    phasor_bind: wgpu::BindGroup,
    reduce_bind: wgpu::BindGroup,
    adam_bind: wgpu::BindGroup,
    // Kept alive for the bind groups.
    _multipliers: Vec<GpuMultiplier>,
    _plan: GpuSpectralPlan,
    adam: GpuAdam,
    base: RefineParams,
}

struct Kernels {
    phasor: Kernel,
    plane: Kernel,
    accumulate: Kernel,
    reduce: Kernel,
    adam: Kernel,
}

impl GpuRefiner {
    /// Uploads `model` and plans the operations.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for arrays of the wrong length; [`HoloError::InvalidParameter`]
    /// for no loss plane or a padded plan; [`HoloError::Gpu`] for buffers beyond the device's limits or a
    /// kernel that does not compile.
    pub(crate) fn new(ctx: &GpuContext, model: &GpuRefineModel<'_>, adam: GpuAdam) -> Result<Self> {
        let plan = model.plan;
        let (h, w) = (plan.height(), plan.width());
        if plan.computational_shape() != (h, w) {
            return Err(invalid(
                "pad",
                "the GPU refinement runs on the unpadded grid",
            ));
        }
        let n = h * w;
        let planes = model.multipliers.len();
        if planes == 0 {
            return Err(invalid("planes", "a refinement needs ≥ 1 loss plane"));
        }
        let len = plan.spectrum_len();
        let lengths_ok = model
            .multipliers
            .iter()
            .all(|m| m.iter().all(|c| c.len() == len))
            && model.weights.iter().all(|c| c.len() == len)
            && model.target.len() == planes * 3 * n;
        if !lengths_ok {
            return Err(HoloError::ShapeMismatch {
                what: "GPU refinement model vs its frames".into(),
                expected: vec![planes, 3, h, w],
                got: vec![model.multipliers.len(), model.target.len()],
            });
        }
        let gpu_plan = GpuSpectralPlan::new(ctx, plan, 3)?;
        let complex_bytes = (3 * n * 8) as u64;
        let real_bytes = (3 * n * 4) as u64;
        let phase = ctx.storage("refine phase", real_bytes)?;
        let mean = ctx.storage("refine Adam mean", real_bytes)?;
        let square = ctx.storage("refine Adam square", real_bytes)?;
        let unit = ctx.storage("refine unit phasors", complex_bytes)?;
        let work = ctx.storage("refine work", complex_bytes)?;
        let acc = ctx.storage("refine adjoint sum", complex_bytes)?;
        let target = ctx.storage_with("refine target", model.target)?;
        let groups_1d = grid_1d(n);
        let groups_per_channel = groups_1d[0] as usize * groups_1d[1] as usize;
        let partial = ctx.storage(
            "refine partial sums",
            (planes * 3 * groups_per_channel * 8) as u64,
        )?;
        let sums = ctx.storage("refine sums", 3 * 16)?;
        let staging = ctx.buffer(
            "refine sums read-back",
            3 * 16,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        )?;
        let base = RefineParams {
            hw: n as u32,
            channels: 3,
            groups: groups_per_channel as u32,
            planes: planes as u32,
            quantised: u32::from(adam.quantised),
            step: adam.step,
            beta1: adam.beta1,
            beta2: adam.beta2,
            epsilon: adam.epsilon,
            c1: 1.0,
            c2: 1.0,
            _pad: 0,
        };
        let params = ctx.uniform("refine params", &base)?;
        let kernels = Kernels {
            phasor: ctx.kernel(&shaders::REFINE, "phasor")?,
            plane: ctx.kernel(&shaders::REFINE, "plane")?,
            accumulate: ctx.kernel(&shaders::REFINE, "accumulate")?,
            reduce: ctx.kernel(&shaders::REFINE, "reduce")?,
            adam: ctx.kernel(&shaders::REFINE, "adam")?,
        };
        let mut multipliers = Vec::with_capacity(planes + 1);
        let mut forward = Vec::with_capacity(planes);
        let mut adjoint = Vec::with_capacity(planes);
        let mut plane_binds = Vec::with_capacity(planes);
        let mut accumulate_binds = Vec::with_capacity(planes);
        for (d, m) in model.multipliers.iter().enumerate() {
            let values: Vec<&[Complex32]> = m.iter().map(Vec::as_slice).collect();
            let multiplier = gpu_plan.multiplier(ctx, &values)?;
            forward.push(gpu_plan.bind(ctx, &work, &multiplier)?);
            adjoint.push(gpu_plan.bind_adjoint(ctx, &work, &multiplier)?);
            multipliers.push(multiplier);
            let plane_params = ctx.uniform(
                "refine plane",
                &PlaneParams {
                    plane: d as u32,
                    first: u32::from(d == 0),
                    _pad: [0; 2],
                },
            )?;
            plane_binds.push(ctx.bind_at(
                &kernels.plane,
                &[
                    (0, &params),
                    (1, &plane_params),
                    (4, &work),
                    (6, &target),
                    (7, &partial),
                ],
            ));
            accumulate_binds.push(ctx.bind_at(
                &kernels.accumulate,
                &[(0, &params), (1, &plane_params), (4, &work), (5, &acc)],
            ));
        }
        let weights: Vec<Vec<Complex32>> = model
            .weights
            .iter()
            .map(|w| w.iter().map(|&v| Complex32::new(v, 0.0)).collect())
            .collect();
        let values: Vec<&[Complex32]> = weights.iter().map(Vec::as_slice).collect();
        let weight = gpu_plan.multiplier(ctx, &values)?;
        let weight_op = gpu_plan.bind(ctx, &work, &weight)?;
        multipliers.push(weight);
        let phasor_bind = ctx.bind_at(&kernels.phasor, &[(0, &params), (2, &phase), (3, &unit)]);
        let reduce_bind = ctx.bind_at(&kernels.reduce, &[(0, &params), (7, &partial), (8, &sums)]);
        let adam_bind = ctx.bind_at(
            &kernels.adam,
            &[
                (0, &params),
                (2, &phase),
                (3, &unit),
                (4, &work),
                (5, &acc),
                (8, &sums),
                (9, &mean),
                (10, &square),
            ],
        );
        ctx.take_error()?;
        Ok(Self {
            ctx: ctx.clone(),
            n,
            planes,
            params,
            phase,
            mean,
            square,
            unit,
            work,
            sums,
            staging,
            target,
            kernels,
            groups: [groups_1d[0], groups_1d[1], 3],
            forward,
            adjoint,
            plane_binds,
            accumulate_binds,
            weight_op,
            phasor_bind,
            reduce_bind,
            adam_bind,
            _multipliers: multipliers,
            _plan: gpu_plan,
            adam,
            base,
        })
    }

    /// Replaces the target amplitudes (`[D, 3, H, W]` flat, as made) in place: the next frame of a video, the
    /// multipliers kept.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for another length.
    pub(crate) fn set_target(&self, target: &[f32]) -> Result<()> {
        if target.len() != self.planes * 3 * self.n {
            return Err(HoloError::ShapeMismatch {
                what: "GPU refinement target".into(),
                expected: vec![self.planes * 3 * self.n],
                got: vec![target.len()],
            });
        }
        self.ctx
            .write(&self.target, 0, bytemuck::cast_slice(target));
        Ok(())
    }

    /// Refines `phase` (`[3, H, W]` flat, radians) in place for `iterations` Adam steps from a fresh
    /// optimiser state, calling `progress(iteration, sums)` with the sums of the start (iteration 0) and of
    /// each step's result; the last evaluation takes no step. `ControlFlow::Break` stops it: `phase` is then
    /// unchanged and the error is [`HoloError::Cancelled`]. `phase` is left unwrapped (the caller wraps it).
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for a phase of another size; [`HoloError::Gpu`]; cancellation.
    pub(crate) fn refine(
        &mut self,
        phase: &mut [f32],
        iterations: usize,
        progress: &mut dyn FnMut(usize, ColourSums) -> ControlFlow<()>,
    ) -> Result<()> {
        if phase.len() != 3 * self.n {
            return Err(HoloError::ShapeMismatch {
                what: "GPU refinement phase".into(),
                expected: vec![3 * self.n],
                got: vec![phase.len()],
            });
        }
        let ctx = &self.ctx;
        ctx.write(&self.phase, 0, bytemuck::cast_slice(phase));
        for it in 0..=iterations {
            let step = it < iterations;
            let t = (it + 1) as i32;
            let params = RefineParams {
                c1: 1.0 - self.adam.beta1.powi(t),
                c2: 1.0 - self.adam.beta2.powi(t),
                ..self.base
            };
            ctx.write(&self.params, 0, bytemuck::bytes_of(&params));
            let mut encoder = ctx.encoder("refine iteration");
            if it == 0 {
                // A fresh optimiser state.
                encoder.clear_buffer(&self.mean, 0, None);
                encoder.clear_buffer(&self.square, 0, None);
            }
            self.record(&mut encoder, step);
            encoder.copy_buffer_to_buffer(&self.sums, 0, &self.staging, 0, 3 * 16);
            ctx.submit_and_wait(encoder)?;
            let mut bytes = [0u8; 48];
            ctx.read_staging(&self.staging, &mut bytes)?;
            let values: &[f32] = bytemuck::cast_slice(&bytes);
            let sums: ColourSums =
                std::array::from_fn(|c| (f64::from(values[4 * c]), f64::from(values[4 * c + 1])));
            if progress(it, sums).is_break() {
                return Err(HoloError::Cancelled(format!(
                    "refinement stopped by its caller after {it} of {iterations} iterations; the pattern \
                     is unchanged"
                )));
            }
        }
        let out: Vec<f32> = ctx.read_buffer(&self.phase, 3 * self.n)?;
        phase.copy_from_slice(&out);
        Ok(())
    }

    /// Records one iteration: the loss's sums of the current phase and, with `step`, the gradient and Adam's
    /// update.
    fn record(&self, encoder: &mut wgpu::CommandEncoder, step: bool) {
        let bytes = (3 * self.n * 8) as u64;
        let elements = grid_1d(3 * self.n);
        let dispatch = |encoder: &mut wgpu::CommandEncoder,
                        kernel: &Kernel,
                        bind: &wgpu::BindGroup,
                        groups: [u32; 3]| {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(kernel.entry()),
                timestamp_writes: None,
            });
            kernel.dispatch(&mut pass, bind, groups);
        };
        dispatch(encoder, &self.kernels.phasor, &self.phasor_bind, elements);
        for d in 0..self.planes {
            encoder.copy_buffer_to_buffer(&self.unit, 0, &self.work, 0, bytes);
            self.forward[d].record(encoder);
            dispatch(
                encoder,
                &self.kernels.plane,
                &self.plane_binds[d],
                self.groups,
            );
            if step {
                self.adjoint[d].record(encoder);
                dispatch(
                    encoder,
                    &self.kernels.accumulate,
                    &self.accumulate_binds[d],
                    elements,
                );
            }
        }
        dispatch(encoder, &self.kernels.reduce, &self.reduce_bind, [3, 1, 1]);
        if step {
            encoder.copy_buffer_to_buffer(&self.unit, 0, &self.work, 0, bytes);
            self.weight_op.record(encoder);
            dispatch(encoder, &self.kernels.adam, &self.adam_bind, elements);
        }
    }
}

#[cfg(test)]
pub(super) fn uniform_layouts() -> Vec<super::shader_tests::UniformLayout> {
    use super::shader_tests::uniform_layout;
    use super::shaders::REFINE;
    vec![
        uniform_layout!(
            &REFINE,
            "Params",
            RefineParams {
                hw,
                channels,
                groups,
                planes,
                quantised,
                step,
                beta1,
                beta2,
                epsilon,
                c1,
                c2
            }
        ),
        uniform_layout!(&REFINE, "PlaneParams", PlaneParams { plane, first }),
    ]
}

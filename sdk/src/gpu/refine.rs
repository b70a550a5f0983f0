//! The focal-stack refinement on the GPU (`refine.wgsl`; the model and its analytic gradient are
//! `crate::refine::model`'s, docs/REFINE.md): the three colours at once, per iteration
//!
//! 1. `u = e^{iφ}` (`phasor`, through the linear look-up table when quantised) and its spectrum `S = F{u}`,
//!    kept;
//! 2. per loss plane `d`: `U_d = F⁻¹{m_d·S}` (one inverse transform), the partial sums
//!    `(⟨|U_d|, T_d⟩, ‖U_d‖²)` per workgroup and `V_d = T_d·U_d/|U_d|` (`plane`), then `conj(m_d)·F{V_d}`
//!    added to the adjoint's spectrum (one forward transform), as the CPU does;
//! 3. the sums reduced in a fixed order and `k = A/B` per colour (`reduce`);
//! 4. `acc = F⁻¹{Σ_d conj(m_d)·F{V_d}}`, `F⁻¹{W·S}` and Adam's update (`adam`) with
//!    `g = 2k²·F⁻¹{W·S} − 2k·acc`, `∂L/∂φ = Im(g·conj(u))`.
//!
//! So an iteration with `D` loss planes takes `2D + 3` 2D FFTs of the three colours (17 for 7 planes; each plane
//! as a whole spectral operation and its adjoint would take `4D + 2`, 30). One submission per iteration
//! (Adam's bias corrections change), none waited for: each iteration's sums are copied into a slot of a
//! read-back buffer, read every [`READ_BACK_EVERY`] iterations and at the end for the iterations' records, so
//! the CPU records the next iteration while the GPU runs this one. This module knows no refinement types: the
//! caller (`crate::refine`) hands it the multipliers, the weights and the target as plain arrays. Memory: per
//! loss plane one multiplier (3 colours, complex) and the target (3 colours), `W` (complex), and seven complex
//! and three real `[3, H, W]` planes besides (at 384², 7 planes: 71 MB; at 1080p: 1.0 GB).
//!
//! Through a display model ([`GpuRefineModel::display`]) the phase is the SLM's drive and `model_phasor`,
//! `model_gradient` and `model_adam` stand for `phasor` and `adam` (`refine.wgsl`'s header): two complex and
//! one real `[3, H, W]` planes more (the source, the shown phase and its slope, the phase's gradient: 124 MB
//! at 1080p), the response's tile curves (8 MB per colour for 16-pixel tiles at 1080p) and the kernels.

use std::ops::ControlFlow;

use bytemuck::{Pod, Zeroable};
use num_complex::Complex32;

use super::context::GpuContext;
use super::fft::{GpuForwardOp, GpuInverseOp, GpuMultiplier, GpuSpectralPlan};
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
    width: u32,
}

/// `PlaneParams` of `refine.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub(crate) struct PlaneParams {
    plane: u32,
    _pad: [u32; 3],
}

/// Iterations submitted between two read-backs of their sums (and calls of the progress callback, so also
/// how late a cancellation can take effect).
pub(crate) const READ_BACK_EVERY: usize = 8;

/// Bytes of one iteration's sums (`[C]` of `vec4<f32>`).
const SUMS_BYTES: u64 = 3 * 16;

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
    /// The display model the loss sees (`None`: the ideal SLM, `u = e^{iφ}`).
    pub display: Option<&'a GpuDisplayModel>,
}

/// A display model (`crate::slm::model`) as the GPU refinement's `model_` kernels read it: per colour the
/// source, the response in the tiled form, a crosstalk kernel and the zero order (ideal parts as their
/// identities).
pub(crate) struct GpuDisplayModel {
    /// `S`, `[3, H, W]` flat.
    pub source: Vec<Complex32>,
    /// R, G, B.
    pub colours: [GpuDisplayColour; 3],
}

/// One colour of a [`GpuDisplayModel`].
pub(crate) struct GpuDisplayColour {
    /// The response's tile curves `[tiles, 256]` flat, radians per code (one tile: a global table).
    pub curves: Vec<f32>,
    /// Tiles per row of the tile grid.
    pub grid_cols: usize,
    /// Each row's `[H]` bilinear tile weights `(tile a, tile b, weight of b)`.
    pub rows: Vec<(u32, u32, f32)>,
    /// Each column's `[W]`.
    pub columns: Vec<(u32, u32, f32)>,
    /// The kernel's `(rows, cols, weights row-major)`.
    pub kernel: (usize, usize, Vec<f32>),
    /// `z`.
    pub zero: Complex32,
}

/// The display model's buffers and kernels on the GPU (the buffers kept alive for the bind groups).
struct ModelOps {
    phasor: Kernel,
    gradient: Kernel,
    adam: Kernel,
    phasor_bind: wgpu::BindGroup,
    gradient_bind: wgpu::BindGroup,
    adam_bind: wgpu::BindGroup,
    _buffers: Vec<wgpu::Buffer>,
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
    sums: wgpu::Buffer,
    staging: wgpu::Buffer,
    target: wgpu::Buffer,
    /// The adjoint's spectrum, `Σ_d conj(m_d)·F{V_d}`.
    adjoint_sum: wgpu::Buffer,
    kernels: Kernels,
    groups: [u32; 3],
    /// `S = F{u}`.
    spectrum: GpuForwardOp,
    /// Per plane: `U_d = F⁻¹{m_d·S}`, the plane's `plane` bind group, and `conj(m_d)·F{V_d}` added up.
    forward: Vec<GpuInverseOp>,
    plane_binds: Vec<wgpu::BindGroup>,
    adjoint: Vec<GpuForwardOp>,
    /// `acc = F⁻¹{Σ_d conj(m_d)·F{V_d}}` and `work = F⁻¹{W·S}`.
    adjoint_op: GpuInverseOp,
    weight_op: GpuInverseOp,
    phasor_bind: wgpu::BindGroup,
    reduce_bind: wgpu::BindGroup,
    adam_bind: wgpu::BindGroup,
    /// Through a display model: the kernels that stand for `phasor` and `adam`.
    model: Option<ModelOps>,
    // Kept alive for the bind groups.
    _multipliers: Vec<GpuMultiplier>,
    _plan: GpuSpectralPlan,
    adam: GpuAdam,
    base: RefineParams,
}

struct Kernels {
    phasor: Kernel,
    plane: Kernel,
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
        let sums = ctx.storage("refine sums", SUMS_BYTES)?;
        let staging = ctx.buffer(
            "refine sums read-back",
            SUMS_BYTES * READ_BACK_EVERY as u64,
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
            width: w as u32,
        };
        let params = ctx.uniform("refine params", &base)?;
        let kernels = Kernels {
            phasor: ctx.kernel(&shaders::REFINE, "phasor")?,
            plane: ctx.kernel(&shaders::REFINE, "plane")?,
            reduce: ctx.kernel(&shaders::REFINE, "reduce")?,
            adam: ctx.kernel(&shaders::REFINE, "adam")?,
        };
        let spectrum_buf = gpu_plan.spectrum(ctx, "refine spectrum")?;
        let adjoint_sum = gpu_plan.spectrum(ctx, "refine adjoint spectrum")?;
        let mut multipliers = Vec::with_capacity(planes + 1);
        let mut forward = Vec::with_capacity(planes);
        let mut adjoint = Vec::with_capacity(planes);
        let mut plane_binds = Vec::with_capacity(planes);
        for (d, m) in model.multipliers.iter().enumerate() {
            let values: Vec<&[Complex32]> = m.iter().map(Vec::as_slice).collect();
            let multiplier = gpu_plan.multiplier(ctx, &values)?;
            forward.push(gpu_plan.bind_inverse(ctx, &spectrum_buf, Some(&multiplier), &work));
            adjoint.push(gpu_plan.bind_forward_conj_add(ctx, &work, &multiplier, &adjoint_sum)?);
            multipliers.push(multiplier);
            let plane_params = ctx.uniform(
                "refine plane",
                &PlaneParams {
                    plane: d as u32,
                    _pad: [0; 3],
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
        }
        let weights: Vec<Vec<Complex32>> = model
            .weights
            .iter()
            .map(|w| w.iter().map(|&v| Complex32::new(v, 0.0)).collect())
            .collect();
        let values: Vec<&[Complex32]> = weights.iter().map(Vec::as_slice).collect();
        let weight = gpu_plan.multiplier(ctx, &values)?;
        let weight_op = gpu_plan.bind_inverse(ctx, &spectrum_buf, Some(&weight), &work);
        multipliers.push(weight);
        let adjoint_op = gpu_plan.bind_inverse(ctx, &adjoint_sum, None, &acc);
        let spectrum = gpu_plan.bind_forward(ctx, &unit, &spectrum_buf);
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
        let model_ops = model
            .display
            .map(|d| {
                model_ops(
                    ctx,
                    d,
                    (n, w),
                    &params,
                    [&phase, &unit, &work, &acc, &sums, &mean, &square],
                )
            })
            .transpose()?;
        ctx.take_error()?;
        Ok(Self {
            ctx: ctx.clone(),
            n,
            planes,
            params,
            phase,
            mean,
            square,
            sums,
            staging,
            target,
            adjoint_sum,
            kernels,
            groups: [groups_1d[0], groups_1d[1], 3],
            spectrum,
            forward,
            plane_binds,
            adjoint,
            adjoint_op,
            weight_op,
            phasor_bind,
            reduce_bind,
            adam_bind,
            model: model_ops,
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
    /// each step's result; the last evaluation takes no step. `ControlFlow::Break` stops it at once (`Ok`,
    /// `phase` unchanged; the caller reports the cancellation). `phase` is left unwrapped (the caller wraps
    /// it).
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for a phase of another size; [`HoloError::Gpu`].
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
        let mut pending = 0;
        for it in 0..=iterations {
            let step = it < iterations;
            let t = (it + 1) as i32;
            let params = RefineParams {
                c1: 1.0 - self.adam.beta1.powi(t),
                c2: 1.0 - self.adam.beta2.powi(t),
                ..self.base
            };
            // Ordered before this iteration's submission and after the last one's.
            ctx.write(&self.params, 0, bytemuck::bytes_of(&params));
            let mut encoder = ctx.encoder("refine iteration");
            if it == 0 {
                // A fresh optimiser state.
                encoder.clear_buffer(&self.mean, 0, None);
                encoder.clear_buffer(&self.square, 0, None);
            }
            self.record(&mut encoder, step);
            encoder.copy_buffer_to_buffer(
                &self.sums,
                0,
                &self.staging,
                pending as u64 * SUMS_BYTES,
                SUMS_BYTES,
            );
            pending += 1;
            if pending < READ_BACK_EVERY && step {
                ctx.submit(encoder)?;
                continue;
            }
            ctx.submit_and_wait(encoder)?;
            let mut bytes = [0u8; SUMS_BYTES as usize * READ_BACK_EVERY];
            let bytes = &mut bytes[..pending * SUMS_BYTES as usize];
            ctx.read_staging(&self.staging, bytes)?;
            let values: &[f32] = bytemuck::cast_slice(bytes);
            for (slot, v) in values.chunks_exact(12).enumerate() {
                let sums: ColourSums =
                    std::array::from_fn(|c| (f64::from(v[4 * c]), f64::from(v[4 * c + 1])));
                let done = it + 1 - pending + slot;
                if progress(done, sums).is_break() {
                    return Ok(());
                }
            }
            pending = 0;
        }
        let out: Vec<f32> = ctx.read_buffer(&self.phase, 3 * self.n)?;
        phase.copy_from_slice(&out);
        Ok(())
    }

    /// Records one iteration: the loss's sums of the current phase and, with `step`, the gradient and Adam's
    /// update.
    fn record(&self, encoder: &mut wgpu::CommandEncoder, step: bool) {
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
        match &self.model {
            Some(m) => dispatch(encoder, &m.phasor, &m.phasor_bind, elements),
            None => dispatch(encoder, &self.kernels.phasor, &self.phasor_bind, elements),
        }
        self.spectrum.record(encoder);
        if step {
            encoder.clear_buffer(&self.adjoint_sum, 0, None);
        }
        for d in 0..self.planes {
            self.forward[d].record(encoder);
            dispatch(
                encoder,
                &self.kernels.plane,
                &self.plane_binds[d],
                self.groups,
            );
            if step {
                self.adjoint[d].record(encoder);
            }
        }
        dispatch(encoder, &self.kernels.reduce, &self.reduce_bind, [3, 1, 1]);
        if step {
            self.adjoint_op.record(encoder);
            self.weight_op.record(encoder);
            match &self.model {
                Some(m) => {
                    dispatch(encoder, &m.gradient, &m.gradient_bind, elements);
                    dispatch(encoder, &m.adam, &m.adam_bind, elements);
                }
                None => dispatch(encoder, &self.kernels.adam, &self.adam_bind, elements),
            }
        }
    }
}

/// Uploads `display` (`n` pixels per colour in rows of `width`) and binds the `model_` kernels of
/// `refine.wgsl` to it and to the refinement's `params` and `[phase, unit, work, acc, sums, mean, square]`.
///
/// Errors: [`HoloError::ShapeMismatch`] for a source, tile weights, curves or a kernel of the wrong length;
/// [`HoloError::Gpu`].
fn model_ops(
    ctx: &GpuContext,
    display: &GpuDisplayModel,
    (n, width): (usize, usize),
    params: &wgpu::Buffer,
    [phase, unit, work, acc, sums, mean, square]: [&wgpu::Buffer; 7],
) -> Result<ModelOps> {
    let (h, w) = (n / width.max(1), width);
    let bad = display.source.len() != 3 * n
        || display.colours.iter().any(|c| {
            c.rows.len() != h
                || c.columns.len() != w
                || c.curves.is_empty()
                || c.curves.len() % 256 != 0
                || c.kernel.2.len() != c.kernel.0 * c.kernel.1
        });
    if bad {
        return Err(HoloError::ShapeMismatch {
            what: "GPU display model vs its frames".into(),
            expected: vec![3, h, w],
            got: vec![display.source.len()],
        });
    }
    let source: Vec<[f32; 2]> = display.source.iter().map(|v| [v.re, v.im]).collect();
    let (mut weights, mut tables, mut axes) = (Vec::new(), Vec::new(), Vec::new());
    let mut info: Vec<u32> = Vec::with_capacity(36);
    for c in &display.colours {
        let (rows, cols, k) = &c.kernel;
        info.extend([*rows as u32, *cols as u32, weights.len() as u32, 0]);
        info.extend([c.zero.re.to_bits(), c.zero.im.to_bits(), 0, 0]);
        info.extend([
            tables.len() as u32,
            c.grid_cols as u32,
            axes.len() as u32,
            (axes.len() + h) as u32,
        ]);
        weights.extend_from_slice(k);
        tables.extend_from_slice(&c.curves);
        for &(a, b, t) in c.rows.iter().chain(&c.columns) {
            axes.push([a as f32, b as f32, t, 0.0]);
        }
    }
    let source = ctx.storage_with("refine model source", &source)?;
    let tables = ctx.storage_with("refine model response tiles", &tables)?;
    let weights = ctx.storage_with("refine model kernels", &weights)?;
    let info = ctx.storage_with("refine model info", &info)?;
    let axes = ctx.storage_with("refine model tile weights", &axes)?;
    let shown = ctx.storage("refine model shown phase", (3 * n * 8) as u64)?;
    let dphi = ctx.storage("refine model phase gradient", (3 * n * 4) as u64)?;
    let phasor = ctx.kernel(&shaders::REFINE, "model_phasor")?;
    let gradient = ctx.kernel(&shaders::REFINE, "model_gradient")?;
    let adam = ctx.kernel(&shaders::REFINE, "model_adam")?;
    let phasor_bind = ctx.bind_at(
        &phasor,
        &[
            (0, params),
            (2, phase),
            (3, unit),
            (11, &source),
            (12, &tables),
            (13, &weights),
            (14, &shown),
            (16, &info),
            (17, &axes),
        ],
    );
    let gradient_bind = ctx.bind_at(
        &gradient,
        &[
            (0, params),
            (4, work),
            (5, acc),
            (8, sums),
            (11, &source),
            (14, &shown),
            (15, &dphi),
        ],
    );
    let adam_bind = ctx.bind_at(
        &adam,
        &[
            (0, params),
            (2, phase),
            (9, mean),
            (10, square),
            (13, &weights),
            (15, &dphi),
            (16, &info),
        ],
    );
    Ok(ModelOps {
        phasor,
        gradient,
        adam,
        phasor_bind,
        gradient_bind,
        adam_bind,
        _buffers: vec![source, tables, weights, info, axes, shown, dphi],
    })
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
                c2,
                width
            }
        ),
        uniform_layout!(&REFINE, "PlaneParams", PlaneParams { plane }),
    ]
}

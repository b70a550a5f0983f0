//! [`GpuFrameSession`]: one resolution's whole frame on the GPU, chained from the kernels of [`super::cnn`],
//! [`super::fft`] and [`super::encode`] in one command buffer. The pipeline wraps one as a session's frame
//! executor when its backend is the GPU; it is built from the CNN graphs ([`crate::model::CnnWeights`]) and
//! plain numbers (display, offset, encoding, size), and knows nothing of the pipeline above it. Everything is
//! created once; a frame only uploads the CNN input, records the same dispatches and downloads the codes (plus,
//! on request, the double-phase pattern and the CNN heads).
//!
//! ```text
//! input [C,H,W] ─► hologram CNN ─► heads [6,H,W] ─► field [3,H,W] (A·e^{i(p−0.5)2π})
//!   ─► offset ASM (Eq. 6, carrier removed) × the viewer's aberration correction (Eq. 5) if any
//!      (one spectral pass; skipped at 0 m without a correction)
//!   ─► [pre-filter: field → [Re,Im] planes ─► pre-filter CNN (+ AA-DPM base) ─► field]
//!   ─► double phase (blur for AA-DPM; pass 1 + reduction; pass 2 + LUT) ─► codes (u8 ×4 per u32), phase, stats
//! ```

use std::time::Instant;

use ndarray::Array3;
use num_complex::Complex32;

use super::cnn::{GpuCnn, GpuStorage};
use super::context::GpuContext;
use super::encode::{GpuDoublePhase, GpuFieldToPlanes, GpuHeadsToField, GpuPlanesToField};
use super::fft::{GpuMultiplier, GpuSpectralOp, GpuSpectralPlan, StageCost};
use super::fovea::{GpuFovea, GpuFoveaFrame, GpuFoveaShape};
use super::kernel::Kernel;
use crate::encoding::DoublePhaseMethod;
use crate::error::{invalid, HoloError, Result};
use crate::model::CnnWeights;
use crate::optics::{Carrier, OpticalSetup, PropagationOptions};

/// The pre-filter stage: field → planes → CNN → field.
struct Prefilter {
    to_planes: GpuFieldToPlanes,
    cnn: GpuCnn,
    from_planes: GpuPlanesToField,
}

/// The spectral pass after the heads (one forward and one inverse transform): the offset propagation's
/// transfer functions (Eq. 6) and/or the viewer's aberration correction kernels `Φ` (Eq. 5 with one kernel,
/// `docs/ABERRATION.md` "In the real-time frame"), `field ← F⁻¹{F{field}·T_s·Φ}`.
struct Spectral {
    plan: GpuSpectralPlan,
    /// The transfer functions and the operation applying them alone; `None` at offset 0.
    offset: Option<(GpuMultiplier, GpuSpectralOp)>,
    /// The correction kernels and the operation applying `T_s·Φ` (`Φ` alone at offset 0), built by the first
    /// correction and rewritten in place by later ones.
    correction: Option<(GpuMultiplier, GpuSpectralOp)>,
    /// Whether frames apply the correction.
    correcting: bool,
}

impl Spectral {
    /// The operation a frame records, if any.
    fn op(&self) -> Option<&GpuSpectralOp> {
        match (&self.correction, self.correcting) {
            (Some((_, op)), true) => Some(op),
            _ => self.offset.as_ref().map(|(_, op)| op),
        }
    }
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct PreviewParams {
    n: u32,
    scale: f32,
    _pad: [u32; 2],
}

/// Previews of what the SLM displays (Eq. 8–10): codes → phase-only field × a → Fourier filter →
/// propagation by −s → (per focus) propagation to z(d) → amplitude. Built on the first request.
struct Previews {
    n: usize,
    codes: wgpu::Buffer,
    params: wgpu::Buffer,
    to_field: Kernel,
    to_field_bind: wgpu::BindGroup,
    magnitude: Kernel,
    magnitude_bind: wgpu::BindGroup,
    /// The displayed midpoint field and a copy propagated to each focus.
    midpoint: wgpu::Buffer,
    focused: wgpu::Buffer,
    amplitude: wgpu::Buffer,
    staging: wgpu::Buffer,
    filter: (GpuSpectralPlan, GpuMultiplier, GpuSpectralOp),
    back: Option<(GpuMultiplier, GpuSpectralOp)>,
    /// The plan of the propagations (the CPU propagator's padding) and the transfer functions per focus.
    plan: GpuSpectralPlan,
    props: Vec<crate::optics::Propagator>,
    focus: Vec<(u64, GpuMultiplier, GpuSpectralOp)>,
}

/// Most focus depths whose transfer functions a session keeps on the GPU (the oldest is dropped).
const MAX_CACHED_FOCUS: usize = 8;

/// One stage's name, work and traffic per frame, for `holo bench --backend gpu`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct GpuStage {
    /// Stage name: `hologram_cnn`, `heads_to_field`, `offset_asm` (or `aberration`: a correction at offset 0), `prefilter_cnn`, `double_phase`.
    pub name: &'static str,
    /// Floating-point operations per frame (a multiply-add counts 2).
    pub flops: f64,
    /// Bytes the stage's kernels read and write per frame.
    pub bytes: f64,
}

/// The whole frame of one resolution on the GPU: hologram CNN → heads → field → offset propagation (Eq. 6) →
/// optional pre-filter CNN → double phase encoding (Eq. 7) and look-up table, recorded once into one command
/// buffer; a frame uploads the CNN input `[C, H, W]` and downloads the codes `[3, H, W]`.
pub(crate) struct GpuFrameSession {
    ctx: GpuContext,
    height: usize,
    width: usize,
    in_channels: usize,
    storage: GpuStorage,
    input: wgpu::Buffer,
    heads: wgpu::Buffer,
    cnn: GpuCnn,
    to_field: GpuHeadsToField,
    /// The CNN heads' complex field `[3, H, W]` that the spectral pass, the pre-filter and the encoder share.
    field: wgpu::Buffer,
    spectral: Option<Spectral>,
    prefilter: Option<Prefilter>,
    dp: GpuDoublePhase,
    staging_codes: wgpu::Buffer,
    staging_stats: wgpu::Buffer,
    staging_phase: wgpu::Buffer,
    staging_heads: wgpu::Buffer,
    heads_host: Vec<f32>,
    setup: crate::optics::OpticalSetup,
    options: crate::optics::PropagationOptions,
    offset_m: f64,
    previews: Option<Previews>,
    /// The foveated frames' tile CNN and composition ([`GpuFrameSession::plan_fovea`]).
    fovea: Option<GpuFovea>,
}

impl std::fmt::Debug for GpuFrameSession {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuFrameSession")
            .field("size", &(self.height, self.width))
            .field("storage", &self.storage)
            .field("adapter", &self.ctx.info().name)
            .finish()
    }
}

/// What a frame returns besides the codes: Eq. 7's normaliser, the per-colour mean phase removed before
/// encoding (radians), and with a full read-back the CNN heads (amplitude, phase `[3, H, W]`).
#[derive(Debug)]
pub(crate) struct GpuFrameOutput {
    pub(crate) amplitude_scale: f32,
    pub(crate) mean_phase: [f32; 3],
    pub(crate) heads: Option<(Array3<f32>, Array3<f32>)>,
}

fn bytes_of(n: usize, elem: usize, what: &'static str) -> Result<u64> {
    n.checked_mul(elem)
        .map(|b| b as u64)
        .ok_or_else(|| invalid(what, "frame too large"))
}

impl GpuFrameSession {
    /// Builds every buffer, pipeline and bind group of one frame at `height × width` on `ctx`: the hologram
    /// CNN `hologram` (input `[hologram.in_channels, H, W]`), the offset propagation by `offset_m` metres
    /// (Eq. 6; none at 0) on the display `optics` with `options`, the pre-filter CNN `prefilter` if any, and
    /// the double phase method `encoding`; the CNNs' activations in `storage` (f32 where the adapter has no
    /// f16 shaders).
    ///
    /// Errors: [`HoloError::Gpu`] (a buffer above the device's limits, a shader the device refuses);
    /// [`HoloError::ModelContract`] for a CNN that is not the TensorHolo architecture;
    /// [`HoloError::InvalidParameter`] for an FFT size or double phase method the GPU path does not cover
    /// (the message names it).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        ctx: &GpuContext,
        hologram: &CnnWeights,
        prefilter: Option<&CnnWeights>,
        optics: &OpticalSetup,
        options: PropagationOptions,
        offset_m: f64,
        encoding: DoublePhaseMethod,
        height: usize,
        width: usize,
        storage: GpuStorage,
    ) -> Result<Self> {
        let storage = if ctx.info().shader_f16 {
            storage
        } else {
            GpuStorage::F32
        };
        let n = height
            .checked_mul(width)
            .filter(|&n| n > 0)
            .ok_or_else(|| invalid("size", format!("{height}×{width} is empty or too large")))?;
        let in_channels = hologram.in_channels;
        let input = ctx.storage("cnn input", bytes_of(n * in_channels, 4, "size")?)?;
        let heads = ctx.storage("heads", bytes_of(6 * n, 4, "size")?)?;
        let cnn = GpuCnn::new(ctx, hologram, height, width, &input, &heads, storage)?;
        let field = ctx.storage("field", bytes_of(3 * n, 8, "size")?)?;
        let to_field = GpuHeadsToField::new(ctx, height, width, &heads, &field)?;
        let spectral = if offset_m != 0.0 {
            let props = optics.propagators(height, width, options)?;
            let plan = GpuSpectralPlan::new(ctx, props[0].plan(), 3)?;
            let multiplier = plan.transfer_functions(ctx, &props, offset_m, Carrier::Remove)?;
            let op = plan.bind(ctx, &field, &multiplier)?;
            Some(Spectral {
                plan,
                offset: Some((multiplier, op)),
                correction: None,
                correcting: false,
            })
        } else {
            None
        };
        let prefilter = match prefilter {
            Some(weights) => {
                let planes_in = ctx.storage("prefilter input", bytes_of(6 * n, 4, "size")?)?;
                let planes_out = ctx.storage("prefilter output", bytes_of(6 * n, 4, "size")?)?;
                Some(Prefilter {
                    to_planes: GpuFieldToPlanes::new(ctx, height, width, &field, &planes_in)?,
                    cnn: GpuCnn::new(
                        ctx,
                        weights,
                        height,
                        width,
                        &planes_in,
                        &planes_out,
                        storage,
                    )?,
                    from_planes: GpuPlanesToField::new(ctx, height, width, &planes_out, &field)?,
                })
            }
            None => None,
        };
        let dp = GpuDoublePhase::new(ctx, height, width, &encoding, &field)?;
        let read = wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST;
        let staging_codes = ctx.buffer("codes read-back", bytes_of(3 * n, 1, "size")?, read)?;
        let staging_stats = ctx.buffer("stats read-back", dp.stats_bytes(), read)?;
        let staging_phase = ctx.buffer("phase read-back", bytes_of(3 * n, 4, "size")?, read)?;
        let staging_heads = ctx.buffer("heads read-back", bytes_of(6 * n, 4, "size")?, read)?;
        Ok(Self {
            ctx: ctx.clone(),
            height,
            width,
            in_channels,
            storage,
            input,
            heads,
            cnn,
            to_field,
            field,
            spectral,
            prefilter,
            dp,
            staging_codes,
            staging_stats,
            staging_phase,
            staging_heads,
            heads_host: vec![0.0; 6 * n],
            setup: *optics,
            options,
            offset_m,
            previews: None,
            fovea: None,
        })
    }

    /// Plans this session's foveated frames ([`GpuFrameSession::run_foveated`]): the hologram CNN
    /// `hologram` (the frame's graph) on a tile of `shape.tile`, its heads composed with the periphery into
    /// the frame's heads. Once per session: every gaze uses this plan.
    ///
    /// Errors: as [`GpuFovea::new`].
    pub(crate) fn plan_fovea(&mut self, hologram: &CnnWeights, shape: GpuFoveaShape) -> Result<()> {
        self.fovea = Some(GpuFovea::new(
            &self.ctx,
            hologram,
            shape,
            (self.height, self.width),
            &self.heads,
            self.storage,
        )?);
        Ok(())
    }

    /// Runs one foveated frame (`docs/FOVEATION.md`): uploads the tile's CNN input and the image
    /// ([`GpuFoveaFrame`]), runs the tile's CNN, the band's phase and the composition into the heads, then
    /// the frame's stages after the heads (offset propagation, pre-filter over the whole frame, double phase
    /// encoding) with the global normaliser `normaliser` (`> 0`) instead of the field's own; downloads as
    /// [`GpuFrameSession::run`] does. Returns the frame's output and the band's phase per colour (radians).
    ///
    /// Errors: [`HoloError::Internal`] before [`GpuFrameSession::plan_fovea`]; [`HoloError::InvalidParameter`]
    /// for a normaliser that is not positive and finite; otherwise as [`GpuFovea::upload`] and
    /// [`GpuFrameSession::run`].
    pub(crate) fn run_foveated(
        &mut self,
        frame: &GpuFoveaFrame<'_>,
        normaliser: f32,
        codes: &mut Array3<u8>,
        phase: Option<&mut Array3<f32>>,
    ) -> Result<(GpuFrameOutput, [f32; 3])> {
        if !(normaliser > 0.0 && normaliser.is_finite()) {
            return Err(invalid(
                "normaliser",
                format!("must be > 0 and finite, got {normaliser}"),
            ));
        }
        let Some(fovea) = &self.fovea else {
            return Err(HoloError::Internal(
                "a foveated GPU frame before its plan".into(),
            ));
        };
        fovea.upload(&self.ctx, frame)?;
        let mut encoder = self.ctx.encoder("foveated frame");
        fovea.record(&mut encoder);
        self.record_after_heads(&mut encoder);
        self.dp.set_normaliser(&self.ctx, Some(normaliser));
        let out = self.download(encoder, codes, phase)?;
        let theta = match &self.fovea {
            Some(f) => f.read_theta(&self.ctx)?,
            None => [0.0; 3],
        };
        Ok((out, theta))
    }

    fn build_previews(&self) -> Result<Previews> {
        let ctx = &self.ctx;
        let (h, w) = (self.height, self.width);
        let n = 3 * h * w;
        let codes = ctx.storage("preview codes", n.div_ceil(4) as u64 * 4)?;
        let params = ctx.uniform(
            "preview",
            &PreviewParams {
                n: n as u32,
                scale: 1.0,
                _pad: [0; 2],
            },
        )?;
        let midpoint = ctx.storage("preview midpoint", (n * 8) as u64)?;
        let focused = ctx.storage("preview focused", (n * 8) as u64)?;
        let amplitude = ctx.storage("preview amplitude", (n * 4) as u64)?;
        let read = wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST;
        let staging = ctx.buffer("preview read-back", (n * 4) as u64, read)?;
        let to_field = ctx.kernel(&super::shaders::PREVIEW, "codes_to_field")?;
        let to_field_bind = ctx.bind_at(&to_field, &[(0, &params), (1, &codes), (2, &midpoint)]);
        let magnitude = ctx.kernel(&super::shaders::PREVIEW, "magnitude")?;
        let magnitude_bind =
            ctx.bind_at(&magnitude, &[(0, &params), (2, &focused), (3, &amplitude)]);
        let fourier = crate::optics::FourierFilter::new(h, w)?;
        let filter_plan = GpuSpectralPlan::new(ctx, fourier.plan(), 3)?;
        let m = fourier.multiplier();
        let filter_mult = filter_plan.multiplier(ctx, &[m, m, m])?;
        let filter_op = filter_plan.bind(ctx, &midpoint, &filter_mult)?;
        let props = self.setup.propagators(h, w, self.options)?;
        let plan = GpuSpectralPlan::new(ctx, props[0].plan(), 3)?;
        let back = if self.offset_m != 0.0 {
            let mult = plan.transfer_functions(ctx, &props, -self.offset_m, Carrier::Remove)?;
            let op = plan.bind(ctx, &midpoint, &mult)?;
            Some((mult, op))
        } else {
            None
        };
        Ok(Previews {
            n,
            codes,
            params,
            to_field,
            to_field_bind,
            magnitude,
            magnitude_bind,
            midpoint,
            focused,
            amplitude,
            staging,
            filter: (filter_plan, filter_mult, filter_op),
            back,
            plan,
            props: props.to_vec(),
            focus: Vec::new(),
        })
    }

    /// What a viewer sees of the SLM codes `codes` `[3, H, W]` (linear LUT) with the encoding's normaliser
    /// `amplitude_scale`, focused at normalised depth `focus` ∈ [0, 1]: the amplitude `[3, H, W]` of the
    /// phase-only field after the Fourier filter (Eq. 8–9), brought back by −s and propagated to `z(focus)`
    /// (Eq. 10), as [`crate::optics::post_encoding_midpoint`] then [`crate::optics::focal_stack`] compute on
    /// the CPU. The first call builds the preview buffers; each new focus uploads its transfer functions once
    /// (the last 8 are kept).
    ///
    /// Errors: [`HoloError::InvalidParameter`] for a focus outside [0, 1] or a non-positive scale;
    /// [`HoloError::ShapeMismatch`] for codes of another size; [`HoloError::Gpu`].
    pub(crate) fn preview(
        &mut self,
        codes: &Array3<u8>,
        amplitude_scale: f32,
        focus: f64,
    ) -> Result<Array3<f32>> {
        if !(0.0..=1.0).contains(&focus) {
            return Err(invalid(
                "focus",
                format!("is a normalised depth in [0, 1] (0 = near), got {focus}"),
            ));
        }
        if !(amplitude_scale > 0.0 && amplitude_scale.is_finite()) {
            return Err(invalid(
                "amplitude_scale",
                format!("must be > 0, got {amplitude_scale}"),
            ));
        }
        let want = [3, self.height, self.width];
        if codes.shape() != want {
            return Err(HoloError::ShapeMismatch {
                what: "preview codes vs the session's [3, H, W]".into(),
                expected: want.to_vec(),
                got: codes.shape().to_vec(),
            });
        }
        if self.previews.is_none() {
            self.previews = Some(self.build_previews()?);
        }
        let setup = self.setup;
        let ctx = self.ctx.clone();
        let p = self
            .previews
            .as_mut()
            .ok_or_else(|| HoloError::Internal("previews".into()))?;
        let key = focus.to_bits();
        if !p.focus.iter().any(|(k, _, _)| *k == key) {
            let z = setup.depth_to_z(focus);
            let mult = p
                .plan
                .transfer_functions(&ctx, &p.props, z, Carrier::Remove)?;
            let op = p.plan.bind(&ctx, &p.focused, &mult)?;
            if p.focus.len() == MAX_CACHED_FOCUS {
                p.focus.remove(0);
            }
            p.focus.push((key, mult, op));
        }
        let mut bytes = codes
            .as_slice()
            .ok_or_else(|| HoloError::Internal("codes not contiguous".into()))?
            .to_vec();
        bytes.resize(p.n.div_ceil(4) * 4, 0);
        ctx.write(&p.codes, 0, &bytes);
        ctx.write(
            &p.params,
            0,
            bytemuck::bytes_of(&PreviewParams {
                n: p.n as u32,
                scale: amplitude_scale,
                _pad: [0; 2],
            }),
        );
        let mut encoder = ctx.encoder("preview");
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            p.to_field
                .dispatch(&mut pass, &p.to_field_bind, super::kernel::grid_1d(p.n));
        }
        p.filter.2.record(&mut encoder);
        if let Some((_, op)) = &p.back {
            op.record(&mut encoder);
        }
        encoder.copy_buffer_to_buffer(&p.midpoint, 0, &p.focused, 0, (p.n * 8) as u64);
        if let Some((_, _, op)) = p.focus.iter().find(|(k, _, _)| *k == key) {
            op.record(&mut encoder);
        }
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            p.magnitude
                .dispatch(&mut pass, &p.magnitude_bind, super::kernel::grid_1d(p.n));
        }
        encoder.copy_buffer_to_buffer(&p.amplitude, 0, &p.staging, 0, (p.n * 4) as u64);
        ctx.submit_and_wait(encoder)?;
        let mut out = Array3::<f32>::zeros((3, self.height, self.width));
        let dst = out
            .as_slice_mut()
            .ok_or_else(|| HoloError::Internal("fresh array".into()))?;
        ctx.read_staging(&p.staging, bytemuck::cast_slice_mut(dst))?;
        Ok(out)
    }

    /// The spectral pass a frame records, if any.
    fn spectral_op(&self) -> Option<&GpuSpectralOp> {
        self.spectral.as_ref().and_then(Spectral::op)
    }

    /// The spectral stage's name in profiles: `offset_asm` (with or without a correction), or `aberration`
    /// (a correction at offset 0).
    fn spectral_name(&self) -> &'static str {
        if self.offset_m != 0.0 {
            "offset_asm"
        } else {
            "aberration"
        }
    }

    /// Sets the viewer's aberration correction of the next frames: `kernels` are the correction kernels `Φ`
    /// per colour (R, G, B) in the CPU [`crate::optics::SpectralPlan`] layout of this session's propagators
    /// (`[Wc, Hc]`), scaled by the inverse transform's normalisation `1/(Hc·Wc)` at offset 0 (where no
    /// transfer function carries it) and by 1 otherwise, as the CPU frame's; `None` turns the correction off.
    /// The first correction uploads the kernels (and, at offset 0, plans the spectral pass); later ones rewrite
    /// them in place, allocating no GPU memory.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for kernels of another size; [`HoloError::Gpu`].
    pub(crate) fn set_correction(&mut self, kernels: Option<[&[Complex32]; 3]>) -> Result<()> {
        let Some(kernels) = kernels else {
            if let Some(s) = &mut self.spectral {
                s.correcting = false;
            }
            return Ok(());
        };
        let spectral = match &mut self.spectral {
            Some(s) => s,
            None => {
                let props = self
                    .setup
                    .propagators(self.height, self.width, self.options)?;
                let plan = GpuSpectralPlan::new(&self.ctx, props[0].plan(), 3)?;
                self.spectral.insert(Spectral {
                    plan,
                    offset: None,
                    correction: None,
                    correcting: false,
                })
            }
        };
        match &spectral.correction {
            Some((multiplier, _)) => spectral.plan.rewrite(&self.ctx, multiplier, &kernels)?,
            None => {
                let multiplier = spectral.plan.multiplier(&self.ctx, &kernels)?;
                let op = match &spectral.offset {
                    Some((transfer, _)) => spectral.plan.bind_chain(
                        &self.ctx,
                        &self.field,
                        &[transfer, &multiplier],
                    )?,
                    None => spectral.plan.bind(&self.ctx, &self.field, &multiplier)?,
                };
                spectral.correction = Some((multiplier, op));
            }
        }
        spectral.correcting = true;
        Ok(())
    }

    /// The CNNs' activation storage (what runs: f32 where the adapter has no f16 shaders).
    pub(crate) fn storage(&self) -> GpuStorage {
        self.storage
    }

    /// Records the frame's dispatches (after the input upload) into `encoder`.
    fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        self.cnn.record(encoder);
        self.record_after_heads(encoder);
    }

    /// Records the frame's dispatches after the hologram CNN's heads into `encoder`.
    fn record_after_heads(&self, encoder: &mut wgpu::CommandEncoder) {
        self.to_field.record(encoder);
        if let Some(op) = self.spectral_op() {
            op.record(encoder);
        }
        if let Some(p) = &self.prefilter {
            p.to_planes.record(encoder);
            p.cnn.record(encoder);
            p.from_planes.record(encoder);
        }
        self.dp.record(encoder);
    }

    /// Runs one frame: uploads `input` (the CNN input's `C` planes of `H·W` values each, as
    /// [`crate::model::contract`] packs them, or an RGB-D frame's own planes), runs every stage and downloads
    /// the codes `[3, H, W]` into `codes`; with `phase`, also the double phase pattern `[3, H, W]` (radians)
    /// into it and the CNN heads (amplitude, phase `[3, H, W]`, returned).
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for an input of another shape; [`HoloError::Gpu`] for a GPU
    /// failure (lost device, validation error); [`HoloError::InvalidData`] for a hologram that is zero
    /// everywhere (as the CPU path).
    pub(crate) fn run(
        &mut self,
        input: &[&[f32]],
        codes: &mut Array3<u8>,
        phase: Option<&mut Array3<f32>>,
    ) -> Result<GpuFrameOutput> {
        let n = self.height * self.width;
        if input.len() != self.in_channels || input.iter().any(|p| p.len() != n) {
            return Err(HoloError::ShapeMismatch {
                what: "GPU CNN input planes vs the session's [C, H·W]".into(),
                expected: vec![self.in_channels, n],
                got: vec![input.len(), input.first().map_or(0, |p| p.len())],
            });
        }
        for (i, plane) in input.iter().enumerate() {
            self.ctx
                .write(&self.input, (i * n * 4) as u64, bytemuck::cast_slice(plane));
        }
        self.dp.set_normaliser(&self.ctx, None);
        let mut encoder = self.ctx.encoder("frame");
        self.record(&mut encoder);
        self.download(encoder, codes, phase)
    }

    /// Adds the read-backs to a frame's `encoder` (the codes and statistics; with `phase`, the double phase
    /// pattern and the heads), submits it, waits, and reads them.
    ///
    /// Errors: as [`GpuFrameSession::run`].
    fn download(
        &mut self,
        mut encoder: wgpu::CommandEncoder,
        codes: &mut Array3<u8>,
        phase: Option<&mut Array3<f32>>,
    ) -> Result<GpuFrameOutput> {
        let full = phase.is_some();
        let n = self.height * self.width;
        let codes_bytes = (3 * n) as u64;
        encoder.copy_buffer_to_buffer(
            self.dp.codes_buffer(),
            0,
            &self.staging_codes,
            0,
            codes_bytes.div_ceil(4) * 4,
        );
        encoder.copy_buffer_to_buffer(
            self.dp.stats_buffer(),
            0,
            &self.staging_stats,
            0,
            self.dp.stats_bytes(),
        );
        if full {
            encoder.copy_buffer_to_buffer(
                self.dp.phase_buffer(),
                0,
                &self.staging_phase,
                0,
                (3 * n * 4) as u64,
            );
            encoder.copy_buffer_to_buffer(
                &self.heads,
                0,
                &self.staging_heads,
                0,
                (6 * n * 4) as u64,
            );
        }
        self.ctx.submit_and_wait(encoder)?;
        let mut stats = [0u8; super::encode::STATS_BYTES as usize];
        self.ctx.read_staging(&self.staging_stats, &mut stats)?;
        let (amplitude_scale, mean_phase) = GpuDoublePhase::read_stats(&stats)?;
        let codes = codes
            .as_slice_mut()
            .ok_or_else(|| HoloError::Internal("output codes not contiguous".into()))?;
        self.ctx.read_staging(&self.staging_codes, codes)?;
        let mut out = GpuFrameOutput {
            amplitude_scale,
            mean_phase,
            heads: None,
        };
        let Some(phase) = phase else {
            return Ok(out);
        };
        let phase = phase
            .as_slice_mut()
            .ok_or_else(|| HoloError::Internal("output phase not contiguous".into()))?;
        self.ctx
            .read_staging(&self.staging_phase, bytemuck::cast_slice_mut(phase))?;
        self.ctx.read_staging(
            &self.staging_heads,
            bytemuck::cast_slice_mut(&mut self.heads_host),
        )?;
        let amplitude = Array3::from_shape_vec(
            (3, self.height, self.width),
            self.heads_host[..3 * n].to_vec(),
        )
        .map_err(|e| HoloError::Internal(e.to_string()))?;
        let phase = Array3::from_shape_vec(
            (3, self.height, self.width),
            self.heads_host[3 * n..].to_vec(),
        )
        .map_err(|e| HoloError::Internal(e.to_string()))?;
        out.heads = Some((amplitude, phase));
        Ok(out)
    }

    /// Work and traffic of each stage per frame (for benchmarks: arithmetic intensity = flops / bytes).
    pub(crate) fn stages(&self) -> Vec<GpuStage> {
        let mut v = Vec::new();
        let (flops, bytes) = self.cnn.cost();
        v.push(GpuStage {
            name: "hologram_cnn",
            flops,
            bytes,
        });
        let (flops, bytes) = self.to_field.cost();
        v.push(GpuStage {
            name: "heads_to_field",
            flops,
            bytes,
        });
        if let Some(op) = self.spectral_op() {
            let StageCost { flops, bytes } = op.cost();
            v.push(GpuStage {
                name: self.spectral_name(),
                flops,
                bytes,
            });
        }
        if let Some(p) = &self.prefilter {
            let (f1, b1) = p.to_planes.cost();
            let (f2, b2) = p.cnn.cost();
            let (f3, b3) = p.from_planes.cost();
            v.push(GpuStage {
                name: "prefilter_cnn",
                flops: f1 + f2 + f3,
                bytes: b1 + b2 + b3,
            });
        }
        let (flops, bytes) = self.dp.cost();
        v.push(GpuStage {
            name: "double_phase",
            flops,
            bytes,
        });
        v
    }

    /// Times each stage on its own (one submission and wait per stage, `repeats` times, median seconds), for
    /// `holo bench --backend gpu`. The input is whatever the last frame uploaded. Slower than a frame (every
    /// stage waits for the GPU), and allocates nothing on the GPU.
    ///
    /// Errors: [`HoloError::Gpu`].
    pub(crate) fn profile(&self, repeats: usize) -> Result<Vec<(&'static str, f64)>> {
        type Recorder<'a> = Box<dyn Fn(&mut wgpu::CommandEncoder) + 'a>;
        let mut stages: Vec<(&'static str, Recorder)> = vec![
            ("hologram_cnn", Box::new(|e| self.cnn.record(e))),
            ("heads_to_field", Box::new(|e| self.to_field.record(e))),
        ];
        if let Some(op) = self.spectral_op() {
            stages.push((self.spectral_name(), Box::new(|e| op.record(e))));
        }
        if let Some(p) = &self.prefilter {
            stages.push((
                "prefilter_cnn",
                Box::new(|e| {
                    p.to_planes.record(e);
                    p.cnn.record(e);
                    p.from_planes.record(e);
                }),
            ));
        }
        stages.push(("double_phase", Box::new(|e| self.dp.record(e))));
        let mut out = Vec::new();
        for (name, rec) in &stages {
            let mut times = Vec::new();
            for _ in 0..repeats.max(1) {
                let mut enc = self.ctx.encoder(name);
                rec(&mut enc);
                let t = Instant::now();
                self.ctx.submit_and_wait(enc)?;
                times.push(t.elapsed().as_secs_f64());
            }
            times.sort_by(f64::total_cmp);
            out.push((*name, times[times.len() / 2]));
        }
        Ok(out)
    }
}

/// The uniform structs of this module beside their WGSL twins (checked in `shader_tests`).
#[cfg(test)]
pub(super) fn uniform_layouts() -> Vec<super::shader_tests::UniformLayout> {
    use super::shader_tests::uniform_layout;
    vec![uniform_layout!(
        &super::shaders::PREVIEW,
        "Preview",
        PreviewParams { n, scale }
    )]
}

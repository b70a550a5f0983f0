//! The GPU counterpart of [`crate::optics::SpectralPlan`]: `u ↦ F⁻¹{F{u} · M}` on a batch of complex fields
//! `[C, H, W]` (the three colours at once), with the CPU plan's optional 2× zero padding and its multiplier
//! layout (transposed spectrum `[Wc, Hc]`, FFT bin order, inverse normalisation folded in), so a transfer
//! function computed once by the CPU code ([`crate::optics::Propagator::transfer_function`]) is uploaded as
//! it is.
//!
//! The 2D FFT is rows → transpose → rows (`shaders/fft.wgsl`): a batched Stockham FFT along rows with one pass
//! per radix (mixed radix, direct DFTs of length ≤ 16), and a tiled transpose. Sizes whose prime factors are
//! all ≤ 13 are covered: 384 = 2⁷·3, 540 = 2²·3³·5, 960, 1080, 1920, 3840 and their doubles. Twiddles come
//! from one table per length, computed in f64 on the CPU.

use std::sync::Arc;

use num_complex::Complex32;

use super::context::GpuContext;
use super::kernel::{grid_1d, grid_2d, Kernel};
use super::shaders;
use crate::error::{invalid, HoloError, Result};
use crate::optics::SpectralPlan;

/// Largest prime factor of an FFT length the GPU path covers (direct DFT passes of length ≤ 16).
pub const MAX_PRIME_FACTOR: usize = 13;

/// Floating-point work and memory traffic of one recorded operation (for benchmarks).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct StageCost {
    /// Floating-point operations (an FFT of N points counts 5·N·log₂N).
    pub flops: f64,
    /// Bytes read and written by the kernels.
    pub bytes: f64,
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct PassParams {
    n: u32,
    rows: u32,
    ns: u32,
    radix: u32,
    twiddle_stride: u32,
    sign: f32,
    _pad: [u32; 2],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ShapeParams {
    rows: u32,
    cols: u32,
    planes: u32,
    _pad: u32,
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct GridParams {
    h: u32,
    w: u32,
    hc: u32,
    wc: u32,
    oy: u32,
    ox: u32,
    channels: u32,
    _pad: u32,
}

/// The radices of a length-`n` FFT, 4s first (fewer passes), then 2, 3, 5, 7, 11, 13.
///
/// Errors: [`HoloError::InvalidParameter`] naming `n` and its prime factors if one exceeds
/// [`MAX_PRIME_FACTOR`].
pub(crate) fn radices(n: usize) -> Result<Vec<usize>> {
    if n == 0 {
        return Err(invalid("FFT size", "must be ≥ 1"));
    }
    let mut rest = n;
    let mut out = Vec::new();
    while rest.is_multiple_of(4) {
        out.push(4);
        rest /= 4;
    }
    for p in [2, 3, 5, 7, 11, 13] {
        while rest.is_multiple_of(p) {
            out.push(p);
            rest /= p;
        }
    }
    if rest != 1 {
        let mut factors = Vec::new();
        let (mut m, mut p) = (n, 2);
        while m > 1 {
            while m.is_multiple_of(p) {
                factors.push(p);
                m /= p;
            }
            p += 1;
        }
        return Err(invalid(
            "FFT size",
            format!(
                "the GPU FFT covers lengths whose prime factors are ≤ {MAX_PRIME_FACTOR}; {n} = {} (use the \
                 CPU backend, or a size such as 384, 540, 960, 1080, 1920)",
                factors
                    .iter()
                    .map(|f| f.to_string())
                    .collect::<Vec<_>>()
                    .join("·")
            ),
        ));
    }
    Ok(out)
}

/// A planned batched 1D FFT of one length on `rows` rows, both directions, ping-ponging between the plan's
/// two work buffers: every pass is bound both ways (`[from a → b, from b → a]`).
struct RowFft {
    n: usize,
    rows: usize,
    forward: Vec<([wgpu::BindGroup; 2], [u32; 3])>,
    inverse: Vec<([wgpu::BindGroup; 2], [u32; 3])>,
}

impl RowFft {
    fn new(
        ctx: &GpuContext,
        kernel: &Kernel,
        n: usize,
        rows: usize,
        a: &wgpu::Buffer,
        b: &wgpu::Buffer,
    ) -> Result<Self> {
        if rows > super::kernel::MAX_GROUPS_PER_DIM as usize {
            return Err(invalid(
                "FFT rows",
                format!("{rows} rows exceed one dispatch (65 535)"),
            ));
        }
        let radices = radices(n)?;
        let table: Vec<[f32; 2]> = (0..n)
            .map(|m| {
                let angle = -std::f64::consts::TAU * m as f64 / n as f64;
                [angle.cos() as f32, angle.sin() as f32]
            })
            .collect();
        let twiddles = ctx.storage_with("fft twiddles", &table)?;
        let build = |sign: f32| -> Result<Vec<([wgpu::BindGroup; 2], [u32; 3])>> {
            let mut passes = Vec::new();
            let mut ns = 1;
            for &r in &radices {
                let p = ctx.uniform(
                    "fft pass",
                    &PassParams {
                        n: n as u32,
                        rows: rows as u32,
                        ns: ns as u32,
                        radix: r as u32,
                        twiddle_stride: (n / (ns * r)) as u32,
                        sign,
                        _pad: [0; 2],
                    },
                )?;
                let both = [
                    ctx.bind(kernel, &[&p, a, b, &twiddles]),
                    ctx.bind(kernel, &[&p, b, a, &twiddles]),
                ];
                passes.push((both, grid_2d(n / r, rows, 1, [64, 1])));
                ns *= r;
            }
            Ok(passes)
        };
        Ok(Self {
            n,
            rows,
            forward: build(-1.0)?,
            inverse: build(1.0)?,
        })
    }

    /// Records the passes on data in `b` (`in_b`) or `a`; returns where the result is.
    fn record(
        &self,
        pass: &mut wgpu::ComputePass<'_>,
        kernel: &Kernel,
        inverse: bool,
        mut in_b: bool,
    ) -> bool {
        for (bgs, groups) in if inverse {
            &self.inverse
        } else {
            &self.forward
        } {
            kernel.dispatch(pass, &bgs[usize::from(in_b)], *groups);
            in_b = !in_b;
        }
        in_b
    }

    fn flops(&self) -> f64 {
        5.0 * (self.n as f64) * (self.n as f64).log2() * self.rows as f64
    }

    fn passes(&self) -> usize {
        self.forward.len()
    }
}

/// The kernels, scratch buffers and passes of a [`GpuSpectralPlan`], shared with its bound operations.
struct PlanInner {
    channels: usize,
    height: usize,
    width: usize,
    comp: (usize, usize),
    a: wgpu::Buffer,
    b: wgpu::Buffer,
    grid: wgpu::Buffer,
    pass_kernel: Kernel,
    transpose_kernel: Kernel,
    embed_kernel: Kernel,
    crop_kernel: Kernel,
    multiply_kernel: Kernel,
    /// Made by the first transform that adds into a spectrum ([`GpuSpectralPlan::bind_forward_conj_add`]).
    multiply_conj_add_kernel: std::sync::OnceLock<Kernel>,
    /// Along the width (rows of `[C·Hc, Wc]`) and along the height (rows of the transposed `[C·Wc, Hc]`).
    rows_w: RowFft,
    rows_h: RowFft,
    /// `[C, Hc, Wc] → [C, Wc, Hc]` and back, each bound both ways (from a, from b).
    to_t: [wgpu::BindGroup; 2],
    from_t: [wgpu::BindGroup; 2],
}

/// The GPU counterpart of a [`SpectralPlan`] for `channels` fields: FFT passes, scratch buffers and the
/// kernels (see the [module docs](self)). Operations bound to one plan share its scratch buffers and must
/// run one after another.
pub struct GpuSpectralPlan {
    inner: Arc<PlanInner>,
}

impl std::fmt::Debug for GpuSpectralPlan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuSpectralPlan")
            .field("channels", &self.inner.channels)
            .field("field", &(self.inner.height, self.inner.width))
            .field("computational", &self.inner.comp)
            .finish()
    }
}

/// Spectral multipliers uploaded for a [`GpuSpectralPlan`] (one per channel, `[C, Wc, Hc]`).
#[derive(Debug)]
pub struct GpuMultiplier {
    buffer: wgpu::Buffer,
}

/// One spectral operation bound to a field buffer and one or more multipliers ([`GpuSpectralPlan::bind`],
/// [`GpuSpectralPlan::bind_chain`]).
pub struct GpuSpectralOp {
    plan: Arc<PlanInner>,
    embed: wgpu::BindGroup,
    /// One multiply pass per multiplier, each bound both ways (spectrum in a, in b).
    multiply: Vec<[wgpu::BindGroup; 2]>,
    crop: [wgpu::BindGroup; 2],
}

/// A forward transform bound to a field buffer ([`GpuSpectralPlan::bind_forward`],
/// [`GpuSpectralPlan::bind_forward_conj_add`]): `F{field}` copied into a spectrum buffer, or multiplied by a
/// multiplier's conjugate and added into one.
pub(crate) struct GpuForwardOp {
    plan: Arc<PlanInner>,
    embed: wgpu::BindGroup,
    sink: ForwardSink,
}

/// Where a [`GpuForwardOp`] leaves its spectrum.
enum ForwardSink {
    /// Copied into this buffer (`[C, Wc, Hc]`).
    Copy(wgpu::Buffer),
    /// `sum += conj(M)·F{field}`, bound both ways (the spectrum in a, in b).
    ConjAdd([wgpu::BindGroup; 2]),
}

/// An inverse transform bound to a spectrum buffer and a field buffer ([`GpuSpectralPlan::bind_inverse`]):
/// `field ← F⁻¹{spectrum·M}` (or without a multiplier), the spectrum buffer left as it is.
pub(crate) struct GpuInverseOp {
    plan: Arc<PlanInner>,
    spectrum: wgpu::Buffer,
    /// The multiply pass on the spectrum's copy in `a`.
    multiply: Option<wgpu::BindGroup>,
    crop: [wgpu::BindGroup; 2],
}

impl std::fmt::Debug for GpuSpectralOp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuSpectralOp").finish_non_exhaustive()
    }
}

impl GpuSpectralPlan {
    /// Plans the GPU transforms of `plan` (its field size and padding) for `channels` fields.
    ///
    /// Errors: [`HoloError::InvalidParameter`] for an FFT length with a prime factor above
    /// [`MAX_PRIME_FACTOR`] or zero channels; [`HoloError::Gpu`] for buffers above the device's limits.
    pub(crate) fn new(ctx: &GpuContext, plan: &SpectralPlan, channels: usize) -> Result<Self> {
        if channels == 0 {
            return Err(invalid("channels", "a spectral plan needs ≥ 1 channel"));
        }
        let (hc, wc) = plan.computational_shape();
        radices(hc)?;
        radices(wc)?;
        let elems = channels
            .checked_mul(hc)
            .and_then(|v| v.checked_mul(wc))
            .ok_or_else(|| invalid("size", "spectral grid too large"))?;
        let bytes = (elems as u64) * 8;
        let a = ctx.storage("fft work a", bytes)?;
        let b = ctx.storage("fft work b", bytes)?;
        let pass_kernel = ctx.kernel(&shaders::FFT, "stockham_pass")?;
        let transpose_kernel = ctx.kernel(&shaders::FFT, "transpose")?;
        let embed_kernel = ctx.kernel(&shaders::SPECTRAL, "embed")?;
        let crop_kernel = ctx.kernel(&shaders::SPECTRAL, "crop")?;
        let multiply_kernel = ctx.kernel(&shaders::SPECTRAL, "multiply")?;
        let rows_w = RowFft::new(ctx, &pass_kernel, wc, channels * hc, &a, &b)?;
        let rows_h = RowFft::new(ctx, &pass_kernel, hc, channels * wc, &a, &b)?;
        let shape = |rows: usize, cols: usize| ShapeParams {
            rows: rows as u32,
            cols: cols as u32,
            planes: channels as u32,
            _pad: 0,
        };
        let to_t_params = ctx.uniform("transpose to [C, Wc, Hc]", &shape(hc, wc))?;
        let from_t_params = ctx.uniform("transpose to [C, Hc, Wc]", &shape(wc, hc))?;
        let to_t = [
            ctx.bind(&transpose_kernel, &[&to_t_params, &a, &b]),
            ctx.bind(&transpose_kernel, &[&to_t_params, &b, &a]),
        ];
        let from_t = [
            ctx.bind(&transpose_kernel, &[&from_t_params, &a, &b]),
            ctx.bind(&transpose_kernel, &[&from_t_params, &b, &a]),
        ];
        let grid = ctx.uniform(
            "spectral grid",
            &GridParams {
                h: plan.height() as u32,
                w: plan.width() as u32,
                hc: hc as u32,
                wc: wc as u32,
                oy: ((hc - plan.height()) / 2) as u32,
                ox: ((wc - plan.width()) / 2) as u32,
                channels: channels as u32,
                _pad: 0,
            },
        )?;
        Ok(Self {
            inner: Arc::new(PlanInner {
                channels,
                height: plan.height(),
                width: plan.width(),
                comp: (hc, wc),
                a,
                b,
                grid,
                pass_kernel,
                transpose_kernel,
                embed_kernel,
                crop_kernel,
                multiply_kernel,
                multiply_conj_add_kernel: std::sync::OnceLock::new(),
                rows_w,
                rows_h,
                to_t,
                from_t,
            }),
        })
    }

    /// Uploads one multiplier per channel in the CPU [`SpectralPlan`] layout (`[Wc, Hc]`, e.g.
    /// [`crate::optics::TransferFunction::values`]).
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for a wrong count or length; [`HoloError::Gpu`].
    pub(crate) fn multiplier(
        &self,
        ctx: &GpuContext,
        per_channel: &[&[Complex32]],
    ) -> Result<GpuMultiplier> {
        self.check_multipliers(per_channel)?;
        let flat: Vec<[f32; 2]> = per_channel
            .iter()
            .flat_map(|m| m.iter().map(|v| [v.re, v.im]))
            .collect();
        Ok(GpuMultiplier {
            buffer: ctx.storage_with("spectral multiplier", &flat)?,
        })
    }

    /// Rewrites `target` (uploaded by [`GpuSpectralPlan::multiplier`] for this plan) with new multipliers of
    /// the same layout, in place: no new GPU buffer, and operations bound to it use the new values from their
    /// next recording (e.g. a viewer's prescription slider).
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for a wrong count or length.
    pub(crate) fn rewrite(
        &self,
        ctx: &GpuContext,
        target: &GpuMultiplier,
        per_channel: &[&[Complex32]],
    ) -> Result<()> {
        self.check_multipliers(per_channel)?;
        for (c, m) in per_channel.iter().enumerate() {
            let offset = (c * m.len() * std::mem::size_of::<Complex32>()) as u64;
            ctx.queue()
                .write_buffer(&target.buffer, offset, bytemuck::cast_slice(m));
        }
        Ok(())
    }

    fn check_multipliers(&self, per_channel: &[&[Complex32]]) -> Result<()> {
        let p = &*self.inner;
        let (hc, wc) = p.comp;
        if per_channel.len() != p.channels || per_channel.iter().any(|m| m.len() != hc * wc) {
            return Err(HoloError::ShapeMismatch {
                what: "spectral multipliers vs the plan's [C, Wc·Hc]".into(),
                expected: vec![p.channels, wc * hc],
                got: per_channel.iter().map(|m| m.len()).collect(),
            });
        }
        Ok(())
    }

    /// Uploads the angular-spectrum transfer functions (Eq. 2, with `carrier`) of `props` (one propagator per
    /// channel, planned like this plan) for `distance_m` metres: [`crate::optics::Propagator::transfer_function`]
    /// computed on the CPU, then [`GpuSpectralPlan::multiplier`].
    ///
    /// Errors: as [`crate::optics::Propagator::transfer_function`] and [`GpuSpectralPlan::multiplier`].
    pub(crate) fn transfer_functions(
        &self,
        ctx: &GpuContext,
        props: &[crate::optics::Propagator],
        distance_m: f64,
        carrier: crate::optics::Carrier,
    ) -> Result<GpuMultiplier> {
        let tfs = props
            .iter()
            .map(|p| p.transfer_function(distance_m, carrier))
            .collect::<Result<Vec<_>>>()?;
        let values: Vec<&[Complex32]> = tfs.iter().map(|t| t.values()).collect();
        self.multiplier(ctx, &values)
    }

    /// Binds an operation `field ← F⁻¹{F{field}·M}` on `field` (complex `[C, H, W]`) with `multiplier`.
    ///
    /// Errors: [`HoloError::Gpu`].
    pub(crate) fn bind(
        &self,
        ctx: &GpuContext,
        field: &wgpu::Buffer,
        multiplier: &GpuMultiplier,
    ) -> Result<GpuSpectralOp> {
        self.bind_chain(ctx, field, &[multiplier])
    }

    /// Binds `field ← F⁻¹{F{field}·M₁·M₂·…}` on `field` (complex `[C, H, W]`): one forward and one inverse
    /// transform, and one multiply pass per multiplier (e.g. the offset's transfer function, then the viewer's
    /// aberration correction kernel, paper Eq. 5–6). A multiplier rewritten with [`GpuMultiplier::write`]
    /// takes effect at the next recording, without rebinding.
    ///
    /// Errors: [`HoloError::InvalidParameter`] for no multiplier; [`HoloError::Gpu`].
    pub(crate) fn bind_chain(
        &self,
        ctx: &GpuContext,
        field: &wgpu::Buffer,
        multipliers: &[&GpuMultiplier],
    ) -> Result<GpuSpectralOp> {
        if multipliers.is_empty() {
            return Err(invalid(
                "multipliers",
                "a spectral operation needs ≥ 1 multiplier",
            ));
        }
        let p = &*self.inner;
        Ok(GpuSpectralOp {
            plan: Arc::clone(&self.inner),
            embed: ctx.bind(&p.embed_kernel, &[&p.grid, field, &p.a]),
            multiply: multipliers
                .iter()
                .map(|m| {
                    [
                        ctx.bind(&p.multiply_kernel, &[&p.grid, &p.a, &m.buffer]),
                        ctx.bind(&p.multiply_kernel, &[&p.grid, &p.b, &m.buffer]),
                    ]
                })
                .collect(),
            crop: p.crop_binds(ctx, field),
        })
    }

    /// A buffer for one spectrum of this plan (`[C, Wc, Hc]` complex, [`GpuSpectralPlan::bind_forward`],
    /// [`GpuSpectralPlan::bind_inverse`]).
    ///
    /// Errors: [`HoloError::Gpu`] beyond the device's limits.
    pub(crate) fn spectrum(&self, ctx: &GpuContext, label: &str) -> Result<wgpu::Buffer> {
        ctx.storage(label, self.inner.a.size())
    }

    /// Binds `spectrum ← F{field}` (field complex `[C, H, W]`, embedded as [`GpuSpectralPlan::bind`] does).
    pub(crate) fn bind_forward(
        &self,
        ctx: &GpuContext,
        field: &wgpu::Buffer,
        spectrum: &wgpu::Buffer,
    ) -> GpuForwardOp {
        let p = &*self.inner;
        GpuForwardOp {
            plan: Arc::clone(&self.inner),
            embed: ctx.bind(&p.embed_kernel, &[&p.grid, field, &p.a]),
            sink: ForwardSink::Copy(spectrum.clone()),
        }
    }

    /// Binds `sum ← sum + conj(M)·F{field}` (`sum` a [`GpuSpectralPlan::spectrum`] buffer): the adjoint of
    /// [`GpuSpectralPlan::bind_inverse`] with `M`, added up in the spectrum (e.g. the refinement's
    /// `Σ_d A_d^H V_d`, one inverse transform for all planes).
    ///
    /// Errors: [`HoloError::Gpu`] if its kernel does not compile.
    pub(crate) fn bind_forward_conj_add(
        &self,
        ctx: &GpuContext,
        field: &wgpu::Buffer,
        multiplier: &GpuMultiplier,
        sum: &wgpu::Buffer,
    ) -> Result<GpuForwardOp> {
        let p = &*self.inner;
        if p.multiply_conj_add_kernel.get().is_none() {
            let kernel = ctx.kernel(&shaders::SPECTRAL, "multiply_conj_add")?;
            let _ = p.multiply_conj_add_kernel.set(kernel);
        }
        let kernel = p
            .multiply_conj_add_kernel
            .get()
            .ok_or_else(|| HoloError::Internal("conjugate multiply-add kernel not made".into()))?;
        Ok(GpuForwardOp {
            plan: Arc::clone(&self.inner),
            embed: ctx.bind(&p.embed_kernel, &[&p.grid, field, &p.a]),
            sink: ForwardSink::ConjAdd([
                ctx.bind(kernel, &[&p.grid, &p.a, &multiplier.buffer, sum]),
                ctx.bind(kernel, &[&p.grid, &p.b, &multiplier.buffer, sum]),
            ]),
        })
    }

    /// Binds `field ← F⁻¹{spectrum·M}` (`spectrum` a [`GpuSpectralPlan::spectrum`] buffer, kept; without a
    /// multiplier `F⁻¹{spectrum}`, the inverse normalisation then being the caller's).
    pub(crate) fn bind_inverse(
        &self,
        ctx: &GpuContext,
        spectrum: &wgpu::Buffer,
        multiplier: Option<&GpuMultiplier>,
        field: &wgpu::Buffer,
    ) -> GpuInverseOp {
        let p = &*self.inner;
        GpuInverseOp {
            plan: Arc::clone(&self.inner),
            spectrum: spectrum.clone(),
            multiply: multiplier.map(|m| ctx.bind(&p.multiply_kernel, &[&p.grid, &p.a, &m.buffer])),
            crop: p.crop_binds(ctx, field),
        }
    }
}

impl PlanInner {
    /// `crop` from either scratch buffer into `field`.
    fn crop_binds(&self, ctx: &GpuContext, field: &wgpu::Buffer) -> [wgpu::BindGroup; 2] {
        [
            ctx.bind(&self.crop_kernel, &[&self.grid, field, &self.a]),
            ctx.bind(&self.crop_kernel, &[&self.grid, field, &self.b]),
        ]
    }

    /// The scratch buffer `b` (`in_b`) or `a`.
    fn scratch(&self, in_b: bool) -> &wgpu::Buffer {
        if in_b {
            &self.b
        } else {
            &self.a
        }
    }

    fn elements(&self) -> usize {
        self.channels * self.comp.0 * self.comp.1
    }

    /// Records the forward 2D FFT of the grid in `b` (`in_b`) or `a`: along rows → transpose → along
    /// columns, leaving the transposed spectrum `[C, Wc, Hc]`; returns where it is.
    fn record_forward(&self, pass: &mut wgpu::ComputePass<'_>, in_b: bool) -> bool {
        let (hc, wc) = self.comp;
        let in_b = self.rows_w.record(pass, &self.pass_kernel, false, in_b);
        self.transpose_kernel.dispatch(
            pass,
            &self.to_t[usize::from(in_b)],
            grid_2d(wc, hc, self.channels, [16, 16]),
        );
        self.rows_h.record(pass, &self.pass_kernel, false, !in_b)
    }

    /// Records the inverse of [`PlanInner::record_forward`] (unnormalised) on the spectrum in `b` (`in_b`) or
    /// `a`; returns where the grid is.
    fn record_inverse(&self, pass: &mut wgpu::ComputePass<'_>, in_b: bool) -> bool {
        let (hc, wc) = self.comp;
        let in_b = self.rows_h.record(pass, &self.pass_kernel, true, in_b);
        self.transpose_kernel.dispatch(
            pass,
            &self.from_t[usize::from(in_b)],
            grid_2d(hc, wc, self.channels, [16, 16]),
        );
        self.rows_w.record(pass, &self.pass_kernel, true, !in_b)
    }

    fn crop(&self, pass: &mut wgpu::ComputePass<'_>, binds: &[wgpu::BindGroup; 2], in_b: bool) {
        self.crop_kernel.dispatch(
            pass,
            &binds[usize::from(in_b)],
            grid_1d(self.channels * self.height * self.width),
        );
    }
}

fn begin<'e>(encoder: &'e mut wgpu::CommandEncoder, label: &str) -> wgpu::ComputePass<'e> {
    encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some(label),
        timestamp_writes: None,
    })
}

impl GpuSpectralOp {
    /// Records `field ← F⁻¹{F{field}·M}` into `encoder`: embed (zero padding) → FFT along rows → transpose →
    /// FFT along columns → multiply → inverse along columns → transpose back → inverse along rows → crop.
    pub(crate) fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        let p = &*self.plan;
        let mut pass = begin(encoder, "spectral op");
        let n = p.elements();
        p.embed_kernel.dispatch(&mut pass, &self.embed, grid_1d(n));
        let in_b = p.record_forward(&mut pass, false);
        for multiply in &self.multiply {
            p.multiply_kernel
                .dispatch(&mut pass, &multiply[usize::from(in_b)], grid_1d(n));
        }
        let in_b = p.record_inverse(&mut pass, in_b);
        p.crop(&mut pass, &self.crop, in_b);
    }

    /// Work and traffic per [`GpuSpectralOp::record`].
    pub(crate) fn cost(&self) -> StageCost {
        let p = &*self.plan;
        let (hc, wc) = p.comp;
        let n = (p.channels * hc * wc) as f64;
        let multiplies = self.multiply.len() as f64;
        let flops = 2.0 * (p.rows_w.flops() + p.rows_h.flops()) + 6.0 * n * multiplies;
        // Every FFT pass and transpose reads and writes the grid once (8 B per complex value each way);
        // embed writes it, each multiply reads it, its multiplier and writes it, crop reads the field's part.
        let passes = 2 * (p.rows_w.passes() + p.rows_h.passes()) + 2;
        let field = (p.channels * p.height * p.width) as f64;
        let bytes =
            16.0 * n * passes as f64 + 8.0 * n + 24.0 * n * multiplies + 16.0 * field + 8.0 * field;
        StageCost { flops, bytes }
    }
}

impl GpuForwardOp {
    /// Records the transform: embed → forward FFT → copy into the spectrum buffer, or the conjugate
    /// multiply-add into the sum.
    pub(crate) fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        let p = &*self.plan;
        let n = p.elements();
        let in_b = {
            let mut pass = begin(encoder, "forward transform");
            p.embed_kernel.dispatch(&mut pass, &self.embed, grid_1d(n));
            let in_b = p.record_forward(&mut pass, false);
            if let (ForwardSink::ConjAdd(binds), Some(kernel)) =
                (&self.sink, p.multiply_conj_add_kernel.get())
            {
                kernel.dispatch(&mut pass, &binds[usize::from(in_b)], grid_1d(n));
            }
            in_b
        };
        if let ForwardSink::Copy(spectrum) = &self.sink {
            encoder.copy_buffer_to_buffer(p.scratch(in_b), 0, spectrum, 0, spectrum.size());
        }
    }
}

impl GpuInverseOp {
    /// Records the transform: the spectrum copied into the plan's scratch → multiply → inverse FFT → crop.
    pub(crate) fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        let p = &*self.plan;
        encoder.copy_buffer_to_buffer(&self.spectrum, 0, &p.a, 0, self.spectrum.size());
        let mut pass = begin(encoder, "inverse transform");
        if let Some(bind) = &self.multiply {
            p.multiply_kernel
                .dispatch(&mut pass, bind, grid_1d(p.elements()));
        }
        let in_b = p.record_inverse(&mut pass, false);
        p.crop(&mut pass, &self.crop, in_b);
    }
}

/// The uniform structs of this module beside their WGSL twins (checked in `shader_tests`).
#[cfg(test)]
pub(super) fn uniform_layouts() -> Vec<super::shader_tests::UniformLayout> {
    use super::shader_tests::uniform_layout;
    use super::shaders::{FFT, SPECTRAL};
    vec![
        uniform_layout!(
            &FFT,
            "Pass",
            PassParams {
                n,
                rows,
                ns,
                radix,
                twiddle_stride,
                sign
            }
        ),
        uniform_layout!(&FFT, "Shape", ShapeParams { rows, cols, planes }),
        uniform_layout!(
            &SPECTRAL,
            "Grid",
            GridParams {
                h,
                w,
                hc,
                wc,
                oy,
                ox,
                channels
            }
        ),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_support::context as test_context;
    use crate::optics::{Carrier, OpticalSetup, Padding, PropagationOptions};

    /// Seeded complex noise in [−1, 1]².
    fn noise(n: usize, seed: u64) -> Vec<Complex32> {
        let mut s = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        };
        (0..n).map(|_| Complex32::new(next(), next())).collect()
    }

    fn upload(ctx: &GpuContext, v: &[Complex32]) -> wgpu::Buffer {
        let flat: Vec<[f32; 2]> = v.iter().map(|c| [c.re, c.im]).collect();
        ctx.storage_with("field", &flat).unwrap()
    }

    fn download(ctx: &GpuContext, b: &wgpu::Buffer, n: usize) -> Vec<Complex32> {
        let v: Vec<[f32; 2]> = ctx.read_buffer(b, n).unwrap();
        v.into_iter()
            .map(|[re, im]| Complex32::new(re, im))
            .collect()
    }

    /// max |a − b| / max |b|.
    fn rel(a: &[Complex32], b: &[Complex32]) -> f32 {
        let scale = b.iter().fold(0.0f32, |m, v| m.max(v.norm()));
        a.iter()
            .zip(b)
            .fold(0.0f32, |m, (x, y)| m.max((x - y).norm()))
            / scale
    }

    /// Runs `GpuSpectralOp` on three channels with the given per-channel multipliers.
    fn gpu_apply(
        ctx: &GpuContext,
        plan: &SpectralPlan,
        fields: &[Complex32],
        mult: &[&[Complex32]],
    ) -> Vec<Complex32> {
        let c = mult.len();
        let gp = GpuSpectralPlan::new(ctx, plan, c).unwrap();
        let m = gp.multiplier(ctx, mult).unwrap();
        let buf = upload(ctx, fields);
        let op = gp.bind(ctx, &buf, &m).unwrap();
        let before = ctx.resource_counts();
        let mut enc = ctx.encoder("test");
        op.record(&mut enc);
        ctx.submit_and_wait(enc).unwrap();
        assert_eq!(ctx.resource_counts(), before, "record created GPU objects");
        download(ctx, &buf, fields.len())
    }

    #[test]
    fn radices_cover_the_display_sizes_and_refuse_large_primes() {
        for n in [384, 540, 960, 1080, 1920, 3840, 768, 2160, 1, 7, 49, 13] {
            let r = radices(n).unwrap();
            assert_eq!(r.iter().product::<usize>(), n, "{n}: {r:?}");
        }
        let err = radices(2 * 17 * 19).unwrap_err().to_string();
        assert!(err.contains("646 = 2·17·19"), "{err}");
    }

    #[test]
    fn angular_spectrum_propagation_matches_the_cpu() {
        let Some(ctx) = test_context() else { return };
        let setup = OpticalSetup::default();
        for (h, w) in [(48, 64), (30, 40), (96, 60), (45, 75), (22, 26)] {
            for pad in [false, true] {
                let options = PropagationOptions {
                    pad,
                    band_limit: true,
                };
                let props = setup.propagators(h, w, options).unwrap();
                let tfs: Vec<_> = props
                    .iter()
                    .map(|p| p.transfer_function(6e-3, Carrier::Remove).unwrap())
                    .collect();
                let mults: Vec<&[Complex32]> = tfs.iter().map(|t| t.values()).collect();
                let fields = noise(3 * h * w, (h * w) as u64);
                let gpu = gpu_apply(&ctx, props[0].plan(), &fields, &mults);
                let mut cpu = fields.clone();
                for (c, prop) in props.iter().enumerate() {
                    let mut scratch = prop.plan().scratch();
                    prop.plan()
                        .apply(&mut cpu[c * h * w..(c + 1) * h * w], mults[c], &mut scratch)
                        .unwrap();
                }
                let e = rel(&gpu, &cpu);
                println!("{h}×{w} pad {pad}: max rel Δ {e:.2e}");
                assert!(e < 1e-5, "{h}×{w} pad {pad}: {e}");
            }
        }
    }

    #[test]
    fn a_plane_wave_lands_in_one_bin_and_the_identity_round_trips() {
        let Some(ctx) = test_context() else { return };
        let (h, w) = (24, 30);
        let plan = SpectralPlan::new(h, w, Padding::None).unwrap();
        // Multiplier: 1/N at one bin (kx = 3, ky = 2), zero elsewhere: a plane wave of that frequency passes
        // unchanged, any other frequency vanishes.
        let n = h * w;
        let mut only = vec![Complex32::new(0.0, 0.0); n];
        only[3 * h + 2] = Complex32::new(1.0 / n as f32, 0.0);
        let wave: Vec<Complex32> = (0..n)
            .map(|i| {
                let (y, x) = ((i / w) as f32, (i % w) as f32);
                let a = std::f32::consts::TAU * (3.0 * x / w as f32 + 2.0 * y / h as f32);
                Complex32::new(a.cos(), a.sin())
            })
            .collect();
        let out = gpu_apply(&ctx, &plan, &wave, &[&only]);
        assert!(rel(&out, &wave) < 1e-5, "{}", rel(&out, &wave));
        let other: Vec<Complex32> = wave.iter().map(|v| v * v).collect(); // frequency (6, 4)
        let out = gpu_apply(&ctx, &plan, &other, &[&only]);
        assert!(
            out.iter().all(|v| v.norm() < 1e-5),
            "a foreign frequency leaked"
        );
        // Identity (1/N everywhere) returns random input.
        let ident = vec![Complex32::new(1.0 / n as f32, 0.0); n];
        let x = noise(n, 7);
        assert!(rel(&gpu_apply(&ctx, &plan, &x, &[&ident]), &x) < 1e-5);
    }

    #[test]
    fn propagating_there_and_back_returns_the_field_and_keeps_its_energy() {
        let Some(ctx) = test_context() else { return };
        let (h, w) = (40, 48);
        let options = PropagationOptions {
            pad: false,
            band_limit: false,
        };
        let props = OpticalSetup::default().propagators(h, w, options).unwrap();
        let prop = &props[1];
        let fwd = prop.transfer_function(3e-3, Carrier::Keep).unwrap();
        let back = prop.transfer_function(-3e-3, Carrier::Keep).unwrap();
        let x = noise(h * w, 11);
        let y = gpu_apply(&ctx, prop.plan(), &x, &[fwd.values()]);
        let energy = |v: &[Complex32]| v.iter().map(|c| c.norm_sqr() as f64).sum::<f64>();
        // At 8 µm pitch and 520 nm no component is evanescent: the transfer function is a pure phase.
        let ratio = energy(&y) / energy(&x);
        assert!((ratio - 1.0).abs() < 1e-5, "energy ratio {ratio}");
        let z = gpu_apply(&ctx, prop.plan(), &y, &[back.values()]);
        assert!(rel(&z, &x) < 1e-4, "{}", rel(&z, &x));
    }

    #[test]
    fn unsupported_sizes_and_wrong_multipliers_are_refused() {
        let Some(ctx) = test_context() else { return };
        let plan = SpectralPlan::new(17 * 2, 8, Padding::None).unwrap();
        let err = GpuSpectralPlan::new(&ctx, &plan, 3).unwrap_err();
        assert!(err.to_string().contains("34 = 2·17"), "{err}");
        let plan = SpectralPlan::new(8, 8, Padding::None).unwrap();
        let gp = GpuSpectralPlan::new(&ctx, &plan, 3).unwrap();
        let m = vec![Complex32::new(1.0, 0.0); 64];
        assert!(gp.multiplier(&ctx, &[&m, &m]).is_err());
        assert!(gp.multiplier(&ctx, &[&m, &m, &m[..63]]).is_err());
    }

    #[test]
    fn full_hd_propagation_matches_the_cpu() {
        let Some(ctx) = test_context() else { return };
        let (h, w) = (1080, 1920);
        let options = PropagationOptions::default();
        let props = OpticalSetup::default().propagators(h, w, options).unwrap();
        let tf = props[0].transfer_function(6e-3, Carrier::Remove).unwrap();
        let x = noise(h * w, 3);
        let gpu = gpu_apply(&ctx, props[0].plan(), &x, &[tf.values()]);
        let mut cpu = x.clone();
        props[0]
            .plan()
            .apply(&mut cpu, tf.values(), &mut props[0].plan().scratch())
            .unwrap();
        let e = rel(&gpu, &cpu);
        println!("1080×1920: max rel Δ {e:.2e}");
        assert!(e < 1e-5, "{e}");
    }
}

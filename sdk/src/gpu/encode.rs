//! Field conversions, the AA-DPM blur, double phase encoding (Eq. 7) and the linear look-up table on the GPU:
//! the counterparts of [`crate::model::contract::head_to_phasor`], the pre-filter CNN's `[Re H, Im H]` planes
//! and [`crate::encoding::ChannelEncoder`] (`shaders/field.wgsl`, `blur.wgsl`, `double_phase.wgsl`). Each
//! type is built once with the buffers it reads and writes, and records its dispatches per frame.

use super::context::GpuContext;
use super::kernel::{grid_1d, Kernel};
use super::shaders;
use crate::encoding::DoublePhaseMethod;
use crate::error::{invalid, HoloError, Result};

/// Colour channels of every field (R, G, B).
const CHANNELS: usize = 3;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct PlaneParams {
    n: u32,
    channels: u32,
    _pad: [u32; 2],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct BlurParams {
    h: u32,
    w: u32,
    channels: u32,
    taps: u32,
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct DpParams {
    h: u32,
    w: u32,
    channels: u32,
    groups_per_channel: u32,
}

fn pixels(height: usize, width: usize) -> Result<usize> {
    height
        .checked_mul(width)
        .filter(|&n| n > 0 && n.checked_mul(2 * CHANNELS * 4).is_some())
        .filter(|&n| u32::try_from(n * CHANNELS).is_ok())
        .ok_or_else(|| invalid("size", format!("{height}×{width} is empty or too large")))
}

/// One element-wise kernel of `field.wgsl` bound to a planes buffer `[6, H, W]` and a field `[3, H, W]`.
#[derive(Debug)]
struct PlaneKernel {
    kernel: Kernel,
    bind: wgpu::BindGroup,
    n: usize,
}

impl PlaneKernel {
    fn new(
        ctx: &GpuContext,
        entry: &'static str,
        height: usize,
        width: usize,
        planes: &wgpu::Buffer,
        field: &wgpu::Buffer,
    ) -> Result<Self> {
        let n = pixels(height, width)?;
        let kernel = ctx.kernel(&shaders::FIELD, entry)?;
        let params = ctx.uniform(
            entry,
            &PlaneParams {
                n: n as u32,
                channels: CHANNELS as u32,
                _pad: [0; 2],
            },
        )?;
        let bind = ctx.bind(&kernel, &[&params, planes, field]);
        Ok(Self { kernel, bind, n })
    }

    fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        self.kernel
            .dispatch(&mut pass, &self.bind, grid_1d(CHANNELS * self.n));
    }

    /// (flops, bytes) per frame: `per_pixel_flops` and 16 bytes (two f32 planes + one complex) per element.
    fn cost(&self, per_pixel_flops: f64) -> (f64, f64) {
        let e = (CHANNELS * self.n) as f64;
        (per_pixel_flops * e, 16.0 * e)
    }
}

/// The hologram CNN's heads `[6, H, W]` (amplitude R, G, B, phase R, G, B) → the complex midpoint hologram
/// `[3, H, W]`: `A·e^{i(p − 0.5)2π}` ([`crate::model::contract::head_to_phasor`], `docs/CONVENTIONS.md` §7.1).
#[derive(Debug)]
pub struct GpuHeadsToField(PlaneKernel);

impl GpuHeadsToField {
    /// Binds `heads` (f32 `[6, H, W]`) and `field` (complex `[3, H, W]`).
    ///
    /// Errors: [`HoloError::InvalidParameter`] for an empty or oversized frame; [`HoloError::Gpu`].
    pub(crate) fn new(
        ctx: &GpuContext,
        height: usize,
        width: usize,
        heads: &wgpu::Buffer,
        field: &wgpu::Buffer,
    ) -> Result<Self> {
        PlaneKernel::new(ctx, "heads_to_field", height, width, heads, field).map(Self)
    }

    /// Records the conversion.
    pub(crate) fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        self.0.record(encoder)
    }

    /// (flops, bytes) per frame (sin and cos counted as 10 flops each).
    pub(crate) fn cost(&self) -> (f64, f64) {
        self.0.cost(24.0)
    }
}

/// The complex field `[3, H, W]` → the pre-filter CNN's input planes `[6, H, W]` = `[Re R, G, B, Im R, G, B]`
/// (`docs/CONVENTIONS.md` §7.2, format 2).
#[derive(Debug)]
pub struct GpuFieldToPlanes(PlaneKernel);

impl GpuFieldToPlanes {
    /// Binds `field` (complex `[3, H, W]`) and `planes` (f32 `[6, H, W]`).
    ///
    /// Errors: as [`GpuHeadsToField::new`].
    pub(crate) fn new(
        ctx: &GpuContext,
        height: usize,
        width: usize,
        field: &wgpu::Buffer,
        planes: &wgpu::Buffer,
    ) -> Result<Self> {
        PlaneKernel::new(ctx, "field_to_planes", height, width, planes, field).map(Self)
    }

    /// Records the conversion.
    pub(crate) fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        self.0.record(encoder)
    }

    /// (flops, bytes) per frame.
    pub(crate) fn cost(&self) -> (f64, f64) {
        self.0.cost(0.0)
    }
}

/// The pre-filter CNN's output planes `[6, H, W]` (`[Re, Im]`) → the complex field `[3, H, W]`.
#[derive(Debug)]
pub struct GpuPlanesToField(PlaneKernel);

impl GpuPlanesToField {
    /// Binds `planes` (f32 `[6, H, W]`) and `field` (complex `[3, H, W]`).
    ///
    /// Errors: as [`GpuHeadsToField::new`].
    pub(crate) fn new(
        ctx: &GpuContext,
        height: usize,
        width: usize,
        planes: &wgpu::Buffer,
        field: &wgpu::Buffer,
    ) -> Result<Self> {
        PlaneKernel::new(ctx, "planes_to_field", height, width, planes, field).map(Self)
    }

    /// Records the conversion.
    pub(crate) fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        self.0.record(encoder)
    }

    /// (flops, bytes) per frame.
    pub(crate) fn cost(&self) -> (f64, f64) {
        self.0.cost(0.0)
    }
}

/// The AA-DPM blur: rows then columns through a scratch buffer.
#[derive(Debug)]
struct Blur {
    rows: Kernel,
    cols: Kernel,
    bind_rows: wgpu::BindGroup,
    bind_cols: wgpu::BindGroup,
    elements: usize,
    taps: usize,
}

/// Size of the statistics buffer of [`GpuDoublePhase`]: 8 f32 (see [`GpuDoublePhase::read_stats`]).
pub const STATS_BYTES: u64 = 32;

/// Double phase encoding (Eq. 7) with the AA-DPM pre-filter where asked, and the linear look-up table, on a
/// complex field `[3, H, W]`, all on the GPU: the counterpart of [`crate::encoding::ChannelEncoder`] for the
/// three colours (same global normaliser and per-channel mean phase, same checkerboard and wrapping).
#[derive(Debug)]
pub struct GpuDoublePhase {
    height: usize,
    width: usize,
    blur: Option<Blur>,
    groups: usize,
    analyse: Kernel,
    finish: Kernel,
    encode: Kernel,
    /// One bind group per entry point (auto-derived layouts differ by the bindings each one uses).
    binds: [wgpu::BindGroup; 3],
    phase: wgpu::Buffer,
    stats: wgpu::Buffer,
    codes: wgpu::Buffer,
    /// The normaliser given from outside (`double_phase.wgsl` binding 6; 0: the field's own) and its value.
    fixed: wgpu::Buffer,
    fixed_value: f32,
}

impl GpuDoublePhase {
    /// Prepares the encoding of `field` (complex `[3, H, W]`, blurred in place for AA-DPM) with `method`.
    ///
    /// Errors: [`HoloError::InvalidParameter`] for [`DoublePhaseMethod::BandLimited`] (the GPU path covers plain
    /// double phase, used after the pre-filter CNN, and AA-DPM) or an empty/oversized frame;
    /// [`HoloError::Gpu`].
    pub(crate) fn new(
        ctx: &GpuContext,
        height: usize,
        width: usize,
        method: &DoublePhaseMethod,
        field: &wgpu::Buffer,
    ) -> Result<Self> {
        let n = pixels(height, width)?;
        let elements = CHANNELS * n;
        let blur = match method {
            DoublePhaseMethod::Plain => None,
            DoublePhaseMethod::AntiAliased { .. } => {
                let taps = method.kernel();
                let weights = ctx.storage_with("aa-dpm taps", &taps)?;
                let scratch = ctx.storage("aa-dpm scratch", (elements * 8) as u64)?;
                let params = ctx.uniform(
                    "aa-dpm",
                    &BlurParams {
                        h: height as u32,
                        w: width as u32,
                        channels: CHANNELS as u32,
                        taps: taps.len() as u32,
                    },
                )?;
                let rows = ctx.kernel(&shaders::BLUR, "blur_rows")?;
                let cols = ctx.kernel(&shaders::BLUR, "blur_cols")?;
                let bind_rows = ctx.bind(&rows, &[&params, field, &scratch, &weights]);
                let bind_cols = ctx.bind(&cols, &[&params, &scratch, field, &weights]);
                Some(Blur {
                    rows,
                    cols,
                    bind_rows,
                    bind_cols,
                    elements,
                    taps: taps.len(),
                })
            }
            DoublePhaseMethod::BandLimited { .. } => return Err(invalid(
                "encoding",
                "the GPU path encodes with plain double phase (after a pre-filter CNN) or AA-DPM; \
                     BL-DPM runs on the CPU backend",
            )),
        };
        // Enough workgroups per channel to fill a GPU, few enough for one `finish` workgroup to sum.
        let groups = n.div_ceil(256).clamp(1, 1024);
        let params = ctx.uniform(
            "double phase",
            &DpParams {
                h: height as u32,
                w: width as u32,
                channels: CHANNELS as u32,
                groups_per_channel: groups as u32,
            },
        )?;
        let phase = ctx.storage("double phase", (elements * 4) as u64)?;
        let partials = ctx.storage("double phase partials", (CHANNELS * groups * 8) as u64)?;
        let stats = ctx.storage("double phase stats", STATS_BYTES)?;
        let codes = ctx.storage("codes", elements.div_ceil(4) as u64 * 4)?;
        let fixed = ctx.storage("double phase fixed normaliser", 16)?;
        let analyse = ctx.kernel(&shaders::DOUBLE_PHASE, "analyse")?;
        let finish = ctx.kernel(&shaders::DOUBLE_PHASE, "finish")?;
        let encode = ctx.kernel(&shaders::DOUBLE_PHASE, "encode")?;
        let binds = [
            ctx.bind(&analyse, &[&params, field, &phase, &partials]),
            ctx.bind_at(
                &finish,
                &[(0, &params), (3, &partials), (4, &stats), (6, &fixed)],
            ),
            ctx.bind_at(
                &encode,
                &[
                    (0, &params),
                    (1, field),
                    (2, &phase),
                    (4, &stats),
                    (5, &codes),
                ],
            ),
        ];
        Ok(Self {
            height,
            width,
            blur,
            groups,
            analyse,
            finish,
            encode,
            binds,
            phase,
            stats,
            codes,
            fixed,
            fixed_value: 0.0,
        })
    }

    /// Sets the global normaliser `a` of the next frames: `Some(a)` (`a > 0`: a foveated frame's,
    /// [`crate::foveation::FOVEATED_NORMALISER_GAIN`]` · max A`) instead of the field's largest `|H|`, or
    /// `None` for the field's own. Writes the device's copy only when the value changes (no allocation).
    pub(crate) fn set_normaliser(&mut self, ctx: &GpuContext, a: Option<f32>) {
        let value = a.filter(|a| *a > 0.0 && a.is_finite()).unwrap_or(0.0);
        if value.to_bits() != self.fixed_value.to_bits() {
            ctx.write(&self.fixed, 0, bytemuck::bytes_of(&value));
            self.fixed_value = value;
        }
    }

    /// Records blur (AA-DPM), pass 1, the normaliser and pass 2 with the look-up table.
    pub(crate) fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        if let Some(b) = &self.blur {
            b.rows
                .dispatch(&mut pass, &b.bind_rows, grid_1d(b.elements));
            b.cols
                .dispatch(&mut pass, &b.bind_cols, grid_1d(b.elements));
        }
        self.analyse.dispatch(
            &mut pass,
            &self.binds[0],
            [self.groups as u32, CHANNELS as u32, 1],
        );
        self.finish.dispatch(&mut pass, &self.binds[1], [1, 1, 1]);
        let words = (CHANNELS * self.height * self.width).div_ceil(4);
        self.encode
            .dispatch(&mut pass, &self.binds[2], grid_1d(words));
    }

    /// The wrapped double phase pattern, f32 `[3, H, W]` in `[0, 2π)` after a frame.
    pub(crate) fn phase_buffer(&self) -> &wgpu::Buffer {
        &self.phase
    }

    /// The 8-bit codes, four per `u32` little-endian (`[3, H, W]` order), `ceil(3·H·W / 4)` words.
    pub(crate) fn codes_buffer(&self) -> &wgpu::Buffer {
        &self.codes
    }

    /// The statistics (8 f32, [`GpuDoublePhase::read_stats`]).
    pub(crate) fn stats_buffer(&self) -> &wgpu::Buffer {
        &self.stats
    }

    /// Bytes of [`GpuDoublePhase::stats_buffer`].
    pub(crate) fn stats_bytes(&self) -> u64 {
        STATS_BYTES
    }

    /// The normaliser `a` and the three mean phases (radians) from the statistics' bytes: `[a, mean_r,
    /// mean_g, mean_b, max|H|²_r, max|H|²_g, max|H|²_b, invalid]` as little-endian f32.
    ///
    /// Errors: [`HoloError::InvalidData`] (as [`crate::encoding::normaliser`]) if the hologram is zero
    /// everywhere or not finite; [`HoloError::Internal`] for a wrong length.
    pub(crate) fn read_stats(bytes: &[u8]) -> Result<(f32, [f32; 3])> {
        if bytes.len() != STATS_BYTES as usize {
            return Err(HoloError::Internal(format!(
                "double phase statistics: {} bytes, expected {STATS_BYTES}",
                bytes.len()
            )));
        }
        let mut v = [0.0f32; STATS_BYTES as usize / 4];
        for (x, c) in v.iter_mut().zip(bytes.chunks_exact(4)) {
            *x = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
        }
        let a = v[0];
        if v[7] != 0.0 || !(a > 0.0 && a.is_finite()) || v[1..4].iter().any(|m| !m.is_finite()) {
            return Err(HoloError::InvalidData(
                "hologram amplitude is zero everywhere: nothing to encode".into(),
            ));
        }
        Ok((a, [v[1], v[2], v[3]]))
    }

    /// (flops, bytes) per frame: atan2 ≈ 20 flops, acos ≈ 15, blur 4 flops per tap and pass per complex value.
    pub(crate) fn cost(&self) -> (f64, f64) {
        let e = (CHANNELS * self.height * self.width) as f64;
        let (mut flops, mut bytes) = (
            e * 24.0 + e * 30.0,
            e * (8.0 + 4.0) + e * (8.0 + 4.0 + 4.0 + 1.0),
        );
        if let Some(b) = &self.blur {
            flops += 2.0 * 4.0 * b.taps as f64 * e;
            bytes += 2.0 * 16.0 * e;
        }
        (flops, bytes)
    }
}

/// The uniform structs of this module beside their WGSL twins (checked in `shader_tests`).
#[cfg(test)]
pub(super) fn uniform_layouts() -> Vec<super::shader_tests::UniformLayout> {
    use super::shader_tests::uniform_layout;
    use super::shaders::{BLUR, DOUBLE_PHASE, FIELD};
    vec![
        uniform_layout!(&FIELD, "Planes", PlaneParams { n, channels }),
        uniform_layout!(
            &BLUR,
            "Blur",
            BlurParams {
                h,
                w,
                channels,
                taps
            }
        ),
        uniform_layout!(
            &DOUBLE_PHASE,
            "Dims",
            DpParams {
                h,
                w,
                channels,
                groups_per_channel
            }
        ),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::encoding::{normaliser, ChannelEncoder, ChannelStats};
    use crate::gpu::test_support::{context as test_context, uniform as lcg};
    use crate::model::contract::head_to_phasor;
    use num_complex::Complex32;

    /// A smooth field with a random speckle on top, `[3, H, W]`.
    fn field(h: usize, w: usize, seed: u64) -> Vec<Complex32> {
        let mut r = lcg(seed);
        (0..3 * h * w)
            .map(|e| {
                let (c, i) = (e / (h * w), e % (h * w));
                let (y, x) = ((i / w) as f32, (i % w) as f32);
                let amp =
                    0.3 + 0.5 * ((x * 0.21 + c as f32).sin() * (y * 0.13).cos()).abs() + 0.2 * r();
                let ph = 2.0 * (x * 0.05 + y * 0.07 + c as f32) + 1.5 * r();
                Complex32::from_polar(amp, ph)
            })
            .collect()
    }

    fn upload_c(ctx: &GpuContext, v: &[Complex32]) -> wgpu::Buffer {
        let flat: Vec<[f32; 2]> = v.iter().map(|c| [c.re, c.im]).collect();
        ctx.storage_with("field", &flat).unwrap()
    }

    fn download_c(ctx: &GpuContext, b: &wgpu::Buffer, n: usize) -> Vec<Complex32> {
        let v: Vec<[f32; 2]> = ctx.read_buffer(b, n).unwrap();
        v.into_iter()
            .map(|[re, im]| Complex32::new(re, im))
            .collect()
    }

    fn run(ctx: &GpuContext, record: impl FnOnce(&mut wgpu::CommandEncoder)) {
        let mut enc = ctx.encoder("test");
        record(&mut enc);
        ctx.submit_and_wait(enc).unwrap();
    }

    fn cyclic(a: f32, b: f32) -> f32 {
        let d = (a - b).rem_euclid(std::f32::consts::TAU);
        d.min(std::f32::consts::TAU - d)
    }

    #[test]
    fn heads_become_the_field_and_planes_round_trip() {
        let Some(ctx) = test_context() else { return };
        let (h, w) = (45, 75);
        let n = h * w;
        let mut r = lcg(3);
        let heads: Vec<f32> = (0..6 * n)
            .map(|e| if e < 3 * n { 1.4 * r() } else { r() })
            .collect();
        let heads_buf = ctx.storage_with("heads", &heads).unwrap();
        let field = ctx.storage("field", (3 * n * 8) as u64).unwrap();
        let planes = ctx.storage("planes", (6 * n * 4) as u64).unwrap();
        let to_field = GpuHeadsToField::new(&ctx, h, w, &heads_buf, &field).unwrap();
        run(&ctx, |e| to_field.record(e));
        let got = download_c(&ctx, &field, 3 * n);
        for c in 0..3 {
            for i in 0..n {
                let want = head_to_phasor(heads[c * n + i], heads[(3 + c) * n + i]);
                assert!((got[c * n + i] - want).norm() < 1e-6, "{c} {i}");
            }
        }
        let to_planes = GpuFieldToPlanes::new(&ctx, h, w, &field, &planes).unwrap();
        let back = GpuPlanesToField::new(&ctx, h, w, &planes, &field).unwrap();
        let fresh = field_values(&ctx, &field, &planes, &to_planes, &back, 3 * n);
        assert_eq!(fresh.0, got, "field → planes → field must be exact");
        for (e, v) in got.iter().enumerate() {
            let (c, i) = (e / n, e % n);
            assert_eq!(fresh.1[c * n + i], v.re);
            assert_eq!(fresh.1[(3 + c) * n + i], v.im);
        }
    }

    fn field_values(
        ctx: &GpuContext,
        field: &wgpu::Buffer,
        planes: &wgpu::Buffer,
        to_planes: &GpuFieldToPlanes,
        back: &GpuPlanesToField,
        n3: usize,
    ) -> (Vec<Complex32>, Vec<f32>) {
        run(ctx, |e| to_planes.record(e));
        let p: Vec<f32> = ctx.read_buffer(planes, 2 * n3).unwrap();
        run(ctx, |e| back.record(e));
        (download_c(ctx, field, n3), p)
    }

    /// The CPU's three-channel encoding with `method`: (blurred field, phase, codes, a, mean).
    fn cpu_encode(
        field: &[Complex32],
        h: usize,
        w: usize,
        method: DoublePhaseMethod,
    ) -> (Vec<Complex32>, Vec<f32>, Vec<u8>, f32, [f32; 3]) {
        let n = h * w;
        let mut f = field.to_vec();
        let mut phase = vec![0.0; 3 * n];
        let mut codes = vec![0u8; 3 * n];
        let mut encs: Vec<ChannelEncoder> = (0..3)
            .map(|_| ChannelEncoder::new(h, w, method).unwrap())
            .collect();
        let mut stats = [ChannelStats::default(); 3];
        for c in 0..3 {
            stats[c] = encs[c]
                .analyse(&mut f[c * n..(c + 1) * n], &mut phase[c * n..(c + 1) * n])
                .unwrap();
        }
        let (a, mean) = normaliser(&stats, n).unwrap();
        for c in 0..3 {
            encs[c]
                .encode(
                    &f[c * n..(c + 1) * n],
                    &mut phase[c * n..(c + 1) * n],
                    &mut codes[c * n..(c + 1) * n],
                    mean[c],
                    a,
                )
                .unwrap();
        }
        (f, phase, codes, a, mean)
    }

    #[test]
    fn double_phase_and_lut_match_the_cpu() {
        let Some(ctx) = test_context() else { return };
        for (h, w) in [(48, 64), (45, 75), (270, 480)] {
            for method in [DoublePhaseMethod::Plain, DoublePhaseMethod::default()] {
                let n = h * w;
                let input = field(h, w, (h * 31 + w) as u64);
                let buf = upload_c(&ctx, &input);
                let dp = GpuDoublePhase::new(&ctx, h, w, &method, &buf).unwrap();
                let before = ctx.resource_counts();
                run(&ctx, |e| dp.record(e));
                assert_eq!(ctx.resource_counts(), before, "a frame created GPU objects");
                let (f, phase, codes, a, mean) = cpu_encode(&input, h, w, method);
                // The blurred field.
                let blurred = download_c(&ctx, &buf, 3 * n);
                let scale = f.iter().fold(0.0f32, |m, v| m.max(v.norm()));
                let blur_err = blurred
                    .iter()
                    .zip(&f)
                    .fold(0.0f32, |m, (x, y)| m.max((x - y).norm()))
                    / scale;
                assert!(blur_err < 1e-6, "{h}×{w} {method:?}: blur {blur_err}");
                let stats: Vec<u8> = ctx
                    .read_buffer(dp.stats_buffer(), STATS_BYTES as usize)
                    .unwrap();
                let (ga, gmean) = GpuDoublePhase::read_stats(&stats).unwrap();
                assert!((ga - a).abs() / a < 1e-6, "a {ga} vs {a}");
                for c in 0..3 {
                    assert!(
                        (gmean[c] - mean[c]).abs() < 1e-5,
                        "mean {c}: {} vs {}",
                        gmean[c],
                        mean[c]
                    );
                }
                let gphase: Vec<f32> = ctx.read_buffer(dp.phase_buffer(), 3 * n).unwrap();
                // GPU atan2/acos are less exact than the CPU's (Vulkan allows 4096 ULP; lavapipe measures ~1e-4
                // rad), and acos is ill-conditioned where |H| ≈ a (slope 1/√(1 − x²)). One code step is
                // 2π/256 = 0.0245 rad: bound the worst pixel at 2e-3 rad (8 % of a step), the mean at 1e-4.
                let deltas: Vec<f32> = gphase
                    .iter()
                    .zip(&phase)
                    .map(|(&x, &y)| cyclic(x, y))
                    .collect();
                let max_phase = deltas.iter().fold(0.0f32, |m, &d| m.max(d));
                let mean_phase =
                    deltas.iter().map(|&d| d as f64).sum::<f64>() / deltas.len() as f64;
                assert!(max_phase < 2e-3, "{h}×{w} {method:?}: phase {max_phase}");
                assert!(
                    mean_phase < 1e-4,
                    "{h}×{w} {method:?}: mean phase Δ {mean_phase}"
                );
                assert!(gphase
                    .iter()
                    .all(|p| (0.0..std::f32::consts::TAU).contains(p)));
                let words: Vec<u32> = ctx
                    .read_buffer(dp.codes_buffer(), (3 * n).div_ceil(4))
                    .unwrap();
                let gcodes: Vec<u8> = bytemuck::cast_slice(&words)[..3 * n].to_vec();
                // Codes may differ only where the CPU's value lies within that pixel's phase difference of a
                // tie (k + ½) of the 256-step table, and then by one step.
                let mut differ = 0;
                for (e, (&g, &c)) in gcodes.iter().zip(&codes).enumerate() {
                    if g != c {
                        let x = phase[e] * (256.0 / std::f32::consts::TAU);
                        let tie = (x - x.floor() - 0.5).abs();
                        let slack = deltas[e] * (256.0 / std::f32::consts::TAU) + 1e-3;
                        assert!(tie < slack, "code {e}: {g} vs {c} at {x} (not a tie)");
                        assert_eq!(g.wrapping_sub(c).min(c.wrapping_sub(g)), 1);
                        differ += 1;
                    }
                }
                println!(
                    "{h}×{w} {method:?}: a rel Δ {:.1e}, phase Δ max {max_phase:.1e} / mean {mean_phase:.1e} \
                     rad, blur rel Δ {blur_err:.1e}, codes differing at ties {differ} of {}",
                    (ga - a).abs() / a,
                    3 * n
                );
                assert!(differ as f64 <= 1e-2 * (3 * n) as f64);
            }
        }
    }

    /// A normaliser given from outside (a foveated frame's) replaces the field's own in the statistics and
    /// the pattern, as the CPU's `encode` with a fixed `a`; `None` restores the field's own.
    #[test]
    fn a_fixed_normaliser_replaces_the_fields_own() {
        let Some(ctx) = test_context() else { return };
        let (h, w) = (45, 75);
        let n = h * w;
        let input = field(h, w, 11);
        let buf = upload_c(&ctx, &input);
        let mut dp = GpuDoublePhase::new(&ctx, h, w, &DoublePhaseMethod::Plain, &buf).unwrap();
        let (_, _, _, own, mean) = cpu_encode(&input, h, w, DoublePhaseMethod::Plain);
        let fixed = 1.3 * own;
        let stats_of = |dp: &GpuDoublePhase| {
            let stats: Vec<u8> = ctx
                .read_buffer(dp.stats_buffer(), STATS_BYTES as usize)
                .unwrap();
            GpuDoublePhase::read_stats(&stats).unwrap()
        };
        dp.set_normaliser(&ctx, Some(fixed));
        run(&ctx, |e| dp.record(e));
        let (a, _) = stats_of(&dp);
        assert_eq!(a.to_bits(), fixed.to_bits());
        let gphase: Vec<f32> = ctx.read_buffer(dp.phase_buffer(), 3 * n).unwrap();
        // The CPU's pattern with the same a.
        let mut worst = 0.0f32;
        for c in 0..3 {
            let mut enc = ChannelEncoder::new(h, w, DoublePhaseMethod::Plain).unwrap();
            let mut f = input[c * n..(c + 1) * n].to_vec();
            let mut phase = vec![0.0; n];
            let mut codes = vec![0u8; n];
            enc.analyse(&mut f, &mut phase).unwrap();
            enc.encode(&f, &mut phase, &mut codes, mean[c], fixed)
                .unwrap();
            for (g, p) in gphase[c * n..(c + 1) * n].iter().zip(&phase) {
                worst = worst.max(cyclic(*g, *p));
            }
        }
        assert!(worst < 2e-3, "phase {worst}");
        dp.set_normaliser(&ctx, None);
        run(&ctx, |e| dp.record(e));
        let (a, _) = stats_of(&dp);
        assert!((a - own).abs() / own < 1e-6, "{a} vs {own}");
    }

    #[test]
    fn a_zero_field_is_a_typed_error_and_bl_dpm_is_refused() {
        let Some(ctx) = test_context() else { return };
        let (h, w) = (8, 12);
        let buf = upload_c(&ctx, &vec![Complex32::new(0.0, 0.0); 3 * h * w]);
        let dp = GpuDoublePhase::new(&ctx, h, w, &DoublePhaseMethod::Plain, &buf).unwrap();
        run(&ctx, |e| dp.record(e));
        let stats: Vec<u8> = ctx
            .read_buffer(dp.stats_buffer(), STATS_BYTES as usize)
            .unwrap();
        let err = GpuDoublePhase::read_stats(&stats).unwrap_err();
        assert!(matches!(err, HoloError::InvalidData(_)), "{err}");
        let err = GpuDoublePhase::new(&ctx, h, w, &DoublePhaseMethod::BandLimited { k: 0.5 }, &buf)
            .unwrap_err();
        assert!(err.to_string().contains("BL-DPM"), "{err}");
    }
}

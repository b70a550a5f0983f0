//! The hologram and pre-filter CNNs on the GPU: [`GpuCnn`] runs a [`CnnWeights`] graph (read once by
//! [`crate::model::graph`], which refuses anything but the TensorHolo residual CNN) with one fused pass per
//! layer (`shaders/conv3x3.wgsl`) and the output stage (`shaders/heads.wgsl`).
//!
//! Layer `i`'s pass writes `s_{i+1}` directly (`y_i`, plus `s_{i−1}` where `i + 1` is odd and ≥ 3), so a
//! frame is N passes and one output pass, through a ring of three activation buffers.

use super::context::GpuContext;
use super::kernel::{grid_1d, grid_2d, Kernel};
use super::shaders;
use crate::error::Result;
use crate::model::graph::{CnnOutput, CnnWeights};

/// How the hidden activations are stored and multiplied (resolved: the caller has checked the adapter's
/// `SHADER_F16` for [`GpuStorage::F16`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum GpuStorage {
    /// f32 storage and arithmetic.
    F32,
    /// f16 storage, f32 products and sums; the network's input and output stay f32.
    F16,
}

impl GpuStorage {
    /// `"f32"` or `"f16"`.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Self::F32 => "f32",
            Self::F16 => "f16",
        }
    }
}

/// `Layer` of `conv3x3.wgsl` (both precisions).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct LayerParams {
    h: u32,
    w: u32,
    c_a: u32,
    c_b: u32,
    c_out: u32,
    relu: u32,
    residual: u32,
    offset_a: f32,
    offset_b: f32,
    a_hidden: u32,
    out_hidden: u32,
    _pad: u32,
}

/// `Heads` of `heads.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct HeadParams {
    h: u32,
    w: u32,
    channels: u32,
    taps: u32,
    amp_scale: f32,
    phase_scale: f32,
    _pad: [u32; 2],
}

/// `conv3x3.wgsl`'s block: `WG_X · PX` columns, `WG_Y` rows and `OUT` output channels per workgroup (the
/// shader's constants; a smaller grid leaves pixels uncomputed, which `shipped_cnns_match_tract_f32` catches).
const BLOCK_COLUMNS: usize = 64;
const BLOCK_ROWS: usize = 8;
const BLOCK_CHANNELS: usize = 8;

/// Bytes per stored hidden activation.
fn activation_bytes(storage: GpuStorage) -> u64 {
    match storage {
        GpuStorage::F16 => 2,
        GpuStorage::F32 => 4,
    }
}

/// A [`CnnWeights`] network bound to its input and output buffers at one resolution.
#[derive(Debug)]
pub struct GpuCnn {
    conv: Kernel,
    passes: Vec<(wgpu::BindGroup, [u32; 3])>,
    out_kernel: Kernel,
    out_bind: wgpu::BindGroup,
    elements: usize,
    flops: f64,
    bytes: f64,
}

impl GpuCnn {
    /// Allocates the activations (a ring of three `[hidden, H, W]` buffers, f16 with [`GpuStorage::F16`;
    /// f32 where the adapter lacks `SHADER_F16`) and binds every layer: `input`
    /// f32 `[in_channels, H, W]`, `output` f32 `[6, H, W]` (the heads `[amplitude, phase]`, or the pre-filter's
    /// `[Re, Im]`).
    ///
    /// Errors: [`crate::HoloError::ModelContract`] for an int8 (QDQ) graph (the GPU runs the f32 files);
    /// [`crate::HoloError::Gpu`] for activations above the device's storage-binding limit (the message names
    /// the size) or a shader the device refuses.
    pub(crate) fn new(
        ctx: &GpuContext,
        weights: &CnnWeights,
        height: usize,
        width: usize,
        input: &wgpu::Buffer,
        output: &wgpu::Buffer,
        storage: GpuStorage,
    ) -> Result<Self> {
        if weights.quant.is_some() {
            return Err(crate::HoloError::ModelContract {
                source_name: "CNN graph".into(),
                reason: "an int8 (QDQ) file: the GPU path runs the f32 model files (choose precision f32)"
                    .into(),
            });
        }
        let storage = if ctx.info().shader_f16 {
            storage
        } else {
            GpuStorage::F32
        };
        let n = height
            .checked_mul(width)
            .filter(|&n| n > 0)
            .ok_or_else(|| crate::error::invalid("size", "empty or too large frame"))?;
        let layers = &weights.layers;
        let hidden = layers[0].c_out;
        let act_bytes = (hidden as u64) * (n as u64) * activation_bytes(storage);
        let ring = [
            ctx.storage("cnn activations 0", act_bytes)?,
            ctx.storage("cnn activations 1", act_bytes)?,
            ctx.storage("cnn activations 2", act_bytes)?,
        ];
        let conv = if storage == GpuStorage::F16 {
            ctx.kernel(&shaders::CONV3X3_F16, "conv3x3")?
        } else {
            ctx.kernel(&shaders::CONV3X3, "conv3x3")?
        };
        let mut passes = Vec::new();
        let last = layers.len() - 1;
        // s_0 = the input (with its offset); s_{i+1} goes to ring[i % 3]; layer i reads s_i and, for the
        // residual, s_{i−1}: three different buffers.
        let slot = |i: usize| &ring[(i + 2) % 3]; // s_i for i ≥ 1 (s_1 → ring[0])
        for (i, l) in layers.iter().enumerate() {
            let residual = i >= 2 && (i + 1) % 2 == 1 && i != last;
            let c_a = if i == 0 { l.c_in } else { layers[i - 1].c_out };
            let c_b = if i == last { weights.in_channels } else { 0 };
            let off_a = if i == 0 { weights.input_offset } else { 0.0 };
            let w = ctx.storage_with("conv weights", &l.weights)?;
            let b = ctx.storage_with("conv bias", &l.bias)?;
            // Unused bindings get buffers that cannot alias this layer's writable one.
            let (in_s, res, out_s) = if i == 0 {
                (&ring[2], &ring[2], slot(1))
            } else {
                (slot(i), slot(i - 1), slot(i + 1))
            };
            let params = ctx.uniform(
                "conv layer",
                &LayerParams {
                    h: height as u32,
                    w: width as u32,
                    c_a: c_a as u32,
                    c_b: c_b as u32,
                    c_out: l.c_out as u32,
                    relu: u32::from(i != last),
                    residual: u32::from(residual),
                    offset_a: off_a,
                    offset_b: weights.input_offset,
                    a_hidden: u32::from(i != 0),
                    out_hidden: u32::from(i != last),
                    _pad: 0,
                },
            )?;
            let bind = ctx.bind(
                &conv,
                &[&params, input, in_s, input, &w, &b, res, out_s, output],
            );
            passes.push((
                bind,
                grid_2d(
                    width,
                    height,
                    l.c_out.div_ceil(BLOCK_CHANNELS),
                    [BLOCK_COLUMNS as u32, BLOCK_ROWS as u32],
                ),
            ));
        }
        let (out_kernel, out_bind) = match &weights.output {
            CnnOutput::Heads {
                amplitude_scale,
                phase_scale,
            } => {
                let k = ctx.kernel(&shaders::HEADS, "hologram_heads")?;
                let p = ctx.uniform(
                    "heads",
                    &HeadParams {
                        h: height as u32,
                        w: width as u32,
                        channels: 6,
                        taps: 0,
                        amp_scale: *amplitude_scale,
                        phase_scale: *phase_scale,
                        _pad: [0; 2],
                    },
                )?;
                let bind = ctx.bind(&k, &[&p, output]);
                (k, bind)
            }
            CnnOutput::Prefilter { taps, base } => {
                let k = ctx.kernel(&shaders::HEADS, "prefilter_base")?;
                let p = ctx.uniform(
                    "pre-filter base",
                    &HeadParams {
                        h: height as u32,
                        w: width as u32,
                        channels: weights.in_channels as u32,
                        taps: *taps as u32,
                        amp_scale: 0.0,
                        phase_scale: 0.0,
                        _pad: [0; 2],
                    },
                )?;
                let base = ctx.storage_with("pre-filter base", base)?;
                let bind = ctx.bind(&k, &[&p, output, input, &base]);
                (k, bind)
            }
        };
        let macs = weights.macs_per_pixel() as f64 * n as f64;
        // Each layer reads its input tiles once per block of output channels (the block and its 1-pixel halo)
        // and writes its output once.
        let halo =
            ((BLOCK_COLUMNS + 2) * (BLOCK_ROWS + 2)) as f64 / (BLOCK_COLUMNS * BLOCK_ROWS) as f64;
        let elem = activation_bytes(storage) as f64;
        let bytes: f64 = layers
            .iter()
            .map(|l| {
                elem * n as f64
                    * (l.c_in as f64 * l.c_out.div_ceil(BLOCK_CHANNELS) as f64 * halo
                        + l.c_out as f64)
            })
            .sum();
        Ok(Self {
            conv,
            passes,
            out_kernel,
            out_bind,
            elements: 6 * n,
            flops: 2.0 * macs + 10.0 * 6.0 * n as f64,
            bytes: bytes + 8.0 * 6.0 * n as f64,
        })
    }

    /// Records the layers and the output stage.
    pub(crate) fn record(&self, encoder: &mut wgpu::CommandEncoder) {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        for (bind, groups) in &self.passes {
            self.conv.dispatch(&mut pass, bind, *groups);
        }
        self.out_kernel
            .dispatch(&mut pass, &self.out_bind, grid_1d(self.elements));
    }

    /// (flops, bytes) per frame: 2 per multiply-add of the convolutions (+ the output stage), and the bytes
    /// the passes read and write.
    pub(crate) fn cost(&self) -> (f64, f64) {
        (self.flops, self.bytes)
    }
}

/// The uniform structs of this module beside their WGSL twins (checked in `shader_tests`).
#[cfg(test)]
pub(super) fn uniform_layouts() -> Vec<super::shader_tests::UniformLayout> {
    use super::shader_tests::uniform_layout;
    use super::shaders::{CONV3X3, CONV3X3_F16, HEADS};
    let layer = |shader: &'static super::shaders::Shader| {
        uniform_layout!(
            shader,
            "Layer",
            LayerParams {
                h,
                w,
                c_a,
                c_b,
                c_out,
                relu,
                residual,
                offset_a,
                offset_b,
                a_hidden,
                out_hidden
            }
        )
    };
    vec![
        layer(&CONV3X3),
        layer(&CONV3X3_F16),
        uniform_layout!(
            &HEADS,
            "Heads",
            HeadParams {
                h,
                w,
                channels,
                taps,
                amp_scale,
                phase_scale
            }
        ),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::test_support::context as test_context;
    use crate::model::HologramModel;
    use crate::model::{embedded, ModelConfig, Precision};
    use ndarray::Array3;

    fn config() -> ModelConfig {
        ModelConfig {
            offset_m: 6e-3,
            ..ModelConfig::default()
        }
    }

    fn noise(len: usize, seed: u64, scale: f32) -> Vec<f32> {
        let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(7);
        (0..len)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                scale * ((s >> 40) as f32 / (1u64 << 24) as f32)
            })
            .collect()
    }

    /// Runs `model` on `input` `[C, H, W]` on the GPU (f32) and with tract; returns max |Δ| / max |tract|.
    fn compare(ctx: &GpuContext, model: &HologramModel, input: &Array3<f32>) -> f32 {
        compare_in(ctx, model, input, GpuStorage::F32)
    }

    fn compare_in(
        ctx: &GpuContext,
        model: &HologramModel,
        input: &Array3<f32>,
        precision: GpuStorage,
    ) -> f32 {
        let (c, h, w) = input.dim();
        let weights = CnnWeights::from_model(model).unwrap();
        assert_eq!(weights.in_channels, c);
        assert_eq!(
            Some(weights.macs_per_pixel() as u64),
            model.metadata().macs_per_pixel()
        );
        let inbuf = ctx
            .storage_with("input", input.as_slice().unwrap())
            .unwrap();
        let out = ctx.storage("out", (6 * h * w * 4) as u64).unwrap();
        let cnn = GpuCnn::new(ctx, &weights, h, w, &inbuf, &out, precision).unwrap();
        let before = ctx.resource_counts();
        let mut enc = ctx.encoder("cnn");
        cnn.record(&mut enc);
        ctx.submit_and_wait(enc).unwrap();
        assert_eq!(ctx.resource_counts(), before, "record created GPU objects");
        let gpu: Vec<f32> = ctx.read_buffer(&out, 6 * h * w).unwrap();
        let (a, b) = crate::cnn::tract::TractModel::new(model)
            .unwrap()
            .plan(h, w)
            .unwrap()
            .run_outputs(input.view())
            .unwrap();
        let cpu: Vec<f32> = a.iter().chain(b.iter()).copied().collect();
        let scale = cpu.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        gpu.iter()
            .zip(&cpu)
            .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()))
            / scale
    }

    #[test]
    fn shipped_cnns_match_tract_f32() {
        let Some(ctx) = test_context() else { return };
        let mut cases: Vec<(String, HologramModel, usize)> = Vec::new();
        for layers in crate::model::embedded::LAYERS {
            let m = embedded::hologram_model(*layers, Precision::F32, &config()).unwrap();
            cases.push((format!("holo{layers}"), m, 4));
        }
        let p = embedded::prefilter_model(6, Precision::F32, &config()).unwrap();
        cases.push(("prefilter 6 mm".into(), p, 6));
        for (name, model, c) in &cases {
            for (h, w) in [(48, 64), (37, 133)] {
                let scale = if *c == 4 { 1.0 } else { 2.0 };
                let mut input =
                    Array3::from_shape_vec((*c, h, w), noise(c * h * w, (h + w) as u64, scale))
                        .unwrap();
                if *c == 6 {
                    input.mapv_inplace(|v| v - 1.0);
                }
                let e = compare(&ctx, model, &input);
                println!("{name} {h}×{w}: max rel Δ {e:.2e}");
                assert!(e < 1e-4, "{name} {h}×{w}: {e}");
            }
        }
        // A real-looking input: the built-in scene.
        let frame = crate::scene::procedural::default_scene(40, 56).unwrap();
        let mut input = Array3::zeros((4, 40, 56));
        crate::model::contract::pack_rgbd(&frame, input.view_mut()).unwrap();
        let e = compare(&ctx, &cases[0].1, &input);
        println!("holo8 built-in scene: max rel Δ {e:.2e}");
        assert!(e < 1e-4, "{e}");
    }

    #[test]
    fn f16_activations_stay_within_a_stated_bound_of_tract_f32() {
        let Some(ctx) = test_context() else { return };
        if !ctx.info().shader_f16 {
            eprintln!("skipping: {} has no SHADER_F16", ctx.info().name);
            return;
        }
        // The built-in scene (real-looking input) through holo8, and random fields through the pre-filter.
        let frame = crate::scene::procedural::default_scene(48, 64).unwrap();
        let mut input = Array3::zeros((4, 48, 64));
        crate::model::contract::pack_rgbd(&frame, input.view_mut()).unwrap();
        for layers in crate::model::embedded::LAYERS {
            let m = embedded::hologram_model(*layers, Precision::F32, &config()).unwrap();
            let e = compare_in(&ctx, &m, &input, GpuStorage::F16);
            println!("holo{layers} f16, built-in scene: max rel Δ {e:.2e}");
            // f16 keeps 11 significant bits (4.9e-4 per rounding); measured 2.8–5.1e-4 on lavapipe.
            assert!(e < 2e-3, "holo{layers} f16: {e}");
        }
        let p = embedded::prefilter_model(6, Precision::F32, &config()).unwrap();
        let field = Array3::from_shape_vec((6, 48, 64), noise(6 * 48 * 64, 5, 2.0))
            .unwrap()
            .mapv(|v| v - 1.0);
        let e = compare_in(&ctx, &p, &field, GpuStorage::F16);
        println!("prefilter 6 mm f16: max rel Δ {e:.2e}");
        assert!(e < 2e-3, "prefilter f16: {e}");
    }
}

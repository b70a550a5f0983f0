//! The native engine on int8 QDQ files (`models/*.int8-qdq.onnx`): the network of [`CnnWeights`] with its
//! [`CnnQuant`] grids, on the u8 × s8 direct 3×3 kernels of `tensorholo-kernels` ([`Conv3x3U8`]: i32
//! accumulation, requantisation fused into the epilogue).
//!
//! One frame, for `N` layers, every activation a u8 [`RowPlanar`] on the grid the file gives it:
//!
//! ```text
//! s_0 = Q(x − input_offset) on layer 0's input grid             (ONNX QuantizeLinear, in the input copy)
//! layer i < N−1:  s_{i+1} = Q(ReLU(conv_i(s_i) + b_i) (+ s_{i−1}))   ring of 3 buffers, each layer's grid
//! x_cat = s_0 moved to the concat's grid                       (the file: DequantizeLinear, Concat, Quantize)
//! layer N−1:      o = conv_{N−1}(concat(s_{N−1}, x_cat)) + b     raw f32 [C_out, H, W]
//! o rounded to the file's output grid, then the heads or the pre-filter's base filter, as the f32 engine
//! ```
//!
//! Where the file rounds twice, this engine rounds once: the file quantises each convolution's raw output
//! before its ReLU and then the ReLU's (or the residual sum's) result; the kernels fuse convolution, ReLU,
//! residual add and the second rounding. The difference is at most half a step of the first grid per layer
//! (measured against tract's execution of the file in `cnn/tests.rs`).
//!
//! Threads: as the f32 engine, each layer's rows in one band per thread; the last layer writes raw f32
//! rows `[H][C_out][W]`, so that each band is a slice of its own.

use std::sync::Arc;

use ndarray::{Array3, ArrayView3};
use tensorholo_kernels::{fake_quantize, Conv3x3U8, Conv3x3U8Spec, Inputs, Isa, RowPlanar};

use super::native::{
    finish_outputs, in_bands, on_threads, planar_slice, pool, ring_slots, run_layer,
    standard_input, u8_grid, F32Rows,
};
use super::{kernel_err, CnnPlan};
use crate::error::{HoloError, Result};
use crate::model::{CnnOutput, CnnQuant, CnnWeights};

/// The network's packed int8 layers, shared by every plan of it.
#[derive(Debug)]
struct Network {
    graph: Arc<CnnWeights>,
    layers: Vec<Conv3x3U8>,
    /// The level the layers were packed for (also the heads' vector path).
    isa: Isa,
}

impl Network {
    fn quant(&self) -> Result<&CnnQuant> {
        self.graph
            .quant
            .as_ref()
            .ok_or_else(|| HoloError::Internal("native int8 plan without grids".into()))
    }
}

/// An int8 native plan: one network at one resolution, with its buffers and threads.
#[derive(Debug)]
pub(crate) struct NativeInt8Plan {
    net: Arc<Network>,
    height: usize,
    width: usize,
    threads: usize,
    pool: Option<Arc<rayon::ThreadPool>>,
    /// `s_0` on layer 0's input grid.
    x: RowPlanar<u8>,
    /// `s_0` on the concat's grid: the last layer's second source.
    x_cat: RowPlanar<u8>,
    /// `s_1 …`: `s_k` lives in `ring[(k − 1) % 3]`, its zero point set before the layer that writes it.
    ring: [RowPlanar<u8>; 3],
    /// The last layer's raw output, `[H][C_out][W]` (row-major, so that row bands are disjoint slices).
    raw: Vec<f32>,
    /// Pre-filter: the input as the file's base filter reads it (rounded to the input grid), `[C][H][W]`.
    base_input: Vec<f32>,
    depthwise_scratch: Vec<f32>,
}

impl NativeInt8Plan {
    /// Packs `graph`'s int8 layers for the best int8 kernels of `isa` and allocates the buffers of
    /// `height × width` frames, run on `threads` threads (≥ 1).
    ///
    /// Errors: [`HoloError::InvalidParameter`] for 0 threads; [`HoloError::InvalidData`] for non-finite
    /// scales or biases; [`HoloError::ModelRun`] for a graph without int8 grids, an ISA this CPU lacks, a
    /// size the kernels refuse or a thread pool the OS will not start.
    pub(crate) fn new(
        graph: Arc<CnnWeights>,
        height: usize,
        width: usize,
        threads: usize,
        isa: Isa,
    ) -> Result<Self> {
        if threads == 0 {
            return Err(crate::error::invalid(
                "threads",
                "the native CNN engine needs at least one thread",
            ));
        }
        let quant = graph.quant.as_ref().ok_or_else(|| {
            HoloError::ModelRun("the native int8 engine needs an int8 (QDQ) file".into())
        })?;
        let n = graph.layers.len();
        let hidden = graph.layers[0].c_out;
        let c = graph.in_channels;
        let mut layers = Vec::with_capacity(n);
        for (i, (l, q)) in graph.layers.iter().zip(&quant.layers).enumerate() {
            if l.bias.iter().any(|v| !v.is_finite()) {
                return Err(HoloError::InvalidData(format!(
                    "CNN layer {i} holds a NaN or infinite bias"
                )));
            }
            let last = i + 1 == n;
            let residual = i + 1 >= 3 && (i + 1) % 2 == 1 && !last;
            let spec = Conv3x3U8Spec {
                weights: &q.weights,
                weight_scales: &q.weight_scales,
                bias: &l.bias,
                c_in_a: if last { l.c_in - c } else { l.c_in },
                c_in_b: if last { c } else { 0 },
                c_out: l.c_out,
                input_scale: q.input.scale,
                input_zero_point_a: q.input.zero_point,
                input_zero_point_b: q.input.zero_point,
                relu: !last,
                // s_{i−1} is on the grid layer i − 1 reads.
                residual: residual.then(|| u8_grid(quant.layers[i - 1].input)),
                output: (!last).then(|| u8_grid(q.output)),
            };
            layers.push(Conv3x3U8::new(&spec, isa).map_err(kernel_err)?);
        }
        let c_out = graph.layers[n - 1].c_out;
        let first = quant.layers[0].input;
        let cat = quant.layers[n - 1].input;
        let buf = |ch, zp| RowPlanar::new_quantized(ch, height, width, zp).map_err(kernel_err);
        let prefilter = matches!(graph.output, CnnOutput::Prefilter { .. });
        Ok(Self {
            x: buf(c, first.zero_point)?,
            x_cat: buf(c, cat.zero_point)?,
            ring: [buf(hidden, 0)?, buf(hidden, 0)?, buf(hidden, 0)?],
            raw: vec![0.0; c_out * height * width],
            base_input: if prefilter {
                vec![0.0; c * height * width]
            } else {
                Vec::new()
            },
            depthwise_scratch: Vec::new(),
            height,
            width,
            threads,
            pool: pool(threads)?,
            net: Arc::new(Network { graph, layers, isa }),
        })
    }

    /// The kernel row every layer runs (e.g. `conv3x3.u8s8.4x1.avx2`).
    pub(crate) fn kernel_name(&self) -> &'static str {
        self.net.layers[0].kernel().name
    }

    /// Runs the convolutions of one frame whose input is already in `self.x`; the raw output lands in
    /// `self.raw`.
    fn forward(&mut self) -> Result<()> {
        let net = self.net.clone();
        let quant = net.quant()?;
        let n = net.layers.len();
        let (threads, pool) = (self.threads, self.pool.as_deref());
        for (i, conv) in net.layers.iter().enumerate().take(n - 1) {
            let out = i % 3;
            let residual = (i + 1 >= 3 && (i + 1) % 2 == 1).then_some((i + 1) % 3);
            let (dst, slot) = ring_slots(&mut self.ring, out);
            dst.set_zero_point(quant.layers[i].output.zero_point);
            let src = if i == 0 { &self.x } else { slot((i + 2) % 3) };
            let mut inputs = Inputs::new(src);
            if let Some(r) = residual {
                inputs = inputs.residual(slot(r));
            }
            run_layer(conv, inputs, dst, threads, pool)?;
        }
        let last = &self.ring[(n - 2) % 3];
        let inputs = Inputs::new(last).concat(&self.x_cat);
        let conv = &net.layers[n - 1];
        let raw = F32Rows {
            data: &mut self.raw,
            rows: 0..self.height,
        };
        on_threads(raw, threads, pool, &|band: &mut F32Rows<'_>| {
            conv.run_rows_f32(inputs, band.data, band.rows.clone())
        })
    }
}

impl CnnPlan for NativeInt8Plan {
    fn input_dim(&self) -> (usize, usize, usize) {
        (self.net.graph.in_channels, self.height, self.width)
    }

    fn run_outputs(&mut self, input: ArrayView3<f32>) -> Result<(Array3<f32>, Array3<f32>)> {
        let standard = standard_input(input, self.input_dim())?;
        let planar = planar_slice(&standard)?;
        let net = self.net.clone();
        let quant = net.quant()?;
        let n = net.layers.len();
        let first = quant.layers[0].input;
        let offset = -net.graph.input_offset;
        // Both in row bands on the plan's threads (serial, they were a tenth of a 2-thread frame).
        let (threads, pool) = (self.threads, self.pool.as_deref());
        in_bands(&mut self.x, threads, pool, &|band| {
            band.quantize_fill(planar, offset, first.scale)
        })?;
        let (x, cat_scale) = (&self.x, quant.layers[n - 1].input.scale);
        in_bands(&mut self.x_cat, threads, pool, &|band| {
            band.requantize_from(x, first.scale, cat_scale)
        })?;
        if !self.base_input.is_empty() {
            // The file's base filter reads the input rounded to the input grid (the pre-filter has no offset).
            for (b, &v) in self.base_input.iter_mut().zip(planar) {
                *b = v + offset;
            }
            fake_quantize(&mut self.base_input, u8_grid(first), net.isa).map_err(kernel_err)?;
            if offset != 0.0 {
                self.base_input.iter_mut().for_each(|b| *b -= offset);
            }
        }
        self.forward()?;
        let (h, w) = (self.height, self.width);
        let (raw, c_out) = (&self.raw, net.layers[n - 1].c_out());
        let raw_row = |c: usize, y: usize| &raw[(y * c_out + c) * w..(y * c_out + c + 1) * w];
        finish_outputs(
            &net.graph,
            &raw_row,
            Some(quant.layers[n - 1].output),
            &self.base_input,
            [h, w],
            net.isa,
            self.pool.as_deref(),
            &mut self.depthwise_scratch,
        )
    }

    fn spawn(&self) -> Box<dyn CnnPlan> {
        Box::new(Self {
            net: self.net.clone(),
            height: self.height,
            width: self.width,
            threads: self.threads,
            pool: pool(self.threads).ok().flatten(),
            x: self.x.clone(),
            x_cat: self.x_cat.clone(),
            ring: self.ring.clone(),
            raw: self.raw.clone(),
            base_input: self.base_input.clone(),
            depthwise_scratch: Vec::new(),
        })
    }
}

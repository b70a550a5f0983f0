//! The native engine on int8 QDQ files (`models/*.int8-qdq.onnx`): the network of [`CnnWeights`] with its
//! [`CnnQuant`] grids, on the u8 × s8 direct 3×3 kernels of `tensorholo-kernels` ([`Conv3x3U8`]: i32
//! accumulation, requantisation fused into the epilogue).
//!
//! One frame, for `N` layers, every activation a u8 [`RowPlanar`] on the grid the file gives it:
//!
//! ```text
//! s_0 = Q(x − input_offset) on layer 0's input grid             (ONNX QuantizeLinear, in the input copy)
//! layer i < N−1:  s_{i+1} = Q(ReLU(conv_i(s_i) + b_i) (+ s_{i−1}))   each on its layer's grid
//! x_cat = s_0 moved to the concat's grid                       (the file: DequantizeLinear, Concat, Quantize)
//! layer N−1:      o = conv_{N−1}(concat(s_{N−1}, x_cat)) + b     raw f32 [C_out, H, W]
//! o rounded to the file's output grid where it has one, then the heads or the pre-filter's base filter (of the
//! float input, or of the input rounded to the first grid where the file's Pad reads its DequantizeLinear), as
//! the f32 engine
//! ```
//!
//! The kernels fuse convolution, ReLU, residual add and the rounding of the result, so each layer rounds once.
//! Files exported since the exporter stopped rounding convolution outputs round once too, and leave the last
//! output float; older files quantise each convolution's raw output before its ReLU as well (a second
//! rounding, at most half a step of that grid per layer, that this engine skips: measured against tract's
//! execution of such a file in `cnn/tests.rs`).
//!
//! Strips and threads: as the f32 engine (windows of a few rows, [`super::strips`]; each layer's strip in one
//! band per thread); the last layer writes a strip of raw f32 rows `[S][C_out][W]`, so that each band is a
//! slice of its own.

use std::sync::Arc;

use ndarray::{Array3, ArrayView3};
use tensorholo_kernels::{Conv3x3U8, Conv3x3U8Spec, Inputs, Isa, RowPlanar};

use super::native::{
    finish_outputs, heads_of, heads_rows, owned_outputs, planar_slice, pool, standard_input,
    u8_grid, BaseInput, Outputs, Planes,
};
use super::strips::{bands, hidden_layers, installed, row_bytes, F32Rows, Place, Strips, Window};
use super::{check_planes, kernel_err, CnnPlan};
use crate::error::{HoloError, Result};
use crate::model::{CnnQuant, CnnWeights, QuantGrid};

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

/// An int8 native plan: one network at one resolution, with its activation windows and threads.
#[derive(Debug)]
pub(crate) struct NativeInt8Plan {
    net: Arc<Network>,
    height: usize,
    width: usize,
    threads: usize,
    pool: Option<Arc<rayon::ThreadPool>>,
    strips: Strips,
    /// `s_0` on layer 0's input grid.
    x: Window<u8>,
    /// `s_0` on the concat's grid: the last layer's second source (carried `N + 1` rows).
    x_cat: Window<u8>,
    /// `s_1 … s_{N−1}`, each on the grid of the layer that writes it.
    s: Vec<Window<u8>>,
    /// The last layer's raw output of one strip, `[S][C_out][W]` (row-major, so that row bands are
    /// disjoint slices).
    raw: Vec<f32>,
    /// Where `raw`'s rows sit in the frame (lag `N`, no carry).
    raw_place: Place,
    /// Pre-filter of a file whose base filter reads the rounded input: one channel of that input,
    /// `H·W` values (grown on the first run).
    base_plane: Vec<f32>,
}

impl NativeInt8Plan {
    /// Packs `graph`'s int8 layers for the best int8 kernels of `isa` and allocates the activation windows
    /// of `height × width` frames (strips of `strips::strip_rows`), run on `threads` threads (≥ 1).
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
        Self::with_strip(graph, height, width, threads, isa, None)
    }

    /// [`new`](Self::new) with strips of `strip` rows (`None`: `strips::strip_rows`). Errors: as `new`.
    pub(crate) fn with_strip(
        graph: Arc<CnnWeights>,
        height: usize,
        width: usize,
        threads: usize,
        isa: Isa,
        strip: Option<usize>,
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
        // The grid of s_{k+1}, k < N − 1 (the graph reader requires one for every hidden layer).
        let hidden_grids: Vec<QuantGrid> = quant.layers[..n - 1]
            .iter()
            .enumerate()
            .map(|(k, q)| {
                q.output.ok_or_else(|| {
                    HoloError::ModelRun(format!("int8 file: layer {k} has no output grid"))
                })
            })
            .collect::<Result<_>>()?;
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
                output: (!last).then(|| u8_grid(hidden_grids[i])),
            };
            layers.push(Conv3x3U8::new(&spec, isa).map_err(kernel_err)?);
        }
        let c_out = graph.layers[n - 1].c_out;
        let first = quant.layers[0].input;
        let cat = quant.layers[n - 1].input;
        // Windows: s_0 on layer 0's grid (carry 2), on the concat's (carry N + 1), s_1 … (carry 2), raw f32.
        let (xb, hb) = (row_bytes::<u8>(c, width), row_bytes::<u8>(hidden, width));
        let ob = c_out * width * std::mem::size_of::<f32>();
        let per_row = 2 * xb + (n - 1) * hb + ob;
        let fixed = (n + 7) * xb + 4 * (n - 1) * hb;
        let strips = Strips::for_plan(strip, height, n, [per_row, fixed], threads);
        let window = |ch, zp, lag, carry| {
            Window::new(Place::new(lag, carry), strips, |rows| {
                RowPlanar::new_quantized(ch, rows, width, zp)
            })
        };
        Ok(Self {
            x: window(c, first.zero_point, 0, 2)?,
            x_cat: window(c, cat.zero_point, 0, n + 1)?,
            s: (1..n)
                .map(|k| window(hidden, hidden_grids[k - 1].zero_point, k, 2))
                .collect::<Result<_>>()?,
            raw: vec![0.0; strips.rows * c_out * width],
            raw_place: Place::new(n, 0),
            strips,
            base_plane: Vec::new(),
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

    /// One frame of a checked input into `out`.
    fn run(&mut self, input: Planes<'_>, out: &mut Outputs<'_>) -> Result<()> {
        let net = self.net.clone();
        let quant = net.quant()?;
        let (h, w) = (self.height, self.width);
        self.forward(input, out)?;
        let base = match quant.base_reads_rounded_input {
            // Older files: the base filter reads the input as the first layer does, rounded.
            true => BaseInput::Rounded {
                planar: input,
                // The pre-filter has no offset; the rounding is the file's QuantizeLinear of the input.
                offset: -net.graph.input_offset,
                grid: quant.layers[0].input,
                isa: net.isa,
                plane: &mut self.base_plane,
            },
            false => BaseInput::Planar(input),
        };
        finish_outputs(
            &net.graph,
            out,
            base,
            [h, w],
            net.isa,
            self.threads,
            self.pool.as_deref(),
        )
    }

    /// One frame, strip by strip, on the plan's threads: the input `planar` `[C][H][W]` quantised into its two
    /// windows, every layer's strip, the last layer's raw rows (rounded to the file's output grid if it has one)
    /// turned into the heads (or the pre-filter's raw output) in `out`.
    fn forward(&mut self, input: Planes<'_>, out: &mut Outputs<'_>) -> Result<()> {
        let net = self.net.clone();
        let quant = net.quant()?;
        let n = net.layers.len();
        let (threads, strips, [h, w]) = (self.threads, self.strips, [self.height, self.width]);
        let first = quant.layers[0].input;
        let (cat_scale, out_grid) = (quant.layers[n - 1].input.scale, quant.layers[n - 1].output);
        let offset = -net.graph.input_offset;
        let c_out = net.layers[n - 1].c_out();
        self.x.start_frame()?;
        self.x_cat.start_frame()?;
        for s in &mut self.s {
            s.start_frame()?;
        }
        let heads = heads_of(&net.graph);
        let pool = self.pool.clone();
        let frame = || -> Result<()> {
            for m in 0..strips.steps {
                // s_0 on both grids, in row bands (they were a tenth of a 2-thread frame when serial).
                if let Some((rows, f0)) = self.x.new_rows(strips, m)? {
                    let y0 = rows.start;
                    let band = self.x.buf.band_mut(rows).map_err(kernel_err)?;
                    bands(band, threads, &|b| {
                        let f = f0 + b.rows().start - y0;
                        for c in 0..net.graph.in_channels {
                            b.quantize_fill_channel_rows(
                                c,
                                input.plane(c),
                                f,
                                offset,
                                first.scale,
                            )?;
                        }
                        Ok(())
                    })?;
                }
                if let Some((rows, f0)) = self.x_cat.new_rows(strips, m)? {
                    let (x, y0) = (&self.x, rows.start);
                    let x_first = x.place.first_row(strips, m);
                    let band = self.x_cat.buf.band_mut(rows).map_err(kernel_err)?;
                    bands(band, threads, &|b| {
                        let f = (f0 + b.rows().start - y0) as isize;
                        let from = (f - x_first) as usize;
                        b.requantize_rows_from(&x.buf, from, first.scale, cat_scale)
                    })?;
                }
                hidden_layers(
                    &net.layers[..n - 1],
                    &self.x,
                    &mut self.s,
                    strips,
                    m,
                    threads,
                )?;
                if let Some((rows, f0)) = self.raw_place.new_rows(strips, m).valid {
                    let o = self.raw_place;
                    let last = &self.s[n - 2];
                    let inputs = Inputs::new(&last.buf).concat(&self.x_cat.buf).shifted(
                        o.shift_from(last.place),
                        o.shift_from(self.x_cat.place),
                        0,
                    );
                    let conv = &net.layers[n - 1];
                    let rw = c_out * w;
                    let raw = F32Rows {
                        data: &mut self.raw[rows.start * rw..rows.end * rw],
                        rows: rows.clone(),
                    };
                    bands(raw, threads, &|band: &mut F32Rows<'_>| {
                        conv.run_rows_f32(inputs, band.data, band.rows.clone())
                    })?;
                    let raw = &self.raw;
                    let raw_row = |c: usize, y: usize| {
                        let r = y - f0 + rows.start;
                        &raw[(r * c_out + c) * w..(r * c_out + c + 1) * w]
                    };
                    let frame_rows = f0..f0 + rows.len();
                    // The file's rounding of the last raw output, if it has one.
                    let grid = out_grid;
                    heads_rows(
                        heads,
                        &raw_row,
                        grid,
                        [h, w],
                        frame_rows,
                        net.isa,
                        threads,
                        out,
                    )?;
                }
                self.x.advance(strips)?;
                self.x_cat.advance(strips)?;
                for s in &mut self.s {
                    s.advance(strips)?;
                }
            }
            Ok(())
        };
        installed(pool.as_deref(), threads, frame)
    }
}

impl CnnPlan for NativeInt8Plan {
    fn input_dim(&self) -> (usize, usize, usize) {
        (self.net.graph.in_channels, self.height, self.width)
    }

    fn run_outputs(&mut self, input: ArrayView3<f32>) -> Result<(Array3<f32>, Array3<f32>)> {
        let standard = standard_input(input, self.input_dim())?;
        let planar = planar_slice(&standard)?;
        let (h, w) = (self.height, self.width);
        owned_outputs(h, w, |out| self.run(Planes::Planar(planar, h * w), out))
    }

    fn run_planes(&mut self, planes: &[&[f32]]) -> Result<(Array3<f32>, Array3<f32>)> {
        check_planes(planes, self.input_dim())?;
        let (h, w) = (self.height, self.width);
        owned_outputs(h, w, |out| self.run(Planes::Each(planes), out))
    }

    fn run_planes_into(&mut self, planes: &[&[f32]], outputs: [&mut [f32]; 6]) -> Result<()> {
        check_planes(planes, self.input_dim())?;
        let mut out = Outputs::new(outputs, self.height * self.width)?;
        self.run(Planes::Each(planes), &mut out)
    }

    fn spawn(&self) -> Box<dyn CnnPlan> {
        Box::new(Self {
            net: self.net.clone(),
            height: self.height,
            width: self.width,
            threads: self.threads,
            pool: pool(self.threads).ok().flatten(),
            strips: self.strips,
            x: self.x.clone(),
            x_cat: self.x_cat.clone(),
            s: self.s.clone(),
            raw: self.raw.clone(),
            raw_place: self.raw_place,
            base_plane: Vec::new(),
        })
    }
}

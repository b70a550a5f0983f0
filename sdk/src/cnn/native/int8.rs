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
//! **Mixed precision** (files of `export --float-convs first last`, [`CnnQuant`]): the first and the last
//! layer run the f32 kernels ([`Conv3x3F32`]) on the float input, the layers between on the int8 ones:
//!
//! ```text
//! s_0 = x − input_offset in f32
//! layer 0:        s_1 = Q(ReLU(conv_0(s_0) + b_0))                f32 weights, rounded to s_1's grid
//! layers 1 … N−2: as above, u8 × s8
//! layer N−1:      o = conv_{N−1}(concat(DQ(s_{N−1}), s_0)) + b       f32 weights, s_{N−1} on its own grid
//! ```
//!
//! The rounding of the input (for the first layer and for the concat) is where most of a pre-filter's int8
//! error came from (models/MODEL_CARD.md, "int8: mixed-precision pre-filters"); the two float layers hold a
//! quarter of an 8 × 8 pre-filter's multiply-adds (132 of 516 per pixel) and 7 % of an 8-layer hologram
//! CNN's.
//!
//! Strips and threads: as the f32 engine (windows of a few rows, [`super::strips`]; each layer's strip in one
//! band per thread); the int8 last layer writes a strip of raw f32 rows `[S][C_out][W]`, so that each band is
//! a slice of its own; the f32 last layer writes a window, as the f32 engine's.

use std::sync::Arc;

use ndarray::{Array3, ArrayView3};
use tensorholo_kernels::{Conv3x3F32, Conv3x3U8, Conv3x3U8Spec, Inputs, Isa, RowPlanar};

use super::algorithm::{self, Choice, Rows};
use super::f32::{
    finish_outputs, heads_of, heads_rows, input_rows, last_layer_rows, owned_outputs, planar_slice,
    pool, standard_input, u8_grid, BaseInput, FusedBase, Outputs, Planes,
};
use super::slabs::{Cols, Slab};
use super::strips::{
    advance_all, bands, both, hidden_layers, installed, row_bytes, F32Rows, Place, Strips, Window,
};
use super::PlanSpec;
use crate::cnn::options::ConvAlgorithm;
use crate::cnn::plan::{check_planes, CnnPlan};
use crate::error::{HoloError, Result};
use crate::model::{CnnQuant, CnnWeights, LayerQuant, QuantGrid};

/// The network's packed layers, shared by every plan of it.
#[derive(Debug)]
struct Network {
    graph: Arc<CnnWeights>,
    /// The int8 layers: all `N`, or layers `1 … N−2` of a mixed-precision file.
    layers: Vec<Conv3x3U8>,
    /// Mixed precision: the f32 first and last layers.
    float_ends: Option<[Conv3x3F32; 2]>,
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

/// Layer `i`'s int8 form. Errors: a float layer ([`HoloError::ModelRun`]).
fn int8_layer(quant: &CnnQuant, i: usize) -> Result<&LayerQuant> {
    quant.layers.get(i).and_then(Option::as_ref).ok_or_else(|| {
        HoloError::ModelRun(format!(
            "int8 file: layer {i} is float; the native engine runs files whose learned convolutions are all \
             int8, or all but the first and the last (export --float-convs first last)"
        ))
    })
}

/// The activations at the two ends of the network, by the precision of its first and last layers.
#[derive(Clone, Debug)]
enum Ends {
    /// Every layer int8.
    Int8 {
        /// `s_0` on layer 0's input grid.
        x: Window<u8>,
        /// `s_0` on the concat's grid: the last layer's second source (carried `N + 1` rows).
        x_cat: Window<u8>,
        /// The last layer's raw output of one strip, `[S][C_out][W]` (row-major, so that row bands are
        /// disjoint slices).
        raw: Vec<f32>,
        /// Where `raw`'s rows sit in the frame (lag `N`, no carry).
        raw_place: Place,
    },
    /// Mixed precision: float first and last layers.
    Float {
        /// `s_0` in f32, read by both float layers (carried `N + 1` rows).
        x: Window<f32>,
        /// Layer 0's f32 output, before it is rounded into `s_1`.
        y0: Window<f32>,
        /// `s_{N−1}` dequantised, the last layer's first source.
        last: Window<f32>,
        /// The last layer's raw output.
        raw: Window<f32>,
    },
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
    ends: Ends,
    /// `s_1 … s_{N−1}`, each on the grid of the layer that writes it.
    s: Vec<Window<u8>>,
    /// Pre-filter of a file whose base filter reads the rounded input: one channel of that input,
    /// `H·W` values (grown on the first run).
    base_plane: Vec<f32>,
}

impl NativeInt8Plan {
    /// Packs `graph`'s int8 layers (and its float first and last layers on the rows `rows` decided, the
    /// table's where it holds none) for `spec.isa` and allocates the activation windows of `spec`'s frames
    /// (strips of `spec.strip_rows`, else `strips::strip_rows`; whole rows: `spec.slabs` is the f32 plan's),
    /// run on `spec.threads` threads (≥ 1). The one constructor.
    ///
    /// Errors: [`HoloError::InvalidParameter`] for 0 threads; [`HoloError::InvalidData`] for non-finite
    /// scales, weights or biases; [`HoloError::ModelRun`] for a graph without int8 grids, float layers other
    /// than the first and the last together, an ISA this CPU lacks, a size the kernels refuse or a thread
    /// pool the OS will not start.
    pub(crate) fn new(graph: Arc<CnnWeights>, spec: PlanSpec, rows: &Rows) -> Result<Self> {
        let PlanSpec {
            height,
            width,
            threads,
            isa,
            strip_rows: strip,
            slabs: _,
        } = spec;
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
        let mixed = graph.is_mixed_precision();
        let int8 = if mixed { 1..n - 1 } else { 0..n };
        for (i, l) in graph.layers.iter().enumerate() {
            if l.bias.iter().chain(&l.weights).any(|v| !v.is_finite()) {
                return Err(HoloError::InvalidData(format!(
                    "CNN layer {i} holds a NaN or infinite weight or bias"
                )));
            }
        }
        // The grid of s_{k+1}, k < N − 1: what layer k writes (layer 1's input grid after a float layer 0).
        let hidden_grids: Vec<QuantGrid> = (0..n - 1)
            .map(|k| match (mixed, k) {
                (true, 0) => Ok(int8_layer(quant, 1)?.input),
                _ => int8_layer(quant, k)?.output.ok_or_else(|| {
                    HoloError::ModelRun(format!("int8 file: layer {k} has no output grid"))
                }),
            })
            .collect::<Result<_>>()?;
        let mut layers = Vec::with_capacity(int8.len());
        for i in int8 {
            let (l, q) = (&graph.layers[i], int8_layer(quant, i)?);
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
                // s_{i−1} is on the grid layer i − 1 writes it to.
                residual: residual.then(|| u8_grid(hidden_grids[i - 2])),
                output: (!last).then(|| u8_grid(hidden_grids[i])),
            };
            layers.push(Conv3x3U8::new(&spec, isa).map_err(HoloError::from)?);
        }
        let c_out = graph.layers[n - 1].c_out;
        let float_ends = match mixed {
            true => {
                let (l0, ln) = (&graph.layers[0], &graph.layers[n - 1]);
                // Direct (the strips are one row apart), on the session's row for the shape.
                let f = |l: &crate::model::ConvLayer, relu| {
                    algorithm::plan_layer(l, relu, isa, Choice::Rows(rows, ConvAlgorithm::Direct))
                };
                Some([f(l0, true)?, f(ln, false)?])
            }
            false => None,
        };
        let hb = row_bytes::<u8>(hidden, width);
        let (per_row, fixed) = match mixed {
            false => {
                let xb = row_bytes::<u8>(c, width);
                let ob = c_out * width * std::mem::size_of::<f32>();
                (2 * xb + (n - 1) * hb + ob, (n + 7) * xb + 4 * (n - 1) * hb)
            }
            true => {
                let (xb, fb) = (row_bytes::<f32>(c, width), row_bytes::<f32>(hidden, width));
                let ob = row_bytes::<f32>(c_out, width);
                (
                    xb + (n - 1) * hb + 2 * fb + ob,
                    (n + 3) * xb + 4 * (n - 1) * hb + 6 * fb + 2 * ob,
                )
            }
        };
        // Every layer one row behind the one before: the f32 ends run direct convolutions.
        let strips = Strips::for_plan(strip, height, (n, 1), [per_row, fixed], threads);
        let window = |ch, zp, lag, carry| {
            Window::new(Place::new(lag, carry), strips, |rows| {
                RowPlanar::new_quantized(ch, rows, width, zp)
            })
        };
        let window_f32 = |ch, lag, carry| {
            Window::new(Place::new(lag, carry), strips, |rows| {
                RowPlanar::new(ch, rows, width)
            })
        };
        let ends = match mixed {
            false => {
                let first = int8_layer(quant, 0)?.input;
                let cat = int8_layer(quant, n - 1)?.input;
                Ends::Int8 {
                    x: window(c, first.zero_point, 0, 2)?,
                    x_cat: window(c, cat.zero_point, 0, n + 1)?,
                    raw: vec![0.0; strips.rows * c_out * width],
                    raw_place: Place::new(n, 0),
                }
            }
            true => Ends::Float {
                x: window_f32(c, 0, n + 1)?,
                y0: window_f32(hidden, 1, 0)?,
                last: window_f32(hidden, n - 1, 2)?,
                raw: window_f32(c_out, n, 0)?,
            },
        };
        Ok(Self {
            ends,
            s: (1..n)
                .map(|k| window(hidden, hidden_grids[k - 1].zero_point, k, 2))
                .collect::<Result<_>>()?,
            strips,
            base_plane: Vec::new(),
            height,
            width,
            threads,
            pool: pool(threads)?,
            net: Arc::new(Network {
                graph,
                layers,
                float_ends,
                isa,
            }),
        })
    }

    /// The kernel row the hidden layers run (e.g. `conv3x3.u8s8.4x1.avx2`).
    pub(crate) fn kernel_name(&self) -> &'static str {
        self.net.layers[0].kernel().name
    }

    /// Whether the first and last layers run in f32 (a mixed-precision file).
    #[cfg(test)]
    pub(crate) fn is_mixed(&self) -> bool {
        self.net.float_ends.is_some()
    }

    /// One frame of a checked input into `out`.
    fn run(&mut self, input: Planes<'_>, out: &mut Outputs<'_>) -> Result<()> {
        let net = self.net.clone();
        let quant = net.quant()?;
        let (h, w) = (self.height, self.width);
        // A base filter on the planar input is added to the rows as they are written (FusedBase); older files'
        // base filter reads the input as the first layer does, rounded, and runs after the frame.
        let rounded = quant.base_reads_rounded_input;
        let fused = (!rounded)
            .then(|| FusedBase::of(&net.graph, input, h))
            .flatten();
        match &mut self.ends {
            Ends::Int8 { .. } => self.forward_int8(input, out, fused)?,
            Ends::Float { .. } => self.forward_mixed(input, out, fused)?,
        }
        if !rounded {
            return Ok(());
        }
        let base = BaseInput::Rounded {
            planar: input,
            // The pre-filter has no offset; the rounding is the file's QuantizeLinear of the input.
            offset: -net.graph.input_offset,
            grid: int8_layer(quant, 0)?.input,
            isa: net.isa,
            plane: &mut self.base_plane,
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

    /// One frame of an all-int8 network, strip by strip, on the plan's threads: the input `planar` `[C][H][W]`
    /// quantised into its two windows, every layer's strip, the last layer's raw rows (rounded to the file's
    /// output grid if it has one) turned into the heads (or the pre-filter's raw output) in `out`.
    fn forward_int8(
        &mut self,
        input: Planes<'_>,
        out: &mut Outputs<'_>,
        base: Option<FusedBase<'_>>,
    ) -> Result<()> {
        let net = self.net.clone();
        let quant = net.quant()?;
        let n = net.layers.len();
        let (threads, strips, w) = (self.threads, self.strips, self.width);
        // The int8 plan runs the whole frame as one slab.
        let whole = Slab::whole(w);
        let cols = Cols {
            frame_width: w,
            slab: &whole,
        };
        let first = int8_layer(quant, 0)?.input;
        let last_q = int8_layer(quant, n - 1)?;
        let (cat_scale, out_grid) = (last_q.input.scale, last_q.output);
        let offset = -net.graph.input_offset;
        let c_out = net.layers[n - 1].c_out();
        let Ends::Int8 {
            x,
            x_cat,
            raw,
            raw_place,
        } = &mut self.ends
        else {
            return Err(HoloError::Internal("int8 forward of a mixed plan".into()));
        };
        let s = &mut self.s;
        x.start_frame()?;
        x_cat.start_frame()?;
        for s in s.iter_mut() {
            s.start_frame()?;
        }
        let heads = heads_of(&net.graph);
        let pool = self.pool.clone();
        let frame = || -> Result<()> {
            for m in 0..strips.steps {
                // s_0 on both grids, in row bands (they were a tenth of a 2-thread frame when serial).
                if let Some((rows, f0)) = x.new_rows(strips, m)? {
                    let y0 = rows.start;
                    let band = x.buf.band_mut(rows).map_err(HoloError::from)?;
                    bands(band, threads, &|b| {
                        let f = f0 + b.rows().start - y0;
                        b.quantize_fill_planes_rows(|c| input.plane(c), f, offset, first.scale)
                    })?;
                }
                if let Some((rows, f0)) = x_cat.new_rows(strips, m)? {
                    let (x, y0) = (&*x, rows.start);
                    let x_first = x.place.first_row(strips, m);
                    let band = x_cat.buf.band_mut(rows).map_err(HoloError::from)?;
                    bands(band, threads, &|b| {
                        let f = (f0 + b.rows().start - y0) as isize;
                        let from = (f - x_first) as usize;
                        b.requantize_rows_from(&x.buf, from, first.scale, cat_scale)
                    })?;
                }
                hidden_layers(
                    &net.layers[..n - 1],
                    0,
                    Some(&*x),
                    s,
                    &[],
                    strips,
                    m,
                    threads,
                )?;
                if let Some((rows, f0)) = raw_place.new_rows(strips, m).valid {
                    let o = *raw_place;
                    let last = &s[n - 2];
                    let inputs = Inputs::new(&last.buf).concat(&x_cat.buf).shifted(
                        o.shift_from(last.place),
                        o.shift_from(x_cat.place),
                        0,
                    );
                    let conv = &net.layers[n - 1];
                    let rw = c_out * w;
                    let band = F32Rows {
                        data: &mut raw[rows.start * rw..rows.end * rw],
                        rows: rows.clone(),
                    };
                    bands(band, threads, &|band: &mut F32Rows<'_>| {
                        conv.run_rows_f32(inputs, band.data, band.rows.clone())
                    })?;
                    let raw = &*raw;
                    let raw_row = |c: usize, y: usize| {
                        let r = y - f0 + rows.start;
                        &raw[(r * c_out + c) * w..(r * c_out + c + 1) * w]
                    };
                    let frame_rows = f0..f0 + rows.len();
                    // The file's rounding of the last raw output, if it has one.
                    heads_rows(
                        heads, &raw_row, out_grid, base, cols, frame_rows, net.isa, threads, out,
                    )?;
                }
                both(
                    threads,
                    || x.advance(strips).and_then(|()| x_cat.advance(strips)),
                    || advance_all(s, strips, threads),
                )?;
            }
            Ok(())
        };
        installed(pool.as_deref(), threads, frame)
    }

    /// One frame of a mixed-precision network (see the module docs), strip by strip, on the plan's threads:
    /// the f32 input window, the f32 first layer rounded into `s_1`, the int8 layers, `s_{N−1}` dequantised,
    /// the f32 last layer into `out`.
    fn forward_mixed(
        &mut self,
        input: Planes<'_>,
        out: &mut Outputs<'_>,
        base: Option<FusedBase<'_>>,
    ) -> Result<()> {
        let net = self.net.clone();
        let quant = net.quant()?;
        let n = net.graph.layers.len();
        let (threads, strips) = (self.threads, self.strips);
        let whole = Slab::whole(self.width);
        let cols = Cols {
            frame_width: self.width,
            slab: &whole,
        };
        let (Some([first, last_conv]), Ends::Float { x, y0, last, raw }) =
            (&net.float_ends, &mut self.ends)
        else {
            return Err(HoloError::Internal("mixed forward of an int8 plan".into()));
        };
        let s1_scale = int8_layer(quant, 1)?.input.scale;
        let last_scale = int8_layer(quant, n - 2)?
            .output
            .ok_or_else(|| {
                HoloError::ModelRun(format!("int8 file: layer {} has no output grid", n - 2))
            })?
            .scale;
        let s = &mut self.s;
        for win in [&mut *x, &mut *y0, &mut *last, &mut *raw] {
            win.start_frame()?;
        }
        for s in s.iter_mut() {
            s.start_frame()?;
        }
        let heads = heads_of(&net.graph);
        let offset = -net.graph.input_offset;
        let pool = self.pool.clone();
        let frame = || -> Result<()> {
            for m in 0..strips.steps {
                input_rows(x, input, offset, (strips, m, threads), cols)?;
                // Layer 0 in f32, its output rounded into s_1 (the same frame rows, at another carry).
                if let Some((rows, _)) = y0.new_rows(strips, m)? {
                    let inputs = Inputs::new(&x.buf).shifted(y0.shift_from(x), 0, 0);
                    let band = y0.buf.band_mut(rows).map_err(HoloError::from)?;
                    bands(band, threads, &|b| first.run_band(inputs, b))?;
                }
                if let Some((rows, _)) = s[0].new_rows(strips, m)? {
                    let d = s[0].shift_from(y0);
                    let (y0, band) = (&*y0, s[0].buf.band_mut(rows).map_err(HoloError::from)?);
                    bands(band, threads, &|b| {
                        let from = (b.rows().start as isize - d) as usize;
                        b.quantize_rows_from(&y0.buf, from, s1_scale)
                    })?;
                }
                hidden_layers(&net.layers, 1, None, s, &[], strips, m, threads)?;
                // s_{N−1} dequantised for the f32 last layer.
                if let Some((rows, _)) = last.new_rows(strips, m)? {
                    let src = &s[n - 2];
                    let d = last.shift_from(src);
                    let band = last.buf.band_mut(rows).map_err(HoloError::from)?;
                    bands(band, threads, &|b| {
                        let from = (b.rows().start as isize - d) as usize;
                        b.dequantize_rows_from(&src.buf, from, last_scale)
                    })?;
                }
                let ctx = (heads, cols, net.isa, strips, m, threads, base);
                last_layer_rows(last_conv, last, x, raw, ctx, out)?;
                let ends = [&mut *x, &mut *y0, &mut *last, &mut *raw];
                both(
                    threads,
                    || ends.into_iter().try_for_each(|w| w.advance(strips)),
                    || advance_all(s, strips, threads),
                )?;
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
            ends: self.ends.clone(),
            s: self.s.clone(),
            base_plane: Vec::new(),
        })
    }
}

//! The native engine: a TensorHolo CNN ([`CnnWeights`], read once by [`crate::model::graph`]) on the direct
//! 3×3 convolution kernels of `tensorholo-kernels` (f32; the kernel row is chosen at run time from the CPU's
//! instruction set, [`Isa::active`]).
//!
//! One frame, for `N` layers (`s_0` = the centred input `x − input_offset`, kept for the final concat):
//!
//! ```text
//! layer i < N−1:  s_{i+1} = ReLU(conv_i(s_i) + b_i) (+ s_{i−1} where i+1 is odd and ≥ 3)   ring of 3 buffers
//! layer N−1:      o = conv_{N−1}(concat(s_{N−1}, s_0)) + b                                 raw [6, H, W]
//! heads:          amplitude (tanh(o) + 1)·a, phase (tanh(o) + 1)·p                          hologram CNN
//! pre-filter:     o + depthwise_k×k(edge-replicated x)                                     [Re, Im]
//! ```
//!
//! Threads: each layer's output rows are split into one band per thread (halved recursively with
//! [`RowBand::split_at`] under `rayon::join`); the bands of a layer run in parallel on the plan's own rayon
//! pool (created once with the plan), and the next layer starts when all are done (a 3×3 convolution reads
//! one row above and below its band).
//!
//! Every activation buffer is allocated when the plan is built; a run allocates only its two output arrays
//! (the [`CnnPlan`] contract returns owned arrays).

use std::ops::Range;
use std::sync::Arc;

use ndarray::{Array3, ArrayView3, CowArray, Ix3};
use rayon::prelude::*;
use tensorholo_kernels::buffer::Element;
use tensorholo_kernels::{
    depthwise, fake_quantize, tanh_heads, Affine, Conv3x3F32, Conv3x3U8, Inputs, Isa, KernelError,
    QuantU8, RowBand, RowPlanar,
};

use super::{kernel_err, CnnPlan};
use crate::error::{HoloError, Result};
use crate::model::{CnnOutput, CnnWeights, QuantGrid};

/// The network's packed layers, shared by every plan of it (and by a stream's spawned plan).
#[derive(Debug)]
struct Network {
    graph: Arc<CnnWeights>,
    layers: Vec<Conv3x3F32>,
    /// The level the layers were packed for (also the heads' vector path).
    isa: Isa,
    /// Per input channel: the affine map of the input (scale 1, offset `−input_offset`).
    scale: Vec<f32>,
    offset: Vec<f32>,
}

/// A native plan: one network at one resolution, with its buffers and threads.
#[derive(Debug)]
pub(crate) struct NativePlan {
    net: Arc<Network>,
    height: usize,
    width: usize,
    threads: usize,
    /// The plan's worker threads (`None` with one thread: the caller's thread runs every band).
    pool: Option<Arc<rayon::ThreadPool>>,
    /// `s_0`: the centred input.
    x: RowPlanar<f32>,
    /// `s_1 …`: `s_k` lives in `ring[(k − 1) % 3]`.
    ring: [RowPlanar<f32>; 3],
    /// The last layer's raw output, `C_out` channels.
    raw: RowPlanar<f32>,
    /// Two rows of scratch for the pre-filter's depthwise base filter (grown on the first run).
    depthwise_scratch: Vec<f32>,
}

impl NativePlan {
    /// Packs `graph`'s layers for the best kernels of `isa` and allocates the buffers of `height × width`
    /// frames, run on `threads` threads (≥ 1).
    ///
    /// Errors: [`HoloError::InvalidData`] for non-finite weights; [`HoloError::InvalidParameter`] for 0
    /// threads; [`HoloError::Internal`] for an int8 graph (`NativeInt8Plan` runs those); [`HoloError::ModelRun`] for an ISA this CPU lacks, a size the kernels refuse or a thread
    /// pool the OS will not start.
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
        if graph.quant.is_some() {
            return Err(HoloError::Internal(
                "an int8 graph runs on the int8 native plan, not in f32".into(),
            ));
        }
        let n = graph.layers.len();
        let mut layers = Vec::with_capacity(n);
        for (i, l) in graph.layers.iter().enumerate() {
            if l.weights.iter().chain(&l.bias).any(|v| !v.is_finite()) {
                return Err(HoloError::InvalidData(format!(
                    "CNN layer {i} holds NaN or infinite weights"
                )));
            }
            layers.push(
                Conv3x3F32::new(&l.weights, &l.bias, l.c_in, l.c_out, i + 1 < n, isa)
                    .map_err(kernel_err)?,
            );
        }
        let c = graph.in_channels;
        let hidden = graph.layers[0].c_out;
        let c_out = graph.layers[n - 1].c_out;
        let net = Network {
            scale: vec![1.0; c],
            offset: vec![-graph.input_offset; c],
            graph,
            layers,
            isa,
        };
        let buf = |ch| RowPlanar::new(ch, height, width).map_err(kernel_err);
        Ok(Self {
            x: buf(c)?,
            ring: [buf(hidden)?, buf(hidden)?, buf(hidden)?],
            raw: buf(c_out)?,
            depthwise_scratch: Vec::new(),
            height,
            width,
            threads,
            pool: pool(threads)?,
            net: Arc::new(net),
        })
    }

    /// The kernel row every layer runs (e.g. `conv3x3.f32.6x2.avx2`).
    pub(crate) fn kernel_name(&self) -> &'static str {
        self.net.layers[0].kernel().name
    }

    /// Runs the convolutions of one frame whose input is already in `self.x`; the raw output lands in
    /// `self.raw`.
    fn forward(&mut self) -> Result<()> {
        let n = self.net.layers.len();
        let (threads, pool) = (self.threads, self.pool.as_deref());
        for (i, conv) in self.net.layers.iter().enumerate().take(n - 1) {
            // Layer i reads s_i (the input for i = 0), adds s_{i−1} where i + 1 is odd and ≥ 3, writes s_{i+1}.
            let out = i % 3;
            let residual = (i + 1 >= 3 && (i + 1) % 2 == 1).then_some((i + 1) % 3);
            let (dst, slot) = ring_slots(&mut self.ring, out);
            let src = if i == 0 { &self.x } else { slot((i + 2) % 3) };
            let mut inputs = Inputs::new(src);
            if let Some(r) = residual {
                inputs = inputs.residual(slot(r));
            }
            run_layer(conv, inputs, dst, threads, pool)?;
        }
        let last = if n >= 2 {
            &self.ring[(n - 2) % 3]
        } else {
            &self.x
        };
        let inputs = Inputs::new(last).concat(&self.x);
        run_layer(
            &self.net.layers[n - 1],
            inputs,
            &mut self.raw,
            threads,
            pool,
        )
    }
}

/// The ring slot `out` to write, and a reader of the other slots by index (`slot(k)`, `k ≠ out`).
pub(super) fn ring_slots<'a, T: Element>(
    ring: &'a mut [RowPlanar<T>; 3],
    out: usize,
) -> (
    &'a mut RowPlanar<T>,
    impl Fn(usize) -> &'a RowPlanar<T> + 'a,
) {
    let [a, b, c] = ring;
    let (dst, others): (&mut RowPlanar<T>, [&RowPlanar<T>; 2]) = match out {
        0 => (a, [b, c]),
        1 => (b, [a, c]),
        _ => (c, [a, b]),
    };
    (
        dst,
        move |k: usize| if k < out { others[k] } else { others[k - 1] },
    )
}

/// `input` in standard layout (a view when it already is), checked against the plan's `[C, H, W]`.
/// Errors: [`HoloError::ShapeMismatch`].
pub(super) fn standard_input(
    input: ArrayView3<'_, f32>,
    want: (usize, usize, usize),
) -> Result<CowArray<'_, f32, Ix3>> {
    if input.dim() != want {
        return Err(HoloError::ShapeMismatch {
            what: "CNN input [C, H, W]".into(),
            expected: vec![want.0, want.1, want.2],
            got: input.shape().to_vec(),
        });
    }
    Ok(if input.is_standard_layout() {
        CowArray::from(input)
    } else {
        CowArray::from(input.as_standard_layout().into_owned())
    })
}

/// The planar `[C][H][W]` slice of a standard-layout array.
pub(super) fn planar_slice<'a>(a: &'a CowArray<'_, f32, Ix3>) -> Result<&'a [f32]> {
    a.as_slice()
        .ok_or_else(|| HoloError::Internal("native CNN: standard layout".into()))
}

/// A planned convolution that writes row bands (f32 or u8 activations).
pub(super) trait BandConv<T: Element>: Sync {
    /// Computes the rows of `band` (see `Conv3x3F32::run_band`, `Conv3x3U8::run_band`).
    fn run_band(
        &self,
        inputs: Inputs<'_, T>,
        band: &mut RowBand<'_, T>,
    ) -> std::result::Result<(), KernelError>;
}

impl BandConv<f32> for Conv3x3F32 {
    fn run_band(
        &self,
        inputs: Inputs<'_, f32>,
        band: &mut RowBand<'_, f32>,
    ) -> std::result::Result<(), KernelError> {
        Conv3x3F32::run_band(self, inputs, band)
    }
}

impl BandConv<u8> for Conv3x3U8 {
    fn run_band(
        &self,
        inputs: Inputs<'_, u8>,
        band: &mut RowBand<'_, u8>,
    ) -> std::result::Result<(), KernelError> {
        Conv3x3U8::run_band(self, inputs, band)
    }
}

/// One layer on `threads` row bands of `dst`, in parallel on `pool`.
pub(super) fn run_layer<T: Element + Send + Sync, K: BandConv<T>>(
    conv: &K,
    inputs: Inputs<'_, T>,
    dst: &mut RowPlanar<T>,
    threads: usize,
    pool: Option<&rayon::ThreadPool>,
) -> Result<()> {
    in_bands(dst, threads, pool, &|band| conv.run_band(inputs, band))
}

/// `work` on `threads` near-equal row bands of `dst`, in parallel on `pool` (a layer, or the int8 input's
/// quantisation).
pub(super) fn in_bands<T: Element + Send + Sync>(
    dst: &mut RowPlanar<T>,
    threads: usize,
    pool: Option<&rayon::ThreadPool>,
    work: &(dyn Fn(&mut RowBand<'_, T>) -> std::result::Result<(), KernelError> + Sync),
) -> Result<()> {
    let h = dst.height();
    let band = dst.band_mut(0..h).map_err(kernel_err)?;
    on_threads(band, threads, pool, &|b| work(b))
}

/// What one thread does to its share of the rows.
pub(super) type BandWork<'w, B> =
    dyn Fn(&mut B) -> std::result::Result<(), KernelError> + Sync + 'w;

/// Frame rows owned by one thread's work: a [`RowBand`] of an activation buffer, or [`F32Rows`].
pub(super) trait Rows: Sized + Send {
    fn rows(&self) -> Range<usize>;
    /// Rows `start..y` and `y..end` (`start < y < end`).
    fn split_at(self, y: usize) -> std::result::Result<(Self, Self), KernelError>;
}

impl<T: Element + Send> Rows for RowBand<'_, T> {
    fn rows(&self) -> Range<usize> {
        RowBand::rows(self)
    }
    fn split_at(self, y: usize) -> std::result::Result<(Self, Self), KernelError> {
        RowBand::split_at(self, y)
    }
}

/// Rows `rows` of a raw f32 frame `[H][C][W]`: `data` holds exactly those rows.
pub(super) struct F32Rows<'a> {
    pub data: &'a mut [f32],
    pub rows: Range<usize>,
}

impl Rows for F32Rows<'_> {
    fn rows(&self) -> Range<usize> {
        self.rows.clone()
    }
    fn split_at(self, y: usize) -> std::result::Result<(Self, Self), KernelError> {
        let Range { start, end } = self.rows;
        let row_len = self.data.len() / (end - start);
        let (top, bottom) = self.data.split_at_mut((y - start) * row_len);
        Ok((
            F32Rows {
                data: top,
                rows: start..y,
            },
            F32Rows {
                data: bottom,
                rows: y..end,
            },
        ))
    }
}

/// `work` on `rows` split into `threads` near-equal bands, in parallel on `pool` (one band, on the calling
/// thread, without a pool).
pub(super) fn on_threads<B: Rows>(
    rows: B,
    threads: usize,
    pool: Option<&rayon::ThreadPool>,
    work: &BandWork<'_, B>,
) -> Result<()> {
    match pool {
        Some(pool) if threads > 1 => pool.install(|| split_run(rows, threads, work)),
        _ => split_run(rows, 1, work),
    }
    .map_err(kernel_err)
}

/// Runs `work` on `band` as `parts` near-equal bands: halves recursively through `rayon::join`, so that
/// nothing is allocated per layer.
fn split_run<B: Rows>(
    mut band: B,
    parts: usize,
    work: &BandWork<'_, B>,
) -> std::result::Result<(), KernelError> {
    let rows = band.rows();
    if parts <= 1 || rows.len() < 2 {
        return work(&mut band);
    }
    let left = parts / 2;
    let mid = (rows.start + rows.len() * left / parts).clamp(rows.start + 1, rows.end - 1);
    let (top, bottom) = band.split_at(mid)?;
    let (a, b) = rayon::join(
        || split_run(top, left, work),
        || split_run(bottom, parts - left, work),
    );
    a.and(b)
}

/// The kernels' u8 grid of a model tensor's grid.
pub(super) fn u8_grid(g: QuantGrid) -> QuantU8 {
    QuantU8 {
        scale: g.scale,
        zero_point: g.zero_point,
    }
}

/// A rayon pool of `threads` workers, or `None` for one thread.
pub(super) fn pool(threads: usize) -> Result<Option<Arc<rayon::ThreadPool>>> {
    if threads == 1 {
        return Ok(None);
    }
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("tensorholo-cnn-{i}"))
        .build()
        .map(|p| Some(Arc::new(p)))
        .map_err(|e| HoloError::ModelRun(format!("native CNN engine: thread pool: {e}")))
}

/// The network's two outputs from the last layer's raw output `o` (`raw_row(c, y)`: channel `c`, frame row
/// `y`, `W` values): the hologram CNN's heads `(tanh(o) + 1)·scale`, or the pre-filter's `o` plus its
/// depthwise base filter of `base_input` (`[C][H][W]`, the input as the base branch sees it). `grid`, for an
/// int8 file, rounds `o` to the u8 grid the file quantises the last convolution's output to (ONNX
/// `QuantizeLinear` then `DequantizeLinear`). The heads and the grid run on the kernels' vector code for
/// `isa` ([`tanh_heads`], [`fake_quantize`]); rows run in parallel on `pool`; allocates only the two arrays.
#[allow(clippy::too_many_arguments)]
pub(super) fn finish_outputs<'r>(
    graph: &CnnWeights,
    raw_row: &(dyn Fn(usize, usize) -> &'r [f32] + Sync),
    grid: Option<QuantGrid>,
    base_input: &[f32],
    [h, w]: [usize; 2],
    isa: Isa,
    pool: Option<&rayon::ThreadPool>,
    depthwise_scratch: &mut Vec<f32>,
) -> Result<(Array3<f32>, Array3<f32>)> {
    let plane = 3 * h * w;
    let heads = match &graph.output {
        CnnOutput::Heads {
            amplitude_scale,
            phase_scale,
        } => Some((*amplitude_scale, *phase_scale)),
        CnnOutput::Prefilter { .. } => None,
    };
    let grid = grid.map(u8_grid);
    let mut out = vec![0.0f32; 2 * plane];
    let row = |(i, o): (usize, &mut [f32])| {
        let (c, y) = (i / h, i % h);
        let r = raw_row(c, y);
        match heads {
            Some((a, p)) => tanh_heads(r, o, if c < 3 { a } else { p }, grid, isa),
            None => {
                o.copy_from_slice(r);
                grid.map_or(Ok(()), |g| fake_quantize(o, g, isa))
            }
        }
    };
    match pool {
        Some(pool) => pool.install(|| out.par_chunks_mut(w).enumerate().try_for_each(row)),
        None => out.chunks_mut(w).enumerate().try_for_each(row),
    }
    .map_err(kernel_err)?;
    if let CnnOutput::Prefilter { taps, base } = &graph.output {
        let c = graph.in_channels;
        depthwise(
            base_input,
            c,
            h,
            w,
            base,
            *taps,
            &mut out,
            true,
            depthwise_scratch,
        )
        .map_err(kernel_err)?;
    }
    let imag = out.split_off(plane);
    let shape_err = |_| HoloError::Internal("native CNN: output shape".into());
    Ok((
        Array3::from_shape_vec((3, h, w), out).map_err(shape_err)?,
        Array3::from_shape_vec((3, h, w), imag).map_err(shape_err)?,
    ))
}

impl CnnPlan for NativePlan {
    fn input_dim(&self) -> (usize, usize, usize) {
        (self.net.graph.in_channels, self.height, self.width)
    }

    fn run_outputs(&mut self, input: ArrayView3<f32>) -> Result<(Array3<f32>, Array3<f32>)> {
        let standard = standard_input(input, self.input_dim())?;
        let planar = planar_slice(&standard)?;
        let affine = Affine {
            scale: &self.net.scale,
            offset: &self.net.offset,
        };
        self.x
            .fill_from_planar(planar, Some(affine))
            .map_err(kernel_err)?;
        self.forward()?;
        let (h, w) = (self.height, self.width);
        let src = &self.raw;
        let raw_row = |c: usize, y: usize| src.row(c, y).unwrap_or(&[]);
        finish_outputs(
            &self.net.graph,
            &raw_row,
            None,
            planar,
            [h, w],
            self.net.isa,
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
            // Threads of a stream run at the same time: each plan gets its own workers (a failed pool
            // start leaves the copy on the caller's thread, which still computes the same frames).
            pool: pool(self.threads).ok().flatten(),
            x: self.x.clone(),
            ring: self.ring.clone(),
            raw: self.raw.clone(),
            depthwise_scratch: Vec::new(),
        })
    }
}

//! The native engine's f32 plan: a TensorHolo CNN ([`CnnWeights`], read once by [`crate::model::graph`]) on the direct
//! 3×3 convolution kernels of `tensorholo-kernels` (f32; the kernel row is chosen at run time from the CPU's
//! instruction set, the session's [`crate::cnn::CnnOptions::kernel_isa`]).
//!
//! One frame, for `N` layers (`s_0` = the centred input `x − input_offset`, kept for the final concat):
//!
//! ```text
//! layer i < N−1:  s_{i+1} = ReLU(conv_i(s_i) + b_i) (+ s_{i−1} where i+1 is odd and ≥ 3)
//! layer N−1:      o = conv_{N−1}(concat(s_{N−1}, s_0)) + b                                 raw [6, H, W]
//! heads:          amplitude (tanh(o) + 1)·a, phase (tanh(o) + 1)·p                          hologram CNN
//! pre-filter:     o + depthwise_k×k(edge-replicated x)                                     [Re, Im]
//! ```
//!
//! The frame runs in strips of rows, each layer a row behind the one before, every activation in a window
//! of a few rows ([`super::strips`]): a plan's activations take a budget of 32 MB whatever the frame size,
//! or what the minimum strip needs where that is more (30 layers at 1080p: 66 MB). A wide frame runs as a
//! few column slabs one after the other, through windows as wide as a slab ([`super::slabs`]: the 8-layer
//! network at 1080p in four slabs of 548 columns, bit-identical with the whole frame).
//!
//! Threads: each layer's strip is split into one band per thread (halved recursively with
//! [`tensorholo_kernels::RowBand::split_at`] under `rayon::join`); the bands of a layer run in parallel on the plan's own rayon
//! pool (created once with the plan, installed once per frame), and the next layer starts when all are done
//! (a 3×3 convolution reads one row above and below its band).
//!
//! Every activation window is allocated when the plan is built; a run allocates only its output (the
//! [`CnnPlan`] contract returns owned arrays).

use std::ops::Range;
use std::sync::Arc;

use ndarray::{Array3, ArrayView3, CowArray, Ix3};
use rayon::prelude::*;
use tensorholo_kernels::{
    depthwise_rows, fake_quantize, tanh_heads, Conv3x3F32, Inputs, Isa, KernelError, QuantU8,
    RowPlanar,
};

use super::algorithm::{self, Choice};
use super::slabs::{Cols, Slabs};
use super::strips::{
    advance_all, bands, bands_aligned, both, hidden_layers, installed, row_bytes, BandConv,
    F32Rows, Place, Strips, Window,
};
use super::PlanSpec;
use crate::cnn::plan::{check_output_planes, check_planes, CnnPlan};
use crate::error::{HoloError, Result};
use crate::model::{CnnOutput, CnnWeights, QuantGrid};

/// The network's packed layers, shared by every plan of it (and by a stream's spawned plan).
#[derive(Debug)]
struct Network {
    graph: Arc<CnnWeights>,
    layers: Vec<Conv3x3F32>,
    /// The level the layers were packed for (also the heads' vector path).
    isa: Isa,
}

/// A native plan: one network at one resolution, with its activation windows and threads.
#[derive(Debug)]
pub(crate) struct NativePlan {
    net: Arc<Network>,
    height: usize,
    threads: usize,
    /// The plan's worker threads (`None` with one thread: the caller's thread runs every band).
    pool: Option<Arc<rayon::ThreadPool>>,
    strips: Strips,
    /// The frame's column slabs (one: the whole frame), run one after the other on the same windows.
    slabs: Arc<Slabs>,
    /// `s_0`: the centred input (read by the first layer and by the last layer's concat).
    x: Window<f32>,
    /// `s_1 … s_{N−1}`.
    s: Vec<Window<f32>>,
    /// The last layer's raw output, `C_out` channels.
    raw: Window<f32>,
}

impl NativePlan {
    /// Packs `graph`'s layers for the kernel rows of `spec.isa`, each layer on the row `choice` gives, and
    /// allocates the activation windows of `spec`'s frames (strips of `strips::strip_rows` and column slabs
    /// of `Slabs::count_for` where `spec` sets none), run on `spec.threads` threads (≥ 1). The one
    /// constructor: the engine passes a session's [`CnnOptions`](crate::cnn::CnnOptions) through `spec`.
    ///
    /// Errors: [`HoloError::InvalidData`] for non-finite weights; [`HoloError::InvalidParameter`] for 0
    /// threads; [`HoloError::Internal`] for an int8 graph (`NativeInt8Plan` runs those);
    /// [`HoloError::ModelRun`] for an ISA this CPU lacks, a size the kernels refuse or a thread pool the OS
    /// will not start.
    pub(crate) fn new(graph: Arc<CnnWeights>, spec: PlanSpec, choice: Choice<'_>) -> Result<Self> {
        let PlanSpec {
            height,
            width,
            threads,
            isa,
            strip_rows: strip,
            slabs,
        } = spec;
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
            layers.push(algorithm::plan_layer(l, i + 1 < n, isa, choice)?);
        }
        let c = graph.in_channels;
        let hidden = graph.layers[0].c_out;
        let c_out = graph.layers[n - 1].c_out;
        // Each layer `step` rows behind the one before: 4 where a layer's tiles span 4 rows (F(4×4, 3×3)).
        let step = layers
            .iter()
            .map(|l| l.kernel().row_group())
            .max()
            .unwrap_or(1);
        let net = Network { graph, layers, isa };
        // Column slabs, all `slabs.width` columns wide: the windows are that wide.
        // A wrong column at a slab's edge spoils one tile's columns per layer (see `slabs`).
        let groups: Vec<usize> = net
            .layers
            .iter()
            .map(|l| l.kernel().column_group())
            .collect();
        let halo = groups.iter().sum();
        let count = slabs
            .unwrap_or_else(|| Slabs::count_for(width, hidden * std::mem::size_of::<f32>(), halo));
        let slabs = Slabs::new(width, &groups, count);
        let width = slabs.width;
        // Windows: the input (carry N·step + 1: the concat reads it N·step rows later, one above), s_1 …
        // s_{N−1} (carry 2·step: the next layer reads one row above its strip, the residual two layers on
        // its strip), the raw output (no carry).
        let (xb, hb, ob) = (
            row_bytes::<f32>(c, width),
            row_bytes::<f32>(hidden, width),
            row_bytes::<f32>(c_out, width),
        );
        let per_row = xb + (n - 1) * hb + ob;
        let fixed = (n * step + 3) * xb + (2 * step + 2) * (n - 1) * hb + 2 * ob;
        let strips = Strips::for_plan(strip, height, (n, step), [per_row, fixed], threads);
        let window = |ch, k: usize, carry| {
            Window::new(Place::new(strips.lag(k), carry), strips, |rows| {
                RowPlanar::new(ch, rows, width)
            })
        };
        let pool = pool(threads)?;
        reserve_scratch(&net.layers, pool.as_deref());
        Ok(Self {
            x: window(c, 0, n * step + 1)?,
            s: (1..n)
                .map(|k| window(hidden, k, 2 * step))
                .collect::<Result<_>>()?,
            raw: window(c_out, n, 0)?,
            strips,
            height,
            slabs: Arc::new(slabs),
            threads,
            pool,
            net: Arc::new(net),
        })
    }

    /// The kernel rows the layers run, each once in layer order, with how many layers run it (e.g.
    /// `conv3x3.f32.6x2.avx2 ×2 + conv3x3.f32.wino2x2.6x2.avx2 ×6`; one row alone: its name).
    pub(crate) fn kernel_name(&self) -> String {
        kernel_summary(self.net.layers.iter().map(|l| l.kernel().name))
    }

    /// One frame of a checked input into `out`.
    fn run(&mut self, input: Planes<'_>, out: &mut Outputs<'_>) -> Result<()> {
        let (h, w) = (self.height, self.frame_width());
        if self.forward(input, out)? {
            return Ok(());
        }
        finish_outputs(
            &self.net.graph,
            out,
            BaseInput::Planar(input),
            [h, w],
            self.net.isa,
            self.threads,
            self.pool.as_deref(),
        )
    }

    /// The frame's width in columns.
    fn frame_width(&self) -> usize {
        self.slabs.frame_width
    }

    /// Column slabs per frame ([`super::slabs`]).
    #[cfg(test)]
    pub(crate) fn slab_count(&self) -> usize {
        self.slabs.slabs.len()
    }

    /// Frame rows per strip.
    #[cfg(test)]
    pub(crate) fn strip_rows(&self) -> usize {
        self.strips.rows
    }

    /// One frame, strip by strip, on the plan's threads: the input `planar` `[C][H][W]` centred into the
    /// input window, every layer's strip, the heads (or the pre-filter's raw output) into `out`. A
    /// pre-filter's base filter is added to each strip's rows as they are written where the frame is one slab
    /// ([`FusedBase`]); returns whether it was.
    fn forward(&mut self, input: Planes<'_>, out: &mut Outputs<'_>) -> Result<bool> {
        let net = self.net.clone();
        let n = net.layers.len();
        let (threads, strips) = (self.threads, self.strips);
        let heads = heads_of(&net.graph);
        let (pool, slabs) = (self.pool.clone(), self.slabs.clone());
        let base = match slabs.slabs.len() {
            1 => FusedBase::of(&net.graph, input, self.height),
            _ => None,
        };
        let frame = || -> Result<()> {
            for slab in slabs.iter() {
                let cols = Cols {
                    frame_width: slabs.frame_width,
                    slab,
                };
                self.x.start_frame()?;
                for s in &mut self.s {
                    s.start_frame()?;
                }
                for m in 0..strips.steps {
                    let offset = -net.graph.input_offset;
                    input_rows(&mut self.x, input, offset, (strips, m, threads), cols)?;
                    hidden_layers(
                        &net.layers[..n - 1],
                        0,
                        Some(&self.x),
                        &mut self.s,
                        &slab.layers,
                        strips,
                        m,
                        threads,
                    )?;
                    let last = if n >= 2 { &self.s[n - 2] } else { &self.x };
                    let ctx = (heads, cols, net.isa, strips, m, threads, base);
                    last_layer_rows(&net.layers[n - 1], last, &self.x, &mut self.raw, ctx, out)?;
                    // The windows' carried rows to their tops, the copies in parallel (serial, they were
                    // 9 % of a 1080p frame's samples with F(4×4, 3×3) on 2 threads).
                    let (x, s) = (&mut self.x, &mut self.s);
                    both(
                        threads,
                        || x.advance(strips),
                        || advance_all(s, strips, threads),
                    )?;
                }
            }
            Ok(())
        };
        installed(pool.as_deref(), threads, frame)?;
        Ok(base.is_some())
    }
}

/// Grows the kernels' per-thread scratch for `layers` on the calling thread and on every thread of `pool`
/// ([`Conv3x3F32::reserve_scratch`]): a frame then allocates nothing, whichever thread runs which band.
fn reserve_scratch(layers: &[Conv3x3F32], pool: Option<&rayon::ThreadPool>) {
    let reserve = || layers.iter().for_each(Conv3x3F32::reserve_scratch);
    reserve();
    if let Some(pool) = pool {
        pool.broadcast(|_| reserve());
    }
}

/// The kernel rows of a plan's layers (`names`, in layer order) as reports name them: each row once, in
/// order of first use, with its layer count when the layers run more than one (`a ×2 + b ×6`).
pub(super) fn kernel_summary<'a>(names: impl Iterator<Item = &'a str>) -> String {
    let mut rows: Vec<(&str, usize)> = Vec::new();
    for name in names {
        match rows.iter_mut().find(|(n, _)| *n == name) {
            Some((_, count)) => *count += 1,
            None => rows.push((name, 1)),
        }
    }
    match rows.as_slice() {
        [(name, _)] => (*name).to_string(),
        _ => rows
            .iter()
            .map(|(n, c)| format!("{n} ×{c}"))
            .collect::<Vec<_>>()
            .join(" + "),
    }
}

/// Strip `m`'s new rows of the f32 input window `x`: `s_0 = x + offset` (`offset = −input_offset`) of the
/// planar input's columns of the slab `cols`, in `threads` row bands.
pub(super) fn input_rows(
    x: &mut Window<f32>,
    input: Planes<'_>,
    offset: f32,
    (strips, m, threads): (Strips, usize, usize),
    cols: Cols<'_>,
) -> Result<()> {
    let Some((rows, f0)) = x.new_rows(strips, m)? else {
        return Ok(());
    };
    let c = x.buf.channels();
    let y0 = rows.start;
    let band = x.buf.band_mut(rows).map_err(HoloError::from)?;
    bands(band, threads, &|b| {
        let f = f0 + b.rows().start - y0;
        for ch in 0..c {
            let at = [cols.frame_width, cols.slab.start];
            b.fill_channel_rows_at(ch, input.plane(ch), at, f, Some((1.0, offset)))?;
        }
        Ok(())
    })
}

/// What [`last_layer_rows`] needs of the plan: the heads ([`heads_of`]), the slab's columns, the vector
/// level, the strips, the strip index and the threads.
pub(super) type LastLayerCtx<'a> = (
    Option<(f32, f32)>,
    Cols<'a>,
    Isa,
    Strips,
    usize,
    usize,
    Option<FusedBase<'a>>,
);

/// Strip `m` of the f32 last layer: `o = conv(concat(s_{N−1}, s_0))` into the raw window, then its rows
/// through [`heads_rows`] (the raw output stays float) into `out`. `last` holds `s_{N−1}` in f32 (the f32
/// engine's own, or the mixed-precision int8 engine's dequantised copy), `x` the f32 input window.
pub(super) fn last_layer_rows(
    conv: &Conv3x3F32,
    last: &Window<f32>,
    x: &Window<f32>,
    raw: &mut Window<f32>,
    (heads, cols, isa, strips, m, threads, base): LastLayerCtx<'_>,
    out: &mut Outputs<'_>,
) -> Result<()> {
    let Some((rows, f0)) = raw.new_rows(strips, m)? else {
        return Ok(());
    };
    let inputs = Inputs::new(&last.buf)
        .concat(&x.buf)
        .shifted(raw.shift_from(last), raw.shift_from(x), 0)
        .frame_row(raw.first_row(strips, m));
    let band = raw.buf.band_mut(rows.clone()).map_err(HoloError::from)?;
    // The last layer's columns of the slab (the kept ones, where the slab's layers compute fewer than all).
    let c = cols.slab.layers.last();
    bands_aligned(band, threads, strips.step, &|b| {
        BandConv::run_band(conv, inputs, b, c.cloned())
    })?;
    let raw = &raw.buf;
    let raw_row = |c: usize, y: usize| raw.row(c, y - f0 + rows.start).unwrap_or(&[]);
    let frame_rows = f0..f0 + rows.len();
    heads_rows(
        heads, &raw_row, None, base, cols, frame_rows, isa, threads, out,
    )
}

/// A CNN input `[C][H][W]`: one planar slice, or one slice per channel plane ([`CnnPlan::run_planes`]).
#[derive(Clone, Copy)]
pub(super) enum Planes<'a> {
    /// `[C][H][W]` in one slice, `H·W` values per plane.
    Planar(&'a [f32], usize),
    Each(&'a [&'a [f32]]),
}

impl<'a> Planes<'a> {
    /// Channel `c`'s plane (`H·W` values; empty past the last channel).
    pub(crate) fn plane(&self, c: usize) -> &'a [f32] {
        match *self {
            Planes::Planar(p, hw) => p.get(c * hw..(c + 1) * hw).unwrap_or(&[]),
            Planes::Each(ps) => ps.get(c).copied().unwrap_or(&[]),
        }
    }
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

/// The heads' scales `(amplitude, phase)` of a hologram CNN; `None` for a pre-filter (raw output).
pub(super) fn heads_of(graph: &CnnWeights) -> Option<(f32, f32)> {
    match &graph.output {
        CnnOutput::Heads {
            amplitude_scale,
            phase_scale,
        } => Some((*amplitude_scale, *phase_scale)),
        CnnOutput::Prefilter { .. } => None,
    }
}

/// Where the network's six output channels are written, `H·W` values each: channel `c` of the last layer
/// (after the heads) lands in `planes[c]`, i.e. channels 0–2 are the first output `[3, H, W]` (amplitude heads,
/// or `Re` of a pre-filter) and 3–5 the second (phase heads, or `Im`). The caller's buffers
/// ([`CnnPlan::run_planes_into`]: a session's colour planes) or two owned arrays ([`owned_outputs`]).
pub(super) struct Outputs<'a> {
    planes: [&'a mut [f32]; 6],
}

impl<'a> Outputs<'a> {
    /// The six planes, checked to hold `hw` values each. Errors: [`HoloError::ShapeMismatch`].
    pub(crate) fn new(planes: [&'a mut [f32]; 6], hw: usize) -> Result<Self> {
        check_output_planes(&planes, hw)?;
        Ok(Self { planes })
    }

    /// The six channel planes, in the last layer's channel order.
    fn planes_mut(&mut self) -> impl Iterator<Item = &mut [f32]> + use<'_, 'a> {
        self.planes.iter_mut().map(|p| &mut **p)
    }
}

/// Runs `run` on two zeroed `[3, h, w]` arrays as its [`Outputs`] and returns them (what
/// [`CnnPlan::run_outputs`] returns; [`CnnPlan::run_planes_into`] writes into the caller's planes instead).
pub(super) fn owned_outputs(
    h: usize,
    w: usize,
    run: impl FnOnce(&mut Outputs<'_>) -> Result<()>,
) -> Result<(Array3<f32>, Array3<f32>)> {
    let hw = h * w;
    let mut first = Array3::<f32>::zeros((3, h, w));
    let mut second = Array3::<f32>::zeros((3, h, w));
    {
        let (a, b) = match (first.as_slice_mut(), second.as_slice_mut()) {
            (Some(a), Some(b)) => (a, b),
            _ => return Err(HoloError::Internal("native CNN: output layout".into())),
        };
        let (a0, a12) = a.split_at_mut(hw);
        let (a1, a2) = a12.split_at_mut(hw);
        let (b0, b12) = b.split_at_mut(hw);
        let (b1, b2) = b12.split_at_mut(hw);
        run(&mut Outputs::new([a0, a1, a2, b0, b1, b2], hw)?)?;
    }
    Ok((first, second))
}

/// Frame rows `rows` of the network's two outputs, written into `out` from the last layer's raw output `o`
/// (`raw_row(c, y)`: channel `c`, frame row `y`, the slab's columns of `cols`; the kept ones are written):
/// the hologram CNN's heads `(tanh(o) + 1)·scale`
/// (`heads`, [`heads_of`]) or the pre-filter's `o`. `grid`, for an int8 file, rounds `o` to the u8 grid the
/// file quantises the last convolution's output to (ONNX `QuantizeLinear` then `DequantizeLinear`); `base`,
/// for a pre-filter, adds its base filter to the rows written (after that rounding, as [`finish_outputs`]
/// does). On the
/// kernels' vector code for `isa` ([`tanh_heads`], [`fake_quantize`]); the six channels in parallel on the
/// current rayon pool when `threads > 1`.
#[allow(clippy::too_many_arguments)]
pub(super) fn heads_rows<'r>(
    heads: Option<(f32, f32)>,
    raw_row: &(dyn Fn(usize, usize) -> &'r [f32] + Sync),
    grid: Option<QuantGrid>,
    base: Option<FusedBase<'_>>,
    cols: Cols<'_>,
    rows: Range<usize>,
    isa: Isa,
    threads: usize,
    out: &mut Outputs<'_>,
) -> Result<()> {
    let grid = grid.map(u8_grid);
    let (w, keep) = (cols.frame_width, cols.slab.keep.clone());
    if base.is_some() && keep != (0..w) {
        return Err(HoloError::Internal(
            "native CNN: a base filter fused into a slab narrower than the frame".into(),
        ));
    }
    let from = keep.start - cols.slab.start..keep.end - cols.slab.start;
    let channel = |(c, plane): (usize, &mut [f32])| {
        for y in rows.clone() {
            let o = &mut plane[y * w + keep.start..y * w + keep.end];
            let r = raw_row(c, y).get(from.clone()).unwrap_or(&[]);
            match heads {
                Some((a, p)) => tanh_heads(r, o, if c < 3 { a } else { p }, grid, isa)?,
                None => {
                    o.copy_from_slice(r);
                    if let Some(g) = grid {
                        fake_quantize(o, g, isa)?;
                    }
                }
            }
        }
        match &base {
            Some(b) => b.add_rows(c, plane, rows.clone(), w, isa),
            None => Ok(()),
        }
    };
    if threads > 1 {
        out.planes
            .par_iter_mut()
            .enumerate()
            .try_for_each(|(c, p)| channel((c, &mut **p)))
    } else {
        out.planes_mut().enumerate().try_for_each(channel)
    }
    .map_err(HoloError::from)
}

/// A pre-filter's depthwise base filter (what [`finish_outputs`] adds to the whole output planes) added by
/// [`heads_rows`] to each strip's rows just after it writes them, while they are in cache: the separate pass
/// reads and writes the six output planes once more (100 MB at 1080p). The same [`depthwise_rows`] on the
/// same rows, so bit-identical. Only where one slab keeps every column and the base reads the planar input.
#[derive(Clone, Copy)]
pub(super) struct FusedBase<'a> {
    input: Planes<'a>,
    /// `[C][taps][taps]`.
    kernel: &'a [f32],
    taps: usize,
    height: usize,
}

impl<'a> FusedBase<'a> {
    /// The base filter of `graph` on `input` (`height` rows), or `None` for a hologram CNN.
    pub(super) fn of(graph: &'a CnnWeights, input: Planes<'a>, height: usize) -> Option<Self> {
        match &graph.output {
            CnnOutput::Prefilter { taps, base } => Some(Self {
                input,
                kernel: base,
                taps: *taps,
                height,
            }),
            _ => None,
        }
    }

    /// `plane[y] += base(input channel c)[y]` for frame rows `rows` of the `[H][w]` output plane `plane`.
    /// Errors: the kernels' ([`depthwise_rows`]), a kernel without channel `c`.
    fn add_rows(
        &self,
        c: usize,
        plane: &mut [f32],
        rows: Range<usize>,
        w: usize,
        isa: Isa,
    ) -> std::result::Result<(), KernelError> {
        let out = &mut plane[rows.start * w..rows.end * w];
        let hw = [self.height, w];
        add_base_rows(
            (self.kernel, self.taps, c),
            self.input.plane(c),
            hw,
            rows,
            out,
            isa,
        )
    }
}

/// `out += base(input)` on frame rows `rows` (`out`: exactly those rows of an `[h][w]` plane): channel `c` of
/// the pre-filter's depthwise base filter `(kernel [C][taps][taps], taps, c)` on that channel's input plane
/// ([`depthwise_rows`], edges replicated). Errors: the kernels', a kernel without channel `c`.
fn add_base_rows(
    (kernel, taps, c): (&[f32], usize, usize),
    input: &[f32],
    [h, w]: [usize; 2],
    rows: Range<usize>,
    out: &mut [f32],
    isa: Isa,
) -> std::result::Result<(), KernelError> {
    let k2 = taps * taps;
    let channel = kernel
        .get(c * k2..(c + 1) * k2)
        .ok_or(KernelError::Length {
            what: "pre-filter base kernel [C][taps][taps]",
            expected: (c + 1) * k2,
            got: kernel.len(),
        })?;
    depthwise_rows(input, h, w, channel, taps, rows, out, true, isa)
}

/// The input as a pre-filter's base branch reads it: the planar input `[C][H][W]`, or (int8 files) the input
/// rounded to the first layer's u8 grid, one channel at a time into `plane` (`H·W` values; the file's
/// `QuantizeLinear`/`DequantizeLinear` of `x + offset`, then `− offset`).
pub(super) enum BaseInput<'a> {
    Planar(Planes<'a>),
    Rounded {
        planar: Planes<'a>,
        offset: f32,
        grid: QuantGrid,
        isa: Isa,
        plane: &'a mut Vec<f32>,
    },
}

/// Completes the network's outputs in `out` ([`heads_rows`] of every row written): for a pre-filter, adds
/// its depthwise base filter of `base` ([`depthwise_rows`] on the kernels' vector path for `isa`), channel
/// by channel, each channel's rows in `threads` bands on `pool`; nothing for a hologram CNN.
pub(super) fn finish_outputs(
    graph: &CnnWeights,
    out: &mut Outputs<'_>,
    mut base: BaseInput<'_>,
    [h, w]: [usize; 2],
    isa: Isa,
    threads: usize,
    pool: Option<&rayon::ThreadPool>,
) -> Result<()> {
    let CnnOutput::Prefilter { taps, base: kernel } = &graph.output else {
        return Ok(());
    };
    installed(pool, threads, || {
        for (c, out_plane) in out.planes_mut().enumerate() {
            let input = match &mut base {
                BaseInput::Planar(p) => p.plane(c),
                BaseInput::Rounded {
                    planar,
                    offset,
                    grid,
                    isa,
                    plane,
                } => {
                    plane.clear();
                    plane.extend(planar.plane(c).iter().map(|v| v + *offset));
                    fake_quantize(plane, u8_grid(*grid), *isa).map_err(HoloError::from)?;
                    if *offset != 0.0 {
                        plane.iter_mut().for_each(|b| *b -= *offset);
                    }
                    &plane[..]
                }
            };
            let rows = F32Rows {
                data: out_plane,
                rows: 0..h,
            };
            bands(rows, threads, &|b| {
                let k = (&kernel[..], *taps, c);
                add_base_rows(k, input, [h, w], b.rows.clone(), b.data, isa)
            })?;
        }
        Ok(())
    })
}

impl CnnPlan for NativePlan {
    fn input_dim(&self) -> (usize, usize, usize) {
        (self.net.graph.in_channels, self.height, self.frame_width())
    }

    fn run_outputs(&mut self, input: ArrayView3<f32>) -> Result<(Array3<f32>, Array3<f32>)> {
        let standard = standard_input(input, self.input_dim())?;
        let planar = planar_slice(&standard)?;
        let hw = self.height * self.frame_width();
        owned_outputs(self.height, self.frame_width(), |out| {
            self.run(Planes::Planar(planar, hw), out)
        })
    }

    fn run_planes(&mut self, planes: &[&[f32]]) -> Result<(Array3<f32>, Array3<f32>)> {
        check_planes(planes, self.input_dim())?;
        owned_outputs(self.height, self.frame_width(), |out| {
            self.run(Planes::Each(planes), out)
        })
    }

    fn run_planes_into(&mut self, planes: &[&[f32]], outputs: [&mut [f32]; 6]) -> Result<()> {
        check_planes(planes, self.input_dim())?;
        let mut out = Outputs::new(outputs, self.height * self.frame_width())?;
        self.run(Planes::Each(planes), &mut out)
    }

    fn spawn(&self) -> Box<dyn CnnPlan> {
        Box::new(Self {
            net: self.net.clone(),
            height: self.height,
            threads: self.threads,
            // Threads of a stream run at the same time: each plan gets its own workers (a failed pool
            // start leaves the copy on the caller's thread, which still computes the same frames).
            pool: {
                let pool = pool(self.threads).ok().flatten();
                reserve_scratch(&self.net.layers, pool.as_deref());
                pool
            },
            strips: self.strips,
            slabs: self.slabs.clone(),
            x: self.x.clone(),
            s: self.s.clone(),
            raw: self.raw.clone(),
        })
    }
}

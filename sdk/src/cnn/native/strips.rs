//! Strip-mined execution of a native plan: the network runs a strip of `S` frame rows at a time, every layer
//! a row behind the layer before it, so that each activation lives in a **window** of a few rows instead of a
//! whole frame (a line buffer; no row is computed twice).
//!
//! At strip `m`, the layer that writes `s_k` (lag `k`: the input `s_0` has lag 0, the last layer's raw output
//! lag `N`) computes frame rows `mS − k .. (m+1)S − k`. A 3×3 convolution of `s_k` reads one row above and
//! below; the rows below are the ones the layer before wrote in this strip (it is one row ahead), the rows
//! above come from earlier strips: each window keeps `carry` rows of the previous strip at its top (2 for a
//! layer read by the next one and by a residual two layers on, `N + 1` for the input the final concat
//! reads). A window of `carry + S` interior rows therefore holds, at strip `m`, frame rows from `mS − lag −
//! carry` on; between two strips its last `carry` rows move to its top ([`Window::advance`]).
//!
//! Operands of one convolution sit at different frame rows in their windows; the kernels take the offsets
//! ([`tensorholo_kernels::Inputs::shifted`], [`Window::shift_from`]). Rows that stand for frame rows outside
//! the frame hold the border value (zero padding): the carried rows at the start of a frame
//! ([`Window::start_frame`]) and the new rows past the frame's edges ([`Window::new_rows`]).
//!
//! Memory: `Σ (carry + S + 2)·row` per plan instead of three whole frames: at 1080p, the 8-layer network's
//! 24-channel f32 activations take 0.19 MB a row, so 623 MB of whole-frame buffers become 29 MB (strips of
//! 16 rows; the f32 plan's column slabs make the rows narrower still: [`super::slabs`]).

use std::ops::Range;

use tensorholo_kernels::buffer::{padded_width, Element};
use tensorholo_kernels::{Conv3x3F32, Conv3x3U8, Inputs, KernelError, RowBand, RowPlanar};

use crate::error::{HoloError, Result};

/// Bytes the activation windows of one plan may take; the strip height is the largest that fits (see
/// [`strip_rows`]).
pub(super) const WINDOW_BUDGET_BYTES: usize = 32 << 20;

/// The fewest rows a strip has per thread (each thread computes a band of every layer's strip).
const MIN_ROWS_PER_THREAD: usize = 4;

/// The most rows a strip has (unless threads need more): a layer's strip is read by the next layer while
/// it is still in cache. Measured on Zen 4 (`TENSORHOLO_STRIP_ROWS`, `holo bench`): the 8-layer network at
/// 384² runs 15–20 % faster in strips of 8–16 rows than in one strip of the whole frame; at 1080p and for
/// 30 layers the strip height made no difference above the host's noise.
const MAX_ROWS: usize = 16;

/// How a plan's frames are cut: strips of `rows` frame rows, `steps` of them for a frame of `height` rows
/// and a network of `layers` layers, each layer `step` rows behind the one before (the last strip reaches
/// frame row `height − 1` of the last layer).
///
/// `step` is the most frame rows a layer's kernel computes as one tile
/// ([`tensorholo_kernels::KernelInfo::row_group`]): 1, or 4 where a layer runs Winograd F(4×4, 3×3). Strip
/// heights and lags are then multiples of it, so every layer's strip, and every thread's band of it (see
/// [`bands_aligned`]), starts at a tile's first row, and the rows a tile reads below its band are already in
/// the window.
#[derive(Clone, Copy, Debug)]
pub(super) struct Strips {
    pub rows: usize,
    pub height: usize,
    pub steps: usize,
    pub step: usize,
}

impl Strips {
    pub(crate) fn new(rows: usize, height: usize, layers: usize, step: usize) -> Self {
        let step = step.max(1);
        let lag = layers * step;
        // Clamped to the whole frame before rounding up: a strip taller than `height + lag` rows is one strip
        // (and `TENSORHOLO_STRIP_ROWS=18446744073709551615` rounds without overflowing).
        let rows = rows
            .clamp(1, (height + lag).max(1))
            .next_multiple_of(step)
            .min((height + lag).next_multiple_of(step));
        Self {
            rows,
            height,
            steps: (height + lag).div_ceil(rows),
            step,
        }
    }

    /// The strips of a plan of `layers` layers a `step` apart for frames of `height` rows: `strip` rows when
    /// given, else [`strip_rows`] for windows of `per_row` bytes per strip row and `fixed` bytes besides.
    pub(crate) fn for_plan(
        strip: Option<usize>,
        height: usize,
        (layers, step): (usize, usize),
        [per_row, fixed]: [usize; 2],
        threads: usize,
    ) -> Self {
        let step = step.max(1);
        let lag = layers * step;
        let rows = strip.unwrap_or_else(|| {
            // Every thread's band a whole number of tiles: a multiple of `step·threads` rows (12 rows on 2
            // threads would split 8 + 4), rounded down (within the budget; at 1080p the 8-layer network on 2
            // threads ran faster in strips of 8 rows than in 16: benchmarks/history/BENCHMARKS-2026.md, "Winograd F(4×4, 3×3)").
            let rows = strip_rows(height, lag, per_row, fixed, threads);
            match step {
                1 => rows,
                _ => {
                    let unit = step * threads.max(1);
                    (rows / unit).max(1) * unit
                }
            }
        });
        Self::new(rows, height, layers, step)
    }

    /// The lag of the activation `k` layers after the input: `k·step` rows.
    pub(crate) fn lag(&self, k: usize) -> usize {
        k * self.step
    }
}

/// Bytes of one buffer row (every channel, padded width) of a `c`-channel window of width `w`.
pub(super) fn row_bytes<T: Element>(c: usize, w: usize) -> usize {
    c.div_ceil(T::INTERLEAVE) * T::INTERLEAVE * padded_width(w) * std::mem::size_of::<T>()
}

/// The strip height for a plan whose windows take `per_row` bytes per strip row and `fixed` bytes besides
/// (carried and border rows): the most rows within [`WINDOW_BUDGET_BYTES`] up to `MAX_ROWS` (16), at least
/// `MIN_ROWS_PER_THREAD·threads` (4 per thread), at most `height + lag` (one strip for the whole frame).
/// `PlanRequest::strip_rows` replaces it (for benchmarks of the strip height).
pub(super) fn strip_rows(
    height: usize,
    lag: usize,
    per_row: usize,
    fixed: usize,
    threads: usize,
) -> usize {
    let whole = height + lag;
    let fit = WINDOW_BUDGET_BYTES.saturating_sub(fixed) / per_row.max(1);
    fit.min(MAX_ROWS)
        .max(MIN_ROWS_PER_THREAD * threads)
        .min(whole)
        .max(1)
}

/// Where an activation's rows sit in the frame: `lag` rows behind the strip (the layers between the network
/// input and it), with `carry` rows of the previous strip kept above its new rows.
#[derive(Clone, Copy, Debug)]
pub(super) struct Place {
    lag: usize,
    carry: usize,
}

/// The new rows of one strip in a window ([`Place::new_rows`]): all of them (interior rows `carry .. carry +
/// S`), and those inside the frame with the frame row of the first (`None` when this activation has not
/// reached the frame yet or has passed it).
pub(super) struct NewRows {
    pub all: Range<usize>,
    pub valid: Option<(Range<usize>, usize)>,
}

impl Place {
    pub(crate) fn new(lag: usize, carry: usize) -> Self {
        Self { lag, carry }
    }

    /// `lag + carry`: interior row 0 holds frame row `mS − (lag + carry)` at strip `m`.
    fn behind(self) -> isize {
        (self.lag + self.carry) as isize
    }

    /// The row offset of `operand` from this activation (the output), for
    /// [`tensorholo_kernels::Inputs::shifted`]: interior row `i` of `operand` holds this activation's frame
    /// row of interior row `i + d`.
    pub(crate) fn shift_from(self, operand: Place) -> isize {
        self.behind() - operand.behind()
    }

    /// The frame row held by interior row 0 at strip `m` (may be negative: above the frame).
    pub(crate) fn first_row(self, strips: Strips, m: usize) -> isize {
        m as isize * strips.rows as isize - self.behind()
    }

    /// The new rows of strip `m`: frame rows `mS − lag .. (m+1)S − lag`, at interior rows `carry ..`.
    pub(crate) fn new_rows(self, strips: Strips, m: usize) -> NewRows {
        let s = strips.rows as isize;
        let first = m as isize * s - self.lag as isize;
        let lo = first.max(0);
        let hi = (first + s).min(strips.height as isize);
        let to_row = |f: isize| (f - first) as usize + self.carry;
        NewRows {
            all: self.carry..self.carry + strips.rows,
            valid: (lo < hi).then(|| (to_row(lo)..to_row(hi), lo as usize)),
        }
    }
}

/// One activation of a strip-mined network: a [`RowPlanar`] of `carry + S` interior rows at its [`Place`].
#[derive(Clone, Debug)]
pub(super) struct Window<T: Element> {
    pub buf: RowPlanar<T>,
    pub place: Place,
}

impl<T: Element> Window<T> {
    /// A window at `place` for `strips`, its buffer made by `buffer(interior rows)`.
    pub(crate) fn new(
        place: Place,
        strips: Strips,
        buffer: impl FnOnce(usize) -> std::result::Result<RowPlanar<T>, KernelError>,
    ) -> Result<Self> {
        let buf = buffer(place.carry + strips.rows).map_err(HoloError::from)?;
        Ok(Self { buf, place })
    }

    /// The frame row interior row 0 holds at strip `m` ([`Place::first_row`]; for
    /// [`tensorholo_kernels::Inputs::frame_row`]).
    pub(crate) fn first_row(&self, strips: Strips, m: usize) -> isize {
        self.place.first_row(strips, m)
    }

    /// [`Place::shift_from`] of two windows.
    pub(crate) fn shift_from<U: Element>(&self, operand: &Window<U>) -> isize {
        self.place.shift_from(operand.place)
    }

    /// At the start of a frame: the carried rows stand for frame rows above the frame, so they hold the
    /// border value.
    pub(crate) fn start_frame(&mut self) -> Result<()> {
        self.buf
            .fill_rows_with_border(0..self.place.carry)
            .map_err(HoloError::from)
    }

    /// The new rows of strip `m` ([`Place::new_rows`]): those that stand for frame rows outside the frame
    /// are set to the border value (the next layer reads them as zero padding); returns the rows inside the
    /// frame and the frame row of the first.
    pub(crate) fn new_rows(
        &mut self,
        strips: Strips,
        m: usize,
    ) -> Result<Option<(Range<usize>, usize)>> {
        let NewRows { all, valid } = self.place.new_rows(strips, m);
        let (a, b) = match &valid {
            Some((rows, _)) => (rows.start, rows.end),
            None => (all.end, all.end),
        };
        for outside in [all.start..a, b..all.end] {
            self.buf
                .fill_rows_with_border(outside)
                .map_err(HoloError::from)?;
        }
        Ok(valid)
    }

    /// After a strip: moves the last `carry` rows to the top for the next strip.
    pub(crate) fn advance(&mut self, strips: Strips) -> Result<()> {
        let carry = self.place.carry;
        if carry == 0 {
            return Ok(());
        }
        self.buf
            .copy_rows(strips.rows..strips.rows + carry, 0)
            .map_err(HoloError::from)
    }
}

/// [`Window::advance`] of every window in `windows`, in parallel on the current rayon pool
/// when `threads > 1` (the copies are independent; halved recursively with `rayon::join`, nothing
/// allocated).
pub(super) fn advance_all<T: Element + Send>(
    windows: &mut [Window<T>],
    strips: Strips,
    threads: usize,
) -> Result<()> {
    match windows {
        [] => Ok(()),
        [w] => w.advance(strips),
        _ if threads <= 1 => windows.iter_mut().try_for_each(|w| w.advance(strips)),
        _ => {
            let (a, b) = windows.split_at_mut(windows.len() / 2);
            both(
                threads,
                || advance_all(a, strips, threads),
                || advance_all(b, strips, threads),
            )
        }
    }
}

/// `a` and `b`, at once on the current rayon pool when `threads > 1` (`rayon::join`), else one after the
/// other on the calling thread (no pool is entered).
pub(super) fn both(
    threads: usize,
    a: impl FnOnce() -> Result<()> + Send,
    b: impl FnOnce() -> Result<()> + Send,
) -> Result<()> {
    if threads > 1 {
        let (ra, rb) = rayon::join(a, b);
        ra.and(rb)
    } else {
        a().and_then(|()| b())
    }
}

/// A planned convolution that writes row bands of a window (f32 or u8 activations).
pub(super) trait BandConv<T: Element>: Sync {
    /// Computes the rows of `band`, every column (`cols` `None`: `Conv3x3F32::run_band`,
    /// `Conv3x3U8::run_band`) or columns `cols` only (`Conv3x3F32::run_band_columns`; the int8 rows compute
    /// whole rows: an error for them).
    fn run_band(
        &self,
        inputs: Inputs<'_, T>,
        band: &mut RowBand<'_, T>,
        cols: Option<Range<usize>>,
    ) -> std::result::Result<(), KernelError>;
}

impl BandConv<f32> for Conv3x3F32 {
    fn run_band(
        &self,
        inputs: Inputs<'_, f32>,
        band: &mut RowBand<'_, f32>,
        cols: Option<Range<usize>>,
    ) -> std::result::Result<(), KernelError> {
        match cols {
            Some(cols) => Conv3x3F32::run_band_columns(self, inputs, band, cols),
            None => Conv3x3F32::run_band(self, inputs, band),
        }
    }
}

impl BandConv<u8> for Conv3x3U8 {
    fn run_band(
        &self,
        inputs: Inputs<'_, u8>,
        band: &mut RowBand<'_, u8>,
        cols: Option<Range<usize>>,
    ) -> std::result::Result<(), KernelError> {
        match cols {
            Some(cols) => Err(KernelError::Shape {
                what: format!("the int8 rows compute whole rows, not columns {cols:?}"),
            }),
            None => Conv3x3U8::run_band(self, inputs, band),
        }
    }
}

/// Strip `m` of hidden layers: `layers[j]` is layer `i = first + j` (`first = 1` where the first layer runs
/// elsewhere: the mixed-precision int8 engine's float first layer). Layer `i` reads `s_i` (`x` for `i = 0`,
/// else `s[i − 1]`), adds `s_{i−1}` where `i + 1` is odd and ≥ 3 (the architecture's residual every two
/// layers), writes `s_{i+1}` = `s[i]`; each layer's strip in `threads` bands on the current rayon pool,
/// columns `cols[i]` of it (a column slab's [`Slab::layers`](super::slabs::Slab::layers); every column for
/// a layer past `cols`' end, e.g. all of them for an empty `cols`).
/// Errors: layer 0 without `x` ([`HoloError::Internal`]), the kernels' errors.
#[allow(clippy::too_many_arguments)]
pub(super) fn hidden_layers<T: Element + Send + Sync, K: BandConv<T>>(
    layers: &[K],
    first: usize,
    x: Option<&Window<T>>,
    s: &mut [Window<T>],
    cols: &[Range<usize>],
    strips: Strips,
    m: usize,
    threads: usize,
) -> Result<()> {
    for (j, conv) in layers.iter().enumerate() {
        let i = first + j;
        let (done, rest) = s.split_at_mut(i);
        let Some(dst) = rest.first_mut() else {
            break;
        };
        let Some((rows, _)) = dst.new_rows(strips, m)? else {
            continue;
        };
        let src = match (i, x) {
            (0, Some(x)) => x,
            (0, None) => {
                return Err(HoloError::Internal(
                    "hidden layer 0 without its input".into(),
                ))
            }
            _ => &done[i - 1],
        };
        let residual = (i + 1 >= 3 && (i + 1) % 2 == 1).then(|| &done[i - 2]);
        let mut inputs = Inputs::new(&src.buf);
        let mut d_r = 0;
        if let Some(r) = residual {
            inputs = inputs.residual(&r.buf);
            d_r = dst.shift_from(r);
        }
        let inputs = inputs
            .shifted(dst.shift_from(src), 0, d_r)
            .frame_row(dst.first_row(strips, m));
        let band = dst.buf.band_mut(rows).map_err(HoloError::from)?;
        let c = cols.get(i);
        bands_aligned(band, threads, strips.step, &|b| {
            conv.run_band(inputs, b, c.cloned())
        })?;
    }
    Ok(())
}

/// Runs `frame` with `pool` installed (its bands then run on the pool's threads), or on the calling thread for
/// one thread.
pub(super) fn installed<R: Send>(
    pool: Option<&rayon::ThreadPool>,
    threads: usize,
    frame: impl FnOnce() -> R + Send,
) -> R {
    match pool {
        Some(pool) if threads > 1 => pool.install(frame),
        _ => frame(),
    }
}

/// `work` on `rows` split into `threads` near-equal bands, in parallel on the current rayon pool (the plan's,
/// installed around the frame; one band on the calling thread for one thread).
pub(super) fn bands<B: Rows>(rows: B, threads: usize, work: &BandWork<'_, B>) -> Result<()> {
    split_run(rows, threads, 1, work).map_err(HoloError::from)
}

/// [`bands`], each band but the first starting at a multiple of `align` (a window's interior rows; the
/// windows a convolution writes keep their frame rows aligned to [`Strips::step`] there): rows that cannot
/// be split so run in fewer bands.
pub(super) fn bands_aligned<B: Rows>(
    rows: B,
    threads: usize,
    align: usize,
    work: &BandWork<'_, B>,
) -> Result<()> {
    split_run(rows, threads, align.max(1), work).map_err(HoloError::from)
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

/// Runs `work` on `band` as `parts` near-equal bands split at multiples of `align`: halves recursively
/// through `rayon::join`, so that nothing is allocated per layer.
fn split_run<B: Rows>(
    mut band: B,
    parts: usize,
    align: usize,
    work: &BandWork<'_, B>,
) -> std::result::Result<(), KernelError> {
    let rows = band.rows();
    if parts <= 1 || rows.len() < 2 {
        return work(&mut band);
    }
    let left = parts / 2;
    let mut mid = (rows.start + rows.len() * left / parts).clamp(rows.start + 1, rows.end - 1);
    if align > 1 {
        mid = (mid + align / 2) / align * align;
        if mid <= rows.start || mid >= rows.end {
            // Too few rows to split at a multiple of `align`.
            return work(&mut band);
        }
    }
    let (top, bottom) = band.split_at(mid)?;
    let (a, b) = rayon::join(
        || split_run(top, left, align, work),
        || split_run(bottom, parts - left, align, work),
    );
    a.and(b)
}

//! The f32 plan: [`Conv3x3F32`] packs the weights once for the kernel row it selected and runs any row band.

use super::inputs::Inputs;
use super::job::{F32Job, F32Out};
use super::row::{Algorithm, F32Row, KernelInfo};
use super::table;
use super::wino2x2;
use crate::buffer::band::RowBand;
use crate::buffer::planar::RowPlanar;
use crate::error::KernelError;
use crate::isa::Isa;
use crate::pack;
use std::ops::Range;

/// A planned f32 3×3 convolution `C_in → C_out` with bias and optional ReLU, packed for one kernel row.
#[derive(Clone, Debug)]
pub struct Conv3x3F32 {
    row: &'static F32Row,
    c_in: usize,
    c_out: usize,
    relu: bool,
    weights: Vec<f32>,
    bias: Vec<f32>,
}

impl Conv3x3F32 {
    /// Plans a convolution with the best f32 kernel row for `isa` and `c_out`
    /// ([`registry::selected_f32_for`](crate::registry::selected_f32_for): the first row `isa` includes that
    /// computes the fewest padding output channels, so a 6-channel last layer runs on the 6-channel AVX2 tile
    /// rather than the 8-channel AVX-512 one, which computes 2 of every 8 channels for nothing; which is
    /// faster depends on the CPU: [`registry::f32_rows_of`](crate::registry::f32_rows_of) lists both for a
    /// caller that times them).
    ///
    /// `weights` is `[C_out][C_in][3][3]` (PyTorch/ONNX OIHW order), `bias` is `[C_out]`; `relu` applies
    /// `max(·, 0)` after the bias. Errors: `isa` not available on this CPU ([`KernelError::Isa`]), a zero or
    /// too large channel count ([`KernelError::Dimension`]), wrong slice lengths ([`KernelError::Length`]).
    pub fn new(
        weights: &[f32],
        bias: &[f32],
        c_in: usize,
        c_out: usize,
        relu: bool,
        isa: Isa,
    ) -> Result<Self, KernelError> {
        Self::with_algorithm(weights, bias, c_in, c_out, relu, isa, Algorithm::Direct)
    }

    /// Plans a convolution as [`new`](Self::new) does, with the best row of `algorithm` for `isa` and `c_out`
    /// ([`registry::selected_f32_algorithm`](crate::registry::selected_f32_algorithm); the portable row of
    /// that algorithm when `isa` has no vector row of it). Errors: as [`new`](Self::new).
    pub fn with_algorithm(
        weights: &[f32],
        bias: &[f32],
        c_in: usize,
        c_out: usize,
        relu: bool,
        isa: Isa,
        algorithm: Algorithm,
    ) -> Result<Self, KernelError> {
        if !isa.is_available() {
            return Err(KernelError::Isa {
                name: isa.name().into(),
                why: "not available on this CPU",
            });
        }
        let row = table::select_f32_algorithm(isa, c_out, algorithm);
        Self::with_row(weights, bias, c_in, c_out, relu, row)
    }

    /// Plans a convolution with the kernel row named `name` (e.g. `conv3x3.f32.6x2.avx2`, see
    /// [`registry::f32_kernels`](crate::registry::f32_kernels)). Errors: as [`new`](Self::new), and
    /// [`KernelError::Kernel`] for an unknown name or a row this CPU cannot run.
    pub fn with_kernel(
        weights: &[f32],
        bias: &[f32],
        c_in: usize,
        c_out: usize,
        relu: bool,
        name: &str,
    ) -> Result<Self, KernelError> {
        let row = table::f32_rows()
            .find(|r| r.info.name == name && r.info.isa.is_available())
            .ok_or_else(|| KernelError::Kernel { name: name.into() })?;
        Self::with_row(weights, bias, c_in, c_out, relu, row)
    }

    fn with_row(
        weights: &[f32],
        bias: &[f32],
        c_in: usize,
        c_out: usize,
        relu: bool,
        row: &'static F32Row,
    ) -> Result<Self, KernelError> {
        let pack = match row.info.algorithm {
            Algorithm::Direct => pack::pack_f32,
            Algorithm::Winograd2x2 => pack::pack_winograd_f32,
            Algorithm::Winograd4x4 => pack::pack_winograd4_f32,
        };
        let (weights, bias) = pack(weights, bias, c_in, c_out, row.info.oc_tile)?;
        Ok(Self {
            row,
            c_in,
            c_out,
            relu,
            weights,
            bias,
        })
    }

    /// Prepares the calling thread for this plan: a Winograd plan's rows keep a scratch per thread (`V` and
    /// `M`, `P·(C_in + G)·tiles` f32 values, `P` = 16 or 36 points: 72 KiB for F(2×2, 3×3) and 28 input
    /// channels with AVX-512, 81 KiB for F(4×4, 3×3)), grown on first use;
    /// this grows it now, so that frames allocate nothing on any thread that called it. A direct plan needs
    /// nothing. Call it on every thread that will run the plan (e.g. `rayon::ThreadPool::broadcast`).
    pub fn reserve_scratch(&self) {
        let (points, tile_columns) = match self.row.info.algorithm {
            Algorithm::Direct => return,
            Algorithm::Winograd2x2 => (16, 2),
            Algorithm::Winograd4x4 => (36, 4),
        };
        wino2x2::reserve_scratch(wino2x2::scratch_len(
            points,
            self.c_in,
            self.row.info.oc_tile,
            self.row.info.px_tile / tile_columns,
        ));
    }

    /// The kernel row this plan runs.
    pub fn kernel(&self) -> &'static KernelInfo {
        &self.row.info
    }
    /// Input channels `C_in` (sum over both sources).
    pub fn c_in(&self) -> usize {
        self.c_in
    }
    /// Output channels `C_out`.
    pub fn c_out(&self) -> usize {
        self.c_out
    }

    /// The job of output rows `rows` (checked by the caller) and its kernel row origin `k` (kernel row `y` is
    /// output row `y + k`; 0 unless the inputs are [`shifted`](Inputs::shifted)).
    ///
    /// `cols` (checked by the caller) are the output columns computed: the kernel sees the buffers from column
    /// `cols.start` on (each operand's slice and the output's base moved on by that many values, the row
    /// stride unchanged) as a frame `cols.len()` columns wide, so its reads stay inside `cols.start − 1 ..
    /// cols.end + 1` for the columns it keeps, and it writes columns `cols` and zeros after them as far as its
    /// last vector reaches.
    fn job<'a>(
        &'a self,
        inputs: &Inputs<'a, f32>,
        rows: &Range<usize>,
        cols: &Range<usize>,
    ) -> (F32Job<'a>, usize) {
        let a = inputs.a;
        let (k, views) = inputs.kernel_view();
        // An absent operand's view is empty: it stays empty.
        let [sa, sb, sr] = views.map(|s| s.get(cols.start..).unwrap_or(&[]));
        let job = F32Job {
            a: sa,
            ca: a.channels(),
            b: sb,
            cb: inputs.b.map_or(0, |b| b.channels()),
            h: a.height(),
            w: cols.len(),
            wp: a.padded_width(),
            weights: &self.weights,
            bias: &self.bias,
            cout: self.c_out,
            relu: self.relu,
            residual: inputs.residual.map(|_| sr),
            y0: rows.start - k,
            y1: rows.end - k,
            phase: inputs.phase(k),
        };
        (job, k)
    }

    /// Computes output rows `rows` (frame rows, `0 ≤ start < end ≤ H`) into `out`, a [`RowPlanar`] of `C_out`
    /// channels and the inputs' `H × W`. Only the interior of those rows is written (and their right border
    /// rewritten with zeros). Errors: shape mismatches ([`KernelError::Shape`]; also an F(4×4, 3×3) row's
    /// band on [`shifted`](Inputs::shifted) windows that does not start at a multiple of 4 frame rows,
    /// [`KernelInfo::row_group`]), a bad row band ([`KernelError::Rows`]).
    pub fn run(
        &self,
        inputs: Inputs<'_, f32>,
        out: &mut RowPlanar<f32>,
        rows: Range<usize>,
    ) -> Result<(), KernelError> {
        self.run_band(inputs, &mut out.band_mut(rows)?)
    }

    /// Computes the rows of `band` (of a [`RowPlanar`] of `C_out` channels and the inputs' `H × W`, from
    /// [`RowPlanar::bands_mut`]): as [`run`](Self::run), for one thread's share of a layer. Errors: as `run`.
    pub fn run_band(
        &self,
        inputs: Inputs<'_, f32>,
        band: &mut RowBand<'_, f32>,
    ) -> Result<(), KernelError> {
        let w = band.w;
        self.run_band_columns(inputs, band, 0..w)
    }

    /// [`run_band`](Self::run_band) for output columns `cols` only (`0 ≤ start < end ≤ W`, `start` a multiple
    /// of [`KernelInfo::column_group`], so that the tiles are the whole row's): each computed column gets the
    /// bits the whole row's run gives it, from input columns `start − 1 .. end + 1` (the tiles of a Winograd
    /// row: up to the end of the tile holding column `end − 1`, plus one); columns before `start` are left
    /// as they are, and columns from `end` on up to the kernel's last vector (at most
    /// [`MAX_TILE`](crate::buffer::planar::MAX_TILE) past `end`, within the padded row) are set to zero. For
    /// a caller that computes a frame in column slabs and needs fewer columns of each layer than the one
    /// before. Errors: as `run_band`, and a column range that is empty, past `W` or not so aligned
    /// ([`KernelError::Shape`]).
    pub fn run_band_columns(
        &self,
        inputs: Inputs<'_, f32>,
        band: &mut RowBand<'_, f32>,
        cols: Range<usize>,
    ) -> Result<(), KernelError> {
        let (h, w) = (band.h, band.w);
        let group = self.row.info.column_group();
        if cols.start >= cols.end || cols.end > w || !cols.start.is_multiple_of(group) {
            return Err(KernelError::Shape {
                what: format!(
                    "output columns {cols:?} of a {w}-column row: not a non-empty range inside it \
                     starting at a multiple of {group} ({})",
                    self.row.info.name
                ),
            });
        }
        if band.c != self.c_out {
            return Err(KernelError::Shape {
                what: format!(
                    "output has {} channels, plan's C_out is {}",
                    band.c, self.c_out
                ),
            });
        }
        let rows = band.rows();
        inputs.check_grouped(
            self.c_in,
            self.c_out,
            h,
            w,
            &rows,
            self.row.info.row_group(),
        )?;
        let (job, k) = self.job(&inputs, &rows, &cols);
        // The kernel writes kernel row `y` at output row `y + k`: the band, seen from the kernel, starts `k`
        // rows earlier (`band.base ≥ (rows.start + 1)·stride ≥ k·stride`: `check` keeps `k ≤ rows.start`),
        // and its column 0 is the row's column `cols.start` (`< stride`: the band's first row, one row past
        // `base`'s, starts after it).
        let stride = band.data.len() / rows.len();
        let out = F32Out::Rows {
            data: band.data,
            base: band.base - k * stride - cols.start,
        };
        table::run_f32(self.row, &job, out)
    }

    /// Computes output rows `rows` into a planar `[C_out][H][W]` f32 slice (the last layer: raw values, no
    /// border). Errors: as [`run`](Self::run), and `out.len() != C_out·H·W` ([`KernelError::Length`]).
    pub fn run_planar(
        &self,
        inputs: Inputs<'_, f32>,
        out: &mut [f32],
        rows: Range<usize>,
    ) -> Result<(), KernelError> {
        let (h, w) = (inputs.a.height(), inputs.a.width());
        let expected = self.c_out * h * w;
        if out.len() != expected {
            return Err(KernelError::Length {
                what: "planar output",
                expected,
                got: out.len(),
            });
        }
        if inputs.shift.is_some() {
            return Err(KernelError::Shape {
                what: "a planar output takes whole-frame inputs, not shifted windows".into(),
            });
        }
        inputs.check_grouped(
            self.c_in,
            self.c_out,
            h,
            w,
            &rows,
            self.row.info.row_group(),
        )?;
        let (job, _) = self.job(&inputs, &rows, &(0..w));
        table::run_f32(self.row, &job, F32Out::Planar(out))
    }
}

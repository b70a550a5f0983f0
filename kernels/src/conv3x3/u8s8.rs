//! The int8 plan: u8 activations, s8 weights (one scale per output channel), i32 accumulation,
//! requantisation fused into the epilogue.
//!
//! # Zero points
//! Activation buffers are asymmetric u8 (`real = (q − zp)·scale`), and their border and padding channels hold
//! `zp` (see [`buffer`](crate::buffer)), so the kernels accumulate `acc = Σ w·q` over the raw u8 values,
//! padding included, and the correction `−Σ_s zp_s·Σ w_s` (per output channel, per source `s`) is constant:
//! the packing code folds it into the accumulator's start value (exact i32). Rows that feed SDOT with
//! `q ⊕ 0x80 = q − 128` (NEON dot product without i8mm) also fold `+128·Σw` into it. Both sources of a
//! concatenation must share one scale (the f32 multiplier is per output channel); their zero points may
//! differ.

use super::inputs::Inputs;
use super::job::{U8Job, U8Out};
use super::row::{KernelInfo, PackKind, U8Row};
use super::table;
use crate::buffer::band::RowBand;
use crate::buffer::planar::RowPlanar;
use crate::error::KernelError;
use crate::isa::Isa;
use crate::pack::{check_channels, check_len};
use crate::quant::{check_scale, QuantU8};
use std::ops::Range;

/// Largest int8 `C_in`: the i32 accumulator holds at least `255·128·9·4096 < 2³¹`.
pub const MAX_C_IN_U8: usize = 4096;

/// Everything an int8 convolution plan needs.
#[derive(Debug, Clone, Copy)]
pub struct Conv3x3U8Spec<'a> {
    /// Weights `[C_out][C_in][3][3]` (OIHW), symmetric s8.
    pub weights: &'a [i8],
    /// Weight scale per output channel, `[C_out]`.
    pub weight_scales: &'a [f32],
    /// Bias per output channel, `[C_out]`, in real (output) units.
    pub bias: &'a [f32],
    /// Channels of source `a` (`C_in = c_in_a + c_in_b`).
    pub c_in_a: usize,
    /// Channels of source `b` (0 when there is one source).
    pub c_in_b: usize,
    /// Output channels.
    pub c_out: usize,
    /// Scale shared by both sources.
    pub input_scale: f32,
    /// Zero point of source `a`.
    pub input_zero_point_a: u8,
    /// Zero point of source `b` (ignored when `c_in_b == 0`).
    pub input_zero_point_b: u8,
    /// ReLU after the bias.
    pub relu: bool,
    /// Quantisation of the residual buffer, when the layer adds one (after the ReLU).
    pub residual: Option<QuantU8>,
    /// Quantisation of the u8 output; `None` for a layer whose output is raw f32 ([`Conv3x3U8::run_planar`]).
    pub output: Option<QuantU8>,
}

/// A planned int8 3×3 convolution, packed for one kernel row.
#[derive(Clone, Debug)]
pub struct Conv3x3U8 {
    row: &'static U8Row,
    ca: usize,
    cb: usize,
    c_out: usize,
    zp_a: u8,
    zp_b: u8,
    relu: bool,
    residual: Option<QuantU8>,
    output: Option<QuantU8>,
    weights: Vec<u8>,
    init: Vec<i32>,
    mult: Vec<f32>,
    bias: Vec<f32>,
}

impl Conv3x3U8 {
    /// Plans with the best int8 row for `isa`. Errors: `isa` not available ([`KernelError::Isa`]), bad
    /// channel counts (0, or `C_in >` [`MAX_C_IN_U8`]: [`KernelError::Dimension`]), slice lengths ([`KernelError::Length`]), scales not finite
    /// and positive ([`KernelError::Parameter`]).
    pub fn new(spec: &Conv3x3U8Spec<'_>, isa: Isa) -> Result<Self, KernelError> {
        if !isa.is_available() {
            return Err(KernelError::Isa {
                name: isa.name().into(),
                why: "not available on this CPU",
            });
        }
        Self::with_row(spec, table::select_u8(isa))
    }

    /// Plans with the int8 row named `name` (see [`registry::u8_kernels`](crate::registry::u8_kernels)).
    /// Errors: as [`new`](Self::new), and [`KernelError::Kernel`] for an unknown name or a row this CPU
    /// cannot run.
    pub fn with_kernel(spec: &Conv3x3U8Spec<'_>, name: &str) -> Result<Self, KernelError> {
        let row = table::u8_rows()
            .find(|r| r.info.name == name && r.info.isa.is_available())
            .ok_or_else(|| KernelError::Kernel { name: name.into() })?;
        Self::with_row(spec, row)
    }

    fn with_row(s: &Conv3x3U8Spec<'_>, row: &'static U8Row) -> Result<Self, KernelError> {
        let (ca, cb, c_out) = (s.c_in_a, s.c_in_b, s.c_out);
        if ca == 0 {
            return Err(KernelError::Dimension {
                what: "C_in of source a",
                value: 0,
            });
        }
        check_channels(ca + cb, c_out)?;
        // |acc| ≤ 255·128·9·C_in must stay inside i32.
        if ca + cb > MAX_C_IN_U8 {
            return Err(KernelError::Dimension {
                what: "int8 C_in (at most 4096)",
                value: ca + cb,
            });
        }
        check_len(
            "weights [C_out][C_in][3][3]",
            s.weights.len(),
            c_out * (ca + cb) * 9,
        )?;
        check_len("weight scales [C_out]", s.weight_scales.len(), c_out)?;
        check_len("bias [C_out]", s.bias.len(), c_out)?;
        check_scale("input scale", s.input_scale)?;
        for (o, &ws) in s.weight_scales.iter().enumerate() {
            check_scale(&format!("weight scale [{o}]"), ws)?;
        }
        if let Some(b) = s.bias.iter().find(|b| !b.is_finite()) {
            return Err(KernelError::Parameter {
                what: format!("bias {b} is not finite"),
            });
        }
        for q in [s.residual, s.output].into_iter().flatten() {
            check_scale("residual/output scale", q.scale)?;
        }
        let g = row.info.oc_tile;
        let zp_b = if cb == 0 { 0 } else { s.input_zero_point_b };
        let (ga, gb) = (ca.div_ceil(4), cb.div_ceil(4));
        let groups = c_out.div_ceil(g);
        let cin = ca + cb;
        let wb = match row.pack {
            PackKind::I16 => 8,
            PackKind::I8 | PackKind::I8Xor128 => 4,
        };
        let mut weights = vec![0u8; groups * (ga + gb) * 9 * g * wb];
        let mut init = vec![0i32; groups * g];
        let mut mult = vec![0.0f32; groups * g];
        let mut bias = vec![0.0f32; groups * g];
        for o in 0..c_out {
            let (grp, lane) = (o / g, o % g);
            let mut corr: i64 = 0;
            for (gi, (src_first, src_c, zp)) in (0..ga)
                .map(|j| (j * 4, ca, s.input_zero_point_a))
                .chain((0..gb).map(|j| (ca + j * 4, ca + cb, zp_b)))
                .enumerate()
            {
                for t in 0..9 {
                    for l in 0..4 {
                        let ic = src_first + l;
                        if ic >= src_c {
                            continue;
                        }
                        let wv = s.weights[(o * cin + ic) * 9 + t];
                        corr += wv as i64 * zp as i64;
                        if row.pack == PackKind::I8Xor128 {
                            corr -= wv as i64 * 128;
                        }
                        let step = (grp * (ga + gb) + gi) * 9 + t;
                        let at = (step * g + lane) * wb;
                        match row.pack {
                            PackKind::I16 => weights[at + 2 * l..at + 2 * l + 2]
                                .copy_from_slice(&(wv as i16).to_le_bytes()),
                            _ => weights[at + l] = wv as u8,
                        }
                    }
                }
            }
            // |corr| ≤ 255·127·9·C_in, far inside i32 for C_in ≤ MAX_DIM.
            init[o] = -(corr as i32);
            mult[o] = s.input_scale * s.weight_scales[o];
            bias[o] = s.bias[o];
        }
        Ok(Self {
            row,
            ca,
            cb,
            c_out,
            zp_a: s.input_zero_point_a,
            zp_b,
            relu: s.relu,
            residual: s.residual,
            output: s.output,
            weights,
            init,
            mult,
            bias,
        })
    }

    /// The kernel row this plan runs.
    pub fn kernel(&self) -> &'static KernelInfo {
        &self.row.info
    }

    /// Input channels `C_in` (both sources).
    pub fn c_in(&self) -> usize {
        self.ca + self.cb
    }

    /// Output channels `C_out`.
    pub fn c_out(&self) -> usize {
        self.c_out
    }

    fn check(
        &self,
        inputs: &Inputs<'_, u8>,
        h: usize,
        w: usize,
        rows: &Range<usize>,
    ) -> Result<(), KernelError> {
        inputs.check(self.ca + self.cb, self.c_out, h, w, rows)?;
        let mismatch = |what: &str, got: u8, want: u8| KernelError::Shape {
            what: format!("{what} has zero point {got}, the plan expects {want}"),
        };
        if inputs.a.channels() != self.ca {
            return Err(KernelError::Shape {
                what: format!(
                    "source a has {} channels, the plan {}",
                    inputs.a.channels(),
                    self.ca
                ),
            });
        }
        if inputs.a.zero_point() != self.zp_a {
            return Err(mismatch("source a", inputs.a.zero_point(), self.zp_a));
        }
        if let Some(b) = inputs.b {
            if b.zero_point() != self.zp_b {
                return Err(mismatch("source b", b.zero_point(), self.zp_b));
            }
        }
        match (inputs.residual, self.residual) {
            (Some(r), Some(q)) if r.zero_point() != q.zero_point => {
                Err(mismatch("residual", r.zero_point(), q.zero_point))
            }
            (Some(_), None) => Err(KernelError::Shape {
                what: "residual given, the plan has none".into(),
            }),
            (None, Some(_)) => Err(KernelError::Shape {
                what: "the plan needs a residual".into(),
            }),
            _ => Ok(()),
        }
    }

    /// The job of output rows `rows` (checked by the caller) and its kernel row origin `k` (kernel row `y` is
    /// output row `y + k`; 0 unless the inputs are [`shifted`](Inputs::shifted)).
    fn job<'a>(&'a self, inputs: &Inputs<'a, u8>, rows: &Range<usize>) -> (U8Job<'a>, usize) {
        let a = inputs.a;
        let out = self.output.unwrap_or(QuantU8 {
            scale: 1.0,
            zero_point: 0,
        });
        let (k, [sa, sb, sr]) = inputs.kernel_view();
        let job = U8Job {
            a: sa,
            ga: a.groups(),
            b: sb,
            gb: inputs.b.map_or(0, |b| b.groups()),
            w: a.width(),
            wp: a.padded_width(),
            weights: &self.weights,
            init: &self.init,
            mult: &self.mult,
            bias: &self.bias,
            cout: self.c_out,
            relu: self.relu,
            residual: inputs
                .residual
                .zip(self.residual)
                .map(|(_, q)| (sr, q.zero_point as f32, q.scale)),
            out_inv: 1.0 / out.scale,
            out_zp: out.zero_point as f32,
            out_zp_u8: out.zero_point,
            y0: rows.start - k,
            y1: rows.end - k,
        };
        (job, k)
    }

    /// Computes output rows `rows` into `out`, a u8 [`RowPlanar`] of `C_out` channels whose zero point is the
    /// plan's output zero point. Errors: the plan has no u8 output, shapes or zero points that do not match
    /// ([`KernelError::Shape`]), a bad row band ([`KernelError::Rows`]).
    pub fn run(
        &self,
        inputs: Inputs<'_, u8>,
        out: &mut RowPlanar<u8>,
        rows: Range<usize>,
    ) -> Result<(), KernelError> {
        self.run_band(inputs, &mut out.band_mut(rows)?)
    }

    /// Computes the rows of `band` (of a u8 [`RowPlanar`] of `C_out` channels whose zero point is the plan's
    /// output zero point, from [`RowPlanar::band_mut`]): as [`run`](Self::run), for one thread's share of a
    /// layer. Errors: as `run`.
    pub fn run_band(
        &self,
        inputs: Inputs<'_, u8>,
        band: &mut RowBand<'_, u8>,
    ) -> Result<(), KernelError> {
        let q = self.output.ok_or_else(|| KernelError::Shape {
            what: "the plan has f32 output (output: None); use run_planar".into(),
        })?;
        if band.c != self.c_out || band.border != q.zero_point {
            return Err(KernelError::Shape {
                what: format!(
                    "output has {} channels and zero point {}, the plan {} and {}",
                    band.c, band.border, self.c_out, q.zero_point
                ),
            });
        }
        let rows = band.rows();
        self.check(&inputs, band.h, band.w, &rows)?;
        let (job, k) = self.job(&inputs, &rows);
        // As `Conv3x3F32::run_band`: seen from the kernel, the band starts `k ≤ rows.start` rows earlier.
        let stride = band.data.len() / rows.len();
        let out = U8Out::Rows {
            data: band.data,
            base: band.base - k * stride,
        };
        table::run_u8(self.row, &job, out)
    }

    /// Computes output rows `rows` as raw f32 (dequantised, before any output quantisation) into a planar
    /// `[C_out][H][W]` slice. Errors: as [`run`](Self::run), and `out.len() != C_out·H·W`.
    pub fn run_planar(
        &self,
        inputs: Inputs<'_, u8>,
        out: &mut [f32],
        rows: Range<usize>,
    ) -> Result<(), KernelError> {
        self.run_f32(inputs, out, rows, true)
    }

    /// Computes output rows `rows` as raw f32 (as [`run_planar`](Self::run_planar)) into `out`, which holds
    /// exactly those rows, each with every channel: `[rows.len()][C_out][W]` (row `y`, channel `o` at
    /// `((y − rows.start)·C_out + o)·W`). Disjoint row bands of one `[H][C_out][W]` frame are disjoint
    /// slices, so each may go to its own thread. Errors: as [`run`](Self::run), and `out.len() !=
    /// rows.len()·C_out·W`.
    pub fn run_rows_f32(
        &self,
        inputs: Inputs<'_, u8>,
        out: &mut [f32],
        rows: Range<usize>,
    ) -> Result<(), KernelError> {
        self.run_f32(inputs, out, rows, false)
    }

    /// Raw f32 output, planar `[C_out][H][W]` or the rows' `[rows][C_out][W]`.
    fn run_f32(
        &self,
        inputs: Inputs<'_, u8>,
        out: &mut [f32],
        rows: Range<usize>,
        planar: bool,
    ) -> Result<(), KernelError> {
        let (w, c) = (inputs.a.width(), self.c_out);
        // Shifted windows have no output buffer: the rows are in the output's frame, whose height only the
        // operands bound (checked there).
        let h = match inputs.shift {
            Some(_) if planar => {
                return Err(KernelError::Shape {
                    what: "a planar output takes whole-frame inputs, not shifted windows".into(),
                })
            }
            Some(_) => rows.end,
            None => inputs.a.height(),
        };
        self.check(&inputs, h, w, &rows)?;
        let (job, _) = self.job(&inputs, &rows);
        let (what, len, c_stride, y_stride, base) = if planar {
            ("planar output [C_out][H][W]", c * h * w, h * w, w, 0)
        } else {
            let n = rows.len();
            // Kernel rows `y0 = rows.start − k ..`: `data[0]` is kernel row `y0`.
            (
                "f32 output rows [rows][C_out][W]",
                n * c * w,
                w,
                c * w,
                job.y0 * c * w,
            )
        };
        check_len(what, out.len(), len)?;
        let out = U8Out::F32 {
            data: out,
            c_stride,
            y_stride,
            base,
        };
        table::run_u8(self.row, &job, out)
    }
}

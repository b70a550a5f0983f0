//! Direct 3×3 convolutions (stride 1, zero padding 1, no groups) on [`RowPlanar`] buffers.
//!
//! A plan ([`Conv3x3F32`]) packs the weights once for the kernel row it selected (see [`registry`]) and
//! then runs any row band `[y0, y1)` of a frame: every output pixel is computed by the same instruction
//! sequence whatever the band, so any split of the rows (over threads, say) gives bit-identical frames.
//!
//! Epilogue per output value: `v = conv + bias`; `v = max(v, 0)` when the plan has ReLU; `v += residual`
//! when a residual buffer is given (after the ReLU). Inputs may come from two buffers (channel
//! concatenation: channels `[0, Ca)` from `a`, `[Ca, Ca + Cb)` from `b`) so no copy is needed.

pub mod registry;

mod f32_scalar;
#[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
mod simd_f32;
#[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
mod simd_u8;
mod u8s8;
#[cfg(target_arch = "aarch64")]
mod u8s8_neon;
mod u8s8_scalar;
#[cfg(target_arch = "x86_64")]
mod u8s8_x86;

#[cfg(target_arch = "x86_64")]
mod f32_avx2;
#[cfg(target_arch = "x86_64")]
mod f32_avx512;
#[cfg(target_arch = "aarch64")]
mod f32_neon;

#[cfg(test)]
mod reference;
#[cfg(test)]
pub(crate) mod tests;

use crate::buffer::{Element, RowBand, RowPlanar};
use crate::pack;
use crate::{Isa, KernelError};
use registry::{F32Row, KernelInfo};
use std::ops::Range;
pub use u8s8::{Conv3x3U8, Conv3x3U8Spec, QuantU8, MAX_C_IN_U8};

/// The inputs of one convolution call: source `a`, an optional second source `b` concatenated after `a`'s
/// channels, and an optional residual added after the ReLU (same shape as the output).
#[derive(Clone, Copy, Debug)]
pub struct Inputs<'a, T: Element> {
    /// First source: channels `[0, Ca)` of the convolution input.
    pub a: &'a RowPlanar<T>,
    /// Second source: channels `[Ca, Ca + Cb)`; `None` when the input is `a` alone.
    pub b: Option<&'a RowPlanar<T>>,
    /// Residual `[C_out][H][W]` added after the ReLU; `None` for no residual.
    pub residual: Option<&'a RowPlanar<T>>,
    /// Row offsets `[a, b, residual]` of the operands from the output ([`Inputs::shifted`]); `None`: every
    /// buffer holds the whole frame.
    pub shift: Option<[isize; 3]>,
}

impl<'a, T: Element> Inputs<'a, T> {
    /// One source, no residual.
    pub fn new(a: &'a RowPlanar<T>) -> Self {
        Self {
            a,
            b: None,
            residual: None,
            shift: None,
        }
    }
    /// Adds a second source concatenated after `a`'s channels.
    pub fn concat(mut self, b: &'a RowPlanar<T>) -> Self {
        self.b = Some(b);
        self
    }
    /// Adds a residual.
    pub fn residual(mut self, r: &'a RowPlanar<T>) -> Self {
        self.residual = Some(r);
        self
    }

    /// Makes the buffers **windows** of a taller frame, each holding other frame rows (a network run a strip
    /// of rows at a time, every layer a few rows behind the one before): interior row `i` of operand `x`
    /// holds the frame row of the output's interior row `i + d_x`, for `d = [a, b, residual]` (ignored for an
    /// operand that is absent). The buffers' heights are then free: every row a call reads must lie inside
    /// its operand (rows `r − d − 1 ..= r + 1 − d` of the sources, buffer border rows included, and row `r −
    /// d` of the residual, for each output row `r`), which the call checks. The caller keeps the rows that
    /// stand for frame rows outside the frame at the border value (the zero padding).
    pub fn shifted(mut self, a: isize, b: isize, residual: isize) -> Self {
        self.shift = Some([a, b, residual]);
        self
    }

    /// The kernel's row origin `k` (output row `r` is kernel row `r − k`; 0 without [`shifted`](Self::shifted))
    /// and the three operands' storage from that origin on: source rows are read at kernel rows `y..=y + 2`
    /// and the residual at `y + 1`, as in a whole-frame buffer. Call after [`check`](Self::check).
    pub(crate) fn kernel_view(&self) -> (usize, [&'a [T]; 3]) {
        let d = self.shifts();
        let k = d.iter().copied().max().unwrap_or(0).max(0);
        let from = |b: Option<&'a RowPlanar<T>>, d: isize| -> &'a [T] {
            b.map_or(&[][..], |b| {
                // `k ≥ d`, so the offset is ≥ 0; `check` kept it inside the buffer.
                let rows = (k - d) as usize;
                &b.as_slice()[rows * b.row_stride()..]
            })
        };
        (
            k as usize,
            [
                from(Some(self.a), d[0]),
                from(self.b, d[1]),
                from(self.residual, d[2]),
            ],
        )
    }

    /// The row offsets `[a, b, residual]` that apply: 0 without [`shifted`](Self::shifted), and 0 for an
    /// absent operand whatever was given (only the operands a call reads are checked, so only theirs may move
    /// the kernel's row origin).
    fn shifts(&self) -> [isize; 3] {
        let d = self.shift.unwrap_or([0; 3]);
        [
            d[0],
            self.b.map_or(0, |_| d[1]),
            self.residual.map_or(0, |_| d[2]),
        ]
    }

    /// Checks the shapes against a plan of `c_in → c_out` and an output of `h × w`, and the row band; with
    /// [`shifted`](Self::shifted) operands, that every row the band reads lies inside its operand.
    pub(crate) fn check(
        &self,
        c_in: usize,
        c_out: usize,
        h: usize,
        w: usize,
        rows: &Range<usize>,
    ) -> Result<(), KernelError> {
        let d = match self.shift {
            Some(_) => self.shifts(),
            None => {
                // Whole frames: every operand has the output's height and width.
                let operands = [("source a", Some(self.a)), ("source b", self.b)];
                for (what, b) in operands.into_iter().chain([("residual", self.residual)]) {
                    if let Some(b) = b.filter(|b| b.height() != h || b.width() != w) {
                        return Err(KernelError::Shape {
                            what: format!(
                                "{what} is {}×{}, output is {h}×{w}",
                                b.height(),
                                b.width()
                            ),
                        });
                    }
                }
                [0; 3]
            }
        };
        self.check_shifted(c_in, c_out, h, w, rows, d)
    }

    /// What [`check`](Self::check) checks of every call: widths, channels, the row band, and every row the band
    /// reads inside its operand (with whole frames, `rows.end ≤ H`).
    fn check_shifted(
        &self,
        c_in: usize,
        c_out: usize,
        h: usize,
        w: usize,
        rows: &Range<usize>,
        d: [isize; 3],
    ) -> Result<(), KernelError> {
        if rows.start >= rows.end || rows.end > h {
            return Err(KernelError::Rows {
                start: rows.start,
                end: rows.end,
                height: h,
            });
        }
        let (r0, r1) = (rows.start as isize, rows.end as isize);
        // Buffer rows (border rows included: 0..H+2) of `b` that the band reads, `lo..hi`.
        let inside = |what: &str, b: &RowPlanar<T>, lo: isize, hi: isize| {
            if b.width() != w {
                return Err(KernelError::Shape {
                    what: format!("{what} is {} wide, output is {w}", b.width()),
                });
            }
            if lo < 0 || hi > b.height() as isize + 2 {
                return Err(KernelError::Shape {
                    what: format!(
                        "{what} holds buffer rows 0..{}, the band reads {lo}..{hi}",
                        b.height() + 2
                    ),
                });
            }
            Ok(())
        };
        inside("source a", self.a, r0 - d[0], r1 - d[0] + 2)?;
        let cb = match self.b {
            Some(b) => {
                inside("source b", b, r0 - d[1], r1 - d[1] + 2)?;
                b.channels()
            }
            None => 0,
        };
        if self.a.channels() + cb != c_in {
            return Err(KernelError::Shape {
                what: format!(
                    "input channels {} + {cb} != plan's C_in {c_in}",
                    self.a.channels()
                ),
            });
        }
        if let Some(r) = self.residual {
            // Interior rows only (the kernel row origin must not pass the band's first row).
            inside("residual", r, r0 - d[2], r1 - d[2] + 2)?;
            if r.channels() != c_out {
                return Err(KernelError::Shape {
                    what: format!(
                        "residual has {} channels, plan's C_out is {c_out}",
                        r.channels()
                    ),
                });
            }
        }
        Ok(())
    }
}

/// Everything an f32 kernel needs, checked by the safe API: the sources (`a` with `ca` channels, `b` with `cb`,
/// possibly 0), the frame `h × w` with padded row `wp`, the packed weights `[group][C_in][3][3][G]` and bias
/// `[group·G]` of the kernel's `G`, and the output rows `[y0, y1)`.
pub(crate) struct F32Job<'a> {
    pub a: &'a [f32],
    pub ca: usize,
    pub b: &'a [f32],
    pub cb: usize,
    pub h: usize,
    pub w: usize,
    pub wp: usize,
    pub weights: &'a [f32],
    pub bias: &'a [f32],
    pub cout: usize,
    pub relu: bool,
    pub residual: Option<&'a [f32]>,
    pub y0: usize,
    pub y1: usize,
}

/// Where an f32 kernel writes: a [`RowPlanar`] buffer of `C_out` channels (`[H+2][C_out][Wp]`) or a planar
/// `[C_out][H][W]` slice.
pub(crate) enum F32Out<'a> {
    /// Buffer rows of a `[H+2][C_out][Wp]` buffer: `data[0]` is element `base` of the whole buffer (a band of
    /// rows, [`RowBand`]); the kernel writes only rows `y0..y1`, which lie inside it.
    Rows {
        data: &'a mut [f32],
        base: usize,
    },
    Planar(&'a mut [f32]),
}

/// Everything an int8 kernel needs, checked by the safe API: sources `a`/`b` in the u8 layout with `ga`/`gb`
/// channel groups of 4, packed weights (bytes; i8 or i16 per the row's [`registry::PackKind`]), per output
/// channel (padded to the tile) the i32 accumulator start (zero-point corrections), the f32 multiplier and
/// bias; the residual `(buffer, zero point, scale)`; the output quantisation `1/scale` and zero point.
pub(crate) struct U8Job<'a> {
    pub a: &'a [u8],
    pub ga: usize,
    pub b: &'a [u8],
    pub gb: usize,
    pub w: usize,
    pub wp: usize,
    pub weights: &'a [u8],
    pub init: &'a [i32],
    pub mult: &'a [f32],
    pub bias: &'a [f32],
    pub cout: usize,
    pub relu: bool,
    pub residual: Option<(&'a [u8], f32, f32)>,
    pub out_inv: f32,
    /// Read by the SIMD rows only (none on other architectures).
    #[cfg_attr(
        not(any(target_arch = "x86_64", target_arch = "aarch64")),
        allow(dead_code)
    )]
    pub out_zp: f32,
    pub out_zp_u8: u8,
    pub y0: usize,
    pub y1: usize,
}

/// Where an int8 kernel writes: a u8 [`RowPlanar`] (`[H+2][C_out/4][Wp][4]`) or raw f32.
pub(crate) enum U8Out<'a> {
    /// Buffer rows of a u8 buffer: `data[0]` is element `base` of the whole buffer (a band of rows,
    /// [`RowBand`]); the kernel writes only rows `y0..y1`, which lie inside it.
    Rows { data: &'a mut [u8], base: usize },
    /// Raw f32: output channel `o`, row `y`, pixel `x` at `data[o·c_stride + y·y_stride + x − base]`
    /// (planar `[C_out][H][W]`: `c_stride = H·W`, `y_stride = W`, `base = 0`; a band of rows `y0..` of
    /// `[H][C_out][W]`: `c_stride = W`, `y_stride = C_out·W`, `base = y0·C_out·W`).
    F32 {
        data: &'a mut [f32],
        c_stride: usize,
        y_stride: usize,
        base: usize,
    },
}

impl U8Out<'_> {
    /// Index in `data` of the f32 output `(o, y, x)` (only for [`U8Out::F32`]).
    #[inline(always)]
    pub(crate) fn f32_index(
        c_stride: usize,
        y_stride: usize,
        base: usize,
        o: usize,
        y: usize,
        x: usize,
    ) -> usize {
        o * c_stride + y * y_stride + x - base
    }
}

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
    /// ([`registry::selected_f32_for`]: the first row `isa` includes that computes the fewest padding output
    /// channels, so a 6-channel last layer runs on the 6-channel AVX2 tile rather than the 8-channel AVX-512
    /// one, which would compute 2 of every 8 channels for nothing).
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
        if !isa.is_available() {
            return Err(KernelError::Isa {
                name: isa.name().into(),
                why: "not available on this CPU",
            });
        }
        Self::with_row(
            weights,
            bias,
            c_in,
            c_out,
            relu,
            registry::select_f32_for(isa, c_out),
        )
    }

    /// Plans a convolution with the kernel row named `name` (e.g. `conv3x3.f32.6x2.avx2`, see
    /// [`registry::f32_kernels`]). Errors: as [`new`](Self::new), and [`KernelError::Kernel`] for an unknown
    /// name or a row this CPU cannot run.
    pub fn with_kernel(
        weights: &[f32],
        bias: &[f32],
        c_in: usize,
        c_out: usize,
        relu: bool,
        name: &str,
    ) -> Result<Self, KernelError> {
        let row = registry::F32_ROWS
            .iter()
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
        let (weights, bias) = pack::pack_f32(weights, bias, c_in, c_out, row.info.oc_tile)?;
        Ok(Self {
            row,
            c_in,
            c_out,
            relu,
            weights,
            bias,
        })
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
    fn job<'a>(&'a self, inputs: &Inputs<'a, f32>, rows: &Range<usize>) -> (F32Job<'a>, usize) {
        let a = inputs.a;
        let (k, [sa, sb, sr]) = inputs.kernel_view();
        let job = F32Job {
            a: sa,
            ca: a.channels(),
            b: sb,
            cb: inputs.b.map_or(0, |b| b.channels()),
            h: a.height(),
            w: a.width(),
            wp: a.padded_width(),
            weights: &self.weights,
            bias: &self.bias,
            cout: self.c_out,
            relu: self.relu,
            residual: inputs.residual.map(|_| sr),
            y0: rows.start - k,
            y1: rows.end - k,
        };
        (job, k)
    }

    /// Computes output rows `rows` (frame rows, `0 ≤ start < end ≤ H`) into `out`, a [`RowPlanar`] of `C_out`
    /// channels and the inputs' `H × W`. Only the interior of those rows is written (and their right border
    /// rewritten with zeros). Errors: shape mismatches ([`KernelError::Shape`]), a bad row band
    /// ([`KernelError::Rows`]).
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
        let (h, w) = (band.h, band.w);
        if band.c != self.c_out {
            return Err(KernelError::Shape {
                what: format!(
                    "output has {} channels, plan's C_out is {}",
                    band.c, self.c_out
                ),
            });
        }
        let rows = band.rows();
        inputs.check(self.c_in, self.c_out, h, w, &rows)?;
        let (job, k) = self.job(&inputs, &rows);
        // The kernel writes kernel row `y` at output row `y + k`: the band, seen from the kernel, starts `k`
        // rows earlier (`band.base ≥ (rows.start + 1)·stride ≥ k·stride`: `check` keeps `k ≤ rows.start`).
        let stride = band.data.len() / rows.len();
        let out = F32Out::Rows {
            data: band.data,
            base: band.base - k * stride,
        };
        registry::run_f32(self.row, &job, out)
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
        inputs.check(self.c_in, self.c_out, h, w, &rows)?;
        let (job, _) = self.job(&inputs, &rows);
        registry::run_f32(self.row, &job, F32Out::Planar(out))
    }
}

//! The operands of one convolution call ([`Inputs`]): one or two sources, an optional residual, and the row
//! offsets that make the buffers windows of a taller frame ([`Inputs::shifted`]). Both plans check a call's
//! operands here and take the kernel's view of them from here.

use crate::buffer::planar::{Element, RowPlanar};
use crate::error::KernelError;
use std::ops::Range;

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
    /// The frame row of the output's interior row 0 ([`Inputs::frame_row`]; 0 for whole frames). Winograd
    /// rows pair output rows by frame row, so that every split into bands and windows gives the same bits.
    pub frame_row: isize,
}

impl<'a, T: Element> Inputs<'a, T> {
    /// One source, no residual.
    pub fn new(a: &'a RowPlanar<T>) -> Self {
        Self {
            a,
            b: None,
            residual: None,
            shift: None,
            frame_row: 0,
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

    /// Says which frame row the output's interior row 0 holds (with [`shifted`](Self::shifted) windows: the
    /// output window's first frame row; default 0, a whole frame). Only Winograd rows read it: they compute
    /// output rows in tiles of frame rows (`2j, 2j + 1` for F(2×2, 3×3); `4j .. 4j + 4` for F(4×4, 3×3),
    /// whose bands on windows must start at such a row), and a tile split between two calls is computed the
    /// same way by both, so bands, windows and threads never change a bit of the result.
    pub fn frame_row(mut self, row: isize) -> Self {
        self.frame_row = row;
        self
    }

    /// The frame row of kernel row 0 from origin `k` ([`kernel_view`](Self::kernel_view)), modulo 4: the
    /// Winograd rows' tile rows start where `y + phase` is a multiple of the tile's height (2 or 4).
    pub(crate) fn phase(&self, k: usize) -> usize {
        (k as isize + self.frame_row).rem_euclid(4) as usize
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
        self.check_grouped(c_in, c_out, h, w, rows, 1)
    }

    /// [`check`](Self::check) for a row whose tiles span `group` frame rows
    /// ([`KernelInfo::row_group`](crate::KernelInfo::row_group)): with [`shifted`](Self::shifted) windows, the
    /// band also starts at a group's first frame row, and the sources hold every row the band's last group
    /// reads (to one row past the group's end). Whole frames take any band.
    pub(crate) fn check_grouped(
        &self,
        c_in: usize,
        c_out: usize,
        h: usize,
        w: usize,
        rows: &Range<usize>,
        group: usize,
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
        let mut reads_to = rows.end as isize;
        if group > 1 && self.shift.is_some() && !rows.is_empty() {
            let g = group as isize;
            let first = rows.start as isize + self.frame_row;
            if first.rem_euclid(g) != 0 {
                return Err(KernelError::Shape {
                    what: format!(
                        "the band starts at frame row {first}: a row whose tiles span {group} rows runs on \
                         windows only from a multiple of {group}"
                    ),
                });
            }
            reads_to = (rows.start + rows.len().div_ceil(group) * group) as isize;
        }
        self.check_shifted(c_in, c_out, h, w, rows, d, reads_to)
    }

    /// What [`check`](Self::check) checks of every call: widths, channels, the row band, and every row the band
    /// reads inside its operand (with whole frames, `rows.end ≤ H`); the sources are read for output rows
    /// `rows.start..reads_to`.
    #[allow(clippy::too_many_arguments)]
    fn check_shifted(
        &self,
        c_in: usize,
        c_out: usize,
        h: usize,
        w: usize,
        rows: &Range<usize>,
        d: [isize; 3],
        reads_to: isize,
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
        inside("source a", self.a, r0 - d[0], reads_to - d[0] + 2)?;
        let cb = match self.b {
            Some(b) => {
                inside("source b", b, r0 - d[1], reads_to - d[1] + 2)?;
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

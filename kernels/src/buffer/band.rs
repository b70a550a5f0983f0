//! Bands and windows: [`RowBand`], frame rows of a buffer borrowed mutably (one thread's share, what a
//! kernel writes), and the operations on rows that let a buffer of a few rows stand for a taller frame (a
//! window, [`Inputs::shifted`](crate::Inputs::shifted)): whole-row fills and copies, f32 fills of a band from
//! other rows of a planar frame.

use std::ops::Range;

use super::planar::{Affine, Element, RowPlanar};
use crate::error::KernelError;

impl<T: Element> RowPlanar<T> {
    /// Frame rows `rows` as a mutable band, for a kernel to write ([`Conv3x3F32::run_band`]).
    /// Errors: an empty band or one past `H` ([`KernelError::Rows`]).
    ///
    /// [`Conv3x3F32::run_band`]: crate::Conv3x3F32::run_band
    pub fn band_mut(&mut self, rows: Range<usize>) -> Result<RowBand<'_, T>, KernelError> {
        if rows.start >= rows.end || rows.end > self.h {
            return Err(KernelError::Rows {
                start: rows.start,
                end: rows.end,
                height: self.h,
            });
        }
        let stride = self.row_stride();
        let (c, h, w, border) = (self.c, self.h, self.w, self.border);
        let base = (rows.start + 1) * stride;
        let data = &mut self.as_mut_slice()[base..(rows.end + 1) * stride];
        Ok(RowBand {
            data,
            base,
            rows,
            c,
            h,
            w,
            border,
        })
    }

    /// The frame's rows split into at most `n` disjoint bands of near-equal height (fewer when `H < n`; at
    /// least one), top to bottom: one per thread, so that threads write one buffer at the same time.
    pub fn bands_mut(&mut self, n: usize) -> Vec<RowBand<'_, T>> {
        let h = self.h;
        let n = n.clamp(1, h);
        let stride = self.row_stride();
        let (c, w, border) = (self.c, self.w, self.border);
        // Skip the top border row; the bottom border row is never handed out.
        let (_, mut rest) = self.as_mut_slice().split_at_mut(stride);
        let mut bands = Vec::with_capacity(n);
        let mut y0 = 0;
        for i in 0..n {
            let y1 = h * (i + 1) / n;
            let (band, tail) = rest.split_at_mut((y1 - y0) * stride);
            bands.push(RowBand {
                data: band,
                base: (y0 + 1) * stride,
                rows: y0..y1,
                c,
                h,
                w,
                border,
            });
            rest = tail;
            y0 = y1;
        }
        bands
    }

    /// Sets interior rows `rows` wholly (every column and channel) to the border value: rows of a window that
    /// stand for frame rows outside the frame, which the next layer must read as zero padding
    /// ([`Inputs::shifted`](crate::Inputs::shifted)). Errors: rows past `H` ([`KernelError::Rows`]).
    pub fn fill_rows_with_border(&mut self, rows: Range<usize>) -> Result<(), KernelError> {
        if rows.start > rows.end || rows.end > self.h {
            return Err(KernelError::Rows {
                start: rows.start,
                end: rows.end,
                height: self.h,
            });
        }
        let (stride, border) = (self.row_stride(), self.border);
        self.as_mut_slice()[(rows.start + 1) * stride..(rows.end + 1) * stride].fill(border);
        Ok(())
    }

    /// Copies interior rows `src` (whole rows: every column and channel) to interior rows `dst..`, as
    /// `copy_within`: a window moving down its frame keeps the rows the next strip still reads. Errors: rows
    /// past `H` ([`KernelError::Rows`]).
    pub fn copy_rows(&mut self, src: Range<usize>, dst: usize) -> Result<(), KernelError> {
        if src.start > src.end || src.end > self.h || dst + src.len() > self.h {
            return Err(KernelError::Rows {
                start: src.start,
                end: src.end,
                height: self.h,
            });
        }
        let stride = self.row_stride();
        self.as_mut_slice().copy_within(
            (src.start + 1) * stride..(src.end + 1) * stride,
            (dst + 1) * stride,
        );
        Ok(())
    }
}

/// Frame rows `rows` of a [`RowPlanar`] buffer, borrowed mutably ([`RowPlanar::band_mut`],
/// [`RowPlanar::bands_mut`]): what a kernel writes. Bands of one buffer never overlap, so each may go to its
/// own thread.
#[derive(Debug)]
pub struct RowBand<'a, T: Element> {
    /// Buffer rows `rows.start + 1 .. rows.end + 1`.
    pub(crate) data: &'a mut [T],
    /// Index of `data[0]` in the whole buffer's storage.
    pub(crate) base: usize,
    pub(crate) rows: Range<usize>,
    pub(crate) c: usize,
    pub(crate) h: usize,
    pub(crate) w: usize,
    /// The buffer's border value (the zero point of a u8 buffer).
    pub(crate) border: T,
}

impl<'a, T: Element> RowBand<'a, T> {
    /// The frame rows of the band.
    pub fn rows(&self) -> Range<usize> {
        self.rows.clone()
    }

    /// Index in `data` of channel `c`'s interior column 1 on frame row `y` (inside the band).
    pub(super) fn interior_at(&self, c: usize, y: usize) -> usize {
        let k = T::INTERLEAVE;
        let row_len = self.data.len() / self.rows.len();
        let wp = row_len / (self.c.div_ceil(k) * k);
        (y - self.rows.start) * row_len + ((c / k) * wp + 1) * k + c % k
    }

    /// Splits the band at frame row `y` into rows `start..y` and `y..end`, for two threads (no allocation:
    /// recursive splitting feeds a fork-join pool). Errors: `y` not strictly inside the band
    /// ([`KernelError::Rows`]).
    pub fn split_at(self, y: usize) -> Result<(Self, Self), KernelError> {
        let Range { start, end } = self.rows;
        if y <= start || y >= end {
            return Err(KernelError::Rows {
                start: y,
                end: y,
                height: self.h,
            });
        }
        let stride = self.data.len() / (end - start);
        let (top, bottom) = self.data.split_at_mut((y - start) * stride);
        let (c, h, w, base, border) = (self.c, self.h, self.w, self.base, self.border);
        Ok((
            RowBand {
                data: top,
                base,
                rows: start..y,
                c,
                h,
                w,
                border,
            },
            RowBand {
                data: bottom,
                base: base + (y - start) * stride,
                rows: y..end,
                c,
                h,
                w,
                border,
            },
        ))
    }
}
impl RowBand<'_, f32> {
    /// Overwrites the band's rows from rows `src_y0..` of a planar `[C][src_h][W]` frame (band row `y` takes
    /// source row `src_y0 + y − rows.start`), applying `x·scale[c] + offset[c]` when `affine` is given: the
    /// rows of a window ([`Inputs::shifted`](crate::Inputs::shifted)), one thread's share. Errors:
    /// `src.len() != C·src_h·W`, source rows past `src_h` or an affine slice whose length is not `C`
    /// ([`KernelError::Length`]).
    pub fn fill_rows_from_planar(
        &mut self,
        src: &[f32],
        src_h: usize,
        src_y0: usize,
        affine: Option<Affine<'_>>,
    ) -> Result<(), KernelError> {
        check_source(
            self.c * src_h * self.w,
            src.len(),
            src_y0 + self.rows.len(),
            src_h,
        )?;
        if let Some(a) = affine {
            for (what, s) in [("affine scale", a.scale), ("affine offset", a.offset)] {
                if s.len() != self.c {
                    return Err(KernelError::Length {
                        what,
                        expected: self.c,
                        got: s.len(),
                    });
                }
            }
        }
        let plane = src_h * self.w;
        for c in 0..self.c {
            let map = affine.map(|a| (a.scale[c], a.offset[c]));
            self.fill_channel_rows(c, &src[c * plane..(c + 1) * plane], src_y0, map)?;
        }
        Ok(())
    }

    /// Channel `c` of the band's rows from rows `src_y0..` of one plane `[src_h][W]` (`plane.len()` a
    /// multiple of `W`), as `x·m + b` when `affine = Some((m, b))`: [`fill_rows_from_planar`](
    /// Self::fill_rows_from_planar) for an input held plane by plane. Errors: `c ≥ C`, a plane whose length
    /// is not a multiple of `W` or rows past its end ([`KernelError::Length`]).
    pub fn fill_channel_rows(
        &mut self,
        c: usize,
        plane: &[f32],
        src_y0: usize,
        affine: Option<(f32, f32)>,
    ) -> Result<(), KernelError> {
        self.fill_channel_rows_at(c, plane, [self.w, 0], src_y0, affine)
    }

    /// [`fill_channel_rows`](Self::fill_channel_rows) from columns `x0 .. x0 + W` of a wider plane whose rows
    /// hold `stride` values (`[stride, x0]`): a column slab of a frame. Errors: as `fill_channel_rows`, and
    /// `x0 + W > stride` ([`KernelError::Length`]).
    pub fn fill_channel_rows_at(
        &mut self,
        c: usize,
        plane: &[f32],
        [stride, x0]: [usize; 2],
        src_y0: usize,
        affine: Option<(f32, f32)>,
    ) -> Result<(), KernelError> {
        let (w, y0) = (self.w, self.rows.start);
        if x0 + w > stride {
            return Err(KernelError::Length {
                what: "source plane row (columns of the band past the row's end)",
                expected: x0 + w,
                got: stride,
            });
        }
        check_plane(c, self.c, plane.len(), stride, src_y0 + self.rows.len())?;
        for y in self.rows() {
            let at = self.interior_at(c, y);
            let sy = src_y0 + y - y0;
            let row = &plane[sy * stride + x0..sy * stride + x0 + w];
            let dst = &mut self.data[at..at + w];
            match affine {
                Some((m, b)) => dst.iter_mut().zip(row).for_each(|(d, &v)| *d = v * m + b),
                None => dst.copy_from_slice(row),
            }
        }
        Ok(())
    }
}
/// Checks one channel plane of a source: `c < channels`, a whole number of rows of `w`, at least `end` rows.
pub(super) fn check_plane(
    c: usize,
    channels: usize,
    len: usize,
    w: usize,
    end: usize,
) -> Result<(), KernelError> {
    if c >= channels || !len.is_multiple_of(w) || len / w < end {
        return Err(KernelError::Length {
            what: "source channel plane [H][W] (channel, rows)",
            expected: end * w,
            got: len,
        });
    }
    Ok(())
}

/// Checks a planar source: `len == expected` and source rows up to `end ≤ src_h`.
pub(super) fn check_source(
    expected: usize,
    len: usize,
    end: usize,
    src_h: usize,
) -> Result<(), KernelError> {
    if len != expected {
        return Err(KernelError::Length {
            what: "planar source [C][H][W]",
            expected,
            got: len,
        });
    }
    if end > src_h {
        return Err(KernelError::Length {
            what: "planar source rows",
            expected: end,
            got: src_h,
        });
    }
    Ok(())
}

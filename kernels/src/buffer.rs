//! Activation buffers with a one-pixel border: [`RowPlanar`].
//!
//! # Layout and invariants
//!
//! A `RowPlanar<T>` of `C` channels and `H × W` pixels stores `H + 2` buffer rows; buffer row `r` holds frame
//! row `r − 1` (rows 0 and `H + 1` are the top and bottom border). Each buffer row holds, for each channel
//! group, `Wp` columns; column 0 is the left border, columns `1..=W` the pixels, columns `W+1..Wp` the right
//! border. `Wp = padded_width(W) = round_up(W + 2 + MAX_TILE, 16)`, so a kernel may load up to [`MAX_TILE`]
//! pixels past the last tile start without leaving the row, and store whole vectors of up to `MAX_TILE`
//! pixels (with the lanes past `W` set to the border value).
//!
//! * `f32`: logical shape `[H+2][C][Wp]`, one value per element; the border is `0.0`.
//! * `u8`: logical shape `[H+2][ceil(C/4)][Wp][4]`: four consecutive input channels of one pixel are
//!   adjacent, so one 32-bit lane holds the four `u8` inputs of a dot-product instruction (`vpdpbusd`,
//!   `UDOT`/`USDOT`). `C` is padded up to a multiple of 4 with channels that hold the zero point. The border
//!   (and the padding channels) hold the buffer's **zero point** `zp`, the quantised value of real 0, so
//!   zero padding of the convolution is exact for asymmetric activations; the packing code folds the
//!   constant `−zp·Σw` into the accumulator's start value.
//!
//! Kernels write only the interior (rows `1..=H`, columns `1..=W`) plus the right border of the rows they
//! compute, which they rewrite with the border value; rows 0 and `H + 1` and column 0 are never written.
//! [`RowPlanar::border_is_clean`] checks the invariant.

use std::ops::Range;

use crate::quant::{check_scale, quantize};
use crate::KernelError;

/// The widest pixel tile a kernel may use (pixels along a row); [`padded_width`] leaves this much slack.
pub const MAX_TILE: usize = 64;

/// Largest height, width or channel count accepted (keeps every index computation far from overflow).
pub const MAX_DIM: usize = 1 << 16;

/// The padded row length `Wp` used for a frame of width `w`: `round_up(w + 2 + MAX_TILE, 16)` elements
/// (pixels).
pub fn padded_width(w: usize) -> usize {
    (w + 2 + MAX_TILE).next_multiple_of(16)
}

mod sealed {
    pub trait Sealed {}
    impl Sealed for f32 {}
    impl Sealed for u8 {}
}

/// An element type of a [`RowPlanar`] buffer (`f32` or `u8`); sealed.
pub trait Element: sealed::Sealed + Copy + Default + PartialEq + std::fmt::Debug + 'static {
    /// Channels interleaved per pixel: 1 for `f32`, 4 for `u8`.
    const INTERLEAVE: usize;
}
impl Element for f32 {
    const INTERLEAVE: usize = 1;
}
impl Element for u8 {
    const INTERLEAVE: usize = 4;
}

/// An activation buffer `[H+2][ceil(C/K)][Wp][K]` with a one-pixel border (K = 1 for `f32`, 4 for `u8`); see
/// the [module documentation](self) for the layout and its invariants.
#[derive(Clone, Debug)]
pub struct RowPlanar<T: Element> {
    c: usize,
    h: usize,
    w: usize,
    wp: usize,
    border: T,
    /// Storage with up to 64 bytes of slack in front: the buffer starts at `data[off]`, chosen so that
    /// column 1 of every row lies on a 64-byte boundary (fewer cache-line-splitting loads and stores). A
    /// clone may have another alignment; only speed depends on it.
    data: Vec<T>,
    off: usize,
    len: usize,
}

impl<T: Element> PartialEq for RowPlanar<T> {
    fn eq(&self, other: &Self) -> bool {
        (self.c, self.h, self.w, self.border) == (other.c, other.h, other.w, other.border)
            && self.as_slice() == other.as_slice()
    }
}

pub(crate) fn check_dims(c: usize, h: usize, w: usize) -> Result<(), KernelError> {
    for (what, value) in [("channels", c), ("height", h), ("width", w)] {
        if value == 0 || value > MAX_DIM {
            return Err(KernelError::Dimension { what, value });
        }
    }
    let groups = c.div_ceil(4) * 4;
    let total = (h + 2)
        .checked_mul(groups)
        .and_then(|x| x.checked_mul(padded_width(w)))
        .filter(|&n| n <= (isize::MAX as usize) / 8);
    if total.is_none() {
        return Err(KernelError::Dimension {
            what: "channels × height × width",
            value: c * h,
        });
    }
    Ok(())
}

impl<T: Element> RowPlanar<T> {
    fn with_border(c: usize, h: usize, w: usize, border: T) -> Result<Self, KernelError> {
        check_dims(c, h, w)?;
        let wp = padded_width(w);
        let groups = c.div_ceil(T::INTERLEAVE);
        let len = (h + 2) * groups * wp * T::INTERLEAVE;
        let size = std::mem::size_of::<T>();
        let data = vec![border; len + 64 / size];
        // Column 1 is 4 bytes into a row in both layouts (one f32, or one pixel of 4 u8).
        let addr = data.as_ptr() as usize;
        let off = (64 - (addr + 4) % 64) % 64 / size;
        Ok(Self {
            c,
            h,
            w,
            wp,
            border,
            data,
            off,
            len,
        })
    }

    /// Channels `C` (not counting padding channels).
    pub fn channels(&self) -> usize {
        self.c
    }
    /// Frame height `H` in pixels (without the border).
    pub fn height(&self) -> usize {
        self.h
    }
    /// Frame width `W` in pixels (without the border).
    pub fn width(&self) -> usize {
        self.w
    }
    /// The padded row length `Wp` in pixels ([`padded_width`]).
    pub fn padded_width(&self) -> usize {
        self.wp
    }
    /// The raw storage, `[H+2][ceil(C/K)][Wp][K]` elements.
    pub fn as_slice(&self) -> &[T] {
        &self.data[self.off..self.off + self.len]
    }
    pub(crate) fn as_mut_slice(&mut self) -> &mut [T] {
        &mut self.data[self.off..self.off + self.len]
    }
    /// Elements of one buffer row: `ceil(C/K) · Wp · K`.
    pub(crate) fn row_stride(&self) -> usize {
        self.groups() * self.wp * T::INTERLEAVE
    }

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

    /// Channel groups `ceil(C/K)` stored per buffer row.
    pub(crate) fn groups(&self) -> usize {
        self.c.div_ceil(T::INTERLEAVE)
    }

    /// Index in [`as_slice`](Self::as_slice) of channel `c`, buffer row `r` (0..H+2), buffer column `j`
    /// (0..Wp).
    fn index(&self, c: usize, r: usize, j: usize) -> usize {
        let k = T::INTERLEAVE;
        ((r * self.groups() + c / k) * self.wp + j) * k + c % k
    }

    /// The value of channel `c` at pixel `(y, x)` (frame coordinates, without the border); `None` outside.
    pub fn get(&self, c: usize, y: usize, x: usize) -> Option<T> {
        (c < self.c && y < self.h && x < self.w)
            .then(|| self.as_slice()[self.index(c, y + 1, x + 1)])
    }

    /// True when every element outside the interior (rows 0 and `H+1`, column 0, columns past `W`, padding
    /// channels) holds the border value (0 for `f32`, the zero point for `u8`). For tests and debug checks.
    pub fn border_is_clean(&self) -> bool {
        let k = T::INTERLEAVE;
        let groups = self.groups();
        for r in 0..self.h + 2 {
            for g in 0..groups {
                for j in 0..self.wp {
                    for l in 0..k {
                        let c = g * k + l;
                        let inside = r >= 1 && r <= self.h && j >= 1 && j <= self.w && c < self.c;
                        if !inside
                            && self.as_slice()[((r * groups + g) * self.wp + j) * k + l]
                                != self.border
                        {
                            return false;
                        }
                    }
                }
            }
        }
        true
    }

    fn check_planar(&self, len: usize) -> Result<(), KernelError> {
        let expected = self.c * self.h * self.w;
        if len != expected {
            return Err(KernelError::Length {
                what: "planar [C][H][W] slice",
                expected,
                got: len,
            });
        }
        Ok(())
    }

    /// Copies the interior out to a planar `[C][H][W]` slice. Errors: `out.len() != C·H·W`.
    pub fn read_planar(&self, out: &mut [T]) -> Result<(), KernelError> {
        self.check_planar(out.len())?;
        let (h, w) = (self.h, self.w);
        for c in 0..self.c {
            for y in 0..h {
                for x in 0..w {
                    out[(c * h + y) * w + x] = self.as_slice()[self.index(c, y + 1, x + 1)];
                }
            }
        }
        Ok(())
    }

    /// The interior as a planar `[C][H][W]` vector.
    pub fn to_planar(&self) -> Vec<T> {
        let mut out = vec![T::default(); self.c * self.h * self.w];
        // The length is right by construction.
        let _ = self.read_planar(&mut out);
        out
    }

    /// Fills the interior from a planar `[C][H][W]` slice, converting each value with `f(channel, value)`.
    fn fill_with<S: Copy>(
        &mut self,
        src: &[S],
        f: impl Fn(usize, S) -> T,
    ) -> Result<(), KernelError> {
        self.check_planar(src.len())?;
        let (h, w, k) = (self.h, self.w, T::INTERLEAVE);
        for c in 0..self.c {
            for y in 0..h {
                // Row y of channel c: `w` elements `k` apart from column 1 (one slice, one bounds check).
                let start = self.index(c, y + 1, 1);
                let dst = &mut self.as_mut_slice()[start..start + (w - 1) * k + 1];
                let row = &src[(c * h + y) * w..(c * h + y + 1) * w];
                for (d, &v) in dst.iter_mut().step_by(k).zip(row) {
                    *d = f(c, v);
                }
            }
        }
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
    fn interior_at(&self, c: usize, y: usize) -> usize {
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

/// A per-channel affine map `x·scale[c] + offset[c]` applied while filling a buffer (e.g. input centring
/// `x − 0.5`: scale 1, offset −0.5). Both slices have one value per channel.
#[derive(Clone, Copy, Debug)]
pub struct Affine<'a> {
    /// Multiplier per channel.
    pub scale: &'a [f32],
    /// Offset per channel, added after the multiplication.
    pub offset: &'a [f32],
}

impl RowPlanar<f32> {
    /// A zeroed buffer of `c` channels and `h × w` pixels. Errors: a zero or too large dimension
    /// ([`KernelError::Dimension`]).
    pub fn new(c: usize, h: usize, w: usize) -> Result<Self, KernelError> {
        Self::with_border(c, h, w, 0.0)
    }

    /// A buffer filled from a planar `[c][h][w]` slice, with an optional per-channel affine map. Errors: as
    /// [`new`](Self::new) and [`fill_from_planar`](Self::fill_from_planar).
    pub fn from_planar(
        src: &[f32],
        c: usize,
        h: usize,
        w: usize,
        affine: Option<Affine<'_>>,
    ) -> Result<Self, KernelError> {
        let mut b = Self::new(c, h, w)?;
        b.fill_from_planar(src, affine)?;
        Ok(b)
    }

    /// The `W` interior values of channel `c` on frame row `y`; `None` outside the buffer.
    pub fn row(&self, c: usize, y: usize) -> Option<&[f32]> {
        (c < self.c && y < self.h).then(|| {
            let at = self.index(c, y + 1, 1);
            &self.as_slice()[at..at + self.w]
        })
    }

    /// Overwrites the interior from a planar `[C][H][W]` slice, applying `x·scale[c] + offset[c]` when
    /// `affine` is given. Errors: `src.len() != C·H·W` or an affine slice whose length is not `C`
    /// ([`KernelError::Length`]).
    pub fn fill_from_planar(
        &mut self,
        src: &[f32],
        affine: Option<Affine<'_>>,
    ) -> Result<(), KernelError> {
        match affine {
            None => self.fill_with(src, |_, v| v),
            Some(a) => {
                for (what, s) in [("affine scale", a.scale), ("affine offset", a.offset)] {
                    if s.len() != self.c {
                        return Err(KernelError::Length {
                            what,
                            expected: self.c,
                            got: s.len(),
                        });
                    }
                }
                self.fill_with(src, |c, v| v * a.scale[c] + a.offset[c])
            }
        }
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
        let (w, y0) = (self.w, self.rows.start);
        check_plane(c, self.c, plane.len(), w, src_y0 + self.rows.len())?;
        for y in self.rows() {
            let at = self.interior_at(c, y);
            let sy = src_y0 + y - y0;
            let row = &plane[sy * w..(sy + 1) * w];
            let dst = &mut self.data[at..at + w];
            match affine {
                Some((m, b)) => dst.iter_mut().zip(row).for_each(|(d, &v)| *d = v * m + b),
                None => dst.copy_from_slice(row),
            }
        }
        Ok(())
    }
}

impl RowBand<'_, f32> {
    /// Overwrites the band's rows with `other`'s values dequantised (ONNX `DequantizeLinear`): `(q − zp)·scale`,
    /// `zp` being `other`'s zero point. Band row `y` takes `other`'s interior row `other_y0 + y − rows.start`
    /// (windows of a frame held at other rows). The f32 input of a float layer that reads a u8 activation (the
    /// native engine's mixed-precision last layer). Errors: another channel count or width, or rows past
    /// `other`'s height ([`KernelError::Shape`]); a scale that is not finite and positive.
    pub fn dequantize_rows_from(
        &mut self,
        other: &RowPlanar<u8>,
        other_y0: usize,
        scale: f32,
    ) -> Result<(), KernelError> {
        check_scale("dequantisation scale", scale)?;
        let zp = other.border as f32;
        self.map_rows_from(other, other_y0, |q| (q as f32 - zp) * scale)
    }
}

impl<T: Element> RowBand<'_, T> {
    /// Overwrites the band's rows with `f` of `other`'s values, element by element: band row `y` takes `other`'s
    /// interior row `other_y0 + y − rows.start`. Errors: as [`RowBand::dequantize_rows_from`].
    fn map_rows_from<S: Element>(
        &mut self,
        other: &RowPlanar<S>,
        other_y0: usize,
        f: impl Fn(S) -> T,
    ) -> Result<(), KernelError> {
        let rows = self.rows.len();
        if (other.c, other.w) != (self.c, self.w) || other_y0 + rows > other.h {
            return Err(KernelError::Shape {
                what: format!(
                    "convert rows {other_y0}..{} of a {}×{}×{} buffer into {rows} rows of a {}×{} one",
                    other_y0 + rows,
                    other.c,
                    other.h,
                    other.w,
                    self.c,
                    self.w
                ),
            });
        }
        let (w, y0, ks, kd) = (self.w, self.rows.start, S::INTERLEAVE, T::INTERLEAVE);
        for c in 0..self.c {
            for y in self.rows() {
                let at = self.interior_at(c, y);
                let from = other.index(c, other_y0 + y - y0 + 1, 1);
                let src = &other.as_slice()[from..from + ks * (w - 1) + 1];
                let dst = &mut self.data[at..at + kd * (w - 1) + 1];
                for (d, &v) in dst.iter_mut().step_by(kd).zip(src.iter().step_by(ks)) {
                    *d = f(v);
                }
            }
        }
        Ok(())
    }
}

/// Checks one channel plane of a source: `c < channels`, a whole number of rows of `w`, at least `end` rows.
fn check_plane(
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
fn check_source(expected: usize, len: usize, end: usize, src_h: usize) -> Result<(), KernelError> {
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

impl RowBand<'_, u8> {
    /// [`RowPlanar::quantize_fill`] for the band's rows only (`src` is still the whole planar `[C][H][W]`
    /// frame), so that threads can share the work. Errors: as `quantize_fill`.
    pub fn quantize_fill(
        &mut self,
        src: &[f32],
        offset: f32,
        scale: f32,
    ) -> Result<(), KernelError> {
        let (h, y0) = (self.h, self.rows.start);
        self.quantize_fill_rows(src, h, y0, offset, scale)
    }

    /// [`quantize_fill`](Self::quantize_fill) of the band's rows from rows `src_y0..` of a planar
    /// `[C][src_h][W]` frame: band row `y` takes source row `src_y0 + y − rows.start` (a window of a taller
    /// frame, [`Inputs::shifted`](crate::Inputs::shifted)). Errors: `src.len() != C·src_h·W` or source rows
    /// past `src_h` ([`KernelError::Length`]), a scale that is not finite and positive.
    pub fn quantize_fill_rows(
        &mut self,
        src: &[f32],
        src_h: usize,
        src_y0: usize,
        offset: f32,
        scale: f32,
    ) -> Result<(), KernelError> {
        check_scale("quantisation scale", scale)?;
        check_source(
            self.c * src_h * self.w,
            src.len(),
            src_y0 + self.rows.len(),
            src_h,
        )?;
        let plane = src_h * self.w;
        for c in 0..self.c {
            let p = &src[c * plane..(c + 1) * plane];
            self.quantize_fill_channel_rows(c, p, src_y0, offset, scale)?;
        }
        Ok(())
    }

    /// Channel `c` of [`quantize_fill_rows`](Self::quantize_fill_rows) from one plane `[src_h][W]`: for an
    /// input held plane by plane. Errors: as [`RowBand::fill_channel_rows`], and a scale that is not finite
    /// and positive.
    pub fn quantize_fill_channel_rows(
        &mut self,
        c: usize,
        plane: &[f32],
        src_y0: usize,
        offset: f32,
        scale: f32,
    ) -> Result<(), KernelError> {
        check_scale("quantisation scale", scale)?;
        let (w, zp, y0) = (self.w, self.border, self.rows.start);
        check_plane(c, self.c, plane.len(), w, src_y0 + self.rows.len())?;
        for y in self.rows() {
            let at = self.interior_at(c, y);
            let dst = &mut self.data[at..at + 4 * (w - 1) + 1];
            let sy = src_y0 + y - y0;
            let row = &plane[sy * w..(sy + 1) * w];
            for (d, &v) in dst.iter_mut().step_by(4).zip(row) {
                *d = quantize((v + offset) / scale, zp);
            }
        }
        Ok(())
    }

    /// [`RowPlanar::requantize_from`] for the band's rows only, so that threads can share the work. Errors:
    /// as `requantize_from`.
    pub fn requantize_from(
        &mut self,
        other: &RowPlanar<u8>,
        other_scale: f32,
        scale: f32,
    ) -> Result<(), KernelError> {
        if other.h != self.h {
            return Err(KernelError::Shape {
                what: format!(
                    "requantise a {}×{}×{} buffer into a {}×{}×{} one",
                    other.c, other.h, other.w, self.c, self.h, self.w
                ),
            });
        }
        let y0 = self.rows.start;
        self.requantize_rows_from(other, y0, other_scale, scale)
    }

    /// [`requantize_from`](Self::requantize_from) of the band's rows from interior rows `other_y0..` of
    /// `other` (band row `y` takes `other`'s row `other_y0 + y − rows.start`; windows of a frame held at
    /// other rows). Errors: another channel count or width, or rows past `other`'s height
    /// ([`KernelError::Shape`]); scales not finite and positive.
    pub fn requantize_rows_from(
        &mut self,
        other: &RowPlanar<u8>,
        other_y0: usize,
        other_scale: f32,
        scale: f32,
    ) -> Result<(), KernelError> {
        check_scale("quantisation scale", scale)?;
        check_scale("source scale", other_scale)?;
        if (other.c, other.w) != (self.c, self.w) || other_y0 + self.rows.len() > other.h {
            return Err(KernelError::Shape {
                what: format!(
                    "requantise rows {other_y0}..{} of a {}×{}×{} buffer into {} rows of a {}×{} one",
                    other_y0 + self.rows.len(),
                    other.c,
                    other.h,
                    other.w,
                    self.rows.len(),
                    self.c,
                    self.w
                ),
            });
        }
        let (zp, zo, w, y0) = (self.border, other.border as f32, self.w, self.rows.start);
        // Same shape, so the same layout: only the interior differs in meaning, but the border must keep its
        // own zero point, so the interior rows are mapped one by one, each as one contiguous run of `4·W`
        // bytes (the padding channels hold `other`'s zero point, real 0, and map to this zero point).
        for g in 0..self.c.div_ceil(4) {
            for y in self.rows() {
                let at = self.interior_at(4 * g, y);
                let from = other.index(4 * g, other_y0 + y - y0 + 1, 1);
                let src = &other.as_slice()[from..from + 4 * w];
                for (d, &q) in self.data[at..at + 4 * w].iter_mut().zip(src) {
                    let real = (q as f32 - zo) * other_scale;
                    *d = quantize(real / scale, zp);
                }
            }
        }
        Ok(())
    }
}

impl RowBand<'_, u8> {
    /// Overwrites the band's rows with `other`'s f32 values quantised to this buffer's grid (ONNX
    /// `QuantizeLinear`): `q = clamp(round_ties_even(x / scale) + zp, 0, 255)`. Band row `y` takes `other`'s
    /// interior row `other_y0 + y − rows.start`. The u8 output of a float layer that an int8 layer reads (the
    /// native engine's mixed-precision first layer). Errors: as [`RowBand::dequantize_rows_from`].
    pub fn quantize_rows_from(
        &mut self,
        other: &RowPlanar<f32>,
        other_y0: usize,
        scale: f32,
    ) -> Result<(), KernelError> {
        check_scale("quantisation scale", scale)?;
        let zp = self.border;
        self.map_rows_from(other, other_y0, |v| quantize(v / scale, zp))
    }
}

impl RowPlanar<u8> {
    /// A buffer of `c` channels and `h × w` pixels whose every element (border, padding channels, interior)
    /// holds the zero point `zp`. Errors: a zero or too large dimension.
    pub fn new_quantized(c: usize, h: usize, w: usize, zp: u8) -> Result<Self, KernelError> {
        Self::with_border(c, h, w, zp)
    }

    /// The zero point: the value of the border and of the padding channels.
    pub fn zero_point(&self) -> u8 {
        self.border
    }

    /// A buffer filled from a planar `[c][h][w]` slice of quantised values with zero point `zp`.
    pub fn from_planar_u8(
        src: &[u8],
        c: usize,
        h: usize,
        w: usize,
        zp: u8,
    ) -> Result<Self, KernelError> {
        let mut b = Self::new_quantized(c, h, w, zp)?;
        b.fill_with(src, |_, v| v)?;
        Ok(b)
    }

    /// A buffer quantised from a planar `[c][h][w]` f32 slice: `q = clamp(round_ties_even(x / scale) + zp,
    /// 0, 255)`. Errors: dimensions, length, a scale that is not finite and positive.
    pub fn quantize_from_planar(
        src: &[f32],
        c: usize,
        h: usize,
        w: usize,
        scale: f32,
        zp: u8,
    ) -> Result<Self, KernelError> {
        check_scale("quantisation scale", scale)?;
        let mut b = Self::new_quantized(c, h, w, zp)?;
        let inv = 1.0 / scale;
        b.fill_with(src, |_, v| quantize(v * inv, zp))?;
        Ok(b)
    }

    /// Makes `zp` the buffer's zero point: every element outside the interior (border rows and columns,
    /// padding channels) is rewritten with it, the interior is left as it is (a layer overwrites it next). A
    /// ring of buffers reused by layers whose outputs have different zero points calls this before each
    /// layer; it writes only the border (no work when the zero point does not change).
    pub fn set_zero_point(&mut self, zp: u8) {
        if zp == self.border {
            return;
        }
        self.border = zp;
        let (h, w, wp, groups, c) = (self.h, self.w, self.wp, self.groups(), self.c);
        let data = self.as_mut_slice();
        let row = groups * wp * 4;
        data[..row].fill(zp);
        data[(h + 1) * row..(h + 2) * row].fill(zp);
        for r in 1..=h {
            for g in 0..groups {
                let at = (r * groups + g) * wp * 4;
                data[at..at + 4].fill(zp);
                data[at + (w + 1) * 4..at + wp * 4].fill(zp);
                // Padding channels of the last group (C not a multiple of 4).
                if g == groups - 1 && c % 4 != 0 {
                    for j in 1..=w {
                        data[at + j * 4 + c % 4..at + j * 4 + 4].fill(zp);
                    }
                }
            }
        }
    }

    /// Overwrites the interior from a planar `[C][H][W]` f32 slice, quantised as ONNX `QuantizeLinear`
    /// does: `q = clamp(round_ties_even((x + offset) / scale) + zp, 0, 255)` with the buffer's zero point.
    /// Errors: `src.len() != C·H·W` ([`KernelError::Length`]), a scale that is not finite and positive.
    pub fn quantize_fill(
        &mut self,
        src: &[f32],
        offset: f32,
        scale: f32,
    ) -> Result<(), KernelError> {
        let h = self.h;
        self.band_mut(0..h)?.quantize_fill(src, offset, scale)
    }

    /// Overwrites the interior with `other`'s values moved to this buffer's grid: `q = clamp(round_ties_even(
    /// (q_other − zp_other)·scale_other / scale) + zp, 0, 255)` (ONNX `DequantizeLinear` then
    /// `QuantizeLinear`). Errors: another shape ([`KernelError::Shape`]), scales not finite and positive.
    pub fn requantize_from(
        &mut self,
        other: &RowPlanar<u8>,
        other_scale: f32,
        scale: f32,
    ) -> Result<(), KernelError> {
        let h = self.h;
        self.band_mut(0..h)?
            .requantize_from(other, other_scale, scale)
    }

    /// The interior dequantised to a planar `[C][H][W]` vector: `(q − zp)·scale`.
    pub fn dequantize_to_planar(&self, scale: f32) -> Vec<f32> {
        let zp = self.border as f32;
        self.to_planar()
            .into_iter()
            .map(|q| (q as f32 - zp) * scale)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roundtrip_and_border() {
        let (c, h, w) = (3, 4, 5);
        let src: Vec<f32> = (0..c * h * w).map(|i| i as f32 + 1.0).collect();
        let scale = [1.0, 2.0, 1.0];
        let offset = [-0.5, 0.0, 1.0];
        let b = RowPlanar::from_planar(
            &src,
            c,
            h,
            w,
            Some(Affine {
                scale: &scale,
                offset: &offset,
            }),
        )
        .unwrap();
        assert!(b.border_is_clean());
        let back = b.to_planar();
        for ch in 0..c {
            for i in 0..h * w {
                let k = ch * h * w + i;
                assert_eq!(back[k], src[k] * scale[ch] + offset[ch]);
            }
        }
        assert_eq!(b.get(1, 2, 3), Some(src[(h + 2) * w + 3] * 2.0));
        for ch in 0..c {
            for y in 0..h {
                let k = (ch * h + y) * w;
                assert_eq!(b.row(ch, y).unwrap(), &back[k..k + w]);
            }
        }
        assert_eq!(b.row(c, 0), None);
        assert_eq!(b.row(0, h), None);
        assert!(b.padded_width() >= w + 2 + MAX_TILE);
        let mut bad = vec![0.0; 3];
        assert!(matches!(
            b.read_planar(&mut bad),
            Err(KernelError::Length { .. })
        ));
        assert!(RowPlanar::<f32>::new(0, 1, 1).is_err());
    }

    #[test]
    fn u8_roundtrip_zero_point_border() {
        let (c, h, w) = (6, 3, 7);
        let src: Vec<u8> = (0..c * h * w).map(|i| (i * 7 % 251) as u8).collect();
        let b = RowPlanar::from_planar_u8(&src, c, h, w, 17).unwrap();
        assert_eq!(b.to_planar(), src);
        assert!(b.border_is_clean());
        // Column 1 of every row is 64-byte aligned.
        assert_eq!((b.as_slice().as_ptr() as usize + 4) % 64, 0);
        // Padding channels 6, 7 hold the zero point.
        assert_eq!(b.as_slice().len(), (h + 2) * 2 * b.padded_width() * 4);
        let mut corrupt = b.clone();
        let i = corrupt.index(6, 1, 1);
        corrupt.as_mut_slice()[i] = 0;
        assert!(!corrupt.border_is_clean());
    }

    #[test]
    fn quantize_rounds_ties_to_even_and_clamps() {
        assert_eq!(quantize(2.5, 0), 2);
        assert_eq!(quantize(3.5, 0), 4);
        assert_eq!(quantize(-300.0, 10), 0);
        assert_eq!(quantize(1e30, 10), 255);
        assert_eq!(quantize(-0.5, 3), 3);
    }

    #[test]
    fn window_rows_fill_copy_and_map_frame_rows() {
        // Rows of a window: border fill, copy (the carry between strips), and fills from other rows of a
        // taller frame, whole planar or plane by plane, agree with the whole-frame fills row for row.
        let (c, h, w, fh) = (5, 6, 9, 11);
        let src: Vec<f32> = (0..c * fh * w)
            .map(|i| (i % 97) as f32 * 0.25 - 3.0)
            .collect();
        let (scale, offset) = ([1.0, 2.0, 0.5, 1.0, -1.0], [0.0, -0.5, 0.25, 1.0, 0.0]);
        let affine = Affine {
            scale: &scale,
            offset: &offset,
        };
        let whole = RowPlanar::from_planar(&src, c, fh, w, Some(affine)).unwrap();
        let mut win = RowPlanar::new(c, h, w).unwrap();
        // Window rows 1..5 take frame rows 4..8: once from the planar frame, once plane by plane.
        win.band_mut(1..5)
            .unwrap()
            .fill_rows_from_planar(&src, fh, 4, Some(affine))
            .unwrap();
        let mut per_plane = RowPlanar::new(c, h, w).unwrap();
        for ch in 0..c {
            let plane = &src[ch * fh * w..(ch + 1) * fh * w];
            let mut band = per_plane.band_mut(1..5).unwrap();
            band.fill_channel_rows(ch, plane, 4, Some((scale[ch], offset[ch])))
                .unwrap();
        }
        assert_eq!(win, per_plane);
        for ch in 0..c {
            for i in 1..5 {
                assert_eq!(win.row(ch, i), whole.row(ch, i + 3), "({ch}, {i})");
            }
        }
        // Rows past the plane's end are refused, as is a channel past C.
        let mut band = per_plane.band_mut(0..6).unwrap();
        assert!(band.fill_channel_rows(0, &src[..fh * w], 6, None).is_err());
        assert!(band.fill_channel_rows(c, &src[..fh * w], 0, None).is_err());
        // Carry: rows 3..5 move to 0..2; then rows 2..6 are set to the border (zero), borders stay clean.
        let before = win.clone();
        win.copy_rows(3..5, 0).unwrap();
        win.fill_rows_with_border(2..6).unwrap();
        for ch in 0..c {
            assert_eq!(win.row(ch, 0), before.row(ch, 3));
            assert_eq!(win.row(ch, 1), before.row(ch, 4));
            for i in 2..6 {
                assert!(win.row(ch, i).unwrap().iter().all(|&v| v == 0.0));
            }
        }
        assert!(win.border_is_clean());
        assert!(win.copy_rows(3..6, 4).is_err());
        assert!(win.fill_rows_with_border(2..7).is_err());

        // u8: quantised rows of a taller frame, then requantised from other rows of another window.
        let q = RowPlanar::quantize_from_planar(&src, c, fh, w, 0.05, 7).unwrap();
        let mut qa = RowPlanar::new_quantized(c, h, w, 7).unwrap();
        qa.band_mut(0..6)
            .unwrap()
            .quantize_fill_rows(&src, fh, 5, 0.0, 0.05)
            .unwrap();
        let mut qb = RowPlanar::new_quantized(c, h, w, 7).unwrap();
        for ch in 0..c {
            let plane = &src[ch * fh * w..(ch + 1) * fh * w];
            qb.band_mut(0..6)
                .unwrap()
                .quantize_fill_channel_rows(ch, plane, 5, 0.0, 0.05)
                .unwrap();
        }
        assert_eq!(qa, qb);
        let mut cat = RowPlanar::new_quantized(c, 3, w, 200).unwrap();
        cat.band_mut(1..3)
            .unwrap()
            .requantize_rows_from(&qa, 2, 0.05, 0.1)
            .unwrap();
        for ch in 0..c {
            for x in 0..w {
                for (i, f) in [(1, 7), (2, 8)] {
                    let real = (q.get(ch, f, x).unwrap() as f32 - 7.0) * 0.05;
                    assert_eq!(cat.get(ch, i, x), Some(quantize(real / 0.1, 200)));
                }
                assert_eq!(cat.get(ch, 0, x), Some(200));
            }
        }
        assert!(cat.border_is_clean());
        let mut band = cat.band_mut(0..3).unwrap();
        assert!(band.requantize_rows_from(&qa, 4, 0.05, 0.1).is_err());
    }

    #[test]
    fn rows_convert_between_f32_and_u8_as_onnx_quantize_and_dequantize() {
        // The mixed-precision layers' conversions: other rows of a window, element by element against the
        // ONNX definitions, borders untouched; mismatched shapes and rows past the source refused.
        let (c, h, w) = (6, 5, 7);
        let src: Vec<f32> = (0..c * h * w)
            .map(|i| ((i * 37) % 101) as f32 * 0.031 - 1.2)
            .collect();
        let f = RowPlanar::from_planar(&src, c, h, w, None).unwrap();
        let (scale, zp) = (0.0123, 97);
        let mut q = RowPlanar::new_quantized(c, 3, w, zp).unwrap();
        q.band_mut(1..3)
            .unwrap()
            .quantize_rows_from(&f, 2, scale)
            .unwrap();
        let mut back = RowPlanar::new(c, 4, w).unwrap();
        back.band_mut(2..4)
            .unwrap()
            .dequantize_rows_from(&q, 1, scale)
            .unwrap();
        for ch in 0..c {
            for x in 0..w {
                assert_eq!(q.get(ch, 0, x), Some(zp));
                for (i, fy) in [(1, 2), (2, 3)] {
                    let v = f.get(ch, fy, x).unwrap();
                    let want = (v / scale)
                        .round_ties_even()
                        .clamp(-(zp as f32), 255.0 - zp as f32);
                    let got = q.get(ch, i, x).unwrap();
                    assert_eq!(got as f32 - zp as f32, want, "({ch}, {i}, {x})");
                    let deq = back.get(ch, i + 1, x).unwrap();
                    assert_eq!(deq, (got as f32 - zp as f32) * scale);
                    assert!((deq - v).abs() <= scale * 0.5 + 1e-6 || !(-1.19..=1.9).contains(&v));
                }
                assert_eq!(back.get(ch, 0, x), Some(0.0));
            }
        }
        assert!(q.border_is_clean() && back.border_is_clean());
        let mut band = q.band_mut(0..3).unwrap();
        assert!(band.quantize_rows_from(&f, 3, scale).is_err());
        assert!(band.quantize_rows_from(&f, 0, 0.0).is_err());
        let narrow = RowPlanar::new(c, h, w - 1).unwrap();
        assert!(band.quantize_rows_from(&narrow, 0, scale).is_err());
        let mut band = back.band_mut(0..4).unwrap();
        assert!(band.dequantize_rows_from(&q, 0, scale).is_err());
    }
}

//! Quantised fills: u8 buffers and bands filled from f32 as ONNX `QuantizeLinear` does, requantised from
//! another u8 buffer, and dequantised back to f32 (`DequantizeLinear`), whole or a band of rows at a time.

use super::band::{check_plane, check_source, RowBand};
use super::planar::{Element, RowPlanar};
use super::rows::{dequantize_row, level, quantize_row, requantize_row};
use crate::error::KernelError;
use crate::quant::{check_scale, quantize};

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
        self.check_rows_from(other, other_y0)?;
        let zp = other.border as f32;
        let (w, y0, full) = (self.w, self.rows.start, self.c / 4);
        // Whole channel groups four rows at a time; the channels of a last partial group one by one.
        for g in 0..full {
            for y in self.rows() {
                let from = other.index(4 * g, other_y0 + y - y0 + 1, 1);
                let at = [0, 1, 2, 3].map(|k| self.interior_at(4 * g + k, y));
                let rows = four_rows_mut(self.data, at, w);
                dequantize_row(
                    level(),
                    &other.as_slice()[from..from + 4 * w],
                    rows,
                    zp,
                    scale,
                )?;
            }
        }
        self.map_rows_from(other, other_y0, 4 * full..self.c, |q| {
            (q as f32 - zp) * scale
        });
        Ok(())
    }
}

impl<T: Element> RowBand<'_, T> {
    /// Checks that `other` has this band's channels and width and holds rows `other_y0..other_y0 + rows`.
    /// Errors: as [`RowBand::dequantize_rows_from`].
    fn check_rows_from<S: Element>(
        &self,
        other: &RowPlanar<S>,
        other_y0: usize,
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
        Ok(())
    }

    /// Overwrites channels `channels` of the band's rows with `f` of `other`'s values, element by element:
    /// band row `y` takes `other`'s interior row `other_y0 + y − rows.start` (shapes checked by the caller,
    /// [`RowBand::check_rows_from`]).
    fn map_rows_from<S: Element>(
        &mut self,
        other: &RowPlanar<S>,
        other_y0: usize,
        channels: std::ops::Range<usize>,
        f: impl Fn(S) -> T,
    ) {
        let (w, y0, ks, kd) = (self.w, self.rows.start, S::INTERLEAVE, T::INTERLEAVE);
        for c in channels {
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
    }
}

/// Four disjoint rows `data[at[k]..at[k] + len]` (`at` increasing, each row ending before the next starts).
fn four_rows_mut(data: &mut [f32], at: [usize; 4], len: usize) -> [&mut [f32]; 4] {
    let (head, rest) = data[at[0]..].split_at_mut(at[1] - at[0]);
    let (r1, rest) = rest.split_at_mut(at[2] - at[1]);
    let (r2, r3) = rest.split_at_mut(at[3] - at[2]);
    [
        &mut head[..len],
        &mut r1[..len],
        &mut r2[..len],
        &mut r3[..len],
    ]
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
        self.quantize_fill_planes_rows(|c| &src[c * plane..(c + 1) * plane], src_y0, offset, scale)
    }

    /// [`quantize_fill_rows`](Self::quantize_fill_rows) from the `C` planes `[src_h][W]` that `plane(c)` gives
    /// (an input held plane by plane): whole channel groups four planes at a time, as 4-byte pixels (the
    /// compiler vectorises that), the channels of a last partial group one by one
    /// ([`quantize_fill_channel_rows`](Self::quantize_fill_channel_rows)). Errors: as
    /// `quantize_fill_channel_rows`, for any plane.
    pub fn quantize_fill_planes_rows<'p>(
        &mut self,
        plane: impl Fn(usize) -> &'p [f32],
        src_y0: usize,
        offset: f32,
        scale: f32,
    ) -> Result<(), KernelError> {
        check_scale("quantisation scale", scale)?;
        let (w, zp, y0, full) = (self.w, self.border, self.rows.start, self.c / 4);
        for g in 0..full {
            let planes = [0, 1, 2, 3].map(|k| plane(4 * g + k));
            for (k, p) in planes.iter().enumerate() {
                check_plane(4 * g + k, self.c, p.len(), w, src_y0 + self.rows.len())?;
            }
            for y in self.rows() {
                let at = self.interior_at(4 * g, y);
                let sy = src_y0 + y - y0;
                let rows = planes.map(|p| &p[sy * w..(sy + 1) * w]);
                quantize_row(
                    level(),
                    &mut self.data[at..at + 4 * w],
                    rows,
                    zp,
                    offset,
                    scale,
                )?;
            }
        }
        for c in 4 * full..self.c {
            self.quantize_fill_channel_rows(c, plane(c), src_y0, offset, scale)?;
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
                let dst = &mut self.data[at..at + 4 * w];
                requantize_row(level(), dst, src, (zo, other_scale), (zp, scale))?;
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
        self.check_rows_from(other, other_y0)?;
        let (zp, w, y0, full) = (self.border, self.w, self.rows.start, self.c / 4);
        // Whole channel groups as 4-byte pixels; the channels of a last partial group one by one.
        for g in 0..full {
            for y in self.rows() {
                let at = self.interior_at(4 * g, y);
                let src = other.as_slice();
                let rows = [0, 1, 2, 3].map(|k| {
                    let from = other.index(4 * g + k, other_y0 + y - y0 + 1, 1);
                    &src[from..from + w]
                });
                // `(v + 0)/scale` is `v/scale` but for −0, which quantises as +0 does.
                quantize_row(
                    level(),
                    &mut self.data[at..at + 4 * w],
                    rows,
                    zp,
                    0.0,
                    scale,
                )?;
            }
        }
        self.map_rows_from(other, other_y0, 4 * full..self.c, |v| {
            quantize(v / scale, zp)
        });
        Ok(())
    }
}

impl RowPlanar<u8> {
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

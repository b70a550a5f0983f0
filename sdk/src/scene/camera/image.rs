//! The camera's buffers as images: colour ([`ColorImage`]), depth ([`DepthImage`]) and depth confidence
//! ([`ConfidenceImage`]), each one generic type over its bytes `D` (as image-rs's `ImageBuffer<P,
//! Container>`): borrowed over `&[u8]` (what a conversion reads), owned over `Vec<u8>` ([`ColorImageBuf`],
//! [`DepthImageBuf`], [`ConfidenceImageBuf`]). Each checks its layout (size, row stride, length) and decodes
//! with a [`Rotation`] applied while reading.

use ndarray::{Array2, Array3};

use super::fit::{CropRect, Rotation};
use super::formats::{ColorFormat, DepthFormat};
use crate::color::srgb8_to_amplitude;
use crate::error::{invalid, HoloError, Result};
use crate::scene::depth::DecodedDepth;

/// An interleaved 8-bit colour buffer, sRGB-encoded, `height` rows of `width` pixels, over its bytes `D`:
/// `ColorImage<&[u8]>` borrows them (what [`CameraFrame`](crate::scene::CameraFrame) holds),
/// [`ColorImageBuf`] (`ColorImage<Vec<u8>>`) owns them.
///
/// Row `y` starts at byte `y · stride`, where `stride = row_stride`, or `width · bytes_per_pixel` when
/// `row_stride` is 0 (packed). The buffer length must satisfy
/// `stride · (height − 1) + width · bpp ≤ data.len() ≤ stride · height` (the last row's padding may be
/// absent); see [`ColorImage::validate`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ColorImage<D> {
    /// The pixel bytes.
    pub data: D,
    /// Byte layout of a pixel.
    pub format: ColorFormat,
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Bytes from the start of one row to the next; `0` = packed (`width · bytes_per_pixel`).
    pub row_stride: usize,
}

/// An owned colour buffer: a [`ColorImage`] over a `Vec<u8>`.
pub type ColorImageBuf = ColorImage<Vec<u8>>;

/// A depth buffer, `height` rows of `width` little-endian samples, laid out like [`ColorImage`] (row stride
/// in bytes, `0` = packed; same length rule, see [`DepthImage::validate`]), over its bytes `D`:
/// `DepthImage<&[u8]>` borrows them, [`DepthImageBuf`] (`DepthImage<Vec<u8>>`) owns them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DepthImage<D> {
    /// The sample bytes.
    pub data: D,
    /// Sample format.
    pub format: DepthFormat,
    /// Samples per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Bytes from the start of one row to the next; `0` = packed (`width · bytes_per_pixel`).
    pub row_stride: usize,
}

/// An owned depth buffer: a [`DepthImage`] over a `Vec<u8>`.
pub type DepthImageBuf = DepthImage<Vec<u8>>;

/// A depth buffer's confidence: one byte per depth sample, `[height, width]` as the depth buffer, rows
/// `row_stride` bytes apart (`0` = packed), over its bytes `D` (`ConfidenceImage<&[u8]>` borrowed,
/// [`ConfidenceImageBuf`] owned). ARKit's `ARDepthData.confidenceMap` (`ARConfidenceLevel`: 0 low, 1 medium,
/// 2 high) and ARCore's `Frame.acquireRawDepthConfidenceImage` (0–255, 255 = most confident). Depth samples
/// below `min_confidence` are invalid ([`crate::scene::apply_confidence`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConfidenceImage<D> {
    /// One byte per sample.
    pub data: D,
    /// The lowest confidence kept, on the buffer's own scale: [`crate::scene::DEFAULT_MIN_CONFIDENCE`] (1,
    /// ARKit's medium) for ARKit; e.g. 128 for ARCore's 0–255.
    pub min_confidence: u8,
    /// Samples per row (the depth buffer's).
    pub width: usize,
    /// Rows (the depth buffer's).
    pub height: usize,
    /// Bytes from the start of one row to the next; `0` = packed (`width`).
    pub row_stride: usize,
}

/// An owned confidence buffer: a [`ConfidenceImage`] over a `Vec<u8>`.
pub type ConfidenceImageBuf = ConfidenceImage<Vec<u8>>;

/// Row stride and bytes per pixel of a validated `height × width` buffer.
#[derive(Debug, Clone, Copy)]
struct Layout {
    stride: usize,
    bpp: usize,
    height: usize,
    width: usize,
}

/// The names a buffer's errors give it: the buffer's and its row stride's.
type Names = (&'static str, &'static str);

/// Checks a buffer's size, stride and length (see [`ColorImage`]); `names` name it in the errors
/// ([`HoloError::InvalidParameter`]).
fn check_layout(
    (name, stride_name): Names,
    len: usize,
    (height, width): (usize, usize),
    bpp: usize,
    row_stride: usize,
) -> Result<Layout> {
    if width == 0 || height == 0 {
        return Err(invalid(
            name,
            format!(
                "the {name} buffer must have a non-zero size, got width {width} x height {height}"
            ),
        ));
    }
    // A frame no camera makes is refused by its pixel count before its bytes are read (the image files'
    // limit, `crate::io::InputLimits::max_image_pixels`: 100 M by default).
    let max = crate::io::input_limits().max_image_pixels;
    let pixels = (width as u64).saturating_mul(height as u64);
    if pixels > max {
        return Err(invalid(
            name,
            format!(
                "the {name} buffer is {width} × {height} = {pixels} pixels, more than the {max} a frame may \
                 have (tensorholo::io::InputLimits::max_image_pixels)"
            ),
        ));
    }
    let row = width.checked_mul(bpp).ok_or_else(|| {
        invalid(
            name,
            format!("width {width} x {bpp} bytes per pixel overflows usize"),
        )
    })?;
    let stride = if row_stride == 0 { row } else { row_stride };
    if stride < row {
        return Err(invalid(
            stride_name,
            format!(
                "row stride of {stride} bytes is shorter than one row ({width} pixels x {bpp} bytes = \
                 {row} bytes)"
            ),
        ));
    }
    let min_len = stride
        .checked_mul(height - 1)
        .and_then(|n| n.checked_add(row))
        .ok_or_else(|| {
            invalid(
                name,
                format!(
                    "buffer size stride·(height−1) + width·bpp = {stride}·{} + {row} bytes overflows usize",
                    height - 1
                ),
            )
        })?;
    // stride·height overflowing means every representable length is below it.
    let max_len = stride.saturating_mul(height);
    if len < min_len {
        return Err(invalid(
            name,
            format!(
                "{name} buffer too short: {height} rows of stride {stride} bytes ({width} pixels x {bpp} \
                 bytes) need at least {min_len} bytes (stride·(height−1) + width·bpp), got {len}"
            ),
        ));
    }
    if len > max_len {
        return Err(invalid(
            name,
            format!(
                "{name} buffer too long: {height} rows of stride {stride} bytes hold at most {max_len} \
                 bytes (stride·height), got {len}"
            ),
        ));
    }
    Ok(Layout {
        stride,
        bpp,
        height,
        width,
    })
}

impl Layout {
    /// `(H', W')` of the buffer after `rotation`.
    fn rotated_size(&self, rotation: Rotation) -> (usize, usize) {
        rotation.rotated_size(self.height, self.width)
    }

    /// Calls `f(i, pixel_bytes)` for every output pixel `i` (row-major index in the rotated `[H', W']`
    /// frame) of the buffer `data` this layout was validated for.
    fn for_each_rotated(&self, data: &[u8], rotation: Rotation, mut f: impl FnMut(usize, &[u8])) {
        let (ho, wo) = self.rotated_size(rotation);
        let Layout {
            stride,
            bpp,
            height,
            width,
        } = *self;
        for yo in 0..ho {
            for xo in 0..wo {
                let (y, x) = rotation.source(yo, xo, height, width);
                // In bounds and without overflow: y·stride + (x+1)·bpp ≤ stride·(height−1) + width·bpp ≤ len.
                let off = y * stride + x * bpp;
                f(yo * wo + xo, &data[off..off + bpp]);
            }
        }
    }
}

/// Error for an internal shape inconsistency (cannot happen for validated input).
fn shape_error(e: ndarray::ShapeError) -> HoloError {
    HoloError::Internal(format!("shape error on validated input: {e}"))
}

impl<D> ColorImage<D> {
    /// This buffer's format and geometry over the bytes `f(&self.data)`.
    pub(super) fn map_data<'s, E>(&'s self, f: impl FnOnce(&'s D) -> E) -> ColorImage<E> {
        ColorImage {
            data: f(&self.data),
            format: self.format,
            width: self.width,
            height: self.height,
            row_stride: self.row_stride,
        }
    }
}

impl<D: AsRef<[u8]>> ColorImage<D> {
    /// Borrows as a `ColorImage<&[u8]>` (the same bytes, no copy).
    pub fn view(&self) -> ColorImage<&[u8]> {
        self.map_data(|d| d.as_ref())
    }

    /// Checks the buffer: non-zero `width` and `height`; `stride ≥ width · bpp`; and
    /// `stride · (height − 1) + width · bpp ≤ data.len() ≤ stride · height`, all in checked arithmetic.
    ///
    /// Errors: [`HoloError::InvalidParameter`] with name `color` (zero size, size overflow, buffer too
    /// short or too long, giving the expected and actual byte counts) or `color_row_stride` (stride shorter
    /// than a row).
    pub fn validate(&self) -> Result<()> {
        self.layout().map(|_| ())
    }

    fn layout(&self) -> Result<Layout> {
        let (len, bpp) = (self.data.as_ref().len(), self.format.bytes_per_pixel());
        let names = ("color", "color_row_stride");
        check_layout(names, len, (self.height, self.width), bpp, self.row_stride)
    }

    /// Decodes to linear amplitude `[3, H', W']`, channels R, G, B (whatever the byte order), each value
    /// [`srgb8_to_amplitude`] of its byte (`√(linear intensity)` in `[0, 1]`); alpha is ignored. The
    /// `rotation` is applied while decoding, so `(H', W') = rotation.rotated_size(height, width)`.
    ///
    /// Errors: those of [`ColorImage::validate`], checked before allocating.
    pub(crate) fn to_amplitude(&self, rotation: Rotation) -> Result<Array3<f32>> {
        let layout = self.layout()?;
        let lut: [f32; 256] = std::array::from_fn(|c| srgb8_to_amplitude(c as u8));
        let (ho, wo) = layout.rotated_size(rotation);
        // ho·wo ≤ data.len() and the output is 3·ho·wo f32 values: bounded by the input's size.
        let plane = ho * wo;
        let mut flat = vec![0.0f32; 3 * plane];
        let [r, g, b] = self.format.rgb_offsets();
        layout.for_each_rotated(self.data.as_ref(), rotation, |i, px| {
            flat[i] = lut[px[r] as usize];
            flat[plane + i] = lut[px[g] as usize];
            flat[2 * plane + i] = lut[px[b] as usize];
        });
        Array3::from_shape_vec((3, ho, wo), flat).map_err(shape_error)
    }
}

impl<'a> ColorImage<&'a [u8]> {
    /// The sub-image `crop` of this buffer: the same bytes (no copy), format and row stride, `crop.width ×
    /// crop.height` pixels starting at column `crop.x` of row `crop.y` (before any rotation).
    ///
    /// Errors: those of [`ColorImage::validate`] for this buffer, then those of `CropRect::validate`
    /// (`color_crop`: empty, or not inside the buffer).
    pub(crate) fn crop(&self, crop: CropRect) -> Result<ColorImage<&'a [u8]>> {
        let Layout { stride, bpp, .. } = self.layout()?;
        crop.validate(self.width, self.height)?;
        // Inside the validated buffer: start + stride·(h−1) + w·bpp = stride·(y+h−1) + (x+w)·bpp
        //   ≤ stride·(height−1) + width·bpp ≤ data.len().
        let start = crop.y * stride + crop.x * bpp;
        let end = start + stride * (crop.height - 1) + crop.width * bpp;
        Ok(ColorImage {
            data: &self.data[start..end],
            format: self.format,
            width: crop.width,
            height: crop.height,
            row_stride: stride,
        })
    }
}

impl<D> DepthImage<D> {
    /// This buffer's format and geometry over the bytes `f(&self.data)`.
    pub(super) fn map_data<'s, E>(&'s self, f: impl FnOnce(&'s D) -> E) -> DepthImage<E> {
        DepthImage {
            data: f(&self.data),
            format: self.format,
            width: self.width,
            height: self.height,
            row_stride: self.row_stride,
        }
    }
}

impl<D: AsRef<[u8]>> DepthImage<D> {
    /// Borrows as a `DepthImage<&[u8]>` (the same bytes, no copy).
    pub fn view(&self) -> DepthImage<&[u8]> {
        self.map_data(|d| d.as_ref())
    }

    /// Checks the buffer like [`ColorImage::validate`].
    ///
    /// Errors: [`HoloError::InvalidParameter`] with name `depth` (zero size, size overflow, buffer too
    /// short or too long, giving the expected and actual byte counts) or `depth_row_stride`.
    pub fn validate(&self) -> Result<()> {
        self.layout().map(|_| ())
    }

    fn layout(&self) -> Result<Layout> {
        let (len, bpp) = (self.data.as_ref().len(), self.format.bytes_per_pixel());
        let names = ("depth", "depth_row_stride");
        check_layout(names, len, (self.height, self.width), bpp, self.row_stride)
    }

    /// Decodes to metric depth `[H', W']` with its validity mask (a [`DecodedDepth`] with
    /// `metric = true`: valid values are z-depths in metres > 0, invalid ones `0.0`), using the formulas of
    /// [`DepthFormat`]. The `rotation` is applied while decoding, so
    /// `(H', W') = rotation.rotated_size(height, width)`.
    ///
    /// Errors: those of [`DepthImage::validate`], checked before allocating. A buffer without any valid
    /// pixel decodes fine (all `valid` false).
    pub fn decode(&self, rotation: Rotation) -> Result<DecodedDepth> {
        let layout = self.layout()?;
        let (ho, wo) = layout.rotated_size(rotation);
        let mut values = vec![0.0f32; ho * wo];
        let mut valid = vec![false; ho * wo];
        let format = self.format;
        layout.for_each_rotated(self.data.as_ref(), rotation, |i, px| {
            if let Some(z) = format.decode_sample(px) {
                values[i] = z;
                valid[i] = true;
            }
        });
        Ok(DecodedDepth {
            values: Array2::from_shape_vec((ho, wo), values).map_err(shape_error)?,
            valid: Array2::from_shape_vec((ho, wo), valid).map_err(shape_error)?,
            metric: true,
        })
    }
}

impl<D> ConfidenceImage<D> {
    /// This buffer's threshold and geometry over the bytes `f(&self.data)`.
    pub(super) fn map_data<'s, E>(&'s self, f: impl FnOnce(&'s D) -> E) -> ConfidenceImage<E> {
        ConfidenceImage {
            data: f(&self.data),
            min_confidence: self.min_confidence,
            width: self.width,
            height: self.height,
            row_stride: self.row_stride,
        }
    }
}

impl<D: AsRef<[u8]>> ConfidenceImage<D> {
    /// Checks the buffer like [`ColorImage::validate`].
    ///
    /// Errors: [`HoloError::InvalidParameter`] with name `confidence` (zero size, size overflow, buffer too
    /// short or too long) or `confidence_row_stride`.
    pub(crate) fn validate(&self) -> Result<()> {
        self.layout().map(|_| ())
    }

    fn layout(&self) -> Result<Layout> {
        let len = self.data.as_ref().len();
        let names = ("confidence", "confidence_row_stride");
        check_layout(names, len, (self.height, self.width), 1, self.row_stride)
    }

    /// The confidence `[H', W']` after `rotation` (as [`DepthImage::decode`] turns its depth buffer).
    ///
    /// Errors: those of [`ConfidenceImage::validate`].
    pub(crate) fn decode(&self, rotation: Rotation) -> Result<Array2<u8>> {
        let layout = self.layout()?;
        let (ho, wo) = layout.rotated_size(rotation);
        let mut out = vec![0u8; ho * wo];
        layout.for_each_rotated(self.data.as_ref(), rotation, |i, px| out[i] = px[0]);
        Array2::from_shape_vec((ho, wo), out).map_err(shape_error)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A buffer claiming more pixels than a frame may have is refused by its count, before its bytes (a
    /// 20000 × 20000 frame: 400 M pixels against the 100 M limit), naming the buffer and the limit.
    #[test]
    fn a_frame_beyond_the_pixel_limit_is_refused_by_its_count() {
        let max = crate::io::input_limits().max_image_pixels;
        for (w, h, refused) in [
            (20_000, 20_000, true),
            (10_000, 10_001, true),
            (10_000, 10_000, false),
        ] {
            let e = check_layout(("depth", "depth_row_stride"), 4, (h, w), 2, 0).unwrap_err();
            let e = e.to_string();
            assert_eq!(e.contains("pixels, more than"), refused, "{w}×{h}: {e}");
            if refused {
                assert!(e.contains(&max.to_string()) && e.contains("depth"), "{e}");
            } else {
                assert!(e.contains("too short"), "{e}");
            }
        }
    }

    #[test]
    fn crop_takes_the_rectangle_through_the_row_stride() {
        // 6 × 5 RGB8 with 7 bytes of row padding; pixel (y, x) = [10y + x, 100 + x, 200 − y].
        let (h, w, stride) = (5usize, 6usize, 6 * 3 + 7);
        let mut data = vec![0xEEu8; stride * h];
        for y in 0..h {
            for x in 0..w {
                data[y * stride + 3 * x..][..3].copy_from_slice(&[
                    (10 * y + x) as u8,
                    100 + x as u8,
                    200 - y as u8,
                ]);
            }
        }
        let image = ColorImage {
            data: &data[..],
            format: ColorFormat::Rgb8,
            width: w,
            height: h,
            row_stride: stride,
        };
        let crop = CropRect {
            x: 2,
            y: 1,
            width: 3,
            height: 4,
        }; // columns 2..5, rows 1..5 (the last row)
        let sub = image.crop(crop).unwrap();
        assert_eq!((sub.width, sub.height, sub.row_stride), (3, 4, stride));
        // The last row's padding is not needed: 3·stride + 3·3 bytes from row 1, column 2.
        assert_eq!(sub.data.len(), 3 * stride + 9);
        let amp = sub.to_amplitude(Rotation::Deg0).unwrap();
        for ((c, y, x), &a) in amp.indexed_iter() {
            let (by, bx) = (y + 1, x + 2);
            let byte = [(10 * by + bx) as u8, 100 + bx as u8, 200 - by as u8][c];
            assert_eq!(a, srgb8_to_amplitude(byte), "({c},{y},{x})");
        }
        // Out of the buffer, or on a bad buffer: typed errors, no panic.
        let err = image
            .crop(CropRect {
                x: 4,
                y: 0,
                width: 3,
                height: 1,
            })
            .unwrap_err();
        assert!(
            matches!(
                err,
                HoloError::InvalidParameter {
                    name: "color_crop",
                    ..
                }
            ),
            "{err}"
        );
        let short = ColorImage {
            data: &data[..10],
            ..image
        };
        let err = short.crop(CropRect::full(1, 1)).unwrap_err();
        assert!(
            matches!(err, HoloError::InvalidParameter { name: "color", .. }),
            "{err}"
        );
    }
}

//! RGB-D frames from phone camera buffers: an interleaved 8-bit colour buffer with a row stride plus a
//! depth map in the sensor's own format and resolution → [`RgbdFrame`] at the hologram resolution.
//!
//! [`CameraFrame::to_rgbd`] runs, in this order:
//! 1. validation of both buffers (sizes, row stride, buffer length, all with checked arithmetic), of the
//!    colour crop ([`CameraFrame::color_crop`], a [`CropRect`]) and of the target size, before anything is
//!    allocated; the crop, when given, replaces the colour buffer by its sub-rectangle (no copy), so that
//!    colour and depth cover the same field of view (registration: ARCore's depth covers the GPU texture's
//!    16:9 field of view, a band of its 4:3 CPU image);
//! 2. decoding: colour ([`ColorFormat`], sRGB 8-bit) → `[3, H, W]` amplitude with
//!    [`crate::color::srgb8_to_amplitude`], channels R, G, B whatever the byte order; depth
//!    ([`DepthFormat`], little-endian) → metres + validity mask ([`DecodedDepth`], metric);
//! 3. the clockwise [`Rotation`] that makes both buffers upright (fused with step 2: each output pixel reads
//!    its source pixel, no extra copy);
//! 4. depth (values and validity) brought to the colour resolution by nearest neighbour (the default: no depth
//!    mixed across an occlusion edge) or, with [`FrameOptions::depth_upsampling`], by the colour-guided joint
//!    bilateral upsampling ([`super::upsample_depth`]: depth mixed only among samples of similar colour, a
//!    hole's edge following the colour's).
//!    The (cropped) colour and the depth are assumed to cover the
//!    same field of view, as AVFoundation's `AVDepthData` (delivered alongside the photo / video frame) and
//!    ARKit's `sceneDepth` do, and ARCore's depth image does after the crop of step 1: the depth map is
//!    stretched onto the colour frame, so a depth map with another aspect ratio is stretched too (logged as
//!    a warning);
//! 5. [`normalise_depth`] with [`FrameOptions::range`] / [`FrameOptions::mapping`] (automatic range = 1st /
//!    99th percentiles of the valid depths), then [`fill_invalid`]: invalid pixels take the farthest
//!    neighbouring depth and are never read as near;
//! 6. the [`Fit`] to the hologram's `height × width` (crop, letterbox or stretch), resampling with
//!    [`RgbdFrame::resize`] (Catmull-Rom in intensity for amplitude, nearest for depth).
//!
//! Memory: the decoded colour `[3, H, W]` f32 and depth at colour resolution, the fitted output, and for
//! [`Fit::Crop`] one copy of the cropped region; nothing else at full resolution.

use std::sync::atomic::{AtomicBool, Ordering};

use ndarray::{s, Array2, Array3};
use serde::Serialize;

use super::depth::{
    fill_invalid, normalise_depth, DecodedDepth, DepthEncoding, DepthMapping, DepthRange,
};
use super::frame::{LayeredDepthImage, LdiLayer, RgbdFrame};
use super::ldi_files::assemble_layers;
use crate::color::srgb8_to_amplitude;
use crate::error::{invalid, HoloError, Result};

/// Byte layout of an interleaved 8-bit colour buffer. Values are sRGB-encoded; alpha is ignored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub enum ColorFormat {
    /// 4 bytes per pixel in memory order R, G, B, A (e.g. Android `PixelFormat.RGBA_8888`,
    /// `HardwareBuffer.RGBA_8888`).
    Rgba8,
    /// 4 bytes per pixel in memory order B, G, R, A: iOS `kCVPixelFormatType_32BGRA`.
    Bgra8,
    /// 3 bytes per pixel in memory order R, G, B (packed RGB, as the `image` crate's `RgbImage`).
    Rgb8,
}

impl ColorFormat {
    /// Every colour format (for exhaustive tests and fuzzing).
    pub const ALL: [ColorFormat; 3] = [ColorFormat::Rgba8, ColorFormat::Bgra8, ColorFormat::Rgb8];

    /// Bytes per pixel: 4 for [`Rgba8`](Self::Rgba8) and [`Bgra8`](Self::Bgra8), 3 for
    /// [`Rgb8`](Self::Rgb8).
    pub fn bytes_per_pixel(&self) -> usize {
        match self {
            ColorFormat::Rgba8 | ColorFormat::Bgra8 => 4,
            ColorFormat::Rgb8 => 3,
        }
    }

    /// Byte offsets of R, G and B inside one pixel.
    fn rgb_offsets(&self) -> [usize; 3] {
        match self {
            ColorFormat::Rgba8 | ColorFormat::Rgb8 => [0, 1, 2],
            ColorFormat::Bgra8 => [2, 1, 0],
        }
    }
}

/// Sample format of a phone depth buffer; every format is **little-endian**.
///
/// | variant | source | bytes | z in metres |
/// |---|---|---|---|
/// | [`MetresF32`](Self::MetresF32) | `AVDepthData` `kCVPixelFormatType_DepthFloat32` | 4 | `v` |
/// | [`MetresF16`](Self::MetresF16) | `AVDepthData` `kCVPixelFormatType_DepthFloat16` | 2 | `v` |
/// | [`DisparityF32`](Self::DisparityF32) | `AVDepthData` `kCVPixelFormatType_DisparityFloat32` | 4 | `1/v` (`v` in 1/m) |
/// | [`DisparityF16`](Self::DisparityF16) | `AVDepthData` `kCVPixelFormatType_DisparityFloat16` | 2 | `1/v` (`v` in 1/m) |
/// | [`MillimetresU16`](Self::MillimetresU16) | ARCore `Frame.acquireDepthImage16Bits` | 2 | `v/1000` |
/// | [`Depth16`](Self::Depth16) | Android `ImageFormat.DEPTH16` | 2 | `(v & 0x1FFF)/1000` |
///
/// Invalid pixels (never read as near; filled later by [`fill_invalid`]): any sample whose z is 0, NaN,
/// ±∞ or negative (so a disparity of 0, NaN, ±∞ or negative too), and for [`Depth16`](Self::Depth16) a
/// confidence code of 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub enum DepthFormat {
    /// IEEE 754 binary32 z-depth in metres (iOS `DepthFloat32`).
    MetresF32,
    /// IEEE 754 binary16 z-depth in metres (iOS `DepthFloat16`), decoded with the `half` crate.
    MetresF16,
    /// IEEE 754 binary32 disparity in 1/m (iOS `DisparityFloat32`): z = 1/v metres.
    DisparityF32,
    /// IEEE 754 binary16 disparity in 1/m (iOS `DisparityFloat16`): z = 1/v metres.
    DisparityF16,
    /// Unsigned 16-bit z-depth in millimetres (ARCore `acquireDepthImage16Bits`): z = v/1000 m, 0 = no
    /// depth.
    MillimetresU16,
    /// Android `ImageFormat.DEPTH16`: the low 13 bits are the range in millimetres (z = range/1000 m), the
    /// high 3 bits a confidence code `c`: 0 means 100 % confidence, 1 means 0 %, 2..=7 mean `(c − 1)/7`.
    /// A pixel with range 0 or confidence code 1 is invalid; every other confidence is accepted.
    Depth16,
}

impl DepthFormat {
    /// Every depth format (for exhaustive tests and fuzzing).
    pub const ALL: [DepthFormat; 6] = [
        DepthFormat::MetresF32,
        DepthFormat::MetresF16,
        DepthFormat::DisparityF32,
        DepthFormat::DisparityF16,
        DepthFormat::MillimetresU16,
        DepthFormat::Depth16,
    ];

    /// Bytes per sample: 4 for the f32 formats, 2 for the others.
    pub fn bytes_per_pixel(&self) -> usize {
        match self {
            DepthFormat::MetresF32 | DepthFormat::DisparityF32 => 4,
            DepthFormat::MetresF16
            | DepthFormat::DisparityF16
            | DepthFormat::MillimetresU16
            | DepthFormat::Depth16 => 2,
        }
    }

    /// Decodes one little-endian sample of `bytes_per_pixel()` bytes to metres; `None` if invalid.
    fn decode_sample(&self, b: &[u8]) -> Option<f32> {
        let f32_le = |b: &[u8]| f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        let f16_le = |b: &[u8]| half::f16::from_le_bytes([b[0], b[1]]).to_f32();
        let u16_le = |b: &[u8]| u16::from_le_bytes([b[0], b[1]]);
        let z = match self {
            DepthFormat::MetresF32 => f32_le(b),
            DepthFormat::MetresF16 => f16_le(b),
            DepthFormat::DisparityF32 => 1.0 / f32_le(b),
            DepthFormat::DisparityF16 => 1.0 / f16_le(b),
            DepthFormat::MillimetresU16 => {
                return DepthEncoding::Millimetres16.decode_sample(u16_le(b))
            }
            DepthFormat::Depth16 => {
                let v = u16_le(b);
                if v >> 13 == 1 {
                    return None; // confidence 0 %
                }
                return DepthEncoding::Millimetres16.decode_sample(v & 0x1FFF);
            }
        };
        // Rejects 0, NaN, ±inf and negatives (for disparity: 1/0 = inf, 1/inf = 0, 1/NaN = NaN).
        (z.is_finite() && z > 0.0).then_some(z)
    }
}

/// Clockwise rotation applied to both buffers to make them upright (phone sensors deliver landscape
/// buffers; e.g. Android's `SENSOR_ORIENTATION` is the clockwise angle through which the output image
/// must be rotated to be upright in the device's native orientation).
///
/// For a buffer of `H` rows and `W` columns, the buffer pixel at row `y`, column `x` goes to:
///
/// | variant | output size | output pixel (row, column) |
/// |---|---|---|
/// | [`Deg0`](Self::Deg0) | `H × W` | `(y, x)` |
/// | [`Deg90`](Self::Deg90) | `W × H` | `(x, H − 1 − y)` |
/// | [`Deg180`](Self::Deg180) | `H × W` | `(H − 1 − y, W − 1 − x)` |
/// | [`Deg270`](Self::Deg270) | `W × H` | `(W − 1 − x, y)` |
///
/// So after `Deg90` the buffer's top-left pixel is at the top-right, after `Deg180` at the bottom-right and
/// after `Deg270` at the bottom-left.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize)]
pub enum Rotation {
    /// No rotation (default).
    #[default]
    Deg0,
    /// 90° clockwise.
    Deg90,
    /// 180°.
    Deg180,
    /// 270° clockwise (90° counter-clockwise).
    Deg270,
}

impl Rotation {
    /// `(height, width)` of a `height × width` buffer after this rotation (swapped for 90° and 270°).
    pub fn rotated_size(&self, height: usize, width: usize) -> (usize, usize) {
        match self {
            Rotation::Deg0 | Rotation::Deg180 => (height, width),
            Rotation::Deg90 | Rotation::Deg270 => (width, height),
        }
    }

    /// Buffer pixel `(row, column)` shown at output pixel `(yo, xo)` of a `h × w` buffer (the inverse of
    /// the table in the type's documentation). Requires `h, w ≥ 1` and `(yo, xo)` inside the output.
    fn source(&self, yo: usize, xo: usize, h: usize, w: usize) -> (usize, usize) {
        match self {
            Rotation::Deg0 => (yo, xo),
            Rotation::Deg90 => (h - 1 - xo, yo),
            Rotation::Deg180 => (h - 1 - yo, w - 1 - xo),
            Rotation::Deg270 => (xo, w - 1 - yo),
        }
    }
}

/// How the (rotated) camera frame is fitted to the hologram's `height × width`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize)]
pub enum Fit {
    /// Centred crop to the target aspect ratio (the crop's width or height rounded to whole pixels), then
    /// resample; fills the hologram, loses the frame's edges (default).
    #[default]
    Crop,
    /// Resample to the largest size with the frame's aspect ratio (rounded to whole pixels) that fits
    /// inside the target, centred (the extra pixel of an odd margin at the bottom / right); the margins get
    /// amplitude 0 (black) and depth 1 (far).
    Letterbox,
    /// Resample to the target size, ignoring the aspect ratio (exactly [`RgbdFrame::resize`]).
    Stretch,
}

/// A borrowed interleaved 8-bit colour buffer, sRGB-encoded, `height` rows of `width` pixels.
///
/// Row `y` starts at byte `y · stride`, where `stride = row_stride`, or `width · bytes_per_pixel` when
/// `row_stride` is 0 (packed). The buffer length must satisfy
/// `stride · (height − 1) + width · bpp ≤ data.len() ≤ stride · height` (the last row's padding may be
/// absent); see [`ColorImage::validate`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ColorImage<'a> {
    /// The pixel bytes.
    pub data: &'a [u8],
    /// Byte layout of a pixel.
    pub format: ColorFormat,
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Bytes from the start of one row to the next; `0` = packed (`width · bytes_per_pixel`).
    pub row_stride: usize,
}

/// A borrowed depth buffer, `height` rows of `width` little-endian samples, laid out like
/// [`ColorImage`] (row stride in bytes, `0` = packed; same length rule, see [`DepthImage::validate`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DepthImage<'a> {
    /// The sample bytes.
    pub data: &'a [u8],
    /// Sample format.
    pub format: DepthFormat,
    /// Samples per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Bytes from the start of one row to the next; `0` = packed (`width · bytes_per_pixel`).
    pub row_stride: usize,
}

/// A rectangle of a colour buffer in colour pixels, in the buffer as delivered (before the [`Rotation`]):
/// columns `x .. x + width`, rows `y .. y + height`; `(x, y)` is its top-left pixel (column, row as in
/// `docs/CONVENTIONS.md` §2).
///
/// [`CameraFrame::color_crop`] registers colour with depth when the depth buffer covers only part of the
/// colour buffer's field of view. ARCore is the case in point: its depth image covers the field of view of
/// the GPU camera texture (usually 16:9), not that of the 640 × 480 (4:3) CPU image; the CPU image's
/// rectangle seen by the texture is what `Frame.transformCoordinates2d` maps the texture's corners to
/// (`TEXTURE_NORMALIZED` → `IMAGE_PIXELS`), e.g. `x 0, y 60, width 640, height 360` for a 16:9 texture on a
/// 640 × 480 image. The Android helpers compute it (`RgbdFrames.fromArFrame`, `CameraPlanes.cropForTexture`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub struct CropRect {
    /// First column (pixels from the left edge of the buffer).
    pub x: usize,
    /// First row (pixels from the top edge of the buffer).
    pub y: usize,
    /// Columns, ≥ 1.
    pub width: usize,
    /// Rows, ≥ 1.
    pub height: usize,
}

impl CropRect {
    /// The whole of a `width × height` buffer (`x = y = 0`): cropping with it changes nothing.
    pub fn full(width: usize, height: usize) -> Self {
        CropRect {
            x: 0,
            y: 0,
            width,
            height,
        }
    }

    /// Checks that the rectangle is non-empty and lies inside a `buffer_width × buffer_height` buffer:
    /// `width ≥ 1`, `height ≥ 1`, `x + width ≤ buffer_width`, `y + height ≤ buffer_height` (checked
    /// arithmetic, so no sum overflows).
    ///
    /// Errors: [`HoloError::InvalidParameter`] named `color_crop`, giving the rectangle and the buffer's size.
    pub(crate) fn validate(&self, buffer_width: usize, buffer_height: usize) -> Result<()> {
        let CropRect {
            x,
            y,
            width,
            height,
        } = *self;
        let describe = || {
            format!(
                "colour crop x {x}, y {y}, width {width}, height {height} (columns {x}..{x}+{width}, \
                 rows {y}..{y}+{height})"
            )
        };
        if width == 0 || height == 0 {
            return Err(invalid(
                "color_crop",
                format!(
                    "{} is empty: width and height must be at least 1",
                    describe()
                ),
            ));
        }
        let inside = |start: usize, len: usize, limit: usize| {
            start.checked_add(len).is_some_and(|end| end <= limit)
        };
        if !inside(x, width, buffer_width) || !inside(y, height, buffer_height) {
            return Err(invalid(
                "color_crop",
                format!(
                    "{} does not lie inside the {buffer_width}x{buffer_height} colour buffer",
                    describe()
                ),
            ));
        }
        Ok(())
    }
}

/// Row stride and bytes per row of a validated buffer.
#[derive(Debug, Clone, Copy)]
struct Layout {
    stride: usize,
    bpp: usize,
}

/// Checks a buffer's size, stride and length (see [`ColorImage`]); `name` / `stride_name` name it in the
/// errors ([`HoloError::InvalidParameter`]).
fn check_layout(
    name: &'static str,
    stride_name: &'static str,
    len: usize,
    width: usize,
    height: usize,
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
    Ok(Layout { stride, bpp })
}

/// Calls `f(i, pixel_bytes)` for every output pixel `i` (row-major index in the rotated `[H', W']` frame)
/// of a validated `height × width` buffer.
fn for_each_rotated(
    data: &[u8],
    layout: Layout,
    height: usize,
    width: usize,
    rotation: Rotation,
    mut f: impl FnMut(usize, &[u8]),
) {
    let (ho, wo) = rotation.rotated_size(height, width);
    let Layout { stride, bpp } = layout;
    for yo in 0..ho {
        for xo in 0..wo {
            let (y, x) = rotation.source(yo, xo, height, width);
            // In bounds and without overflow: y·stride + (x+1)·bpp ≤ stride·(height−1) + width·bpp ≤ len.
            let off = y * stride + x * bpp;
            f(yo * wo + xo, &data[off..off + bpp]);
        }
    }
}

/// Error for an internal shape inconsistency (cannot happen for validated input).
fn shape_error(e: ndarray::ShapeError) -> HoloError {
    HoloError::Internal(format!("shape error on validated input: {e}"))
}

impl<'a> ColorImage<'a> {
    /// Checks the buffer: non-zero `width` and `height`; `stride ≥ width · bpp`; and
    /// `stride · (height − 1) + width · bpp ≤ data.len() ≤ stride · height`, all in checked arithmetic.
    ///
    /// Errors: [`HoloError::InvalidParameter`] with name `color` (zero size, size overflow, buffer too
    /// short or too long, giving the expected and actual byte counts) or `color_row_stride` (stride shorter
    /// than a row).
    pub fn validate(&self) -> Result<()> {
        self.layout().map(|_| ())
    }

    /// The sub-image `crop` of this buffer: the same bytes (no copy), format and row stride, `crop.width ×
    /// crop.height` pixels starting at column `crop.x` of row `crop.y` (before any rotation).
    ///
    /// Errors: those of [`ColorImage::validate`] for this buffer, then those of [`CropRect::validate`]
    /// (`color_crop`: empty, or not inside the buffer).
    pub(crate) fn crop(&self, crop: CropRect) -> Result<ColorImage<'a>> {
        let Layout { stride, bpp } = self.layout()?;
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

    fn layout(&self) -> Result<Layout> {
        check_layout(
            "color",
            "color_row_stride",
            self.data.len(),
            self.width,
            self.height,
            self.format.bytes_per_pixel(),
            self.row_stride,
        )
    }

    /// Decodes to linear amplitude `[3, H', W']`, channels R, G, B (whatever the byte order), each value
    /// [`srgb8_to_amplitude`] of its byte (`√(linear intensity)` in `[0, 1]`); alpha is ignored. The
    /// `rotation` is applied while decoding, so `(H', W') = rotation.rotated_size(height, width)`.
    ///
    /// Errors: those of [`ColorImage::validate`], checked before allocating.
    pub(crate) fn to_amplitude(self, rotation: Rotation) -> Result<Array3<f32>> {
        let layout = self.layout()?;
        let lut: [f32; 256] = std::array::from_fn(|c| srgb8_to_amplitude(c as u8));
        let (ho, wo) = rotation.rotated_size(self.height, self.width);
        // ho·wo ≤ data.len() and the output is 3·ho·wo f32 values: bounded by the input's size.
        let plane = ho * wo;
        let mut flat = vec![0.0f32; 3 * plane];
        let [r, g, b] = self.format.rgb_offsets();
        for_each_rotated(
            self.data,
            layout,
            self.height,
            self.width,
            rotation,
            |i, px| {
                flat[i] = lut[px[r] as usize];
                flat[plane + i] = lut[px[g] as usize];
                flat[2 * plane + i] = lut[px[b] as usize];
            },
        );
        Array3::from_shape_vec((3, ho, wo), flat).map_err(shape_error)
    }
}

impl DepthImage<'_> {
    /// Checks the buffer like [`ColorImage::validate`].
    ///
    /// Errors: [`HoloError::InvalidParameter`] with name `depth` (zero size, size overflow, buffer too
    /// short or too long, giving the expected and actual byte counts) or `depth_row_stride`.
    pub fn validate(&self) -> Result<()> {
        self.layout().map(|_| ())
    }

    fn layout(&self) -> Result<Layout> {
        check_layout(
            "depth",
            "depth_row_stride",
            self.data.len(),
            self.width,
            self.height,
            self.format.bytes_per_pixel(),
            self.row_stride,
        )
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
        let (ho, wo) = rotation.rotated_size(self.height, self.width);
        let mut values = vec![0.0f32; ho * wo];
        let mut valid = vec![false; ho * wo];
        let format = self.format;
        for_each_rotated(
            self.data,
            layout,
            self.height,
            self.width,
            rotation,
            |i, px| {
                if let Some(z) = format.decode_sample(px) {
                    values[i] = z;
                    valid[i] = true;
                }
            },
        );
        Ok(DecodedDepth {
            values: Array2::from_shape_vec((ho, wo), values).map_err(shape_error)?,
            valid: Array2::from_shape_vec((ho, wo), valid).map_err(shape_error)?,
            metric: true,
        })
    }
}

/// A depth buffer's confidence, borrowed: one byte per depth sample, `[height, width]` as the depth buffer,
/// rows `row_stride` bytes apart (`0` = packed). ARKit's `ARDepthData.confidenceMap` (`ARConfidenceLevel`: 0
/// low, 1 medium, 2 high) and ARCore's `Frame.acquireRawDepthConfidenceImage` (0–255, 255 = most confident).
/// Depth samples below `min_confidence` are invalid ([`crate::scene::apply_confidence`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConfidenceImage<'a> {
    /// One byte per sample.
    pub data: &'a [u8],
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

impl ConfidenceImage<'_> {
    /// Checks the buffer like [`ColorImage::validate`].
    ///
    /// Errors: [`HoloError::InvalidParameter`] with name `confidence` (zero size, size overflow, buffer too
    /// short or too long) or `confidence_row_stride`.
    pub(crate) fn validate(&self) -> Result<()> {
        self.layout().map(|_| ())
    }

    fn layout(&self) -> Result<Layout> {
        check_layout(
            "confidence",
            "confidence_row_stride",
            self.data.len(),
            self.width,
            self.height,
            1,
            self.row_stride,
        )
    }

    /// The confidence `[H', W']` after `rotation` (as [`DepthImage::decode`] turns its depth buffer).
    ///
    /// Errors: those of [`ConfidenceImage::validate`].
    pub(crate) fn decode(&self, rotation: Rotation) -> Result<Array2<u8>> {
        let layout = self.layout()?;
        let (ho, wo) = rotation.rotated_size(self.height, self.width);
        let mut out = vec![0u8; ho * wo];
        for_each_rotated(
            self.data,
            layout,
            self.height,
            self.width,
            rotation,
            |i, px| out[i] = px[0],
        );
        Array2::from_shape_vec((ho, wo), out).map_err(shape_error)
    }
}

/// An owned confidence buffer: the fields of [`ConfidenceImage`] with a `Vec<u8>`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfidenceImageBuf {
    /// One byte per sample.
    pub data: Vec<u8>,
    /// The lowest confidence kept ([`ConfidenceImage::min_confidence`]).
    pub min_confidence: u8,
    /// Samples per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Bytes from the start of one row to the next; `0` = packed.
    pub row_stride: usize,
}

impl ConfidenceImageBuf {
    /// Borrows as a [`ConfidenceImage`].
    pub(crate) fn view(&self) -> ConfidenceImage<'_> {
        ConfidenceImage {
            data: &self.data,
            min_confidence: self.min_confidence,
            width: self.width,
            height: self.height,
            row_stride: self.row_stride,
        }
    }
}

/// One phone camera frame, borrowed: a colour buffer, a depth buffer covering the same field of view as the
/// colour (or as its [`color_crop`](Self::color_crop)) at any resolution, and the clockwise rotation that
/// makes both upright. Convert with [`CameraFrame::to_rgbd`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CameraFrame<'a> {
    /// The colour buffer.
    pub color: ColorImage<'a>,
    /// The depth buffer (same field of view as `color`, or as `color_crop` when given).
    pub depth: DepthImage<'a>,
    /// Clockwise rotation applied to both buffers (after the crop).
    pub rotation: Rotation,
    /// The rectangle of `color`, in colour pixels before the rotation, that covers the depth buffer's field
    /// of view; `None` = the whole colour buffer. Applied before the rotation and the fit, so that colour
    /// and depth are registered (see [`CropRect`]; ARCore needs it).
    pub color_crop: Option<CropRect>,
    /// The depth buffer's confidence, where the camera gives one (ARKit, ARCore's raw depth): depth samples
    /// below its `min_confidence` are invalid, filled from their confident neighbours.
    pub confidence: Option<ConfidenceImage<'a>>,
}

/// An owned colour buffer: the fields of [`ColorImage`] with a `Vec<u8>`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ColorImageBuf {
    /// The pixel bytes.
    pub data: Vec<u8>,
    /// Byte layout of a pixel.
    pub format: ColorFormat,
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Bytes from the start of one row to the next; `0` = packed.
    pub row_stride: usize,
}

impl ColorImageBuf {
    /// Borrows as a [`ColorImage`].
    pub fn view(&self) -> ColorImage<'_> {
        ColorImage {
            data: &self.data,
            format: self.format,
            width: self.width,
            height: self.height,
            row_stride: self.row_stride,
        }
    }
}

/// An owned depth buffer: the fields of [`DepthImage`] with a `Vec<u8>`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DepthImageBuf {
    /// The sample bytes (little-endian).
    pub data: Vec<u8>,
    /// Sample format.
    pub format: DepthFormat,
    /// Samples per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Bytes from the start of one row to the next; `0` = packed.
    pub row_stride: usize,
}

impl DepthImageBuf {
    /// Borrows as a [`DepthImage`].
    pub fn view(&self) -> DepthImage<'_> {
        DepthImage {
            data: &self.data,
            format: self.format,
            width: self.width,
            height: self.height,
            row_stride: self.row_stride,
        }
    }
}

/// An owned [`CameraFrame`] (e.g. to keep a frame after the camera has recycled its buffers).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CameraFrameBuf {
    /// The colour buffer.
    pub color: ColorImageBuf,
    /// The depth buffer (same field of view as `color`, or as `color_crop` when given).
    pub depth: DepthImageBuf,
    /// Clockwise rotation applied to both buffers (after the crop).
    pub rotation: Rotation,
    /// The rectangle of `color` covering the depth's field of view ([`CameraFrame::color_crop`]).
    pub color_crop: Option<CropRect>,
    /// The depth buffer's confidence ([`CameraFrame::confidence`]).
    pub confidence: Option<ConfidenceImageBuf>,
}

impl CameraFrameBuf {
    /// Borrows as a [`CameraFrame`].
    pub fn view(&self) -> CameraFrame<'_> {
        CameraFrame {
            color: self.color.view(),
            depth: self.depth.view(),
            rotation: self.rotation,
            color_crop: self.color_crop,
            confidence: self.confidence.as_ref().map(ConfidenceImageBuf::view),
        }
    }
}

/// Options of [`CameraFrame::to_rgbd`]. `Default`: [`Fit::Crop`], automatic range (1st/99th percentiles
/// of the valid depths, as [`normalise_depth`]), linear in diopters, depth of a lower resolution brought to
/// the colour's by nearest neighbour (the joint bilateral upsampling is closer to full-resolution depth but
/// costs 85 ms at 1080p on two desktop cores, too much of a phone's frame for now: docs/VIDEO.md).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameOptions {
    /// How the frame fits the hologram's size.
    pub fit: Fit,
    /// Metric range mapped to `d ∈ [0,1]`; `None` = 1st/99th percentiles of the valid depths (computed
    /// over the whole rotated frame at colour resolution, before the fit).
    pub range: Option<DepthRange>,
    /// Metric → `d` mapping ([`DepthMapping::LinearDiopters`] by default).
    pub mapping: DepthMapping,
    /// How a depth buffer of another resolution than the colour's is brought to it (step 4;
    /// [`super::upsample_depth`]; nearest neighbour by default, see above).
    pub depth_upsampling: super::upsample::DepthUpsampling,
}

impl Default for FrameOptions {
    fn default() -> Self {
        Self {
            fit: Fit::default(),
            range: None,
            mapping: DepthMapping::default(),
            depth_upsampling: super::upsample::DepthUpsampling::Nearest,
        }
    }
}

/// What [`CameraFrame::to_rgbd`] found, for logs and app diagnostics (serialisable to JSON).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CameraFrameReport {
    /// Metric range mapped to `d ∈ [0,1]` (given or automatic). Always `Some` for the metric
    /// [`DepthFormat`]s.
    pub range_used: Option<DepthRange>,
    /// Fraction of the depth buffer's pixels (at its own resolution) that were invalid and were filled.
    pub invalid_fraction: f32,
    /// `(height, width)` of the colour buffer as delivered (before rotation).
    pub color_size: (usize, usize),
    /// `(height, width)` of the depth buffer as delivered (before rotation).
    pub depth_size: (usize, usize),
    /// The colour crop applied ([`CameraFrame::color_crop`]), `None` when the whole colour buffer was used.
    pub color_crop: Option<CropRect>,
}

/// Set once the aspect-ratio mismatch of step 4 has been logged (once per process, not per frame).
static ASPECT_WARNED: AtomicBool = AtomicBool::new(false);

/// Checks a target `height × width` for an [`RgbdFrame`] (non-zero, `3 · H · W` f32 values addressable).
fn check_target(height: usize, width: usize) -> Result<()> {
    if height == 0 {
        return Err(invalid("height", "target height must be non-zero, got 0"));
    }
    if width == 0 {
        return Err(invalid("width", "target width must be non-zero, got 0"));
    }
    let bytes = height
        .checked_mul(width)
        .and_then(|n| n.checked_mul(3 * std::mem::size_of::<f32>()));
    if bytes.is_none_or(|b| b > isize::MAX as usize) {
        return Err(invalid(
            "size",
            format!(
                "target size {height}x{width} is too large: [3, {height}, {width}] f32 overflows"
            ),
        ));
    }
    Ok(())
}

/// `round(num / den)` for positive `den`, in `u128`, clamped to `[1, max]`.
fn rounded_ratio(num: u128, den: u128, max: usize) -> usize {
    let r = (2 * num + den) / (2 * den);
    r.clamp(1, max as u128) as usize
}

/// Centred crop window `(y0, x0, height, width)` of an `h × w` frame with the aspect ratio of `th × tw`.
fn crop_window(h: usize, w: usize, th: usize, tw: usize) -> (usize, usize, usize, usize) {
    let (h128, w128, th128, tw128) = (h as u128, w as u128, th as u128, tw as u128);
    let (ch, cw) = if w128 * th128 > tw128 * h128 {
        // Wider than the target: keep the height, crop the width to h·tw/th.
        (h, rounded_ratio(h128 * tw128, th128, w))
    } else {
        (rounded_ratio(w128 * th128, tw128, h), w)
    };
    ((h - ch) / 2, (w - cw) / 2, ch, cw)
}

/// Size `(height, width)` of an `h × w` frame scaled to fit inside `th × tw` with its aspect ratio.
fn letterbox_size(h: usize, w: usize, th: usize, tw: usize) -> (usize, usize) {
    let (h128, w128, th128, tw128) = (h as u128, w as u128, th as u128, tw as u128);
    if w128 * th128 >= tw128 * h128 {
        // At least as wide as the target: full width.
        (rounded_ratio(h128 * tw128, w128, th), tw)
    } else {
        (th, rounded_ratio(w128 * th128, h128, tw))
    }
}

/// [`RgbdFrame::resize`] without the copy when the size is already right.
fn resize_owned(frame: RgbdFrame, height: usize, width: usize) -> Result<RgbdFrame> {
    if (frame.height(), frame.width()) == (height, width) {
        Ok(frame)
    } else {
        frame.resize(height, width)
    }
}

/// Step 6 of [`CameraFrame::to_rgbd`]: fits `frame` to `height × width` with `fit`.
fn fit_frame(frame: RgbdFrame, height: usize, width: usize, fit: Fit) -> Result<RgbdFrame> {
    match fit {
        Fit::Stretch => resize_owned(frame, height, width),
        Fit::Crop => {
            let (y0, x0, ch, cw) = crop_window(frame.height(), frame.width(), height, width);
            if (ch, cw) == (frame.height(), frame.width()) {
                return resize_owned(frame, height, width);
            }
            let cropped = RgbdFrame {
                amplitude: frame
                    .amplitude
                    .slice(s![.., y0..y0 + ch, x0..x0 + cw])
                    .to_owned(),
                depth: frame.depth.slice(s![y0..y0 + ch, x0..x0 + cw]).to_owned(),
            };
            drop(frame);
            resize_owned(cropped, height, width)
        }
        Fit::Letterbox => {
            let (ih, iw) = letterbox_size(frame.height(), frame.width(), height, width);
            let inner = resize_owned(frame, ih, iw)?;
            if (ih, iw) == (height, width) {
                return Ok(inner);
            }
            let (y0, x0) = ((height - ih) / 2, (width - iw) / 2);
            let mut amplitude = Array3::<f32>::zeros((3, height, width));
            let mut depth = Array2::<f32>::ones((height, width));
            amplitude
                .slice_mut(s![.., y0..y0 + ih, x0..x0 + iw])
                .assign(&inner.amplitude);
            depth
                .slice_mut(s![y0..y0 + ih, x0..x0 + iw])
                .assign(&inner.depth);
            Ok(RgbdFrame { amplitude, depth })
        }
    }
}

impl CameraFrame<'_> {
    /// Copies the buffers into an owned [`CameraFrameBuf`].
    pub fn to_buf(&self) -> CameraFrameBuf {
        CameraFrameBuf {
            color: ColorImageBuf {
                data: self.color.data.to_vec(),
                format: self.color.format,
                width: self.color.width,
                height: self.color.height,
                row_stride: self.color.row_stride,
            },
            depth: DepthImageBuf {
                data: self.depth.data.to_vec(),
                format: self.depth.format,
                width: self.depth.width,
                height: self.depth.height,
                row_stride: self.depth.row_stride,
            },
            rotation: self.rotation,
            color_crop: self.color_crop,
            confidence: self.confidence.map(|c| ConfidenceImageBuf {
                data: c.data.to_vec(),
                min_confidence: c.min_confidence,
                width: c.width,
                height: c.height,
                row_stride: c.row_stride,
            }),
        }
    }

    /// Converts the camera frame to an [`RgbdFrame`] of `height × width` pixels (`amplitude` `[3, height,
    /// width]` linear, R, G, B; `depth` `[height, width]`, `d ∈ [0,1]`, 0 = near) and a report:
    /// 1. validates the target size, [`FrameOptions::range`], both buffers ([`ColorImage::validate`],
    ///    [`DepthImage::validate`]) and the colour crop (`CropRect::validate`) before allocating anything;
    ///    with a [`color_crop`](Self::color_crop) the rest sees only that rectangle of the colour buffer
    ///    (`ColorImage::crop`, no copy);
    /// 2. decodes both buffers (`ColorImage::to_amplitude`, [`DepthImage::decode`]),
    /// 3. applying the [`Rotation`] to both while decoding (no extra copy);
    /// 4. resamples depth (values and validity) to the (cropped) colour resolution
    ///    ([`FrameOptions::depth_upsampling`]: nearest neighbour by default, or colour-guided joint bilateral).
    ///    Depth and (cropped) colour must cover the same field of view
    ///    (as `AVDepthData` and ARKit's `sceneDepth` do, and ARCore's depth image with the crop of its
    ///    texture's field of view): the depth map is stretched onto the colour frame, whatever its aspect
    ///    ratio (a mismatch over 2 % is logged as a warning, once per process);
    /// 5. [`normalise_depth`] with `options.range` (automatic: 1st/99th percentiles of the valid depths of
    ///    the whole rotated frame) and `options.mapping`, then [`fill_invalid`] (holes take the farthest
    ///    neighbouring depth, never near);
    /// 6. fits to `height × width` with `options.fit` ([`Fit`]), resampling with [`RgbdFrame::resize`]
    ///    (Catmull-Rom in intensity for amplitude, nearest for depth).
    ///
    /// Memory: the decoded colour and depth at colour resolution, the output, and for [`Fit::Crop`] one
    /// copy of the cropped region.
    ///
    /// With [`Fit::Stretch`] at the colour buffer's own (rotated) size, no crop, and a depth buffer of that
    /// size, the result equals [`crate::scene::load_rgbd`] on the same pixels.
    ///
    /// Errors, all before any allocation except the last: [`HoloError::InvalidParameter`] for a target
    /// `height` or `width` of 0 (`height` / `width`) or too large (`size`), an invalid
    /// [`FrameOptions::range`] (`depth_range`), or a bad buffer (`color`, `color_row_stride`, `depth`,
    /// `depth_row_stride`, `confidence`, `confidence_row_stride`; see [`ColorImage::validate`]; a confidence
    /// buffer of another size than the depth buffer: `confidence`), or a crop that is empty or outside the colour
    /// buffer (`color_crop`); [`HoloError::InvalidDepth`] when every depth
    /// pixel is invalid (or, after a downsampling of depth to colour resolution, no valid one is left).
    pub fn to_rgbd(
        &self,
        height: usize,
        width: usize,
        options: &FrameOptions,
    ) -> Result<(RgbdFrame, CameraFrameReport)> {
        let (amplitude, decoded, invalid_fraction) =
            self.registered(height, width, options, true)?;

        // 5. Normalise, then fill holes (never read as near).
        let (d, range_used) = normalise_depth(&decoded, options.range, options.mapping)?;
        let DecodedDepth { valid, .. } = decoded; // the metric values are no longer needed
        let filled = fill_invalid(&d, &valid)?;
        drop((d, valid));
        let frame = RgbdFrame::new(amplitude, filled)?;

        // 6. Fit to the hologram's size.
        let frame = fit_frame(frame, height, width, options.fit)?;
        let report = self.report(range_used, invalid_fraction);
        log::debug!(
            "camera frame {}x{} colour (crop {:?}) + {}x{} {:?} depth ({:.1} % invalid), {:?} -> {height}x{width} ({:?})",
            self.color.height,
            self.color.width,
            self.color_crop,
            self.depth.height,
            self.depth.width,
            self.depth.format,
            100.0 * invalid_fraction,
            self.rotation,
            options.fit
        );
        Ok((frame, report))
    }

    /// The report of a conversion of this frame with `range_used` and the depth buffer's `invalid_fraction`.
    fn report(&self, range_used: Option<DepthRange>, invalid_fraction: f32) -> CameraFrameReport {
        CameraFrameReport {
            range_used,
            invalid_fraction,
            color_size: (self.color.height, self.color.width),
            depth_size: (self.depth.height, self.depth.width),
            color_crop: self.color_crop,
        }
    }

    /// Steps 1–4 of [`CameraFrame::to_rgbd`]: validation, decoding with the rotation, depth (values and
    /// validity) to the (cropped) colour resolution. Returns amplitude `[3, Hc, Wc]`, the decoded depth
    /// `[Hc, Wc]` and the fraction of invalid pixels of the depth buffer. `need_depth`: refuse a depth buffer
    /// without one valid pixel (an RGB-D frame, an LDI's front layer), else accept it (an LDI's back layer
    /// may be empty).
    fn registered(
        &self,
        height: usize,
        width: usize,
        options: &FrameOptions,
        need_depth: bool,
    ) -> Result<(Array3<f32>, DecodedDepth, f32)> {
        // 1. Validation, before allocating anything.
        check_target(height, width)?;
        if let Some(r) = options.range {
            r.validate()?;
        }
        self.color.validate()?;
        self.depth.validate()?;
        if let Some(c) = &self.confidence {
            c.validate()?;
            if (c.height, c.width) != (self.depth.height, self.depth.width) {
                return Err(invalid(
                    "confidence",
                    format!(
                        "the confidence buffer is {}x{} (height x width), its depth buffer {}x{}: one \
                         confidence byte per depth sample",
                        c.height, c.width, self.depth.height, self.depth.width
                    ),
                ));
            }
        }
        let color = match self.color_crop {
            Some(crop) => self.color.crop(crop)?,
            None => self.color,
        };

        // 2 + 3. Decode with the rotation; depth first (small, and all-invalid fails early), its
        // low-confidence samples invalid.
        let mut decoded = self.depth.decode(self.rotation)?;
        if let Some(c) = &self.confidence {
            let map = c.decode(self.rotation)?;
            super::depth::apply_confidence(
                &mut decoded,
                &map,
                c.min_confidence,
                std::path::Path::new("the confidence buffer"),
            )?;
        }
        let invalid_fraction = decoded.invalid_fraction();
        if need_depth && decoded.valid.iter().all(|&v| !v) {
            return Err(HoloError::InvalidDepth(format!(
                "all {} pixels of the {}x{} {:?} depth buffer are invalid (0, NaN, ±inf, negative{})",
                decoded.valid.len(),
                self.depth.height,
                self.depth.width,
                self.depth.format,
                match (self.depth.format, self.confidence.is_some()) {
                    (_, true) => " or below the minimum confidence",
                    (DepthFormat::Depth16, false) => " or confidence 0 %",
                    _ => "",
                }
            )));
        }
        let amplitude = color.to_amplitude(self.rotation)?;
        let (_, hc, wc) = amplitude.dim();

        // 4. Depth to colour resolution (joint bilateral or nearest: values and validity alike).
        let (hd, wd) = decoded.values.dim();
        // Aspect ratios differing by more than 2 %: the depth map is stretched (same field of view).
        if decoded.aspect_mismatch(hc, wc) > super::depth::MAX_DEPTH_ASPECT_MISMATCH
            && !ASPECT_WARNED.swap(true, Ordering::Relaxed)
        {
            log::warn!(
                "depth buffer {hd}x{wd} and colour buffer {hc}x{wc} (after crop and rotation) differ in \
                 aspect ratio; the depth map is stretched onto the colour frame (same field of view \
                 assumed; ARCore needs color_crop); warned once"
            );
        }
        let decoded =
            super::upsample::upsample_depth(decoded, amplitude.view(), options.depth_upsampling);
        Ok((amplitude, decoded, invalid_fraction))
    }
}

/// Converts a layered depth image delivered as camera frames, one per layer front to back (what a
/// renderer's depth-peeling pass or a multi-layer capture gives), to a [`LayeredDepthImage`] of `height ×
/// width` pixels, with the buffer rules of [`CameraFrame::to_rgbd`] for every layer:
/// - each layer is validated, decoded, rotated and registered as steps 1–4 of [`CameraFrame::to_rgbd`]; all
///   must give layer 0's colour size;
/// - layer 0 is the RGB-D image: at least one valid depth pixel, holes filled ([`fill_invalid`]);
/// - in layers `K ≥ 1` an invalid depth sample (0, NaN, ±inf, negative, confidence 0 %) means "no point
///   here"; a point may appear only where layer `K − 1` holds one, no nearer than it;
/// - the metric depths of all layers map to `d ∈ [0, 1]` with one range: `options.range`, or the 1st/99th
///   percentiles of every layer's valid depths together;
/// - fitted to `height × width` with `options.fit` (letterbox bars: black and far in layer 0, no point
///   behind).
///
/// The report is layer 0's, with the common range.
///
/// Errors: as [`CameraFrame::to_rgbd`] for each layer; [`HoloError::InvalidParameter`] (`layers`) for no
/// layer; [`HoloError::ShapeMismatch`] when a layer's (cropped, rotated) colour size differs from layer 0's;
/// [`HoloError::InvalidDepth`] naming the layers for a violated order or a gap.
pub fn ldi_from_camera_frames(
    frames: &[CameraFrame<'_>],
    height: usize,
    width: usize,
    options: &FrameOptions,
) -> Result<(LayeredDepthImage, CameraFrameReport)> {
    let Some(front) = frames.first() else {
        return Err(invalid(
            "layers",
            "a layered depth image needs at least one layer",
        ));
    };
    let mut amplitudes: Vec<Array3<f32>> = Vec::with_capacity(frames.len());
    let mut decoded = Vec::with_capacity(frames.len());
    let mut invalid_fraction = 0.0;
    for (k, frame) in frames.iter().enumerate() {
        let (amplitude, d, invalid) = frame.registered(height, width, options, k == 0)?;
        if k == 0 {
            invalid_fraction = invalid;
        } else if amplitude.dim() != amplitudes[0].dim() {
            let (_, h0, w0) = amplitudes[0].dim();
            let (_, h, w) = amplitude.dim();
            return Err(HoloError::ShapeMismatch {
                what: format!(
                    "LDI layer {k}'s colour buffer vs layer 0's (after crop and rotation)"
                ),
                expected: vec![h0, w0],
                got: vec![h, w],
            });
        }
        amplitudes.push(amplitude);
        decoded.push(d);
    }
    let names: Vec<String> = (0..frames.len()).map(|k| format!("buffer {k}")).collect();
    let (ldi, range_used) =
        assemble_layers(amplitudes, decoded, &names, options.range, options.mapping)?;
    let ldi = fit_ldi(ldi, height, width, options.fit)?;
    Ok((ldi, front.report(range_used, invalid_fraction)))
}

/// [`fit_frame`] for every layer of an LDI: the same crop window or letterbox bars for all, resampled as
/// [`LayeredDepthImage::resize`]. Letterbox bars are black and far in layer 0 and hold no point behind.
fn fit_ldi(
    ldi: LayeredDepthImage,
    height: usize,
    width: usize,
    fit: Fit,
) -> Result<LayeredDepthImage> {
    let (h, w) = (ldi.height(), ldi.width());
    match fit {
        Fit::Stretch => ldi.resize(height, width),
        Fit::Crop => {
            let (y0, x0, ch, cw) = crop_window(h, w, height, width);
            if (ch, cw) == (h, w) {
                return ldi.resize(height, width);
            }
            let layers = ldi
                .into_layers()
                .into_iter()
                .map(|l| LdiLayer {
                    amplitude: l
                        .amplitude
                        .slice(s![.., y0..y0 + ch, x0..x0 + cw])
                        .to_owned(),
                    depth: l.depth.slice(s![y0..y0 + ch, x0..x0 + cw]).to_owned(),
                    valid: l.valid.slice(s![y0..y0 + ch, x0..x0 + cw]).to_owned(),
                })
                .collect();
            LayeredDepthImage::new(layers)?.resize(height, width)
        }
        Fit::Letterbox => {
            let (ih, iw) = letterbox_size(h, w, height, width);
            let inner = ldi.resize(ih, iw)?;
            if (ih, iw) == (height, width) {
                return Ok(inner);
            }
            let (y0, x0) = ((height - ih) / 2, (width - iw) / 2);
            let layers = inner
                .into_layers()
                .into_iter()
                .enumerate()
                .map(|(k, l)| {
                    let mut amplitude = Array3::<f32>::zeros((3, height, width));
                    let mut depth = Array2::<f32>::ones((height, width));
                    let mut valid = Array2::from_elem((height, width), k == 0);
                    amplitude
                        .slice_mut(s![.., y0..y0 + ih, x0..x0 + iw])
                        .assign(&l.amplitude);
                    depth
                        .slice_mut(s![y0..y0 + ih, x0..x0 + iw])
                        .assign(&l.depth);
                    valid
                        .slice_mut(s![y0..y0 + ih, x0..x0 + iw])
                        .assign(&l.valid);
                    LdiLayer {
                        amplitude,
                        depth,
                        valid,
                    }
                })
                .collect();
            LayeredDepthImage::new(layers)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_source_inverts_the_documented_mapping() {
        let (h, w) = (3usize, 5usize);
        for rot in [
            Rotation::Deg0,
            Rotation::Deg90,
            Rotation::Deg180,
            Rotation::Deg270,
        ] {
            // The documented forward mapping, written independently.
            let forward = |y: usize, x: usize| match rot {
                Rotation::Deg0 => (y, x),
                Rotation::Deg90 => (x, h - 1 - y),
                Rotation::Deg180 => (h - 1 - y, w - 1 - x),
                Rotation::Deg270 => (w - 1 - x, y),
            };
            let (ho, wo) = rot.rotated_size(h, w);
            let mut seen = vec![false; h * w];
            for yo in 0..ho {
                for xo in 0..wo {
                    let (y, x) = rot.source(yo, xo, h, w);
                    assert!(y < h && x < w, "{rot:?}");
                    assert_eq!(forward(y, x), (yo, xo), "{rot:?}");
                    assert!(!seen[y * w + x], "{rot:?}: not a bijection");
                    seen[y * w + x] = true;
                }
            }
        }
    }

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
            let e = check_layout("depth", "depth_row_stride", 4, w, h, 2, 0).unwrap_err();
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
    fn depth16_range_and_confidence() {
        let dec = |v: u16| DepthFormat::Depth16.decode_sample(&v.to_le_bytes());
        assert_eq!(dec(500), Some(0.5)); // confidence code 0 = 100 %
        assert_eq!(dec(500 | 1 << 13), None); // code 1 = 0 %
        for c in 2..8u16 {
            assert_eq!(dec(500 | c << 13), Some(0.5), "confidence code {c}");
        }
        assert_eq!(dec(0x1FFF), Some(8.191));
        assert_eq!(dec(0), None);
        assert_eq!(dec(7 << 13), None); // range 0 whatever the confidence
    }

    #[test]
    fn float_formats_reject_non_physical_values() {
        for v in [
            0.0f32,
            -0.0,
            -1.0,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ] {
            for f in [DepthFormat::MetresF32, DepthFormat::DisparityF32] {
                assert_eq!(f.decode_sample(&v.to_le_bytes()), None, "{f:?} {v}");
            }
            let h = half::f16::from_f32(v).to_le_bytes();
            for f in [DepthFormat::MetresF16, DepthFormat::DisparityF16] {
                assert_eq!(f.decode_sample(&h), None, "{f:?} {v}");
            }
        }
        // Disparity so small that 1/v overflows f32: invalid, not infinitely far.
        assert_eq!(
            DepthFormat::DisparityF32.decode_sample(&1e-40f32.to_le_bytes()),
            None
        );
        assert_eq!(
            DepthFormat::DisparityF32.decode_sample(&4.0f32.to_le_bytes()),
            Some(0.25)
        );
    }

    #[test]
    fn crop_and_letterbox_geometry() {
        // 480x640 (4:3 landscape) into a square: crop the centre 480x480; letterbox to 480x480 in 640.
        assert_eq!(crop_window(480, 640, 100, 100), (0, 80, 480, 480));
        assert_eq!(letterbox_size(480, 640, 100, 100), (75, 100));
        // Portrait target from a landscape frame.
        assert_eq!(crop_window(480, 640, 200, 100), (0, 200, 480, 240));
        assert_eq!(letterbox_size(480, 640, 200, 100), (75, 100));
        // Taller than the target: crop rows.
        assert_eq!(crop_window(640, 480, 100, 100), (80, 0, 480, 480));
        assert_eq!(letterbox_size(640, 480, 100, 100), (100, 75));
        // Same aspect: nothing cropped, full target.
        assert_eq!(crop_window(480, 640, 3, 4), (0, 0, 480, 640));
        assert_eq!(letterbox_size(480, 640, 3, 4), (3, 4));
        // Extreme ratios never give an empty window.
        assert_eq!(crop_window(1, 1000, 1000, 1), (0, 499, 1, 1));
        assert_eq!(letterbox_size(1, 1000, 1000, 1), (1, 1));
        // Huge sizes do not overflow.
        let big = usize::MAX / 2;
        assert_eq!(crop_window(big, big, 1, 1), (0, 0, big, big));
    }

    /// An RGB8 `h × w` buffer (packed) whose pixel `(y, x)` is `px(y, x)`.
    fn rgb8(h: usize, w: usize, px: impl Fn(usize, usize) -> [u8; 3]) -> Vec<u8> {
        let mut v = Vec::with_capacity(h * w * 3);
        for y in 0..h {
            for x in 0..w {
                v.extend_from_slice(&px(y, x));
            }
        }
        v
    }

    #[test]
    fn crop_rect_is_validated_with_a_typed_error() {
        let ok = |c: CropRect| c.validate(640, 480);
        assert!(ok(CropRect::full(640, 480)).is_ok());
        assert!(ok(CropRect {
            x: 0,
            y: 60,
            width: 640,
            height: 360
        })
        .is_ok());
        assert!(ok(CropRect {
            x: 639,
            y: 479,
            width: 1,
            height: 1
        })
        .is_ok());
        for (bad, needle) in [
            (
                CropRect {
                    x: 0,
                    y: 0,
                    width: 0,
                    height: 10,
                },
                "is empty",
            ),
            (
                CropRect {
                    x: 0,
                    y: 0,
                    width: 10,
                    height: 0,
                },
                "is empty",
            ),
            (
                CropRect {
                    x: 1,
                    y: 0,
                    width: 640,
                    height: 480,
                },
                "inside the 640x480",
            ),
            (
                CropRect {
                    x: 0,
                    y: 121,
                    width: 640,
                    height: 360,
                },
                "inside the 640x480",
            ),
            (
                CropRect {
                    x: usize::MAX,
                    y: 0,
                    width: 2,
                    height: 1,
                },
                "inside",
            ),
            (
                CropRect {
                    x: 0,
                    y: usize::MAX,
                    width: 1,
                    height: usize::MAX,
                },
                "inside",
            ),
        ] {
            match ok(bad) {
                Err(HoloError::InvalidParameter { name, reason }) => {
                    assert_eq!(name, "color_crop", "{reason}");
                    assert!(reason.contains(needle), "{bad:?}: {reason}");
                }
                other => panic!("{bad:?}: expected InvalidParameter, got {other:?}"),
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
            data: &data,
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

    /// The ARCore case, computed by hand: a 640 × 480 CPU image whose depth (160 × 90) covers the 16:9
    /// texture's field of view, rows 60..420 of the CPU image (`transformCoordinates2d`). A horizontal edge
    /// of the scene at 37 % of that field of view lies at CPU row 60 + 0.37·360 = 193.2 (rows 0..=192 are
    /// bright, near) and at depth row 0.37·90 = 33.3 (rows 0..=32 near). Portrait (`Deg90`) turns it into a
    /// vertical edge.
    fn arcore_edge_frame(crop: Option<CropRect>) -> (RgbdFrame, CameraFrameReport) {
        let color = rgb8(480, 640, |y, _| if y <= 192 { [230; 3] } else { [20; 3] });
        let depth: Vec<u8> = (0..90usize)
            .flat_map(|y| {
                let mm: u16 = if y <= 32 { 500 } else { 2000 };
                (0..160).flat_map(move |_| mm.to_le_bytes())
            })
            .collect();
        let frame = CameraFrame {
            color: ColorImage {
                data: &color,
                format: ColorFormat::Rgb8,
                width: 640,
                height: 480,
                row_stride: 0,
            },
            depth: DepthImage {
                data: &depth,
                format: DepthFormat::MillimetresU16,
                width: 160,
                height: 90,
                row_stride: 0,
            },
            rotation: Rotation::Deg90,
            color_crop: crop,
            confidence: None,
        };
        let (ho, wo) = match crop {
            Some(c) => (c.width, c.height),
            None => (640, 480),
        };
        let options = FrameOptions {
            fit: Fit::Stretch,
            // The registration is checked on nearest neighbour's samples (the rows it reads are documented).
            depth_upsampling: super::super::DepthUpsampling::Nearest,
            ..FrameOptions::default()
        };
        frame.to_rgbd(ho, wo, &options).unwrap()
    }

    /// Last column (from the left) of row 0 where `bright` holds, in a frame whose left part holds it.
    fn last_column(row: impl Iterator<Item = bool>) -> usize {
        let v: Vec<bool> = row.collect();
        let n = v.iter().take_while(|&&b| b).count();
        assert!(v[n..].iter().all(|&b| !b), "one edge only");
        n - 1
    }

    #[test]
    fn crop_registers_arcore_colour_with_its_texture_field_of_view() {
        let crop = CropRect {
            x: 0,
            y: 60,
            width: 640,
            height: 360,
        };
        let (f, report) = arcore_edge_frame(Some(crop));
        assert_eq!((f.height(), f.width()), (640, 360));
        assert_eq!(report.color_crop, Some(crop));
        assert_eq!(report.color_size, (480, 640));
        // After Deg90, buffer row r is output column 359 − r. Colour: cropped rows 133.. (CPU rows 193..) are
        // dark → columns 0..=226 dark; depth: 90 → 360 rows by nearest (row o reads ⌊(o + ½)/4⌋), rows
        // 132.. far → columns 0..=227 far.
        for y in [0, 320, 639] {
            let dark = last_column((0..360).map(|x| f.amplitude[[1, y, x]] < 0.5));
            let far = last_column((0..360).map(|x| f.depth[[y, x]] > 0.5));
            assert_eq!((dark, far), (226, 227), "row {y}");
        }
        // Without the crop the depth is stretched over all 480 CPU rows: colour edge at column 479 − 193 =
        // 286, depth's at 479 − 176 = 303 (row o reads ⌊(o + ½)·90/480⌋ ≥ 33 from o = 176): 17 pixels apart.
        let (f, report) = arcore_edge_frame(None);
        assert_eq!(report.color_crop, None);
        let dark = last_column((0..480).map(|x| f.amplitude[[1, 0, x]] < 0.5));
        let far = last_column((0..480).map(|x| f.depth[[0, x]] > 0.5));
        assert_eq!((dark, far), (286, 303));
    }

    #[test]
    fn a_bad_crop_fails_the_conversion_before_decoding() {
        let color = rgb8(4, 4, |_, _| [9; 3]);
        let depth = 1000u16.to_le_bytes().repeat(4);
        let frame = CameraFrame {
            color: ColorImage {
                data: &color,
                format: ColorFormat::Rgb8,
                width: 4,
                height: 4,
                row_stride: 0,
            },
            depth: DepthImage {
                data: &depth,
                format: DepthFormat::MillimetresU16,
                width: 2,
                height: 2,
                row_stride: 0,
            },
            rotation: Rotation::Deg0,
            color_crop: Some(CropRect {
                x: 2,
                y: 2,
                width: 3,
                height: 2,
            }),
            confidence: None,
        };
        match frame.to_rgbd(2, 2, &FrameOptions::default()) {
            Err(HoloError::InvalidParameter { name, reason }) => {
                assert_eq!(name, "color_crop");
                assert!(
                    reason.contains("x 2, y 2, width 3, height 2") && reason.contains("4x4"),
                    "{reason}"
                );
            }
            other => panic!("expected color_crop error, got {other:?}"),
        }
        // The whole buffer as a crop gives exactly the uncropped result.
        let full = CameraFrame {
            color_crop: Some(CropRect::full(4, 4)),
            ..frame
        };
        let none = CameraFrame {
            color_crop: None,
            ..frame
        };
        let opts = FrameOptions::default();
        assert_eq!(
            full.to_rgbd(3, 3, &opts).unwrap().0,
            none.to_rgbd(3, 3, &opts).unwrap().0
        );
    }
}

//! Geometry of a camera frame: the [`Rotation`] that makes its buffers upright, the colour [`CropRect`] that
//! registers colour with depth, and the [`Fit`] of the upright frame to the hologram's size (crop window,
//! letterbox size, resampling).

use ndarray::{s, Array2, Array3};
use serde::Serialize;

use crate::error::{invalid, Result};
use crate::scene::frame::RgbdFrame;

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
    pub(super) fn source(&self, yo: usize, xo: usize, h: usize, w: usize) -> (usize, usize) {
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

/// A rectangle of a colour buffer in colour pixels, in the buffer as delivered (before the [`Rotation`]):
/// columns `x .. x + width`, rows `y .. y + height`; `(x, y)` is its top-left pixel (column, row as in
/// `docs/CONVENTIONS.md` §2).
///
/// [`CameraFrame::color_crop`](crate::scene::CameraFrame::color_crop) registers colour with depth when the
/// depth buffer covers only part of the colour buffer's field of view. ARCore is the case in point: its
/// depth image covers the field of view of the GPU camera texture (usually 16:9), not that of the 640 × 480
/// (4:3) CPU image; the CPU image's
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
    /// Errors: [`crate::HoloError::InvalidParameter`] named `color_crop`, giving the rectangle and the buffer's size.
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
/// Checks a target `height × width` for an [`RgbdFrame`] (non-zero, `3 · H · W` f32 values addressable).
pub(super) fn check_target(height: usize, width: usize) -> Result<()> {
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
pub(super) fn crop_window(
    h: usize,
    w: usize,
    th: usize,
    tw: usize,
) -> (usize, usize, usize, usize) {
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
pub(super) fn letterbox_size(h: usize, w: usize, th: usize, tw: usize) -> (usize, usize) {
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

/// Step 6 of [`crate::scene::CameraFrame::to_rgbd`]: fits `frame` to `height × width` with `fit`.
pub(super) fn fit_frame(
    frame: RgbdFrame,
    height: usize,
    width: usize,
    fit: Fit,
) -> Result<RgbdFrame> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::HoloError;

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
}

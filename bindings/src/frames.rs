//! Camera frames in ([`RgbdFrame`], [`convert_frame`]) and a frame's results out ([`SlmPatterns`],
//! [`StageTimings`], [`pack_rgba`], [`Preview`]), with the frame enums.

use ndarray::Axis;
use tensorholo::generator as core;
use tensorholo::scene;

use crate::enums::mirror_enum;
use crate::error::{guard, invalid, Result};

/// How the camera frame fits the hologram's size.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum Fit {
    /// Centred crop to the hologram's aspect ratio (the default).
    Crop,
    /// Fit inside, black (and far) margins.
    Letterbox,
    /// Resample ignoring the aspect ratio.
    Stretch,
}

mirror_enum!(Fit <=> scene::Fit { Crop, Letterbox, Stretch });

/// How a depth buffer of a lower resolution than the colour's (ARKit's 256 × 192 LiDAR depth under a
/// 1920 × 1440 image, ARCore's ~160 × 120) is brought to the colour's resolution (`docs/VIDEO.md`, "Depth at
/// the sensor's resolution").
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum DepthUpsampling {
    /// Nearest neighbour (the default): blocky depth edges at the depth's own resolution, the cheapest.
    Nearest,
    /// Joint bilateral upsampling guided by the colour (Kopf et al. 2007): depth edges follow the colour's,
    /// closer to full-resolution depth (1.4–6.4 dB closer on rendered frames with exact depth at 1/4 and
    /// 1/8 resolution), at about 85 ms per 1080p frame on two desktop cores.
    JointBilateral,
}

mirror_enum!(DepthUpsampling <=> scene::DepthUpsampling { Nearest, JointBilateral });

/// Byte layout of an interleaved 8-bit sRGB colour pixel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum ColorFormat {
    /// R, G, B, A (Android `Bitmap.Config.ARGB_8888` bytes).
    Rgba8,
    /// B, G, R, A (iOS `kCVPixelFormatType_32BGRA`).
    Bgra8,
    /// R, G, B.
    Rgb8,
}

mirror_enum!(ColorFormat <=> scene::ColorFormat { Rgba8, Bgra8, Rgb8 });

/// Depth sample format, little-endian.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum DepthFormat {
    /// f32 metres (AVDepthData `DepthFloat32`).
    MetresF32,
    /// f16 metres (AVDepthData `DepthFloat16`).
    MetresF16,
    /// f32 disparity in 1/m (AVDepthData `DisparityFloat32`).
    DisparityF32,
    /// f16 disparity in 1/m (AVDepthData `DisparityFloat16`).
    DisparityF16,
    /// u16 millimetres (ARCore `acquireDepthImage16Bits`).
    MillimetresU16,
    /// Android `ImageFormat.DEPTH16`: low 13 bits millimetres, high 3 bits confidence.
    Depth16,
}

mirror_enum!(DepthFormat <=> scene::DepthFormat {
    MetresF32,
    MetresF16,
    DisparityF32,
    DisparityF16,
    MillimetresU16,
    Depth16,
});

/// Clockwise rotation that makes the camera buffers upright.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum Rotation {
    /// None.
    Deg0,
    /// 90° clockwise.
    Deg90,
    /// 180°.
    Deg180,
    /// 270° clockwise.
    Deg270,
}

mirror_enum!(Rotation <=> scene::Rotation { Deg0, Deg90, Deg180, Deg270 });

/// One camera frame as the phone delivers it: an interleaved 8-bit colour buffer and a depth buffer of the
/// same field of view, each at its own resolution with its own row stride (bytes; 0 = packed).
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct RgbdFrame {
    /// Colour bytes (`color_format`), rows `color_row_stride` apart.
    pub color: Vec<u8>,
    /// Colour pixel layout.
    pub color_format: ColorFormat,
    /// Colour width in pixels.
    pub color_width: u32,
    /// Colour height in pixels.
    pub color_height: u32,
    /// Depth bytes (`depth_format`, little-endian), rows `depth_row_stride` apart.
    pub depth: Vec<u8>,
    /// Depth sample format.
    pub depth_format: DepthFormat,
    /// Depth width in pixels.
    pub depth_width: u32,
    /// Depth height in pixels.
    pub depth_height: u32,
    /// Bytes from one colour row to the next; 0 (default) = packed.
    #[uniffi(default = 0)]
    pub color_row_stride: u32,
    /// Bytes from one depth row to the next; 0 (default) = packed.
    #[uniffi(default = 0)]
    pub depth_row_stride: u32,
    /// Clockwise rotation making both buffers upright; `None` (default) = none.
    #[uniffi(default = None)]
    pub rotation: Option<Rotation>,
    /// The rectangle of the colour buffer (colour pixels, before the rotation) that covers the depth
    /// buffer's field of view; `None` (default) = the whole colour buffer. ARCore needs it: its depth covers
    /// the GPU texture's field of view (usually 16:9), a band of the 4:3 CPU image (Android:
    /// `RgbdFrames.fromArFrame` fills it). Errors: [`TensorholoError::InvalidInput`](crate::TensorholoError::InvalidInput) when it is empty or not
    /// inside the colour buffer.
    #[uniffi(default = None)]
    pub color_crop: Option<CropRect>,
    /// The depth buffer's confidence, one byte per depth sample (`depth_width × depth_height`, rows
    /// `confidence_row_stride` apart): ARKit's `sceneDepth.confidenceMap` (0 low, 1 medium, 2 high), ARCore's
    /// `acquireRawDepthConfidenceImage` (0–255). Depth samples below `min_confidence` are invalid, filled from
    /// their confident neighbours (never read as near). `None` (default): every depth sample is taken.
    /// Errors: [`TensorholoError::InvalidInput`](crate::TensorholoError::InvalidInput) for another size than
    /// the depth buffer's or a buffer of the wrong length.
    #[uniffi(default = None)]
    pub confidence: Option<Vec<u8>>,
    /// Bytes from one confidence row to the next; 0 (default) = packed.
    #[uniffi(default = 0)]
    pub confidence_row_stride: u32,
    /// The lowest confidence kept: 1 (default: ARKit's medium and high); on ARCore's 0–255 scale e.g. 128.
    #[uniffi(default = 1)]
    pub min_confidence: u8,
}

/// A rectangle of a colour buffer in pixels, before any rotation: columns `x .. x + width`, rows
/// `y .. y + height` (`(x, y)` = its top-left pixel).
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Record)]
pub struct CropRect {
    /// First column.
    pub x: u32,
    /// First row.
    pub y: u32,
    /// Columns (≥ 1).
    pub width: u32,
    /// Rows (≥ 1).
    pub height: u32,
}

impl From<CropRect> for scene::CropRect {
    fn from(c: CropRect) -> Self {
        Self {
            x: c.x as usize,
            y: c.y as usize,
            width: c.width as usize,
            height: c.height as usize,
        }
    }
}

impl RgbdFrame {
    /// The core's owned frame (the byte vectors move, nothing is copied).
    pub(crate) fn into_core(self) -> scene::CameraFrameBuf {
        scene::CameraFrameBuf {
            color: scene::ColorImageBuf {
                data: self.color,
                format: self.color_format.into(),
                width: self.color_width as usize,
                height: self.color_height as usize,
                row_stride: self.color_row_stride as usize,
            },
            depth: scene::DepthImageBuf {
                data: self.depth,
                format: self.depth_format.into(),
                width: self.depth_width as usize,
                height: self.depth_height as usize,
                row_stride: self.depth_row_stride as usize,
            },
            rotation: self.rotation.unwrap_or(Rotation::Deg0).into(),
            color_crop: self.color_crop.map(Into::into),
            confidence: self.confidence.map(|data| scene::ConfidenceImageBuf {
                data,
                min_confidence: self.min_confidence,
                width: self.depth_width as usize,
                height: self.depth_height as usize,
                row_stride: self.confidence_row_stride as usize,
            }),
        }
    }
}

/// A camera frame as the CNN receives it ([`convert_frame`]): `width × height` pixels, upright, registered
/// and fitted.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct ConvertedFrame {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Linear amplitude (√ of the linear intensity, in [0, 1]): three planes R, G, B of `width · height`
    /// values each, row-major (`3 · width · height` values).
    pub amplitude: Vec<f32>,
    /// Normalised depth `d` in [0, 1], 0 = near, row-major (`width · height` values); holes filled with
    /// the farthest neighbouring depth.
    pub depth: Vec<f32>,
    /// Nearest depth in metres mapped to `d = 0` (the 1st percentile of the frame's valid depths).
    pub z_near_m: Option<f64>,
    /// Farthest depth in metres mapped to `d = 1` (the 99th percentile).
    pub z_far_m: Option<f64>,
}

/// Converts a camera frame the way a generator does before its CNN (crop, rotation, depth to the colour
/// grid, automatic depth range, hole filling, `fit` to `width × height`; `fit` `None` = [`Fit::Crop`]),
/// without rendering: to check the orientation and the depth–colour registration on a device, e.g. by
/// drawing `depth` over `amplitude`.
///
/// `depth_upsampling` `None` (default) = [`DepthUpsampling::Nearest`], as a generator's default.
///
/// Errors: [`TensorholoError::InvalidInput`](crate::TensorholoError::InvalidInput) for a `width` or `height` of 0, buffers that do not match
/// their sizes, strides and formats, a bad `color_crop`, or a depth map without one valid pixel.
#[uniffi::export(default(depth_upsampling = None))]
pub fn convert_frame(
    frame: RgbdFrame,
    width: u32,
    height: u32,
    fit: Option<Fit>,
    depth_upsampling: Option<DepthUpsampling>,
) -> Result<ConvertedFrame> {
    guard(|| {
        let frame = frame.into_core();
        // `None`: the core's default (`FrameOptions::default()`, the one statement of the camera's defaults).
        let mut options = scene::FrameOptions::default();
        if let Some(fit) = fit {
            options.fit = fit.into();
        }
        if let Some(upsampling) = depth_upsampling {
            options.depth_upsampling = upsampling.into();
        }
        let (rgbd, report) = frame
            .view()
            .to_rgbd(height as usize, width as usize, &options)?;
        Ok(ConvertedFrame {
            width,
            height,
            amplitude: rgbd.amplitude.iter().copied().collect(),
            depth: rgbd.depth.iter().copied().collect(),
            z_near_m: report.range_used.map(|r| r.z_near_m as f64),
            z_far_m: report.range_used.map(|r| r.z_far_m as f64),
        })
    })
}

/// Milliseconds of each stage of one frame.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct StageTimings {
    /// Camera buffers → the CNN's input (decode, rotate, fill holes, fit).
    pub convert_ms: f64,
    /// Hologram CNN.
    pub cnn_ms: f64,
    /// Offset propagation to the SLM (Eq. 6).
    pub offset_ms: f64,
    /// Pre-filter CNN alone (0 without one).
    pub prefilter_ms: f64,
    /// Double phase encoding and look-up table (Eq. 7), with turning the pre-filter CNN's output into the
    /// field where there is one.
    pub encoding_ms: f64,
    /// On the GPU: the whole GPU frame (CNNs and optics; the three stage fields above are then 0 and
    /// `cnn_ms` is the CPU's input checks and packing). 0 on the CPU.
    pub gpu_ms: f64,
    /// CNN to codes (in a stream: the frame period).
    pub total_ms: f64,
}

/// One frame's SLM patterns: three 8-bit planes, one per laser (field-sequential colour), `width · height`
/// codes each, row-major; code `c` displays phase `2π·c/256`.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct SlmPatterns {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Red laser's pattern.
    pub red: Vec<u8>,
    /// Green laser's pattern.
    pub green: Vec<u8>,
    /// Blue laser's pattern.
    pub blue: Vec<u8>,
    /// Nearest scene depth (metres) mapped to the volume in this frame, if the depth was metric.
    pub z_near_m: Option<f64>,
    /// Farthest scene depth (metres) mapped to the volume in this frame.
    pub z_far_m: Option<f64>,
    /// Stage timings.
    pub timings: StageTimings,
    /// In a stream, the phase change from the previous frame's patterns: the mean wrapped `|Δφ|` over every
    /// colour and pixel, radians (through the linear look-up table); `None` for a stream's first frame and
    /// outside a stream.
    pub phase_churn_rad: Option<f64>,
    /// In a stream, the share of (colour, pixel) values whose phase changed by more than π/2 since the
    /// previous frame, `[0, 1]`; `None` as `phase_churn_rad`.
    pub churn_above_half_pi: Option<f64>,
}

impl From<core::SlmPatterns> for SlmPatterns {
    fn from(p: core::SlmPatterns) -> Self {
        let plane = |c: usize| p.codes.index_axis(Axis(0), c).iter().copied().collect();
        let t = p.timings;
        Self {
            width: p.width as u32,
            height: p.height as u32,
            red: plane(0),
            green: plane(1),
            blue: plane(2),
            z_near_m: p.depth_range.map(|r| r.z_near_m as f64),
            z_far_m: p.depth_range.map(|r| r.z_far_m as f64),
            timings: t.into(),
            phase_churn_rad: p.phase_churn.map(|c| c.mean_abs_rad),
            churn_above_half_pi: p.phase_churn.map(|c| c.above_half_pi),
        }
    }
}

impl From<core::PatternTimings> for StageTimings {
    fn from(t: core::PatternTimings) -> Self {
        Self {
            convert_ms: t.convert_s * 1e3,
            cnn_ms: t.frame.cnn_s * 1e3,
            offset_ms: t.frame.offset_s * 1e3,
            prefilter_ms: t.frame.prefilter_s * 1e3,
            encoding_ms: t.frame.encoding_s * 1e3,
            gpu_ms: t.frame.gpu_s * 1e3,
            total_ms: t.frame.total_s * 1e3,
        }
    }
}

/// The most pixels a frame's colour or depth buffer may have (width × height): the core's image limit
/// (`tensorholo::io::InputLimits::max_image_pixels`, 100 M by default: a 48 MP phone photo twice over). A
/// larger buffer is `InvalidInput`; the Python package refuses it before copying an array.
#[uniffi::export]
pub fn max_frame_pixels() -> u64 {
    tensorholo::io::input_limits().max_image_pixels
}

/// The 32-bit frame colour-sequential SLM drivers take over HDMI: `width · height · 4` bytes, row-major, the
/// red laser's pattern in R, green in G, blue in B, alpha 255.
///
/// Errors: [`TensorholoError::InvalidInput`](crate::TensorholoError::InvalidInput) if a plane does not hold `width · height` codes.
#[uniffi::export]
pub fn pack_rgba(patterns: SlmPatterns) -> Result<Vec<u8>> {
    guard(|| {
        let n = (patterns.width as usize)
            .checked_mul(patterns.height as usize)
            .ok_or_else(|| invalid("width · height overflows"))?;
        for (name, p) in [
            ("red", &patterns.red),
            ("green", &patterns.green),
            ("blue", &patterns.blue),
        ] {
            if p.len() != n {
                return Err(invalid(format!(
                    "the {name} plane holds {} codes, expected width · height = {n}",
                    p.len()
                )));
            }
        }
        Ok(core::pack_rgba_planes(
            &patterns.red,
            &patterns.green,
            &patterns.blue,
        )?)
    })
}

/// A simulated view of the hologram for the phone's screen: `width · height · 4` sRGB bytes (RGBA, alpha
/// 255), row-major.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct Preview {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// RGBA8 bytes.
    pub rgba: Vec<u8>,
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::error::TensorholoError;

    /// A 48×32 RGB8 frame with metric depth (a ramp from 0.5 m to 1.5 m) and a few texture edges.
    pub(crate) fn frame() -> RgbdFrame {
        let (w, h) = (48u32, 32u32);
        let mut color = Vec::new();
        let mut depth = Vec::new();
        for y in 0..h {
            for x in 0..w {
                color.extend([(x * 5) as u8, (y * 7) as u8, ((x ^ y) * 9) as u8]);
                depth.extend((0.5 + (x as f32) / w as f32).to_le_bytes());
            }
        }
        RgbdFrame {
            color,
            color_format: ColorFormat::Rgb8,
            color_width: w,
            color_height: h,
            depth,
            depth_format: DepthFormat::MetresF32,
            depth_width: w,
            depth_height: h,
            color_row_stride: 0,
            depth_row_stride: 0,
            rotation: None,
            color_crop: None,
            confidence: None,
            confidence_row_stride: 0,
            min_confidence: 1,
        }
    }

    /// The crop reaches the core: the right half of a frame whose left half is black converts to a
    /// bright frame; a crop outside the buffer is `InvalidInput` naming it.
    #[test]
    fn convert_frame_applies_the_colour_crop() {
        let mut f = frame();
        for (i, px) in f.color.chunks_mut(3).enumerate() {
            let v = if i % 48 < 24 { 0 } else { 255 };
            px.copy_from_slice(&[v; 3]);
        }
        let whole = convert_frame(f.clone(), 24, 32, Some(Fit::Stretch), None).unwrap();
        assert_eq!(
            (whole.amplitude.len(), whole.depth.len()),
            (3 * 24 * 32, 24 * 32)
        );
        assert_eq!(whole.amplitude[0], 0.0);
        let crop = CropRect {
            x: 24,
            y: 0,
            width: 24,
            height: 32,
        };
        let right = convert_frame(
            RgbdFrame {
                color_crop: Some(crop),
                ..f.clone()
            },
            24,
            32,
            Some(Fit::Stretch),
            None,
        )
        .unwrap();
        assert!(right.amplitude.iter().all(|&a| a == 1.0));
        // The depth ramp (0.5 → 1.5 m across the width) is untouched by the colour crop.
        assert!(
            (right.z_near_m.unwrap() - 0.51).abs() < 0.02,
            "{:?}",
            right.z_near_m
        );
        let bad = RgbdFrame {
            color_crop: Some(CropRect { x: 25, ..crop }),
            ..f
        };
        match convert_frame(bad, 24, 32, None, None) {
            Err(TensorholoError::InvalidInput { message }) => {
                assert!(
                    message.contains("color_crop") && message.contains("48x32"),
                    "{message}"
                )
            }
            other => panic!("expected InvalidInput, got {other:?}"),
        }
    }

    /// Depth at 1/8 of the colour's resolution: a near object ending at column 22 of the colour (dark | bright)
    /// is, in the 6 × 4 depth, near in the block centred on column 20 and far from column 28 on. Nearest
    /// neighbour puts the depth edge at the blocks' border (column 24); the joint bilateral upsampling at the
    /// colour's (22), both through `convert_frame` and through a generator's configuration.
    #[test]
    fn depth_upsampling_puts_a_coarse_depth_edge_on_the_colour_edge() {
        let (w, h, edge) = (48u32, 32u32, 22u32);
        let mut f = frame();
        for (i, px) in f.color.chunks_mut(3).enumerate() {
            let v = if (i as u32 % w) < edge { 20 } else { 230 };
            px.copy_from_slice(&[v; 3]);
        }
        let (dw, dh) = (w / 8, h / 8);
        f.depth = (0..dw * dh)
            .flat_map(|i| {
                let centre = (i % dw) * 8 + 4;
                (if centre < edge { 0.5f32 } else { 2.0 }).to_le_bytes()
            })
            .collect();
        (f.depth_width, f.depth_height) = (dw, dh);
        let at = |c: &ConvertedFrame, x: u32| c.depth[(h / 2 * w + x) as usize];
        let nearest = convert_frame(f.clone(), w, h, Some(Fit::Stretch), None).unwrap();
        let bilateral = convert_frame(
            f.clone(),
            w,
            h,
            Some(Fit::Stretch),
            Some(DepthUpsampling::JointBilateral),
        )
        .unwrap();
        // 0 = near, 1 = far (the range is the frame's own: 0.5 and 2 m).
        for x in [edge, edge + 1] {
            assert!(
                at(&nearest, x) < 0.05,
                "nearest at {x}: {}",
                at(&nearest, x)
            );
            assert!(
                at(&bilateral, x) > 0.95,
                "joint bilateral at {x}: {}",
                at(&bilateral, x)
            );
        }
        for x in [edge - 2, edge - 1] {
            assert!(
                at(&bilateral, x) < 0.05,
                "joint bilateral at {x}: {}",
                at(&bilateral, x)
            );
        }
        let mut config = crate::config::tests::config(w, h);
        assert_eq!(
            config.to_core().unwrap().frame_options().depth_upsampling,
            scene::DepthUpsampling::Nearest
        );
        config.depth_upsampling = Some(DepthUpsampling::JointBilateral);
        assert_eq!(
            config.to_core().unwrap().frame_options().depth_upsampling,
            scene::DepthUpsampling::JointBilateral
        );
    }
}

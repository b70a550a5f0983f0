//! Frame assembly: a [`CameraFrame`] (colour, depth, optional confidence, rotation, colour crop) registered
//! and converted to an [`RgbdFrame`] at the hologram's size ([`CameraFrame::to_rgbd`], with
//! [`FrameOptions`]; what it found in a [`CameraFrameReport`]).

use ndarray::Array3;
use serde::Serialize;

use super::fit::{check_target, fit_frame, CropRect, Fit, Rotation};
use super::formats::DepthFormat;
use super::image::{ColorImage, ConfidenceImage, DepthImage};
use crate::error::{invalid, HoloError, Result};
use crate::scene::depth::{
    apply_confidence, fill_invalid, normalise_depth, DecodedDepth, DepthMapping, DepthRange,
    OtherAspect,
};
use crate::scene::frame::RgbdFrame;
use crate::scene::upsample::{upsample_depth, DepthUpsampling};

/// One phone camera frame over its bytes `D`: a colour buffer, a depth buffer covering the same field of view
/// as the colour (or as its [`color_crop`](Self::color_crop)) at any resolution, and the clockwise rotation
/// that makes both upright. `CameraFrame<&[u8]>` borrows the buffers (convert it with
/// [`CameraFrame::to_rgbd`]); [`CameraFrameBuf`] (`CameraFrame<Vec<u8>>`) owns them (e.g. to keep a frame
/// after the camera has recycled its buffers; [`CameraFrame::view`] borrows it back).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CameraFrame<D> {
    /// The colour buffer.
    pub color: ColorImage<D>,
    /// The depth buffer (same field of view as `color`, or as `color_crop` when given).
    pub depth: DepthImage<D>,
    /// Clockwise rotation applied to both buffers (after the crop).
    pub rotation: Rotation,
    /// The rectangle of `color`, in colour pixels before the rotation, that covers the depth buffer's field
    /// of view; `None` = the whole colour buffer. Applied before the rotation and the fit, so that colour
    /// and depth are registered (see [`CropRect`]; ARCore needs it).
    pub color_crop: Option<CropRect>,
    /// The depth buffer's confidence, where the camera gives one (ARKit, ARCore's raw depth): depth samples
    /// below its `min_confidence` are invalid, filled from their confident neighbours.
    pub confidence: Option<ConfidenceImage<D>>,
}

/// An owned camera frame: a [`CameraFrame`] over `Vec<u8>` buffers.
pub type CameraFrameBuf = CameraFrame<Vec<u8>>;

impl<D> CameraFrame<D> {
    /// This frame with each buffer over the bytes `f(&buffer.data)`.
    fn map_data<'s, E>(&'s self, f: impl Fn(&'s D) -> E) -> CameraFrame<E> {
        CameraFrame {
            color: self.color.map_data(&f),
            depth: self.depth.map_data(&f),
            rotation: self.rotation,
            color_crop: self.color_crop,
            confidence: self.confidence.as_ref().map(|c| c.map_data(&f)),
        }
    }
}

impl<D: AsRef<[u8]>> CameraFrame<D> {
    /// Borrows as a `CameraFrame<&[u8]>` (the same bytes, no copy).
    pub fn view(&self) -> CameraFrame<&[u8]> {
        self.map_data(|d| d.as_ref())
    }

    /// Copies the buffers into an owned [`CameraFrameBuf`].
    pub fn to_buf(&self) -> CameraFrameBuf {
        self.map_data(|d| d.as_ref().to_vec())
    }
}

/// Options of [`CameraFrame::to_rgbd`]. `Default`: [`Fit::Crop`], automatic range (1st/99th percentiles
/// of the valid depths, as [`normalise_depth`]), linear in diopters, depth of a lower resolution brought to
/// the colour's by nearest neighbour (the joint bilateral upsampling is closer to full-resolution depth but
/// costs 85 ms at 1080p on two desktop cores, too much of a phone's frame for now: docs/VIDEO.md).
///
/// `FrameOptions::default()` is the one statement of the camera's defaults: the generator's
/// ([`crate::generator::GeneratorConfig::new`]) and the bindings' read it.
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
    /// [`crate::scene::upsample_depth`]; nearest neighbour by default, see above).
    pub depth_upsampling: DepthUpsampling,
}

impl Default for FrameOptions {
    fn default() -> Self {
        Self {
            fit: Fit::default(),
            range: None,
            mapping: DepthMapping::default(),
            depth_upsampling: DepthUpsampling::Nearest,
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

impl<D: AsRef<[u8]>> CameraFrame<D> {
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
    ///    ratio (a mismatch over [`crate::scene::MAX_DEPTH_ASPECT_MISMATCH`] is logged as a warning, once
    ///    per process: the camera's side of the other-aspect rule, where files refuse, see
    ///    [`crate::scene::load_rgbd`]);
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
        let camera = self.view();
        let (amplitude, decoded, invalid_fraction) =
            camera.registered(height, width, options, true)?;

        // 5. Normalise, then fill holes (never read as near).
        let (d, range_used) = normalise_depth(&decoded, options.range, options.mapping)?;
        let DecodedDepth { valid, .. } = decoded; // the metric values are no longer needed
        let filled = fill_invalid(&d, &valid)?;
        drop((d, valid));
        let frame = RgbdFrame::new(amplitude, filled)?;

        // 6. Fit to the hologram's size.
        let frame = fit_frame(frame, height, width, options.fit)?;
        let report = camera.report(range_used, invalid_fraction);
        log::debug!(
            "camera frame {}x{} colour (crop {:?}) + {}x{} {:?} depth ({:.1} % invalid), {:?} -> {height}x{width} ({:?})",
            camera.color.height,
            camera.color.width,
            camera.color_crop,
            camera.depth.height,
            camera.depth.width,
            camera.depth.format,
            100.0 * invalid_fraction,
            camera.rotation,
            options.fit
        );
        Ok((frame, report))
    }
}

impl CameraFrame<&[u8]> {
    /// The report of a conversion of this frame with `range_used` and the depth buffer's `invalid_fraction`.
    pub(super) fn report(
        &self,
        range_used: Option<DepthRange>,
        invalid_fraction: f32,
    ) -> CameraFrameReport {
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
    pub(super) fn registered(
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
            apply_confidence(
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
        // Another aspect ratio: the camera's rule, stretched with a warning (`OtherAspect::WarnAndStretch`).
        decoded.check_aspect(hc, wc, OtherAspect::WarnAndStretch, || {
            let (hd, wd) = decoded.values.dim();
            format!(
                "depth buffer {hd}x{wd} and colour buffer {hc}x{wc} (after crop and rotation) differ in \
                 aspect ratio; the depth map is stretched onto the colour frame (same field of view \
                 assumed; ARCore needs color_crop)"
            )
        })?;
        let decoded = upsample_depth(decoded, amplitude.view(), options.depth_upsampling);
        Ok((amplitude, decoded, invalid_fraction))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::camera::formats::ColorFormat;

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
            depth_upsampling: DepthUpsampling::Nearest,
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

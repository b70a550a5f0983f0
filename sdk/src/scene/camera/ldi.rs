//! Layered depth images from camera frames: one [`CameraFrame`] per layer, front to back, registered as
//! [`CameraFrame::to_rgbd`] registers one frame, mapped to `d` with one common range and fitted alike.

use ndarray::{s, Array2, Array3};

use super::fit::{crop_window, letterbox_size, Fit};
use super::frame::{CameraFrame, CameraFrameReport, FrameOptions};
use crate::error::{invalid, HoloError, Result};
use crate::scene::frame::{LayeredDepthImage, LdiLayer};
use crate::scene::ldi_files::assemble_layers;

/// Converts a layered depth image delivered as camera frames, one per layer front to back (what a
/// renderer's depth-peeling pass or a multi-layer capture gives), to a [`LayeredDepthImage`] of `height ×
/// width` pixels, with the buffer rules of [`CameraFrame::to_rgbd`] for every layer:
/// - each layer is validated, decoded, rotated and registered as steps 1–4 of [`CameraFrame::to_rgbd`]; all
///   must give layer 0's colour size;
/// - layer 0 is the RGB-D image: at least one valid depth pixel, holes filled
///   ([`crate::scene::fill_invalid`]);
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
    frames: &[CameraFrame<&[u8]>],
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

/// `fit_frame` for every layer of an LDI: the same crop window or letterbox bars for all, resampled as
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

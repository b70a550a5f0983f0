//! A frame's results and their timings: [`SlmPatterns`] (and their 32-bit RGBA form), [`Preview`],
//! [`PatternTimings`], [`GeneratorBenchmark`].

use ndarray::{Array3, ArrayView3, Axis};

use crate::color::amplitude_to_srgb8;
use crate::encoding::PhaseChurn;
#[cfg(doc)]
use crate::error::HoloError;
use crate::error::{invalid, Result};
use crate::pipeline::{FrameTimings, SlmFrame};
use crate::scene::DepthRange;

/// Seconds of each stage of one frame through a [`HologramGenerator`].
///
/// [`HologramGenerator`]: super::HologramGenerator
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct PatternTimings {
    /// Camera buffers → RGB-D frame at the hologram resolution (decode, rotate, fill, fit).
    pub convert_s: f64,
    /// The session's stages (CNN, offset, pre-filter, encoding; `total_s` is their sum, or the frame period in
    /// a stream).
    pub frame: FrameTimings,
}

impl PatternTimings {
    /// The median of each stage over `timings` ([`FrameTimings::median`] for the session's stages).
    pub(crate) fn median(timings: &[PatternTimings]) -> PatternTimings {
        let frames: Vec<FrameTimings> = timings.iter().map(|t| t.frame).collect();
        let mut convert: Vec<f64> = timings.iter().map(|t| t.convert_s).collect();
        convert.sort_by(f64::total_cmp);
        PatternTimings {
            convert_s: convert.get(convert.len() / 2).copied().unwrap_or(0.0),
            frame: FrameTimings::median(&frames),
        }
    }
}

/// What [`HologramGenerator::benchmark`] measured.
///
/// [`HologramGenerator::benchmark`]: super::HologramGenerator::benchmark
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct GeneratorBenchmark {
    /// Frames timed (after one warm-up frame).
    pub frames: usize,
    /// The median of each stage (`PatternTimings::median`).
    pub median: PatternTimings,
    /// Frames per second of one frame after another: `1 / (convert_s + total_s)` of the medians; 0 where
    /// that time is 0.
    pub fps: f64,
}

/// One frame's SLM patterns, owned by the caller: three 8-bit planes, one per laser (field-sequential
/// colour), code `c` displaying phase `2π·c/256` (linear look-up table).
#[derive(Debug, Clone, PartialEq)]
pub struct SlmPatterns {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `[3, H, W]` codes (R, G, B), row-major.
    pub codes: Array3<u8>,
    /// Global amplitude normaliser of Eq. 7 (for simulating what the SLM shows).
    pub amplitude_scale: f32,
    /// Metric depth range used for this frame (`None` for relative depth).
    pub depth_range: Option<DepthRange>,
    /// Stage timings.
    pub timings: PatternTimings,
    /// In a stream ([`super::HologramStream`]), the phase churn from the previous frame's patterns
    /// ([`crate::encoding::PhaseContinuity`]); `None` for a stream's first frame and outside a stream.
    pub phase_churn: Option<PhaseChurn>,
}

impl SlmPatterns {
    pub(super) fn from_frame(
        out: &SlmFrame,
        convert_s: f64,
        depth_range: Option<DepthRange>,
    ) -> Self {
        let (_, height, width) = out.codes.dim();
        Self {
            width,
            height,
            codes: out.codes.clone(),
            amplitude_scale: out.amplitude_scale,
            depth_range,
            phase_churn: None,
            timings: PatternTimings {
                convert_s,
                frame: out.timings,
            },
        }
    }

    /// The 32-bit frame colour-sequential SLM drivers take over HDMI/DisplayPort ([`pack_rgba`]):
    /// `[H, W, 4]` bytes, one laser's pattern per colour channel, alpha 255.
    pub fn to_rgba(&self) -> Vec<u8> {
        pack_rgba(self.codes.view())
    }
}

/// Interleaves SLM codes `[3, H, W]` (R, G, B) into the 32-bit frame colour-sequential SLM drivers take over
/// HDMI: `[H, W, 4]` bytes, row-major, the red laser's pattern in R, green in G, blue in B, alpha 255.
pub fn pack_rgba(codes: ArrayView3<u8>) -> Vec<u8> {
    let (c, h, w) = codes.dim();
    let mut out = vec![255u8; h * w * 4];
    for ch in 0..c.min(3) {
        let plane = codes.index_axis(Axis(0), ch);
        match plane.as_slice() {
            Some(src) => interleave(&mut out, ch, src),
            None => interleave(&mut out, ch, &plane.iter().copied().collect::<Vec<_>>()),
        }
    }
    out
}

/// As [`pack_rgba`] from three row-major planes of `width · height` codes each (red, green, blue).
///
/// Errors: [`HoloError::InvalidParameter`] (`planes`) if the planes differ in length.
pub fn pack_rgba_planes(red: &[u8], green: &[u8], blue: &[u8]) -> Result<Vec<u8>> {
    if red.len() != green.len() || red.len() != blue.len() {
        return Err(invalid(
            "planes",
            format!(
                "the red, green and blue planes hold {}, {} and {} codes; they must be equal",
                red.len(),
                green.len(),
                blue.len()
            ),
        ));
    }
    let mut out = vec![255u8; red.len() * 4];
    for (ch, plane) in [red, green, blue].into_iter().enumerate() {
        interleave(&mut out, ch, plane);
    }
    Ok(out)
}

/// Writes `plane` into byte `ch` of every 4-byte pixel of `out`.
fn interleave(out: &mut [u8], ch: usize, plane: &[u8]) {
    for (px, &v) in out.chunks_exact_mut(4).zip(plane) {
        px[ch] = v;
    }
}

/// A simulated view of the SLM patterns ([`HologramGenerator::preview`]): `[H, W, 4]` sRGB bytes, alpha 255.
///
/// [`HologramGenerator::preview`]: super::HologramGenerator::preview
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Preview {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `[H, W, 4]` RGBA8 bytes, row-major, sRGB.
    pub rgba: Vec<u8>,
}

/// An amplitude image `[3, H, W]` as sRGB RGBA8 for the screen.
pub(super) fn preview_image(amp: &Array3<f32>) -> Preview {
    let (_, height, width) = amp.dim();
    let mut rgba = vec![255u8; height * width * 4];
    for c in 0..3 {
        for (px, &a) in rgba
            .chunks_exact_mut(4)
            .zip(amp.index_axis(Axis(0), c).iter())
        {
            px[c] = amplitude_to_srgb8(a.max(0.0));
        }
    }
    Preview {
        width,
        height,
        rgba,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rgba_packs_one_laser_per_channel() {
        let codes = Array3::from_shape_fn((3, 2, 3), |(c, y, x)| (c * 100 + y * 10 + x) as u8);
        let rgba = pack_rgba(codes.view());
        assert_eq!(rgba.len(), 2 * 3 * 4);
        let planes: Vec<Vec<u8>> = (0..3)
            .map(|c| codes.index_axis(Axis(0), c).iter().copied().collect())
            .collect();
        assert_eq!(
            pack_rgba_planes(&planes[0], &planes[1], &planes[2]).unwrap(),
            rgba
        );
        assert!(pack_rgba_planes(&planes[0], &planes[1][1..], &planes[2]).is_err());
        // A non-contiguous view packs the same codes.
        let reversed = codes.slice(ndarray::s![.., .., ..;-1]);
        let packed = pack_rgba(reversed);
        assert_eq!(
            &packed[..4],
            [codes[[0, 0, 2]], codes[[1, 0, 2]], codes[[2, 0, 2]], 255]
        );
        for y in 0..2 {
            for x in 0..3 {
                let px = &rgba[(y * 3 + x) * 4..][..4];
                assert_eq!(
                    px,
                    [codes[[0, y, x]], codes[[1, y, x]], codes[[2, y, x]], 255]
                );
            }
        }
    }
}

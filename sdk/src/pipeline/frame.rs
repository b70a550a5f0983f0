//! The types every executor produces or consumes: the CNN heads ([`Heads`]), one frame's SLM patterns
//! ([`SlmFrame`]) and its stage timings ([`FrameTimings`]), and the black-frame rule ([`check_not_black`]).
//! They sit below the executors: `gpu/` and the CPU frame import them, never the session.

use std::sync::Arc;

use ndarray::Array3;
use num_complex::Complex32;

use super::config::Backend;
use crate::error::{HoloError, Result};
use crate::model::contract;

/// The CNN heads of the midpoint hologram, `[3, H, W]` each: amplitude in `[0, √2]`, phase in `[0, 1]`
/// meaning `(p − 0.5)·2π` rad (`docs/CONVENTIONS.md` §7.1).
#[derive(Debug, Clone, PartialEq)]
pub struct Heads {
    /// Amplitude head `[3, H, W]`.
    pub amplitude: Array3<f32>,
    /// Phase head `[3, H, W]`.
    pub phase: Array3<f32>,
}

impl Heads {
    /// The complex midpoint hologram `[3, H, W]` (R, G, B): `A·e^{i(p − 0.5)2π}`
    /// ([`contract::heads_to_field`]).
    ///
    /// Errors: [`HoloError::ShapeMismatch`] if the two heads differ in shape.
    pub fn to_field(&self) -> Result<Array3<Complex32>> {
        contract::heads_to_field(self.amplitude.view(), self.phase.view())
    }

    /// Zeroed heads `[3, height, width]` each.
    pub(super) fn zeros(height: usize, width: usize) -> Self {
        Self {
            amplitude: Array3::zeros((3, height, width)),
            phase: Array3::zeros((3, height, width)),
        }
    }

    /// The heads arrays a frame with full outputs writes into: `previous` (the last frame's) where nothing
    /// else holds it and it is `[3, height, width]` in standard layout (no allocation; written pages: fresh
    /// arrays cost the CNN 5–10 % at 1080p in page faults), else new zeroed ones.
    pub(super) fn reuse_or_new(
        previous: Option<Arc<Heads>>,
        height: usize,
        width: usize,
    ) -> Arc<Heads> {
        let fits = |a: &Array3<f32>| a.dim() == (3, height, width) && a.is_standard_layout();
        match previous {
            Some(p) if Arc::strong_count(&p) == 1 && fits(&p.amplitude) && fits(&p.phase) => p,
            _ => Arc::new(Heads::zeros(height, width)),
        }
    }

    /// The six planes a CNN writes its heads into ([`crate::cnn::CnnPlan::run_planes_into`]): amplitude R,
    /// G, B then phase R, G, B, `H·W` values each; `None` unless both heads are `[3, H, W]` in standard
    /// layout.
    pub(super) fn planes_mut(&mut self) -> Option<[&mut [f32]; 6]> {
        let (c, h, w) = self.amplitude.dim();
        if c != 3 || self.phase.dim() != (c, h, w) {
            return None;
        }
        let n = h * w;
        let (a0, a12) = self.amplitude.as_slice_mut()?.split_at_mut(n);
        let (a1, a2) = a12.split_at_mut(n);
        let (p0, p12) = self.phase.as_slice_mut()?.split_at_mut(n);
        let (p1, p2) = p12.split_at_mut(n);
        Some([a0, a1, a2, p0, p1, p2])
    }
}

/// Wall-clock seconds of each stage of one frame.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct FrameTimings {
    /// Hologram CNN (input packing + the engine: native, tract or the GPU).
    pub cnn_s: f64,
    /// Heads → field and offset propagation (Eq. 6), colours in parallel.
    pub offset_s: f64,
    /// Pre-filter CNN alone (0 without one): its run from the offset hologram's planes to its output planes.
    pub prefilter_s: f64,
    /// Double phase encoding (with its pre-filter, if any: AA-DPM's Gaussian, or turning the pre-filter
    /// CNN's output into the filtered field) and the look-up table, colours in parallel.
    pub encoding_s: f64,
    /// On the GPU backend: the GPU's whole frame (both CNNs and the optics in one submission, with the
    /// downloads); the stage fields above are then 0 but `cnn_s`, which holds the CPU's input checks (and the
    /// packing of an LDI or an intensity-mapped frame).
    /// `holo bench --backend gpu` times the GPU stages one by one. 0 on the CPU backend.
    pub gpu_s: f64,
    /// A foveated frame's periphery ([`crate::foveation`]): the gaze's depth, the synthetic blur and the blend
    /// with the tile's CNN heads (0 for a full frame). On the GPU backend the gaze's depth (and a
    /// calibration's intensity maps on the amplitude) only: the blur and the blend are in `gpu_s`, and `cnn_s`
    /// is the tile's packing.
    pub periphery_s: f64,
    /// The whole frame (in a stream: from the end of the previous frame, i.e. the frame period).
    pub total_s: f64,
}

/// The median of `values` (the upper middle of an even count); 0 for none.
fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values.get(values.len() / 2).copied().unwrap_or(0.0)
}

impl FrameTimings {
    /// The median of each stage over `timings`, stage by stage (so the stages need not add up to
    /// `total_s`); for an even count the upper of the two middle values. All zero for no frames. The one
    /// median of `holo render`, `holo bench` and [`crate::generator::HologramGenerator::benchmark`].
    pub fn median(timings: &[FrameTimings]) -> FrameTimings {
        let m = |f: fn(&FrameTimings) -> f64| median(timings.iter().map(f).collect());
        FrameTimings {
            cnn_s: m(|t| t.cnn_s),
            offset_s: m(|t| t.offset_s),
            prefilter_s: m(|t| t.prefilter_s),
            encoding_s: m(|t| t.encoding_s),
            gpu_s: m(|t| t.gpu_s),
            periphery_s: m(|t| t.periphery_s),
            total_s: m(|t| t.total_s),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_is_taken_stage_by_stage() {
        let t = |cnn_s, total_s| FrameTimings {
            cnn_s,
            total_s,
            ..FrameTimings::default()
        };
        // Stage by stage: the cnn median (2) and the total median (30) come from different frames.
        let m = FrameTimings::median(&[t(3.0, 10.0), t(1.0, 30.0), t(2.0, 40.0)]);
        assert_eq!((m.cnn_s, m.total_s), (2.0, 30.0));
        // An even count takes the upper middle value; none gives zeros.
        assert_eq!(FrameTimings::median(&[t(1.0, 1.0), t(5.0, 2.0)]).cnn_s, 5.0);
        assert_eq!(FrameTimings::median(&[]), FrameTimings::default());
    }

    #[test]
    fn max_and_finite_match_a_serial_scan() {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
        // Lengths around the 16 lanes (the remainder loop), values in [-1, 1).
        for len in [0usize, 1, 15, 16, 17, 100, 1027] {
            let mut v: Vec<f32> = (0..len).map(|_| 2.0 * next() - 1.0).collect();
            let serial = v.iter().fold(0.0f32, |m, &a| m.max(a));
            assert_eq!(max_and_finite(&v), (serial, true), "len {len}");
            // A non-finite value anywhere (lane or remainder) is found; NaN does not become the maximum.
            for (i, bad) in [(len / 2, f32::NAN), (len.saturating_sub(1), f32::INFINITY)] {
                if len == 0 {
                    continue;
                }
                let keep = v[i];
                v[i] = bad;
                let (m, finite) = max_and_finite(&v);
                assert!(!finite, "len {len}, {bad} at {i}");
                if bad.is_nan() {
                    let serial = v.iter().fold(0.0f32, |m, &a| m.max(a));
                    assert_eq!(m, serial, "len {len}");
                } else {
                    assert_eq!(m, f32::INFINITY);
                }
                v[i] = keep;
            }
            // Negative values only: the maximum stays 0 (amplitudes are ≥ 0).
            let neg: Vec<f32> = v.iter().map(|x| -x.abs() - 1.0).collect();
            assert_eq!(max_and_finite(&neg), (0.0, true));
        }
    }
}

/// One frame's SLM patterns, owned by the session and overwritten by the next frame.
#[derive(Debug, Clone)]
pub struct SlmFrame {
    /// 8-bit SLM codes `[3, H, W]` (R, G, B; one plane per laser, field-sequential), through the display
    /// calibration's look-up tables ([`HologramPipeline::with_calibration`](crate::pipeline::HologramPipeline::with_calibration); the linear one without).
    pub codes: Array3<u8>,
    /// The double phase pattern `[3, H, W]` in radians, `[0, 2π)`.
    pub phase: Array3<f32>,
    /// The global amplitude normaliser `a` of Eq. 7 (see [`crate::encoding::DoublePhase`]).
    pub amplitude_scale: f32,
    /// Per-channel mean phase removed before encoding (radians).
    pub mean_phase: [f32; 3],
    /// Stage timings.
    pub timings: FrameTimings,
    /// Which backend computed this frame: [`Backend::Cpu`] or [`Backend::Gpu`].
    pub backend: Backend,
}

/// The amplitude at or below which a frame counts as black and is refused
/// ([`HoloError::InvalidData`], [`check_not_black`]): that of sRGB code 1 of 255 (`√(1/255/12.92)` ≈ 0.0175), which
/// the eye cannot tell from 0.
pub const BLACK_FRAME_AMPLITUDE: f32 = 0.0175;

/// One pass over `values`: their largest value (at least 0; NaN is skipped, as by `f32::max`) and whether every
/// value is finite, the two input checks of a frame together (a 1080p frame's planes are 33 MB, read once
/// instead of twice). Sixteen independent lanes of both, so that neither check is one serial chain.
pub(crate) fn max_and_finite(values: &[f32]) -> (f32, bool) {
    const LANES: usize = 16;
    const EXPONENT: u32 = 0x7f80_0000;
    let mut max = [0.0f32; LANES];
    let mut non_finite = [0u32; LANES];
    let mut chunks = values.chunks_exact(LANES);
    for chunk in &mut chunks {
        for ((m, bad), &v) in max.iter_mut().zip(&mut non_finite).zip(chunk) {
            *m = if v > *m { v } else { *m };
            *bad |= u32::from(v.to_bits() & EXPONENT == EXPONENT);
        }
    }
    let mut m = max.iter().fold(0.0f32, |a, &b| if b > a { b } else { a });
    let mut finite = non_finite.iter().all(|&b| b == 0);
    for &v in chunks.remainder() {
        m = if v > m { v } else { m };
        finite &= v.is_finite();
    }
    (m, finite)
}

/// Refuses a frame whose brightest amplitude (over every colour, pixel and layer) is at most
/// [`BLACK_FRAME_AMPLITUDE`]: the CNN's output for a black frame is its own bias, not darkness (a 32×32 black
/// frame gives a midpoint hologram of peak amplitude 0.228 with the shipped 8-layer CNN, `sdk/tests/pipeline.rs`), which the double phase
/// encoding's normalisation (Eq. 7) would then show at full brightness.
///
/// Errors: [`HoloError::InvalidData`] saying the frame is black.
pub fn check_not_black(brightest_amplitude: f32) -> Result<()> {
    if brightest_amplitude <= BLACK_FRAME_AMPLITUDE {
        return Err(HoloError::InvalidData(format!(
            "the frame is black (brightest amplitude {brightest_amplitude:.4}, at most sRGB code 1 of 255): \
             there is nothing to display, and the CNN's output for it would be noise shown at full brightness"
        )));
    }
    Ok(())
}

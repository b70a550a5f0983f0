//! [`CnnStage`]: packs RGB-D frames or LDIs into the hologram CNN's input (with the display calibration's
//! intensity maps and the black-frame check) and runs it on a [`CnnPlan`] (tract or the native engine).

use std::sync::Arc;
use std::time::Instant;

use ndarray::{s, Array3, Axis};

use super::frame::{check_not_black, max_and_finite, Heads};
use crate::cnn::CnnPlan;
use crate::error::{invalid, HoloError, Result};
use crate::model::contract;
use crate::scene::{LayeredDepthImage, RgbdFrame};
use crate::slm::DisplayCalibration;

/// Packs frames into the hologram CNN's input and runs it (one per thread in a stream).
#[derive(Debug)]
pub(super) struct CnnStage {
    /// The hologram CNN's plan (tract's or the native engine's).
    pub(super) plan: Box<dyn CnnPlan>,
    /// The packed input `[4·L, H, W]` of the last packed frame; empty until a frame needs packing (an LDI,
    /// intensity maps, the GPU), since an RGB-D frame on the CPU is read in place ([`CnnStage::run_frame_into`]).
    pub(super) input: Array3<f32>,
    /// The display calibration whose laser intensity scale maps multiply the packed amplitudes.
    pub(super) calibration: Option<Arc<DisplayCalibration>>,
    /// The fraction of the model's volume the display's volume uses
    /// ([`crate::display::DisplayMapping::depth_fraction`]): each packed depth `d` becomes
    /// `0.5 + (d − 0.5)·fraction`; 1 (no change, frames read in place) for a volume the models serve whole.
    pub(super) depth_fraction: f32,
}

impl CnnStage {
    /// A stage for another thread (a stream's CNN thread): the same plan's network, its own input buffer.
    pub(super) fn spawn(&self) -> Self {
        Self {
            plan: self.plan.spawn(),
            input: self.input.clone(),
            calibration: self.calibration.clone(),
            depth_fraction: self.depth_fraction,
        }
    }

    /// Runs the hologram CNN on `frame` into new heads (a stream's CNN thread); returns them with the seconds
    /// it took. The frame's planes are read in place where [`CnnStage::frame_planes`] allows (no `[4, H, W]`
    /// copy: 33 MB at 1080p), as [`CnnStage::run_frame_into`] reads them.
    ///
    /// Errors: as [`CnnStage::pack_frame`] and the plan's run.
    pub(super) fn run_frame(&mut self, frame: &RgbdFrame) -> Result<(Heads, f64)> {
        let t = Instant::now();
        if let Some(planes) = self.frame_planes(frame, false)? {
            let (_, h, w) = self.plan.input_dim();
            let mut heads = Heads::zeros(h, w);
            let out = heads
                .planes_mut()
                .ok_or_else(|| HoloError::Internal("new heads not contiguous".into()))?;
            self.plan.run_planes_into(&planes, out)?;
            return Ok((heads, t.elapsed().as_secs_f64()));
        }
        self.pack_frame(frame)?;
        self.run(t)
    }

    /// Checks `frame` against the CNN and packs it into `self.input`; for an LDI CNN, as a one-layer LDI
    /// (the back layers empty, [`contract::pack_ldi`]).
    pub(super) fn pack_frame(&mut self, frame: &RgbdFrame) -> Result<()> {
        let (c, h, w) = self.plan.input_dim();
        check_size("RGB-D frame", frame.amplitude.dim(), (h, w))?;
        let mut input = self.input_mut();
        contract::pack_rgbd(frame, input.slice_mut(s![..4, .., ..]))?;
        contract::fill_empty_layers(input, 1, c / 4);
        self.fit_depths(1);
        self.scale_intensity();
        self.check_not_black()
    }

    /// The packed input buffer, allocated at the plan's `[C, H, W]` on first use.
    fn input_mut(&mut self) -> ndarray::ArrayViewMut3<'_, f32> {
        let dim = self.plan.input_dim();
        if self.input.dim() != dim {
            self.input = Array3::zeros(dim);
        }
        self.input.view_mut()
    }

    /// Runs the hologram CNN on `frame` (checked as [`CnnStage::pack_frame`] checks it), writing the heads
    /// into `heads` ([`CnnPlan::run_planes_into`]: amplitude R, G, B then phase R, G, B, `H·W` values each);
    /// returns the seconds it took. Without intensity maps the CNN reads the frame's planes in place: no
    /// `[4, H, W]` copy (33 MB at 1080p).
    ///
    /// Errors: as [`CnnStage::pack_frame`] and the plan's run.
    pub(super) fn run_frame_into(
        &mut self,
        frame: &RgbdFrame,
        heads: [&mut [f32]; 6],
    ) -> Result<f64> {
        let t = Instant::now();
        if let Some(planes) = self.frame_planes(frame, false)? {
            self.plan.run_planes_into(&planes, heads)?;
        } else {
            self.pack_frame(frame)?;
            self.plan
                .run_planes_into(&Self::planes_of(&self.input), heads)?;
        }
        Ok(t.elapsed().as_secs_f64())
    }

    /// The planes R, G, B, depth (`H·W` values each) of `frame`, checked as [`CnnStage::pack_frame`] checks
    /// them, where the hologram CNN can read them in place: an RGB-D CNN, no intensity maps, contiguous
    /// planes. `None` where the frame must be packed ([`CnnStage::pack_frame`]). With `check_finite` (the
    /// accelerator's frames: a GPU's `max` may skip NaN), it also refuses NaN and infinite values, in the
    /// same pass over the amplitudes.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] for a frame of another size, [`HoloError::InvalidData`] for a
    /// black one (or, with `check_finite`, one holding NaN or infinite values).
    pub(super) fn frame_planes<'f>(
        &self,
        frame: &'f RgbdFrame,
        check_finite: bool,
    ) -> Result<Option<[&'f [f32]; 4]>> {
        let scaled = self
            .calibration
            .as_ref()
            .is_some_and(|cal| cal.colours.iter().any(|c| c.intensity_scale.is_some()));
        let (c, h, w) = self.plan.input_dim();
        let (false, true, Some(amplitude), Some(depth), 4) = (
            scaled,
            self.depth_fraction == 1.0,
            frame.amplitude.as_slice(),
            frame.depth.as_slice(),
            c,
        ) else {
            return Ok(None);
        };
        check_size("RGB-D frame", frame.amplitude.dim(), (h, w))?;
        let (brightest, mut finite) = max_and_finite(amplitude);
        if check_finite {
            finite &= max_and_finite(depth).1;
            if !finite {
                return Err(HoloError::InvalidData(
                    "the RGB-D frame holds NaN or infinite values".into(),
                ));
            }
        }
        check_not_black(brightest)?;
        let (r, gb) = amplitude.split_at(h * w);
        let (g, b) = gb.split_at(h * w);
        Ok(Some([r, g, b, depth]))
    }

    /// Packs the planes of [`CnnStage::frame_planes`] into `self.input` (for the CPU frame of a frame the
    /// accelerator read in place: its self-check, its fallback).
    pub(super) fn pack_planes(&mut self, planes: &[&[f32]; 4]) {
        let mut input = self.input_mut();
        for (mut dst, src) in input.outer_iter_mut().zip(planes) {
            if let Some(d) = dst.as_slice_mut() {
                d.copy_from_slice(src);
            }
        }
    }

    /// The `C` planes of `H·W` values of a packed input `[C, H, W]` (`CnnStage::input`).
    pub(super) fn planes_of(input: &Array3<f32>) -> Vec<&[f32]> {
        let (c, h, w) = input.dim();
        let packed = input.as_slice().unwrap_or_default();
        (0..c)
            .map(|i| packed.get(i * h * w..(i + 1) * h * w).unwrap_or_default())
            .collect()
    }

    /// Refuses a packed input whose amplitudes (every layer, after the intensity maps) are black
    /// ([`check_not_black`]).
    fn check_not_black(&self) -> Result<()> {
        let mut brightest = 0.0f32;
        for (i, plane) in self.input.outer_iter().enumerate() {
            if i % 4 != 3 {
                let m = match plane.as_slice() {
                    Some(values) => max_and_finite(values).0,
                    None => plane.iter().fold(0.0f32, |m, &a| m.max(a)),
                };
                brightest = brightest.max(m);
            }
        }
        check_not_black(brightest)
    }

    /// Multiplies each layer's colour-`c` amplitude by the calibration's intensity scale map of colour `c`
    /// (where it has one): the target the CNN sees is what the unevenly lit display can show.
    fn scale_intensity(&mut self) {
        let Some(cal) = &self.calibration else {
            return;
        };
        let layers = self.input.dim().0 / 4;
        for (c, col) in cal.colours.iter().enumerate() {
            let Some(scale) = &col.intensity_scale else {
                continue;
            };
            for k in 0..layers {
                // Invalid LDI points hold amplitude 0, which stays 0.
                let mut plane = self.input.index_axis_mut(Axis(0), 4 * k + c);
                plane.zip_mut_with(scale, |a, &s| *a *= s);
            }
        }
    }

    pub(super) fn run_ldi(&mut self, ldi: &LayeredDepthImage) -> Result<(Heads, f64)> {
        let t = Instant::now();
        self.pack_ldi(ldi)?;
        self.run(t)
    }

    /// Checks `ldi` against the CNN and packs it into `self.input`.
    pub(super) fn pack_ldi(&mut self, ldi: &LayeredDepthImage) -> Result<()> {
        let (c, h, w) = self.plan.input_dim();
        let want = c / 4;
        if ldi.num_layers() > want {
            return Err(invalid(
                "ldi",
                format!(
                    "the layered depth image has {} layers, and this hologram CNN takes {want}{}",
                    ldi.num_layers(),
                    if want == 1 {
                        " (an RGB-D network): use an LDI network (e.g. the shipped holo8_ldi) or \
                         the front layer alone"
                    } else {
                        ": merge or drop the back layers"
                    }
                ),
            ));
        }
        check_size("LDI", (3, ldi.height(), ldi.width()), (h, w))?;
        contract::pack_ldi(ldi, self.input_mut())?;
        self.fit_depths(ldi.num_layers());
        self.scale_intensity();
        self.check_not_black()
    }

    /// Maps the packed depths of the first `layers` layers into the part of the model's volume the display
    /// uses (`depth_fraction`): `d → 0.5 + (d − 0.5)·fraction`, the front layer's every depth and the back
    /// layers' points (a depth of [`contract::INVALID_DEPTH`] there marks "no point" and stays). Nothing for
    /// a fraction of 1.
    fn fit_depths(&mut self, layers: usize) {
        let k = self.depth_fraction;
        if k == 1.0 {
            return;
        }
        for layer in 0..layers {
            let mut depth = self.input.index_axis_mut(Axis(0), 4 * layer + 3);
            depth.mapv_inplace(|d| {
                if layer > 0 && d >= contract::INVALID_DEPTH {
                    d
                } else {
                    0.5 + (d - 0.5) * k
                }
            });
        }
    }

    pub(super) fn run(&mut self, t: Instant) -> Result<(Heads, f64)> {
        let (amplitude, phase) = self.plan.run_outputs(self.input.view())?;
        Ok((Heads { amplitude, phase }, t.elapsed().as_secs_f64()))
    }
}

fn check_size(what: &str, got: (usize, usize, usize), want: (usize, usize)) -> Result<()> {
    if (got.1, got.2) != want {
        return Err(HoloError::ShapeMismatch {
            what: format!("{what} vs the session's [H, W]"),
            expected: vec![want.0, want.1],
            got: vec![got.1, got.2],
        });
    }
    Ok(())
}

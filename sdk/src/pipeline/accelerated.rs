//! A session's frames on its accelerator (a [`super::executor::FrameExecutor`], the GPU today): the frame
//! itself with the CPU frame as fallback when the device fails, the first-frame self-check of
//! [`Backend::Auto`], and what else the accelerator computes for apps and benchmarks (previews, stage
//! timings).

use std::time::Instant;

use ndarray::Array3;

use super::config::Backend;
use super::frame::{max_and_finite, FrameTimings, SlmFrame};
use super::report::{SelfCheck, StageProfile};
use super::session::HologramSession;
use crate::error::{HoloError, Result};
use crate::slm::codes::recode_calibrated;

impl HologramSession {
    /// What a viewer sees focused at normalised depth `focus` ∈ [0, 1] (0 = near) from `codes` `[3, H, W]`
    /// shown with normaliser `amplitude_scale` (Eq. 8–10), computed by the accelerator that runs this
    /// session's frames, as amplitudes `[3, H, W]`; `None` where the CPU runs them (compute it there with
    /// [`crate::optics::post_encoding_midpoint`] and [`crate::optics::focal_stack`]). The first call builds the
    /// accelerator's preview buffers; each new focus its transfer functions (the last 8 are kept).
    ///
    /// Errors (inside the `Some`): [`HoloError::InvalidParameter`] for a focus outside [0, 1] or a
    /// non-positive scale; [`HoloError::ShapeMismatch`] for codes of another size; [`HoloError::Gpu`].
    pub fn accelerator_preview(
        &mut self,
        codes: &Array3<u8>,
        amplitude_scale: f32,
        focus: f64,
    ) -> Option<Result<Array3<f32>>> {
        let a = self.accelerator.as_mut()?;
        Some(a.executor.preview(codes, amplitude_scale, focus))
    }

    /// Each stage of the accelerator's frame (`hologram_cnn`, `heads_to_field`, `offset_asm`,
    /// `prefilter_cnn`, `double_phase`) timed on its own on the last frame's input (median of `repeats`
    /// submissions), with its work and traffic per frame, for `holo bench --backend gpu`; `None` where the
    /// CPU runs the frames. Slower than a frame (every stage waits for the device); allocates nothing on it.
    ///
    /// Errors (inside the `Some`): [`HoloError::Gpu`].
    pub fn accelerator_stages(&self, repeats: usize) -> Option<Result<Vec<StageProfile>>> {
        let a = self.accelerator.as_ref()?;
        Some(a.executor.stages(repeats))
    }

    /// The GPU frame of the CNN input `planes` (R, G, B, depth of an RGB-D frame, read in place), or of the
    /// input packed in `self.cnn.input` where `planes` is `None` (packing started at `t`): runs it on the GPU,
    /// with the first-frame self-check of [`Backend::Auto`]; on a GPU failure, re-renders it on the CPU and
    /// stays there.
    pub(super) fn render_on_accelerator(
        &mut self,
        planes: Option<[&[f32]; 4]>,
        t: Instant,
    ) -> Result<&SlmFrame> {
        let Some(gpu) = self.accelerator.as_mut() else {
            return Err(HoloError::Internal("no accelerator".into()));
        };
        let packed;
        let input: &[&[f32]] = match &planes {
            // Checked for NaN and infinities by `CnnStage::frame_planes`.
            Some(p) => p,
            None => {
                packed = super::cnn_stage::CnnStage::planes_of(&self.cnn.input);
                // The CPU path catches NaN/∞ in the CNN's heads; a GPU's max() may silently skip NaN, so
                // check the input here.
                if packed.iter().any(|p| !max_and_finite(p).1) {
                    return Err(HoloError::InvalidData(
                        "the RGB-D frame holds NaN or infinite values".into(),
                    ));
                }
                &packed
            }
        };
        let cnn_s = t.elapsed().as_secs_f64();
        let t_gpu = Instant::now();
        // A calibrated look-up table runs on the CPU, on the downloaded double phase pattern.
        let calibrated = self
            .calibration
            .as_ref()
            .is_some_and(|c| c.has_calibrated_lut());
        let full = self.full_outputs || gpu.pending_check || calibrated;
        let backend = gpu.executor.backend();
        match gpu.executor.run(input, &mut self.output, full) {
            Ok(heads) => {
                if calibrated {
                    recode_calibrated(
                        self.calibration.as_deref(),
                        self.output.phase.view(),
                        self.output.codes.view_mut(),
                    )?;
                }
                let gpu_s = t_gpu.elapsed().as_secs_f64();
                self.output.backend = backend;
                self.output.timings = FrameTimings {
                    cnn_s,
                    gpu_s,
                    total_s: t.elapsed().as_secs_f64(),
                    ..FrameTimings::default()
                };
                if let Some(heads) = heads {
                    self.last_heads = Some(std::sync::Arc::new(heads));
                }
                if gpu.pending_check {
                    // The self-check renders the frame on the CPU too, from the packed input.
                    if let Some(p) = &planes {
                        self.cnn.pack_planes(p);
                    }
                    self.self_check()?;
                }
                Ok(&self.output)
            }
            Err(HoloError::Gpu(e)) => {
                log::warn!("{backend} frame failed ({e}); this frame and the next run on the CPU");
                self.accelerator = None;
                self.backend.active = Backend::Cpu;
                self.backend.gpu_precision = None;
                self.backend.reason = format!("GPU failed mid-stream, CPU since: {e}");
                if let Some(p) = &planes {
                    self.cnn.pack_planes(p);
                }
                let (heads, cnn_s) = self.cnn.run(t)?;
                self.encode_heads(heads, cnn_s)
            }
            // Bad data (e.g. a hologram that is zero everywhere) is the frame's fault, not the GPU's.
            Err(e) => Err(e),
        }
    }

    /// The self-check of [`Backend::Auto`] after the GPU rendered the first frame into `self.output`: renders
    /// it on the CPU too, compares the codes ([`SelfCheck`]), and keeps the GPU (and its output) only if they
    /// agree; otherwise the CPU's output stands and the session stays on the CPU.
    fn self_check(&mut self) -> Result<()> {
        let gpu_output = self.output.clone();
        let gpu_heads = self.last_heads.take();
        let (heads, cnn_s) = self.cnn.run(Instant::now())?;
        self.encode_heads(heads, cnn_s)?;
        let check = SelfCheck::compare(&gpu_output.codes, &self.output.codes);
        self.backend.self_check = Some(check);
        if check.passed {
            self.backend.reason = format!(
                "GPU self-check passed ({} of {} codes off by more than one step)",
                check.codes_off_by_more_than_one, check.codes
            );
            self.output = gpu_output;
            self.last_heads = gpu_heads;
            if let Some(g) = self.accelerator.as_mut() {
                g.pending_check = false;
            }
        } else {
            self.backend.reason = format!(
                "GPU self-check failed ({} of {} codes off by more than one step, max {}): CPU",
                check.codes_off_by_more_than_one, check.codes, check.max_code_difference
            );
            self.backend.active = Backend::Cpu;
            self.backend.gpu_precision = None;
            self.accelerator = None;
        }
        log::info!("{}", self.backend.reason);
        Ok(())
    }
}

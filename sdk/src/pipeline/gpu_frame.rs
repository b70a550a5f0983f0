//! The GPU as a frame executor (cargo feature `gpu`): the GPU module's whole frame behind [`FrameExecutor`]
//! (its outputs put into [`SlmFrame`] and [`Heads`]), and how a session gets one ([`build`]: the adapter, the
//! precision, the fallback reasons).

use ndarray::Array3;
use num_complex::Complex32;

use super::config::{Backend, GpuPrecision};
use super::executor::{Accelerator, BackendReportParts, FoveatedInput, FrameExecutor};
use super::frame::{Heads, SlmFrame};
use super::models::HologramPipeline;
use super::report::StageProfile;
use crate::error::Result;
use crate::foveation::TileGeometry;
use crate::gpu::cnn::GpuStorage;
use crate::gpu::fovea::{max_half_width, GpuFoveaFrame, GpuFoveaShape};
use crate::gpu::session::GpuFrameSession;
use crate::gpu::{GpuContext, GpuOptions};

impl FrameExecutor for GpuFrameSession {
    fn backend(&self) -> Backend {
        Backend::Gpu
    }

    fn run(&mut self, input: &[&[f32]], out: &mut SlmFrame, full: bool) -> Result<Option<Heads>> {
        let phase = full.then_some(&mut out.phase);
        let frame = GpuFrameSession::run(self, input, &mut out.codes, phase)?;
        out.amplitude_scale = frame.amplitude_scale;
        out.mean_phase = frame.mean_phase;
        Ok(frame
            .heads
            .map(|(amplitude, phase)| Heads { amplitude, phase }))
    }

    fn preview(
        &mut self,
        codes: &Array3<u8>,
        amplitude_scale: f32,
        focus: f64,
    ) -> Result<Array3<f32>> {
        GpuFrameSession::preview(self, codes, amplitude_scale, focus)
    }

    fn set_correction(&mut self, kernels: Option<[&[Complex32]; 3]>) -> Result<()> {
        GpuFrameSession::set_correction(self, kernels)
    }

    fn stages(&self, repeats: usize) -> Result<Vec<StageProfile>> {
        let times = self.profile(repeats)?;
        Ok(GpuFrameSession::stages(self)
            .into_iter()
            .zip(times)
            .map(|(stage, (_, seconds))| StageProfile {
                name: stage.name,
                flops: stage.flops,
                bytes: stage.bytes,
                seconds,
            })
            .collect())
    }

    fn plan_foveated(
        &mut self,
        pipeline: &HologramPipeline,
        geometry: &TileGeometry,
        blur_px: [f64; 3],
    ) -> Result<bool> {
        // A tile as large as the frame: every foveated frame is a full frame (`render`), nothing to plan.
        if geometry.tile == geometry.frame {
            return Ok(true);
        }
        let (h, w) = geometry.frame;
        let shape = GpuFoveaShape {
            tile: geometry.tile,
            radius_px: geometry.radius_px,
            band_px: geometry.band_px,
            blur_px,
            max_half_width: max_half_width(blur_px.iter().copied().fold(0.0, f64::max), h, w),
        };
        let hologram = pipeline.hologram_model().cnn_graph()?;
        self.plan_fovea(&hologram, shape)?;
        Ok(true)
    }

    fn run_foveated(
        &mut self,
        input: &FoveatedInput<'_>,
        out: &mut SlmFrame,
        full: bool,
    ) -> Result<(Option<Heads>, [f32; 3])> {
        let frame = GpuFoveaFrame {
            tile: input.tile,
            amplitude: input.amplitude,
            depth: input.depth,
            gaze: input.gaze,
            gaze_depth: input.gaze_depth,
            origin: input.origin,
        };
        let phase = full.then_some(&mut out.phase);
        let (frame, theta) =
            GpuFrameSession::run_foveated(self, &frame, input.normaliser, &mut out.codes, phase)?;
        out.amplitude_scale = frame.amplitude_scale;
        out.mean_phase = frame.mean_phase;
        let heads = frame
            .heads
            .map(|(amplitude, phase)| Heads { amplitude, phase });
        Ok((heads, theta))
    }
}

/// The options of the shared context a session without the app's own runs on: a software adapter only where
/// [`Backend::Gpu`] asks for the GPU.
fn shared_options(requested: Backend) -> GpuOptions {
    GpuOptions {
        allow_software: requested == Backend::Gpu,
        name_contains: None,
    }
}

impl HologramPipeline {
    /// The GPU context a session of this pipeline whose frames run on the GPU (`report.active`, its
    /// [`super::BackendReport`]) uses: the app's ([`HologramPipeline::with_gpu_context`]) or the shared one;
    /// `None` where the frames run on the CPU. For work beside the frames on the same device (the
    /// refinement: [`crate::refine::FrameRefiner::for_pipeline`]).
    ///
    /// Errors: [`crate::HoloError::Gpu`] where the shared context can no longer be made.
    pub(crate) fn frame_gpu_context(
        &self,
        report: &super::BackendReport,
    ) -> Result<Option<GpuContext>> {
        if report.active != Backend::Gpu {
            return Ok(None);
        }
        match self.gpu_context() {
            Some(ctx) => Ok(Some(ctx.clone())),
            None => GpuContext::shared(&shared_options(self.config().backend)).map(Some),
        }
    }
}

/// The GPU frame of `pipeline` at `height × width` (`setup.rs`'s `choose_backend` with the `gpu` feature): on the app's context or the shared one (a software adapter only for [`Backend::Gpu`]), the CNN
/// graphs read once by the models ([`crate::model::HologramModel::cnn_graph`]).
pub(super) fn build(
    pipeline: &HologramPipeline,
    height: usize,
    width: usize,
) -> Result<(BackendReportParts, Option<Accelerator>)> {
    let requested = pipeline.config().backend;
    let cpu = |reason: String| BackendReportParts::cpu(requested, reason);
    let ctx = match pipeline.gpu_context() {
        Some(ctx) => Ok(ctx.clone()),
        None if requested == Backend::Auto && !crate::gpu::context::hardware_gpu_possible() => {
            return Ok((
                cpu(
                    "no hardware GPU: no GPU device node on this system (/dev/dri/renderD*, \
                     /dev/nvidia0, /dev/dxg), so the GPU drivers were not loaded"
                        .into(),
                ),
                None,
            ));
        }
        None => GpuContext::shared(&shared_options(requested)),
    };
    let ctx = match (ctx, requested) {
        (Ok(ctx), _) => ctx,
        (Err(e), Backend::Gpu) => return Err(e),
        (Err(e), _) => return Ok((cpu(format!("no hardware GPU: {e}")), None)),
    };
    let info = ctx.info();
    let adapter = Some(format!(
        "{} ({}, {})",
        info.name, info.backend, info.device_type
    ));
    let wanted = pipeline.config().gpu_precision;
    let note = if wanted == GpuPrecision::F16 && !info.shader_f16 {
        " (f16 asked, but the adapter has no SHADER_F16: f32)"
    } else {
        ""
    };
    let storage = match wanted.resolve(info.shader_f16) {
        GpuPrecision::F16 => GpuStorage::F16,
        GpuPrecision::F32 | GpuPrecision::Auto => GpuStorage::F32,
    };
    let frame = (|| {
        let hologram = pipeline.hologram_model().cnn_graph()?;
        let prefilter = match pipeline.prefilter_model() {
            Some(p) => Some(p.cnn_graph()?),
            None => None,
        };
        let cfg = pipeline.config();
        GpuFrameSession::new(
            &ctx,
            &hologram,
            prefilter.as_deref(),
            &cfg.optics,
            cfg.options,
            cfg.offset_m,
            pipeline.encoding(),
            height,
            width,
            storage,
        )
    })();
    match frame {
        Ok(frame) => Ok((
            BackendReportParts {
                requested,
                reason: if requested == Backend::Gpu {
                    format!("GPU requested{note}")
                } else {
                    format!("GPU adapter found; first-frame self-check pending{note}")
                },
                adapter,
                gpu_precision: Some(frame.storage().name().into()),
            },
            Some(Accelerator {
                executor: Box::new(frame),
                pending_check: requested == Backend::Auto,
            }),
        )),
        Err(e) if requested == Backend::Gpu => Err(e),
        Err(e) => {
            log::info!("GPU backend unavailable for {height}×{width}, using the CPU: {e}");
            Ok((
                BackendReportParts {
                    adapter,
                    ..cpu(format!("the GPU path cannot run this session: {e}"))
                },
                None,
            ))
        }
    }
}

//! How a [`HologramSession`] is set up: the size and calibration checks, the choice of a frame executor
//! ([`choose_backend`]), the CNN engine's plans ([`crate::cnn::select`]), and the colour states (FFT plans,
//! offset transfer functions, double phase encoders, buffers) the CPU frame reuses.

use ndarray::Array3;
use num_complex::Complex32;
use rayon::prelude::*;

use super::cnn_stage::CnnStage;
use super::colour::ColourState;
use super::config::{Backend, MAX_HOLOGRAM_PIXELS};
use super::executor::{Accelerator, BackendReportParts};
use super::frame::{FrameTimings, SlmFrame};
use super::models::HologramPipeline;
use super::pool::OpticsPool;
use super::report::BackendReport;
use super::session::HologramSession;
use super::workers::ColourWorkers;
use crate::cnn::CnnPlans;
use crate::encoding::{ChannelEncoder, ChannelStats, PassOneLayout};
#[cfg(not(feature = "gpu"))]
use crate::error::invalid as invalid_backend;
#[cfg(doc)]
use crate::error::HoloError;
use crate::error::{invalid, kernel_isa, Result};
use crate::optics::Carrier;

impl HologramPipeline {
    /// Prepares a session for `height × width` frames: plans the CNNs for that size on the engine the
    /// configuration asks for (timing the candidates where it says `Auto`), plans the FFTs, computes the offset transfer functions and allocates all buffers, and starts
    /// three colour worker threads.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`size`) for a size of 0 or above
    /// [`MAX_HOLOGRAM_PIXELS`], checked first; [`HoloError::ShapeMismatch`] for a display calibration of
    /// another size; as [`crate::cnn::cnn_plan`] (the CNN engine's plans), [`crate::optics::SpectralPlan::new`]
    /// and [`ChannelEncoder::new`]; with [`Backend::Gpu`], the GPU's errors ([`HoloError::Gpu`]).
    pub fn session(&self, height: usize, width: usize) -> Result<HologramSession> {
        HologramSession::new(self, height, width)
    }
}

impl HologramSession {
    pub(super) fn new(pipeline: &HologramPipeline, height: usize, width: usize) -> Result<Self> {
        // Before any allocation: a session holds several [3, H, W] complex fields and the CNN's activations.
        if height == 0 || width == 0 || height.saturating_mul(width) > MAX_HOLOGRAM_PIXELS {
            return Err(invalid(
                "size",
                format!(
                    "{height}×{width}: a session needs 1 to {} pixels (8192×8192)",
                    MAX_HOLOGRAM_PIXELS
                ),
            ));
        }
        let calibration = pipeline.calibration().cloned();
        if let Some(cal) = &calibration {
            cal.check_size(height, width)?;
        }
        let (parts, accelerator) = choose_backend(pipeline, height, width)?;
        let backend = BackendReport {
            requested: parts.requested,
            active: accelerator
                .as_ref()
                .map_or(Backend::Cpu, |a| a.executor.backend()),
            reason: parts.reason,
            adapter: parts.adapter,
            gpu_precision: if accelerator.is_some() {
                parts.gpu_precision
            } else {
                None
            },
            self_check: None,
        };
        log::info!(
            "backend for {height}×{width}: {} ({})",
            backend.active,
            backend.reason
        );
        let request = pipeline.plan_request()?;
        let CnnPlans {
            hologram,
            prefilter,
            report: plan_report,
        } = crate::cnn::select(
            pipeline.hologram_model(),
            pipeline.prefilter_model(),
            height,
            width,
            pipeline.config().cnn_engine,
            &request,
        )?;
        let cfg = pipeline.config();
        let encoding = pipeline.encoding();
        let props = cfg.optics.propagators(height, width, cfg.options)?;
        // The three colours' transfer functions in parallel (their quarters: 0.1 s of a 1080p setup).
        let transfers = props
            .par_iter()
            .map(|prop| {
                (cfg.offset_m != 0.0)
                    .then(|| prop.even_transfer_function(cfg.offset_m, Carrier::Remove))
                    .transpose()
            })
            .collect::<Result<Vec<_>>>()?;
        let n = height * width;
        let mut states: [Option<Box<ColourState>>; 3] = [None, None, None];
        for (colour, ((slot, prop), transfer)) in
            states.iter_mut().zip(&props).zip(transfers).enumerate()
        {
            *slot = Some(Box::new(ColourState {
                field: vec![Complex32::default(); n],
                plan: prop.plan().clone(),
                transfer,
                scratch: prop.plan().scratch(),
                prefilter_input: if pipeline.prefilter_model().is_some() {
                    vec![0.0; 2 * n]
                } else {
                    Vec::new()
                },
                encoder: ChannelEncoder::new(height, width, encoding)?,
                phase: vec![0.0; n],
                stats: ChannelStats::default(),
                layout: PassOneLayout::Field,
                colour,
                size: (height, width),
                isa: kernel_isa()?,
            }));
        }
        Ok(Self {
            height,
            width,
            encoding,
            offset_m: cfg.offset_m,
            cnn: CnnStage {
                plan: hologram,
                input: Array3::zeros((0, 0, 0)),
                calibration: calibration.clone(),
                depth_fraction: pipeline.display_mapping().depth_fraction() as f32,
            },
            prefilter,
            states,
            workers: ColourWorkers::start()?,
            optics: OpticsPool::start()?,
            output: SlmFrame {
                codes: Array3::zeros((3, height, width)),
                phase: Array3::zeros((3, height, width)),
                amplitude_scale: 0.0,
                mean_phase: [0.0; 3],
                timings: FrameTimings::default(),
                backend: Backend::Cpu,
            },
            last_heads: None,
            plan_report,
            backend,
            full_outputs: true,
            calibration,
            wavelengths_m: cfg.optics.wavelengths_m,
            accelerator,
        })
    }
}

/// Builds the accelerator of `pipeline`'s sessions at `height × width` when its backend asks for one:
/// `(report, accelerator)`; `None` runs the CPU frame.
///
/// Errors: with [`Backend::Gpu`], the GPU's errors ([`crate::HoloError::Gpu`], or
/// [`crate::HoloError::InvalidParameter`] in a build without the `gpu` feature); with [`Backend::Auto`], none
/// (the CPU runs and the report says why).
pub(super) fn choose_backend(
    pipeline: &HologramPipeline,
    height: usize,
    width: usize,
) -> Result<(BackendReportParts, Option<Accelerator>)> {
    let requested = pipeline.config().backend;
    if requested == Backend::Cpu {
        return Ok((
            BackendReportParts::cpu(requested, "CPU requested".into()),
            None,
        ));
    }
    #[cfg(not(feature = "gpu"))]
    {
        let _ = (height, width);
        if requested == Backend::Gpu {
            return Err(invalid_backend(
                "backend",
                "this build has no GPU path (cargo feature `gpu` of tensorholo)",
            ));
        }
        Ok((
            BackendReportParts::cpu(
                requested,
                "this build has no GPU path (cargo feature `gpu`)".into(),
            ),
            None,
        ))
    }
    #[cfg(feature = "gpu")]
    super::gpu_frame::build(pipeline, height, width)
}

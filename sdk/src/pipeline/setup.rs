//! How a [`HologramSession`] is set up: the size and calibration checks, the choice of a frame executor
//! ([`choose_backend`]), the CNN engine's plans ([`crate::cnn::select`]), and the colour states (FFT plans,
//! offset transfer functions, double phase encoders, buffers) the CPU frame reuses.

use ndarray::Array3;
use num_complex::Complex32;
use rayon::prelude::*;

use super::cnn_stage::CnnStage;
use super::colour::ColourState;
use super::config::{Backend, MAX_HOLOGRAM_PIXELS};
use super::correction::{AberrationReport, PupilCorrection};
use super::executor::{Accelerator, BackendReportParts};
use super::fovea_tiles::FoveatedState;
use super::frame::{FrameTimings, SlmFrame};
use super::models::HologramPipeline;
use super::pool::OpticsPool;
use super::report::BackendReport;
use super::session::HologramSession;
use super::workers::ColourWorkers;
use crate::cnn::CnnPlans;
use crate::display::AberrationProfile;
use crate::encoding::{ChannelEncoder, ChannelStats, PassOneLayout};
#[cfg(not(feature = "gpu"))]
use crate::error::invalid as invalid_backend;
#[cfg(doc)]
use crate::error::HoloError;
use crate::error::{invalid, Result};
use crate::optics::Carrier;
use std::sync::Arc;

impl HologramPipeline {
    /// Prepares a session for `height × width` frames: plans the CNNs for that size on the engine the
    /// configuration asks for (timing the candidates where it says `Auto`), plans the FFTs, computes the offset transfer functions and allocates all buffers, and starts
    /// three colour worker threads.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`size`) for a size of 0 or above
    /// [`MAX_HOLOGRAM_PIXELS`], checked first; [`HoloError::ShapeMismatch`] for a display calibration of
    /// another size; as [`crate::cnn::cnn_plan`] (the CNN engine's plans), `crate::optics::SpectralPlan::new`
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
        pipeline.check_trained_aberration()?;
        let calibration = pipeline.calibration().cloned();
        if let Some(cal) = &calibration {
            cal.check_size(height, width)?;
        }
        let (parts, mut accelerator) = choose_backend(pipeline, height, width)?;
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
        // The kernels' instruction set, resolved once for the session: its CNNs, encoders and colour rows.
        let isa = request.cnn.kernel_isa()?;
        let CnnPlans {
            hologram,
            prefilter,
            report: plan_report,
        } = crate::cnn::select(
            pipeline.hologram_model(),
            pipeline.prefilter_model(),
            height,
            width,
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
        let foveated = match cfg.foveation {
            Some(options) => Some(Box::new(FoveatedState::new(
                pipeline,
                options,
                &request,
                (height, width),
                std::thread::available_parallelism().map_or(1, |n| n.get()),
            )?)),
            None => None,
        };
        // The accelerator runs the foveated frames where it can (one plan for every gaze).
        let mut foveated = foveated;
        if let (Some(acc), Some(fov)) = (accelerator.as_mut(), foveated.as_mut()) {
            let geometry = *fov.periphery.geometry();
            match acc.executor.plan_foveated(pipeline, &geometry, fov.blur_px) {
                Ok(runs) => fov.on_accelerator = runs,
                Err(e) if backend.requested == Backend::Gpu => return Err(e),
                Err(e) => log::warn!("foveated frames run on the CPU frame: {e}"),
            }
        }
        let n = height * width;
        let mut states: [Option<Box<ColourState>>; 3] = [None, None, None];
        for (colour, ((slot, prop), transfer)) in
            states.iter_mut().zip(&props).zip(transfers).enumerate()
        {
            *slot = Some(Box::new(ColourState {
                field: vec![Complex32::default(); n],
                plan: prop.plan().clone(),
                transfer,
                correction: None,
                scratch: prop.plan().scratch(),
                encoder: ChannelEncoder::new(height, width, encoding)?.with_isa(isa)?,
                phase: vec![0.0; n],
                stats: ChannelStats::default(),
                layout: PassOneLayout::Field,
                colour,
                size: (height, width),
                isa,
            }));
        }
        Self {
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
            display: cfg.optics,
            aberration: None,
            correction: None,
            corrected_by_cnn: pipeline.corrected_by_cnn(),
            accelerator,
            foveated,
        }
        .with_aberration(pipeline.aberration().cloned())
    }

    /// The session with `profile` applied (errors as [`HologramSession::set_aberration`]).
    fn with_aberration(mut self, profile: Option<Arc<AberrationProfile>>) -> Result<Self> {
        if self.corrected_by_cnn {
            if let Some(profile) = profile {
                let report = AberrationReport::by_cnn(&profile, self.offset_m);
                self.aberration = Some((profile, report));
            }
        } else if profile.is_some() {
            self.set_aberration(profile)?;
        }
        Ok(self)
    }

    /// Replaces the viewer's aberration correction of this session's next frames (`None`: none), e.g. as a
    /// viewer moves a prescription slider, without rebuilding the session: the correction kernel `Φ` of the
    /// profile's coefficients at the midpoint plane (`d = −s`) multiplies the midpoint hologram's spectrum in
    /// the offset propagation's pass, `H_SLM = F⁻¹{F{H}·Φ·T_s}` (paper Eq. 5 with one kernel, Eq. 6; exact for
    /// coefficients the same at every distance, [`AberrationReport`] otherwise). At offset 0 this adds one
    /// spectral pass per colour. The kernels' buffers are reused: a new profile with as many distinct
    /// colour sets allocates nothing. The CPU frame and the GPU frame apply it alike (the GPU's kernels are
    /// uploaded once and rewritten in place). A session with a DDPM pre-filter keeps it (and
    /// logs a warning): on corrected fields it falls below AA-DPM once the correction is more than weak, so
    /// make sessions that correct from a pipeline with [`HologramPipeline::with_aberration`], which encodes
    /// with AA-DPM.
    ///
    /// Errors: [`HoloError::InvalidParameter`] (`wavelengths_m`, `pixel_pitch_m`) for a profile calibrated
    /// for another display (`AberrationProfile::check_setup`), or (`aberration`) on a session whose hologram
    /// CNN was trained for its aberrations ([`HologramPipeline::corrected_by_cnn`]). The session keeps its
    /// correction on error.
    /// A GPU frame that fails to take the kernels is dropped with a warning: the frames run on the CPU,
    /// corrected, and [`HologramSession::backend_report`] says why.
    pub fn set_aberration(&mut self, profile: Option<Arc<AberrationProfile>>) -> Result<()> {
        if self.corrected_by_cnn {
            return Err(invalid(
                "aberration",
                "this session's hologram CNN was trained for its aberrations and corrects them itself \
                 (metadata tensorholo.aberration): a correction that changes needs a CNN trained without \
                 one, such as the shipped CNNs",
            ));
        }
        let Some(profile) = profile else {
            for state in self.states.iter_mut().flatten() {
                state.correction = None;
            }
            self.correction = None;
            self.aberration = None;
            if let Some(acc) = &mut self.accelerator {
                acc.executor.set_correction(None)?;
            }
            return Ok(());
        };
        profile.check_setup(&self.display)?;
        let report = AberrationReport::new(&profile, &self.display, self.offset_m);
        if self.prefilter.is_some() && !profile.is_zero() {
            log::warn!(
                "this session encodes with a DDPM pre-filter CNN, trained on uncorrected fields: on corrected \
                 ones it falls below AA-DPM (−2 dB at 1 D of cylinder, −24 dB at 5 D); a pipeline made \
                 with_aberration encodes with AA-DPM"
            );
        }
        if self.states.iter().any(Option::is_none) {
            return Err(super::workers::lost_state());
        }
        for state in self.states.iter_mut().flatten() {
            state.correction = None;
        }
        let reuse = self.correction.take().and_then(|c| Arc::try_unwrap(c).ok());
        let Some(plan) = self.states.iter().flatten().next().map(|s| &s.plan) else {
            return Err(super::workers::lost_state());
        };
        // Without a transfer function (offset 0) the kernel carries the inverse transform's normalisation.
        let (ch, cw) = plan.computational_shape();
        let scale = if self.offset_m == 0.0 {
            1.0 / (ch * cw) as f32
        } else {
            1.0
        };
        let correction = Arc::new(PupilCorrection::build(
            plan,
            &report.coefficients,
            scale,
            reuse,
        ));
        for state in self.states.iter_mut().flatten() {
            state.correction = Some(correction.clone());
        }
        let gpu = match &mut self.accelerator {
            Some(acc) => acc
                .executor
                .set_correction(Some([0, 1, 2].map(|c| correction.kernel(c)))),
            None => Ok(()),
        };
        self.correction = Some(correction);
        self.aberration = Some((profile, report));
        if let Err(e) = gpu {
            // The CPU frame is corrected: frames go on there rather than uncorrected on the GPU.
            log::warn!(
                "the GPU frame could not take the aberration correction, running on the CPU: {e}"
            );
            self.accelerator = None;
            self.backend.active = Backend::Cpu;
            self.backend.reason =
                format!("the GPU frame could not take the aberration correction: {e}");
        }
        Ok(())
    }

    /// The viewer's aberration profile this session corrects, and what the correction applies and leaves
    /// ([`AberrationReport`]); `None` without one.
    pub fn aberration(&self) -> Option<(&Arc<AberrationProfile>, &AberrationReport)> {
        self.aberration.as_ref().map(|(p, r)| (p, r))
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

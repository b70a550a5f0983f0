//! The refinement of a pipeline's frames ([`FrameRefiner::for_pipeline`]): the display, calibration and
//! viewer's aberration the pipeline's sessions apply, and the device its frames run on, assembled here once
//! for `holo` and the generator.

use std::sync::Arc;

use super::models::HologramPipeline;
use super::report::BackendReport;
use crate::display::AberrationProfile;
use crate::error::Result;
use crate::refine::device::RefineDevice;
use crate::refine::frame::{FrameRefinement, FrameRefiner, RefineDisplay};
use crate::slm::DisplayCalibration;

impl FrameRefiner {
    /// The refiner of `pipeline`'s frames on `threads` CPU threads (≥ 1): the pipeline's display (optics,
    /// propagation, SLM offset, double phase method), its calibration's look-up tables and its viewer's
    /// aberration (which the refinement's model sees through, so that the refined pattern stays corrected),
    /// with the iterations where the frames run (`backend`: a session's report): on the session's GPU when
    /// it has one (cargo feature `gpu`; a quantised refinement through a calibrated look-up table then runs on
    /// the CPU, [`crate::refine::RefinedFrame::backend_reason`] says so), else on the CPU.
    ///
    /// Errors: as [`FrameRefiner::new`]; [`crate::HoloError::Gpu`] where the GPU context can no longer be
    /// made.
    pub fn for_pipeline(
        request: FrameRefinement,
        pipeline: &HologramPipeline,
        backend: &BackendReport,
        threads: usize,
    ) -> Result<Self> {
        let calibration = pipeline.calibration().cloned();
        let viewer = pipeline.aberration().cloned();
        Self::for_session(request, pipeline, backend, (calibration, viewer), threads)
    }

    /// As [`FrameRefiner::for_pipeline`], with the calibration and viewer's aberration a session applies now
    /// (the generator's, which may have changed since the pipeline was made).
    ///
    /// Errors: as [`FrameRefiner::for_pipeline`].
    pub(crate) fn for_session(
        request: FrameRefinement,
        pipeline: &HologramPipeline,
        backend: &BackendReport,
        (calibration, viewer): (
            Option<Arc<DisplayCalibration>>,
            Option<Arc<AberrationProfile>>,
        ),
        threads: usize,
    ) -> Result<Self> {
        let cfg = pipeline.config();
        let display = RefineDisplay {
            optics: cfg.optics,
            propagation: cfg.options,
            offset_m: cfg.offset_m,
            encoding: cfg.encoding,
            calibration,
            viewer,
            viewer_corrected_by_cnn: pipeline.corrected_by_cnn(),
        };
        let refiner = FrameRefiner::new(request, display, threads)?;
        Ok(refiner.on_device(refine_device(pipeline, backend)?))
    }
}

/// The device a pipeline's refinement runs on: the GPU its frames run on (`backend.active`), or `None` (the
/// CPU).
///
/// Errors: [`crate::HoloError::Gpu`] where the shared GPU context can no longer be made.
fn refine_device(
    pipeline: &HologramPipeline,
    backend: &BackendReport,
) -> Result<Option<Box<dyn RefineDevice>>> {
    #[cfg(feature = "gpu")]
    let device = pipeline
        .frame_gpu_context(backend)?
        .map(|ctx| Box::new(ctx) as Box<dyn RefineDevice>);
    #[cfg(not(feature = "gpu"))]
    let device = {
        let _ = (pipeline, backend);
        None
    };
    Ok(device)
}

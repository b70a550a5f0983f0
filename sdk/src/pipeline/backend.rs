//! Which executor runs a session's frames: [`choose_backend`] builds the accelerator the configuration asks
//! for (the GPU frame, `gpu_frame.rs`) or says why the CPU frame runs.

use super::config::Backend;
use super::executor::{Accelerator, BackendReportParts};
use super::models::HologramPipeline;
#[cfg(not(feature = "gpu"))]
use crate::error::invalid;
use crate::error::Result;

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
            return Err(invalid(
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

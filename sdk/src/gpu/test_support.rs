//! The GPU context of this crate's unit tests: [`super::test_context`] on any adapter, skipping with a message
//! where none exists. The library reads no environment; CI's requirement that the GPU tests run
//! (`TENSORHOLO_REQUIRE_GPU=1`, set by `.ci/run`) is enforced by the integration tests, which read it
//! (`sdk/tests/gpu_common`, `sdk/tests/gpu_context.rs`) and fail where no adapter exists.

use super::GpuContext;

/// A context on any adapter, or `None` (skip) where none exists.
pub(crate) fn context() -> Option<GpuContext> {
    super::test_context(false)
}

//! The GPU context of this crate's unit tests: [`super::test_context`], required where the environment says
//! `TENSORHOLO_REQUIRE_GPU=1` (set by `.ci/run`). Test code only: the library reads no environment.

use super::GpuContext;

/// A context on any adapter, or `None` (skip) where none exists, unless `TENSORHOLO_REQUIRE_GPU=1`.
pub(crate) fn context() -> Option<GpuContext> {
    super::test_context(std::env::var("TENSORHOLO_REQUIRE_GPU").as_deref() == Ok("1"))
}

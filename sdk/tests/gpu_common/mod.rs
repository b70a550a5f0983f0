//! Shared by the GPU tests: the context they run on, or a skip (`tensorholo::gpu::test_context`), required
//! (a missing adapter fails) where `TENSORHOLO_REQUIRE_GPU=1`, as `.ci/run` sets it.
#![allow(dead_code)]

use tensorholo::gpu::GpuContext;

/// A context on any adapter (lavapipe in CI), or `None` with a message; a panic instead where
/// `TENSORHOLO_REQUIRE_GPU=1`.
pub fn context() -> Option<GpuContext> {
    tensorholo::gpu::test_context(std::env::var("TENSORHOLO_REQUIRE_GPU").as_deref() == Ok("1"))
}

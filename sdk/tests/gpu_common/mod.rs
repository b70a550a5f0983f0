//! Shared by the GPU tests: the context they run on, or a skip.
#![allow(dead_code)]

use tensorholo::gpu::{GpuContext, GpuOptions};

/// A context on any adapter, software included (lavapipe in CI). `None`, with a message, where there is no
/// adapter, unless `TENSORHOLO_REQUIRE_GPU=1` (CI), which turns that into a failure.
pub fn context() -> Option<GpuContext> {
    match GpuContext::new(&GpuOptions {
        allow_software: true,
        name_contains: None,
    }) {
        Ok(ctx) => Some(ctx),
        Err(e) if std::env::var("TENSORHOLO_REQUIRE_GPU").as_deref() == Ok("1") => {
            panic!("TENSORHOLO_REQUIRE_GPU=1 but {e}")
        }
        Err(e) => {
            eprintln!("skipping: {e} (install mesa-vulkan-drivers libvulkan1 for lavapipe)");
            None
        }
    }
}

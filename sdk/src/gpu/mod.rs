//! The GPU path (cargo feature `gpu`): a whole hologram frame — hologram CNN, offset propagation (Eq. 6),
//! pre-filter CNN, double phase encoding (Eq. 7) and look-up table — as WGSL compute shaders run by wgpu on
//! Metal (iOS, macOS) or Vulkan (Android, Linux). It sits below the pipeline and imports nothing of it: the
//! pipeline wraps `session`'s frame as one of its frame executors. The CPU path stays the reference: every
//! kernel here is tested against it (the unit tests of each module, `sdk/tests/gpu_pipeline.rs`), and the
//! pipeline's `Backend::Auto` falls back to it when no adapter exists or a first-frame self-check fails. Apps
//! see the [`GpuContext`] (to share their own device) and its reports; the frame itself is crate-private.
//!
//! - `context`: [`GpuContext`] picks the adapter and device once (or adopts the app's), creates every buffer,
//!   pipeline and bind group (counted, so tests can assert that no frame creates one), and turns wgpu's
//!   validation errors and device loss into [`crate::HoloError::Gpu`].
//! - `kernel`: one compute pipeline per WGSL entry point, bound by position, dispatched over 1D/2D grids.
//! - `shaders`: every `.wgsl` source by name; `shader_tests` translates each to MSL and SPIR-V with naga and
//!   checks every uniform struct against its `#[repr(C)]` Rust twin.
//! - `fft`, `encode`, `cnn`, `session`: the optics, the encoding, the CNNs and one whole frame; `fovea`: a
//!   foveated frame's tile CNN, periphery blur and blend (`crate::foveation`); `refine`: the focal-stack
//!   refinement's iterations (its model handed in by `crate::refine`).
//!
//! Layout convention shared by all kernels: real planes are `array<f32>` `[C, H, W]` row-major (as the CPU
//! path's `Array3`), complex planes `array<vec2<f32>>` `[C, H, W]` (re, im), codes four per `u32`
//! little-endian. Each `.wgsl` file starts with a comment listing its bindings and their layouts.

pub(crate) mod cnn;
pub(crate) mod context;
pub(crate) mod encode;
pub(crate) mod fft;
pub(crate) mod fovea;
pub(crate) mod kernel;
pub(crate) mod refine;
pub(crate) mod session;
pub(crate) mod shaders;

pub use context::{GpuContext, GpuInfo, GpuOptions, ResourceCounts};

#[cfg(test)]
mod shader_tests;
#[cfg(test)]
pub(crate) mod test_support;

/// For tests (this crate's, the workspace's): a context on any adapter (lavapipe in CI), or `None` with a
/// message where none exists; with `require` a missing adapter is a panic instead, so that CI cannot skip the
/// GPU tests silently. The library reads no environment: the integration tests pass `TENSORHOLO_REQUIRE_GPU=1`
/// (set by `.ci/run`) as `require` (`sdk/tests/gpu_common`); the unit tests skip (`test_support`).
#[doc(hidden)]
pub fn test_context(require: bool) -> Option<GpuContext> {
    match GpuContext::new(&GpuOptions {
        allow_software: true,
        name_contains: None,
    }) {
        Ok(ctx) => Some(ctx),
        Err(e) if require => panic!("a GPU adapter is required (TENSORHOLO_REQUIRE_GPU=1) but {e}"),
        Err(e) => {
            eprintln!("skipping: {e} (install mesa-vulkan-drivers libvulkan1 for lavapipe)");
            None
        }
    }
}

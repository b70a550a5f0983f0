//! The GPU context of this crate's unit tests: [`super::test_context`] on any adapter, skipping with a message
//! where none exists. The library reads no environment; CI's requirement that the GPU tests run
//! (`TENSORHOLO_REQUIRE_GPU=1`, set by `.ci/run`) is enforced by the integration tests, which read it
//! (`sdk/tests/gpu_common`, `sdk/tests/gpu_context.rs`) and fail where no adapter exists.

use super::GpuContext;

/// A context on any adapter, or `None` (skip) where none exists.
pub(crate) fn context() -> Option<GpuContext> {
    super::test_context(false)
}

/// Uniform values in `[0, 1)` from `seed` ([`crate::splitmix::SplitMix64`]): the shader tests' random inputs.
pub(crate) fn uniform(seed: u64) -> impl FnMut() -> f32 {
    let mut rng = crate::splitmix::SplitMix64::new(seed);
    move || rng.next_f64() as f32
}

//! Which backend a session runs and why ([`BackendReport`]), an accelerator's stages ([`StageProfile`]), and
//! the first-frame self-check of [`Backend::Auto`] ([`SelfCheck`]).

use ndarray::Array3;

use super::config::Backend;

/// Which backend a [`HologramSession`](crate::pipeline::HologramSession) runs and why ([`HologramSession::backend_report`](crate::pipeline::HologramSession::backend_report)).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BackendReport {
    /// What the configuration asked for.
    pub requested: Backend,
    /// What runs the frames now: [`Backend::Cpu`] or [`Backend::Gpu`].
    pub active: Backend,
    /// Why, in words (e.g. "no hardware GPU adapter: …", "self-check passed", "GPU failed mid-stream: …").
    pub reason: String,
    /// The GPU adapter, "name (api, type)", where one was used or tried.
    pub adapter: Option<String>,
    /// The GPU CNNs' arithmetic ("f32" or "f16"), where the GPU runs.
    pub gpu_precision: Option<String>,
    /// The first frame's comparison of the GPU against the CPU ([`Backend::Auto`] only).
    pub self_check: Option<SelfCheck>,
}

/// The first-frame comparison of [`Backend::Auto`]: the GPU's SLM codes against the CPU's for the same frame.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SelfCheck {
    /// Codes compared (`3·H·W`).
    pub codes: usize,
    /// Codes whose cyclic difference exceeds 1 (one LUT step, a rounding tie or float rounding).
    pub codes_off_by_more_than_one: usize,
    /// Largest cyclic code difference.
    pub max_code_difference: u8,
    /// Whether the GPU is kept: at most [`SELF_CHECK_MAX_FRACTION`] of the codes off by more than one.
    pub passed: bool,
}

/// The largest fraction of SLM codes that may differ from the CPU's by more than one step in the self-check of
/// [`Backend::Auto`] (f32 GPUs measure below 1e-3 on real frames, docs/GPU.md).
pub const SELF_CHECK_MAX_FRACTION: f64 = 0.01;

impl SelfCheck {
    /// Compares two code planes of the same shape.
    pub fn compare(gpu: &Array3<u8>, cpu: &Array3<u8>) -> Self {
        let mut off = 0;
        let mut max = 0u8;
        for (&g, &c) in gpu.iter().zip(cpu.iter()) {
            let d = g.wrapping_sub(c).min(c.wrapping_sub(g));
            max = max.max(d);
            if d > 1 {
                off += 1;
            }
        }
        let codes = cpu.len();
        Self {
            codes,
            codes_off_by_more_than_one: off,
            max_code_difference: max,
            passed: gpu.shape() == cpu.shape()
                && (off as f64) <= SELF_CHECK_MAX_FRACTION * codes as f64,
        }
    }
}

/// One stage of an accelerator's frame, timed on its own ([`HologramSession::accelerator_stages`](crate::pipeline::HologramSession::accelerator_stages),
/// what `holo bench --backend gpu` prints): its work, traffic and time per frame.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StageProfile {
    /// Stage name: `hologram_cnn`, `heads_to_field`, `offset_asm`, `prefilter_cnn`, `double_phase`.
    pub name: &'static str,
    /// Floating-point operations per frame (a multiply-add counts 2).
    pub flops: f64,
    /// Bytes the stage's kernels read and write per frame.
    pub bytes: f64,
    /// Median seconds of the stage on its own (one submission and wait each).
    pub seconds: f64,
}

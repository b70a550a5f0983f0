//! Focal-stack refinement of a phase-only SLM pattern: a few iterations of gradient descent (Adam) on the
//! SLM phase so that what the viewer sees at a stack of focal planes matches a target hologram's focal
//! stack, warm-started from the CNN's pattern (`docs/REFINE.md`).
//!
//! The image formation model is the display's own: the SLM field `e^{iφ}` through the Fourier filter
//! (paper Eq. 8–9) and propagated by the angular spectrum method from the SLM plane to each focal plane
//! (Eq. 2, Eq. 10). The loss, per colour, is `Σ_d ‖k·|U_d| − T_d‖²` with the least-squares scale `k` (as the
//! scores of `docs/REFINE.md`); its gradient is analytic (the derivation in `refine/model.rs` and
//! `docs/REFINE.md`), so no autodiff framework is needed. Targets: the SM-LBM ground truth (Eq. 1–4), the
//! CNN's own midpoint hologram, or a given focal stack ([`FocalTarget`]). Starts: any phase pattern (the
//! CNN's, the previous frame's refined one, SM-LBM + double phase), zero or random ([`initial_phase`]).
//!
//! A [`Refiner`] is made once per frame size, target and display; [`Refiner::refine`] allocates nothing per
//! iteration after its first, runs colours and planes in parallel on its own threads, and gives the same
//! bits for the same inputs whatever the thread count (every sum in a fixed order).
//!
//! The folder, one concept per file:
//!
//! - `options`: what a refinement is asked ([`RefineOptions`], [`RefineStart`], [`initial_phase`]) and what
//!   it reports ([`IterationRecord`], [`RefineReport`]);
//! - `target`: the focal stack aimed at ([`FocalTarget`], [`loss_depths`], [`held_out_depths`]);
//! - `model`: the image formation model, its loss terms and their gradient;
//! - `engine`: [`Refiner`], planned once ([`Refiner::new`]) and run ([`Refiner::refine`]);
//! - `iterations`: the iterations on any device behind one trait, with what every device shares written
//!   once: the start's check, the records, the cancellation, the wrap;
//! - `device`: where a frame refiner's iterations run, chosen once (the CPU, or a device such as the GPU);
//! - `gpu` (cargo feature `gpu`): `GpuRefinement`, the iterations on a GPU;
//! - `frame`: one frame's refinement as apps and `holo` ask for it ([`FrameRefiner`]; the refiner of a
//!   pipeline's frames is `FrameRefiner::for_pipeline`, in `crate::pipeline`).
//!
//! The SLM's codes ↔ phase map the refinement reads and writes its patterns through is the display's
//! ([`crate::slm::codes`]); the refinement's loss as a score of any pattern is
//! [`crate::evaluation::focal_psnr`].

pub(crate) mod device;
pub(crate) mod engine;
pub(crate) mod frame;
#[cfg(feature = "gpu")]
mod gpu;
mod iterations;
pub(crate) mod model;
pub(crate) mod options;
pub mod target;
#[cfg(test)]
mod tests;

pub use engine::Refiner;
pub use frame::{
    FrameRefinement, FrameRefiner, HeldOutScores, RefineDisplay, RefineTarget, RefinedFrame,
    DEFAULT_TARGET_LEVELS,
};
#[cfg(feature = "gpu")]
pub use gpu::GpuRefinement;
pub use options::{
    initial_phase, IterationRecord, RefineOptions, RefineReport, RefineStart, MAX_ITERATIONS,
    MAX_STEP_RAD,
};
pub use target::{held_out_depths, loss_depths, FocalTarget, PLANES_RANGE};

//! The CNN engines, all in one place: a session's CNNs (hologram and pre-filter) run on the CPU on one of
//! them, chosen per session ([`CnnEngine`]; `Auto` times them on the machine). The session's CNN stage
//! ([`crate::pipeline`]) holds a `Box<dyn CnnPlan>` and never asks which engine it is.
//!
//! One concept per file, lower files first:
//!
//! - `tuning`: what a session asks and gets: [`CnnEngine`], [`CnnLayout`], [`ThreadCount`], [`PlanRequest`],
//!   [`PlanReport`] and the timing rule every engine shares;
//! - `plan`: `CnnPlan`, one CNN at one resolution, whatever engine runs it;
//! - `engine`: `Engine`, what an engine answers (can it run this model, its timing, its plans);
//! - `native/`: our direct 3×3 convolutions (`tensorholo-kernels`, SIMD rows chosen at run time) over the
//!   graph read by [`crate::model::graph`]; f32 and int8 QDQ files;
//! - `tract/` (cargo feature `tract`): tract's optimised plans, any ONNX graph that passes the contract
//!   (`docs/CONVENTIONS.md` §7), with its own per-model plan cache (`tract::TractModel`);
//! - `registry`: the engines of this build, the one place an engine is registered;
//! - `select`: the engine of a session ([`CnnEngine::Auto`] times those that can run the file),
//!   [`cnn_plan`] for one CNN (what `holo bench` times), [`check_runnable`].
//!
//! A new engine (or a second plan family of the native engine, such as Winograd convolutions) is a folder
//! here implementing `Engine` plus one entry in `registry.rs`.
//!
//! The GPU runs whole frames, not CNNs alone: it is a frame executor of the pipeline (`pipeline/executor.rs`),
//! not an engine here.

mod engine;
mod native;
mod plan;
mod registry;
mod select;
pub mod tract;
mod tuning;

pub use native::{f32_peak_gflops, int8_peak_gops, native_isa};
pub use select::{check_runnable, cnn_plan, CpuCnnPlan};
pub use tuning::{
    auto_thread_candidates, CnnEngine, CnnLayout, PlanReport, PlanRequest, PlanTiming, ThreadCount,
    MAX_CNN_THREADS,
};

#[cfg(all(test, feature = "tract"))]
pub(crate) use native::native_plan_on;
pub(crate) use plan::CnnPlan;
pub(crate) use select::{select, CnnPlans};

#[cfg(all(test, feature = "embedded-models"))]
mod tests;

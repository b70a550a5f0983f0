//! The CNN engines, all in one place: a session's CNNs (hologram and pre-filter) run on the CPU on one of
//! them, chosen per session ([`CnnEngine`]; `Auto` takes the plan table's, or times them when asked:
//! [`PlanSource`]). The session's CNN stage
//! ([`crate::pipeline`]) holds a `Box<dyn CnnPlan>` and never asks which engine it is.
//!
//! One concept per file, lower files first:
//!
//! - `options`: what a caller may ask for, as one [`CnnOptions`]: [`CnnEngine`], [`CnnLayout`], [`ThreadCount`],
//!   [`ConvAlgorithm`], the kernels' [`Isa`];
//! - `saved`: [`SavedPlans`], a session's plan decisions as a JSON file the caller owns;
//! - `tuning`: what a session asks and gets: [`PlanRequest`] (with its [`PlanSource`]: the plan table, a
//!   saved tuning, or a timing), [`PlanReport`] and the timing rule every engine shares;
//! - `table`: the plan table, the decisions made without timing (per ISA, layer shape and file), and where
//!   each entry was measured;
//! - `plan`: `CnnPlan`, one CNN at one resolution, whatever engine runs it;
//! - `engine`: `Engine`, what an engine answers (can it run this model, its timing, its plans);
//! - `native/`: our direct 3×3 convolutions (`tensorholo-kernels`, SIMD rows chosen at run time) over the
//!   graph read by `model::graph`; f32 and int8 QDQ files;
//! - `tract/` (cargo feature `tract`): tract's optimised plans, any ONNX graph that passes the contract
//!   (`docs/CONVENTIONS.md` §7), with its own per-model plan cache (`tract::TractModel`);
//! - `select`: the engine of a session ([`CnnEngine::Auto`] times those that can run the file),
//!   [`cnn_plan`] for one CNN (what `holo bench` times), [`check_runnable`], over the engines it is given;
//! - this file: the registry, the engines of this build (`engines`, the one place an engine is registered,
//!   and the one `cfg(feature = "tract")` outside `tract/`), and the entry points over it.
//!
//! A new engine (or a second plan family of the native engine, such as Winograd convolutions) is a folder
//! here implementing `Engine`, its `mod` line and entry in `engines` here, and its [`CnnEngine`] variant in
//! `tuning.rs`: three files.
//!
//! The GPU runs whole frames, not CNNs alone: it is a frame executor of the pipeline (`pipeline/executor.rs`),
//! not an engine here.

mod engine;
mod native;
mod options;
mod plan;
mod saved;
mod select;
mod table;
pub mod tract;
mod tuning;

use std::sync::Arc;

use engine::Registry;

#[cfg(doc)]
use crate::error::HoloError;
use crate::error::Result;
use crate::model::HologramModel;

pub use native::{f32_peak_gflops, int8_peak_gops};
pub use options::{
    default_threads, CnnEngine, CnnLayout, CnnOptions, ConvAlgorithm, ThreadCount, MAX_CNN_THREADS,
};
pub use saved::{SavedPlans, SavedRow, SavedSession, SAVED_PLANS_FORMAT, SAVED_PLANS_VERSION};
pub use select::CpuCnnPlan;
pub use tensorholo_kernels::Isa;
pub use tuning::{
    auto_thread_candidates, PlanOrigin, PlanReport, PlanRequest, PlanSource, PlanTiming,
};

#[cfg(all(test, feature = "tract"))]
pub(crate) use native::native_plan_on;
pub(crate) use options::available;
pub(crate) use plan::CnnPlan;
pub(crate) use select::CnnPlans;

/// The CPU CNN engines compiled into this build, best first: the native engine, and tract with the cargo
/// feature `tract`. The one place an engine is registered.
fn engines() -> Registry {
    &[
        &native::NativeEngine,
        #[cfg(feature = "tract")]
        &tract::TractEngine,
    ]
}

/// The plans for `height × width` frames of `hologram` (and `prefilter`) on the engine `request` names, made
/// as it says: a session's CNNs.
///
/// Errors: [`crate::HoloError::InvalidParameter`] (`engine`) for an engine this build lacks (naming its
/// cargo feature) or one that cannot run the file (the reason is given);
/// [`crate::HoloError::ShapeMismatch`] if the file fixes another size; the engines' plan and run errors.
pub(crate) fn select(
    hologram: &Arc<HologramModel>,
    prefilter: Option<&Arc<HologramModel>>,
    height: usize,
    width: usize,
    request: &PlanRequest,
) -> Result<CnnPlans> {
    select::select(engines(), hologram, prefilter, height, width, request)
}

/// Refuses a model that no CPU engine of this build can run, when a pipeline is made (so that a phone build
/// without tract refuses such a file before any session): `Ok` where one engine runs it.
///
/// Errors: [`HoloError::ModelContract`] naming why each engine cannot run it and the cargo features this
/// build leaves out; [`HoloError::ModelLoad`] where the last engine tried cannot read the file at all.
pub fn check_runnable(model: &Arc<HologramModel>) -> Result<()> {
    select::check_runnable(engines(), model)
}

/// `model`'s CNN for `height × width` inputs on the engine `request` names ([`CnnOptions::engine`]), made as
/// it says, and how it was chosen, as a session chooses.
///
/// Errors: as the session's choice: [`HoloError::InvalidParameter`] (`engine`) for an engine this build
/// lacks or one that cannot run the file; the engine's plan errors.
pub fn cnn_plan(
    model: &Arc<HologramModel>,
    height: usize,
    width: usize,
    request: &PlanRequest,
) -> Result<(CpuCnnPlan, PlanReport)> {
    select::cnn_plan(engines(), model, height, width, request)
}

#[cfg(all(test, feature = "embedded-models"))]
mod tests;

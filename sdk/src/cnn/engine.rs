//! [`Engine`]: what a CPU CNN engine answers so that a session's engine choice (`cnn/select.rs`) can ask it:
//! whether it runs a model, its timing, its plans. An engine is a folder under `cnn/` implementing it and one
//! entry in the registry (`cnn/mod.rs`).

use std::sync::Arc;

use tensorholo_kernels::Isa;

use super::options::{CnnEngine, CnnLayout};
use super::plan::CnnPlan;
use super::saved::SavedRow;
use super::tuning::{PlanRequest, PlanTiming};
use crate::error::Result;
use crate::model::HologramModel;

/// The CNNs of one session: the hologram CNN and, where the pipeline has one, the pre-filter CNN.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Networks<'a> {
    pub(crate) hologram: &'a Arc<HologramModel>,
    pub(crate) prefilter: Option<&'a Arc<HologramModel>>,
}

impl Networks<'_> {
    /// Both networks, hologram CNN first.
    pub(crate) fn each(&self) -> impl Iterator<Item = &Arc<HologramModel>> {
        std::iter::once(self.hologram).chain(self.prefilter)
    }
}

/// What an engine's timing chose ([`Engine::tune`]): the layout and threads of its fastest candidate, every
/// candidate's timing, and the seconds the timing took.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Tuning {
    pub(crate) layout: CnnLayout,
    /// `None`: tract's process-wide executor.
    pub(crate) threads: Option<usize>,
    /// Every candidate timed, in order (empty when nothing was timed).
    pub(crate) candidates: Vec<PlanTiming>,
    /// Wall-clock seconds of the timing (plans and runs); 0 when nothing was timed or it came from a cache.
    pub(crate) seconds: f64,
    /// The kernel row of each f32 layer shape (the native engine; empty for tract).
    pub(crate) rows: Vec<SavedRow>,
    /// What a saved tuning decided and what the table filled in, for the report (empty otherwise).
    pub(crate) notes: Vec<String>,
}

impl Tuning {
    /// The fastest candidate's seconds, if any was timed.
    pub(crate) fn best_seconds(&self) -> Option<f64> {
        self.candidates
            .iter()
            .filter_map(|t| t.seconds)
            .min_by(|a, b| a.total_cmp(b))
    }
}

/// The plans an engine built for one session ([`Engine::plans`]).
#[derive(Debug)]
pub(crate) struct EnginePlans {
    pub(crate) hologram: Box<dyn CnnPlan>,
    pub(crate) prefilter: Option<Box<dyn CnnPlan>>,
    /// The kernel row the layers run on (the native engine), for the report.
    pub(crate) kernel: Option<String>,
}

/// One CPU CNN engine, as the session's engine choice (`cnn/select.rs`) asks it.
/// The engines of a build, best first (`cnn/mod.rs` registers them; `cnn/select.rs` reads them).
pub(crate) type Registry = &'static [&'static dyn Engine];

pub(crate) trait Engine: Sync {
    /// Which engine this is.
    fn id(&self) -> CnnEngine;

    /// `Ok` where this engine can run every network of `nets`, otherwise why not (the reason names the
    /// network and what the engine lacks).
    fn supports(&self, nets: Networks<'_>) -> Result<()>;

    /// Decides this engine's plans of `request` for `height × width` frames of `nets`: from the plan table
    /// or a saved tuning (`request.source`), or, with [`super::PlanSource::Tune`], by timing its candidates
    /// (layouts × thread counts it has, each f32 layer shape's rows) and keeping the fastest. A single
    /// candidate is timed only when `time_single` (to compare engines). `to_beat`: the best seconds of an
    /// engine timed before this one (on the same input); an engine with several candidates times its
    /// likeliest first and may leave the others untimed (reported as skipped) when that one is far slower
    /// (tract: 1.5×, its `PLAUSIBLE_FACTOR`).
    ///
    /// Errors: [`crate::HoloError::InvalidParameter`] (`tuning`) for saved plans of another kernel ISA level;
    /// the engine's plan and run errors.
    fn tune(
        &self,
        nets: Networks<'_>,
        height: usize,
        width: usize,
        request: &PlanRequest,
        time_single: bool,
        to_beat: Option<f64>,
    ) -> Result<Tuning>;

    /// `Some(why)` where this engine, able to run the files, is known to outrun every other engine of the
    /// build on this CPU at the instruction set `isa`, so that [`super::CnnEngine::Auto`] does not time the
    /// engines after it (tract's plan and run cost 0.3–0.4 s of a 1080p session's setup). `None`, the default:
    /// they are timed.
    fn outruns_the_others(&self, _isa: Isa) -> Option<String> {
        None
    }

    /// The plans of `nets` at `height × width` with `tuning`'s layout, threads and rows (the pre-filter runs
    /// channels-first with the same threads), as `request` allows.
    ///
    /// Errors: the engine's plan errors.
    fn plans(
        &self,
        nets: Networks<'_>,
        height: usize,
        width: usize,
        request: &PlanRequest,
        tuning: &Tuning,
    ) -> Result<EnginePlans>;
}

//! The tract engine ([`CnnEngine::Tract`], cargo feature `tract`): tract 0.23's optimised plans, which run any
//! ONNX graph that passes the contract (`docs/CONVENTIONS.md` §7), int8 QOperator files included; the
//! native engine and the GPU run the TensorHolo residual CNN only. Notes: `docs/MODEL_TRACT.md`.
//!
//! - `model.rs`: [`TractModel`], tract's side of one model (the typed, decluttered graph, its plans per
//!   resolution and layout, the autotuning of layouts × thread counts);
//! - `plan.rs`: [`ModelPlan`] (one optimised plan, a `CnnPlan`), [`NodeTiming`].
//!
//! The engine keeps one [`TractModel`] per model a session has asked it about ([`TractModel::of`]), and drops
//! it with the model: the plans and the autotuning results outlive the session, so a second session of the
//! same size starts at once.
#![cfg(feature = "tract")]

mod model;
mod plan;

use std::sync::{Arc, Mutex, Weak};

pub use model::TractModel;
pub use plan::{ModelPlan, NodeTiming};

use super::engine::{Engine, EnginePlans, Networks, Tuning};
use super::options::{CnnEngine, CnnLayout, ThreadCount};
use super::plan::{time_plan, CnnPlan};
use super::saved::network_key;
use super::tuning::{PlanRequest, PlanTiming};
use crate::error::Result;
use crate::model::HologramModel;

/// The tract engine (registered in `cnn/mod.rs`).
pub(crate) struct TractEngine;

/// The engine's [`TractModel`]s, one per live model (a model is known by its `Arc`; an entry whose model was
/// dropped is removed at the next look-up).
type Cache = Vec<(Weak<HologramModel>, Arc<TractModel>)>;

static MODELS: Mutex<Cache> = Mutex::new(Vec::new());

impl TractModel {
    /// tract's side of `model` from the engine's cache: parsed, typed and decluttered on the first call for
    /// this model, shared afterwards (with its plans and autotuning results) until the model is dropped.
    ///
    /// Errors: as [`TractModel::new`] (not cached: the next call tries again).
    pub fn of(model: &Arc<HologramModel>) -> Result<Arc<TractModel>> {
        {
            // Nothing panics while holding the lock; recover the cache rather than propagate poison.
            let mut cache = MODELS.lock().unwrap_or_else(|p| p.into_inner());
            cache.retain(|(m, _)| m.strong_count() > 0);
            if let Some((_, t)) = cache.iter().find(|(m, _)| m.as_ptr() == Arc::as_ptr(model)) {
                return Ok(t.clone());
            }
        }
        // Typed outside the lock: another model's session need not wait for this one.
        let fresh = Arc::new(TractModel::new(model)?);
        let mut cache = MODELS.lock().unwrap_or_else(|p| p.into_inner());
        if let Some((_, t)) = cache.iter().find(|(m, _)| m.as_ptr() == Arc::as_ptr(model)) {
            return Ok(t.clone());
        }
        cache.push((Arc::downgrade(model), fresh.clone()));
        Ok(fresh)
    }
}

impl Engine for TractEngine {
    fn id(&self) -> CnnEngine {
        CnnEngine::Tract
    }

    fn supports(&self, nets: Networks<'_>) -> Result<()> {
        for model in nets.each() {
            TractModel::of(model)?;
        }
        Ok(())
    }

    fn tune(
        &self,
        nets: Networks<'_>,
        height: usize,
        width: usize,
        request: &PlanRequest,
        time_single: bool,
        to_beat: Option<f64>,
    ) -> Result<Tuning> {
        let model = TractModel::of(nets.hologram)?;
        // A saved tuning's layout and threads for this session, as if asked for.
        let mut request = request.clone();
        let mut notes = Vec::new();
        let saved = request
            .source
            .saved()
            .and_then(|p| p.session(&network_key(nets.hologram), [height, width]))
            .filter(|s| s.engine == CnnEngine::Tract)
            .cloned();
        if let Some(s) = saved {
            if request.cnn.layout == CnnLayout::Auto {
                request.cnn.layout = s.layout;
                notes.push(format!("tract layout {} from the saved plans", s.layout));
            }
            if request.cnn.threads == ThreadCount::Auto {
                request.cnn.threads = s
                    .threads
                    .map_or(ThreadCount::ProcessDefault, ThreadCount::Fixed);
                notes.push("tract threads from the saved plans".into());
            }
        }
        let report = model.tuning(height, width, &request, to_beat)?;
        let mut tuning = Tuning {
            layout: report.layout,
            threads: report.threads,
            candidates: report.candidates,
            seconds: report.tuning_s,
            rows: Vec::new(),
            notes,
        };
        if tuning.candidates.is_empty() && time_single {
            // A single candidate was not timed: time it now, on the same input as the other engines.
            let plan = model.plan_with_layout(height, width, tuning.layout)?;
            let plan = match tuning.threads {
                Some(t) => plan.with_threads(t)?,
                None => plan,
            };
            let mut plan: Box<dyn CnnPlan> = Box::new(plan);
            let s = time_plan(plan.as_mut(), model.input_channels(), height, width)?;
            tuning.candidates.push(PlanTiming {
                engine: CnnEngine::Tract,
                layout: tuning.layout,
                threads: tuning.threads,
                seconds: Some(s),
                skipped: None,
            });
        }
        Ok(tuning)
    }

    fn plans(
        &self,
        nets: Networks<'_>,
        height: usize,
        width: usize,
        _request: &PlanRequest,
        tuning: &Tuning,
    ) -> Result<EnginePlans> {
        let with_threads = |plan: ModelPlan| match tuning.threads {
            Some(t) => plan.with_threads(t),
            None => Ok(plan),
        };
        let hologram =
            TractModel::of(nets.hologram)?.plan_with_layout(height, width, tuning.layout)?;
        // The pre-filter always runs channels-first (PipelineConfig::cnn_layout), with the same threads.
        let prefilter: Option<Box<dyn CnnPlan>> = match nets.prefilter {
            Some(p) => Some(Box::new(with_threads(
                TractModel::of(p)?.plan(height, width)?,
            )?)),
            None => None,
        };
        Ok(EnginePlans {
            hologram: Box::new(with_threads(hologram)?),
            prefilter,
            kernel: None,
        })
    }
}

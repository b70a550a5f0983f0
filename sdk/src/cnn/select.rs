//! [`select`]: the CNN plans of one session, on the engine [`CnnEngine`] asks for or, for
//! [`CnnEngine::Auto`], on the plan table's engine (`cnn/table.rs`), a saved tuning's, or with
//! [`PlanSource::Tune`] the engine of this build that ran fastest on this machine at session creation;
//! [`super::cnn_plan`] does the same for one CNN (what `holo bench` times), and [`super::check_runnable`]
//! refuses, when a pipeline is made, a model no engine of this build can run.
//!
//! The timing rule is the same for every engine ([`crate::cnn::tuning`]): the same input (a constant 0.5),
//! the same resolution ([`timing_resolution`]: the frame, or a full-width strip of a large one), one run or
//! the fastest of three when a run is short. Each engine times its own candidates (tract: layouts × thread
//! counts; native: layer rows, thread counts); this file compares the engines' best.

use std::sync::Arc;

use ndarray::{Array3, ArrayView3};

use super::engine::{Engine, Networks, Registry, Tuning};
use super::options::CnnEngine;
use super::plan::CnnPlan;
use super::saved::network_key;
use super::table;
use super::tuning::{
    timing_resolution, PlanOrigin, PlanReport, PlanRequest, PlanSource, PlanTiming, NOT_TIMED,
};
use crate::error::{invalid, HoloError, Result};
use crate::model::HologramModel;

/// The plans of one session: the hologram CNN's, the pre-filter CNN's (if any), and how they were chosen.
#[derive(Debug)]
pub(crate) struct CnnPlans {
    pub(crate) hologram: Box<dyn CnnPlan>,
    pub(crate) prefilter: Option<Box<dyn CnnPlan>>,
    pub(crate) report: PlanReport,
}

/// The plans for `height × width` frames of `hologram` (and `prefilter`) on `engine`, made as `request`
/// says (its source: the plan table, a saved tuning, or timed now).
///
/// Errors: [`HoloError::InvalidParameter`] (`engine`) for an engine this build lacks (naming its cargo
/// feature) or one that cannot run the file (the reason is given); [`HoloError::InvalidParameter`]
/// (`tuning`) for saved plans of another kernel ISA level; [`HoloError::ShapeMismatch`] if the file fixes
/// another size; the engines' plan and run errors.
pub(super) fn select(
    engines: Registry,
    hologram: &Arc<HologramModel>,
    prefilter: Option<&Arc<HologramModel>>,
    height: usize,
    width: usize,
    request: &PlanRequest,
) -> Result<CnnPlans> {
    // The options once for every engine: threads, strips, slabs, and an instruction set this CPU has.
    request.cnn.validate()?;
    let engine = request.cnn.engine;
    hologram.check_fixed_size(height, width)?;
    let nets = Networks {
        hologram,
        prefilter,
    };
    if engine != CnnEngine::Auto {
        let chosen = find(engines, engine)?;
        if let Err(e) = chosen.supports(nets) {
            return Err(invalid(
                "engine",
                format!(
                    "the {engine} CNN engine cannot run this model: {e}{}",
                    others(engines, engine)
                ),
            ));
        }
        let tuning = chosen.tune(nets, height, width, request, false, None)?;
        return build(chosen, nets, [height, width], request, "requested", tuning);
    }
    let mut able = Vec::new();
    let mut unable = Vec::new();
    for e in engines {
        match e.supports(nets) {
            Ok(()) => able.push(*e),
            Err(err) => unable.push((e.id(), err)),
        }
    }
    match able.as_slice() {
        [] => Err(unable
            .pop()
            .map(|(_, e)| e)
            .unwrap_or_else(|| HoloError::Internal("no CNN engine is registered".into()))),
        [only] => {
            let why = if unable.is_empty() {
                format!(
                    "the only CPU engine of this build{}",
                    missing_features(engines)
                )
            } else {
                unable
                    .iter()
                    .map(|(id, e)| format!("the {id} engine cannot run this model ({e})"))
                    .collect::<Vec<_>>()
                    .join("; ")
            };
            let tuning = only.tune(nets, height, width, request, false, None)?;
            build(*only, nets, [height, width], request, &why, tuning)
        }
        several if request.source.tunes() => fastest(several, nets, [height, width], request),
        several => planned(several, nets, [height, width], request),
    }
}

/// [`CnnEngine::Auto`] where several engines can run the files and nothing is timed: a saved tuning's engine
/// for this session where it is one of them, else the plan table's ([`table::engine`]).
fn planned(
    able: &[&dyn Engine],
    nets: Networks<'_>,
    [height, width]: [usize; 2],
    request: &PlanRequest,
) -> Result<CnnPlans> {
    let has = |id| able.iter().copied().find(|e| e.id() == id);
    let saved = request
        .source
        .saved()
        .and_then(|p| p.session(&network_key(nets.hologram), [height, width]))
        .and_then(|s| has(s.engine));
    let (engine, why) = match saved {
        Some(e) => (e, "the saved plans".to_string()),
        None => {
            let isa = request.cnn.kernel_isa()?;
            let int8 = nets.each().any(|m| m.metadata().precision != "f32");
            let native = has(CnnEngine::Native).is_some();
            let tract = has(CnnEngine::Tract).is_some();
            let (id, why) = table::engine(isa, int8, native, tract)
                .ok_or_else(|| HoloError::Internal("no engine in the plan table".into()))?;
            let e = has(id).ok_or_else(|| HoloError::Internal(format!("no {id} engine")))?;
            (e, why)
        }
    };
    log::info!("CNN engine for {height}×{width}: {}, {why}", engine.id());
    let tuning = engine.tune(nets, height, width, request, false, None)?;
    build(engine, nets, [height, width], request, &why, tuning)
}

/// [`CnnEngine::Auto`] where several engines can run the files: each timed on this machine, in the
/// registry's order (the native engine first), the fastest kept. Each engine is told the best time so far,
/// so that one far slower stops after its likeliest candidate (tract: one plan instead of four); and an
/// engine that outruns the others on this CPU ([`Engine::outruns_the_others`]) is kept without timing them
/// (each is reported as a candidate not timed, with the reason).
fn fastest(
    able: &[&dyn Engine],
    nets: Networks<'_>,
    [height, width]: [usize; 2],
    request: &PlanRequest,
) -> Result<CnnPlans> {
    let isa = request.cnn.kernel_isa()?;
    let mut timed = Vec::new();
    let mut untimed = Vec::new();
    // Why the engines after the first one timed are not timed: that engine's reason, with its id.
    let mut decided: Option<(CnnEngine, String)> = None;
    let mut to_beat: Option<f64> = None;
    for e in able {
        if let Some((first, why)) = &decided {
            untimed.push(PlanTiming {
                engine: e.id(),
                layout: request.cnn.layout,
                threads: None,
                seconds: None,
                skipped: Some(format!("{NOT_TIMED}: the {first} engine runs {why}")),
            });
            continue;
        }
        let tuning = e.tune(nets, height, width, request, true, to_beat)?;
        let best = tuning.best_seconds().unwrap_or(f64::INFINITY);
        to_beat = Some(to_beat.map_or(best, |b| b.min(best)));
        timed.push((*e, tuning, best));
        if timed.len() == 1 && best.is_finite() {
            decided = e.outruns_the_others(isa).map(|why| (e.id(), why));
        }
    }
    timed.sort_by(|a, b| a.2.total_cmp(&b.2));
    let candidates: Vec<_> = timed
        .iter()
        .flat_map(|(_, t, _)| t.candidates.iter().cloned())
        .chain(untimed)
        .collect();
    let seconds = timed.iter().map(|(_, t, _)| t.seconds).sum();
    let mut ranked = timed.into_iter();
    let (winner, tuning, best) = ranked
        .next()
        .ok_or_else(|| HoloError::Internal("no engine timed".into()))?;
    let runner_up = ranked.next();
    let why = match (&runner_up, &decided) {
        (Some((other, _, s)), _) => format!(
            "faster on this CPU ({:.2}× {}'s best)",
            s / best,
            other.id()
        ),
        (None, Some((_, why))) => why.clone(),
        (None, None) => "faster on this CPU".into(),
    };
    log::info!("CNN engine for {height}×{width}: {}, {why}", winner.id());
    let tuning = Tuning {
        candidates,
        seconds,
        ..tuning
    };
    let mut plans = build(winner, nets, [height, width], request, &why, tuning)?;
    plans.report.autotuned = true;
    Ok(plans)
}

/// The plans of `engine` for `tuning`, reported with what was asked (`request`), why (`why`), the timings,
/// their cost and where the decisions came from.
fn build(
    engine: &dyn Engine,
    nets: Networks<'_>,
    [height, width]: [usize; 2],
    request: &PlanRequest,
    why: &str,
    tuning: Tuning,
) -> Result<CnnPlans> {
    let plans = engine
        .plans(nets, height, width, request, &tuning)
        .map_err(|e| match (&request.source, e) {
            // A saved session's engine or layout this network cannot run: the saved plans are at fault (their
            // file and session), not a setting the user gave.
            (PlanSource::Saved(p), HoloError::InvalidParameter { name, reason })
                if why == "the saved plans" || !tuning.notes.is_empty() =>
            {
                invalid(
                    "tuning",
                    format!(
                        "the saved plans ({}) give the session of {} at {height}×{width} the {} engine \
                         with layout {}, which it cannot run ({name}: {reason}); tune again (--tune) or \
                         remove that session from the file",
                        p.origin,
                        network_key(nets.hologram),
                        engine.id(),
                        tuning.layout
                    ),
                )
            }
            (_, e) => e,
        })?;
    let (source, source_detail) = match &request.source {
        PlanSource::Table => (
            PlanOrigin::Table,
            "the plan table (a function of the CPU's features, the shapes, the size and the threads; \
             nothing timed)"
                .to_string(),
        ),
        PlanSource::Tune => (
            PlanOrigin::Tuned,
            format!(
                "tuned on this machine in {:.2} s (save it to repeat these plans)",
                tuning.seconds
            ),
        ),
        PlanSource::Saved(p) => {
            let mut notes = tuning.notes.clone();
            if why == "the saved plans" {
                notes.insert(0, format!("engine {} from the saved plans", engine.id()));
            }
            let what = if notes.is_empty() {
                "nothing for this session: the plan table".to_string()
            } else {
                notes.join("; ")
            };
            (
                PlanOrigin::Saved,
                format!("saved plans ({}): {what}", p.origin),
            )
        }
    };
    Ok(CnnPlans {
        hologram: plans.hologram,
        prefilter: plans.prefilter,
        report: PlanReport {
            resolution: [height, width],
            request: request.clone(),
            engine: engine.id(),
            engine_reason: why.to_string(),
            kernel: plans.kernel,
            layout: tuning.layout,
            threads: tuning.threads,
            autotuned: tuning.candidates.len() > 1,
            timed_resolution: timing_resolution(height, width),
            candidates: tuning.candidates,
            tuning_s: tuning.seconds,
            source,
            source_detail,
            network: network_key(nets.hologram),
            isa: request.cnn.kernel_isa()?.name().to_string(),
            rows: tuning.rows,
        },
    })
}

/// The registered engine `id`. Errors: [`HoloError::InvalidParameter`] (`engine`) for one this build lacks,
/// naming its cargo feature.
fn find(engines: Registry, id: CnnEngine) -> Result<&'static dyn Engine> {
    engines
        .iter()
        .copied()
        .find(|e| e.id() == id)
        .ok_or_else(|| {
            let feature = id.cargo_feature().unwrap_or("?");
            invalid(
                "engine",
                format!(
                    "this build has no {id} engine (cargo feature `{feature}` of tensorholo and \
                 tensorholo-ffi, on by default){}",
                    others(engines, id)
                ),
            )
        })
}

/// "; use the X engine" naming the other engines of this build, or nothing.
fn others(engines: Registry, id: CnnEngine) -> String {
    let names: Vec<&str> = engines
        .iter()
        .map(|e| e.id())
        .filter(|&e| e != id)
        .map(CnnEngine::name)
        .collect();
    match names.as_slice() {
        [] => String::new(),
        n => format!("; use the {} engine", n.join(" or ")),
    }
}

/// " (no cargo feature `tract`)" for the engines this build leaves out, or nothing.
fn missing_features(engines: Registry) -> String {
    let missing: Vec<String> = CnnEngine::ENGINES
        .iter()
        .filter(|id| engines.iter().all(|e| e.id() != **id))
        .filter_map(|id| id.cargo_feature())
        .map(|f| format!("`{f}`"))
        .collect();
    if missing.is_empty() {
        String::new()
    } else {
        format!(" (no cargo feature {})", missing.join(", "))
    }
}

/// [`super::check_runnable`] over `engines`.
pub(super) fn check_runnable(engines: Registry, model: &Arc<HologramModel>) -> Result<()> {
    let nets = Networks {
        hologram: model,
        prefilter: None,
    };
    let mut reasons = Vec::new();
    for e in engines {
        match e.supports(nets) {
            Ok(()) => return Ok(()),
            Err(err) => reasons.push((e.id(), err)),
        }
    }
    let missing = missing_features(engines);
    if missing.is_empty() {
        if let Some((_, last)) = reasons.pop() {
            return Err(last);
        }
    }
    let why: Vec<String> = reasons
        .into_iter()
        .map(|(id, e)| match e {
            HoloError::ModelContract { reason, .. } => format!("{reason} ({id} engine)"),
            other => format!("{other} ({id} engine)"),
        })
        .collect();
    Err(HoloError::ModelContract {
        source_name: model.source_name().to_string(),
        reason: format!(
            "{}. This build has no other CPU CNN engine{missing}: tract runs any other graph that \
             passes the contract",
            why.join("; ")
        ),
    })
}

/// One CNN at one resolution on the engine [`super::cnn_plan`] chose: what `holo bench` times, engine against
/// engine. A session builds its own plans; this is for measuring the CNN alone.
#[derive(Debug)]
pub struct CpuCnnPlan(Box<dyn CnnPlan>);

impl CpuCnnPlan {
    /// `(channels, height, width)` of the input `[C, H, W]`.
    pub fn input_dim(&self) -> (usize, usize, usize) {
        self.0.input_dim()
    }

    /// Runs the CNN on `input` `[C, H, W]`: its two outputs `[3, H, W]` (amplitude and phase of a hologram
    /// CNN; `Re`, `Im` of a pre-filter). Errors: [`HoloError::ShapeMismatch`]; the engine's run errors.
    pub fn run_outputs(&mut self, input: ArrayView3<f32>) -> Result<(Array3<f32>, Array3<f32>)> {
        self.0.run_outputs(input)
    }
}

/// [`super::cnn_plan`] over `engines`.
pub(super) fn cnn_plan(
    engines: Registry,
    model: &Arc<HologramModel>,
    height: usize,
    width: usize,
    request: &PlanRequest,
) -> Result<(CpuCnnPlan, PlanReport)> {
    let plans = select(engines, model, None, height, width, request)?;
    Ok((CpuCnnPlan(plans.hologram), plans.report))
}

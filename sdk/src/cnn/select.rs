//! [`select`]: the CNN plans of one session, on the engine [`CnnEngine`] asks for or, for
//! [`CnnEngine::Auto`], on the engine that ran faster on this machine at session creation.
//!
//! The timing follows tract's own tuning ([`HologramModel::tuned_plan`]): the same input (a constant 0.5), the
//! same resolution ([`timing_resolution`]: the frame, or a full-width strip of a large one), one run or the
//! fastest of three when a run is short. tract's candidates are its layouts × thread counts; the native
//! engine's are the thread counts.

use std::sync::Arc;
use std::time::Instant;

use ndarray::Array3;

use super::{active_isa, native_plan, CnnEngine, CnnPlan};
use crate::error::{invalid, Result};
use crate::model::tuning::fastest_run;
use crate::model::{
    auto_thread_candidates, timing_resolution, CnnLayout, CnnWeights, HologramModel, PlanReport,
    PlanRequest, PlanTiming, ThreadCount,
};

/// The plans of one session: the hologram CNN's, the pre-filter CNN's (if any), and how they were chosen.
#[derive(Debug)]
pub(crate) struct CnnPlans {
    pub(crate) hologram: Box<dyn CnnPlan>,
    pub(crate) prefilter: Option<Box<dyn CnnPlan>>,
    pub(crate) report: PlanReport,
}

/// The plans for `height × width` frames of `hologram` (and `prefilter`) on `engine`, with tract's layout
/// and threads from `request` (the native engine uses `request.threads`).
///
/// Errors: [`crate::HoloError::InvalidParameter`] (`engine`) for [`CnnEngine::Native`] with a file it cannot run
/// (int8, or a graph that is not the architecture: the reason is given); as
/// [`HologramModel::tuned_plan`] and [`HologramModel::plan`].
pub(crate) fn select(
    hologram: &HologramModel,
    prefilter: Option<&HologramModel>,
    height: usize,
    width: usize,
    engine: CnnEngine,
    request: PlanRequest,
) -> Result<CnnPlans> {
    hologram.check_fixed_size(height, width)?;
    let graphs = native_graphs(hologram, prefilter);
    match (engine, graphs) {
        #[cfg(feature = "tract")]
        (CnnEngine::Tract, _) => {
            tract_plans(hologram, prefilter, height, width, request, "requested")
        }
        #[cfg(not(feature = "tract"))]
        (CnnEngine::Tract, _) => Err(invalid("engine", NO_TRACT)),
        (CnnEngine::Native, Err(e)) => Err(invalid(
            "engine",
            format!("the native CNN engine cannot run this model: {e}{USE_TRACT}"),
        )),
        #[cfg(feature = "tract")]
        (CnnEngine::Auto, Err(e)) => {
            let why = format!("the native engine cannot run this model ({e})");
            tract_plans(hologram, prefilter, height, width, request, &why)
        }
        #[cfg(not(feature = "tract"))]
        (CnnEngine::Auto, Err(e)) => Err(e),
        (CnnEngine::Native, Ok((graph, pre))) => {
            let tuning = tune_native(&graph, height, width, request.threads, false)?;
            native_plans(&graph, pre, [height, width], request, "requested", tuning)
        }
        #[cfg(feature = "tract")]
        (CnnEngine::Auto, Ok((graph, pre))) => {
            faster_engine(hologram, prefilter, &graph, pre, [height, width], request)
        }
        #[cfg(not(feature = "tract"))]
        (CnnEngine::Auto, Ok((graph, pre))) => {
            let tuning = tune_native(&graph, height, width, request.threads, false)?;
            let why = "the only CPU engine of this build (no cargo feature `tract`)";
            native_plans(&graph, pre, [height, width], request, why, tuning)
        }
    }
}

/// What to do when the native engine cannot run a file.
const USE_TRACT: &str = if cfg!(feature = "tract") {
    "; use the tract engine"
} else {
    ""
};

/// Why [`CnnEngine::Tract`] is refused in a build without the `tract` feature.
#[cfg(not(feature = "tract"))]
const NO_TRACT: &str = "this build has no tract engine (cargo feature `tract` of tensorholo and \
                        tensorholo-ffi, on by default); use the native engine";

/// [`CnnEngine::Auto`] where both engines can run the files: each timed on this machine, the faster kept.
#[cfg(feature = "tract")]
fn faster_engine(
    hologram: &HologramModel,
    prefilter: Option<&HologramModel>,
    graph: &Arc<CnnWeights>,
    pre: Option<Arc<CnnWeights>>,
    [height, width]: [usize; 2],
    request: PlanRequest,
) -> Result<CnnPlans> {
    let native = tune_native(graph, height, width, request.threads, true)?;
    let (tract_plan, tract_report) = hologram.tuned_plan(height, width, request)?;
    let best = |c: &[PlanTiming]| {
        c.iter()
            .filter_map(|t| t.seconds)
            .min_by(|a, b| a.total_cmp(b))
    };
    let native_best = best(&native.candidates);
    let tract_best = best(&tract_report.candidates);
    let mut candidates = tract_report.candidates.clone();
    candidates.extend(native.candidates.iter().cloned());
    let tuning_s = tract_report.tuning_s + native.seconds;
    // tract with a single candidate was not timed: time it now, on the same input.
    let tract_best = match tract_best {
        Some(s) => s,
        None => {
            let s = time_plan(
                &mut tract_plan.clone(),
                hologram.input_channels(),
                height,
                width,
            )?;
            candidates.push(PlanTiming {
                engine: CnnEngine::Tract,
                layout: tract_report.layout,
                threads: tract_report.threads,
                seconds: Some(s),
                skipped: None,
            });
            s
        }
    };
    let native_best = native_best.unwrap_or(f64::INFINITY);
    let ratio = tract_best / native_best;
    if native_best <= tract_best {
        let why = format!("faster on this CPU ({ratio:.2}× tract's best)");
        log::info!("CNN engine for {height}×{width}: native, {why}");
        let tuning = NativeTuning {
            threads: native.threads,
            candidates,
            seconds: tuning_s,
        };
        let mut plans = native_plans(graph, pre, [height, width], request, &why, tuning)?;
        plans.report.autotuned = true;
        Ok(plans)
    } else {
        let why = format!("faster on this CPU ({:.2}× the native engine)", 1.0 / ratio);
        log::info!("CNN engine for {height}×{width}: tract, {why}");
        let mut plans = tract_with(prefilter, height, width, tract_plan, tract_report)?;
        plans.report.engine_reason = why;
        plans.report.candidates = candidates;
        plans.report.tuning_s = tuning_s;
        plans.report.autotuned = true;
        Ok(plans)
    }
}

/// The graphs the native engine would run, or why it cannot.
fn native_graphs(
    hologram: &HologramModel,
    prefilter: Option<&HologramModel>,
) -> Result<(Arc<CnnWeights>, Option<Arc<CnnWeights>>)> {
    let graph = hologram.cnn_graph()?;
    let pre = prefilter.map(|p| p.cnn_graph()).transpose()?;
    active_isa()?;
    Ok((graph, pre))
}

#[cfg(feature = "tract")]
fn tract_plans(
    hologram: &HologramModel,
    prefilter: Option<&HologramModel>,
    height: usize,
    width: usize,
    request: PlanRequest,
    why: &str,
) -> Result<CnnPlans> {
    let (plan, report) = hologram.tuned_plan(height, width, request)?;
    let mut plans = tract_with(prefilter, height, width, plan, report)?;
    plans.report.engine_reason = why.to_string();
    Ok(plans)
}

#[cfg(feature = "tract")]
fn tract_with(
    prefilter: Option<&HologramModel>,
    height: usize,
    width: usize,
    plan: crate::model::ModelPlan,
    report: PlanReport,
) -> Result<CnnPlans> {
    let prefilter: Option<Box<dyn CnnPlan>> = match prefilter {
        Some(p) => {
            // The pre-filter always runs channels-first (PipelineConfig::cnn_layout), with the same threads.
            let plan = p.plan(height, width)?;
            Some(Box::new(match report.threads {
                Some(t) => plan.with_threads(t)?,
                None => plan,
            }))
        }
        None => None,
    };
    Ok(CnnPlans {
        hologram: Box::new(plan),
        prefilter,
        report,
    })
}

/// What [`tune_native`] chose: the thread count, the candidates' timings and the seconds the timing took.
struct NativeTuning {
    threads: usize,
    candidates: Vec<PlanTiming>,
    seconds: f64,
}

/// The native engine's thread count for `request`: timed among [`auto_thread_candidates`] for
/// [`ThreadCount::Auto`] (with the timings and the seconds spent), else the count asked for (1 for
/// [`ThreadCount::ProcessDefault`], tract's process-wide setting, which the native engine does not share).
/// A single count is timed only when `time_single` (to compare with tract).
fn tune_native(
    graph: &Arc<CnnWeights>,
    height: usize,
    width: usize,
    threads: ThreadCount,
    time_single: bool,
) -> Result<NativeTuning> {
    let counts = match threads {
        ThreadCount::Auto => auto_thread_candidates(),
        ThreadCount::Fixed(n) => vec![n],
        ThreadCount::ProcessDefault => vec![1],
    };
    if counts.len() == 1 && !time_single {
        return Ok(NativeTuning {
            threads: counts[0],
            candidates: Vec::new(),
            seconds: 0.0,
        });
    }
    let [th, tw] = timing_resolution(height, width);
    let start = Instant::now();
    let mut timings = Vec::new();
    let isa = active_isa()?;
    for &t in &counts {
        let (mut plan, _) = native_plan(graph.clone(), th, tw, t, isa)?;
        let s = time_plan(plan.as_mut(), graph.in_channels, th, tw)?;
        timings.push(PlanTiming {
            engine: CnnEngine::Native,
            layout: CnnLayout::ChannelsFirst,
            threads: Some(t),
            seconds: Some(s),
            skipped: None,
        });
    }
    let best = timings
        .iter()
        .min_by(|a, b| {
            a.seconds
                .unwrap_or(f64::INFINITY)
                .total_cmp(&b.seconds.unwrap_or(f64::INFINITY))
        })
        .and_then(|t| t.threads)
        .unwrap_or(1);
    Ok(NativeTuning {
        threads: best,
        candidates: timings,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Fastest wall-clock seconds of one run of `plan` on a constant `[c, h, w]` input (tract's rule,
/// [`fastest_run`]).
fn time_plan(plan: &mut dyn CnnPlan, c: usize, h: usize, w: usize) -> Result<f64> {
    let input = Array3::<f32>::from_elem((c, h, w), 0.5);
    fastest_run(|| {
        let t = Instant::now();
        plan.run_outputs(input.view())?;
        Ok(t.elapsed().as_secs_f64())
    })
}

/// Native plans for both CNNs at `[height, width]` on `tuning.threads` threads, reported with what was asked
/// (`request`), why (`why`), the timings and their cost.
fn native_plans(
    graph: &Arc<CnnWeights>,
    pre: Option<Arc<CnnWeights>>,
    [height, width]: [usize; 2],
    request: PlanRequest,
    why: &str,
    tuning: NativeTuning,
) -> Result<CnnPlans> {
    let isa = active_isa()?;
    let threads = tuning.threads;
    let (hologram, kernel) = native_plan(graph.clone(), height, width, threads, isa)?;
    let prefilter = match pre {
        Some(p) => Some(native_plan(p, height, width, threads, isa)?.0),
        None => None,
    };
    Ok(CnnPlans {
        report: PlanReport {
            resolution: [height, width],
            request,
            engine: CnnEngine::Native,
            engine_reason: why.to_string(),
            kernel: Some(kernel.to_string()),
            layout: CnnLayout::ChannelsFirst,
            threads: Some(threads),
            autotuned: tuning.candidates.len() > 1,
            timed_resolution: timing_resolution(height, width),
            candidates: tuning.candidates,
            tuning_s: tuning.seconds,
        },
        hologram,
        prefilter,
    })
}

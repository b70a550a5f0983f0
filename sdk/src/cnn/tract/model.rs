//! [`TractModel`]: tract's side of one model (cargo feature `tract`): its graph parsed, typed and decluttered
//! once with symbolic `H`, `W`, one optimised [`ModelPlan`] per resolution and layout, and the autotuning of
//! layouts × thread counts ([`TractModel::tuned_plan`]), cached per resolution and request.

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::Instant;

use ndarray::{Array3, ArrayView3};
use num_complex::Complex32;
use tract_onnx::prelude::{Framework, InferenceModelExt, IntoRunnable, Symbol, TDim, TypedModel};

use super::plan::{optimise, tract_msg, ModelPlan, PlanFailure};
use crate::cnn::options::{default_threads, CnnEngine, CnnLayout, CnnOptions, ThreadCount};
use crate::cnn::table;
use crate::cnn::tuning::{
    auto_thread_candidates, fastest_run, timing_resolution, PlanOrigin, PlanReport, PlanRequest,
    PlanTiming, NOT_TIMED, PLAUSIBLE_FACTOR,
};
use crate::error::{guarded, invalid, HoloError, Result};
use crate::model::network::check_fixed_size;
use crate::model::{contract, HologramModel, ModelKind};
use crate::scene::RgbdFrame;

/// tract's graph of one [`HologramModel`], typed and decluttered once, with its optimised plans per
/// resolution and layout and its autotuning results. `Send + Sync`: plans can be built and run from several
/// threads; a failed plan or run leaves it usable.
///
/// Sessions find it in the tract engine's cache (one per model, dropped with the model); [`TractModel::new`]
/// makes one of its own (e.g. to plan a layout or profile the operators).
pub struct TractModel {
    decluttered: TypedModel,
    /// Symbols of the input's height and width (`None` where the file fixes that dimension).
    dims: [Option<Symbol>; 2],
    plans: Mutex<HashMap<(usize, usize, CnnLayout), ModelPlan>>,
    tuned: Mutex<HashMap<(usize, usize, PlanRequest), PlanReport>>,
    kind: ModelKind,
    channels: usize,
    input_layers: usize,
    source_name: String,
    fixed: [Option<usize>; 2],
}

impl std::fmt::Debug for TractModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let plans = self.plans.lock().map(|p| p.len()).unwrap_or(0);
        f.debug_struct("TractModel")
            .field("source_name", &self.source_name)
            .field("nodes", &self.decluttered.nodes.len())
            .field("dims", &self.dims)
            .field("plans", &plans)
            .finish()
    }
}

impl TractModel {
    /// Parses, types and declutters `model`'s ONNX file with tract (the file was decoded and checked against
    /// the contract by [`HologramModel`]'s loader).
    ///
    /// Errors: [`HoloError::ModelLoad`] where tract cannot parse or type the graph (also a panic inside
    /// tract), [`HoloError::ModelContract`] for an input dimension that is neither a symbol nor a positive
    /// size.
    pub fn new(model: &HologramModel) -> Result<Self> {
        let source_name = model.source_name();
        let load_err = |reason: String| HoloError::ModelLoad {
            source_name: source_name.to_string(),
            reason,
        };
        let bytes = model.file_bytes();
        // Value infos are hints on intermediate tensors; tract 0.23 rejects the QDQ exporter's, and the
        // graph's own ops determine every type anyway.
        let onnx = tract_onnx::onnx().with_ignore_value_info(true);
        let decluttered = guarded("typing the graph", || {
            let proto = onnx
                .proto_model_for_read(&mut &bytes[..])
                .map_err(|e| format!("not a valid ONNX protobuf ({})", tract_msg(&e)))?;
            let model = onnx
                .model_for_proto_model(&proto)
                .map_err(|e| format!("cannot parse the graph: {}", tract_msg(&e)))?;
            model
                .into_typed()
                .and_then(|m| m.into_decluttered())
                .map_err(|e| format!("cannot type the graph: {}", tract_msg(&e)))
        })
        .map_err(load_err)?;
        let fact = decluttered
            .input_fact(0)
            .map_err(|e| load_err(tract_msg(&e)))?
            .clone();
        let mut dims = [None, None];
        for (i, d) in fact.shape.iter().skip(2).take(2).enumerate() {
            match d {
                TDim::Sym(s) => dims[i] = Some(s.clone()),
                _ => match d.to_i64() {
                    Ok(v) if v > 0 => {}
                    _ => {
                        return Err(HoloError::ModelContract {
                            source_name: source_name.to_string(),
                            reason: format!(
                                "input dimension {} is `{d}`, expected a symbol or a positive size",
                                i + 2
                            ),
                        })
                    }
                },
            }
        }
        Ok(Self {
            decluttered,
            dims,
            plans: Mutex::new(HashMap::new()),
            tuned: Mutex::new(HashMap::new()),
            kind: model.kind(),
            channels: model.input_channels(),
            input_layers: model.metadata().input_layers,
            source_name: source_name.to_string(),
            fixed: model.fixed_size(),
        })
    }

    /// Hologram CNN or pre-filter.
    pub fn kind(&self) -> ModelKind {
        self.kind
    }

    /// Channels of the network input `[C, H, W]`.
    pub(crate) fn input_channels(&self) -> usize {
        self.channels
    }

    /// The model file's name, as errors name it.
    pub(crate) fn source_name(&self) -> &str {
        &self.source_name
    }

    fn check_fixed_size(&self, height: usize, width: usize) -> Result<()> {
        check_fixed_size(&self.fixed, &self.source_name, height, width)
    }
    /// The resolutions planned so far, sorted (`[height, width]` pairs).
    pub fn planned_resolutions(&self) -> Vec<(usize, usize)> {
        let mut v: Vec<_> = self.lock().keys().map(|&(h, w, _)| (h, w)).collect();
        v.sort_unstable();
        v.dedup();
        v
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<(usize, usize, CnnLayout), ModelPlan>> {
        // No code panics while holding the lock; recover the map anyway rather than propagate poison.
        self.plans.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The runnable plan for `height × width` inputs, optimised for that resolution (the graph with `H`, `W`
    /// bound, then tract's codegen). Built on first use and cached inside the model; cheap afterwards
    /// (an `Arc` clone).
    ///
    /// Errors: [`HoloError::InvalidParameter`] for a zero size, [`HoloError::ShapeMismatch`] if the file
    /// fixes a different size, [`HoloError::ModelLoad`] if tract cannot optimise the graph at that size.
    pub fn plan(&self, height: usize, width: usize) -> Result<ModelPlan> {
        self.plan_with_layout(height, width, CnnLayout::ChannelsFirst)
    }

    /// As [`TractModel::plan`], run in `layout` (see [`CnnLayout`]); plans are cached per resolution and
    /// layout. Inputs and outputs of the returned plan stay `[C, H, W]` / `[3, H, W]` whatever the layout.
    /// [`CnnLayout::Auto`] is the plan table's layout on tract's process-wide executor (nothing timed;
    /// [`TractModel::tuned_plan`] with [`crate::cnn::PlanSource::Tune`] times both).
    ///
    /// Errors: as [`TractModel::plan`]; [`HoloError::InvalidParameter`] if tract cannot move this graph
    /// channels-last (int8 QOperator files: tract 0.23's quantised convolution takes no axis change).
    pub fn plan_with_layout(
        &self,
        height: usize,
        width: usize,
        layout: CnnLayout,
    ) -> Result<ModelPlan> {
        if layout == CnnLayout::Auto {
            let request = PlanRequest {
                cnn: CnnOptions {
                    layout,
                    threads: ThreadCount::ProcessDefault,
                    ..CnnOptions::default()
                },
                ..PlanRequest::default()
            };
            return self.tuned_plan(height, width, &request).map(|(p, _)| p);
        }
        if let Some(p) = self.lock().get(&(height, width, layout)) {
            return Ok(p.clone());
        }
        let plan = self.build_plan(height, width, layout)?;
        Ok(self
            .lock()
            .entry((height, width, layout))
            .or_insert(plan)
            .clone())
    }

    /// Builds (without caching) the plan for `height × width` in a concrete `layout`.
    fn build_plan(&self, height: usize, width: usize, layout: CnnLayout) -> Result<ModelPlan> {
        if height == 0 || width == 0 {
            return Err(crate::error::invalid(
                "height/width",
                format!("a CNN plan needs a non-empty resolution, got {height}×{width}"),
            ));
        }
        if layout == CnnLayout::Auto {
            return Err(HoloError::Internal(
                "build_plan needs a concrete layout".into(),
            ));
        }
        self.check_fixed_size(height, width)?;
        let subs: HashMap<Symbol, TDim> = self
            .dims
            .iter()
            .zip([height, width])
            .filter_map(|(s, n)| s.clone().map(|s| (s, TDim::Val(n as i64))))
            .collect();
        let plan = guarded("optimising", || {
            let model = self
                .decluttered
                .set_symbols(&subs)
                .map_err(|e| PlanFailure::Tract(tract_msg(&e)))?;
            optimise(model, layout)?
                .into_runnable()
                .map_err(|e| PlanFailure::Tract(tract_msg(&e)))
        })
        .map_err(|reason| match reason {
            PlanFailure::Layout(reason) => crate::error::invalid(
                "layout",
                format!("`{}` cannot run {layout}: {reason}", self.source_name()),
            ),
            PlanFailure::Tract(reason) => HoloError::ModelLoad {
                source_name: self.source_name().to_string(),
                reason: format!("cannot optimise for {height}×{width} ({layout}): {reason}"),
            },
        })?;
        Ok(ModelPlan {
            plan,
            kind: self.kind(),
            channels: self.input_channels(),
            height,
            width,
            layout,
            threads: None,
            executor: None,
        })
    }

    /// Runs the network on one input `[C, H, W]` (`C` = `TractModel::input_channels`; hologram CNN:
    /// per layer `r, g, b` amplitude then depth `d`, all in `[0, 1]`; pre-filter: `Re H` then `Im H` of the
    /// offset hologram), planning `H × W` if needed.
    ///
    /// Returns the complex field `[3, H, W]` (R, G, B): the midpoint hologram for the hologram CNN
    /// ([`crate::model::heads_to_field`]), the filtered SLM-plane hologram `Re + i·Im` for the pre-filter.
    ///
    /// Errors: as [`TractModel::plan`] and [`ModelPlan::run`].
    pub fn run(&self, input: ArrayView3<f32>) -> Result<Array3<Complex32>> {
        let (_, h, w) = input.dim();
        self.plan(h, w)?.run(input)
    }

    /// Runs a hologram CNN with RGB-D input (`L = 1`) on a frame: input `[r, g, b, d]` from the frame's
    /// linear amplitude `[3, H, W]` and normalised depth `[H, W]` (0 = near). Returns the midpoint hologram
    /// `[3, H, W]`.
    ///
    /// Errors: [`HoloError::InvalidParameter`] if the model is a pre-filter or takes `L ≠ 1` layers; as
    /// [`TractModel::run`] otherwise.
    pub fn run_frame(&self, frame: &RgbdFrame) -> Result<Array3<Complex32>> {
        if self.kind() != ModelKind::Hologram || self.input_layers != 1 {
            return Err(crate::error::invalid(
                "model",
                format!(
                    "run_frame needs an RGB-D hologram CNN (L = 1); this file is a {} with L = {}",
                    self.kind(),
                    self.input_layers
                ),
            ));
        }
        let mut input = Array3::<f32>::zeros((4, frame.height(), frame.width()));
        contract::pack_rgbd(frame, input.view_mut())?;
        self.run(input.view())
    }

    /// The plan of `request` for `height × width` inputs, and the report of how it was chosen: the plan
    /// table's layout and threads for `Auto` ([`crate::cnn::PlanSource::Table`] or `Saved`: nothing timed), or
    /// with [`crate::cnn::PlanSource::Tune`] the fastest candidate.
    ///
    /// Every candidate (layouts × thread counts; a layout tract cannot apply to this graph is skipped with
    /// the reason) runs on a constant input at the timing resolution (the frame, or a full-width strip of a frame above
    /// 64 Ki pixels): once, or three times when a run takes
    /// under 0.25 s (the fastest run counts). The winner's plan is then built at the real resolution (cached
    /// like [`TractModel::plan_with_layout`]'s) with its thread count (`ModelPlan::with_threads`).
    /// With a single candidate nothing is timed. Results are cached per `(height, width, request)`.
    ///
    /// Errors: as [`TractModel::plan_with_layout`] and `ModelPlan::with_threads`;
    /// [`HoloError::InvalidParameter`] if no candidate can run.
    pub fn tuned_plan(
        &self,
        height: usize,
        width: usize,
        request: &PlanRequest,
    ) -> Result<(ModelPlan, PlanReport)> {
        let report = self.tuning(height, width, request, None)?;
        let plan = self.plan_with_layout(height, width, report.layout)?;
        let plan = match report.threads {
            Some(t) => plan.with_threads(t)?,
            None => plan,
        };
        Ok((plan, report))
    }

    /// How [`TractModel::tuned_plan`] chooses, without building the chosen plan at the real resolution (the
    /// engine choice builds it only if tract wins). `to_beat`: the best seconds of another engine on the same
    /// input; the likeliest candidate (the most threads, the first layout) is timed first, and the others
    /// are skipped, with the reason, when it takes over [`PLAUSIBLE_FACTOR`] times as long. A report with
    /// skipped candidates is not cached.
    ///
    /// Errors: as [`TractModel::tuned_plan`].
    pub(crate) fn tuning(
        &self,
        height: usize,
        width: usize,
        request: &PlanRequest,
        to_beat: Option<f64>,
    ) -> Result<PlanReport> {
        if height == 0 || width == 0 {
            return Err(invalid(
                "height/width",
                format!("a CNN plan needs a non-empty resolution, got {height}×{width}"),
            ));
        }
        self.check_fixed_size(height, width)?;
        let key = (height, width, request.clone());
        if let Some(mut r) = self.tuned_lock().get(&key).cloned() {
            r.tuning_s = 0.0;
            return Ok(r);
        }
        let r = self.tune(height, width, request, to_beat)?;
        if r.autotuned {
            log::info!(
                "CNN plan for {height}×{width}: {} with {} thread(s), chosen in {:.2} s from {}",
                r.layout,
                r.threads.map_or("default".into(), |t| t.to_string()),
                r.tuning_s,
                r.candidates
                    .iter()
                    .map(|c| format!(
                        "{}/{}: {}",
                        c.layout,
                        c.threads.map_or("default".into(), |t| t.to_string()),
                        c.seconds
                            .map_or("skipped".into(), |s| format!("{:.1} ms", s * 1e3))
                    ))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
        let pruned = r.candidates.iter().any(|c| {
            c.skipped
                .as_deref()
                .is_some_and(|s| s.starts_with(NOT_TIMED))
        });
        if !pruned {
            self.tuned_lock().insert(key, r.clone());
        }
        Ok(r)
    }

    fn tuned_lock(
        &self,
    ) -> std::sync::MutexGuard<'_, HashMap<(usize, usize, PlanRequest), PlanReport>> {
        // Nothing panics while holding the lock; recover the map rather than propagate poison.
        self.tuned.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn tune(
        &self,
        height: usize,
        width: usize,
        request: &PlanRequest,
        to_beat: Option<f64>,
    ) -> Result<PlanReport> {
        let tunes = request.source.tunes();
        let layouts: Vec<CnnLayout> = match request.cnn.layout {
            CnnLayout::Auto if tunes => CnnLayout::ALL.to_vec(),
            CnnLayout::Auto => vec![self.table_layout(height, width)?],
            l => vec![l],
        };
        // The most threads first: the likeliest winner, timed before any early stop (`to_beat`).
        let threads: Vec<Option<usize>> = match request.cnn.threads {
            ThreadCount::Auto if tunes => auto_thread_candidates()
                .into_iter()
                .rev()
                .map(Some)
                .collect(),
            ThreadCount::Auto => vec![Some(default_threads())],
            ThreadCount::Fixed(n) => vec![Some(n)],
            ThreadCount::ProcessDefault => vec![None],
        };
        let timed_resolution = timing_resolution(height, width);
        if layouts.len() * threads.len() == 1 {
            return Ok(self.report(
                [height, width],
                request,
                (layouts[0], threads[0]),
                Vec::new(),
                0.0,
            ));
        }
        let start = Instant::now();
        let [th, tw] = timed_resolution;
        let input = Array3::<f32>::from_elem((self.input_channels(), th, tw), 0.5);
        let mut candidates = Vec::new();
        for &layout in &layouts {
            let base = if [th, tw] == [height, width] {
                self.plan_with_layout(height, width, layout)
            } else {
                self.build_plan(th, tw, layout)
            };
            let base = match base {
                Ok(p) => p,
                Err(HoloError::InvalidParameter {
                    name: "layout",
                    reason,
                }) => {
                    candidates.extend(threads.iter().map(|&t| PlanTiming {
                        engine: CnnEngine::Tract,
                        layout,
                        threads: t,
                        seconds: None,
                        skipped: Some(reason.clone()),
                    }));
                    continue;
                }
                Err(e) => return Err(e),
            };
            for &t in &threads {
                let plan = match t {
                    Some(n) => base.with_threads(n)?,
                    None => base.clone(),
                };
                let best = fastest_run(|| time_run(&plan, &input))?;
                candidates.push(PlanTiming {
                    engine: CnnEngine::Tract,
                    layout,
                    threads: t,
                    seconds: Some(best),
                    skipped: None,
                });
                if let Some(other) = to_beat.filter(|&o| best > o * PLAUSIBLE_FACTOR) {
                    let reason = format!(
                        "{NOT_TIMED}: {layout}/{} took {:.1} ms, over {PLAUSIBLE_FACTOR}× another engine's {:.1} ms",
                        t.map_or("default".into(), |n| n.to_string()),
                        best * 1e3,
                        other * 1e3
                    );
                    for &l in &layouts {
                        for &u in &threads {
                            if !candidates.iter().any(|c| c.layout == l && c.threads == u) {
                                candidates.push(PlanTiming {
                                    engine: CnnEngine::Tract,
                                    layout: l,
                                    threads: u,
                                    seconds: None,
                                    skipped: Some(reason.clone()),
                                });
                            }
                        }
                    }
                    break;
                }
            }
            if candidates.len() == layouts.len() * threads.len() {
                break;
            }
        }
        let best = candidates
            .iter()
            .filter_map(|c| c.seconds.map(|s| (s, c)))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, c)| (c.layout, c.threads))
            .ok_or_else(|| {
                invalid(
                    "layout",
                    format!(
                        "no CNN plan candidate can run `{}`: {:?}",
                        self.source_name(),
                        candidates
                    ),
                )
            })?;
        Ok(self.report(
            [height, width],
            request,
            best,
            candidates,
            start.elapsed().as_secs_f64(),
        ))
    }

    /// The plan table's layout for this graph: [`table::tract_layout`], or channels-first where tract cannot
    /// move this graph channels-last (int8 QOperator files). Errors: as [`TractModel::plan_with_layout`].
    fn table_layout(&self, height: usize, width: usize) -> Result<CnnLayout> {
        let layout = table::tract_layout();
        if layout == CnnLayout::ChannelsFirst {
            return Ok(layout);
        }
        match self.plan_with_layout(height, width, layout) {
            Ok(_) => Ok(layout),
            Err(HoloError::InvalidParameter { name: "layout", .. }) => Ok(CnnLayout::ChannelsFirst),
            Err(e) => Err(e),
        }
    }

    /// The report of tract's choice `(layout, threads)` for `request` at `resolution` among `candidates`
    /// (timed in `tuning_s` seconds; none when nothing was timed).
    fn report(
        &self,
        resolution: [usize; 2],
        request: &PlanRequest,
        (layout, threads): (CnnLayout, Option<usize>),
        candidates: Vec<PlanTiming>,
        tuning_s: f64,
    ) -> PlanReport {
        let autotuned = !candidates.is_empty();
        PlanReport {
            resolution,
            request: request.clone(),
            engine: CnnEngine::Tract,
            engine_reason: "tract's plan".into(),
            kernel: None,
            layout,
            threads,
            autotuned,
            timed_resolution: timing_resolution(resolution[0], resolution[1]),
            candidates,
            tuning_s,
            source: if autotuned {
                PlanOrigin::Tuned
            } else {
                PlanOrigin::Table
            },
            source_detail: String::new(),
            network: self.source_name().to_string(),
            isa: String::new(),
            rows: Vec::new(),
        }
    }
}

/// Seconds of one run of `plan` on `input`.
fn time_run(plan: &ModelPlan, input: &Array3<f32>) -> Result<f64> {
    let t = Instant::now();
    plan.run_outputs(input.view())?;
    Ok(t.elapsed().as_secs_f64())
}

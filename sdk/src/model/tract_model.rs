//! The tract engine's methods of a [`HologramModel`] (cargo feature `tract`): its plans per resolution and
//! layout ([`HologramModel::plan`], [`HologramModel::tuned_plan`]), tract's autotuning and runs. The graph and
//! the plans themselves are `model/tract.rs`, which does not know the model: this file ties the two, so that
//! neither imports the other in a circle.

use std::collections::HashMap;
use std::time::Instant;

use ndarray::{Array3, ArrayView3};
use num_complex::Complex32;
use tract_onnx::prelude::{IntoRunnable, Symbol, TDim};

use super::metadata::ModelKind;
use super::tract::{optimise, tract_msg, PlanFailure};
use super::tuning::{auto_thread_candidates, fastest_run, timing_resolution};
use super::{
    CnnEngine, CnnLayout, HologramModel, ModelPlan, PlanReport, PlanRequest, PlanTiming,
    ThreadCount,
};
use crate::error::{guarded, invalid, HoloError, Result};
use crate::scene::RgbdFrame;

impl HologramModel {
    /// The resolutions planned so far, sorted (`[height, width]` pairs).
    pub fn planned_resolutions(&self) -> Vec<(usize, usize)> {
        let mut v: Vec<_> = self.lock().keys().map(|&(h, w, _)| (h, w)).collect();
        v.sort_unstable();
        v.dedup();
        v
    }

    pub(super) fn lock(
        &self,
    ) -> std::sync::MutexGuard<'_, HashMap<(usize, usize, CnnLayout), ModelPlan>> {
        // No code panics while holding the lock; recover the map anyway rather than propagate poison.
        self.tract.plans.lock().unwrap_or_else(|p| p.into_inner())
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

    /// As [`HologramModel::plan`], run in `layout` (see [`CnnLayout`]); plans are cached per resolution and
    /// layout. Inputs and outputs of the returned plan stay `[C, H, W]` / `[3, H, W]` whatever the layout.
    /// [`CnnLayout::Auto`] times both layouts with tract's process-wide executor and returns the faster
    /// ([`HologramModel::tuned_plan`], which also reports the timings).
    ///
    /// Errors: as [`HologramModel::plan`]; [`HoloError::InvalidParameter`] if tract cannot move this graph
    /// channels-last (int8 QOperator files: tract 0.23's quantised convolution takes no axis change).
    pub fn plan_with_layout(
        &self,
        height: usize,
        width: usize,
        layout: CnnLayout,
    ) -> Result<ModelPlan> {
        if layout == CnnLayout::Auto {
            let request = super::PlanRequest {
                layout,
                threads: super::ThreadCount::ProcessDefault,
            };
            return self.tuned_plan(height, width, request).map(|(p, _)| p);
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
    pub(super) fn build_plan(
        &self,
        height: usize,
        width: usize,
        layout: CnnLayout,
    ) -> Result<ModelPlan> {
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
            .tract
            .dims
            .iter()
            .zip([height, width])
            .filter_map(|(s, n)| s.clone().map(|s| (s, TDim::Val(n as i64))))
            .collect();
        let plan = guarded("optimising", || {
            let model = self
                .tract
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

    /// Runs the network on one input `[C, H, W]` (`C` = [`HologramModel::input_channels`]; hologram CNN:
    /// per layer `r, g, b` amplitude then depth `d`, all in `[0, 1]`; pre-filter: `Re H` then `Im H` of the
    /// offset hologram), planning `H × W` if needed.
    ///
    /// Returns the complex field `[3, H, W]` (R, G, B): the midpoint hologram for the hologram CNN
    /// ([`heads_to_field`](super::heads_to_field)), the filtered SLM-plane hologram `Re + i·Im` for the pre-filter.
    ///
    /// Errors: as [`HologramModel::plan`] and [`ModelPlan::run`].
    pub fn run(&self, input: ArrayView3<f32>) -> Result<Array3<Complex32>> {
        let (_, h, w) = input.dim();
        self.plan(h, w)?.run(input)
    }

    /// Runs a hologram CNN with RGB-D input (`L = 1`) on a frame: input `[r, g, b, d]` from the frame's
    /// linear amplitude `[3, H, W]` and normalised depth `[H, W]` (0 = near). Returns the midpoint hologram
    /// `[3, H, W]`.
    ///
    /// Errors: [`HoloError::InvalidParameter`] if the model is a pre-filter or takes `L ≠ 1` layers; as
    /// [`HologramModel::run`] otherwise.
    pub fn run_frame(&self, frame: &RgbdFrame) -> Result<Array3<Complex32>> {
        if self.kind() != ModelKind::Hologram || self.metadata().input_layers != 1 {
            return Err(crate::error::invalid(
                "model",
                format!(
                    "run_frame needs an RGB-D hologram CNN (L = 1); this file is a {} with L = {}",
                    self.kind(),
                    self.metadata().input_layers
                ),
            ));
        }
        let mut input = Array3::<f32>::zeros((4, frame.height(), frame.width()));
        super::contract::pack_rgbd(frame, input.view_mut())?;
        self.run(input.view())
    }
}

impl HologramModel {
    /// The fastest plan of `request` for `height × width` inputs, and the report of how it was chosen.
    ///
    /// Every candidate (layouts × thread counts; a layout tract cannot apply to this graph is skipped with
    /// the reason) runs on a constant input at [`timing_resolution`]: once, or three times when a run takes
    /// under 0.25 s (the fastest run counts). The winner's plan is then built at the real resolution (cached
    /// like [`HologramModel::plan_with_layout`]'s) with its thread count ([`ModelPlan::with_threads`]).
    /// With a single candidate nothing is timed. Results are cached per `(height, width, request)`.
    ///
    /// Errors: as [`HologramModel::plan_with_layout`] and [`ModelPlan::with_threads`];
    /// [`HoloError::InvalidParameter`] if no candidate can run.
    pub fn tuned_plan(
        &self,
        height: usize,
        width: usize,
        request: PlanRequest,
    ) -> Result<(ModelPlan, PlanReport)> {
        if height == 0 || width == 0 {
            return Err(invalid(
                "height/width",
                format!("a CNN plan needs a non-empty resolution, got {height}×{width}"),
            ));
        }
        self.check_fixed_size(height, width)?;
        let key = (height, width, request);
        let cached = self.tuned_lock().get(&key).cloned();
        let report = match cached {
            Some(mut r) => {
                r.tuning_s = 0.0;
                r
            }
            None => {
                let r = self.tune(height, width, request)?;
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
                self.tuned_lock().insert(key, r.clone());
                r
            }
        };
        let plan = self.plan_with_layout(height, width, report.layout)?;
        let plan = match report.threads {
            Some(t) => plan.with_threads(t)?,
            None => plan,
        };
        Ok((plan, report))
    }

    fn tuned_lock(
        &self,
    ) -> std::sync::MutexGuard<'_, std::collections::HashMap<(usize, usize, PlanRequest), PlanReport>>
    {
        // Nothing panics while holding the lock; recover the map rather than propagate poison.
        self.tuned.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn tune(&self, height: usize, width: usize, request: PlanRequest) -> Result<PlanReport> {
        let layouts: Vec<CnnLayout> = match request.layout {
            CnnLayout::Auto => CnnLayout::ALL.to_vec(),
            l => vec![l],
        };
        let threads: Vec<Option<usize>> = match request.threads {
            ThreadCount::Auto => auto_thread_candidates().into_iter().map(Some).collect(),
            ThreadCount::Fixed(n) => vec![Some(n)],
            ThreadCount::ProcessDefault => vec![None],
        };
        let timed_resolution = timing_resolution(height, width);
        if layouts.len() * threads.len() == 1 {
            return Ok(PlanReport {
                resolution: [height, width],
                request,
                engine: CnnEngine::Tract,
                engine_reason: "tract's plan".into(),
                kernel: None,
                layout: layouts[0],
                threads: threads[0],
                autotuned: false,
                timed_resolution,
                candidates: Vec::new(),
                tuning_s: 0.0,
            });
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
        Ok(PlanReport {
            resolution: [height, width],
            request,
            engine: CnnEngine::Tract,
            engine_reason: "tract's plan".into(),
            kernel: None,
            layout: best.0,
            threads: best.1,
            autotuned: true,
            timed_resolution,
            candidates,
            tuning_s: start.elapsed().as_secs_f64(),
        })
    }
}

/// Seconds of one run of `plan` on `input`.
fn time_run(plan: &ModelPlan, input: &Array3<f32>) -> Result<f64> {
    let t = Instant::now();
    plan.run_outputs(input.view())?;
    Ok(t.elapsed().as_secs_f64())
}

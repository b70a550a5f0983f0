//! tract's plans: [`ModelPlan`] (one model's graph optimised for one resolution and layout, a
//! [`CnnPlan`] of the session's CNN stage), how a graph is optimised for a layout, per-operator profiling
//! ([`NodeTiming`]).

use std::sync::Arc;

use ndarray::{Array3, ArrayView3, Zip};
use num_complex::Complex32;
use tract_linalg::multithread::{multithread_tract_scope, Executor};
use tract_onnx::prelude::{tvec, IntoTValue, Tensor, TypedModel, TypedSimplePlan};

use crate::cnn::options::{CnnLayout, MAX_CNN_THREADS};
use crate::cnn::plan::CnnPlan;
use crate::error::{guarded, HoloError, Result};
use crate::model::{heads_to_field, ModelKind};

/// Formats a tract error with its whole context chain on one line.
pub(super) fn tract_msg(e: &tract_onnx::prelude::TractError) -> String {
    format!("{e:#}")
}

/// Why [`optimise`] failed: the requested layout does not apply to the graph, or tract failed.
pub(super) enum PlanFailure {
    Layout(String),
    Tract(String),
}

impl From<String> for PlanFailure {
    fn from(reason: String) -> Self {
        Self::Tract(reason)
    }
}

/// Optimises a graph whose `H`, `W` are bound, for `layout` (see [`CnnLayout`]).
///
/// Channels-last: after tract's declutter, the axis change `Move(1, 3)` is applied at the input and
/// propagated through the whole graph with tract's own `change_axes` (convolutions switch to NHWC, the
/// element-wise ops, concatenations and slices follow, the outputs become `[1, H, W, 3]`); then tract
/// declutters again (the interfaces are locked, so nothing moves back) and generates code. It fails if any
/// operator refuses the change.
pub(super) fn optimise(
    mut model: TypedModel,
    layout: CnnLayout,
) -> std::result::Result<TypedModel, PlanFailure> {
    use tract_onnx::tract_core::ops::change_axes::{AxisChange, AxisOp};
    let tract = |e: tract_onnx::prelude::TractError| PlanFailure::Tract(tract_msg(&e));
    if layout == CnnLayout::ChannelsLast {
        model.declutter().map_err(tract)?;
        let input = model.input_outlets().map_err(tract)?[0];
        if model.outlet_fact(input).map_err(tract)?.rank() != 4 {
            return Err(PlanFailure::Layout("the input is not [1, C, H, W]".into()));
        }
        let change = AxisChange {
            outlet: input,
            op: AxisOp::Move(1, 3),
        };
        let mut explored = Default::default();
        let (patch, _) = tract_onnx::tract_core::optim::change_axes::change_axes(
            &model,
            &change,
            &[],
            &[],
            &mut explored,
        )
        .map_err(tract)?
        .ok_or_else(|| {
            PlanFailure::Layout(
                "an operator of the graph refuses the channels-last axis change (with tract 0.23: \
                 the quantised convolutions of QOperator int8 files, and the pre-filter CNN's graph; \
                 such files run channels-first only)"
                    .into(),
            )
        })?;
        patch.apply(&mut model).map_err(tract)?;
    }
    model.into_optimized().map_err(tract)
}

/// Wall-clock time of one operator of a [`ModelPlan`] in one run ([`ModelPlan::profile`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct NodeTiming {
    /// The node's name in the optimised graph (derived from the ONNX node names).
    pub node: String,
    /// tract's operator after optimisation, e.g. `DirectSpatialConv`, `LazyIm2col`, `OptMatMul`.
    pub op: String,
    /// Seconds spent evaluating it.
    pub seconds: f64,
}

/// A tract plan for one resolution of a model ([`super::TractModel::plan`]: the graph with `H`, `W` bound and
/// optimised).
///
/// Cloning is cheap (shared plan and thread pool). Each [`ModelPlan::run`] spawns its own tract state, so one
/// plan may run from several threads.
#[derive(Debug, Clone)]
pub struct ModelPlan {
    pub(super) plan: Arc<TypedSimplePlan>,
    pub(super) kind: ModelKind,
    pub(super) channels: usize,
    pub(super) height: usize,
    pub(super) width: usize,
    pub(super) layout: CnnLayout,
    /// Threads of this plan's own executor; `None`: tract's process-wide default executor (one thread).
    pub(super) threads: Option<usize>,
    pub(super) executor: Option<Executor>,
}

impl ModelPlan {
    /// This plan running its matrix products and convolutions on `threads` threads of its own (a private
    /// pool for `threads > 1`, the calling thread for 1), whatever tract's process-wide default is.
    ///
    /// Errors: [`HoloError::InvalidParameter`] for 0 threads or more than [`MAX_CNN_THREADS`], or if the
    /// operating system refuses to start the threads.
    pub(crate) fn with_threads(&self, threads: usize) -> Result<ModelPlan> {
        let executor = match threads {
            0 => {
                return Err(crate::error::invalid(
                    "threads",
                    "a plan needs at least 1 thread (0 = automatic is resolved by autotuning)",
                ))
            }
            1 => Executor::SingleThread,
            n if n > MAX_CNN_THREADS => {
                return Err(crate::error::invalid(
                    "threads",
                    format!("at most {MAX_CNN_THREADS} CNN threads, got {n}"),
                ))
            }
            n => {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .thread_name(|i| format!("tensorholo-cnn-{i}"))
                    .build()
                    .map_err(|e| {
                        crate::error::invalid("threads", format!("cannot start {n} threads: {e}"))
                    })?;
                Executor::MultiThread(Arc::new(pool))
            }
        };
        Ok(ModelPlan {
            threads: Some(threads),
            executor: Some(executor),
            ..self.clone()
        })
    }

    /// The threads of this plan's own executor (`ModelPlan::with_threads`); `None` when it uses tract's
    /// process-wide default.
    pub fn threads(&self) -> Option<usize> {
        self.threads
    }

    /// Runs `f` with this plan's executor as tract's executor on the calling thread.
    fn scoped<R>(&self, f: impl FnOnce() -> R) -> R {
        match &self.executor {
            Some(e) => multithread_tract_scope(e.clone(), f),
            None => f(),
        }
    }

    /// The memory layout tract runs this plan in.
    pub fn layout(&self) -> CnnLayout {
        self.layout
    }

    /// `(channels, height, width)` of the input this plan accepts.
    pub fn input_dim(&self) -> (usize, usize, usize) {
        (self.channels, self.height, self.width)
    }

    /// Which CNN this plan runs.
    pub fn kind(&self) -> ModelKind {
        self.kind
    }

    /// Checks `input` `[C, H, W]` against this plan (shape, finite values) and copies it into the
    /// `[1, C, H, W]` tensor tract takes.
    fn input_tensor(&self, input: ArrayView3<f32>) -> Result<Tensor> {
        let want = [self.channels, self.height, self.width];
        if input.shape() != want {
            return Err(HoloError::ShapeMismatch {
                what: format!("{} input [C, H, W] vs the plan's", self.kind),
                expected: want.to_vec(),
                got: input.shape().to_vec(),
            });
        }
        if input.iter().any(|v| !v.is_finite()) {
            return Err(HoloError::InvalidData(format!(
                "{} input holds NaN or infinite values",
                self.kind
            )));
        }
        let (data, shape): (Vec<f32>, _) = match self.layout {
            CnnLayout::ChannelsFirst | CnnLayout::Auto => (
                input.iter().copied().collect(),
                [1, self.channels, self.height, self.width],
            ),
            CnnLayout::ChannelsLast => (
                input.permuted_axes([1, 2, 0]).iter().copied().collect(),
                [1, self.height, self.width, self.channels],
            ),
        };
        Tensor::from_shape(&shape, &data).map_err(|e| HoloError::ModelRun(tract_msg(&e)))
    }

    /// The operators of this plan after tract's optimisation, in evaluation order: `(node name, operator
    /// name)`, e.g. `("conv_3", "DirectSpatialConv")`: which convolution algorithm tract chose.
    pub fn operators(&self) -> Vec<(String, String)> {
        let model = self.plan.model();
        self.plan
            .order_without_consts()
            .iter()
            .map(|&id| {
                let n = &model.nodes[id];
                (n.name.clone(), n.op().name().to_string())
            })
            .collect()
    }

    /// Runs the network once on `input` `[C, H, W]` and times every operator: one [`NodeTiming`] per
    /// evaluated node, in evaluation order (wall-clock seconds of the node's `eval`, including the work
    /// it hands to tract's thread pool). `holo bench --profile` sums them per operator.
    ///
    /// Errors: as [`ModelPlan::run_outputs`].
    pub fn profile(&self, input: ArrayView3<f32>) -> Result<Vec<NodeTiming>> {
        let tensor = self.input_tensor(input)?;
        let mut timings = Vec::new();
        guarded("profiling", || {
            let mut state = self.plan.spawn().map_err(|e| tract_msg(&e))?;
            self.scoped(|| {
                state.run_plan_with_eval(
                    tvec!(tensor.into_tvalue()),
                    |ctx, op_state, node, inputs| {
                        let start = std::time::Instant::now();
                        let out = tract_onnx::tract_core::plan::eval(ctx, op_state, node, inputs);
                        timings.push(NodeTiming {
                            node: node.name.clone(),
                            op: node.op().name().to_string(),
                            seconds: start.elapsed().as_secs_f64(),
                        });
                        out
                    },
                )
            })
            .map(drop)
            .map_err(|e| tract_msg(&e))
        })
        .map_err(HoloError::ModelRun)?;
        Ok(timings)
    }

    /// Runs the network on `input` `[C, H, W]` and returns its two outputs, each `[3, H, W]`, in the
    /// contract's order (`docs/CONVENTIONS.md` §7, [`ModelKind::output_names`]): for a hologram CNN the heads
    /// `(amplitude, phase)`, amplitude in `[0, √2]`, phase in `[0, 1]` meaning `(p − 0.5)·2π` rad; for a
    /// pre-filter `(real, imag)` of the filtered SLM-plane field.
    ///
    /// Errors: [`HoloError::ShapeMismatch`] if `input` is not this plan's `[C, H, W]`;
    /// [`HoloError::InvalidData`] if it holds NaN/∞; [`HoloError::ModelRun`] if tract fails or returns
    /// outputs of an unexpected type or shape.
    pub fn run_outputs(&self, input: ArrayView3<f32>) -> Result<(Array3<f32>, Array3<f32>)> {
        let tensor = self.input_tensor(input)?;
        let outputs = guarded("running", || {
            self.scoped(|| self.plan.run(tvec!(tensor.into_tvalue())))
                .map_err(|e| tract_msg(&e))
        })
        .map_err(HoloError::ModelRun)?;
        if outputs.len() != 2 {
            return Err(HoloError::ModelRun(format!(
                "expected 2 outputs, got {}",
                outputs.len()
            )));
        }
        let shape = (3, self.height, self.width);
        let names = self.kind.output_names();
        let head = |i: usize| -> Result<Array3<f32>> {
            let t = &outputs[i];
            let got = t.shape().to_vec();
            let slice = t
                .try_as_plain_ram()
                .and_then(|v| v.as_slice::<f32>().map(<[f32]>::to_vec))
                .map_err(|e| {
                    HoloError::ModelRun(format!("output `{}`: {}", names[i], tract_msg(&e)))
                })?;
            let want = match self.layout {
                CnnLayout::ChannelsFirst | CnnLayout::Auto => [1, 3, self.height, self.width],
                CnnLayout::ChannelsLast => [1, self.height, self.width, 3],
            };
            if got != want {
                return Err(HoloError::ShapeMismatch {
                    what: format!("output `{}` ({} layout)", names[i], self.layout),
                    expected: want.to_vec(),
                    got,
                });
            }
            match self.layout {
                CnnLayout::ChannelsFirst | CnnLayout::Auto => Array3::from_shape_vec(shape, slice),
                CnnLayout::ChannelsLast => {
                    Array3::from_shape_vec((self.height, self.width, 3), slice)
                        .map(|a| a.permuted_axes([2, 0, 1]).as_standard_layout().into_owned())
                }
            }
            .map_err(|e| HoloError::ModelRun(e.to_string()))
        };
        Ok((head(0)?, head(1)?))
    }

    /// Runs the network on `input` `[C, H, W]` and returns its output as the complex field `[3, H, W]`: the
    /// midpoint hologram for a hologram CNN ([`heads_to_field`]), the filtered SLM-plane hologram
    /// `Re + i·Im` for a pre-filter. Errors: as [`ModelPlan::run_outputs`].
    pub fn run(&self, input: ArrayView3<f32>) -> Result<Array3<Complex32>> {
        let (a, b) = self.run_outputs(input)?;
        match self.kind {
            ModelKind::Hologram => heads_to_field(a.view(), b.view()),
            ModelKind::PreFilter => {
                let mut out = Array3::<Complex32>::zeros(a.raw_dim());
                Zip::from(&mut out)
                    .and(&a)
                    .and(&b)
                    .for_each(|o, &re, &im| *o = Complex32::new(re, im));
                Ok(out)
            }
        }
    }
}

impl CnnPlan for ModelPlan {
    fn input_dim(&self) -> (usize, usize, usize) {
        ModelPlan::input_dim(self)
    }

    fn run_outputs(&mut self, input: ArrayView3<f32>) -> Result<(Array3<f32>, Array3<f32>)> {
        ModelPlan::run_outputs(self, input)
    }

    fn spawn(&self) -> Box<dyn CnnPlan> {
        // A tract plan is an `Arc` of the optimised graph: a clone shares it, and each run makes its state.
        Box::new(self.clone())
    }
}

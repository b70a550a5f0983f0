//! [`HologramModel`]: one ONNX CNN loaded with tract, checked against the I/O contract and metadata of
//! `docs/CONVENTIONS.md` §7, with one optimised [`ModelPlan`] per resolution.

use std::collections::{BTreeMap, HashMap};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use std::sync::{Arc, Mutex};

use ndarray::{Array3, ArrayView3, Zip};
use num_complex::Complex32;
use tract_onnx::pb;
use tract_onnx::prelude::{
    tvec, Framework, InferenceModelExt, IntoRunnable, IntoTValue, Symbol, TDim, Tensor, TypedModel,
    TypedSimplePlan,
};

use super::contract::heads_to_field;
use super::metadata::{ModelConfig, ModelKind, ModelMetadata};
use super::CnnLayout;
use tract_linalg::multithread::{multithread_tract_scope, Executor};

/// The most threads a CNN plan may use ([`ModelPlan::with_threads`]): far above any phone or desktop core
/// count, low enough that a typo cannot ask the OS for a hundred thousand threads.
pub const MAX_CNN_THREADS: usize = 256;
use crate::error::{HoloError, Result};
use crate::scene::RgbdFrame;

/// ONNX `TensorProto.DataType.FLOAT`.
const ONNX_FLOAT: i32 = 1;

/// Formats a tract error with its whole context chain on one line.
fn tract_msg(e: &tract_onnx::prelude::TractError) -> String {
    format!("{e:#}")
}

/// Runs `f`, turning a panic inside tract into an error (a corrupt file must never panic the caller).
fn guarded<T, E: From<String>>(
    what: &str,
    f: impl FnOnce() -> std::result::Result<T, E>,
) -> std::result::Result<T, E> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(p) => {
            let msg = p
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "unknown panic".into());
            Err(E::from(format!("{what} panicked: {msg}")))
        }
    }
}

/// Why [`optimise`] failed: the requested layout does not apply to the graph, or tract failed.
enum PlanFailure {
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
fn optimise(
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

/// One dimension of a graph input/output as written in the file.
#[derive(Debug, Clone, PartialEq)]
enum Dim {
    Fixed(i64),
    Named(String),
    Unknown,
}

impl std::fmt::Display for Dim {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Dim::Fixed(v) => write!(f, "{v}"),
            Dim::Named(s) => f.write_str(s),
            Dim::Unknown => f.write_str("?"),
        }
    }
}

/// `(elem_type, dims)` of a graph value; `None` when the file gives no tensor type or shape.
fn value_type(v: &pb::ValueInfoProto) -> Option<(i32, Vec<Dim>)> {
    use pb::tensor_shape_proto::dimension::Value;
    use pb::type_proto::Value as TypeValue;
    // `TensorType` is the only variant tract's protobuf knows; sequences/maps decode as `None`.
    let TypeValue::TensorType(t) = v.r#type.as_ref()?.value.as_ref()?;
    let dims = t
        .shape
        .as_ref()?
        .dim
        .iter()
        .map(|d| match &d.value {
            Some(Value::DimValue(v)) => Dim::Fixed(*v),
            Some(Value::DimParam(s)) if !s.is_empty() => Dim::Named(s.clone()),
            _ => Dim::Unknown,
        })
        .collect();
    Some((t.elem_type, dims))
}

fn dims_str(d: &[Dim]) -> String {
    let parts: Vec<String> = d.iter().map(Dim::to_string).collect();
    format!("[{}]", parts.join(","))
}

/// Checks one graph value is f32 `[1, channels, H, W]` (H, W named, fixed or unknown).
fn check_value(
    v: &pb::ValueInfoProto,
    role: &str,
    channels: usize,
) -> std::result::Result<(), String> {
    let want = format!("f32 [1,{channels},H,W]");
    let (elem, dims) = value_type(v)
        .ok_or_else(|| format!("{role} `{}` has no tensor shape, expected {want}", v.name))?;
    if elem != ONNX_FLOAT {
        return Err(format!(
            "{role} `{}` has ONNX element type {elem}, expected {want} (f32 at the boundary)",
            v.name
        ));
    }
    let ok = dims.len() == 4
        && matches!(dims[0], Dim::Fixed(1) | Dim::Named(_) | Dim::Unknown)
        && dims[1] == Dim::Fixed(channels as i64)
        && dims[2..]
            .iter()
            .all(|d| !matches!(d, Dim::Fixed(v) if *v <= 0));
    if !ok {
        return Err(format!(
            "{role} `{}` has shape {}, expected {want}",
            v.name,
            dims_str(&dims)
        ));
    }
    Ok(())
}

/// Checks the graph's inputs and outputs against `docs/CONVENTIONS.md` §7 for `metadata.kind`.
fn check_contract(graph: &pb::GraphProto, md: &ModelMetadata) -> std::result::Result<(), String> {
    let initialisers: std::collections::HashSet<&str> =
        graph.initializer.iter().map(|t| t.name.as_str()).collect();
    let inputs: Vec<&pb::ValueInfoProto> = graph
        .input
        .iter()
        .filter(|i| !initialisers.contains(i.name.as_str()))
        .collect();
    let in_name = md.kind.input_name();
    let in_channels = md.input_channels();
    let names: Vec<&str> = inputs.iter().map(|i| i.name.as_str()).collect();
    if inputs.len() != 1 || inputs[0].name != in_name {
        return Err(format!(
            "inputs are {names:?}, expected exactly one input `{in_name}` f32 [1,{in_channels},H,W] for a {}",
            md.kind
        ));
    }
    check_value(inputs[0], "input", in_channels)?;
    let out_names: Vec<&str> = graph.output.iter().map(|o| o.name.as_str()).collect();
    let want = md.kind.output_names();
    if out_names != want {
        return Err(format!(
            "outputs are {out_names:?}, expected {want:?} (f32 [1,3,H,W] each) for a {} of format {}",
            md.kind, md.format_version
        ));
    }
    for o in &graph.output {
        check_value(o, "output", 3)?;
    }
    Ok(())
}

/// A hologram or pre-filter CNN loaded from ONNX (`docs/CONVENTIONS.md` §7, paper Fig. 3), ready to be
/// planned per resolution.
///
/// Holds the decluttered tract graph with symbolic `H`, `W` and a cache of optimised [`ModelPlan`]s, one per
/// `(height, width)`. `Send + Sync`: plans can be built and run from several threads; a failed plan or run
/// leaves the model usable.
#[derive(Debug)]
pub struct HologramModel {
    metadata: ModelMetadata,
    source_name: String,
    decluttered: TypedModel,
    /// The file's ONNX graph as decoded (weights included), for the GPU path's reading of the layers.
    graph: Arc<pb::GraphProto>,
    /// Symbols of the input's height and width (`None` where the file fixes that dimension).
    dims: [Option<Symbol>; 2],
    /// Fixed input height/width from the file, where not symbolic.
    fixed: [Option<usize>; 2],
    plans: Mutex<HashMap<(usize, usize, CnnLayout), ModelPlan>>,
    /// The graph as the TensorHolo residual CNN, read on first use ([`HologramModel::cnn_graph`]).
    pub(super) cnn_graph:
        std::sync::OnceLock<std::result::Result<Arc<super::graph::CnnWeights>, String>>,
    /// Autotuning results per `(height, width, request)` ([`HologramModel::tuned_plan`]).
    pub(super) tuned: Mutex<HashMap<(usize, usize, super::PlanRequest), super::PlanReport>>,
}

impl HologramModel {
    /// Loads a CNN from the bytes of an ONNX file and checks it (see the [module docs](super)).
    ///
    /// * `kind`: which CNN the caller expects (`tensorholo.kind` must agree);
    /// * `expected`: the display and pipeline settings the file's metadata must match.
    ///
    /// Errors: [`HoloError::ModelLoad`] (not an ONNX protobuf, truncated, an operator tract cannot type),
    /// [`HoloError::ModelMetadata`] (missing/unparsable key or mismatch with `expected`, naming the key, the
    /// file's value and the expected one), [`HoloError::ModelContract`] (inputs/outputs not the contract's).
    pub fn from_bytes(bytes: &[u8], kind: ModelKind, expected: &ModelConfig) -> Result<Self> {
        Self::load(bytes, "<bytes>".into(), kind, expected)
    }

    /// As [`HologramModel::from_bytes`], naming the source `name` (e.g. the embedded file's name) in every
    /// error message instead of `<bytes>`.
    pub fn from_named_bytes(
        bytes: &[u8],
        name: &str,
        kind: ModelKind,
        expected: &ModelConfig,
    ) -> Result<Self> {
        Self::load(bytes, name.into(), kind, expected)
    }

    /// Loads a CNN from an ONNX file; as [`HologramModel::from_bytes`], plus [`HoloError::Io`] if the file
    /// cannot be read. Errors name the path.
    pub fn from_path(
        path: impl AsRef<Path>,
        kind: ModelKind,
        expected: &ModelConfig,
    ) -> Result<Self> {
        let path = path.as_ref();
        let bytes = crate::io::read_bytes(path)?;
        Self::load(&bytes, path.display().to_string(), kind, expected)
    }

    fn load(
        bytes: &[u8],
        source_name: String,
        kind: ModelKind,
        expected: &ModelConfig,
    ) -> Result<Self> {
        let load_err = |reason: String| HoloError::ModelLoad {
            source_name: source_name.clone(),
            reason,
        };
        // Value infos are hints on intermediate tensors; tract 0.23 rejects the QDQ exporter's, and the
        // graph's own ops determine every type anyway.
        let onnx = tract_onnx::onnx().with_ignore_value_info(true);
        let proto = guarded("decoding", || {
            onnx.proto_model_for_read(&mut &bytes[..])
                .map_err(|e| format!("not a valid ONNX protobuf ({})", tract_msg(&e)))
        })
        .map_err(load_err)?;
        let graph = proto
            .graph
            .as_ref()
            .filter(|g| !g.node.is_empty() || !g.output.is_empty())
            .ok_or_else(|| {
                load_err("the file holds no graph (empty or not an ONNX model)".into())
            })?;
        let raw: BTreeMap<String, String> = proto
            .metadata_props
            .iter()
            .map(|p| (p.key.clone(), p.value.clone()))
            .collect();
        let metadata = ModelMetadata::from_props(raw)?;
        metadata.check(kind, expected)?;
        check_contract(graph, &metadata).map_err(|reason| HoloError::ModelContract {
            source_name: source_name.clone(),
            reason,
        })?;
        let decluttered = guarded("typing the graph", || {
            let model = onnx
                .model_for_proto_model(&proto)
                .map_err(|e| format!("cannot parse the graph: {}", tract_msg(&e)))?;
            model
                .into_typed()
                .and_then(|m| m.into_decluttered())
                .map_err(|e| format!("cannot type the graph: {}", tract_msg(&e)))
        })
        .map_err(load_err)?;
        let graph = Arc::new(graph.clone());
        let fact = decluttered
            .input_fact(0)
            .map_err(|e| load_err(tract_msg(&e)))?
            .clone();
        let mut dims = [None, None];
        let mut fixed = [None, None];
        for (i, d) in fact.shape.iter().skip(2).take(2).enumerate() {
            match d {
                TDim::Sym(s) => dims[i] = Some(s.clone()),
                _ => match d.to_i64() {
                    Ok(v) if v > 0 => fixed[i] = Some(v as usize),
                    _ => {
                        return Err(HoloError::ModelContract {
                            source_name,
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
            metadata,
            source_name,
            decluttered,
            graph,
            dims,
            fixed,
            plans: Mutex::new(HashMap::new()),
            cnn_graph: std::sync::OnceLock::new(),
            tuned: Mutex::new(HashMap::new()),
        })
    }

    /// The decoded ONNX graph (nodes and weights) the model was loaded from.
    #[cfg_attr(not(feature = "gpu"), allow(dead_code))]
    pub(crate) fn onnx_graph(&self) -> &pb::GraphProto {
        &self.graph
    }

    /// The file's parsed `tensorholo.*` metadata.
    pub fn metadata(&self) -> &ModelMetadata {
        &self.metadata
    }

    /// Hologram CNN or pre-filter.
    pub fn kind(&self) -> ModelKind {
        self.metadata.kind
    }

    /// Channels of the network input: `4·L` (hologram CNN) or 6 (pre-filter).
    pub fn input_channels(&self) -> usize {
        self.metadata.input_channels()
    }

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
                format!("`{}` cannot run {layout}: {reason}", self.source_name),
            ),
            PlanFailure::Tract(reason) => HoloError::ModelLoad {
                source_name: self.source_name.clone(),
                reason: format!("cannot optimise for {height}×{width} ({layout}): {reason}"),
            },
        })?;
        Ok(ModelPlan {
            plan,
            kind: self.metadata.kind,
            channels: self.input_channels(),
            height,
            width,
            layout,
            threads: None,
            executor: None,
        })
    }

    /// Errors: [`HoloError::ShapeMismatch`] if the file fixes a size other than `height × width`.
    pub(super) fn check_fixed_size(&self, height: usize, width: usize) -> Result<()> {
        for (i, &n) in [height, width].iter().enumerate() {
            if let Some(f) = self.fixed[i] {
                if f != n {
                    return Err(HoloError::ShapeMismatch {
                        what: format!("model input size (fixed in `{}`)", self.source_name),
                        expected: vec![
                            self.fixed[0].unwrap_or(height),
                            self.fixed[1].unwrap_or(width),
                        ],
                        got: vec![height, width],
                    });
                }
            }
        }
        Ok(())
    }

    /// The name of the file (or `<bytes>`) this model was loaded from, as errors name it.
    pub fn source_name(&self) -> &str {
        &self.source_name
    }

    /// Runs the network on one input `[C, H, W]` (`C` = [`HologramModel::input_channels`]; hologram CNN:
    /// per layer `r, g, b` amplitude then depth `d`, all in `[0, 1]`; pre-filter: `Re H` then `Im H` of the
    /// offset hologram), planning `H × W` if needed.
    ///
    /// Returns the complex field `[3, H, W]` (R, G, B): the midpoint hologram for the hologram CNN
    /// ([`heads_to_field`]), the filtered SLM-plane hologram `Re + i·Im` for the pre-filter.
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
        if self.kind() != ModelKind::Hologram || self.metadata.input_layers != 1 {
            return Err(crate::error::invalid(
                "model",
                format!(
                    "run_frame needs an RGB-D hologram CNN (L = 1); this file is a {} with L = {}",
                    self.kind(),
                    self.metadata.input_layers
                ),
            ));
        }
        let mut input = Array3::<f32>::zeros((4, frame.height(), frame.width()));
        super::contract::pack_rgbd(frame, input.view_mut())?;
        self.run(input.view())
    }
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

/// A tract plan for one resolution of a [`HologramModel`] (graph with `H`, `W` bound and optimised).
///
/// Cloning is cheap (shared plan and thread pool). Each [`ModelPlan::run`] spawns its own tract state, so one
/// plan may run from several threads.
#[derive(Debug, Clone)]
pub struct ModelPlan {
    plan: Arc<TypedSimplePlan>,
    kind: ModelKind,
    channels: usize,
    height: usize,
    width: usize,
    layout: CnnLayout,
    /// Threads of this plan's own executor; `None`: tract's process-wide default ([`super::set_cnn_threads`]).
    threads: Option<usize>,
    executor: Option<Executor>,
}

impl ModelPlan {
    /// This plan running its matrix products and convolutions on `threads` threads of its own (a private
    /// pool for `threads > 1`, the calling thread for 1), whatever tract's process-wide default is.
    ///
    /// Errors: [`HoloError::InvalidParameter`] for 0 threads or more than [`MAX_CNN_THREADS`], or if the
    /// operating system refuses to start the threads.
    pub fn with_threads(&self, threads: usize) -> Result<ModelPlan> {
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

    /// The threads of this plan's own executor ([`ModelPlan::with_threads`]); `None` when it uses tract's
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

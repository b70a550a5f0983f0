//! [`HologramModel`]: one ONNX CNN, decoded ([`super::onnx`]) and checked against the I/O contract and
//! metadata of `docs/CONVENTIONS.md` §7. The engines run it: the native CPU engine and the GPU path through
//! [`HologramModel::cnn_graph`]; tract (cargo feature `tract`) from `HologramModel::file_bytes`, in its own
//! cache (`cnn/tract/`). The model holds no engine's state.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use super::graph::CnnWeights;
use super::metadata::{ModelConfig, ModelKind, ModelMetadata};
use super::onnx as pb;
use crate::error::{guarded, HoloError, Result};

/// ONNX `TensorProto.DataType.FLOAT`.
const ONNX_FLOAT: i32 = pb::FLOAT;

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
/// planned per resolution by an engine ([`crate::cnn`], the GPU).
///
/// Holds the file (its bytes, for engines that read it themselves), its decoded graph and metadata, and the
/// graph read as the TensorHolo residual CNN (`HologramModel::cnn_graph`, for the native engine and the
/// GPU). `Send + Sync`: engines plan and run it from several threads.
pub struct HologramModel {
    metadata: ModelMetadata,
    source_name: String,
    /// The ONNX file as loaded (read by the tract engine).
    #[cfg_attr(not(feature = "tract"), allow(dead_code))]
    bytes: Arc<[u8]>,
    /// The file's ONNX graph as decoded (weights included), read by [`super::graph`].
    graph: Arc<pb::GraphProto>,
    /// Fixed input height/width from the file, where not symbolic.
    fixed: [Option<usize>; 2],
    /// The graph as the TensorHolo residual CNN, read on first use ([`HologramModel::cnn_graph`]).
    cnn_graph: std::sync::OnceLock<std::result::Result<Arc<CnnWeights>, String>>,
}

impl std::fmt::Debug for HologramModel {
    /// The source, metadata and planned state; not the weights (a derived `Debug` printed megabytes).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut d = f.debug_struct("HologramModel");
        d.field("source_name", &self.source_name)
            .field("metadata", &self.metadata)
            .field("fixed", &self.fixed)
            .field("nodes", &self.graph.node.len());
        d.finish_non_exhaustive()
    }
}

impl HologramModel {
    /// Loads a CNN from the bytes of an ONNX file and checks it (see the [module docs](super)).
    ///
    /// * `kind`: which CNN the caller expects (`tensorholo.kind` must agree);
    /// * `expected`: the display and pipeline settings the file's metadata must match.
    ///
    /// Which engine can run the file is asked when a pipeline is made ([`crate::cnn::check_runnable`]).
    ///
    /// Errors: [`HoloError::ModelLoad`] (not an ONNX protobuf, truncated, no graph),
    /// [`HoloError::ModelMetadata`] (missing/unparsable key or mismatch with `expected`, naming the key, the
    /// file's value and the expected one), [`HoloError::ModelContract`] (inputs/outputs not the contract's).
    pub fn from_bytes(bytes: &[u8], kind: ModelKind, expected: &ModelConfig) -> Result<Self> {
        Self::load(bytes, "<bytes>".into(), kind, expected)
    }

    /// As [`HologramModel::from_bytes`], naming the source `name` (e.g. the embedded file's name) in every
    /// error message instead of `<bytes>`.
    pub(crate) fn from_named_bytes(
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
        let proto = pb::decode_model(bytes)
            .map_err(|e| load_err(format!("not a valid ONNX protobuf ({e})")))?;
        let graph = proto
            .graph
            .filter(|g| !g.node.is_empty() || !g.output.is_empty())
            .ok_or_else(|| {
                load_err("the file holds no graph (empty or not an ONNX model)".into())
            })?;
        let raw: BTreeMap<String, String> = proto
            .metadata_props
            .into_iter()
            .map(|p| (p.key, p.value))
            .collect();
        let metadata = ModelMetadata::from_props(raw)?;
        metadata.check(kind, expected)?;
        let contract_err = |reason| HoloError::ModelContract {
            source_name: source_name.clone(),
            reason,
        };
        check_contract(&graph, &metadata).map_err(contract_err)?;
        // The input's H and W as the file writes them (check_contract refused sizes ≤ 0).
        let mut fixed = [None, None];
        if let Some((_, dims)) = graph
            .input
            .iter()
            .find(|i| i.name == metadata.kind.input_name())
            .and_then(value_type)
        {
            for (f, d) in fixed.iter_mut().zip(&dims[2..]) {
                if let Dim::Fixed(v) = d {
                    *f = Some(*v as usize);
                }
            }
        }
        Ok(Self {
            metadata,
            source_name,
            bytes: bytes.into(),
            graph: Arc::new(graph),
            fixed,
            cnn_graph: std::sync::OnceLock::new(),
        })
    }

    /// The ONNX file's bytes, as loaded (what an engine that parses the file itself reads, e.g. tract).
    #[cfg(feature = "tract")]
    pub(crate) fn file_bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// The input's `[height, width]` where the file fixes them (`None` where symbolic, as the shipped files
    /// leave both).
    #[cfg(feature = "tract")]
    pub(crate) fn fixed_size(&self) -> [Option<usize>; 2] {
        self.fixed
    }

    /// The decoded ONNX graph (nodes and weights) the model was loaded from.
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

    /// Errors: [`HoloError::ShapeMismatch`] if the file fixes a size other than `height × width`.
    pub(crate) fn check_fixed_size(&self, height: usize, width: usize) -> Result<()> {
        check_fixed_size(&self.fixed, &self.source_name, height, width)
    }

    /// The name of the file (or `<bytes>`) this model was loaded from, as errors name it.
    pub fn source_name(&self) -> &str {
        &self.source_name
    }
}

impl CnnWeights {
    /// Reads the layers of `model`'s ONNX graph and checks it is the TensorHolo residual CNN (the
    /// [`graph`](super::graph) module docs: every convolution 3×3 with padding 1, stride 1, no groups, f32
    /// weights and bias; the residual wiring and the final concat exactly as the architecture says; the
    /// hologram heads or the pre-filter's base filter). [`HologramModel::cnn_graph`] reads it once per model
    /// and shares it.
    ///
    /// Errors: [`HoloError::ModelContract`] naming the first node that breaks the pattern (int8 files among
    /// them: the GPU runs the f32 files).
    pub(crate) fn from_model(model: &HologramModel) -> Result<Self> {
        Self::from_graph(model.onnx_graph(), model.kind(), model.source_name())
    }
}

impl HologramModel {
    /// This model's graph as the TensorHolo residual CNN ([`CnnWeights::from_model`]), read from the ONNX
    /// file on the first call and shared by every executor after it (the GPU path, the native engine).
    ///
    /// Errors: [`HoloError::ModelContract`] (every call, the same reason) where the graph is not the
    /// architecture; such a model runs on tract only.
    pub(crate) fn cnn_graph(&self) -> Result<Arc<CnnWeights>> {
        // The reader walks an untrusted graph: a file on which it would panic is refused, not a crash.
        let cached = self.cnn_graph.get_or_init(|| {
            guarded(
                "reading the graph's layers",
                || match CnnWeights::from_model(self) {
                    Ok(w) => Ok(Arc::new(w)),
                    Err(HoloError::ModelContract { reason, .. }) => Err(reason),
                    Err(e) => Err(e.to_string()),
                },
            )
        });
        cached.clone().map_err(|reason| HoloError::ModelContract {
            source_name: self.source_name().to_string(),
            reason,
        })
    }
}

/// Checks `height × width` against the sizes a file fixes (`fixed`, `None` where symbolic; `source_name` for
/// the message). Errors: [`HoloError::ShapeMismatch`].
pub(crate) fn check_fixed_size(
    fixed: &[Option<usize>; 2],
    source_name: &str,
    height: usize,
    width: usize,
) -> Result<()> {
    for (i, &n) in [height, width].iter().enumerate() {
        if let Some(f) = fixed[i] {
            if f != n {
                return Err(HoloError::ShapeMismatch {
                    what: format!("model input size (fixed in `{source_name}`)"),
                    expected: vec![fixed[0].unwrap_or(height), fixed[1].unwrap_or(width)],
                    got: vec![height, width],
                });
            }
        }
    }
    Ok(())
}

//! The TensorHolo residual CNN as a graph of its own ([`CnnWeights`]), read once from the same ONNX file tract
//! runs (`model/onnx.rs`) and checked against the architecture, so that every executor that is not tract (the GPU path, the
//! native CPU engine) runs exactly what the file specifies, without a second reader.
//!
//! The architecture (training/tensorholo_training/model.py, `ResidualCNN`): N 3×3 convolutions with zero
//! padding; ReLU after all but the last; with `s_i` the input of layer `i` and `y_i` its output, `s_0 = x`
//! (the hologram CNN centres its input: `x − 0.5`), `s_i = y_{i−1}` for `i ∈ {1, 2}` or even `i`,
//! `s_i = y_{i−1} + s_{i−2}` for odd `i ≥ 3`, and the last layer reads `concat(s_{N−1}, x)`. The hologram CNN
//! ends in tanh heads (amplitude `(tanh + 1)·√2/2`, phase `(tanh + 1)/2`); the pre-filter CNN adds its raw
//! output to a fixed depthwise filter of its edge-replicated input (the AA-DPM blur).

use std::collections::HashMap;

use super::metadata::ModelKind;
use super::onnx as pb;
use crate::error::{HoloError, Result};

/// One 3×3 convolution of the CNN.
#[derive(Debug, Clone, PartialEq)]
pub struct ConvLayer {
    /// Output channels.
    pub c_out: usize,
    /// Input channels (for the last layer: the hidden channels plus the network input's).
    pub c_in: usize,
    /// Weights `[c_out, c_in, 3, 3]` as in the ONNX file.
    pub weights: Vec<f32>,
    /// Bias `[c_out]`.
    pub bias: Vec<f32>,
}

/// What follows the last convolution.
#[derive(Debug, Clone, PartialEq)]
pub enum CnnOutput {
    /// Hologram CNN heads: amplitude `(tanh(o) + 1)·amplitude_scale` (channels 0–2), phase
    /// `(tanh(o) + 1)·phase_scale` (channels 3–5), the scales read from the graph (√2/2 and 1/2).
    Heads {
        /// Amplitude head scale.
        amplitude_scale: f32,
        /// Phase head scale.
        phase_scale: f32,
    },
    /// Pre-filter CNN: raw output plus a depthwise `taps × taps` filter of the edge-replicated input.
    Prefilter {
        /// Kernel width (odd).
        taps: usize,
        /// `[channels, taps, taps]` weights.
        base: Vec<f32>,
    },
}

/// The grid of a u8 tensor of a QDQ file: `real = (q − zero_point)·scale` (ONNX `QuantizeLinear`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QuantGrid {
    /// Real units per step (finite, > 0).
    pub scale: f32,
    /// The u8 code of real 0.
    pub zero_point: u8,
}

/// The int8 form of one convolution of a QDQ file.
#[derive(Debug, Clone, PartialEq)]
pub struct LayerQuant {
    /// Symmetric s8 weights `[c_out, c_in, 3, 3]` (the f32 [`ConvLayer::weights`] are these times their scale).
    pub weights: Vec<i8>,
    /// Weight scale per output channel, `[c_out]` (a per-tensor scale is repeated).
    pub weight_scales: Vec<f32>,
    /// Grid of the layer's input `s_i` (for the last layer: of the concat).
    pub input: QuantGrid,
    /// Grid the file rounds the layer's result to before the next layer reads it: `s_{i+1}` (for the
    /// second-to-last layer the concat's, or in a mixed-precision file the grid `s_{N−1}` enters the float
    /// concat on), always present for those; for the last layer the grid of its raw
    /// output before the heads or the pre-filter's sum, `None` where the file leaves that output float (the
    /// exporter does since it stopped rounding convolution outputs).
    pub output: Option<QuantGrid>,
}

/// The quantisation of an int8 QDQ file (`models/*.int8-qdq.onnx`): every int8 convolution's s8 weights and
/// the u8 grid of every activation a convolution reads. An engine that fuses a layer's convolution, ReLU and
/// residual add rounds once, to [`LayerQuant::output`], as the current exporter's files do; files exported
/// before it (per-tensor weight scales) also round each convolution's raw output before its ReLU (a second
/// rounding, of at most half a step, that such an engine skips).
///
/// Two layouts are read: every learned convolution int8, or **mixed precision** (`export --float-convs first
/// last`): the first and the last convolution keep f32 weights and read the float input (the first reads it
/// alone, the last in its concat), the hidden layers between are int8, `s_1` and `s_{N−1}` are rounded to
/// their own grids. Any other placement of float layers is refused (tract runs such files).
#[derive(Debug, Clone, PartialEq)]
pub struct CnnQuant {
    /// One entry per [`CnnWeights::layers`] entry; `None` for a float layer (the first and the last of a
    /// mixed-precision file, whose [`ConvLayer::weights`] are the file's f32 ones).
    pub layers: Vec<Option<LayerQuant>>,
    /// Pre-filter: whether the file's base filter reads the input rounded to the first layer's grid (files
    /// exported before the exporter kept the blur's input float) rather than the float input itself.
    pub base_reads_rounded_input: bool,
}

/// A TensorHolo residual CNN read from its ONNX graph (`CnnWeights::from_model`).
#[derive(Debug, Clone, PartialEq)]
pub struct CnnWeights {
    /// Network input channels (`4·L` for the hologram CNN, 6 for the pre-filter).
    pub in_channels: usize,
    /// Value subtracted from the input before the first layer and the final concat (0.5 or 0).
    pub input_offset: f32,
    /// The convolutions, first to last.
    pub layers: Vec<ConvLayer>,
    /// The output stage.
    pub output: CnnOutput,
    /// The int8 quantisation of a QDQ file (then [`ConvLayer::weights`] and `bias` hold the dequantised
    /// values); `None` for an f32 file.
    pub quant: Option<CnnQuant>,
}

/// What a tensor of the graph is, as far as the CNN pattern goes.
#[derive(Debug, Clone, PartialEq)]
enum Sym {
    /// The network input.
    Input,
    /// The input minus a constant.
    Centred(f32),
    /// `y_i`: ReLU of layer `i`.
    Relu(usize),
    /// Raw (pre-activation) output of layer `i`.
    Conv(usize),
    /// A sum of two activations.
    Sum(Box<Sym>, Box<Sym>),
    /// A channel concatenation.
    Cat(Box<Sym>, Box<Sym>),
    /// The edge-replicated input (pre-filter base branch).
    PaddedInput,
    /// The base filter of the pre-filter.
    Base,
    /// Scalars and shape arithmetic (constants, shapes, pads).
    Meta,
    /// Output-stage tensors after the last convolution.
    Tail,
}

fn contract_err(source_name: &str, reason: String) -> HoloError {
    HoloError::ModelContract {
        source_name: source_name.to_string(),
        reason: format!(
            "the GPU path and the native CPU engine run the TensorHolo residual CNN only: {reason}"
        ),
    }
}

/// An f32 tensor of the graph: `(dims, values)`.
fn f32_tensor(t: &pb::TensorProto) -> Option<(Vec<usize>, Vec<f32>)> {
    if t.data_type != 1 {
        return None;
    }
    let dims: Vec<usize> = t.dims.iter().map(|&d| d.max(0) as usize).collect();
    let n: usize = dims.iter().product();
    let values = if !t.float_data.is_empty() {
        t.float_data.clone()
    } else {
        t.raw_data
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect()
    };
    (values.len() == n).then_some((dims, values))
}

/// An int8 (`INT8`, data type 3) tensor: `(dims, values)`.
fn i8_tensor(t: &pb::TensorProto) -> Option<(Vec<usize>, Vec<i8>)> {
    if t.data_type != 3 {
        return None;
    }
    let dims: Vec<usize> = t.dims.iter().map(|&d| d.max(0) as usize).collect();
    let n: usize = dims.iter().product();
    let values: Vec<i8> = if !t.int32_data.is_empty() {
        t.int32_data.iter().map(|&v| v as i8).collect()
    } else {
        t.raw_data.iter().map(|&b| b as i8).collect()
    };
    (values.len() == n).then_some((dims, values))
}

/// An integer tensor (`UINT8` 2, `INT8` 3, `INT32` 6) as i64 values.
fn int_tensor(t: &pb::TensorProto) -> Option<Vec<i64>> {
    let n: usize = t.dims.iter().map(|&d| d.max(0) as usize).product();
    let values: Vec<i64> = match t.data_type {
        2 | 3 | 6 if !t.int32_data.is_empty() => t.int32_data.iter().map(|&v| v as i64).collect(),
        2 => t.raw_data.iter().map(|&b| b as i64).collect(),
        3 => t.raw_data.iter().map(|&b| b as i8 as i64).collect(),
        6 => t
            .raw_data
            .chunks_exact(4)
            .map(|c| i32::from_le_bytes([c[0], c[1], c[2], c[3]]) as i64)
            .collect(),
        _ => return None,
    };
    (values.len() == n).then_some(values)
}

fn attr<'a>(node: &'a pb::NodeProto, name: &str) -> Option<&'a pb::AttributeProto> {
    node.attribute.iter().find(|a| a.name == name)
}

impl CnnWeights {
    /// Reads the layers of a decoded ONNX graph of a CNN of `kind` (`source_name` names the file in errors)
    /// and checks it is the TensorHolo residual CNN (see the [module docs](self)): every convolution 3×3 with
    /// padding 1, stride 1, no groups, f32 weights and bias; the residual wiring and the final concat exactly
    /// as the architecture says; the hologram heads or the pre-filter's base filter. A loaded model reads its
    /// own once and shares it (`HologramModel::cnn_graph`).
    ///
    /// Errors: [`HoloError::ModelContract`] naming the first node that breaks the pattern (int8 files among
    /// them: the GPU runs the f32 files).
    pub(crate) fn from_graph(
        graph: &pb::GraphProto,
        kind: ModelKind,
        source_name: &str,
    ) -> Result<Self> {
        let err = |r: String| contract_err(source_name, r);
        let input = graph
            .input
            .first()
            .map(|i| i.name.clone())
            .ok_or_else(|| err("no graph input".into()))?;
        let mut inits: HashMap<String, (Vec<usize>, Vec<f32>)> = HashMap::new();
        let mut raw: HashMap<&str, &pb::TensorProto> = HashMap::new();
        for t in &graph.initializer {
            raw.insert(t.name.as_str(), t);
            if let Some(v) = f32_tensor(t) {
                inits.insert(t.name.clone(), v);
            }
        }
        // QDQ files: the s8 weights behind each dequantised weight tensor, the u8 grid of each rounded
        // activation, and per layer the grid of its input, its weights and the grid of its raw output.
        let mut saw_qdq = false;
        let mut qweights: HashMap<String, (Vec<i8>, Vec<f32>)> = HashMap::new();
        let mut grids: HashMap<String, QuantGrid> = HashMap::new();
        let mut layer_in_grid: Vec<Option<QuantGrid>> = Vec::new();
        let mut layer_qw: Vec<Option<(Vec<i8>, Vec<f32>)>> = Vec::new();
        let mut conv_out_grid: HashMap<usize, QuantGrid> = HashMap::new();
        let mut consts: HashMap<String, Vec<f32>> = HashMap::new();
        let mut syms: HashMap<String, Sym> = HashMap::new();
        syms.insert(input.clone(), Sym::Input);
        let mut layers: Vec<ConvLayer> = Vec::new();
        let mut layer_inputs: Vec<Sym> = Vec::new();
        let mut base: Option<(usize, Vec<f32>)> = None;
        // (operator, output tensor, constant) of each Add/Mul of the heads.
        let mut tail_consts: Vec<(&str, &str, f32)> = Vec::new();
        let mut tanh_count = 0;
        let mut base_rounded = false;
        // The grids of the final concat's two inputs (hidden state, network input) where they are rounded.
        let mut cat_grids: (Option<QuantGrid>, Option<QuantGrid>) = (None, None);
        let sym = |syms: &HashMap<String, Sym>, name: &str| -> Sym {
            syms.get(name).cloned().unwrap_or(Sym::Meta)
        };
        for node in &graph.node {
            let op = node.op_type.as_str();
            let where_ = || format!("node `{}` ({op})", node.name);
            let ins: Vec<Sym> = node.input.iter().map(|i| sym(&syms, i)).collect();
            let is_act = |s: &Sym| !matches!(s, Sym::Meta);
            let out = match op {
                "Constant" => {
                    if let Some(t) = attr(node, "value").and_then(|a| a.t.as_ref()) {
                        if let (Some(o), Some((_, v))) = (node.output.first(), f32_tensor(t)) {
                            consts.insert(o.clone(), v);
                        }
                    }
                    Sym::Meta
                }
                "QLinearConv" | "ConvInteger" => {
                    return Err(err(format!(
                        "{} is a QOperator int8 convolution; the native CPU engine runs the f32 and int8 QDQ \
                         files",
                        where_()
                    )))
                }
                "QuantizeLinear" | "DequantizeLinear" => {
                    saw_qdq = true;
                    let x = node.input.first().map(String::as_str).unwrap_or_default();
                    let out_name = node.output.first().cloned().unwrap_or_default();
                    let scale = node
                        .input
                        .get(1)
                        .and_then(|n| inits.get(n.as_str()))
                        .map(|v| v.1.clone())
                        .ok_or_else(|| err(format!("{}: no f32 scale", where_())))?;
                    let zp = match node.input.get(2).filter(|n| !n.is_empty()) {
                        Some(n) => Some(
                            raw.get(n.as_str())
                                .copied()
                                .ok_or_else(|| err(format!("{}: zero point", where_())))?,
                        ),
                        None => None,
                    };
                    if let (true, Some(t)) = (op == "DequantizeLinear", raw.get(x).copied()) {
                        // A constant: s8 weights or i32 bias.
                        let zps = zp.and_then(int_tensor).unwrap_or_default();
                        let dims: Vec<usize> = t.dims.iter().map(|&d| d.max(0) as usize).collect();
                        // Per-axis scales must run along the output channels (ONNX's default axis is 1).
                        let axis = attr(node, "axis").map_or(1, |a| a.i);
                        if scale.len() > 1 && axis != 0 {
                            return Err(err(format!(
                                "{}: per-channel scales along axis {axis} (expected 0, the output channels)",
                                where_()
                            )));
                        }
                        if let Some((dims, q)) = i8_tensor(t) {
                            let c_out = dims.first().copied().unwrap_or(0);
                            let per = q.len() / c_out.max(1);
                            let scales: Vec<f32> = match scale.len() {
                                1 => vec![scale[0]; c_out],
                                n if n == c_out => scale.clone(),
                                _ => return Err(err(format!("{}: weight scales", where_()))),
                            };
                            if zps.iter().any(|&z| z != 0) || dims.len() != 4 {
                                return Err(err(format!(
                                    "{}: expected symmetric s8 weights [O, I, kH, kW]",
                                    where_()
                                )));
                            }
                            let f: Vec<f32> = q
                                .iter()
                                .enumerate()
                                .map(|(i, &v)| v as f32 * scales[i / per.max(1)])
                                .collect();
                            inits.insert(out_name.clone(), (dims, f));
                            qweights.insert(out_name, (q, scales));
                        } else if let (6, Some(q)) = (t.data_type, int_tensor(t)) {
                            // An i32 bias: one scale (per-tensor weights) or one per output channel
                            // (input scale × each channel's weight scale).
                            if scale.len() != 1 && scale.len() != q.len() {
                                return Err(err(format!(
                                    "{}: {} bias scales for {} biases",
                                    where_(),
                                    scale.len(),
                                    q.len()
                                )));
                            }
                            let f = q
                                .iter()
                                .enumerate()
                                .map(|(i, &v)| {
                                    let z = zps.get(i).or(zps.first()).copied().unwrap_or(0);
                                    (v - z) as f32 * scale[i.min(scale.len() - 1)]
                                })
                                .collect();
                            inits.insert(out_name, (dims, f));
                        } else {
                            return Err(err(format!(
                                "{}: dequantised constant of type {}",
                                where_(),
                                t.data_type
                            )));
                        }
                        Sym::Meta
                    } else {
                        // An activation rounded to a u8 grid: the same tensor for the pattern.
                        let grid = match (op, grids.get(x)) {
                            ("DequantizeLinear", Some(g)) => *g,
                            _ => {
                                let z = zp.filter(|t| t.data_type == 2).and_then(int_tensor);
                                match (&scale[..], z.as_deref()) {
                                    ([s], Some([z])) if s.is_finite() && *s > 0.0 => QuantGrid {
                                        scale: *s,
                                        zero_point: *z as u8,
                                    },
                                    _ => {
                                        return Err(err(format!(
                                            "{}: expected a per-tensor u8 activation grid",
                                            where_()
                                        )))
                                    }
                                }
                            }
                        };
                        if let (Some(Sym::Conv(i)), "QuantizeLinear") = (ins.first(), op) {
                            conv_out_grid.insert(*i, grid);
                        }
                        grids.insert(out_name, grid);
                        ins.first().cloned().unwrap_or(Sym::Meta)
                    }
                }
                _ if !ins.iter().any(is_act) && op != "Conv" => Sym::Meta,
                "Sub" => {
                    let c = node
                        .input
                        .get(1)
                        .and_then(|n| consts.get(n).or(inits.get(n.as_str()).map(|v| &v.1)));
                    match (&ins[0], c.map(|v| v.as_slice())) {
                        (Sym::Input, Some([k])) => Sym::Centred(*k),
                        _ => return Err(err(format!("{}: expected input − constant", where_()))),
                    }
                }
                "Pad" => {
                    let edge = attr(node, "mode").is_some_and(|a| a.s == b"edge");
                    if ins[0] != Sym::Input || !edge {
                        return Err(err(format!("{}: only an edge pad of the input", where_())));
                    }
                    // The graph input itself, or its DequantizeLinear (the same tensor, rounded).
                    base_rounded = node.input.first() != Some(&input);
                    Sym::PaddedInput
                }
                "Conv" => {
                    let ints = |n: &str| attr(node, n).map(|a| a.ints.clone());
                    let group = attr(node, "group").map_or(1, |a| a.i);
                    let w = node.input.get(1).and_then(|n| {
                        inits
                            .get(n.as_str())
                            .cloned()
                            .or_else(|| consts.get(n).map(|v| (Vec::new(), v.clone())))
                    });
                    if ins[0] == Sym::PaddedInput {
                        // The pre-filter's base: depthwise k×k, no padding of its own (the Pad did it).
                        let (_, wv) = w.ok_or_else(|| err(format!("{}: no weights", where_())))?;
                        let k = ints("kernel_shape").unwrap_or_default();
                        let c = group as usize;
                        let taps = k.first().copied().unwrap_or(0) as usize;
                        if k.len() != 2
                            || k[0] != k[1]
                            || taps.is_multiple_of(2)
                            || wv.len() != c * taps * taps
                        {
                            return Err(err(format!("{}: base filter shape", where_())));
                        }
                        if node.input.len() > 2 {
                            return Err(err(format!("{}: base filter with a bias", where_())));
                        }
                        base = Some((taps, wv));
                        Sym::Base
                    } else {
                        let (dims, weights) = node
                            .input
                            .get(1)
                            .and_then(|n| inits.get(n.as_str()).cloned())
                            .ok_or_else(|| {
                                err(format!("{}: weights are not f32 initializers", where_()))
                            })?;
                        let bias = node
                            .input
                            .get(2)
                            .and_then(|n| inits.get(n.as_str()).map(|v| v.1.clone()))
                            .ok_or_else(|| err(format!("{}: no f32 bias", where_())))?;
                        let ok = dims.len() == 4
                            && dims[2] == 3
                            && dims[3] == 3
                            && group == 1
                            && ints("pads").is_none_or(|p| p == [1, 1, 1, 1])
                            && ints("strides").is_none_or(|s| s == [1, 1])
                            && ints("dilations").is_none_or(|d| d == [1, 1])
                            && bias.len() == dims[0];
                        if !ok {
                            return Err(err(format!(
                                "{}: expected a 3×3 convolution, padding 1, stride 1, one group, with bias \
                                 (weights {dims:?})",
                                where_()
                            )));
                        }
                        layers.push(ConvLayer {
                            c_out: dims[0],
                            c_in: dims[1],
                            weights,
                            bias,
                        });
                        layer_in_grid.push(grids.get(&node.input[0]).copied());
                        layer_qw.push(node.input.get(1).and_then(|n| qweights.get(n)).cloned());
                        layer_inputs.push(ins[0].clone());
                        Sym::Conv(layers.len() - 1)
                    }
                }
                "Relu" => match ins[0] {
                    Sym::Conv(i) => Sym::Relu(i),
                    _ => {
                        return Err(err(format!(
                            "{}: ReLU of something else than a convolution",
                            where_()
                        )))
                    }
                },
                "Add" if ins.iter().all(is_act) => {
                    let (a, b) = (ins[0].clone(), ins[1].clone());
                    match (&a, &b) {
                        (Sym::Base, Sym::Conv(_)) | (Sym::Conv(_), Sym::Base) => Sym::Tail,
                        (Sym::Tail, _) | (_, Sym::Tail) => Sym::Tail,
                        _ => Sym::Sum(Box::new(a), Box::new(b)),
                    }
                }
                "Concat" => {
                    if ins.len() != 2 || attr(node, "axis").map_or(0, |a| a.i) != 1 {
                        return Err(err(format!(
                            "{}: expected a 2-way channel concat",
                            where_()
                        )));
                    }
                    cat_grids = (grids.get(&node.input[0]).copied(), grids.get(&node.input[1]).copied());
                    Sym::Cat(Box::new(ins[0].clone()), Box::new(ins[1].clone()))
                }
                "Slice" | "Split" | "Tanh" | "Add" | "Mul" => {
                    if op == "Tanh" {
                        tanh_count += 1;
                    }
                    if matches!(op, "Add" | "Mul") {
                        for n in node.input.iter().skip(1) {
                            if let Some([v]) = consts
                                .get(n)
                                .or(inits.get(n.as_str()).map(|v| &v.1))
                                .map(|v| v.as_slice())
                            {
                                let out = node.output.first().map_or("", String::as_str);
                                tail_consts.push((op, out, *v));
                            }
                        }
                    }
                    if !ins.iter().any(|s| matches!(s, Sym::Conv(_) | Sym::Tail)) {
                        return Err(err(format!("{}: unexpected {op}", where_())));
                    }
                    Sym::Tail
                }
                _ => {
                    return Err(err(format!(
                        "{}: operator {op} is not part of the architecture",
                        where_()
                    )))
                }
            };
            for o in &node.output {
                syms.insert(o.clone(), out.clone());
            }
        }
        let n = layers.len();
        if n < 2 {
            return Err(err(format!("{n} convolution(s), expected ≥ 2")));
        }
        let x = layer_inputs[0].clone();
        let input_offset = match x {
            Sym::Input => 0.0,
            Sym::Centred(k) => k,
            ref s => return Err(err(format!("layer 0 reads {s:?}, expected the input"))),
        };
        // The residual wiring of the architecture, layer by layer.
        let mut s: Vec<Sym> = vec![x.clone()];
        for i in 1..n {
            let y = Sym::Relu(i - 1);
            let expect = if i >= 3 && i % 2 == 1 {
                Sym::Sum(Box::new(y), Box::new(s[i - 2].clone()))
            } else {
                y
            };
            let got = &layer_inputs[i];
            let swapped = |e: &Sym| match e {
                Sym::Sum(a, b) => Sym::Sum(b.clone(), a.clone()),
                other => other.clone(),
            };
            let want = if i == n - 1 {
                Sym::Cat(Box::new(expect.clone()), Box::new(x.clone()))
            } else {
                expect.clone()
            };
            let ok = *got == want
                || (i == n - 1
                    && *got == Sym::Cat(Box::new(swapped(&expect)), Box::new(x.clone())))
                || *got == swapped(&want);
            if !ok {
                return Err(err(format!(
                    "layer {i} reads {got:?}, the architecture has {want:?}"
                )));
            }
            s.push(expect);
        }
        let in_channels = layers[0].c_in;
        for (i, l) in layers.iter().enumerate() {
            let want_in = match i {
                0 => in_channels,
                _ if i == n - 1 => layers[i - 1].c_out + in_channels,
                _ => layers[i - 1].c_out,
            };
            if l.c_in != want_in || (i > 0 && i < n - 1 && l.c_out != layers[0].c_out) {
                return Err(err(format!(
                    "layer {i} has {} → {} channels, the architecture needs {want_in} inputs",
                    l.c_in, l.c_out
                )));
            }
        }
        let last = &layers[n - 1];
        let output = match kind {
            ModelKind::Hologram => {
                // tanh heads: Add 1 then Mul by the scale, per head (constants in graph order).
                // Each head is (tanh + 1)·scale; the Mul of a head writes the graph output of its name
                // (amplitude first, phase second), in whatever order the file lists the nodes.
                let outputs: Vec<&str> = graph.output.iter().map(|o| o.name.as_str()).collect();
                let scale_of = |name: Option<&&str>| {
                    tail_consts
                        .iter()
                        .find(|(op, out, _)| *op == "Mul" && Some(out) == name)
                        .map(|t| t.2)
                };
                let ones = tail_consts
                    .iter()
                    .filter(|(op, _, v)| *op == "Add" && *v == 1.0)
                    .count();
                let (Some(amp), Some(phs)) = (scale_of(outputs.first()), scale_of(outputs.get(1)))
                else {
                    return Err(err(format!(
                        "heads: constants {tail_consts:?}, expected a scale for each of {outputs:?}"
                    )));
                };
                if tanh_count != 2
                    || ones != 2
                    || tail_consts.len() != 4
                    || last.c_out != 6
                    || base.is_some()
                {
                    return Err(err(
                        "heads: expected (tanh + 1)·scale on 2 × 3 channels".into()
                    ));
                }
                CnnOutput::Heads {
                    amplitude_scale: amp,
                    phase_scale: phs,
                }
            }
            ModelKind::PreFilter => {
                let (taps, base) =
                    base.ok_or_else(|| err("pre-filter without a base filter".into()))?;
                if last.c_out != in_channels || base.len() != in_channels * taps * taps {
                    return Err(err("pre-filter output channels".into()));
                }
                CnnOutput::Prefilter { taps, base }
            }
        };
        let quant = if saw_qdq {
            // Mixed precision: the first and the last layer float, both reading the float input.
            let mixed = n >= 3 && layer_qw[0].is_none() && layer_qw[n - 1].is_none();
            if mixed {
                let float_input = layer_in_grid[0].is_none() && cat_grids.1.is_none();
                if !float_input || layer_in_grid[n - 1].is_some() || cat_grids.0.is_none() {
                    return Err(err(
                        "mixed-precision int8 file: the float first and last layers must read the float \
                         input, and the last its hidden input rounded to a grid of its own (export \
                         --float-convs first last)"
                            .into(),
                    ));
                }
            }
            let mut q = Vec::with_capacity(n);
            for i in 0..n {
                let missing = |what: &str| err(format!("int8 file: layer {i} has no {what}"));
                if mixed && (i == 0 || i == n - 1) {
                    q.push(None);
                    continue;
                }
                let (weights, weight_scales) = layer_qw[i].clone().ok_or_else(|| {
                    missing(
                        "s8 weights (a float layer: the native engine runs int8 files whose first and \
                         last layers are both int8 or both float)",
                    )
                })?;
                let input = layer_in_grid[i].ok_or_else(|| missing("u8 input grid"))?;
                let next = match mixed && i + 2 == n {
                    true => cat_grids.0,
                    false => layer_in_grid.get(i + 1).copied().flatten(),
                };
                let output = match i + 1 < n {
                    true => Some(next.ok_or_else(|| missing("u8 output grid"))?),
                    false => conv_out_grid.get(&i).copied(),
                };
                q.push(Some(LayerQuant {
                    weights,
                    weight_scales,
                    input,
                    output,
                }));
            }
            Some(CnnQuant {
                layers: q,
                base_reads_rounded_input: base_rounded,
            })
        } else {
            None
        };
        Ok(Self {
            in_channels,
            input_offset,
            layers,
            output,
            quant,
        })
    }

    /// Whether this is a mixed-precision int8 file: float first and last layers, int8 between (the graph
    /// reader allows no other float layers); false for an f32 file.
    pub(crate) fn is_mixed_precision(&self) -> bool {
        let n = self.layers.len();
        self.quant
            .as_ref()
            .is_some_and(|q| n >= 3 && q.layers[0].is_none() && q.layers[n - 1].is_none())
    }

    /// The layers of an int8 file that run in f32: the first and the last of a mixed-precision file, none
    /// otherwise (and none for an f32 file, whose layers are all f32 anyway).
    pub(crate) fn float_layers_of_int8(&self) -> impl Iterator<Item = &ConvLayer> {
        let n = self.layers.len();
        let ends = if self.is_mixed_precision() {
            vec![0, n - 1]
        } else {
            Vec::new()
        };
        ends.into_iter().map(move |i| &self.layers[i])
    }

    #[cfg(feature = "gpu")]
    /// Multiply-adds per output pixel of the convolutions.
    pub(crate) fn macs_per_pixel(&self) -> usize {
        self.layers.iter().map(|l| l.c_out * l.c_in * 9).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{embedded, ModelConfig, Precision};

    fn config() -> ModelConfig {
        ModelConfig {
            offset_m: 6e-3,
            ..ModelConfig::default()
        }
    }

    #[test]
    fn other_graphs_are_refused_naming_the_node() {
        #[cfg(feature = "qop-models")]
        {
            let qop = embedded::hologram_model(8, Precision::Int8QOperator, &config()).unwrap();
            let err = CnnWeights::from_model(&qop).unwrap_err().to_string();
            assert!(err.contains("QOperator"), "{err}");
        }
        let f32 = embedded::hologram_model(8, Precision::F32, &config()).unwrap();
        let good = f32.onnx_graph().clone();
        // Rewire one residual connection: layer 5 reads y_4 + y_0 instead of y_4 + s_3.
        let mut bad = good.clone();
        let relu0 = bad
            .node
            .iter()
            .find(|n| n.op_type == "Relu")
            .unwrap()
            .output[0]
            .clone();
        let add1 = bad
            .node
            .iter_mut()
            .filter(|n| n.op_type == "Add")
            .nth(1)
            .unwrap();
        add1.input[1] = relu0;
        let err = CnnWeights::from_graph(&bad, ModelKind::Hologram, "rewired")
            .unwrap_err()
            .to_string();
        assert!(err.contains("layer 5 reads"), "{err}");
        // A 5×5 convolution.
        let mut bad = good.clone();
        let conv = bad.node.iter_mut().find(|n| n.op_type == "Conv").unwrap();
        for a in conv.attribute.iter_mut().filter(|a| a.name == "pads") {
            a.ints = vec![0, 0, 0, 0];
        }
        let err = CnnWeights::from_graph(&bad, ModelKind::Hologram, "unpadded")
            .unwrap_err()
            .to_string();
        assert!(err.contains("padding 1"), "{err}");
        // An operator the architecture does not have.
        let mut bad = good;
        bad.node
            .iter_mut()
            .find(|n| n.op_type == "Relu")
            .unwrap()
            .op_type = "Sigmoid".into();
        let err = CnnWeights::from_graph(&bad, ModelKind::Hologram, "sigmoid")
            .unwrap_err()
            .to_string();
        assert!(err.contains("Sigmoid"), "{err}");
    }

    #[test]
    fn a_qdq_file_reads_as_the_f32_network_with_its_int8_grids() {
        for (kind, qdq, f32) in [
            (
                ModelKind::Hologram,
                embedded::hologram_model(8, Precision::Int8Qdq, &config()).unwrap(),
                embedded::hologram_model(8, Precision::F32, &config()).unwrap(),
            ),
            (
                ModelKind::PreFilter,
                embedded::prefilter_model(6, Precision::Int8Qdq, &config()).unwrap(),
                embedded::prefilter_model(6, Precision::F32, &config()).unwrap(),
            ),
        ] {
            let q = CnnWeights::from_model(&qdq).unwrap();
            let f = CnnWeights::from_model(&f32).unwrap();
            assert!(f.quant.is_none());
            let quant = q.quant.as_ref().expect("QDQ grids");
            assert_eq!(quant.layers.len(), f.layers.len(), "{kind:?}");
            // The exporter keeps the pre-filter's blur on the float input (export.py, _float_blur_input).
            assert!(!quant.base_reads_rounded_input, "{kind:?}");
            assert_eq!(
                (q.in_channels, q.input_offset),
                (f.in_channels, f.input_offset)
            );
            for (i, ((lq, lf), g)) in q
                .layers
                .iter()
                .zip(&f.layers)
                .zip(&quant.layers)
                .enumerate()
            {
                assert_eq!((lq.c_in, lq.c_out), (lf.c_in, lf.c_out));
                let Some(g) = g else {
                    // A float layer of a mixed-precision file: the f32 file's weights.
                    assert!(i == 0 || i + 1 == quant.layers.len(), "{kind:?} layer {i}");
                    assert_eq!((&lq.weights, &lq.bias), (&lf.weights, &lf.bias));
                    continue;
                };
                // The dequantised weights are the s8 codes times their scale, and within half a step of the
                // f32 file's weights (the file was quantised from them).
                let per = lq.c_in * 9;
                for (j, (&wq, &wf)) in lq.weights.iter().zip(&lf.weights).enumerate() {
                    let s = g.weight_scales[j / per];
                    assert_eq!(wq, g.weights[j] as f32 * s);
                    assert!(
                        (wq - wf).abs() <= 0.5 * s * 1.001,
                        "{kind:?} layer {i}: {wq} vs {wf}"
                    );
                }
                for (bq, bf) in lq.bias.iter().zip(&lf.bias) {
                    assert!((bq - bf).abs() < 1e-3 * bf.abs().max(1.0), "{bq} vs {bf}");
                }
                // Layer i writes what layer i + 1 reads.
                match quant.layers.get(i + 1) {
                    Some(Some(next)) => assert_eq!(g.output, Some(next.input)),
                    // The float last layer of a mixed-precision file reads s_{N−1} on a grid of its own.
                    Some(None) => assert!(g.output.is_some(), "{kind:?}"),
                    // The exporter leaves the last convolution's output float (export.py).
                    None => assert_eq!(g.output, None, "{kind:?}"),
                }
            }
            // Hidden activations after a ReLU are ≥ 0: their grids start at code 0.
            let second = quant.layers[1].as_ref().expect("an int8 second layer");
            assert_eq!(second.input.zero_point, 0, "{kind:?}");
        }
        // The hologram CNN's centred input x − 0.5 spans [−0.5, 0.5]: zero point 128, 1/255 per step.
        let q = CnnWeights::from_model(
            &embedded::hologram_model(8, Precision::Int8Qdq, &config()).unwrap(),
        )
        .unwrap();
        let g0 = q.quant.unwrap().layers[0]
            .clone()
            .expect("an int8 first layer")
            .input;
        assert_eq!(g0.zero_point, 128);
        assert!((g0.scale - 1.0 / 255.0).abs() < 1e-6, "{g0:?}");
    }

    #[test]
    fn a_mixed_precision_file_has_float_ends_and_its_concat_must_read_a_rounded_hidden_state() {
        // The shipped int8 pre-filters (export --float-convs first last): f32 first and last layers, int8
        // between, s_{N−1} rounded to a grid of its own before the concat.
        let qdq = embedded::prefilter_model(6, Precision::Int8Qdq, &config()).unwrap();
        let good = qdq.onnx_graph().clone();
        let q = CnnWeights::from_graph(&good, ModelKind::PreFilter, "mixed").unwrap();
        let quant = q.quant.as_ref().unwrap();
        let n = quant.layers.len();
        assert!(quant.layers[0].is_none() && quant.layers[n - 1].is_none());
        assert!(quant.layers[1..n - 1].iter().all(Option::is_some));
        // s_{N−1} is a sum of ReLU outputs: its own grid starts at code 0.
        let hidden = quant.layers[n - 2].as_ref().unwrap().output.unwrap();
        assert_eq!(hidden.zero_point, 0);
        // A concat of the unrounded hidden state is not what the native engine computes: refused.
        let mut bad = good;
        let cat = bad.node.iter().position(|n| n.op_type == "Concat").unwrap();
        let made_by = |g: &pb::GraphProto, t: &str| {
            g.node.iter().find(|n| n.output[0] == t).unwrap().input[0].clone()
        };
        let q_out = made_by(&bad, &bad.node[cat].input[0]);
        let unrounded = made_by(&bad, &q_out);
        bad.node[cat].input[0] = unrounded;
        let err = CnnWeights::from_graph(&bad, ModelKind::PreFilter, "unrounded")
            .unwrap_err()
            .to_string();
        assert!(err.contains("mixed-precision"), "{err}");
    }

    #[test]
    fn per_channel_weight_scales_are_read_along_the_output_channels() {
        let qdq = embedded::hologram_model(8, Precision::Int8Qdq, &config()).unwrap();
        let good = qdq.onnx_graph().clone();
        let q = CnnWeights::from_graph(&good, ModelKind::Hologram, "qdq").unwrap();
        // The shipped QDQ files carry one scale per output channel (training/.../export.py, per_channel):
        // each channel's largest |code| is 127 (symmetric MinMax), so the scales differ between channels.
        for (l, g) in q.layers.iter().zip(&q.quant.as_ref().unwrap().layers) {
            let Some(g) = g else { continue };
            let per = l.c_in * 9;
            for (c, chunk) in g.weights.chunks(per).enumerate() {
                let top = chunk.iter().map(|&v| v.unsigned_abs()).max().unwrap();
                assert!(top >= 126, "channel {c}: largest code {top}");
            }
            let (lo, hi) = g
                .weight_scales
                .iter()
                .fold((f32::MAX, 0f32), |(a, b), &s| (a.min(s), b.max(s)));
            assert!(hi > 1.05 * lo, "scales {lo}..{hi}");
        }
        // ONNX's default axis is 1: per-channel scales without `axis = 0` would scale input channels.
        let mut bad = good;
        let dq = bad
            .node
            .iter_mut()
            .find(|n| {
                n.op_type == "DequantizeLinear" && n.attribute.iter().any(|a| a.name == "axis")
            })
            .expect("a per-channel DequantizeLinear");
        dq.attribute.retain(|a| a.name != "axis");
        let err = CnnWeights::from_graph(&bad, ModelKind::Hologram, "axis")
            .unwrap_err()
            .to_string();
        assert!(err.contains("axis 1"), "{err}");
    }
}

"""ONNX export of trained CNNs (``docs/CONVENTIONS.md`` §7) and int8 static quantisation.

``python -m tensorholo_training.export --checkpoint RUN/final.pt --out-dir models --name NAME
[--int8 --calib-dataset DIR]``

Files (``NAME`` e.g. ``holo30_rgbd_6mm``):

- ``NAME.onnx``: hologram CNN, float32, opset 17, input ``rgbd`` ``[1, 4·L, H, W]`` with symbolic ``H``,
  ``W``; outputs ``amplitude`` and ``phase`` ``[1, 3, H, W]``;
- ``NAME.prefilter.onnx``: the DDPM pre-filter CNN (only when the run trained one), input ``slm_field``
  ``[1, 6, H, W]`` = ``[Re H, Im H]`` of the offset hologram, outputs ``real`` and ``imag`` ``[1, 3, H, W]``
  of the filtered field (format version 2; the AA-DPM base blur is a ``Pad(edge)`` + depthwise ``Conv`` and
  the residual an ``Add`` inside the graph, :class:`.model.PrefilterCNN`);
- with ``--int8``, for each: ``.int8-qop.onnx`` (QOperator: ``QLinearConv``; only ``Conv`` nodes are
  quantised, so residual ``Add``, ``Concat``, ``Relu`` and ``Tanh`` stay float, because tract 0.23 runs
  ``QLinearConv`` but not ``QLinearAdd``) and ``.int8-qdq.onnx`` (QDQ: ``QuantizeLinear``/``DequantizeLinear``
  pairs around float ``Conv``, which tract folds). Static calibration (MinMax) on training inputs and
  optionally real frames (``--calib-npy``); weights int8 symmetric with one scale per output channel (the native
  engine's scheme; ``--per-tensor`` for one per tensor), activations uint8 with a zero point. The pre-filter's fixed blur stays float (it is not learned,
  and its output carries the whole field, while the learned correction is small).

Every file carries ``metadata_props`` (all keys prefixed ``tensorholo.``): ``kind`` (``hologram-cnn`` or
``prefilter-cnn``), ``layers``, ``wavelengths_m`` (comma-separated, R,G,B), ``pixel_pitch_m``,
``volume_depth_m``, ``offset_m``, ``input_layers``, ``trained_resolution`` (``HxW``), ``training_commit``, plus
``precision`` (``f32``, ``int8-qoperator-conv``, ``int8-qdq-conv``), ``channels``, ``format_version`` and ``io``
(a one-line statement of the input/output semantics), and for a pre-filter ``prefilter_base``
(``aa-dpm(sigma_px=0.7,taps=5)`` or ``identity``) and ``hologram_layers`` (the depth of the hologram CNN it
was trained with); ``aberration`` (compact ``tensorholo.aberration`` JSON) when the training data was corrected
for aberrations (the dataset manifest's ``synthesis.aberration``).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import warnings
from typing import Iterable, Sequence

import numpy as np
import torch

from .model import PrefilterCNN, ResidualCNN, hologram_cnn, load_prefilter_state, prefilter_cnn

INPUT_NAMES = {"hologram-cnn": "rgbd", "prefilter-cnn": "slm_field"}
OUTPUT_NAMES = {"hologram-cnn": ("amplitude", "phase"), "prefilter-cnn": ("real", "imag")}
#: ``tensorholo.format_version`` per kind: 2 for the Cartesian pre-filter (``[Re, Im]`` in and out), 1 for the
#: hologram CNN (unchanged since version 1).
FORMAT_VERSION = {"hologram-cnn": "1", "prefilter-cnn": "2"}
METADATA_PREFIX = "tensorholo."
IO_DESCRIPTION = {
    "hologram-cnn": "rgbd[1,4L,H,W] in [0,1], per layer r,g,b amplitude then depth d (0 = near) -> "
                    "amplitude[1,3,H,W] in [0,sqrt2], phase[1,3,H,W] in [0,1] meaning (p-0.5)*2pi rad: "
                    "the midpoint hologram, R,G,B",
    "prefilter-cnn": "slm_field[1,6,H,W] = Re H (R,G,B), Im H (R,G,B) of H = ASM(H_mid, s)*exp(-i 2pi s/lambda) "
                     "(midpoint amplitude units, not rescaled) -> real[1,3,H,W], imag[1,3,H,W] of the filtered "
                     "field H' = base(H) + CNN(H), then double phase encoding",
}


def model_metadata(
    kind: str,
    module: ResidualCNN | PrefilterCNN,
    wavelengths_m: Sequence[float],
    pixel_pitch_m: float,
    volume_depth_m: float,
    offset_m: float,
    input_layers: int,
    trained_resolution: Sequence[int],
    training_commit: str,
    precision: str = "f32",
    hologram_layers: int | None = None,
    aberration: dict | None = None,
) -> dict[str, str]:
    """The ``metadata_props`` of an exported CNN (``docs/CONVENTIONS.md`` §7.3), keys prefixed ``tensorholo.``.

    Args:
        kind: ``"hologram-cnn"`` or ``"prefilter-cnn"``.
        module: the network (its layer and channel counts are recorded).
        wavelengths_m: R, G, B wavelengths in metres; pixel_pitch_m, volume_depth_m, offset_m: metres.
        input_layers: ``L`` of the hologram CNN (for a pre-filter: that of the hologram CNN it was trained with).
        trained_resolution: ``(H, W)`` of the training crops.
        training_commit: git commit of the training code.
        precision: ``f32``, ``int8-qoperator-conv`` or ``int8-qdq-conv``.
        hologram_layers: for a pre-filter, the depth of the hologram CNN it was trained with (written as
            ``tensorholo.hologram_layers``; the SDK runs a pre-filter by default only with that CNN's depth).
        aberration: the ``tensorholo.aberration`` profile the training data was corrected for (the dataset
            manifest's ``synthesis.aberration.profile``), written as ``tensorholo.aberration`` (compact JSON);
            ``None``: none (the key is left out).
    Returns:
        dict of strings.
    """
    if kind not in INPUT_NAMES:
        raise ValueError(f"kind must be one of {sorted(INPUT_NAMES)}, got {kind!r}")
    values = {
        "kind": kind,
        "layers": str(module.num_layers),
        "channels": str(module.channels),
        "wavelengths_m": ",".join(repr(float(w)) for w in wavelengths_m),
        "pixel_pitch_m": repr(float(pixel_pitch_m)),
        "volume_depth_m": repr(float(volume_depth_m)),
        "offset_m": repr(float(offset_m)),
        "input_layers": str(int(input_layers)),
        "trained_resolution": f"{int(trained_resolution[0])}x{int(trained_resolution[1])}",
        "training_commit": training_commit,
        "precision": precision,
        "format_version": FORMAT_VERSION[kind],
        "io": IO_DESCRIPTION[kind],
    }
    if hologram_layers is not None:
        values["hologram_layers"] = str(int(hologram_layers))
    if aberration is not None:
        values["aberration"] = json.dumps(aberration, separators=(",", ":"), sort_keys=True)
    if isinstance(module, PrefilterCNN):
        values["prefilter_base"] = (f"aa-dpm(sigma_px={module.sigma_px!r},taps={module.size})"
                                    if module.base == "aa-dpm" else module.base)
    return {METADATA_PREFIX + k: v for k, v in values.items()}


def set_metadata(path: str, metadata: dict[str, str]) -> None:
    """Replaces the ``metadata_props`` of the ONNX file at ``path`` by ``metadata`` (others are kept)."""
    import onnx

    m = onnx.load(path)
    keep = [p for p in m.metadata_props if p.key not in metadata]
    del m.metadata_props[:]
    m.metadata_props.extend(keep)
    for k, v in metadata.items():
        p = m.metadata_props.add()
        p.key, p.value = k, v
    onnx.save(m, path)


def read_metadata(path: str) -> dict[str, str]:
    """The ``metadata_props`` of an ONNX file as a dict."""
    import onnx

    return {p.key: p.value for p in onnx.load(path).metadata_props}


def export_onnx(module: ResidualCNN | PrefilterCNN, path: str, kind: str, metadata: dict[str, str], example_size=(64, 64),
                opset: int = 17) -> str:
    """Exports a CNN to ONNX (float32, batch 1, symbolic ``H``, ``W``) and writes its metadata.

    Args:
        module: the network (moved to CPU float32 for export).
        path: output ``.onnx`` path.
        kind: ``"hologram-cnn"`` (input ``rgbd``) or ``"prefilter-cnn"`` (input ``slm_field``).
        metadata: from :func:`model_metadata`.
        example_size: ``(H, W)`` of the tracing input (any; the graph is size-independent).
        opset: ONNX opset (17).
    Returns:
        ``path``.
    """
    module = module.to("cpu").float().eval()
    x = torch.rand(1, module.in_channels, *example_size)
    name = INPUT_NAMES[kind]
    outputs = list(OUTPUT_NAMES[kind])
    axes = {2: "H", 3: "W"}
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with torch.no_grad(), warnings.catch_warnings():
        # The TorchScript exporter (dynamo=False) is deprecated but needs no onnxscript and gives plain graphs.
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(
            module, (x,), path, dynamo=False, opset_version=opset, input_names=[name],
            output_names=outputs, dynamic_axes={name: axes} | {o: axes for o in outputs},
            do_constant_folding=True,
        )
    set_metadata(path, metadata)
    return path


class _Reader:
    """onnxruntime ``CalibrationDataReader`` over a list of input arrays."""

    def __init__(self, name: str, inputs: Iterable[np.ndarray]):
        self.name = name
        self.items = iter(list(inputs))

    def get_next(self):
        x = next(self.items, None)
        return None if x is None else {self.name: x.astype(np.float32)}


#: values of the ``tensorholo.int8_weights`` metadata (docs/CONVENTIONS.md §7)
INT8_WEIGHTS = ("f32-file", "bias-corrected", "quantisation-aware")


def quantize_int8(f32_path: str, out_path: str, calibration: Sequence[np.ndarray], fmt: str = "qoperator",
                  per_channel: bool = True, calib_method: str = "minmax", float_convs: Sequence[str] = (),
                  weights: str = "f32-file") -> str:
    """Static int8 quantisation of the ``Conv`` nodes only (onnxruntime.quantization, MinMax calibration by
    default):
    symmetric s8 weights, one scale per output channel (``per_channel``, what the native engine's int8 kernels
    apply; ``axis`` 0 of the weight's ``DequantizeLinear``) or one per tensor; u8 activations with a zero
    point, one scale per tensor.

    Args:
        f32_path: float32 model from :func:`export_onnx`.
        out_path: output path.
        calibration: inputs ``[1, C, H, W]`` float32 (training crops, real frames), e.g. 16–64 of them.
        fmt: ``"qoperator"`` (``QLinearConv``) or ``"qdq"`` (Q/DQ pairs around float ``Conv``).
        per_channel: weight scales per output channel (default) or per tensor.
        calib_method: ``"minmax"`` (each activation's range over the calibration inputs) or ``"percentile"``
            (its 99.99th percentile of absolute values, onnxruntime's ``CalibPercentile``).
        float_convs: learned convolutions left in float: ``"first"`` (it reads the float input), ``"last"``
            (float weights for the heads' input or the pre-filter's correction, reading the float input and, in
            the QDQ file, the last hidden state rounded to a grid of its own). Both is the native engine's mixed
            precision (the shipped int8 pre-filters); either alone runs on tract only. Metadata
            ``tensorholo.int8_float_convs``.
        weights: metadata ``tensorholo.int8_weights``: ``"f32-file"`` (the weights are the shipped f32 file's),
            ``"bias-corrected"`` (its weights, biases corrected, :func:`.qat.bias_correction`) or
            ``"quantisation-aware"`` (fine-tuned with the int8 roundings, :mod:`.qat`).
    Returns:
        ``out_path`` (metadata copied, ``tensorholo.precision`` updated).
    """
    from onnxruntime.quantization import CalibrationMethod, QuantFormat, QuantType, quantize_static

    methods = {"minmax": CalibrationMethod.MinMax, "percentile": CalibrationMethod.Percentile}
    if calib_method not in methods:
        raise ValueError(f"calib_method must be one of {sorted(methods)}, got {calib_method!r}")
    if weights not in INT8_WEIGHTS:
        raise ValueError(f"weights must be one of {INT8_WEIGHTS}, got {weights!r}")
    if set(float_convs) - {"first", "last"}:
        raise ValueError(f"float_convs may hold 'first' and 'last', got {list(float_convs)}")

    formats = {"qoperator": (QuantFormat.QOperator, "int8-qoperator-conv"),
               "qdq": (QuantFormat.QDQ, "int8-qdq-conv")}
    if fmt not in formats:
        raise ValueError(f"fmt must be 'qoperator' or 'qdq', got {fmt!r}")
    qformat, precision = formats[fmt]
    meta = read_metadata(f32_path)
    import tempfile

    import onnx
    from onnxruntime.quantization.shape_inference import quant_pre_process

    name = onnx.load(f32_path).graph.input[0].name
    extra = {"WeightSymmetric": True, "ActivationSymmetric": False, "CalibPercentile": 99.99}
    if fmt == "qdq":
        # A convolution's raw output is not rounded: what the next convolution reads is (after the ReLU and
        # the residual add), once, as the native engine's fused layers do; the last one's output (the heads'
        # or the pre-filter's correction) stays float.
        extra["OpTypesToExcludeOutputQuantization"] = ["Conv"]
    with tempfile.TemporaryDirectory() as tmp:
        prepared = os.path.join(tmp, "prepared.onnx")
        quant_pre_process(f32_path, prepared)
        # Grouped convolutions are the pre-filter's fixed AA-DPM blur: kept in float (see the module docs).
        convs = [n for n in onnx.load(prepared).graph.node if n.op_type == "Conv"]
        fixed = [n.name for n in convs if any(a.name == "group" and a.i > 1 for a in n.attribute)]
        learned = [n.name for n in convs if n.name not in fixed]
        fixed += [learned[0]] if "first" in float_convs else []
        fixed += [learned[-1]] if "last" in float_convs else []
        if fmt == "qoperator" and learned[-1] not in fixed:
            # A QLinearConv rounds its output by definition: the last one (the heads' input, the pre-filter's
            # correction) stays a float Conv, as the QDQ file leaves that output float.
            fixed.append(learned[-1])
        quantize_static(
            prepared, out_path, _Reader(name, calibration), quant_format=qformat, op_types_to_quantize=["Conv"],
            per_channel=per_channel, activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8,
            nodes_to_exclude=fixed, extra_options=extra, calibrate_method=methods[calib_method],
        )
        if fmt == "qdq" and "last" in float_convs:
            _round_concat_hidden_input(out_path, prepared, calibration, calib_method)
    if fmt == "qdq":
        _float_blur_input(out_path)
    meta[METADATA_PREFIX + "precision"] = precision
    meta[METADATA_PREFIX + "int8_weight_scales"] = "per-output-channel" if per_channel else "per-tensor"
    meta[METADATA_PREFIX + "int8_weights"] = weights
    meta[METADATA_PREFIX + "int8_float_convs"] = " ".join(c for c in ("first", "last") if c in float_convs) or "none"
    meta[METADATA_PREFIX + "int8_calibration"] = {"minmax": "minmax", "percentile": "percentile-99.99"}[calib_method]
    set_metadata(out_path, meta)
    return out_path


def _round_concat_hidden_input(path: str, f32_path: str, calibration: Sequence[np.ndarray],
                               calib_method: str) -> None:
    """Rounds the last convolution's hidden input ``s_{N−1}`` (the concat's first input) to a u8 grid of its own
    in a QDQ file whose last convolution is float (``float_convs`` holds ``"last"``): the native engine's
    mixed-precision layout (``docs/CONVENTIONS.md`` §7), where the int8 layer before writes ``s_{N−1}`` in u8
    and the f32 last layer reads it dequantised, beside the float input. Without it the file would read
    ``s_{N−1}`` unrounded, which no int8 engine computes. The grid is calibrated as the exporter's others, on
    ``calibration`` through the f32 graph ``f32_path``: MinMax, or the 99.99th percentile as the top of the
    range (``s_{N−1}`` is a sum of ReLU outputs, ≥ 0), with 0 on the grid.
    """
    import onnx
    import onnxruntime as ort
    from onnx import helper, numpy_helper

    model = onnx.load(path)
    graph = model.graph
    made_by = {o: n for n in graph.node for o in n.output}
    learned = [n for n in graph.node
               if n.op_type == "Conv" and not any(a.name == "group" and a.i > 1 for a in n.attribute)]
    cat = made_by.get(learned[-1].input[0])
    if cat is None or cat.op_type != "Concat":
        raise ValueError(f"{path}: the last convolution does not read a concat")
    hidden = cat.input[0]
    probe = onnx.load(f32_path)
    probe.graph.output.append(helper.make_tensor_value_info(hidden, onnx.TensorProto.FLOAT, None))
    session = ort.InferenceSession(probe.SerializeToString(), providers=["CPUExecutionProvider"])
    name = session.get_inputs()[0].name
    values = [session.run([hidden], {name: x.astype(np.float32)})[0] for x in calibration]
    lo = min(0.0, min(float(v.min()) for v in values))
    if calib_method == "percentile":
        hi = float(np.percentile(np.concatenate([v.ravel() for v in values]), 99.99))
    else:
        hi = float(max(v.max() for v in values))
    hi = max(hi, 0.0)
    scale = np.float32((hi - lo) / 255.0 if hi > lo else 1.0)
    zero = np.uint8(np.clip(round(-lo / float(scale)), 0, 255))
    tag = hidden + "_concat_u8"
    graph.initializer.extend([numpy_helper.from_array(np.array(scale, np.float32), tag + "_scale"),
                              numpy_helper.from_array(np.array(zero, np.uint8), tag + "_zero_point")])
    q = helper.make_node("QuantizeLinear", [hidden, tag + "_scale", tag + "_zero_point"], [tag + "_q"],
                         name=tag + "_QuantizeLinear")
    dq = helper.make_node("DequantizeLinear", [tag + "_q", tag + "_scale", tag + "_zero_point"], [tag],
                          name=tag + "_DequantizeLinear")
    at = list(graph.node).index(cat)
    graph.node.insert(at, dq)
    graph.node.insert(at, q)
    cat.input[0] = tag
    onnx.save(model, path)


def _float_blur_input(path: str) -> None:
    """Makes the pre-filter's fixed blur (its ``Pad`` → grouped ``Conv``) read the float graph input again.

    The QDQ pass rounds the graph input to u8 for the first learned convolution and hands that rounded tensor
    to every consumer, the blur's ``Pad`` included, so the whole field (not only the small learned correction)
    would pass through 8 bits: −0.26 dB displayed for the 30-layer CNN's 6 mm pre-filter. The QOperator form
    and the SDK's native int8 engine already blur the float input. A hologram CNN has no ``Pad``: unchanged.
    """
    import onnx

    model = onnx.load(path)
    graph_inputs = {i.name for i in model.graph.input}
    quantised = {n.output[0]: n.input[0] for n in model.graph.node
                 if n.op_type == "QuantizeLinear" and n.input[0] in graph_inputs}
    dequantised = {n.output[0]: quantised[n.input[0]] for n in model.graph.node
                   if n.op_type == "DequantizeLinear" and n.input[0] in quantised}
    changed = False
    for n in model.graph.node:
        if n.op_type == "Pad" and n.input[0] in dequantised:
            n.input[0] = dequantised[n.input[0]]
            changed = True
    if changed:
        onnx.save(model, path)


def run_onnx(path: str, x: np.ndarray, threads: int = 1, exact: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Runs an exported CNN with onnxruntime on CPU.

    Args:
        path: ``.onnx`` file; x: float32 ``[1, C, H, W]``.
        threads: onnxruntime's intra-op threads.
        exact: evaluate an int8 file's arithmetic exactly, independent of the CPU: every ``QLinearConv`` is
            rewritten to ``DequantizeLinear`` → float ``Conv`` → ``QuantizeLinear`` (the operator's definition)
            and graph optimisation is off, so no integer kernel runs. Without it, onnxruntime's u8×s8 kernel
            on x86 CPUs without VNNI (AVX2 ``vpmaddubsw``) saturates pairs of products at int16 and some
            outputs come out wrong by up to ~0.3 (measured on a Zen 3); the file itself is not at fault.
    Returns:
        its two outputs, float32 ``[1, 3, H, W]`` each: ``(amplitude, phase)`` of a hologram CNN, ``(real,
        imag)`` of a pre-filter.
    """
    sess = onnx_session(path, threads, exact)
    name = sess.get_inputs()[0].name
    first, second = sess.run(None, {name: x.astype(np.float32)})
    return first, second


def onnx_session(path: str, threads: int = 1, exact: bool = False):
    """An onnxruntime CPU session for an exported file; ``exact`` as in :func:`run_onnx`."""
    import onnx
    import onnxruntime as ort

    so = ort.SessionOptions()
    so.intra_op_num_threads = threads
    so.log_severity_level = 3
    model: str | bytes = path
    if exact:
        so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_DISABLE_ALL
        model = _qlinearconv_as_float(onnx.load(path)).SerializeToString()
    return ort.InferenceSession(model, so, providers=["CPUExecutionProvider"])


def _qlinearconv_as_float(model):
    """Rewrites each ``QLinearConv`` as ``DequantizeLinear`` (input, weight) → ``Conv`` → ``QuantizeLinear``,
    its definition in the ONNX operator spec; an int32 bias becomes ``B · x_scale · w_scale`` in float."""
    from onnx import TensorProto, helper

    nodes = []
    for n in model.graph.node:
        if n.op_type != "QLinearConv":
            nodes.append(n)
            continue
        x, xs, xz, w, ws, wz, ys, yz = n.input[:8]
        t = f"{n.name or n.output[0]}_exact"
        nodes += [helper.make_node("DequantizeLinear", [x, xs, xz], [t + "_x"]),
                  helper.make_node("DequantizeLinear", [w, ws, wz], [t + "_w"], axis=0)]
        conv_in = [t + "_x", t + "_w"]
        if len(n.input) > 8 and n.input[8]:
            nodes += [helper.make_node("Cast", [n.input[8]], [t + "_bi"], to=TensorProto.FLOAT),
                      helper.make_node("Mul", [xs, ws], [t + "_bs"]),
                      helper.make_node("Mul", [t + "_bi", t + "_bs"], [t + "_b"])]
            conv_in.append(t + "_b")
        conv = helper.make_node("Conv", conv_in, [t + "_y"])
        conv.attribute.extend(n.attribute)
        nodes += [conv, helper.make_node("QuantizeLinear", [t + "_y", ys, yz], [n.output[0]])]
    del model.graph.node[:]
    model.graph.node.extend(nodes)
    return model


def load_checkpoint(path: str) -> dict:
    """Loads a training checkpoint and rebuilds its networks: ``{"net", "prefilter" (or None), "config",
    "training_commit", "trained_resolution"}``."""
    s = torch.load(path, map_location="cpu", weights_only=False)
    cfg = s["config"]
    net = hologram_cnn(cfg["num_layers"], cfg["input_layers"], cfg["channels"])
    net.load_state_dict(s["net"])
    pre = None
    if s.get("prefilter") is not None:
        pre = prefilter_cnn(cfg["prefilter_layers"], cfg["prefilter_channels"], cfg.get("prefilter_base", "aa-dpm"),
                            cfg.get("aa_sigma_px", 0.7), cfg.get("aa_kernel_size", 5))
        load_prefilter_state(pre, s["prefilter"], path)
    return {"net": net.eval(), "prefilter": pre.eval() if pre is not None else None, "config": cfg,
            "training_commit": s.get("training_commit", "unknown"),
            "trained_resolution": s.get("trained_resolution", [0, 0])}


def load_onnx_network(path: str) -> tuple[torch.nn.Module, dict[str, str]]:
    """The network of an exported f32 ONNX file rebuilt in PyTorch, the inverse of :func:`export_onnx` with
    :func:`model_metadata`: the architecture from ``tensorholo.layers``, ``channels``, ``input_layers`` and
    ``prefilter_base``, the weights from the initialisers (:func:`.train.initial_state`). Returns ``(net in eval
    mode, metadata)``.

    Raises:
        ValueError: an int8 file, an unknown ``tensorholo.kind``, a missing or unknown ``prefilter_base``.
    """
    from .train import initial_state

    md = read_metadata(path)
    layers, channels = int(md[METADATA_PREFIX + "layers"]), int(md[METADATA_PREFIX + "channels"])
    state = initial_state(path, "cpu")
    if md[METADATA_PREFIX + "kind"] == "hologram-cnn":
        net = hologram_cnn(layers, int(md[METADATA_PREFIX + "input_layers"]), channels)
        net.load_state_dict(state["net"])
        return net.eval(), md
    base = md.get(METADATA_PREFIX + "prefilter_base", "<missing>")
    if base.startswith("aa-dpm(") and base.endswith(")"):  # model_metadata's aa-dpm(sigma_px=…,taps=…)
        args = dict(kv.split("=", 1) for kv in base[len("aa-dpm("):-1].split(","))
        pre = prefilter_cnn(layers, channels, "aa-dpm", float(args["sigma_px"]), int(args["taps"]))
    elif base == "identity":
        pre = prefilter_cnn(layers, channels, "identity")
    else:
        raise ValueError(f"{path}: tensorholo.prefilter_base {base!r}")
    load_prefilter_state(pre, state["prefilter"], path)
    return pre.eval(), md


def calibration_inputs(dataset_root: str, input_layers: int, count: int = 32, size: int | None = None,
                       split: str = "train", seed: int = 0) -> list[np.ndarray]:
    """Hologram-CNN calibration inputs ``[1, 4·L, h, w]`` from a dataset (random crops of ``size`` if given)."""
    from .data import Augment, LdiDataset

    ds = LdiDataset(dataset_root, split, input_layers, Augment((size, size) if size else None), seed=seed)
    idx = np.random.default_rng(seed).permutation(len(ds))[:count]
    return [ds[int(i)]["rgbd"].numpy()[None] for i in idx]


def exporter_grids(net: torch.nn.Module, kind: str, inputs: Sequence[np.ndarray], calib_method: str = "minmax"
                   ) -> list:
    """The grids :func:`quantize_int8` gives ``net`` (a copy of it exported to a temporary QDQ file)
    calibrated on ``inputs`` (each ``[1, C, h, w]``) with ``calib_method``: the rounding a fine-tuning should
    learn, exactly as the int8 file written from the same weights will have it.

    Args:
        net: a hologram CNN or a pre-filter CNN; kind: ``"hologram-cnn"`` or ``"prefilter-cnn"``.
    Returns:
        one :class:`.qat.Grid` per convolution of :func:`.qat.learned_convs`.
    """
    import copy
    import tempfile

    from . import qat

    with tempfile.TemporaryDirectory() as tmp:
        f32 = export_onnx(copy.deepcopy(net), os.path.join(tmp, "f32.onnx"), kind, {})
        q = quantize_int8(f32, os.path.join(tmp, "q.onnx"), list(inputs), "qdq", calib_method=calib_method)
        return qat.file_grids(q)


def prefilter_calibration_inputs(net, calib: Sequence[np.ndarray], offset_m: float, display) -> list[np.ndarray]:
    """The pre-filter's calibration inputs ``[1, 6, h, w]``: each hologram-CNN calibration input through ``net``
    (the hologram CNN the pre-filter was trained behind), offset to the SLM plane (Eq. 6, ``offset_m`` metres),
    as ``[Re, Im]`` channels (:func:`.model.prefilter_input`)."""
    from .model import prefilter_input
    from .optics import amp_phase_to_complex, offset_to_slm

    out = []
    with torch.no_grad():
        for x in calib:
            a, p = net(torch.from_numpy(x))
            out.append(prefilter_input(offset_to_slm(amp_phase_to_complex(a, p), offset_m, display)).numpy())
    return out


def frame_calibration_inputs(paths: Sequence[str], input_layers: int, crops_per_frame: int, size: int | None,
                             seed: int = 0) -> list[np.ndarray]:
    """Calibration inputs ``[1, 4·L, h, w]`` from hologram CNN inputs saved by ``holo render --save-cnn-input``
    (``[4·L, H, W]`` float32 ``.npy``, e.g. the real frames of ``training/real_frames.py inputs``): ``crops_per_frame``
    random crops of ``size`` each (the whole frame if ``size`` is None or larger than the frame). An RGB-D input
    ``[4, H, W]`` for an LDI CNN is a one-layer LDI: the layers behind it are empty (amplitude 0, depth 1, what
    the SDK feeds an LDI CNN for an RGB-D frame, ``docs/CONVENTIONS.md`` §7).

    Raises:
        ValueError: a file that is neither ``[4·input_layers, H, W]`` nor ``[4, H, W]``.
    """
    rng = np.random.default_rng(seed)
    out = []
    for p in paths:
        x = np.load(p).astype(np.float32)
        if x.ndim == 4 and x.shape[0] == 1:
            x = x[0]
        if x.ndim == 3 and x.shape[0] == 4 and input_layers > 1:
            empty = np.zeros((4 * (input_layers - 1),) + x.shape[1:], np.float32)
            empty[3::4] = 1.0
            x = np.concatenate([x, empty])
        if x.ndim != 3 or x.shape[0] != 4 * input_layers:
            raise ValueError(f"{p}: shape {x.shape}, expected [{4 * input_layers}, H, W] "
                             f"(holo render --save-cnn-input with a {input_layers}-layer-input CNN)")
        _, h, w = x.shape
        for _ in range(crops_per_frame):
            if size is None or size >= min(h, w):
                out.append(x[None])
                break
            i, j = int(rng.integers(0, h - size + 1)), int(rng.integers(0, w - size + 1))
            out.append(np.ascontiguousarray(x[None, :, i:i + size, j:j + size]))
    return out


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (see the module docstring)."""
    ap = argparse.ArgumentParser(prog="python -m tensorholo_training.export", description=__doc__.split("\n\n")[0])
    ap.add_argument("--checkpoint", required=True, help="training checkpoint (final.pt / stage1.pt)")
    ap.add_argument("--out-dir", required=True)
    ap.add_argument("--name", required=True, help="file stem, e.g. holo30_rgbd_6mm")
    ap.add_argument("--int8", action="store_true", help="also write int8 QOperator and QDQ models")
    ap.add_argument("--calib-dataset", help="dataset for int8 calibration (default: the run's dataset)")
    ap.add_argument("--calib-samples", type=int, default=32)
    ap.add_argument("--calib-size", type=int, default=0, help="crop size of calibration inputs (0 = full)")
    ap.add_argument("--calib-npy", nargs="*", default=[],
                    help="hologram CNN inputs [4L,H,W] of real frames (holo render --save-cnn-input; "
                         "training/real_frames.py inputs) added to the calibration set, --calib-crops crops each")
    ap.add_argument("--calib-crops", type=int, default=4, help="calibration crops per --calib-npy frame")
    ap.add_argument("--calib-method", choices=["minmax", "percentile"], default="minmax",
                    help="activation ranges: MinMax (default) or the 99.99th percentile")
    ap.add_argument("--float-convs", nargs="*", choices=["first", "last"], default=[],
                    help="learned convolutions of the int8 files left in float (first: reads the float input; "
                         "last: float weights for the heads' input or the pre-filter's correction); both: the "
                         "native engine's mixed precision (the shipped int8 pre-filters); either alone: tract only")
    ap.add_argument("--bias-correction", action="store_true",
                    help="int8 files quantised from the network with each convolution's bias corrected for the mean "
                         "error its rounding adds, measured on the calibration inputs (qat.bias_correction)")
    ap.add_argument("--int8-only", action="store_true",
                    help="write only the int8 files (implies --int8), e.g. from a quantisation-aware fine-tuning "
                         "run (qat_grids_from) whose f32 weights are not the shipped f32 file's")
    ap.add_argument("--per-tensor", action="store_true",
                    help="one weight scale per tensor (default: per output channel, the native engine's scheme)")
    only = ap.add_mutually_exclusive_group()
    only.add_argument("--no-prefilter", action="store_true", help="export only the hologram CNN")
    only.add_argument("--prefilter-only", action="store_true",
                      help="export only the pre-filter CNN (NAME.onnx, NAME.int8-*.onnx); the SDK pairs it with "
                           "any hologram CNN of the same optics (runs with stage2_train_hologram=false)")
    args = ap.parse_args(argv)
    ck = load_checkpoint(args.checkpoint)
    cfg = ck["config"]
    common = dict(wavelengths_m=cfg["wavelengths_m"], pixel_pitch_m=cfg["pixel_pitch_m"],
                  volume_depth_m=cfg["volume_depth_m"], offset_m=cfg["offset_mm"] * 1e-3,
                  input_layers=cfg["input_layers"], trained_resolution=ck["trained_resolution"],
                  training_commit=ck["training_commit"], aberration=cfg.get("aberration"))
    written = []
    os.makedirs(args.out_dir, exist_ok=True)
    int8_weights = "quantisation-aware" if cfg.get("qat_grids_from") else "f32-file"
    if args.int8_only:
        args.int8 = True
    import tempfile

    scratch = tempfile.TemporaryDirectory()
    # --int8-only: the f32 files (what the int8 ones are quantised from) are not kept
    f32_dir = scratch.name if args.int8_only else args.out_dir

    def int8_source(net, kind: str, inputs, f32_path: str) -> tuple[str, str]:
        """The f32 file the int8 files are quantised from and their ``int8_weights``: ``f32_path``, or with
        --bias-correction the network with corrected biases (qat.bias_correction), in the scratch folder."""
        if not args.bias_correction:
            return f32_path, "f32-file"
        from . import qat

        grids = exporter_grids(net, kind, inputs, args.calib_method)
        corrected = qat.bias_correction(net, grids, inputs)
        out = os.path.join(scratch.name, f"bias-corrected-{kind}.onnx")
        return export_onnx(corrected, out, kind, read_metadata(f32_path)), "bias-corrected"
    path = os.path.join(f32_dir, f"{args.name}.onnx")
    if args.prefilter_only and ck["prefilter"] is None:
        ap.error(f"{args.checkpoint} holds no pre-filter CNN (a 0 mm run?)")
    if not args.prefilter_only:
        export_onnx(ck["net"], path, "hologram-cnn", model_metadata("hologram-cnn", ck["net"], **common))
        written += [] if args.int8_only else [path]
    pre_path = None
    if ck["prefilter"] is not None and not args.no_prefilter:
        pre_path = path if args.prefilter_only else os.path.join(f32_dir, f"{args.name}.prefilter.onnx")
        export_onnx(ck["prefilter"], pre_path, "prefilter-cnn",
                    model_metadata("prefilter-cnn", ck["prefilter"], **common, hologram_layers=cfg["num_layers"]))
        written += [] if args.int8_only else [pre_path]
    if args.int8:
        root = args.calib_dataset or cfg["dataset"]
        if root == "synthetic":
            root = os.path.join(cfg["run_dir"], "synthetic_dataset")
        calib = calibration_inputs(root, cfg["input_layers"], args.calib_samples, args.calib_size or None)
        calib += frame_calibration_inputs(args.calib_npy, cfg["input_layers"], args.calib_crops,
                                          args.calib_size or None)
        for fmt, suffix in (("qoperator", "int8-qop"), ("qdq", "int8-qdq")):
            if args.prefilter_only:
                break
            out = os.path.join(args.out_dir, f"{args.name}.{suffix}.onnx")
            source, weights = int8_source(ck["net"], "hologram-cnn", calib, path)
            # (a qat run fine-tunes only the pre-filter: its hologram CNN's weights are the f32 file's)
            quantize_int8(source, out, calib, fmt, not args.per_tensor, args.calib_method, args.float_convs, weights)
            written.append(out)
        if pre_path is not None:
            from .optics import Display

            display = Display(tuple(cfg["wavelengths_m"]), cfg["pixel_pitch_m"], cfg["volume_depth_m"])
            pre_calib = prefilter_calibration_inputs(ck["net"], calib, cfg["offset_mm"] * 1e-3, display)
            for fmt, suffix in (("qoperator", "int8-qop"), ("qdq", "int8-qdq")):
                stem = args.name if args.prefilter_only else f"{args.name}.prefilter"
                out = os.path.join(args.out_dir, f"{stem}.{suffix}.onnx")
                source, weights = int8_source(ck["prefilter"], "prefilter-cnn", pre_calib, pre_path)
                quantize_int8(source, out, pre_calib, fmt, not args.per_tensor, args.calib_method,
                              args.float_convs, int8_weights if weights == "f32-file" else weights)
                written.append(out)
    print(json.dumps({"written": written, "metadata": read_metadata(path)}, indent=1))
    scratch.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())

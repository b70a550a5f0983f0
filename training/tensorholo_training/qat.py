"""Quantisation-aware fine-tuning for the native engine's int8 scheme (the SDK's ``cnn::native_int8``).

:func:`.export.quantize_int8` rounds, in every int8 file: each learned convolution's weights to s8, one
symmetric scale per output channel (``max|w| / 127``), and each activation a convolution reads to u8 on one
affine grid per tensor (calibrated over the calibration inputs: MinMax, ``scale = (max − min) / 255`` with
``0`` on the grid, or a percentile), once, where the convolution reads it. The last output (the heads' input, the pre-filter's correction)
and the pre-filter's fixed blur stay float.

:func:`fake_quantise` makes a network compute exactly those roundings in training (PyTorch's fake quantisation,
straight-through gradients), on the grids the exporter gives the starting weights (:func:`exporter_grids`,
from the same calibration inputs), so that a short fine-tuning lets the weights adapt to the 8-bit grids before the
int8 files are written from them. The network's parameters and ``state_dict`` are unchanged in form: the
roundings are a wrapper around each convolution's ``forward``, not parameters.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn


@dataclass(frozen=True)
class Grid:
    """An affine u8 grid ``real = (q − zero_point)·scale`` (ONNX ``QuantizeLinear``)."""

    scale: float
    zero_point: int


def learned_convs(net: nn.Module) -> list[nn.Conv2d]:
    """The learned convolutions of a hologram CNN or a pre-filter CNN, first to last (the pre-filter's fixed
    blur is a buffer, not a module)."""
    inner = getattr(net, "net", net)
    return list(inner.convs)


def file_grids(path: str) -> list[Grid]:
    """The u8 grid each learned convolution of an int8 QDQ file reads its input on, first to last (the
    ``DequantizeLinear`` feeding the convolution; the pre-filter's grouped blur is skipped).

    Raises:
        ValueError: a learned convolution whose input is not dequantised (not a QDQ file of the exporter).
    """
    import onnx
    from onnx import numpy_helper

    graph = onnx.load(path).graph
    inits = {i.name: numpy_helper.to_array(i) for i in graph.initializer}
    made_by = {o: n for n in graph.node for o in n.output}
    grids = []
    for n in graph.node:
        if n.op_type != "Conv" or any(a.name == "group" and a.i > 1 for a in n.attribute):
            continue
        dq = made_by.get(n.input[0])
        if dq is None or dq.op_type != "DequantizeLinear":
            raise ValueError(f"{path}: convolution {n.name} reads {n.input[0]}, not a dequantised tensor")
        grids.append(Grid(float(inits[dq.input[1]]), int(inits[dq.input[2]])))
    return grids


def exporter_grids(net: nn.Module, kind: str, inputs: Sequence[np.ndarray], calib_method: str = "minmax"
                   ) -> list[Grid]:
    """The grids :func:`.export.quantize_int8` gives ``net`` (a copy of it exported to a temporary QDQ file)
    calibrated on ``inputs`` (each ``[1, C, h, w]``) with ``calib_method``: the rounding a fine-tuning should
    learn, exactly as the int8 file written from the same weights will have it.

    Args:
        net: a hologram CNN or a pre-filter CNN; kind: ``"hologram-cnn"`` or ``"prefilter-cnn"``.
    Returns:
        one :class:`Grid` per convolution of :func:`learned_convs`.
    """
    import copy
    import tempfile

    from .export import export_onnx, quantize_int8

    with tempfile.TemporaryDirectory() as tmp:
        f32 = export_onnx(copy.deepcopy(net), os.path.join(tmp, "f32.onnx"), kind, {})
        q = quantize_int8(f32, os.path.join(tmp, "q.onnx"), list(inputs), "qdq", calib_method=calib_method)
        return file_grids(q)


def fake_quantised_weight(w: torch.Tensor) -> torch.Tensor:
    """``w`` ``[c_out, c_in, k, k]`` rounded to s8 with one symmetric scale per output channel
    (``max|w| / 127``), straight-through gradient."""
    scale = (w.detach().abs().flatten(1).amax(1) / 127.0).clamp_min(1e-12)
    zero = torch.zeros_like(scale, dtype=torch.int32)
    return torch.fake_quantize_per_channel_affine(w, scale, zero, 0, -127, 127)


def fake_quantise(net: nn.Module, grids: Sequence[Grid]) -> None:
    """Makes ``net`` compute the int8 file's roundings (see the module docs): each learned convolution's input
    rounded to its grid where it is made, so that every reader sees the rounded tensor, as the QDQ graph's
    ``DequantizeLinear`` feeds the convolution, a later residual add and the last layer's concat alike; and s8
    weights. :func:`remove_fake_quantisation` undoes it.

    Raises:
        ValueError: a grid count that is not the convolution count.
    """
    inner = getattr(net, "net", net)
    convs = learned_convs(net)
    if len(grids) != len(convs):
        raise ValueError(f"{len(grids)} grids for {len(convs)} convolutions")

    def round_input(i: int, x: torch.Tensor) -> torch.Tensor:
        return torch.fake_quantize_per_tensor_affine(x, grids[i].scale, grids[i].zero_point, 0, 255)

    inner.activation_quant = round_input
    for conv in convs:
        def forward(x, conv=conv):
            return F.conv2d(x, fake_quantised_weight(conv.weight), conv.bias, conv.stride, conv.padding,
                            conv.dilation, conv.groups)
        conv.forward = forward


def remove_fake_quantisation(net: nn.Module) -> None:
    """Restores the float network."""
    getattr(net, "net", net).activation_quant = None
    for conv in learned_convs(net):
        if "forward" in conv.__dict__:
            del conv.forward



def bias_correction(net: nn.Module, grids: Sequence[Grid], inputs: Sequence[np.ndarray]) -> nn.Module:
    """Bias correction of the int8 network (Nagel et al. 2019, "Data-free quantization", §4.2, with data): a
    copy of ``net`` whose every learned convolution's bias is lowered by the mean error its int8 form adds to
    that convolution's output, layer after layer (each measured with the layers before it already rounded and
    corrected), over ``inputs`` (each ``[1, C, h, w]``) and every pixel. Rounding leaves the mean of a
    channel's error, which a bias can take back; the rest is noise. Returns the copy in float: its weights are
    ``net``'s, its biases corrected, to be quantised as usual (:func:`.export.quantize_int8`)."""
    import copy

    corrected = copy.deepcopy(net).eval()
    fake = copy.deepcopy(net).eval()
    fake_quantise(fake, grids)
    convs_q, convs_f = learned_convs(fake), learned_convs(net)
    xs = [torch.from_numpy(x) for x in inputs]
    for conv_q, conv_f, conv_c in zip(convs_q, convs_f, learned_convs(corrected)):
        out: dict = {}
        hooks = [conv_q.register_forward_hook(lambda m, a, o: out.__setitem__("q", o.detach())),
                 conv_f.register_forward_hook(lambda m, a, o: out.__setitem__("f", o.detach()))]
        total = torch.zeros_like(conv_q.bias)
        with torch.no_grad():
            for x in xs:
                fake(x)
                net(x)
                total += (out["q"] - out["f"]).mean(dim=(0, 2, 3))
            for h in hooks:
                h.remove()
            shift = total / len(xs)
            conv_q.bias -= shift
            conv_c.bias -= shift
    return corrected

"""The native engine's int8 scheme (the SDK's ``cnn::native_int8``) in PyTorch: fake quantisation for
quantisation-aware fine-tuning, and bias correction.

:func:`.export.quantize_int8` rounds, in every int8 file: each learned convolution's weights to s8, one
symmetric scale per output channel (``max|w| / 127``), and each activation a convolution reads to u8 on one
affine grid per tensor (calibrated over the calibration inputs: MinMax, ``scale = (max − min) / 255`` with
``0`` on the grid, or a percentile), once, where the convolution reads it. The last output (the heads' input,
the pre-filter's correction) and the pre-filter's fixed blur stay float.

- :func:`fake_quantise` makes a network compute exactly those roundings (PyTorch's fake quantisation,
  straight-through gradients) on the grids of an int8 file (:func:`file_grids`;
  :func:`.export.exporter_grids` makes them without keeping a file), for a fine-tuning with the roundings in
  the loop (``train`` option ``qat_grids_from``). The parameters and ``state_dict`` keep their form: the
  roundings wrap each convolution's ``forward``. Measured on the shipped pre-filters: it did not bring the int8
  output closer to f32 (models/MODEL_CARD.md, "int8: what did not help").
- :func:`bias_correction` lowers each bias by the mean error its convolution's rounding adds
  (``export --bias-correction``): closer to f32 on held-out crops for every shipped pre-filter, not shipped.
"""
from __future__ import annotations

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

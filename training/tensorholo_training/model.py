"""The CNNs of Tensor Holography V2 (paper "Details of training", ``DESIGN.md`` §3).

Hologram CNN: ``num_layers`` 3×3 convolutions (8, 15 or 30) with 24 filters, ReLU, a residual connection every
two layers, and a last layer that sees the network input again (the input is concatenated to its input). The
last layer has 6 outputs through two heads:

- amplitude ``A = (tanh(o[:3]) + 1)/2·√2 ∈ [0, √2]``;
- phase ``p = (tanh(o[3:]) + 1)/2 ∈ [0, 1]``, meaning ``(p − 0.5)·2π`` radians.

Input ``rgbd`` ``[B, 4·L, H, W]`` in ``[0, 1]`` (``L = 1`` for RGB-D, 5 for an LDI; per layer ``r, g, b, d``,
depth 0 = near), centred by ``−0.5`` inside the network. Output: the midpoint hologram (Fig. 3).

Pre-filter CNN (DDPM, Eq. 6): the same architecture with 8 layers of 8 filters; input and output ``[B, 6, H, W]``
= amplitude and phase of the offset (SLM-plane) hologram in the same head semantics (see :func:`prefilter_input`).

Residual wiring (TensorHolo's): with ``y_i`` the output of layer ``i`` and ``s_i`` its input,
``s_0 = x``, ``s_i = y_{i−1}`` for ``i ∈ {1, 2}`` or ``i`` even, and ``s_i = y_{i−1} + s_{i−2}`` for odd
``i ≥ 3``, so each pair of layers ``(i−2, i−1)`` is bypassed by an identity; the last layer reads
``concat(s_{N−1}, x)``. No batch normalisation (at inference it would fold into the convolutions anyway).
"""
from __future__ import annotations

import math

import torch
from torch import nn

from .optics import amp_phase_to_complex, anti_alias_blur, complex_to_amp_phase

SQRT2 = math.sqrt(2.0)

#: Variants of the hologram CNN shipped by the SDK (number of convolution layers).
VARIANTS = (8, 15, 30)


class ResidualCNN(nn.Module):
    """TensorHolo residual CNN with amplitude/phase heads (see the module docstring).

    Args:
        num_layers: number of 3×3 convolutions (≥ 2).
        channels: filters per hidden layer (24 for the hologram CNN, 8 for the pre-filter).
        in_channels: input channels (``4·L`` for the hologram CNN, 6 for the pre-filter).
        out_channels: 6 (3 amplitude + 3 phase).
        centre_input: subtract 0.5 from the input first (inputs live in ``[0, 1]``).
    """

    def __init__(
        self,
        num_layers: int = 30,
        channels: int = 24,
        in_channels: int = 4,
        out_channels: int = 6,
        centre_input: bool = True,
    ):
        super().__init__()
        if num_layers < 2:
            raise ValueError(f"num_layers must be ≥ 2, got {num_layers}")
        if out_channels % 2:
            raise ValueError("out_channels must be even (amplitude and phase halves)")
        self.num_layers = num_layers
        self.channels = channels
        self.in_channels = in_channels
        self.out_channels = out_channels
        self.centre_input = centre_input
        convs = [nn.Conv2d(in_channels, channels, 3, padding=1)]
        convs += [nn.Conv2d(channels, channels, 3, padding=1) for _ in range(num_layers - 2)]
        convs.append(nn.Conv2d(channels + in_channels, out_channels, 3, padding=1))
        self.convs = nn.ModuleList(convs)

    def layer_inputs_are_residual(self) -> list[bool]:
        """For each layer, whether its input is ``y_{i−1} + s_{i−2}`` (a residual connection)."""
        return [i >= 3 and i % 2 == 1 for i in range(self.num_layers)]

    def raw(self, x: torch.Tensor) -> torch.Tensor:
        """Pre-activation output of the last layer.

        Args:
            x: float ``[B, in_channels, H, W]`` in ``[0, 1]``.
        Returns:
            float ``[B, out_channels, H, W]`` (before tanh).
        """
        if not torch.jit.is_tracing() and x.shape[1] != self.in_channels:
            raise ValueError(f"expected {self.in_channels} input channels, got {x.shape[1]}")
        xin = x - 0.5 if self.centre_input else x
        residual = self.layer_inputs_are_residual()
        inputs: list[torch.Tensor] = []
        y = xin
        for i, conv in enumerate(self.convs):
            if i == 0:
                s = xin
            elif residual[i]:
                s = y + inputs[i - 2]
            else:
                s = y
            inputs.append(s)
            if i == self.num_layers - 1:
                return conv(torch.cat([s, xin], dim=1))
            y = torch.relu(conv(s))
        raise AssertionError("unreachable")

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Runs the network.

        Args:
            x: float ``[B, in_channels, H, W]`` in ``[0, 1]``.
        Returns:
            ``(amplitude, phase)``: float ``[B, out/2, H, W]`` each; amplitude in ``[0, √2]``, phase in
            ``[0, 1]`` (meaning ``(p − 0.5)·2π`` rad).
        """
        o = self.raw(x)
        half = self.out_channels // 2
        amplitude = (torch.tanh(o[:, :half]) + 1.0) * (0.5 * SQRT2)
        phase = (torch.tanh(o[:, half:]) + 1.0) * 0.5
        return amplitude, phase


def hologram_cnn(num_layers: int = 30, input_layers: int = 1, channels: int = 24) -> ResidualCNN:
    """The hologram CNN: ``num_layers`` (8/15/30) layers of ``channels`` filters, input ``[B, 4·L, H, W]``.

    Args:
        num_layers: 8, 15 or 30 (other values are allowed for experiments).
        input_layers: ``L``: 1 for RGB-D input, 5 for the full LDI.
        channels: filters per layer (24 in the paper).
    Returns:
        a :class:`ResidualCNN` with 6 outputs (amplitude, phase).
    """
    return ResidualCNN(num_layers, channels, 4 * input_layers, 6)


def prefilter_cnn(num_layers: int = 8, channels: int = 8) -> ResidualCNN:
    """The DDPM pre-filter CNN: 8 layers × 8 filters, input/output ``[B, 6, H, W]`` (amplitude, phase)."""
    return ResidualCNN(num_layers, channels, 6, 6)


def prefilter_input(slm_field: torch.Tensor) -> torch.Tensor:
    """Pre-filter CNN input from the SLM-plane field (DESIGN §3, Eq. 6).

    Channels ``[|H|_r, |H|_g, |H|_b, p_r, p_g, p_b]`` with ``|H|`` in the hologram CNN's amplitude units (not
    rescaled) and ``p = arg(H)/(2π) + 0.5 ∈ [0, 1]``, the same semantics as the CNN heads, so that an identity
    mapping is representable (TensorHolo's choice).

    Args:
        slm_field: complex64 ``[B, 3, H, W]`` after offset propagation with the carrier removed.
    Returns:
        float32 ``[B, 6, H, W]``.
    """
    amp, phs = complex_to_amp_phase(slm_field)
    return torch.cat([amp, phs], dim=1)


class AntiAliasFilter(nn.Module):
    """The non-learned AA-DPM filter with the pre-filter CNN's interface: input :func:`prefilter_input`
    ``[B, 6, H, W]``, output ``(amplitude, phase01)`` of the Gaussian-blurred field
    (:func:`.optics.anti_alias_blur`). Puts "CNN + AA-DPM" through the same DDPM chain and metrics as a trained
    pre-filter, and is the target of the ``identity_target = "aa-dpm"`` pre-training."""

    def __init__(self, sigma_px: float = 0.7, size: int = 5):
        super().__init__()
        self.sigma_px, self.size = sigma_px, size

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        field = amp_phase_to_complex(x[:, :3], x[:, 3:])
        return complex_to_amp_phase(anti_alias_blur(field, self.sigma_px, self.size))


def count_parameters(module: nn.Module) -> int:
    """Number of trainable parameters (weights and biases)."""
    return sum(p.numel() for p in module.parameters() if p.requires_grad)


def macs_per_pixel(module: ResidualCNN) -> int:
    """Multiply-adds per output pixel of a :class:`ResidualCNN` (``9·C_in·C_out`` summed over layers)."""
    return sum(9 * c.in_channels * c.out_channels for c in module.convs)


if __name__ == "__main__":  # pragma: no cover - printed by `python -m tensorholo_training.model`
    for layers in VARIANTS:
        for inputs, name in ((1, "RGB-D"), (5, "LDI")):
            m = hologram_cnn(layers, inputs)
            print(f"hologram CNN {layers:2d} layers {name:5s}: {count_parameters(m):7d} parameters, "
                  f"{macs_per_pixel(m):7d} MAC/pixel")
    p = prefilter_cnn()
    print(f"pre-filter CNN 8 layers × 8 filters: {count_parameters(p)} parameters, {macs_per_pixel(p)} MAC/pixel")

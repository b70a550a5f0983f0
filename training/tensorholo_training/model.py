"""The CNNs of Tensor Holography V2 (paper "Details of training", ``docs/CONVENTIONS.md`` §7).

Hologram CNN: ``num_layers`` 3×3 convolutions (8, 15 or 30) with 24 filters, ReLU, a residual connection every
two layers, and a last layer that sees the network input again (the input is concatenated to its input). The
last layer has 6 outputs through two heads:

- amplitude ``A = (tanh(o[:3]) + 1)/2·√2 ∈ [0, √2]``;
- phase ``p = (tanh(o[3:]) + 1)/2 ∈ [0, 1]``, meaning ``(p − 0.5)·2π`` radians.

Input ``rgbd`` ``[B, 4·L, H, W]`` in ``[0, 1]`` (``L = 1`` for RGB-D, 5 for an LDI; per layer ``r, g, b, d``,
depth 0 = near), centred by ``−0.5`` inside the network. Output: the midpoint hologram (Fig. 3).

Pre-filter CNN (DDPM, Eq. 6; :class:`PrefilterCNN`): a residual correction of a fixed base filter in Cartesian
form, ``H' = base(H) + f([Re H, Im H])``, where ``f`` is the same architecture with 8 layers of 8 filters (no
heads, no input centring) whose last layer starts at zero, and ``base`` is the AA-DPM Gaussian blur (default) or
the identity. Input and output ``[B, 6, H, W]`` = real and imaginary parts of the offset (SLM-plane) hologram.

Residual wiring (TensorHolo's): with ``y_i`` the output of layer ``i`` and ``s_i`` its input,
``s_0 = x``, ``s_i = y_{i−1}`` for ``i ∈ {1, 2}`` or ``i`` even, and ``s_i = y_{i−1} + s_{i−2}`` for odd
``i ≥ 3``, so each pair of layers ``(i−2, i−1)`` is bypassed by an identity; the last layer reads
``concat(s_{N−1}, x)``. No batch normalisation (at inference it would fold into the convolutions anyway).
"""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from .optics import gaussian_kernel

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
        # Rounding of each convolution's input ``s_i`` (and of the last one's concat), ``(i, tensor) -> tensor``,
        # where every reader of ``s_i`` sees it (its convolution, a later residual add, the concat): the int8
        # scheme, set by :func:`.qat.fake_quantise`. ``None``: float.
        self.activation_quant = None

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
        q = self.activation_quant
        for i, conv in enumerate(self.convs):
            if i == 0:
                s = xin
            elif residual[i]:
                s = y + inputs[i - 2]
            else:
                s = y
            if i == self.num_layers - 1:
                cat = torch.cat([s, inputs[0]], dim=1)
                return conv(q(i, cat) if q is not None else cat)
            s = q(i, s) if q is not None else s
            inputs.append(s)
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


#: Bases of the pre-filter CNN (:class:`PrefilterCNN`).
PREFILTER_BASES = ("aa-dpm", "identity")


class PrefilterCNN(nn.Module):
    """The DDPM pre-filter CNN in Cartesian residual form: ``H' = base(H) + f([Re H, Im H])``.

    ``f`` is a :class:`ResidualCNN` (``num_layers`` × ``channels``, 6 in, 6 out, raw output: no tanh heads, no
    input centring) whose last layer is zero at initialisation, so an untrained pre-filter is exactly its
    ``base``: the AA-DPM blur (:func:`.optics.anti_alias_blur`, σ = ``sigma_px``, ``size`` taps, edges
    replicated) or the identity (plain DPM). This replaces the paper's identity pre-training (the network is
    the identity, or AA-DPM, by construction) and lets training only improve on that encoding; the paper's
    amplitude/phase pre-filter cannot represent the blur, whose output phase is not a smooth function of the
    input phase near zeros of ``|H|`` (``training/README.md``, "Why the amplitude/phase pre-filters lost to
    AA-DPM").

    The blur is a fixed depthwise 2D convolution (the outer product of the 1D Gaussian) after replicate padding
    of the 6 real channels, which is the complex separable blur exactly (it is linear), and which ONNX and tract
    run as ``Pad(mode=edge)`` + grouped ``Conv``.

    Args:
        num_layers, channels: of the correction CNN ``f`` (8 × 8 in the paper).
        base: ``"aa-dpm"`` or ``"identity"``.
        sigma_px, size: the AA-DPM Gaussian (standard deviation in pixels, odd number of taps).
    """

    def __init__(self, num_layers: int = 8, channels: int = 8, base: str = "aa-dpm", sigma_px: float = 0.7,
                 size: int = 5):
        super().__init__()
        if base not in PREFILTER_BASES:
            raise ValueError(f"pre-filter base must be one of {PREFILTER_BASES}, got {base!r}")
        self.base, self.sigma_px, self.size = base, float(sigma_px), int(size)
        self.net = ResidualCNN(num_layers, channels, in_channels=6, out_channels=6, centre_input=False)
        nn.init.zeros_(self.net.convs[-1].weight)
        nn.init.zeros_(self.net.convs[-1].bias)
        k = gaussian_kernel(self.sigma_px, self.size)
        self.register_buffer("blur", torch.outer(k, k).expand(6, 1, self.size, self.size).clone(),
                             persistent=False)

    @property
    def num_layers(self) -> int:
        """Convolution layers of the correction CNN (8 in the paper; written as ``tensorholo.layers``)."""
        return self.net.num_layers

    @property
    def channels(self) -> int:
        """Filters per hidden layer of the correction CNN (8 in the paper)."""
        return self.net.channels

    @property
    def in_channels(self) -> int:
        """Input channels: 6 = ``[Re H, Im H]`` of R, G, B."""
        return 6

    def base_filter(self, x: torch.Tensor) -> torch.Tensor:
        """``base`` on ``[B, 6, H, W]`` Cartesian channels (identity or the AA-DPM blur)."""
        if self.base == "identity":
            return x
        r = self.size // 2
        return F.conv2d(F.pad(x, (r, r, r, r), mode="replicate"), self.blur.to(x.dtype), groups=6)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Filters the offset hologram.

        Args:
            x: float ``[B, 6, H, W]`` = ``[Re H (R, G, B), Im H (R, G, B)]`` (:func:`prefilter_input`), in the
                midpoint hologram's amplitude units.
        Returns:
            ``(real, imag)``: float ``[B, 3, H, W]`` each, the filtered field ``H'``.
        """
        real, imag = torch.split(self.base_filter(x) + self.net.raw(x), 3, dim=1)
        return real, imag


def prefilter_cnn(num_layers: int = 8, channels: int = 8, base: str = "aa-dpm", sigma_px: float = 0.7,
                  size: int = 5) -> PrefilterCNN:
    """The DDPM pre-filter CNN (:class:`PrefilterCNN`): 8 layers × 8 filters on an AA-DPM base by default."""
    return PrefilterCNN(num_layers, channels, base, sigma_px, size)


def prefilter_input(slm_field: torch.Tensor) -> torch.Tensor:
    """Pre-filter CNN input from the SLM-plane field (``docs/CONVENTIONS.md`` §7.2, Eq. 6): ``[Re H, Im H]``.

    Args:
        slm_field: complex64 ``[B, 3, H, W]`` after offset propagation with the carrier removed (amplitude in
            the hologram CNN's units, not rescaled).
    Returns:
        float32 ``[B, 6, H, W]``: real parts R, G, B then imaginary parts R, G, B.
    """
    return torch.cat([slm_field.real, slm_field.imag], dim=1).float()


def prefilter_output(real: torch.Tensor, imag: torch.Tensor) -> torch.Tensor:
    """The filtered complex field ``[B, 3, H, W]`` from the pre-filter's ``(real, imag)`` outputs."""
    return torch.complex(real.float(), imag.float())


def load_prefilter_state(prefilter: PrefilterCNN, state: dict, source: str) -> None:
    """Loads pre-filter weights, refusing with a clear error those of the removed amplitude/phase pre-filter
    (a :class:`ResidualCNN` state, keys ``convs.*``) or of another architecture."""
    try:
        prefilter.load_state_dict(state)
    except RuntimeError as e:
        old = any(k.startswith("convs.") for k in state)
        raise ValueError(
            f"{source}: its pre-filter weights do not fit this pre-filter CNN"
            + (" (they are the old amplitude/phase pre-filter; train a new one from a stage1.pt)" if old else "")
            + f": {e}") from None


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
    print(f"pre-filter CNN 8 layers × 8 filters: {count_parameters(p)} parameters, "
          f"{macs_per_pixel(p.net) + 6 * p.size ** 2} MAC/pixel (with the AA-DPM blur)")

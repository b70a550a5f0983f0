"""Training losses of Tensor Holography V2 (paper Eq. 6–11, "Details of training"; TensorHolo V1 for the rest).

Stage 1 (supervised): ``w_data · data fidelity + w_fs · dynamic focal stack + w_fs_tv · its total variation``.
Stage 2 (DDPM, unsupervised): the midpoint prediction goes through offset propagation (Eq. 6), the pre-filter
CNN, double phase encoding without blur (Eq. 7), the Fourier filter (Eq. 8–9) and back-propagation (Eq. 10);
loss ``w_fs · focal stack(post-encoding, GT) + w_fs_tv · TV + w_reg · Eq. 11``. The pre-filter needs no
identity pre-training: :class:`.model.PrefilterCNN` starts as its base filter by construction.

Complex fields are complex64 ``[B, 3, H, W]``; depths are normalised (0 = near); amplitudes in the units of
the midpoint hologram.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

from . import optics
from .model import PrefilterCNN, prefilter_input, prefilter_output
from .optics import Display, PropagationOptions


def _op(kind: str):
    if kind == "l2":
        return lambda a, b: ((a - b) ** 2).mean()
    if kind == "l1":
        return lambda a, b: (a - b).abs().mean()
    raise ValueError(f"loss kind must be 'l1' or 'l2', got {kind!r}")


def global_phase(pred: torch.Tensor, gt: torch.Tensor) -> torch.Tensor:
    """Per-channel unit phasor ``⟨pred, gt⟩/|⟨pred, gt⟩|`` with ``⟨p, g⟩ = Σ conj(p)·g`` over pixels: the
    constant rotation that best aligns ``pred`` with ``gt`` (1 where the inner product vanishes).

    Args:
        pred, gt: complex ``[B, C, H, W]``.
    Returns:
        complex ``[B, C, 1, 1]``.
    """
    ip = (pred.conj() * gt).sum(dim=(-2, -1), keepdim=True)
    mag = ip.abs()
    safe = mag > 1e-20
    return torch.where(safe, ip / torch.where(safe, mag, torch.ones_like(mag)), torch.ones_like(ip))


def data_fidelity_loss(pred: torch.Tensor, gt: torch.Tensor, mode: str = "complex", kind: str = "l2"):
    """Data fidelity between predicted and ground-truth midpoint holograms, blind to a global phase per channel.

    - ``mode="complex"``: rotate ``pred`` by :func:`global_phase` and take ``kind`` (L2/L1) of the complex
      difference (``|Δ|²`` mean for L2, ``|Δ|`` mean for L1). Exactly invariant to ``pred·e^{ic}``.
    - ``mode="tensorholo"``: TensorHolo's form: ``Δφ = wrap(φ_gt − φ_pred)``, minus its mean per channel, then
      ``op(A_gt·cos Δφ, A_pred) + op(A_gt·sin Δφ, 0)`` (invariant up to phase-wrapping effects).

    Args:
        pred, gt: complex64 ``[B, 3, H, W]``.
        mode: ``"complex"`` or ``"tensorholo"``.
        kind: ``"l2"`` or ``"l1"``.
    Returns:
        scalar tensor.
    """
    if mode == "complex":
        d = pred * global_phase(pred, gt) - gt
        return (d.abs() ** 2).mean() if kind == "l2" else d.abs().mean()
    if mode == "tensorholo":
        op = _op(kind)
        dphi = torch.angle(gt) - torch.angle(pred)
        dphi = torch.atan2(torch.sin(dphi), torch.cos(dphi))
        dphi = dphi - dphi.mean(dim=(-2, -1), keepdim=True)
        a_gt, a_pred = gt.abs(), pred.abs()
        return op(a_gt * torch.cos(dphi), a_pred) + op(a_gt * torch.sin(dphi), torch.zeros_like(a_gt))
    raise ValueError(f"mode must be 'complex' or 'tensorholo', got {mode!r}")


@dataclass
class FocalStackLossConfig:
    """Dynamic focal stack loss parameters.

    Attributes:
        bins: histogram bins over normalised depth ``[0, 1]`` (200).
        top: most populated bins used per sample (15).
        random: extra random bins among the rest (5).
        attention_scale: ``κ`` of the depth attention ``exp(−κ·(|D − d| − min|D − d|))`` (normalised depth
            units); TensorHolo's value is not published, 5 makes content 0.2 away weigh ``e⁻¹``.
        kind: ``"l2"`` or ``"l1"``.
        pad: zero-pad the ASM (linear convolution), as TensorHolo does.
        band_limit: Matsushima band limit in the ASM.
        chunk: depths per ASM batch (memory), ``None`` = all at once.
    """

    bins: int = 200
    top: int = 15
    random: int = 5
    attention_scale: float = 5.0
    kind: str = "l2"
    pad: bool = True
    band_limit: bool = False
    chunk: int | None = None

    @property
    def options(self) -> PropagationOptions:
        """The :class:`~.optics.PropagationOptions` of the loss's ASM."""
        return PropagationOptions(self.pad, self.band_limit)


def select_focal_depths(
    depth: torch.Tensor, bins: int = 200, top: int = 15, random: int = 5, generator: torch.Generator | None = None,
    valid: torch.Tensor | None = None,
) -> torch.Tensor:
    """Per-sample focal depths of the dynamic focal stack (TensorHolo V1/V2).

    Histogram of each sample's depth in ``bins`` bins over ``[0, 1]`` (the first layer's, or every valid point
    of every layer of an LDI depth ``[B, L, H, W]`` with ``valid``); bins sorted by count
    (descending, stable); one uniform jitter ``u ∈ [0, 1)`` per sample moves all centres inside their bins
    (``(index + u)/bins``); the ``top`` most populated plus ``random`` drawn from the remaining bins.

    Args:
        depth: float ``[B, H, W]`` normalised depth, or ``[B, L, H, W]`` that of each LDI layer.
        bins, top, random: see above (``top + random ≤ bins``).
        generator: torch random generator (CPU) for reproducibility, or a list of one per sample (then a
            sample's planes do not depend on the other samples of its batch: data-parallel ranks draw what one
            process with the whole batch draws).
        valid: ``[B, L, H, W]`` (bool or 0/1) the LDI's valid points; required with a 4-D ``depth``.
    Returns:
        float32 ``[B, top + random]`` normalised depths in ``[0, 1)``.
    """
    if top + random > bins:
        raise ValueError("top + random must not exceed bins")
    if depth.ndim == 4 and valid is None:
        raise ValueError("an LDI depth [B, L, H, W] needs its valid mask")
    out = []
    for b in range(depth.shape[0]):
        points = depth[b].detach().float().cpu()
        if depth.ndim == 4:
            points = points[valid[b].detach().cpu().bool()]
        hist = torch.histc(points, bins=bins, min=0.0, max=1.0)
        order = torch.argsort(hist, descending=True, stable=True).float()
        g = generator[b] if isinstance(generator, (list, tuple)) else generator
        u = torch.rand(1, generator=g)
        idx = (order + u) / bins
        rest = idx[top:]
        pick = rest[torch.randperm(rest.numel(), generator=g)[:random]]
        out.append(torch.cat([idx[:top], pick]))
    return torch.stack(out).to(depth.device)


def attention_masks(
    depth: torch.Tensor, focal: torch.Tensor, scale: float, valid: torch.Tensor | None = None
) -> torch.Tensor:
    """Depth attention per focal plane: ``exp(κ·(1 − |D − d|))`` normalised to max 1 per plane.

    With an LDI depth ``[B, L, H, W]``, ``|D − d|`` is that of the pixel's nearest valid layer,
    ``min_k |D_k − d|``: a pixel counts fully where any of its points, hidden or not, is in focus. With the
    first layer's depth alone (the paper), a wall hidden behind a near bar weighs ``e^{−κ·Δ}`` in the bar's
    pixels when the focal plane is on the wall, although the wall's light passes around the bar there.

    Args:
        depth: float ``[B, H, W]``, or ``[B, L, H, W]`` per LDI layer; focal: float ``[B, D]``; scale: ``κ``.
        valid: ``[B, L, H, W]`` the LDI's valid points; required with a 4-D ``depth`` (layer 0 should be valid
            everywhere; a pixel with no valid layer gets the weight of depth distance 1).
    Returns:
        float32 ``[B, D, 1, H, W]`` in ``(0, 1]``.
    """
    if depth.ndim == 4:
        if valid is None:
            raise ValueError("an LDI depth [B, L, H, W] needs its valid mask")
        diff = (depth[:, None] - focal[:, :, None, None, None]).abs()
        diff = diff.masked_fill(~valid[:, None].bool(), 1.0).amin(dim=2)
    else:
        diff = (depth[:, None] - focal[:, :, None, None]).abs()
    w = torch.exp(scale * (1.0 - diff))
    w = w / w.flatten(2).amax(dim=2)[..., None, None]
    return w[:, :, None].float()


def focal_stack_loss(
    pred: torch.Tensor,
    gt: torch.Tensor,
    depth: torch.Tensor,
    focal: torch.Tensor,
    display: Display,
    cfg: FocalStackLossConfig = FocalStackLossConfig(),
    gt_stack: torch.Tensor | None = None,
    valid: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Dynamic focal stack loss and its total-variation term.

    For each focal depth ``d``: images ``|ASM(H, z(d))|`` of prediction and ground truth, both multiplied by
    the attention mask; loss = ``kind`` of their difference; TV = ``0.5·kind(∂x) + 0.5·kind(∂y)`` of the
    weighted images' finite differences. Averaged over samples and focal planes.

    Args:
        pred, gt: complex64 ``[B, 3, H, W]`` midpoint holograms.
        depth: float ``[B, H, W]`` first-layer normalised depth, or ``[B, L, H, W]`` per LDI layer (with
            ``valid``; :func:`attention_masks`).
        focal: float ``[B, D]`` focal depths (:func:`select_focal_depths`).
        display: geometry; cfg: see :class:`FocalStackLossConfig`.
        gt_stack: precomputed ``|ASM(gt, z(d))|`` ``[B, D, 3, H, W]`` (optional).
        valid: ``[B, L, H, W]`` the LDI's valid points (with a 4-D ``depth``).
    Returns:
        ``(focal_stack_loss, tv_loss)`` scalars.
    """
    op = _op(cfg.kind)
    opts = cfg.options
    img_pred = optics.focal_stack(pred, focal, display, 0.0, opts, chunk=cfg.chunk)
    if gt_stack is None:
        with torch.no_grad():
            gt_stack = optics.focal_stack(gt, focal, display, 0.0, opts, chunk=cfg.chunk)
    w = attention_masks(depth, focal, cfg.attention_scale, valid)
    wp, wg = img_pred * w, gt_stack * w
    loss = op(wp, wg)
    tv = 0.5 * op(wp[..., :, 1:] - wp[..., :, :-1], wg[..., :, 1:] - wg[..., :, :-1]) + 0.5 * op(
        wp[..., 1:, :] - wp[..., :-1, :], wg[..., 1:, :] - wg[..., :-1, :]
    )
    return loss, tv


def phase_regulariser(phase01: torch.Tensor) -> torch.Tensor:
    """Eq. 11 on the pre-encoding target hologram phase, in the heads' normalised units (``p − 0.5``, i.e.
    radians / 2π, as TensorHolo's code): ``std(φ) + |mean(φ)|`` per channel, averaged over channels and batch.

    Args:
        phase01: float ``[B, 3, H, W]`` phase in ``[0, 1]`` (``(p − 0.5)·2π`` rad).
    Returns:
        scalar tensor.
    """
    phi = phase01 - 0.5
    mean = phi.mean(dim=(-2, -1))
    std = torch.sqrt(((phi - mean[..., None, None]) ** 2).mean(dim=(-2, -1)) + 1e-12)
    return (std + mean.abs()).mean()


@dataclass
class DdpmOutput:
    """Intermediate results of :func:`ddpm_forward` (all ``[B, 3, H, W]``)."""

    slm_field: torch.Tensor  #: complex64, offset hologram ``ASM(H_mid, s)·e^{−i2πs/λ}`` (Eq. 6, before the CNN)
    pre_amplitude: torch.Tensor  #: float, pre-encoding amplitude (``|pre-filter output|`` or ``|slm_field|``)
    pre_phase01: torch.Tensor  #: float, pre-encoding phase in [0, 1]
    phase: torch.Tensor  #: float, double phase pattern (radians, unwrapped)
    amplitude_scale: torch.Tensor  #: float ``[B]``, the double phase normaliser ``a``
    post_midpoint: torch.Tensor  #: complex64, post-encoding midpoint hologram ×a (Eq. 10), comparable with GT


def ddpm_forward(
    amplitude: torch.Tensor,
    phase01: torch.Tensor,
    prefilter: PrefilterCNN | None,
    offset_m: float,
    display: Display,
    options: PropagationOptions = PropagationOptions(pad=True),
) -> DdpmOutput:
    """The stage-2 chain of Fig. 3: offset propagation (Eq. 6) → pre-filter CNN → double phase without blur
    (Eq. 7) → Fourier filter (Eq. 8–9) → back-propagation (Eq. 10), rescaled by the normaliser ``a`` so that
    the post-encoding hologram is in the midpoint's units. Differentiable end to end.

    Args:
        amplitude, phase01: hologram CNN outputs ``[B, 3, H, W]`` (``[0, √2]``, ``[0, 1]``).
        prefilter: the pre-filter CNN (``[Re, Im]`` in and out), or ``None`` (plain DPM, e.g. for a 0 mm
            offset).
        offset_m: SLM offset ``s`` in metres.
        display: geometry; options: ASM padding / band limit.
    Returns:
        :class:`DdpmOutput`.
    """
    mid = optics.amp_phase_to_complex(amplitude, phase01)
    slm = optics.offset_to_slm(mid, offset_m, display, options)
    pre = prefilter_output(*prefilter(prefilter_input(slm))) if prefilter is not None else slm
    pa, pp = optics.complex_to_amp_phase(pre)
    dp = optics.double_phase_encode(pre, wrap=False, clamp_eps=1e-6)
    post = optics.simulate_phase_only(dp.phase, offset_m, display, options)
    post = post * dp.amplitude_scale[:, None, None, None]
    return DdpmOutput(slm, pa, pp, dp.phase, dp.amplitude_scale, post)


@dataclass
class LossWeights:
    """Weights of the loss terms (paper: ``w_data = 1``, ``w_pcp = 1``, ``w_tgt-pre = 0.07``)."""

    data: float = 1.0
    focal_stack: float = 1.0
    focal_stack_tv: float = 1.0
    regulariser: float = 0.07


def stage1_loss(
    amplitude: torch.Tensor,
    phase01: torch.Tensor,
    gt: torch.Tensor,
    depth: torch.Tensor,
    display: Display,
    weights: LossWeights = LossWeights(),
    fs: FocalStackLossConfig = FocalStackLossConfig(),
    data_mode: str = "complex",
    generator: torch.Generator | None = None,
    valid: torch.Tensor | None = None,
) -> dict[str, torch.Tensor]:
    """Stage-1 loss: data fidelity + dynamic focal stack + TV.

    Args:
        amplitude, phase01: hologram CNN outputs ``[B, 3, H, W]``.
        gt: complex64 ``[B, 3, H, W]`` ground-truth midpoint.
        depth: float ``[B, H, W]`` first-layer depth, or ``[B, L, H, W]`` per LDI layer with ``valid``
            ``[B, L, H, W]`` (``fs.attention = "layers"``; :func:`attention_masks`).
        display, weights, fs, data_mode: see the respective functions/classes.
        generator: random generator of the focal depth selection.
    Returns:
        dict with ``"total"``, ``"data"``, ``"focal_stack"``, ``"focal_stack_tv"`` scalars.
    """
    pred = optics.amp_phase_to_complex(amplitude, phase01)
    data = data_fidelity_loss(pred, gt, data_mode, fs.kind)
    focal = select_focal_depths(depth, fs.bins, fs.top, fs.random, generator, valid)
    fsl, tv = focal_stack_loss(pred, gt, depth, focal, display, fs, valid=valid)
    total = weights.data * data + weights.focal_stack * fsl + weights.focal_stack_tv * tv
    return {"total": total, "data": data, "focal_stack": fsl, "focal_stack_tv": tv}


def stage2_loss(
    out: DdpmOutput,
    gt: torch.Tensor,
    depth: torch.Tensor,
    display: Display,
    weights: LossWeights = LossWeights(),
    fs: FocalStackLossConfig = FocalStackLossConfig(),
    generator: torch.Generator | None = None,
    valid: torch.Tensor | None = None,
) -> dict[str, torch.Tensor]:
    """Stage-2 loss: focal stack of the post-encoding midpoint vs GT, its TV, and Eq. 11 on the pre-encoding
    phase. No direct supervision by the GT hologram (paper: "intentionally ablated").

    Args:
        out: :func:`ddpm_forward` output; gt: complex64 ``[B, 3, H, W]``; depth: ``[B, H, W]``, or
        ``[B, L, H, W]`` with ``valid`` (as :func:`stage1_loss`).
    Returns:
        dict with ``"total"``, ``"focal_stack"``, ``"focal_stack_tv"``, ``"regulariser"`` scalars.
    """
    focal = select_focal_depths(depth, fs.bins, fs.top, fs.random, generator, valid)
    fsl, tv = focal_stack_loss(out.post_midpoint, gt, depth, focal, display, fs, valid=valid)
    reg = phase_regulariser(out.pre_phase01)
    total = weights.focal_stack * fsl + weights.focal_stack_tv * tv + weights.regulariser * reg
    return {"total": total, "focal_stack": fsl, "focal_stack_tv": tv, "regulariser": reg}

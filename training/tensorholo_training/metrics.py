"""PSNR and SSIM in PyTorch, with the definitions of the SDK's ``metrics`` module (scikit-image's SSIM).

SSIM: 11×11 Gaussian window (σ = 1.5, truncate 3.5 → radius 5), ``K1 = 0.01``, ``K2 = 0.03``, population
(co)variances, map cropped by 5 pixels on each side (a "valid" convolution), mean over the map; computed in
float64. For colour stacks, the mean over channels (``channel_axis=0`` in scikit-image).
"""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F


def psnr(reference: torch.Tensor, test: torch.Tensor, data_range: float = 1.0) -> torch.Tensor:
    """Peak signal-to-noise ratio in dB, ``10·log10(range²/MSE)`` over all but the first axis.

    Args:
        reference, test: float ``[B, ...]`` of the same shape.
        data_range: peak-to-peak range of the signal (1.0 for amplitudes in ``[0, 1]``).
    Returns:
        float64 ``[B]`` (``inf`` where the images are identical).
    """
    if reference.shape != test.shape:
        raise ValueError(f"shapes differ: {tuple(reference.shape)} vs {tuple(test.shape)}")
    diff = (reference.double() - test.double()).flatten(1)
    mse = (diff * diff).mean(dim=1)
    return 10.0 * torch.log10(data_range**2 / mse)


def _gaussian_window(device) -> torch.Tensor:
    sigma, radius = 1.5, 5
    x = torch.arange(-radius, radius + 1, dtype=torch.float64, device=device)
    g = torch.exp(-(x * x) / (2 * sigma * sigma))
    return g / g.sum()


def ssim(reference: torch.Tensor, test: torch.Tensor, data_range: float = 1.0) -> torch.Tensor:
    """Mean SSIM of image stacks (scikit-image ``gaussian_weights=True, sigma=1.5``), averaged over channels.

    Args:
        reference, test: float ``[B, C, H, W]`` with ``H, W ≥ 11``.
        data_range: peak-to-peak range of the signal.
    Returns:
        float64 ``[B]`` in ``[−1, 1]``.
    """
    if reference.shape != test.shape or reference.dim() != 4:
        raise ValueError(f"expected two [B, C, H, W] stacks of one shape, got {tuple(reference.shape)}, "
                         f"{tuple(test.shape)}")
    b, c, h, w = reference.shape
    if h < 11 or w < 11:
        raise ValueError(f"SSIM needs images of at least 11×11 pixels, got {h}×{w}")
    g = _gaussian_window(reference.device)
    gx = g.view(1, 1, 1, -1)
    gy = g.view(1, 1, -1, 1)

    def blur(x):
        x = x.reshape(b * c, 1, h, w)
        return F.conv2d(F.conv2d(x, gx), gy)

    x = reference.double()
    y = test.double()
    mx, my = blur(x), blur(y)
    vx = blur(x * x) - mx * mx
    vy = blur(y * y) - my * my
    cxy = blur(x * y) - mx * my
    c1 = (0.01 * data_range) ** 2
    c2 = (0.03 * data_range) ** 2
    s = ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2))
    return s.reshape(b, c, -1).mean(dim=2).mean(dim=1)


def psnr_to_mse(db: float, data_range: float = 1.0) -> float:
    """Mean squared error corresponding to a PSNR in dB."""
    return data_range**2 / (10.0 ** (db / 10.0)) if math.isfinite(db) else 0.0

"""Differentiable wave optics in PyTorch: copies of the SDK's physics (``sdk/src/optics``, ``sdk/src/encoding``).

Every operator here mirrors a Rust function and is tested against fixtures written by ``holo`` on the same
input (``tests/test_optics_fixtures.py``):

==============================  ==============================================================
this module                      Rust reference
==============================  ==============================================================
:func:`transfer_function`        ``optics::Propagator::transfer_function`` (Eq. 2)
:func:`propagate`                ``optics::propagate_colour`` (Eq. 2; Eq. 6 and 10 with carrier removal)
:func:`offset_to_slm`            ``reference`` offset step: ``ASM(H, s)·exp(−i2πs/λ)`` (Eq. 6)
:func:`double_phase_encode`      ``encoding::double_phase_encode`` with ``DoublePhaseMethod::Plain`` (Eq. 7)
:func:`fourier_filter`           ``optics::FourierFilter`` (Eq. 8–9)
:func:`simulate_phase_only`      ``optics::simulate_phase_only`` (Eq. 8–10)
:func:`focal_stack`              ``optics::focal_stack``
==============================  ==============================================================

Fields are ``torch.complex64`` tensors ``[..., C, H, W]`` with channel order R, G, B; distances in metres,
positive along the light (from the scene toward the SLM); phases in radians. Transfer functions are computed
in float64 and rounded to complex64, as in Rust. All operators are differentiable with respect to the fields.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from functools import lru_cache
from typing import Sequence

import numpy as np
import torch
import torch.nn.functional as F

TAU = 2.0 * math.pi


@dataclass(frozen=True)
class Display:
    """Display geometry of ``docs/CONVENTIONS.md`` §3 (the paper's setup by default).

    Attributes:
        wavelengths_m: laser wavelengths in metres, R, G, B.
        pixel_pitch_m: SLM pixel pitch in metres.
        volume_depth_m: depth of the 3D volume in metres, centred on the midpoint hologram.
    """

    wavelengths_m: tuple[float, float, float] = (638e-9, 520e-9, 450e-9)
    pixel_pitch_m: float = 8e-6
    volume_depth_m: float = 6e-3

    def depth_to_z(self, d):
        """Axial position ``z(d) = (0.5 − d)·volume_depth`` (metres) of normalised depth ``d`` (0 = near).

        Args:
            d: float or tensor of normalised depths in ``[0, 1]``.
        Returns:
            Same type and shape as ``d``, in metres (near points have ``z > 0``).
        """
        return (0.5 - d) * self.volume_depth_m

    def to_dict(self) -> dict:
        """JSON-serialisable form."""
        d = asdict(self)
        d["wavelengths_m"] = list(self.wavelengths_m)
        return d


@dataclass(frozen=True)
class PropagationOptions:
    """Options of the angular spectrum method (``optics::PropagationOptions``).

    Attributes:
        pad: zero-pad to ``2H × 2W`` (centred) before the FFT and crop afterwards (linear convolution).
        band_limit: Matsushima & Shimobaba band limit ``|f| ≤ 1/(λ·√((2·Δf·z)² + 1))`` per axis.
    """

    pad: bool = False
    band_limit: bool = False


def _signed_freq_index(n: int) -> np.ndarray:
    """Signed DFT bin indices in FFT order (``fft::signed_index``; same as ``numpy.fft.fftfreq(n)·n``)."""
    k = np.arange(n)
    return np.where(k < (n + 1) // 2, k, k - n)


@lru_cache(maxsize=64)
def _frequency_grid(ch: int, cw: int, pitch: float, wavelengths: tuple, device: str):
    """float64 grids of a computational grid: ``fx [1, cw]``, ``fy [ch, 1]``, ``f² [ch, cw]``,
    ``kz = √max(λ⁻² − f², 0)`` ``[C, ch, cw]``, non-evanescent mask ``[C, ch, cw]`` and ``1/λ`` ``[C, 1, 1]``."""
    dev = torch.device(device)
    fx = torch.from_numpy(_signed_freq_index(cw) / (cw * pitch)).to(dev)[None, :]
    fy = torch.from_numpy(_signed_freq_index(ch) / (ch * pitch)).to(dev)[:, None]
    f2 = fx * fx + fy * fy
    inv_l = 1.0 / torch.tensor(wavelengths, dtype=torch.float64, device=dev)[:, None, None]
    arg = inv_l * inv_l - f2
    propagating = arg > 0.0
    kz = torch.sqrt(torch.where(propagating, arg, torch.zeros_like(arg)))
    return fx, fy, f2, kz, propagating, inv_l


def transfer_function(
    height: int,
    width: int,
    pixel_pitch_m: float,
    wavelengths_m: Sequence[float],
    distance_m,
    carrier: str = "keep",
    options: PropagationOptions = PropagationOptions(),
    device=None,
) -> torch.Tensor:
    """Angular spectrum transfer function ``exp(i·2π·z·√(λ⁻² − fx² − fy²))`` (paper Eq. 2).

    Evanescent components (``λ⁻² − f² ≤ 0``) are zeroed; with ``options.band_limit`` frequencies beyond the
    Matsushima limit are zeroed too. ``carrier="remove"`` multiplies by ``exp(−i·2π·z/λ)`` (Eq. 6/10), computed
    as ``−2π·z·f²/(kz + 1/λ)`` to avoid cancellation, exactly as the Rust code does. Phases are computed in
    float64 (on ``device``) and rounded to complex64. The inverse-FFT normalisation is *not* folded in
    (``torch.fft.ifft2`` applies it).

    Args:
        height, width: field size in pixels (the grid is ``2H × 2W`` when ``options.pad``).
        pixel_pitch_m: sampling pitch in metres.
        wavelengths_m: ``C`` wavelengths in metres.
        distance_m: float, or array/tensor of shape ``S`` of distances in metres (any sign).
        carrier: ``"keep"`` (plain Eq. 2) or ``"remove"``.
        options: padding and band limit.
        device: torch device of the result.
    Returns:
        complex64 tensor ``[*S, C, ch, cw]`` in FFT (unshifted) order.
    """
    if carrier not in ("keep", "remove"):
        raise ValueError(f"carrier must be 'keep' or 'remove', got {carrier!r}")
    dev = torch.device(device) if device is not None else torch.device("cpu")
    factor = 2 if options.pad else 1
    ch, cw = height * factor, width * factor
    fx, fy, f2, kz, propagating, inv_l = _frequency_grid(
        ch, cw, float(pixel_pitch_m), tuple(float(l) for l in wavelengths_m), str(dev)
    )
    z = torch.as_tensor(distance_m, dtype=torch.float64).to(dev)
    zz = z[..., None, None, None]  # [*S, 1, 1, 1]
    if carrier == "keep":
        phase = TAU * zz * kz
    else:
        phase = -TAU * zz * f2 / (kz + inv_l)
    valid = propagating
    if options.band_limit:
        lam = 1.0 / inv_l
        dfx, dfy = 1.0 / (cw * pixel_pitch_m), 1.0 / (ch * pixel_pitch_m)
        fx_lim = 1.0 / (lam * torch.sqrt((2.0 * dfx * zz) ** 2 + 1.0))
        fy_lim = 1.0 / (lam * torch.sqrt((2.0 * dfy * zz) ** 2 + 1.0))
        valid = valid & (fx.abs() <= fx_lim) & (fy.abs() <= fy_lim)
    tf = torch.polar(valid.to(torch.float64).expand_as(phase).contiguous(), phase)
    return tf.to(torch.complex64)


def _embed(field: torch.Tensor) -> torch.Tensor:
    """Centres ``[..., H, W]`` in a zero ``[..., 2H, 2W]`` grid (offset ``(H//2, W//2)``, as ``SpectralPlan::embed``)."""
    h, w = field.shape[-2:]
    out = field.new_zeros(field.shape[:-2] + (2 * h, 2 * w))
    oy, ox = h // 2, w // 2
    out[..., oy : oy + h, ox : ox + w] = field
    return out


def _crop(field: torch.Tensor, h: int, w: int) -> torch.Tensor:
    """Inverse of :func:`_embed`: the centre ``[..., h, w]`` of a ``[..., 2h, 2w]`` grid."""
    oy, ox = h // 2, w // 2
    return field[..., oy : oy + h, ox : ox + w]


def spectrum(field: torch.Tensor, pad: bool = False) -> torch.Tensor:
    """2D FFT of ``field`` ``[..., H, W]`` (complex64), zero padded to ``2H × 2W`` first when ``pad``."""
    return torch.fft.fft2(_embed(field) if pad else field)


def from_spectrum(spec: torch.Tensor, height: int, width: int, pad: bool = False) -> torch.Tensor:
    """Inverse of :func:`spectrum`: ``ifft2`` then crop to ``[..., height, width]`` when ``pad``."""
    out = torch.fft.ifft2(spec)
    return _crop(out, height, width) if pad else out


def propagate(
    field: torch.Tensor,
    distance_m,
    wavelengths_m: Sequence[float],
    pixel_pitch_m: float,
    carrier: str = "keep",
    options: PropagationOptions = PropagationOptions(),
) -> torch.Tensor:
    """Angular spectrum propagation (Eq. 2) of a colour stack, one wavelength per channel.

    Matches ``optics::propagate_colour`` (and ``holo propagate``). With ``carrier="remove"`` this is the offset
    propagation of Eq. 6 (``distance_m = s``) and its inverse Eq. 10 (``distance_m = −s``).

    Args:
        field: complex64 ``[..., C, H, W]``.
        distance_m: float (metres), or a tensor of shape ``field.shape[:-3]`` with one distance per item.
        wavelengths_m: ``C`` wavelengths in metres.
        pixel_pitch_m: pitch in metres.
        carrier: ``"keep"`` or ``"remove"``.
        options: padding and band limit.
    Returns:
        complex64 ``[..., C, H, W]``, the propagated field.
    """
    h, w = field.shape[-2:]
    tf = transfer_function(h, w, pixel_pitch_m, wavelengths_m, distance_m, carrier, options, field.device)
    return from_spectrum(spectrum(field, options.pad) * tf, h, w, options.pad)


def offset_to_slm(field: torch.Tensor, offset_m: float, display: Display, options=PropagationOptions()):
    """Offset propagation of Eq. 6: ``ASM(H_mid, s)·exp(−i·2π·s/λ)`` (identity for ``s = 0``).

    Args:
        field: midpoint hologram, complex64 ``[..., 3, H, W]``.
        offset_m: SLM distance ``s`` from the midpoint plane in metres.
        display: wavelengths and pitch.
        options: padding and band limit.
    Returns:
        SLM-plane field, complex64 ``[..., 3, H, W]`` (``holo encode``'s ``slm_field.npy``).
    """
    if offset_m == 0.0:
        return field
    return propagate(field, offset_m, display.wavelengths_m, display.pixel_pitch_m, "remove", options)


def wrap_phase(phase: torch.Tensor) -> torch.Tensor:
    """Wraps radians to ``[0, 2π)`` with the same float32 operations as ``encoding::wrap_phase``.

    Args:
        phase: float tensor (radians), any shape.
    Returns:
        float tensor of the same shape in ``[0, 2π)``.
    """
    tau = torch.tensor(TAU, dtype=phase.dtype, device=phase.device)
    fast = (phase >= -2 * tau) & (phase < 2 * tau)
    w = phase
    for _ in range(2):
        w = torch.where(w < 0, w + tau, w)
    for _ in range(2):
        w = torch.where(w >= tau, w - tau, w)
    slow = torch.remainder(phase, tau)
    slow = torch.where(slow >= tau, slow - tau, slow)
    return torch.where(fast, w, slow)


def checkerboard(height: int, width: int, device=None) -> torch.Tensor:
    """Bool ``[H, W]``: True where ``x + y`` is odd (``x`` column, ``y`` row), the ``φ − acos`` pixels of Eq. 7."""
    y = torch.arange(height, device=device)[:, None]
    x = torch.arange(width, device=device)[None, :]
    return ((x + y) % 2) == 1


@dataclass
class DoublePhase:
    """Result of :func:`double_phase_encode`.

    Attributes:
        phase: float32 ``[..., C, H, W]`` phase-only pattern in radians (``[0, 2π)`` when wrapped).
        amplitude_scale: float32 ``[...]`` global amplitude normaliser ``a`` (max over colours and pixels).
        mean_phase: float32 ``[..., C]`` per-channel mean phase removed before encoding (radians).
    """

    phase: torch.Tensor
    amplitude_scale: torch.Tensor
    mean_phase: torch.Tensor


def double_phase_encode(
    field: torch.Tensor, wrap: bool = True, clamp_eps: float = 0.0
) -> DoublePhase:
    """Double phase encoding of Eq. 7 (``encoding::double_phase_encode``, ``DoublePhaseMethod::Plain``).

    1. ``a`` = max amplitude over all colours and pixels (per item of the batch), ``Ã = |H|/a``;
    2. ``φ = atan2(Im H, Re H)`` de-meaned per channel (arithmetic mean over pixels);
    3. ``P = φ − acos Ã`` where ``x + y`` is odd, ``φ + acos Ã`` where it is even;
    4. optionally wrapped to ``[0, 2π)``.

    Args:
        field: complex64 ``[..., C, H, W]``.
        wrap: wrap the result to ``[0, 2π)`` (``exp(iP)`` does not depend on it; training skips it).
        clamp_eps: clamp ``Ã`` to ``1 − clamp_eps`` before ``acos``; use ``> 0`` (e.g. ``1e-6``) when
            differentiating, since ``d acos(x)/dx`` is infinite at the maximum pixel (``Ã = 1``).
    Returns:
        :class:`DoublePhase` with ``phase`` ``[..., C, H, W]`` (radians), ``amplitude_scale`` ``[...]`` and
        ``mean_phase`` ``[..., C]``.
    """
    h, w = field.shape[-2:]
    amp = field.abs()
    phi = torch.atan2(field.imag, field.real)
    a = amp.flatten(-3).amax(dim=-1)
    if not bool(torch.all(a > 0)):
        raise ValueError("hologram amplitude is zero everywhere: nothing to encode")
    mean = phi.double().mean(dim=(-2, -1)).to(phi.dtype)
    x = (amp / a[..., None, None, None]).clamp(max=1.0 - clamp_eps)
    theta = torch.acos(x)
    odd = checkerboard(h, w, field.device)
    centred = phi - mean[..., None, None]
    phase = torch.where(odd, centred - theta, centred + theta)
    if wrap:
        phase = wrap_phase(phase)
    return DoublePhase(phase=phase, amplitude_scale=a, mean_phase=mean)


@lru_cache(maxsize=32)
def _aperture_np(height: int, width: int, pad: bool) -> np.ndarray:
    factor = 2 if pad else 1
    ch, cw = height * factor, width * factor
    sy, sx = height / ch, width / cw
    r = min(height, width) / 2.0
    u = _signed_freq_index(cw)[None, :] * sx
    v = _signed_freq_index(ch)[:, None] * sy
    return (u * u + v * v <= r * r).astype(np.float32)


def aperture_mask(height: int, width: int, pad: bool = False, device=None) -> torch.Tensor:
    """Circular Fourier-plane aperture of Eq. 9 (``optics::filter::aperture_mask``).

    ``M = 1`` where ``kx² + ky² ≤ r²``, ``r = min(H, W)/2``, with ``kx, ky`` signed frequency indices of the
    unpadded grid (on a padded grid the indices are rescaled by ½, so it is the same physical filter).

    Args:
        height, width: field size in pixels.
        pad: mask for the ``2H × 2W`` padded grid.
        device: torch device.
    Returns:
        float32 ``[ch, cw]`` 0/1 mask in FFT order.
    """
    return torch.from_numpy(_aperture_np(height, width, pad)).to(device)


def fourier_filter(field: torch.Tensor) -> torch.Tensor:
    """Fourier filter of Eq. 8: ``F⁻¹{F{field}·M}`` on the unpadded grid (``optics::FourierFilter::apply``).

    Args:
        field: complex64 ``[..., H, W]``.
    Returns:
        complex64 ``[..., H, W]``.
    """
    h, w = field.shape[-2:]
    return torch.fft.ifft2(torch.fft.fft2(field) * aperture_mask(h, w, False, field.device))


def simulate_phase_only(
    phase: torch.Tensor, offset_m: float, display: Display, options=PropagationOptions()
) -> torch.Tensor:
    """What a phase-only SLM shows after the Fourier filter, at the midpoint plane (Eq. 8–10).

    ``ASM(F⁻¹{F{e^{iP}}·M}, −s)·e^{+i2πs/λ}`` (``optics::simulate_phase_only``): for a double-phase pattern the
    post-encoding midpoint hologram, whose amplitude approximates ``|H|/a``.

    Args:
        phase: float ``[..., 3, H, W]`` radians.
        offset_m: SLM distance ``s`` from the midpoint plane in metres.
        display: wavelengths and pitch.
        options: padding and band limit of the back-propagation (the filter is always unpadded).
    Returns:
        complex64 ``[..., 3, H, W]``.
    """
    slm = torch.polar(torch.ones_like(phase), phase)
    filtered = fourier_filter(slm)
    if offset_m == 0.0:
        return filtered
    return propagate(filtered, -offset_m, display.wavelengths_m, display.pixel_pitch_m, "remove", options)


def focal_stack(
    field: torch.Tensor,
    depths,
    display: Display,
    plane_z_m: float = 0.0,
    options: PropagationOptions = PropagationOptions(),
    aperture: bool = False,
    chunk: int | None = None,
) -> torch.Tensor:
    """Amplitude focal stack ``|ASM(field, z(d) − plane_z)|`` (``optics::focal_stack``, carrier removed).

    One forward FFT per field, one inverse per depth.

    Args:
        field: complex64 ``[B, C, H, W]`` lying at ``plane_z_m`` (0 for a midpoint hologram).
        depths: normalised depths (0 = near): a sequence/tensor ``[D]`` shared by the batch, or a tensor
            ``[B, D]`` with one set per item (the dynamic focal stack loss).
        display: wavelengths, pitch and volume depth.
        plane_z_m: axial position of ``field`` in metres.
        options: padding and band limit.
        aperture: apply the Fourier filter of Eq. 8–9 at the field's plane first.
        chunk: process at most this many depths at once (memory); ``None`` = all.
    Returns:
        float32 amplitudes ``[B, D, C, H, W]``.
    """
    b, c, h, w = field.shape
    if isinstance(depths, torch.Tensor):
        d = depths.detach().to("cpu", torch.float64)
    else:
        d = torch.tensor(list(depths), dtype=torch.float64)
    if d.dim() == 1:
        d = d[None, :].expand(b, -1)
    if d.shape[0] != b:
        raise ValueError(f"depths must be [D] or [B={b}, D], got {tuple(d.shape)}")
    z = display.depth_to_z(d) - plane_z_m  # [B, D] metres
    spec = spectrum(field, options.pad)[:, None]  # [B, 1, C, ch, cw]
    if aperture:
        spec = spec * aperture_mask(h, w, options.pad, field.device)
    n = d.shape[1]
    step = n if not chunk else chunk
    out = []
    for k in range(0, n, step):
        tf = transfer_function(
            h, w, display.pixel_pitch_m, display.wavelengths_m, z[:, k : k + step], "remove", options, field.device
        )  # [B, d, C, ch, cw]
        out.append(from_spectrum(spec * tf, h, w, options.pad).abs())
    return torch.cat(out, dim=1)


def gaussian_kernel(sigma_px: float, size: int) -> torch.Tensor:
    """Normalised 1D Gaussian of odd length ``size`` and standard deviation ``sigma_px`` (pixels), as the SDK's
    AA-DPM (``sdk/src/encoding/double_phase.rs``)."""
    if size < 1 or size % 2 == 0 or not sigma_px > 0:
        raise ValueError(f"need an odd size ≥ 1 and sigma > 0, got size {size}, sigma {sigma_px}")
    r = size // 2
    k = torch.exp(-torch.arange(-r, r + 1, dtype=torch.float32) ** 2 / (2.0 * sigma_px * sigma_px))
    return k / k.sum()


def anti_alias_blur(field: torch.Tensor, sigma_px: float = 0.7, size: int = 5) -> torch.Tensor:
    """The AA-DPM pre-filter (Shi et al. 2021): a separable Gaussian blur of the complex field
    ``[..., H, W]`` with edge pixels replicated, exactly as the SDK's ``DoublePhaseMethod::AntiAliased``
    (default σ = 0.7 px, 5 taps). Returns complex64 of the same shape."""
    k = gaussian_kernel(sigma_px, size).to(field.device)
    r = size // 2
    shape = field.shape
    x = torch.view_as_real(field.to(torch.complex64)).movedim(-1, -3).reshape(-1, 2, shape[-2], shape[-1])
    x = F.pad(x, (r, r, r, r), mode="replicate")
    x = F.conv2d(x, k.view(1, 1, 1, size).expand(2, 1, 1, size), groups=2)
    x = F.conv2d(x, k.view(1, 1, size, 1).expand(2, 1, size, 1), groups=2)
    x = x.reshape(*shape[:-2], 2, shape[-2], shape[-1]).movedim(-3, -1).contiguous()
    return torch.view_as_complex(x)


def amp_phase_to_complex(amplitude: torch.Tensor, phase01: torch.Tensor) -> torch.Tensor:
    """Complex field from the CNN heads (``docs/CONVENTIONS.md`` §7.1): ``A·exp(i·(p − 0.5)·2π)``.

    Args:
        amplitude: float ``[..., 3, H, W]`` in ``[0, √2]``.
        phase01: float ``[..., 3, H, W]`` in ``[0, 1]``.
    Returns:
        complex64 ``[..., 3, H, W]``.
    """
    return torch.polar(amplitude.float(), (phase01.float() - 0.5) * TAU)


def complex_to_amp_phase(field: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Inverse of :func:`amp_phase_to_complex`: ``(|H|, arg(H)/(2π) + 0.5)``, phase in ``[0, 1]``.

    Args:
        field: complex64 ``[..., 3, H, W]``.
    Returns:
        ``(amplitude, phase01)``, float32 ``[..., 3, H, W]`` each.
    """
    return field.abs(), torch.atan2(field.imag, field.real) / TAU + 0.5

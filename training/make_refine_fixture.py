"""The refinement's gradient by PyTorch autograd through this package's optics: the fixture the SDK's analytic
gradient is tested against (``sdk/src/refine/tests.rs``, ``the_gradient_is_pytorch_autograds``).

The loss is the SDK's (``sdk/src/refine/model.rs``, docs/REFINE.md): per colour ``c``,
``L_c = Σ_d ‖k_c·|U_d| − T_d‖²`` at the least-squares scale ``k_c = A_c/B_c``, i.e. ``L_c = E_c − A_c²/B_c`` with
``A_c = Σ_d ⟨|U_d|, T_d⟩``, ``B_c = Σ_d ‖U_d‖²``, ``E_c = Σ_d ‖T_d‖²``; ``L = Σ_c L_c``. ``U_d`` is the SLM field
``e^{iφ}`` through the Fourier filter (Eq. 8–9), propagated from the SLM plane (``z = s``) to the focal plane
``z(d)`` by the angular spectrum method with the carrier removed: :func:`optics.focal_stack` with
``plane_z_m = s`` and ``aperture=True``. Nothing here is the SDK's code: the gradient is autograd's.

Writes, to ``OUT`` (default ``sdk/tests/fixtures/refine_gradient``): ``phase.npy`` ``[3, H, W]`` (radians),
``target.npy`` ``[D, 3, H, W]`` (amplitudes at ``depths``), ``gradient.npy`` ``[3, H, W]`` (``∂L/∂φ``) and
``meta.json`` (the loss, depths, offset, display, seeds). Usage::

    python training/make_refine_fixture.py [OUT]
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from tensorholo_training.optics import Display, PropagationOptions, focal_stack  # noqa: E402

HEIGHT, WIDTH = 24, 32
# The SDK's loss planes for 3 planes (refine::loss_depths(3): k/(D − 1)).
DEPTHS = [0.0, 0.5, 1.0]
OFFSET_M = 2e-3
SEED = 7


def loss_of(phase: torch.Tensor, target: torch.Tensor, display: Display) -> torch.Tensor:
    """``L = Σ_c (E_c − A_c²/B_c)`` (float64) of ``phase`` ``[3, H, W]`` against ``target`` ``[D, 3, H, W]``."""
    field = torch.polar(torch.ones_like(phase), phase)[None]
    u = focal_stack(field, DEPTHS, display, plane_z_m=OFFSET_M, options=PropagationOptions(), aperture=True)[0]
    u, t = u.double(), target.double()
    a = (u * t).sum(dim=(0, 2, 3))
    b = (u * u).sum(dim=(0, 2, 3))
    e = (t * t).sum(dim=(0, 2, 3))
    return (e - a * a / b).sum()


def make(out: Path) -> dict:
    """Writes the fixture to ``out``; returns its metadata."""
    display = Display()
    rng = np.random.default_rng(SEED)
    phase = rng.uniform(0.0, 2.0 * math.pi, (3, HEIGHT, WIDTH)).astype(np.float32)
    # The target: the focal stack of another pattern (what some hologram shows), with multiplicative noise, so
    # that the loss's minimum is not at `phase`.
    other = torch.from_numpy(rng.uniform(0.0, 2.0 * math.pi, (3, HEIGHT, WIDTH)).astype(np.float32))
    with torch.no_grad():
        stack = focal_stack(
            torch.polar(torch.ones_like(other), other)[None], DEPTHS, display, plane_z_m=OFFSET_M, aperture=True
        )[0]
    noise = rng.uniform(0.8, 1.2, tuple(stack.shape)).astype(np.float32)
    target = (0.5 * stack.numpy() * noise).astype(np.float32)

    p = torch.from_numpy(phase).requires_grad_(True)
    loss = loss_of(p, torch.from_numpy(target), display)
    loss.backward()
    gradient = p.grad.numpy().astype(np.float32)

    out.mkdir(parents=True, exist_ok=True)
    np.save(out / "phase.npy", phase)
    np.save(out / "target.npy", target)
    np.save(out / "gradient.npy", gradient)
    meta = {
        "what": "the refinement's loss and its gradient by PyTorch autograd (training/make_refine_fixture.py)",
        "loss": float(loss.item()),
        "depths": DEPTHS,
        "offset_m": OFFSET_M,
        "display": display.to_dict(),
        "seed": SEED,
        "torch": torch.__version__,
    }
    (out / "meta.json").write_text(json.dumps(meta, indent=2) + "\n")
    return meta


if __name__ == "__main__":
    root = Path(__file__).resolve().parent.parent
    dest = Path(sys.argv[1]) if len(sys.argv) > 1 else root / "sdk/tests/fixtures/refine_gradient"
    m = make(dest)
    print(f"{dest}: loss {m['loss']:.6e}")

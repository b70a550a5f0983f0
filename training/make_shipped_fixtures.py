"""Writes the reference outputs that `sdk/tests/shipped_models.rs` compares tract against: for every shipped
model, a fixed random input and the PyTorch output of the checkpoint it was exported from.

    PYTHONPATH=training .venv/bin/python training/make_shipped_fixtures.py [--runs runs/cpu] [--out models/fixtures] \
        [--dataset data/cpu256]

Files: ``<name>_input.npy`` float32 ``[C, 24, 32]`` (``C`` = 4 for hologram CNNs: random RGB-D in ``[0, 1]``; 6
for pre-filters: ``[Re H, Im H]`` of a real offset hologram, the 8-layer CNN's midpoint hologram of a 24×32
crop of test scene 0 propagated to the pre-filter's offset, i.e. the distribution the pre-filter and its int8
calibration saw; a random-phase field is far outside it, and int8 pre-filters err by ≈ 0.08 on average there)
and the PyTorch outputs (f32), float32
``[3, 24, 32]`` each: ``<name>_amplitude.npy``, ``<name>_phase.npy`` of a hologram CNN, ``<name>_real.npy``,
``<name>_imag.npy`` of a pre-filter. The int8 files are checked against the same f32 outputs with the int8
tolerance. Checkpoints: ``best.pt`` of each run (what ``ship_cpu.sh export`` exports), ``final.pt`` for runs
older than ``best.pt``.
"""
from __future__ import annotations

import argparse
import os

import numpy as np
import torch

from tensorholo_training.export import OUTPUT_NAMES, load_checkpoint


def offset_hologram(dataset: str, holo_ckpt: str, cfg: dict) -> np.ndarray:
    """``[Re H, Im H]`` ``[6, 24, 32]`` of the offset hologram of a crop of test scene 0 (see the module docs)."""
    from tensorholo_training.data import LdiDataset
    from tensorholo_training.model import prefilter_input
    from tensorholo_training.optics import Display, amp_phase_to_complex, offset_to_slm

    net = load_checkpoint(holo_ckpt)["net"].eval()
    rgbd = LdiDataset(dataset, "test", 1)[0]["rgbd"][None, :, 100:124, 100:132]
    display = Display(tuple(cfg["wavelengths_m"]), cfg["pixel_pitch_m"], cfg["volume_depth_m"])
    with torch.no_grad():
        a, p = net(rgbd)
        slm = offset_to_slm(amp_phase_to_complex(a, p), cfg["offset_mm"] * 1e-3, display)
    return prefilter_input(slm)[0].numpy().astype(np.float32)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", default="runs/cpu")
    ap.add_argument("--out", default="models/fixtures")
    ap.add_argument("--dataset", default="data/cpu256", help="holo dataset whose test scene 0 feeds the pre-filters")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    rng = np.random.default_rng(2026)
    # the checkpoints ship_cpu.sh exports: best.pt (final.pt for runs older than best.pt)
    best = lambda run: f"{run}/best.pt" if os.path.exists(f"{run}/best.pt") else f"{run}/final.pt"  # noqa: E731
    jobs = [(f"holo{l}_rgbd", best(f"{args.runs}/holo{l}"), "net", 4) for l in (8, 15, 30)]
    jobs += [(f"prefilter_{o}mm", f"{args.runs}/pre{o}/best.pt", "prefilter", 6) for o in (6, 12)]
    for name, ckpt, key, channels in jobs:
        net = load_checkpoint(ckpt)[key].eval()
        x = rng.random((channels, 24, 32), dtype=np.float32)
        outputs = OUTPUT_NAMES["hologram-cnn" if key == "net" else "prefilter-cnn"]
        if key == "prefilter":
            x = offset_hologram(args.dataset, best(f"{args.runs}/holo8"), load_checkpoint(ckpt)["config"])
        with torch.no_grad():
            a, p = net(torch.from_numpy(x)[None])
        np.save(os.path.join(args.out, f"{name}_input.npy"), x)
        np.save(os.path.join(args.out, f"{name}_{outputs[0]}.npy"), a[0].numpy().astype(np.float32))
        np.save(os.path.join(args.out, f"{name}_{outputs[1]}.npy"), p[0].numpy().astype(np.float32))
        print(f"{name}: {ckpt} [{key}] -> {args.out}/{name}_*.npy")


if __name__ == "__main__":
    main()

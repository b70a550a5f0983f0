"""Writes the reference outputs that `sdk/tests/shipped_models.rs` compares tract against: for every shipped
model, a fixed random input and the PyTorch output of the checkpoint it was exported from.

    PYTHONPATH=training .venv/bin/python training/make_shipped_fixtures.py [--runs runs/cpu] [--out models/fixtures]

Files: ``<name>_input.npy`` float32 ``[C, 24, 32]`` (``C`` = 4 for hologram CNNs: RGB-D in ``[0, 1]``; 6 for
pre-filters: ``[Re H, Im H]`` of a random field with ``|H|`` up to 1.2) and the PyTorch outputs (f32), float32
``[3, 24, 32]`` each: ``<name>_amplitude.npy``, ``<name>_phase.npy`` of a hologram CNN, ``<name>_real.npy``,
``<name>_imag.npy`` of a pre-filter. The int8 files are checked against the same f32 outputs with the int8
tolerance. Pre-filters are read from ``best.pt`` (what ``ship_cpu.sh export`` exports), hologram CNNs from
``final.pt``.
"""
from __future__ import annotations

import argparse
import os

import numpy as np
import torch

from tensorholo_training.export import OUTPUT_NAMES, load_checkpoint


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", default="runs/cpu")
    ap.add_argument("--out", default="models/fixtures")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    rng = np.random.default_rng(2026)
    jobs = [(f"holo{l}_rgbd", f"{args.runs}/holo{l}/final.pt", "net", 4) for l in (8, 15, 30)]
    jobs += [(f"prefilter_{o}mm", f"{args.runs}/pre{o}/best.pt", "prefilter", 6) for o in (6, 12)]
    for name, ckpt, key, channels in jobs:
        net = load_checkpoint(ckpt)[key].eval()
        x = rng.random((channels, 24, 32), dtype=np.float32)
        outputs = OUTPUT_NAMES["hologram-cnn" if key == "net" else "prefilter-cnn"]
        if key == "prefilter":  # |H| of an offset hologram spans about [0, 1.2], any phase
            field = 1.2 * np.sqrt(x[:3]) * np.exp(2j * np.pi * x[3:])
            x = np.concatenate([field.real, field.imag]).astype(np.float32)
        with torch.no_grad():
            a, p = net(torch.from_numpy(x)[None])
        np.save(os.path.join(args.out, f"{name}_input.npy"), x)
        np.save(os.path.join(args.out, f"{name}_{outputs[0]}.npy"), a[0].numpy().astype(np.float32))
        np.save(os.path.join(args.out, f"{name}_{outputs[1]}.npy"), p[0].numpy().astype(np.float32))
        print(f"{name}: {ckpt} [{key}] -> {args.out}/{name}_*.npy")


if __name__ == "__main__":
    main()

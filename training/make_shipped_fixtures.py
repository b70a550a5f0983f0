"""Writes the reference outputs that `sdk/tests/shipped_models.rs` compares tract against: for every shipped
model, a fixed random input and the PyTorch output of the checkpoint it was exported from.

    PYTHONPATH=training .venv/bin/python training/make_shipped_fixtures.py [--runs runs/cpu] [--out models/fixtures]

Files: ``<name>_input.npy`` float32 ``[C, 24, 32]`` (``C`` = 4 for hologram CNNs, 6 for pre-filters) and
``<name>_amplitude.npy``, ``<name>_phase.npy`` float32 ``[3, 24, 32]`` (PyTorch, f32). The int8 files are
checked against the same f32 outputs with the int8 tolerance.
"""
from __future__ import annotations

import argparse
import os

import numpy as np
import torch

from tensorholo_training.export import load_checkpoint


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", default="runs/cpu")
    ap.add_argument("--out", default="models/fixtures")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    rng = np.random.default_rng(2026)
    jobs = [(f"holo{l}_rgbd", f"{args.runs}/holo{l}/final.pt", "net", 4) for l in (8, 15, 30)]
    jobs += [(f"prefilter_{o}mm", f"{args.runs}/pre{o}/final.pt", "prefilter", 6) for o in (6, 12)]
    for name, ckpt, key, channels in jobs:
        net = load_checkpoint(ckpt)[key].eval()
        x = rng.random((channels, 24, 32), dtype=np.float32)
        if channels == 6:
            x[:3] *= 1.2  # |H| of an offset hologram spans about [0, 1.2]
        with torch.no_grad():
            a, p = net(torch.from_numpy(x)[None])
        np.save(os.path.join(args.out, f"{name}_input.npy"), x)
        np.save(os.path.join(args.out, f"{name}_amplitude.npy"), a[0].numpy().astype(np.float32))
        np.save(os.path.join(args.out, f"{name}_phase.npy"), p[0].numpy().astype(np.float32))
        print(f"{name}: {ckpt} [{key}] -> {args.out}/{name}_*.npy")


if __name__ == "__main__":
    main()

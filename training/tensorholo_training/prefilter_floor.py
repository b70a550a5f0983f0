"""Compares a trained DDPM pre-filter with the non-learned encodings under the training's own validation
protocol (same scenes, crops, focal depths and metrics as the learning curve's ``val_psnr_*``).

The rows:

- ``ddpm``: the run's pre-filter CNN, then double phase (Eq. 6–7), Fourier filter, back to the midpoint;
- ``aa-dpm``: an untrained :class:`.model.PrefilterCNN` on the AA-DPM base (its correction starts at zero,
  so it is exactly the SDK's AA-DPM blur) in its place;
- ``dpm``: no pre-filter (plain double phase).

Each row gives the amplitude and focal-stack PSNR of the post-encoding midpoint hologram against the
ground truth, and the loss terms of stage 2 (including the Eq. 11 phase regulariser).

    python -m tensorholo_training.prefilter_floor runs/cpu/pre6            # run dir with config.json, final.pt
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os

import torch

from .model import prefilter_cnn
from .train import Trainer, TrainConfig


def compare(run_dir: str, checkpoint: str = "final.pt", batches: int | None = None) -> dict[str, dict]:
    """Validation metrics and mean stage-2 loss terms for the run's pre-filter, AA-DPM and plain DPM."""
    with open(os.path.join(run_dir, "config.json")) as f:
        cfg = TrainConfig.from_dict(json.load(f))
    cfg = dataclasses.replace(cfg, init_from=os.path.join(run_dir, checkpoint),
                              run_dir=os.path.join(run_dir, "prefilter_floor"), stages=["stage2"],
                              val_batches=batches or cfg.val_batches)
    tr = Trainer(cfg, log=lambda m: None)
    if tr.prefilter is None:
        raise ValueError(f"{run_dir} has no pre-filter (offset {cfg.offset_mm} mm)")
    out = {}
    aa = prefilter_cnn(cfg.prefilter_layers, cfg.prefilter_channels, "aa-dpm", cfg.aa_sigma_px,
                       cfg.aa_kernel_size).to(tr.device)
    for name, pf in [("ddpm", tr.prefilter), ("aa-dpm", aa), ("dpm", None)]:
        tr.prefilter = pf
        row = tr.validate("stage2")
        terms: dict[str, float] = {}
        n = 0
        for k, _, batch in tr.val_batches():
            with torch.no_grad():
                res = tr.compute_loss(batch, "stage2", tr._generator(k, salt=1))
            for key, v in res.items():
                if key != "pred":
                    terms[key] = terms.get(key, 0.0) + float(v)
            n += 1
        out[name] = row | {f"loss_{k}": v / max(n, 1) for k, v in terms.items()}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tensorholo_training.prefilter_floor",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("run_dir")
    ap.add_argument("--checkpoint", default="final.pt")
    ap.add_argument("--batches", type=int, help="validation batches (default: the run's val_batches)")
    args = ap.parse_args(argv)
    rows = compare(args.run_dir, args.checkpoint, args.batches)
    print("| encoding | val PSNR amplitude (dB) | val PSNR focal stack (dB) | focal-stack loss | Eq. 11 regulariser |")
    print("|---|---:|---:|---:|---:|")
    for name, r in rows.items():
        print(f"| {name} | {r['val_psnr_amp']:.2f} | {r['val_psnr_fs']:.2f} | {r['loss_focal_stack']:.5f} | "
              f"{r['loss_regulariser']:.4f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

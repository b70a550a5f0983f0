"""Experiment (not part of the package or the SDK yet): a DDPM pre-filter in real/imaginary channels with a
complex residual, ``H' = base(H) + f([Re H, Im H])``, where ``base`` is the identity or the AA-DPM blur and
the last layer of ``f`` starts at zero. The pre-filter therefore starts exactly at plain DPM or at AA-DPM,
which the shipped amplitude/phase pre-filter cannot reproduce (training/README.md, "Why the shipped
pre-filters lose to AA-DPM").

It trains stage 2 (DDPM) with the frozen hologram CNN of a pre-filter run's configuration, and prints the
validation PSNR of the post-encoding hologram at the start, during and at the end. The protocol is the one of
``prefilter_floor``. Run from the repository root:

    PYTHONPATH=training .venv/bin/python training/experiments/cartesian_prefilter.py \\
        --config runs/cpu/pre6/config.json --base aa-dpm --w-regulariser 0.01 --steps 1000 --run-dir runs/exp/cart
"""
from __future__ import annotations

import argparse
import dataclasses
import json

import torch
from torch import nn

from tensorholo_training import optics as O
from tensorholo_training.model import ResidualCNN
from tensorholo_training.train import Trainer, TrainConfig


class CartesianPrefilter(nn.Module):
    """``H' = base(H) + f([Re H, Im H])`` with the pre-filter interface (input/output amplitude, phase01)."""

    def __init__(self, layers: int = 8, channels: int = 8, base: str = "identity"):
        super().__init__()
        self.base = base
        self.net = ResidualCNN(layers, channels, in_channels=6, out_channels=6, centre_input=False)
        nn.init.zeros_(self.net.convs[-1].weight)
        nn.init.zeros_(self.net.convs[-1].bias)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h = O.amp_phase_to_complex(x[:, :3], x[:, 3:])
        d = self.net.raw(torch.cat([h.real, h.imag], 1))
        if self.base == "aa-dpm":
            h = O.anti_alias_blur(h)
        return O.complex_to_amp_phase(torch.complex(h.real + d[:, :3], h.imag + d[:, 3:]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", required=True, help="a pre-filter run's config.json (dataset, CNN, offset)")
    ap.add_argument("--base", choices=["identity", "aa-dpm"], default="aa-dpm")
    ap.add_argument("--w-regulariser", type=float, default=0.01)
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--run-dir", required=True)
    args = ap.parse_args()
    with open(args.config) as f:
        base = TrainConfig.from_dict(json.load(f))
    cfg = dataclasses.replace(base, run_dir=args.run_dir, stages=["stage2"], stage2_steps=args.steps,
                              w_regulariser=args.w_regulariser, val_every=250, log_every=250,
                              ckpt_every=10 ** 9)
    tr = Trainer(cfg, log=lambda m: print(m, flush=True))
    tr.prefilter = CartesianPrefilter(cfg.prefilter_layers, cfg.prefilter_channels, args.base)
    tr._new_optimizer()
    print("start:", tr.validate("stage2"), flush=True)
    tr.run()
    print("end:", tr.validate("stage2"), flush=True)


if __name__ == "__main__":
    main()

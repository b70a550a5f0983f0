"""Experiments of issue 23 on why the LDI hologram CNN does not use the layers behind the first (the record
behind models/MODEL_CARD.md, "LDI: why the hidden layers stay unused"). Not part of the shipped training.

Each ``train`` variant fine-tunes an 8-layer LDI CNN from the RGB-D CNN ``runs/photo/holo8/best.pt`` (the
shipped ``holo8_rgbd``, step 7500) on ``data/photo256`` for STEPS steps (cosine learning rate 3e-4 → 3e-5,
``fs_attention = "layers"``), like the shipped ``holo8_ldi`` (which used ``"front"``):

- ``attention``: that alone;
- ``input-scale``: the back layers' inputs multiplied by 10 before the network (the same function as weights
  10× larger: Adam then moves those weights 10× faster); the saved checkpoints have the 10 folded into the
  weights;
- ``occlusion-weight``: the data and focal-stack losses weighted ``1 + 4·M`` (normalised to mean 1), ``M`` the
  pixels within 12 px of a front-layer point with a hidden point behind it near the edge of what it hides;
- ``sum-init``: the back layers' first-layer weights start equal to the front layer's (the network first sees
  hidden points as if visible), the bias compensated so that a pixel with no hidden point starts as in the
  RGB-D CNN.

``oracle`` compares, on test scenes, the SM-LBM hologram of the front layer alone with that of the whole LDI (how
much the hidden points change the ground truth), next to the CNNs' own errors (12-plane focal stack PSNR).

    PYTHONPATH=training python training/experiments/ldi_hidden_layers.py train attention runs/photo/ldi_att_a 2000
    python training/ldi_probe.py runs/photo/ldi_att_a/final.pt
    # oracle: each test scene as an LDI folder, its SM-LBM with all layers and with the front alone
    for i in 0 1 2 3 4 5; do
      holo dataset --out /tmp/ldi$i --export-ldi test:$i --size 256 --seed 2027 --photos data/photos \\
          --photo-probability 0.6 --test 40
      mkdir -p /tmp/front$i && cp /tmp/ldi$i/rgb_0.png /tmp/ldi$i/depth_0.png /tmp/front$i/
      holo reference --ldi /tmp/ldi$i --depth-encoding relative16 --out /tmp/ref${i}_ldi
      holo reference --ldi /tmp/front$i --depth-encoding relative16 --out /tmp/ref${i}_front
    done
    PYTHONPATH=training python training/experiments/ldi_hidden_layers.py oracle /tmp 6
"""
from __future__ import annotations

import sys

import numpy as np
import torch
import torch.nn.functional as F

from tensorholo_training import losses as L
from tensorholo_training import optics
from tensorholo_training.metrics import psnr
from tensorholo_training.model import hologram_cnn
from tensorholo_training.optics import Display, PropagationOptions
from tensorholo_training.train import Trainer, load_config

VARIANTS = ("attention", "input-scale", "occlusion-weight", "sum-init")


def trainer(run_dir: str, steps: int) -> Trainer:
    cfg = load_config("training/configs/cpu_stage1.json", [
        'dataset="data/photo256"', "num_layers=8", "input_layers=5", 'init_from="runs/photo/holo8/best.pt"',
        'fs_attention="layers"', 'lr_schedule="cosine"', f"stage1_steps={steps}"], run_dir=run_dir)
    return Trainer(cfg, log=print)


def occlusion_weight(valid: torch.Tensor, radius: int = 12, alpha: float = 4.0) -> torch.Tensor:
    """``[B, 1, H, W]``: ``1 + alpha·dilate(M)`` over its mean, ``M`` = a hidden point behind the front layer
    within ``radius`` px of a pixel with none (the edge of what the front hides)."""
    v = valid[:, 1:2].float()
    edge = v * F.max_pool2d(1 - v, 2 * radius + 1, 1, radius)
    w = 1 + alpha * F.max_pool2d(edge, 2 * radius + 1, 1, radius)
    return w / w.mean(dim=(-2, -1), keepdim=True)


def train(variant: str, run_dir: str, steps: int) -> None:
    tr = trainer(run_dir, steps)
    if variant == "input-scale":
        forward = tr.net.forward
        tr.net.forward = lambda x: forward(torch.cat([x[:, :4], 10.0 * x[:, 4:]], 1))
    elif variant == "occlusion-weight":
        current: dict = {}
        compute_loss = tr.compute_loss

        def weighted(batch, phase, generator):
            current["w"] = occlusion_weight(batch["valid"])
            return compute_loss(batch, phase, generator)

        attention = L.attention_masks

        def data_fidelity(pred, gt, mode="complex", kind="l2"):
            d = pred * L.global_phase(pred, gt) - gt
            return ((d.abs() ** 2) * current["w"]).mean()

        tr.compute_loss = weighted
        L.attention_masks = lambda *a, **k: attention(*a, **k) * current["w"][:, None, None]
        L.data_fidelity_loss = data_fidelity
    elif variant == "sum-init" and tr.global_step == 0:
        with torch.no_grad():
            conv = tr.net.convs[0]
            for k in range(1, 5):
                conv.weight[:, 4 * k:4 * k + 4] = conv.weight[:, 0:4]
            # an empty back layer (amplitude 0, depth 1) adds the depth taps' sum: taken back off the bias
            conv.bias -= 4 * conv.weight[:, 3].sum(dim=(1, 2))
        tr._new_optimizer()
    elif variant != "attention":
        raise SystemExit(f"variant must be one of {VARIANTS}")
    tr.run()
    if variant == "input-scale":
        fold_input_scale(run_dir, 10.0)


def fold_input_scale(run_dir: str, scale: float) -> None:
    """Multiplies the back layers' input weights of the run's ``best.pt`` and ``final.pt`` by ``scale`` (the
    first convolution's and the last one's input part), so that the saved networks compute what the run did
    without the scaled input (``ldi_probe.py``, export)."""
    import os

    for name in ("best.pt", "final.pt"):
        path = os.path.join(run_dir, name)
        if not os.path.exists(path):
            continue
        st = torch.load(path, map_location="cpu", weights_only=False)
        net = st["net"]
        c = st["config"].get("channels", 24)
        # the network centres its input (x − 0.5) after the scaling: conv(W, s·x − 0.5) =
        # conv(s·W, x − 0.5) + (s − 1)·0.5·ΣW, a bias (exact away from the zero-padded border)
        for conv, first_back in ((0, 4), (st["config"]["num_layers"] - 1, c + 4)):
            w, b = net[f"convs.{conv}.weight"], net[f"convs.{conv}.bias"]
            b += (scale - 1) * 0.5 * w[:, first_back:].sum(dim=(1, 2, 3))
            w[:, first_back:] *= scale
        torch.save(st, path)


def oracle(root: str, scenes: int) -> None:
    display = Display((6.38e-7, 5.2e-7, 4.5e-7), 8e-6, 6e-3)
    focal = torch.linspace(0.02, 0.98, 12)[None]
    shard = np.load("data/photo256/test-00000.npz")

    def stack(field) -> torch.Tensor:
        f = torch.from_numpy(np.asarray(field))[None].to(torch.complex64)
        return optics.focal_stack(f, focal, display, 0.0, PropagationOptions())[0]

    def fs_psnr(a: torch.Tensor, b: torch.Tensor) -> float:
        return float(psnr(a.flatten(0, 1)[:, None], b.flatten(0, 1)[:, None]).mean())

    nets = {}
    for name, path in (("RGB-D CNN", "runs/photo/holo8/best.pt"), ("LDI CNN", "runs/photo/holo8_ldi_v2/best.pt")):
        st = torch.load(path, map_location="cpu", weights_only=False)
        net = hologram_cnn(8, st["config"]["input_layers"])
        net.load_state_dict(st["net"])
        nets[name] = (net.eval(), st["config"]["input_layers"])
    for i in range(scenes):
        gt = stack(shard["midpoint"][i])
        row = [f"scene {i}: SM-LBM of the whole LDI (holo reference) {fs_psnr(stack(np.load(f'{root}/ref{i}_ldi/midpoint.npy')), gt):.1f}",
               f"of the front layer alone {fs_psnr(stack(np.load(f'{root}/ref{i}_front/midpoint.npy')), gt):.2f}"]
        x = torch.from_numpy(shard["ldi"][i])[None]
        for name, (net, layers) in nets.items():
            with torch.no_grad():
                a, p = net(x[:, :4 * layers])
            row.append(f"{name} {fs_psnr(stack(optics.amp_phase_to_complex(a, p)[0].numpy()), gt):.2f}")
        print(" | ".join(row))


if __name__ == "__main__":
    if len(sys.argv) == 5 and sys.argv[1] == "train":
        train(sys.argv[2], sys.argv[3], int(sys.argv[4]))
    elif len(sys.argv) == 4 and sys.argv[1] == "oracle":
        oracle(sys.argv[2], int(sys.argv[3]))
    else:
        raise SystemExit(__doc__)

"""Writes the reference outputs that `sdk/tests/shipped_models.rs` compares tract against: for every shipped
model, a fixed random input and the PyTorch output of the checkpoint it was exported from.

    PYTHONPATH=training .venv/bin/python training/make_shipped_fixtures.py [--runs runs/cpu] [--out models/fixtures] \
        [--dataset data/cpu256] [--ldi-run runs/photo/holo8_ldi_ws] [--only NAME ...]

The pre-filters of the 15- and 30-layer CNNs (``prefilter_{6,12}mm_holo{15,30}``) see the offset hologram of
their own CNN (the shipped ONNX file) on test scene 0 of ``--pair-dataset``.

Files: ``<name>_input.npy`` float32 ``[C, 24, 32]`` (``C`` = 4 for RGB-D hologram CNNs: random RGB-D in ``[0, 1]``;
20 for the LDI CNN ``holo8_ldi``: a random 5-layer LDI, layers valid front to back, invalid points amplitude 0 and
depth 1; 6
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


def hologram_net(source: str):
    """The hologram CNN of a checkpoint (``.pt``) or of a shipped f32 ONNX file."""
    if not source.endswith(".onnx"):
        return load_checkpoint(source)["net"].eval()
    from tensorholo_training.export import read_metadata
    from tensorholo_training.model import hologram_cnn
    from tensorholo_training.train import initial_state

    md = read_metadata(source)
    net = hologram_cnn(int(md["tensorholo.layers"]), int(md["tensorholo.input_layers"]))
    net.load_state_dict(initial_state(source, "cpu")["net"])
    return net.eval()


def offset_hologram(dataset: str, holo_source: str, cfg: dict) -> np.ndarray:
    """``[Re H, Im H]`` ``[6, 24, 32]`` of the offset hologram of a crop of test scene 0 (see the module docs)."""
    from tensorholo_training.data import LdiDataset
    from tensorholo_training.model import prefilter_input
    from tensorholo_training.optics import Display, amp_phase_to_complex, offset_to_slm

    net = hologram_net(holo_source)
    rgbd = LdiDataset(dataset, "test", 1)[0]["rgbd"][None, :, 100:124, 100:132]
    display = Display(tuple(cfg["wavelengths_m"]), cfg["pixel_pitch_m"], cfg["volume_depth_m"])
    with torch.no_grad():
        a, p = net(rgbd)
        slm = offset_to_slm(amp_phase_to_complex(a, p), cfg["offset_mm"] * 1e-3, display)
    return prefilter_input(slm)[0].numpy().astype(np.float32)


def random_ldi(rng: np.random.Generator, layers: int = 5, h: int = 24, w: int = 32) -> np.ndarray:
    """A random LDI ``[4·layers, h, w]`` as the dataset stores one: layer 0 valid everywhere, each further
    layer valid only where the one in front is (probability 0.6), never nearer; invalid points amplitude 0 and
    depth 1."""
    x = np.zeros((4 * layers, h, w), np.float32)
    valid = np.ones((h, w), bool)
    depth = np.zeros((h, w), np.float32)
    for k in range(layers):
        if k:
            valid &= rng.random((h, w)) < 0.6
        depth = depth + (1 - depth) * rng.random((h, w), dtype=np.float32)
        x[4 * k:4 * k + 3] = np.where(valid, rng.random((3, h, w), dtype=np.float32), 0)
        x[4 * k + 3] = np.where(valid, depth, 1)
    return x


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", default="runs/cpu")
    ap.add_argument("--out", default="models/fixtures")
    ap.add_argument("--dataset", default="data/cpu256", help="holo dataset whose test scene 0 feeds the pre-filters")
    ap.add_argument("--ldi-run", default="runs/photo/holo8_ldi_ws", help="the run holo8_ldi was exported from")
    ap.add_argument("--pair-runs", default="runs/photo",
                    help="folder of the pre{6,12}_holo{15,30} runs (pre-filters of the 15/30-layer CNNs)")
    ap.add_argument("--pair-dataset", default="data/photo256",
                    help="holo dataset whose test scene 0 feeds the 15/30-layer CNNs' pre-filters")
    ap.add_argument("--only", nargs="*", help="write only these fixtures (e.g. holo8_ldi)")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    rng = np.random.default_rng(2026)
    # the checkpoints ship_cpu.sh exports: best.pt (final.pt for runs older than best.pt)
    best = lambda run: f"{run}/best.pt" if os.path.exists(f"{run}/best.pt") else f"{run}/final.pt"  # noqa: E731
    jobs = [(f"holo{l}_rgbd", best(f"{args.runs}/holo{l}"), "net", 4) for l in (8, 15, 30)]
    jobs += [(f"prefilter_{o}mm", f"{args.runs}/pre{o}/best.pt", "prefilter", 6) for o in (6, 12)]
    jobs += [("holo8_ldi", best(args.ldi_run), "net", 20)]
    paired = [(f"prefilter_{o}mm_holo{l}", f"{args.pair_runs}/pre{o}_holo{l}/best.pt", "prefilter", 6)
              for l in (15, 30) for o in (6, 12)]
    jobs += paired
    for name, ckpt, key, channels in jobs:
        if args.only and name not in args.only:
            continue
        net = load_checkpoint(ckpt)[key].eval()
        x = rng.random((channels, 24, 32), dtype=np.float32) if channels != 20 else random_ldi(np.random.default_rng(2027))
        outputs = OUTPUT_NAMES["hologram-cnn" if key == "net" else "prefilter-cnn"]
        if (name, ckpt, key, channels) in paired:  # on the holograms of the shipped CNN they were trained with
            layers = name.rsplit("_holo", 1)[1]
            x = offset_hologram(args.pair_dataset, f"models/holo{layers}_rgbd.onnx", load_checkpoint(ckpt)["config"])
        elif key == "prefilter":
            x = offset_hologram(args.dataset, best(f"{args.runs}/holo8"), load_checkpoint(ckpt)["config"])
        with torch.no_grad():
            a, p = net(torch.from_numpy(x)[None])
        np.save(os.path.join(args.out, f"{name}_input.npy"), x)
        np.save(os.path.join(args.out, f"{name}_{outputs[0]}.npy"), a[0].numpy().astype(np.float32))
        np.save(os.path.join(args.out, f"{name}_{outputs[1]}.npy"), p[0].numpy().astype(np.float32))
        print(f"{name}: {ckpt} [{key}] -> {args.out}/{name}_*.npy")


if __name__ == "__main__":
    main()

"""The model card's picture: one test scene of the dataset refocused near, middle and far, for the SM-LBM
ground truth, the non-learned baselines and every shipped model (what the SLM shows: offset, pre-filter,
double phase, Fourier filter; ``--phase-only`` evaluation chain).

    PYTHONPATH=training .venv/bin/python training/model_card_figure.py --dataset data/cpu256 --index 0 \\
        --baselines data/cpu256/baselines --out models/model_card_focal_stacks.png

Rows (central 128×128 crops by default): ground truth, Maimone-style, SM-LBM + AA-DPM (6 mm), holo8 f32 +
AA-DPM (6 mm, the non-learned encoding of the CNN's hologram), then holo8/15/30 + its own 6 mm pre-filter (DDPM),
f32 and the default int8 form. Columns: focused at the 10th, 50th and 90th percentile of the scene's depth. A PNG is
written with zlib only (no imaging library needed).
"""
from __future__ import annotations

import argparse
import os
import struct
import zlib

import numpy as np
import torch

from tensorholo_training import optics
from tensorholo_training.data import LdiDataset, manifest_propagation, read_manifest
from tensorholo_training.evaluate import npy_baseline, onnx_predictor
from tensorholo_training.optics import Display, PropagationOptions


def write_png(path: str, rgb: np.ndarray) -> None:
    """Writes an 8-bit RGB image ``[H, W, 3]``."""
    h, w, _ = rgb.shape
    raw = b"".join(b"\x00" + rgb[y].tobytes() for y in range(h))

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b"")
    with open(path, "wb") as f:
        f.write(png)


def to_srgb8(amp: np.ndarray) -> np.ndarray:
    """Amplitude ``[3, H, W]`` → 8-bit sRGB ``[H, W, 3]`` (intensity = amplitude²)."""
    i = np.clip(amp, 0, 1) ** 2
    s = np.where(i <= 0.0031308, 12.92 * i, 1.055 * i ** (1 / 2.4) - 0.055)
    return (np.clip(s, 0, 1) * 255 + 0.5).astype(np.uint8).transpose(1, 2, 0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dataset", required=True)
    ap.add_argument("--split", default="test")
    ap.add_argument("--index", type=int, default=0)
    ap.add_argument("--models", default="models")
    ap.add_argument("--baselines", help="holo baselines output folder")
    ap.add_argument("--int8", default="int8-qdq", help="int8 form to show (file suffix)")
    ap.add_argument("--crop", type=int, default=128, help="central crop of each tile (pixels; 0 = whole)")
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    options = manifest_propagation(read_manifest(args.dataset)) or PropagationOptions()
    display = Display()
    item = LdiDataset(args.dataset, args.split, 1)[args.index]
    depth = item["depth"]
    d = torch.quantile(depth.flatten(), torch.tensor([0.1, 0.5, 0.9])).float()
    rows = [("ground truth (SM-LBM, 5-layer LDI)", item["midpoint"])]
    if args.baselines:
        rows.append(("Maimone-style", npy_baseline(os.path.join(args.baselines, "maimone"))(args.index, item)))
        rows.append(("SM-LBM + AA-DPM, 6 mm", npy_baseline(os.path.join(args.baselines, "smlbm-aadpm-6mm"))(
            args.index, item)))
    holo8 = os.path.join(args.models, "holo8_rgbd.onnx")
    rows.append(("holo8 f32 + AA-DPM, 6 mm", onnx_predictor(holo8, None, 6e-3, display, True, options,
                                                            aa_dpm=True)(args.index, item)))
    for layers in (8, 15, 30):
        for suffix in ("", "." + args.int8):
            net = os.path.join(args.models, f"holo{layers}_rgbd{suffix}.onnx")
            own = "" if layers == 8 else f"_holo{layers}"  # each CNN with the pre-filter trained on its holograms
            pre = os.path.join(args.models, f"prefilter_6mm{own}{suffix}.onnx")
            predict = onnx_predictor(net, pre, 6e-3, display, True, options)
            rows.append((f"holo{layers}{suffix or ' f32'} + 6 mm pre-filter", predict(args.index, item)))
    tiles = []
    for name, field in rows:
        stack = optics.focal_stack(field[None], d[None], display, 0.0, options)[0].numpy()
        if args.crop:
            h, w = stack.shape[-2:]
            y, x = (h - args.crop) // 2, (w - args.crop) // 2
            stack = stack[..., y:y + args.crop, x:x + args.crop]
        tiles.append(np.concatenate([to_srgb8(stack[k]) for k in range(3)], axis=1))
        print(f"row {len(tiles)}: {name}")
    sep = np.full((4, tiles[0].shape[1], 3), 255, np.uint8)
    grid = np.concatenate(sum([[t, sep] for t in tiles], [])[:-1], axis=0)
    write_png(args.out, grid)
    print(f"wrote {args.out} ({grid.shape[1]}x{grid.shape[0]})")


if __name__ == "__main__":
    main()

"""Does an LDI hologram CNN use the layers behind the first? The bar-over-wall probe of
``sdk/tests/generator.rs`` (``wall_behind_bar_ratios``) on training checkpoints and f32 ONNX files.

The scene (64×96): a dark bar (columns 44–51, depth 0.1) 4.8 mm in front of a finely textured green wall
(depth 0.9); the LDI's second layer holds the wall behind the bar. Focused on the wall, the ratio is the green
amplitude behind the bar's centre (rows 16–47, columns 46–49) over the wall's beside it (columns 12–23). SM-LBM
gives 0.40 with both layers and 0.10 with the front layer alone (the Rust test computes both); a CNN that uses
the hidden wall gives more with the back layer than without it.

    python training/ldi_probe.py runs/photo/holo8_ldi_v2/best.pt models/holo8_ldi.onnx models/holo8_rgbd.onnx

prints, per network, the ratio given both layers and given the front layer alone (an RGB-D CNN: the front).
"""
from __future__ import annotations

import argparse
import sys

import numpy as np
import torch

from tensorholo_training import optics
from tensorholo_training.optics import Display, PropagationOptions

H, W = 64, 96
BAR = slice(44, 52)
WALL_DEPTH, BAR_DEPTH = 0.9, 0.1


def scene(layers: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """The CNN inputs ``[4·layers, H, W]``: the front layer alone (the rest empty: amplitude 0, depth 1) and
    the LDI with the wall behind the bar in layer 1. The wall's texture is the Rust test's hash."""
    y, x = np.mgrid[0:H, 0:W].astype(np.uint64)
    with np.errstate(over="ignore"):
        n = ((y * np.uint64(131) + x * np.uint64(71) + np.uint64(17)) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(40)
    v = 0.3 + 0.7 * (n.astype(np.float64) / float(1 << 24))
    wall = np.stack([0.3 * v, v, 0.3 * v]).astype(np.float32)
    front = np.zeros((4 * layers, H, W), np.float32)
    front[3::4] = 1.0
    front[0:3] = wall
    front[0:3, :, BAR] = 0.05
    front[3] = WALL_DEPTH
    front[3, :, BAR] = BAR_DEPTH
    both = front.copy()
    if layers > 1:
        both[4:7, :, BAR] = wall[:, :, BAR]
        both[7, :, BAR] = WALL_DEPTH
    return front, both


def ratio(net: torch.nn.Module, x: np.ndarray, display: Display) -> float:
    """Green amplitude behind the bar's centre over the wall's beside it, focused on the wall."""
    with torch.no_grad():
        a, p = net(torch.from_numpy(x)[None])
        field = optics.amp_phase_to_complex(a.float(), p.float())
        stack = optics.focal_stack(field, torch.tensor([[WALL_DEPTH]]), display, 0.0, PropagationOptions())
    g = stack[0, 0, 1].numpy()
    return float(g[16:48, 46:50].mean() / g[16:48, 12:24].mean())


def load(path: str) -> tuple[torch.nn.Module, int, Display]:
    """A hologram CNN from a training checkpoint or an f32 ONNX file, its input layers and its optics."""
    if path.endswith(".onnx"):
        from tensorholo_training.export import load_onnx_network

        net, md = load_onnx_network(path)
        layers = int(md["tensorholo.input_layers"])
        wl = tuple(float(v) for v in md["tensorholo.wavelengths_m"].split(","))
        display = Display(wl, float(md["tensorholo.pixel_pitch_m"]), float(md["tensorholo.volume_depth_m"]))
    else:
        from tensorholo_training.model import hologram_cnn

        st = torch.load(path, map_location="cpu", weights_only=False)
        c = st["config"]
        net = hologram_cnn(c["num_layers"], c["input_layers"], c.get("channels", 24))
        net.load_state_dict(st["net"])
        layers = c["input_layers"]
        display = Display(tuple(c["wavelengths_m"]), c["pixel_pitch_m"], c["volume_depth_m"])
    return net.eval(), layers, display


def probe(path: str) -> dict:
    """``{"input_layers", "both", "front"}`` ratios of one network (``both`` is ``None`` for an RGB-D CNN)."""
    net, layers, display = load(path)
    front, both = scene(layers)
    return {"input_layers": layers, "front": ratio(net, front, display),
            "both": ratio(net, both, display) if layers > 1 else None}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("networks", nargs="+", help="training checkpoints (.pt) or f32 ONNX files")
    args = ap.parse_args(argv)
    for path in args.networks:
        r = probe(path)
        both = "—" if r["both"] is None else f"{r['both']:.3f}"
        print(f"{path}: with the back layer {both}, front layer alone {r['front']:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

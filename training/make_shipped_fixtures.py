"""Writes the reference outputs that `sdk/tests/shipped_models.rs` compares tract against: for every shipped
model, a fixed input and the PyTorch output of the network rebuilt from the shipped f32 ONNX file (its
initialisers carry the PyTorch parameter names; ``training/tests/test_export.py`` checks that export and
rebuild round-trip exactly), so no training run is needed.

    PYTHONPATH=training .venv/bin/python training/make_shipped_fixtures.py [--models models] \
        [--out models/fixtures] [--dataset data/photo256] [--only NAME ...]

Files: ``<name>_input.npy`` float32 ``[C, 24, 32]`` (``C`` = 4 for RGB-D hologram CNNs: random RGB-D in ``[0, 1]``;
20 for the LDI CNN ``holo8_ldi``: a random 5-layer LDI, layers valid front to back, invalid points amplitude 0 and
depth 1; 6 for pre-filters: ``[Re H, Im H]`` of a real offset hologram, the midpoint hologram of the CNN the
pre-filter was trained with (``tensorholo.hologram_layers``, the shipped f32 file) on a 24×32 crop of test
scene 0 of ``--dataset`` propagated to the pre-filter's offset, i.e. the distribution the pre-filter and its
int8 calibration saw; a random-phase field is far outside it, and int8 pre-filters err by ≈ 0.08 on average
there) and the PyTorch outputs (f32), float32 ``[3, 24, 32]`` each: ``<name>_amplitude.npy``,
``<name>_phase.npy`` of a hologram CNN, ``<name>_real.npy``, ``<name>_imag.npy`` of a pre-filter. The int8
files are checked against the same f32 outputs with the int8 tolerance.
"""
from __future__ import annotations

import argparse
import os

import numpy as np
import torch

from tensorholo_training.export import OUTPUT_NAMES, load_onnx_network


def offset_hologram(dataset: str, holo_path: str, md: dict) -> np.ndarray:
    """``[Re H, Im H]`` ``[6, 24, 32]`` of the offset hologram of a crop of test scene 0 (see the module docs), at
    the offset and optics of the pre-filter metadata ``md``."""
    from tensorholo_training.data import LdiDataset
    from tensorholo_training.model import prefilter_input
    from tensorholo_training.optics import Display, amp_phase_to_complex, offset_to_slm

    net, _ = load_onnx_network(holo_path)
    rgbd = LdiDataset(dataset, "test", 1)[0]["rgbd"][None, :, 100:124, 100:132]
    wavelengths = tuple(float(w) for w in md["tensorholo.wavelengths_m"].split(","))
    display = Display(wavelengths, float(md["tensorholo.pixel_pitch_m"]), float(md["tensorholo.volume_depth_m"]))
    with torch.no_grad():
        a, p = net(rgbd)
        slm = offset_to_slm(amp_phase_to_complex(a, p), float(md["tensorholo.offset_m"]), display)
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


#: every shipped model with a fixture: hologram CNNs, then pre-filters (``prefilter_{6,12}mm`` go with holo8)
NAMES = ([f"holo{l}_rgbd" for l in (8, 15, 30)] + ["holo8_ldi"]
         + [f"prefilter_{o}mm{suffix}" for suffix in ("", "_holo15", "_holo30") for o in (6, 12)])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", default="models", help="folder of the shipped f32 ONNX files")
    ap.add_argument("--out", default="models/fixtures")
    ap.add_argument("--dataset", default="data/photo256", help="holo dataset whose test scene 0 feeds the pre-filters")
    ap.add_argument("--only", nargs="*", help="write only these fixtures (e.g. holo8_ldi)")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    rng = np.random.default_rng(2026)
    for name in NAMES:
        path = os.path.join(args.models, f"{name}.onnx")
        net, md = load_onnx_network(path)
        kind = md["tensorholo.kind"]
        if kind == "prefilter-cnn":
            holo = os.path.join(args.models, f"holo{md['tensorholo.hologram_layers']}_rgbd.onnx")
            x = offset_hologram(args.dataset, holo, md)
        elif md["tensorholo.input_layers"] == "5":
            x = random_ldi(np.random.default_rng(2027))
        else:  # drawn for every RGB-D CNN, written or not, so that --only leaves the others' inputs unchanged
            x = rng.random((4, 24, 32), dtype=np.float32)
        if args.only and name not in args.only:
            continue
        with torch.no_grad():
            a, p = net(torch.from_numpy(x)[None])
        outputs = OUTPUT_NAMES[kind]
        np.save(os.path.join(args.out, f"{name}_input.npy"), x)
        np.save(os.path.join(args.out, f"{name}_{outputs[0]}.npy"), a[0].numpy().astype(np.float32))
        np.save(os.path.join(args.out, f"{name}_{outputs[1]}.npy"), p[0].numpy().astype(np.float32))
        print(f"{name}: {path} -> {args.out}/{name}_*.npy")


if __name__ == "__main__":
    main()

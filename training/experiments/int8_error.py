"""How far a pre-filter's int8 form is from its f32 output (issue 23; models/MODEL_CARD.md, "int8: what did not
help"): mean squared error of the fake-quantised pre-filter (tensorholo_training.qat: the exporter's grids and
roundings) against the f32 one, on crops it was not calibrated on (40 validation-split crops, 8 crops of each
real frame), through its frozen hologram CNN and the offset propagation.

    PYTHONPATH=training python training/experiments/int8_error.py runs/photo/pre6_photo30/best.pt \\
        [--retrained runs/photo/qat_pre6_photo30/best.pt] [--calib-method percentile]

prints, per set of crops: the f32 weights rounded as the exporter does, the same with bias correction
(qat.bias_correction), mixed precision (the shipped int8 pre-filters, export --float-convs first last: the first
and last convolutions float on the float input, the last hidden state on a MinMax grid of its own), and a
retrained checkpoint's pre-filter (quantisation-aware fine-tuning or distillation) rounded on its own grids.
With --ablation, which rounding costs most: each of the input, the hidden states, the concat and the weights
left float in turn.
"""
from __future__ import annotations

import argparse
import copy
import glob

import numpy as np
import torch

from tensorholo_training import qat
from tensorholo_training.export import (
    calibration_inputs, exporter_grids, frame_calibration_inputs, load_checkpoint, prefilter_calibration_inputs,
)
from tensorholo_training.optics import Display


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint", help="the pre-filter's run (its best.pt: f32 teacher and hologram CNN)")
    ap.add_argument("--retrained", help="a checkpoint whose pre-filter was retrained for int8")
    ap.add_argument("--dataset", default="data/photo256")
    ap.add_argument("--frames", default="runs/real_inputs/rgbd/*.npy")
    ap.add_argument("--calib-method", default="minmax", choices=["minmax", "percentile"])
    ap.add_argument("--ablation", action="store_true", help="also each rounding left out in turn")
    args = ap.parse_args()
    ck = load_checkpoint(args.checkpoint)
    cfg = ck["config"]
    display = Display(tuple(cfg["wavelengths_m"]), cfg["pixel_pitch_m"], cfg["volume_depth_m"])
    offset = cfg["offset_mm"] * 1e-3
    frames = sorted(glob.glob(args.frames))

    def pre_inputs(xs):
        return prefilter_calibration_inputs(ck["net"], xs, offset, display)

    # the exporter's calibration inputs (export: --calib-samples 32 --calib-size 128 --calib-crops 4)
    calib = pre_inputs(calibration_inputs(args.dataset, 1, 32, 128) + frame_calibration_inputs(frames, 1, 4, 128))
    teacher = ck["prefilter"]

    def rounded(net):
        q = copy.deepcopy(net)
        qat.fake_quantise(q, exporter_grids(net, "prefilter-cnn", calib, args.calib_method))
        return q

    grids = exporter_grids(teacher, "prefilter-cnn", calib, args.calib_method)
    n = len(grids)

    def variant(float_inputs=(), float_weights=(), hidden_grid=None):
        """The rounded pre-filter with the inputs of the convolutions ``float_inputs`` and the weights of
        ``float_weights`` left float; ``hidden_grid``: the last layer's concat reads its hidden part on that grid
        and its input part float (mixed precision)."""
        q = rounded(teacher)
        inner, c = q.net, q.net.channels
        base = inner.activation_quant

        def round_input(i, t):
            if i == n - 1 and hidden_grid is not None:
                h = torch.fake_quantize_per_tensor_affine(t[:, :c], hidden_grid.scale, hidden_grid.zero_point, 0, 255)
                return torch.cat([h, t[:, c:]], 1)
            return t if i in float_inputs else base(i, t)
        inner.activation_quant = round_input
        for i in float_weights:
            del qat.learned_convs(q)[i].__dict__["forward"]
        return q

    # the last hidden state's own MinMax grid (export._round_concat_hidden_input)
    top = 0.0
    with torch.no_grad():
        def keep(i, t):
            nonlocal top
            if i == n - 1:
                top = max(top, float(t[:, :teacher.net.channels].max()))
            return t
        teacher.net.activation_quant = keep
        for x in calib:
            teacher(torch.from_numpy(x))
        teacher.net.activation_quant = None
    candidates = {"rounded": rounded(teacher),
                  "bias-corrected": rounded(qat.bias_correction(teacher, grids, calib)),
                  "mixed precision": variant((0,), (0, n - 1), qat.Grid(top / 255, 0))}
    if args.ablation:
        candidates |= {"input float": variant((0,)), "hidden states float": variant(tuple(range(1, n - 1))),
                       "concat float": variant((n - 1,)), "all activations float": variant(tuple(range(n))),
                       "all weights float": variant((), tuple(range(n)))}
    if args.retrained:
        candidates["retrained"] = rounded(load_checkpoint(args.retrained)["prefilter"])
    held_out = {"validation crops": calibration_inputs(args.dataset, 1, 40, 128, split="val", seed=7),
                "real-frame crops": frame_calibration_inputs(frames, 1, 8, 128, seed=9)}
    for name, xs in held_out.items():
        inputs = [torch.from_numpy(x) for x in pre_inputs(xs)]
        with torch.no_grad():
            target = [torch.cat(teacher(x), 1) for x in inputs]
            errors = {k: float(np.mean([(torch.cat(q(x), 1) - t).pow(2).mean() for x, t in zip(inputs, target)]))
                      for k, q in candidates.items()}
        print(f"{name}: " + ", ".join(f"{k} {v:.3e}" for k, v in errors.items()))


if __name__ == "__main__":
    main()

"""The paper's Table 2 protocol on a dataset split, for trained checkpoints, exported ONNX files and baselines.

``python -m tensorholo_training.evaluate (--checkpoint RUN/final.pt | --onnx NAME.onnx [--prefilter-onnx P |
--aa-dpm]) --dataset DIR [--split test] [--phase-only] [--baseline NAME=FOLDER ...] [--out report.json]``

For every scene: PSNR and SSIM (data range 1, scikit-image definitions, :mod:`.metrics`) of

- the **amplitude** of the predicted midpoint hologram vs the ground-truth amplitude (Table 2, unbracketed);
- the **focal stack** ``|ASM(H, z(d))|`` at the 15 most frequent + 5 random depths of the scene's first-layer
  depth histogram (200 bins, fixed seed per scene) vs the same of the ground truth, averaged (bracketed).

With ``--phase-only`` the prediction is the post-encoding midpoint hologram (DDPM chain: offset, pre-filter,
double phase, Fourier filter, back-propagation), what the display shows; otherwise the complex CNN output.
Without a pre-filter the chain is plain double phase; ``--aa-dpm`` puts the non-learned AA-DPM blur (σ = 0.7 px,
5 taps, the SDK's default) in the pre-filter's place: the CNN's hologram as ``holo render`` shows it without
``--prefilter``.

Baselines (Maimone et al. / TensorHolo V1 / AA-DPM / BL-DPM for the model card) are computed by ``holo`` on the
same scenes; ``--baseline NAME=FOLDER`` reads ``FOLDER/<index:05d>.npy`` (complex64 ``[3, H, W]`` midpoint
holograms, the scene index of the split's order) and scores them with the same protocol. Any callable
``(index, item) -> complex64 [3, H, W]`` can be passed to :func:`evaluate` as a baseline too.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Callable

import numpy as np
import torch

from . import optics
from .data import LdiDataset, manifest_propagation, read_manifest
from .losses import ddpm_forward, select_focal_depths
from .metrics import psnr, ssim
from .optics import Display, PropagationOptions

Predictor = Callable[[int, dict], torch.Tensor]


def cnn_predictor(net, prefilter=None, offset_m: float = 0.0, display: Display = Display(),
                  phase_only: bool = False, options=PropagationOptions(), device="cpu") -> Predictor:
    """A predictor ``(index, item) -> complex64 [3, H, W]`` from a PyTorch hologram CNN (and pre-filter).

    Args:
        net: hologram CNN; prefilter: pre-filter CNN or None.
        offset_m: SLM offset (metres) of the phase-only chain.
        phase_only: return the post-encoding midpoint hologram instead of the CNN's complex output.
    """
    net = net.to(device).eval()
    if prefilter is not None:
        prefilter = prefilter.to(device).eval()

    @torch.no_grad()
    def predict(index: int, item: dict) -> torch.Tensor:
        amp, phs = net(item["rgbd"][None].to(device))
        if not phase_only:
            return optics.amp_phase_to_complex(amp, phs)[0]
        return ddpm_forward(amp, phs, prefilter, offset_m, display, options).post_midpoint[0]

    return predict


def onnx_predictor(path: str, prefilter_path: str | None = None, offset_m: float = 0.0,
                   display: Display = Display(), phase_only: bool = False,
                   options=PropagationOptions(), threads: int = 1, aa_dpm: bool = False, exact: bool = True) -> Predictor:
    """Like :func:`cnn_predictor` for exported ONNX files run by onnxruntime (f32 or int8). ``exact`` (the
    default) evaluates int8 arithmetic exactly whatever the CPU (see :func:`.export.run_onnx`). With ``aa_dpm``
    (and no ``prefilter_path``) the pre-filter is the non-learned AA-DPM blur: an untrained
    :class:`.model.PrefilterCNN` on the AA-DPM base, whose correction is zero."""
    from .export import onnx_session

    def session(p):
        return onnx_session(p, threads, exact)

    s_net = session(path)
    s_pre = session(prefilter_path) if prefilter_path else None

    class _Onnx(torch.nn.Module):
        def __init__(self, sess):
            super().__init__()
            self.sess = sess

        def forward(self, x):
            name = self.sess.get_inputs()[0].name
            # (amplitude, phase) of a hologram CNN, (real, imag) of a pre-filter: the graph's output order
            first, second = self.sess.run(None, {name: x.detach().cpu().numpy().astype(np.float32)})
            return torch.from_numpy(first), torch.from_numpy(second)

    if s_pre is not None:
        pre = _Onnx(s_pre)
    elif aa_dpm:
        from .model import prefilter_cnn

        pre = prefilter_cnn(base="aa-dpm")
    else:
        pre = None
    return cnn_predictor(_Onnx(s_net), pre, offset_m, display, phase_only, options)


def npy_baseline(folder: str) -> Predictor:
    """Baseline predictor reading ``folder/<index:05d>.npy`` (complex ``[3, H, W]``, written by ``holo``)."""

    def predict(index: int, item: dict) -> torch.Tensor:
        path = os.path.join(folder, f"{index:05d}.npy")
        if not os.path.exists(path):
            raise FileNotFoundError(f"baseline hologram {path} is missing")
        return torch.from_numpy(np.load(path).astype(np.complex64))

    return predict


def scene_metrics(pred: torch.Tensor, gt: torch.Tensor, depth: torch.Tensor, display: Display,
                  focal: torch.Tensor, options=PropagationOptions()) -> dict[str, float]:
    """Table 2 metrics of one scene.

    Args:
        pred, gt: complex64 ``[3, H, W]`` midpoint holograms; depth: ``[H, W]``; focal: ``[D]`` depths.
    Returns:
        ``{"psnr_amp", "ssim_amp", "psnr_fs", "ssim_fs"}``.
    """
    pa, ga = pred.abs()[None].float(), gt.abs()[None].float()
    out = {"psnr_amp": float(psnr(ga, pa)[0]), "ssim_amp": float(ssim(ga, pa)[0])}
    sp = optics.focal_stack(pred[None], focal[None], display, 0.0, options)[0]
    sg = optics.focal_stack(gt[None], focal[None], display, 0.0, options)[0]
    out["psnr_fs"] = float(psnr(sg, sp).mean())
    out["ssim_fs"] = float(ssim(sg, sp).mean())
    return out


def evaluate(dataset: LdiDataset, predictors: dict[str, Predictor], display: Display = Display(),
             options=PropagationOptions(), limit: int | None = None, seed: int = 0) -> dict:
    """Runs the Table 2 protocol for several predictors on the same scenes and focal depths.

    Args:
        dataset: split to evaluate (no augmentation).
        predictors: name → predictor (:func:`cnn_predictor`, :func:`onnx_predictor`, :func:`npy_baseline`).
        display, options: geometry and ASM options of the focal stacks.
        limit: evaluate only the first ``limit`` scenes.
        seed: seed of the 5 random focal depths (per scene: ``seed + index``).
    Returns:
        ``{name: {"mean": {metric: value}, "per_scene": [...]}, "scenes": n}``.
    """
    n = len(dataset) if limit is None else min(limit, len(dataset))
    results = {name: [] for name in predictors}
    for i in range(n):
        item = dataset[i]
        gt = item["midpoint"]
        depth = item["depth"]
        focal = select_focal_depths(depth[None], generator=torch.Generator().manual_seed(seed + i))[0]
        for name, predict in predictors.items():
            results[name].append(scene_metrics(predict(i, item), gt, depth, display, focal, options))
    report = {"scenes": n}
    for name, rows in results.items():
        mean = {k: float(np.mean([r[k] for r in rows])) for k in rows[0]} if rows else {}
        report[name] = {"mean": mean, "per_scene": rows}
    return report


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (see the module docstring)."""
    ap = argparse.ArgumentParser(prog="python -m tensorholo_training.evaluate",
                                 description=__doc__.split("\n\n")[0])
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--checkpoint")
    src.add_argument("--onnx")
    pre = ap.add_mutually_exclusive_group()
    pre.add_argument("--prefilter-onnx")
    pre.add_argument("--aa-dpm", action="store_true",
                     help="with --phase-only and --onnx: encode with AA-DPM instead of a pre-filter CNN")
    ap.add_argument("--dataset", required=True)
    ap.add_argument("--split", default="test")
    ap.add_argument("--phase-only", action="store_true")
    ap.add_argument("--offset-mm", type=float, help="offset for --onnx (default: its metadata)")
    ap.add_argument("--baseline", action="append", default=[], metavar="NAME=FOLDER")
    ap.add_argument("--limit", type=int)
    ap.add_argument("--out")
    args = ap.parse_args(argv)
    # Focal stacks with the ASM options the dataset's holograms were made with (docs/DATASET.md).
    options = manifest_propagation(read_manifest(args.dataset)) or PropagationOptions()
    if args.checkpoint:
        from .export import load_checkpoint

        ck = load_checkpoint(args.checkpoint)
        cfg = ck["config"]
        display = Display(tuple(cfg["wavelengths_m"]), cfg["pixel_pitch_m"], cfg["volume_depth_m"])
        layers = cfg["input_layers"]
        train_opts = PropagationOptions(bool(cfg.get("asm_pad")), bool(cfg.get("asm_band_limit")))
        model = cnn_predictor(ck["net"], ck["prefilter"], cfg["offset_mm"] * 1e-3, display, args.phase_only,
                              train_opts)
    else:
        from .export import read_metadata

        meta = read_metadata(args.onnx)
        display = Display(tuple(float(v) for v in meta["tensorholo.wavelengths_m"].split(",")),
                          float(meta["tensorholo.pixel_pitch_m"]), float(meta["tensorholo.volume_depth_m"]))
        layers = int(meta["tensorholo.input_layers"])
        offset = args.offset_mm * 1e-3 if args.offset_mm is not None else float(meta["tensorholo.offset_m"])
        model = onnx_predictor(args.onnx, args.prefilter_onnx, offset, display, args.phase_only, options,
                               aa_dpm=args.aa_dpm)
    ds = LdiDataset(args.dataset, args.split, layers)
    predictors = {"model": model}
    for b in args.baseline:
        name, _, folder = b.partition("=")
        predictors[name] = npy_baseline(folder)
    report = evaluate(ds, predictors, display, options, limit=args.limit)
    summary = {k: v["mean"] for k, v in report.items() if isinstance(v, dict)}
    print(json.dumps({"scenes": report["scenes"], "mean": summary}, indent=1))
    if args.out:
        with open(args.out, "w") as f:
            json.dump(report, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())

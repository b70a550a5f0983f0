"""The real RGB-D frames of ``../shared/data`` through ``holo render``: Table 2 scores per frame, and the CNN
inputs of those frames for int8 calibration.

The six frames with depth (Redwood, NYU, SUN, TUM, the iPhone portrait, odak's DragonBunny), each at the size
listed in :data:`FRAMES`. Every score is ``holo render --evaluate``: the paper's Table 2 protocol against the
SM-LBM ground truth of the frame (2048 planes), for the CNN midpoint hologram and for what the SLM displays.

    # scores of one configuration ("variant") of holo render on every frame -> OUT/NAME.json
    python training/real_frames.py evaluate --out models/eval/real --name holo30 -- --layers 30
    python training/real_frames.py evaluate --out models/eval/real --name mine -- --model my.onnx --no-prefilter
    # a per-frame Markdown table of several variants (CNN midpoint and displayed amplitude PSNR)
    python training/real_frames.py table --out models/eval/real holo30 mine
    # per frame, before -> after (delta) of the CNN midpoint (or --part displayed) for BEFORE:AFTER pairs
    python training/real_frames.py compare --out models/eval/real before_holo30:holo30
    # the hologram CNN input [4*L, H, W] of every frame -> DIR/FRAME.npy (int8 calibration, export --calib-npy)
    python training/real_frames.py inputs --dir runs/real_inputs -- --layers 8

Environment: ``HOLO`` (default ``target/release/holo``), ``SHARED_DATA`` (default ``../shared/data`` beside the
repository).
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

#: name -> (rgb, depth, holo render arguments): the Kinect frames at their own 480x640, the iPhone portrait at
#: its depth map's 768x576, odak's 900x1600 render halved (71 % of it is empty background).
FRAMES: dict[str, tuple[str, str, list[str]]] = {
    "redwood": ("redwood_livingroom_seq/color/00000.jpg", "redwood_livingroom_seq/depth/00000.png",
                ["--depth-encoding", "mm16"]),
    "nyu": ("nyu/NYU_color.ppm", "nyu/NYU_depth.pgm", ["--depth-encoding", "kinect-disparity"]),
    "sun": ("sun/SUN_color.jpg", "sun/SUN_depth.png", ["--depth-encoding", "sun"]),
    "tum": ("tum/TUM_color.png", "tum/TUM_depth.png", ["--depth-encoding", "tum"]),
    "iphone": ("iphone_portrait_vase/derived_rgb_576x768.png", "iphone_portrait_vase/disparity_aux_576x768.jpg",
               ["--depth-encoding", "iphone-disparity"]),
    "odak": ("odak_dragonbunny/DragonBunny_rgb.png", "odak_dragonbunny/DragonBunny_depthmap.png",
             ["--depth-encoding", "relative-near-bright", "--size", "450x800", "--max-invalid-depth", "0.8"]),
}


def shared_data() -> str:
    return os.environ.get("SHARED_DATA", os.path.join(os.path.dirname(ROOT), "shared", "data"))


def holo_binary() -> str:
    return os.environ.get("HOLO", os.path.join(ROOT, "target", "release", "holo"))


def render(frame: str, out: str, extra: list[str]) -> dict:
    """Runs ``holo render`` on one frame into ``out``; returns its report.json."""
    rgb, depth, args = FRAMES[frame]
    data = shared_data()
    cmd = [holo_binary(), "render", "--rgb", os.path.join(data, rgb), "--depth", os.path.join(data, depth),
           *args, "--repeat", "0", "--out", out, *extra]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{frame}: {' '.join(cmd)} failed:\n{done.stderr[-2000:]}")
    with open(os.path.join(out, "report.json")) as f:
        return json.load(f)


def evaluate(out_dir: str, name: str, extra: list[str], frames: list[str]) -> dict:
    """Table 2 scores of ``holo render EXTRA --evaluate`` on every frame -> ``out_dir/name.json``."""
    result = {"holo_args": extra, "frames": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for frame in frames:
            rep = render(frame, os.path.join(tmp, frame), [*extra, "--evaluate"])
            ev = rep["evaluation"]
            result["frames"][frame] = {
                "size": rep["size"], "models": rep["models"], "cnn_midpoint": ev["cnn_midpoint"],
                "displayed": ev["displayed"], "smlbm_encoded_displayed": ev["smlbm_encoded_displayed"],
                "levels": ev["ground_truth"]["levels"],
            }
            m, d = ev["cnn_midpoint"], ev["displayed"]
            print(f"{name} {frame}: CNN midpoint {m['psnr_amp']:.2f} dB (focal stack {m['psnr_fs']:.2f}), "
                  f"displayed {d['psnr_amp']:.2f} dB", file=sys.stderr)
    os.makedirs(out_dir, exist_ok=True)
    with open(os.path.join(out_dir, f"{name}.json"), "w") as f:
        json.dump(result, f, indent=1)
    return result


def inputs(out_dir: str, extra: list[str], frames: list[str]) -> None:
    """The hologram CNN input of every frame (``holo render --save-cnn-input``) -> ``out_dir/FRAME.npy``."""
    os.makedirs(out_dir, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        for frame in frames:
            out = os.path.join(tmp, frame)
            render(frame, out, [*extra, "--save-cnn-input", "--no-prefilter"])
            shutil.copy(os.path.join(out, "cnn_input.npy"), os.path.join(out_dir, f"{frame}.npy"))


def table(out_dir: str, names: list[str], key: str = "psnr_amp") -> str:
    """Markdown: one row per frame (and the mean), per variant its CNN midpoint and displayed ``key``."""
    runs = {n: json.load(open(os.path.join(out_dir, f"{n}.json"))) for n in names}
    frames = [f for f in FRAMES if all(f in r["frames"] for r in runs.values())]
    head = "| frame | " + " | ".join(f"{n}: midpoint / displayed" for n in names) + " |"
    lines = [head, "|---|" + "---:|" * len(names)]
    sums = {n: [0.0, 0.0] for n in names}
    for f in frames:
        cells = []
        for n in names:
            r = runs[n]["frames"][f]
            m, d = r["cnn_midpoint"][key], r["displayed"][key]
            sums[n][0] += m
            sums[n][1] += d
            cells.append(f"{m:.2f} / {d:.2f}")
        lines.append(f"| {f} | " + " | ".join(cells) + " |")
    k = max(len(frames), 1)
    lines.append("| **mean** | " + " | ".join(f"**{s[0] / k:.2f} / {s[1] / k:.2f}**" for s in sums.values()) + " |")
    return "\n".join(lines)


def compare(out_dir: str, pairs: list[str], part: str = "cnn_midpoint", key: str = "psnr_amp") -> str:
    """Markdown: per frame (and the mean), ``before → after (Δ)`` of ``part`` (``cnn_midpoint`` or
    ``displayed``) for each ``BEFORE:AFTER`` pair of evaluated variants."""
    pairs_ = [p.split(":", 1) for p in pairs]
    if any(len(p) != 2 for p in pairs_):
        raise SystemExit("compare takes BEFORE:AFTER pairs of variant names")
    runs = {n: json.load(open(os.path.join(out_dir, f"{n}.json"))) for p in pairs_ for n in p}
    frames = [f for f in FRAMES if all(f in r["frames"] for r in runs.values())]
    lines = ["| frame | " + " | ".join(f"{b} → {a}" for b, a in pairs_) + " |", "|---|" + "---:|" * len(pairs_)]
    sums = [[0.0, 0.0] for _ in pairs_]
    for f in frames:
        cells = []
        for k, (b, a) in enumerate(pairs_):
            vb, va = runs[b]["frames"][f][part][key], runs[a]["frames"][f][part][key]
            sums[k][0] += vb
            sums[k][1] += va
            cells.append(f"{vb:.2f} → {va:.2f} ({va - vb:+.2f})")
        lines.append(f"| {f} | " + " | ".join(cells) + " |")
    n = max(len(frames), 1)
    lines.append("| **mean** | " + " | ".join(f"**{b / n:.2f} → {a / n:.2f} ({(a - b) / n:+.2f})**"
                                             for b, a in sums) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    extra: list[str] = []
    if "--" in argv:
        i = argv.index("--")
        argv, extra = argv[:i], argv[i + 1:]
    ap = argparse.ArgumentParser(prog="training/real_frames.py", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    ev = sub.add_parser("evaluate", help="Table 2 scores of one holo render configuration on every frame")
    ev.add_argument("--out", required=True)
    ev.add_argument("--name", required=True)
    ev.add_argument("--frames", default=",".join(FRAMES))
    inp = sub.add_parser("inputs", help="the hologram CNN input of every frame as DIR/FRAME.npy")
    inp.add_argument("--dir", required=True)
    inp.add_argument("--frames", default=",".join(FRAMES))
    tab = sub.add_parser("table", help="per-frame Markdown table of evaluated variants")
    tab.add_argument("--out", required=True)
    tab.add_argument("--key", default="psnr_amp", choices=["psnr_amp", "ssim_amp", "psnr_fs", "ssim_fs"])
    tab.add_argument("names", nargs="+")
    cmp = sub.add_parser("compare", help="per-frame before → after table of BEFORE:AFTER variant pairs")
    cmp.add_argument("--out", required=True)
    cmp.add_argument("--part", default="cnn_midpoint", choices=["cnn_midpoint", "displayed"])
    cmp.add_argument("--key", default="psnr_amp", choices=["psnr_amp", "ssim_amp", "psnr_fs", "ssim_fs"])
    cmp.add_argument("pairs", nargs="+", metavar="BEFORE:AFTER")
    args = ap.parse_args(argv)
    if args.cmd == "compare":
        print(compare(args.out, args.pairs, args.part, args.key))
    elif args.cmd == "evaluate":
        evaluate(args.out, args.name, extra, args.frames.split(","))
    elif args.cmd == "inputs":
        inputs(args.dir, extra, args.frames.split(","))
    else:
        print(table(args.out, args.names, args.key))
    return 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""The picture of docs/FOVEATION.md: a full 3D frame against a foveated one, focused at the gaze's depth and
at another depth, the fovea and its blend band drawn.

    python benchmarks/foveation_figure.py --holo target/release/holo --out docs/images

Runs `holo render` twice on ../shared/data/iphone_portrait_vase (the 576 × 768 colour and its disparity map;
shipped 8-layer CNN, 6 mm, DDPM pre-filter): once in full, once with `--gaze 280,380 --fovea-px 110` (the
vase). Writes foveation.jpg: columns focused near (the vase, the gaze's depth) and far (the wall), rows the
full frame and the foveated one, whose fovea (solid) and band's outer edge (dashed) are drawn. The
numbers each run prints (report.json's `fovea` and `timings_s`) are printed too. Needs Pillow
(`pip install Pillow`).
"""

import argparse
import json
import math
import subprocess
import tempfile
from pathlib import Path

from PIL import Image, ImageDraw

GAZE = (280.0, 380.0)
RADIUS = 110.0


def circle(draw, centre, radius, dashed, colour):
    """A circle of `radius` around `centre`, solid or dashed."""
    steps = 180
    for i in range(steps):
        if dashed and i % 2:
            continue
        a0, a1 = 2 * math.pi * i / steps, 2 * math.pi * (i + 1) / steps
        draw.line(
            [(centre[0] + radius * math.cos(a0), centre[1] + radius * math.sin(a0)),
             (centre[0] + radius * math.cos(a1), centre[1] + radius * math.sin(a1))],
            fill=colour, width=2)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--holo", default="target/release/holo")
    p.add_argument("--data", default="../shared/data")
    p.add_argument("--out", default="docs/images")
    args = p.parse_args()
    frame = Path(args.data) / "iphone_portrait_vase"
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    common = [args.holo, "render", "--rgb", str(frame / "derived_rgb_576x768.png"),
              "--depth", str(frame / "disparity_aux_576x768.jpg"), "--depth-encoding", "iphone-disparity"]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, extra in [("full", []),
                            ("fovea", ["--gaze", f"{GAZE[0]},{GAZE[1]}", "--fovea-px", str(RADIUS)])]:
            folder = Path(tmp) / name
            subprocess.run(common + extra + ["--out", str(folder)], check=True)
            report = json.loads((folder / "report.json").read_text())
            print(name, json.dumps({"fovea": report.get("fovea"),
                                    "median_s": report["timings_s"]["median"]}, indent=1))
            panels = [Image.open(folder / f"{plane}.png").convert("RGB") for plane in ("focus_near", "focus_far")]
            if name == "fovea":
                band = report["fovea"]["band_px"]
                for panel in panels:
                    draw = ImageDraw.Draw(panel)
                    circle(draw, GAZE, RADIUS, False, (255, 64, 64))
                    circle(draw, GAZE, RADIUS + band, True, (255, 64, 64))
            rows.append(panels)
    w, h = rows[0][0].size
    gap = 8
    sheet = Image.new("RGB", (2 * w + gap, 2 * h + gap), "white")
    for r, panels in enumerate(rows):
        for c, panel in enumerate(panels):
            sheet.paste(panel, (c * (w + gap), r * (h + gap)))
    sheet = sheet.resize((sheet.width * 3 // 4, sheet.height * 3 // 4), Image.LANCZOS)
    sheet.save(out / "foveation.jpg", quality=88)
    print(f"wrote {out / 'foveation.jpg'}")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""The picture of docs/VIDEO.md: a phone's RGB-D frame (depth at its own, lower resolution) and its hologram's
reconstruction at two focus distances.

    python benchmarks/phone_frame_figure.py --holo target/release/holo --out docs/images

Runs `holo render` on ../shared/data/iphone_portrait_vase (an iPhone X dual-camera portrait: 3024 × 4032 colour,
576 × 768 disparity; depth brought to the colour by the joint bilateral upsampling, the files' default) at
1024 × 768, and writes video_phone_frame.jpg: above, the normalised depth holo used and the simulated
reconstruction focused near and far (holo's own depth.png, focus_near.png and focus_far.png) at half size; below,
the table's front edge at full size, focused near (sharp) and far (blurred).
Needs Pillow (`pip install Pillow`).
"""

import argparse
import subprocess
import tempfile
from pathlib import Path

from PIL import Image


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--holo", default="target/release/holo")
    p.add_argument("--data", default="../shared/data")
    p.add_argument("--out", default="docs/images")
    args = p.parse_args()
    frame = Path(args.data) / "iphone_portrait_vase"
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run(
            [args.holo, "render", "--rgb", str(frame / "image-with-depth.jpg"),
             "--depth", str(frame / "disparity_aux_576x768.jpg"), "--depth-encoding", "iphone-disparity",
             "--size", "1024x768", "--out", tmp],
            check=True)
        panels = [Image.open(Path(tmp) / f"{name}.png").convert("RGB")
                  for name in ("depth", "focus_near", "focus_far")]
        gap = 8
        w, h = panels[0].width // 2, panels[0].height // 2
        crop = (40, 640, 40 + (3 * w + gap) // 2, 940)  # the table's front edge, full size
        cw, ch = crop[2] - crop[0], crop[3] - crop[1]
        sheet = Image.new("RGB", (3 * w + 2 * gap, h + gap + ch), "white")
        for i, panel in enumerate(panels):
            sheet.paste(panel.resize((w, h), Image.LANCZOS), (i * (w + gap), 0))
        for i, panel in enumerate(panels[1:]):
            sheet.paste(panel.crop(crop), (i * (cw + gap), h + gap))
        path = out / "video_phone_frame.jpg"
        sheet.save(path, quality=88, optimize=True)
        print(f"wrote {path}")


if __name__ == "__main__":
    main()

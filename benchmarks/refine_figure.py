#!/usr/bin/env python3
"""The figure of docs/REFINE.md: PSNR against iterations of `holo render --refine` for each start, on one
real frame, and the before/after focal pictures.

    python benchmarks/refine_figure.py --holo target/release/holo --out docs/images

Runs `holo render --refine N --refine-init S` for S in cnn, smlbm-dpm, zero, random (and once without
--refine), reads each report.json's `refine.history` (PSNR at the loss planes per iteration) and
`refine.held_out` (PSNR at the planes between them, which the loss never saw), and writes
refine_psnr.png (needs matplotlib) and the near/far focus previews of the plain and the refined hologram
(refine_{cnn,refined}_focus_{near,far}.png, copied from holo's own previews).
"""

import argparse
import json
import shutil
import subprocess
import tempfile
from pathlib import Path

STARTS = {"cnn": "the CNN's codes (default)", "smlbm-dpm": "SM-LBM + AA-DPM", "zero": "zero phase",
          "random": "random phase"}


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--holo", default="target/release/holo")
    p.add_argument("--data", default="../shared/data")
    p.add_argument("--iterations", type=int, default=50)
    p.add_argument("--out", default="docs/images")
    a = p.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = Path(a.data)
    scene = ["--rgb", str(data / "redwood_livingroom_seq/color/00000.jpg"), "--depth",
             str(data / "redwood_livingroom_seq/depth/00000.png"), "--depth-encoding", "mm16",
             "--size", "384x384", "--repeat", "0"]
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=120)
    with tempfile.TemporaryDirectory() as tmp:
        for start, label in STARTS.items():
            d = Path(tmp) / start
            subprocess.run([a.holo, "render", *scene, "--refine", str(a.iterations), "--refine-init", start,
                            "--out", str(d)], check=True, capture_output=True)
            r = json.loads((d / "report.json").read_text())["refine"]
            its = [h["iteration"] for h in r["history"]]
            ax.plot(its, [h["psnr_db"] for h in r["history"]], label=f"{label}: {r['held_out']['refined_codes_psnr_db']:.1f} dB held out")
            print(start, [round(h["psnr_db"], 2) for h in r["history"]][::5], r["held_out"])
            if start == "cnn":
                for which in ("near", "far"):
                    shutil.copy(d / f"focus_{which}.png", out / f"refine_refined_focus_{which}.png")
        plain = Path(tmp) / "plain"
        subprocess.run([a.holo, "render", *scene, "--out", str(plain)], check=True, capture_output=True)
        for which in ("near", "far"):
            shutil.copy(plain / f"focus_{which}.png", out / f"refine_cnn_focus_{which}.png")
    ax.set_xlabel("iterations")
    ax.set_ylabel("PSNR at the 7 loss planes (dB)")
    ax.set_title("Refinement of a real frame (Redwood 00000, 384², 8-layer CNN, SM-LBM target)", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, title="start: PSNR after the last iteration at 6 unseen planes", title_fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "refine_psnr.png")
    print(f"wrote {out / 'refine_psnr.png'}")


if __name__ == "__main__":
    main()

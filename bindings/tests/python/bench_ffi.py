"""What crossing the FFI costs at 1080p, next to the CNN (docs/BENCHMARKS.md, "The bindings' own cost").

    PYTHONPATH=OUT_DIR/python bindings/tests/python/.venv/bin/python bindings/tests/python/bench_ffi.py [--frames 3]

A 1920×1080 hologram from a 1920×1080 BGRA camera frame (../shared/data/bbb_frame, padded rows) and a 640×360
f16 depth map (a smooth synthetic ramp: the frame has no depth). For each call of `HologramGenerator.render`:
the wall time seen by Python, the core's own stage timings (camera conversion, CNN, offset, pre-filter,
encoding), and their difference: what the bindings add (bytes in: colour and depth copied into Rust;
bytes out: three 2 MB planes to Python `bytes`; uniffi's lifting and lowering). Also `pack_rgba`'s time.
Median of --frames calls after one warm-up call. Not a test: run by hand (a release build of the bindings).
"""

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from PIL import Image

import tensorholo as th

SHARED = Path(os.environ.get("TENSORHOLO_SHARED_DATA", Path(__file__).resolve().parents[3].parent / "shared" / "data"))


def cpu_name() -> str:
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=3)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--backend", choices=["auto", "cpu", "gpu"], default="auto",
                    help="GeneratorConfig.backend (auto, the default, probes the GPU)")
    args = ap.parse_args()
    rgb = np.asarray(Image.open(SHARED / "bbb_frame" / "bbb_frame_1920x1080.png").convert("RGB"))
    h, w = rgb.shape[:2]
    stride = w * 4 + 64
    bgra = np.zeros((h, stride), np.uint8)
    bgra[:, : w * 4] = np.concatenate([rgb[..., ::-1], np.full((h, w, 1), 255, np.uint8)], 2).reshape(h, -1)
    color = bgra.tobytes()
    dh, dw = 360, 640
    yy, xx = np.mgrid[0:dh, 0:dw]
    depth = (0.6 + 1.4 * (xx / dw) * (0.5 + 0.5 * yy / dh)).astype("<f2").tobytes()
    frame = th.RgbdFrame(color=color, color_format=th.ColorFormat.BGRA8, color_width=w, color_height=h,
                         color_row_stride=stride, depth=depth, depth_format=th.DepthFormat.METRES_F16,
                         depth_width=dw, depth_height=dh)
    t = time.perf_counter()
    backend = getattr(th.Backend, args.backend.upper())
    gen = th.HologramGenerator(th.GeneratorConfig(width=1920, height=1080, threads=args.threads, backend=backend))
    created = time.perf_counter() - t
    info = gen.info()
    print(f"{cpu_name()}, {os.cpu_count()} logical cores; generator created in {created:.1f} s "
          f"(plan {info.cnn_layout}, {info.cnn_threads} thread(s), autotuned {info.autotuned}; "
          f"pre-filter: {info.prefilter_model})", file=sys.stderr)
    rows = []
    for i in range(args.frames + 1):
        t = time.perf_counter()
        p = gen.render(frame)
        wall = (time.perf_counter() - t) * 1e3
        t = time.perf_counter()
        rgba = th.pack_rgba(p)
        pack = (time.perf_counter() - t) * 1e3
        assert len(rgba) == 1920 * 1080 * 4
        core = p.timings.convert_ms + p.timings.total_ms
        if i > 0:
            rows.append((wall, p.timings.convert_ms, p.timings.cnn_ms, p.timings.total_ms, wall - core, pack))
        print(f"frame {i}: wall {wall:.1f} ms, core {core:.1f} ms, pack_rgba {pack:.1f} ms", file=sys.stderr)
    med = [statistics.median(c) for c in zip(*rows)]
    print("| 1080p, median of %d | ms |" % len(rows))
    print("|---|---:|")
    for name, v in zip(["`render` as Python sees it", "camera conversion (core)", "hologram CNN (core)",
                        "CNN → codes, all stages (core)", "bindings' own cost (bytes in/out, uniffi)",
                        "`pack_rgba` (8.3 MB out)"], med):
        print(f"| {name} | {v:.1f} |")


if __name__ == "__main__":
    main()

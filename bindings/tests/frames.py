"""Real RGB-D frames as a phone delivers them, and what `holo render` makes of the same input.

Used by the Python tests (imported) and, through `python3 frames.py OUT_DIR`, by the Kotlin test, which reads
the raw buffers and holo's SLM patterns from OUT_DIR/<case>/.

Each case turns a real frame of ../shared/data into phone buffers (colour bytes with a row stride, depth in a
sensor format at HALF the colour resolution, optionally rotated as a landscape sensor delivers it) and writes
the very same scene for `holo render`: the colour as a PNG (so both sides decode identical pixels) and the depth
nearest-upsampled back to the colour grid, in the file encoding holo reads. Both paths then see the same field:
the SDK upsamples the half-resolution depth by nearest neighbour too. What may differ is float rounding (f16
disparity, the CNN plan chosen on each side), hence the tolerance in `compare_codes`.

Environment: HOLO (the holo binary; default target/release/holo, else target/debug/holo),
TENSORHOLO_SHARED_DATA (default ../shared/data beside the repository).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings
from dataclasses import dataclass, asdict
from pathlib import Path

import numpy as np
from PIL import Image

REPO = Path(__file__).resolve().parents[2]
# The iPhone photo carries a multi-picture (MPO) header Pillow does not need; it reads the base JPEG.
warnings.filterwarnings("ignore", message="Image appears to be a malformed MPO file")

SHARED = Path(os.environ.get("TENSORHOLO_SHARED_DATA", REPO.parent / "shared" / "data"))

# iPhone normalised disparity (8-bit v) in 1/m, as the depth decoders define it (docs/CONVENTIONS.md §6).
IPHONE_DISPARITY = (0.650879, 1.858887)


def holo_binary() -> Path:
    if os.environ.get("HOLO"):
        return Path(os.environ["HOLO"])
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    if not target.is_absolute():
        target = REPO / target
    for profile in ("release", "debug"):
        if (target / profile / "holo").exists():
            return target / profile / "holo"
    raise FileNotFoundError("no holo binary: build it (cargo build -p holo) or set HOLO")


@dataclass
class Case:
    """One phone frame: raw buffers + their layout, the hologram size, and holo's input files."""

    name: str
    color_format: str  # RGBA8 | BGRA8 | RGB8 (the bindings' enum names)
    color_width: int
    color_height: int
    color_row_stride: int
    depth_format: str  # METRES_F16 | MILLIMETRES_U16 | ...
    depth_width: int
    depth_height: int
    depth_row_stride: int
    rotation: str  # DEG0 | DEG90 | ...
    out_width: int
    out_height: int
    holo_rgb: str
    holo_depth: str
    holo_encoding: str


def _padded(rows: np.ndarray, stride: int) -> bytes:
    """Rows of bytes `[H, row_bytes]` laid out `stride` bytes apart (the last row unpadded)."""
    h, row = rows.shape
    buf = np.zeros((h, stride), np.uint8)
    buf[:, :row] = rows
    return buf.tobytes()[: stride * (h - 1) + row]


# Beside each case's `holo_depth` (the camera's depth brought to the colour's resolution by nearest neighbour, as
# a generator does by default): the same depth at the camera's own, half resolution, for `holo render` to bring
# to the colour's itself (`--depth-upsampling`).
LOW_DEPTH = "depth_half.png"


def iphone(tmp: Path) -> tuple[Case, bytes, bytes]:
    """The iPhone portrait as iOS delivers it: BGRA with padded rows, f16 disparity (1/m) at half resolution."""
    src = SHARED / "iphone_portrait_vase"
    rgb = np.asarray(Image.open(src / "derived_rgb_576x768.png").convert("RGB"))
    v = np.asarray(Image.open(src / "disparity_aux_576x768.jpg").convert("L"))
    h, w = v.shape
    v_half = v[::2, ::2]
    disparity = (IPHONE_DISPARITY[0] + v_half.astype(np.float64) / 255 * IPHONE_DISPARITY[1]).astype("<f2")
    bgra = np.concatenate([rgb[..., ::-1], np.full((h, w, 1), 255, np.uint8)], axis=2)
    stride = w * 4 + 64
    color = _padded(bgra.reshape(h, w * 4), stride)
    depth = disparity.tobytes()
    tmp.mkdir(parents=True, exist_ok=True)
    Image.fromarray(rgb).save(tmp / "rgb.png")
    Image.fromarray(np.repeat(np.repeat(v_half, 2, 0), 2, 1)).save(tmp / "depth.png")
    Image.fromarray(v_half).save(tmp / LOW_DEPTH)
    case = Case("iphone", "BGRA8", w, h, stride, "DISPARITY_F16", w // 2, h // 2, 0, "DEG0",
                w // 2, h // 2, str(tmp / "rgb.png"), str(tmp / "depth.png"), "iphone-disparity")
    return case, color, depth


def redwood(tmp: Path) -> tuple[Case, bytes, bytes]:
    """A Redwood frame as an Android landscape sensor delivers it: RGBA and ARCore u16 millimetres at half
    resolution, both turned 90° counter-clockwise, so the SDK must rotate them 90° clockwise."""
    src = SHARED / "redwood_livingroom_seq"
    rgb = np.asarray(Image.open(src / "color" / "00000.jpg").convert("RGB"))
    mm = np.asarray(Image.open(src / "depth" / "00000.png")).astype(np.uint16)
    h, w = mm.shape
    mm_half = mm[::2, ::2]
    rgba = np.concatenate([rgb, np.full((h, w, 1), 255, np.uint8)], axis=2)
    sensor_rgba = np.ascontiguousarray(np.rot90(rgba, k=1))
    sensor_mm = np.ascontiguousarray(np.rot90(mm_half, k=1)).astype("<u2")
    tmp.mkdir(parents=True, exist_ok=True)
    Image.fromarray(rgb).save(tmp / "rgb.png")
    Image.fromarray(np.repeat(np.repeat(mm_half, 2, 0), 2, 1).astype(np.uint16)).save(tmp / "depth.png")
    Image.fromarray(mm_half.astype(np.uint16)).save(tmp / LOW_DEPTH)
    sh, sw = sensor_mm.shape
    case = Case("redwood", "RGBA8", sensor_rgba.shape[1], sensor_rgba.shape[0], 0, "MILLIMETRES_U16", sw, sh, 0,
                "DEG90", w // 2, h // 2, str(tmp / "rgb.png"), str(tmp / "depth.png"), "mm16")
    return case, sensor_rgba.tobytes(), sensor_mm.tobytes()


CASES = {"iphone": iphone, "redwood": redwood}


def holo_codes(case: Case, out: Path, calibration: Path | None = None, depth: str | None = None,
               extra: list[str] | None = None) -> np.ndarray:
    """`holo render` of the case's files at its hologram size (defaults otherwise, through `calibration` if
    given; `depth` instead of the case's depth file; `extra` arguments appended): codes `[3, H, W]`."""
    cmd = [str(holo_binary()), "render", "--rgb", case.holo_rgb, "--depth", depth or case.holo_depth,
           "--depth-encoding", case.holo_encoding, "--size", f"{case.out_height}x{case.out_width}",
           "--repeat", "0", "--out", str(out)]
    if calibration is not None:
        cmd += ["--calibration", str(calibration)]
    cmd += extra or []
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    return read_codes(out)


# The panel of the calibration tests: one gamma curve over 2.4π for every laser.
PANEL_RANGE_RAD = 7.5398
PANEL_GAMMA = 1.3


def panel_calibration(case: Case, out: Path) -> Path:
    """`holo calibrate global` of a non-linear panel at the case's hologram size: the .holocal's path."""
    out.parent.mkdir(parents=True, exist_ok=True)
    cmd = [str(holo_binary()), "calibrate", "global", "--size", f"{case.out_height}x{case.out_width}",
           "--range-rad", str(PANEL_RANGE_RAD), "--gamma", str(PANEL_GAMMA), "--out", str(out)]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    return out


def read_codes(folder: Path) -> np.ndarray:
    return np.stack([np.asarray(Image.open(folder / f"phase_{c}.png")) for c in "rgb"])


def circular_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Code distance on the phase circle (255 and 0 are one code apart)."""
    d = np.abs(a.astype(np.int16) - b.astype(np.int16))
    return np.minimum(d, 256 - d)


# Agreement the bindings must reach with holo on the same scene (measured: see bindings/README.md).
MAX_MEAN_DIFF = 0.02  # mean circular code difference (measured here: 0.0022 iPhone f16, 0 Redwood)
MIN_WITHIN_ONE = 0.999  # fraction of codes within ±1 (measured here: 1.0)


def compare_codes(got: np.ndarray, want: np.ndarray) -> dict:
    assert got.shape == want.shape, (got.shape, want.shape)
    d = circular_diff(got, want)
    stats = {"mean": float(d.mean()), "within_one": float((d <= 1).mean()), "max": int(d.max())}
    assert stats["mean"] <= MAX_MEAN_DIFF and stats["within_one"] >= MIN_WITHIN_ONE, stats
    return stats


def write_case(out: Path, make) -> Case:
    """Writes a case for the Kotlin test: color.raw, depth.raw, case.json, holo/phase_{r,g,b}.png, and
    panel.holocal with holo's patterns through it in holo_calibrated/."""
    case, color, depth = make(out / "inputs")
    (out / "color.raw").write_bytes(color)
    (out / "depth.raw").write_bytes(depth)
    holo_codes(case, out / "holo")
    holo_codes(case, out / "holo_calibrated", panel_calibration(case, out / "panel.holocal"))
    (out / "case.json").write_text(json.dumps(asdict(case), indent=1))
    return case


if __name__ == "__main__":
    root = Path(sys.argv[1])
    for name, make in CASES.items():
        c = write_case(root / name, make)
        print(f"{name}: {c.color_width}x{c.color_height} colour, {c.depth_width}x{c.depth_height} depth "
              f"-> {c.out_width}x{c.out_height}")

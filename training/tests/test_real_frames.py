"""training/real_frames.py: the per-frame tables, on reports written here (running holo is the CLI's own test)."""
import json
import os
import sys

import pytest

sys.path.insert(0, os.path.abspath(os.path.join(os.path.dirname(__file__), "..")))
import real_frames  # noqa: E402


def report(tmp_path, name, midpoints, displayed):
    frames = {f: {"cnn_midpoint": {"psnr_amp": m, "psnr_fs": m - 0.5}, "displayed": {"psnr_amp": d, "psnr_fs": d}}
              for f, m, d in zip(real_frames.FRAMES, midpoints, displayed)}
    (tmp_path / f"{name}.json").write_text(json.dumps({"holo_args": [], "frames": frames}))


def test_compare_gives_each_frame_before_after_and_the_mean_change(tmp_path):
    report(tmp_path, "old", [24.0, 28.0], [23.0, 27.0])
    report(tmp_path, "new", [25.5, 27.5], [23.5, 28.0])
    lines = real_frames.compare(str(tmp_path), ["old:new"]).splitlines()
    names = list(real_frames.FRAMES)
    assert lines[2] == f"| {names[0]} | 24.00 → 25.50 (+1.50) |"
    assert lines[3] == f"| {names[1]} | 28.00 → 27.50 (-0.50) |"
    assert lines[-1] == "| **mean** | **26.00 → 26.50 (+0.50)** |"  # only the frames both reports hold
    shown = real_frames.compare(str(tmp_path), ["old:new"], part="displayed").splitlines()
    assert shown[-1] == "| **mean** | **25.00 → 25.75 (+0.75)** |"
    with pytest.raises(SystemExit, match="BEFORE:AFTER"):
        real_frames.compare(str(tmp_path), ["old"])


def test_table_lists_midpoint_and_displayed_per_variant(tmp_path):
    report(tmp_path, "a", [24.0, 28.0], [23.0, 27.0])
    lines = real_frames.table(str(tmp_path), ["a"], key="psnr_fs").splitlines()
    assert lines[2].endswith("| 23.50 / 23.00 |") and lines[-1] == "| **mean** | **25.50 / 25.00** |"

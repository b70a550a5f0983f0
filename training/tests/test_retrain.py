"""``training/retrain.sh`` (tensorholo_training.retrain): the receptive-field warning's optics, the profile's
errors, the plan of commands, and the refusal of an output folder made for another display. The end-to-end
smoke retraining runs in CI's "training: smoke retraining" step (.ci/run)."""
import json
import math
import os

import pytest

from tensorholo_training import retrain
from tensorholo_training.optics import Display

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
PAPER = Display()


def profile_file(tmp_path, **over):
    raw = {"pixel_pitch_m": 4e-6, "resolution": [1080, 1920], "wavelengths_m": [638e-9, 520e-9, 450e-9],
           "volume_depth_m": 1.5e-3, "offsets_m": [1.5e-3, 3e-3]}
    raw.update(over)
    raw = {k: v for k, v in raw.items() if v is not None}
    path = tmp_path / "display.json"
    path.write_text(json.dumps(raw))
    return str(path)


def test_edge_spread_is_the_diffraction_cone_over_half_the_volume():
    # Paper display, red: sin θ = 638 nm / 16 µm; 3 mm · tan θ / 8 µm.
    s = math.sin(math.asin(638e-9 / 16e-6))
    want = 3e-3 * s / math.sqrt(1 - s * s) / 8e-6
    assert retrain.edge_spread_px(PAPER, 638e-9) == pytest.approx(want, rel=1e-12)
    assert 14.9 < want < 15.0
    # Proportional to the volume depth, and Fresnel-invariant (D ∝ p²) up to the non-paraxial term:
    # tan(asin x) = x (1 + x²/2 + …) with x = λ/2p.
    half = Display(PAPER.wavelengths_m, 8e-6, 3e-3)
    assert retrain.edge_spread_px(half, 638e-9) == pytest.approx(want / 2, rel=1e-12)
    fine = Display(PAPER.wavelengths_m, 4e-6, 1.5e-3)
    x8, x4 = 638e-9 / 16e-6, 638e-9 / 8e-6
    ratio = retrain.edge_spread_px(fine, 638e-9) / want
    assert ratio == pytest.approx((1 + x4 ** 2 / 2) / (1 + x8 ** 2 / 2), rel=1e-4)
    assert ratio != pytest.approx(1, abs=1e-3)


def test_receptive_field_warning_names_the_colour_and_what_to_change():
    w = retrain.receptive_field_warning(PAPER, 8)
    assert w is not None
    assert "15.0 px" in w and "R, 638 nm" in w and "radius of 8 px" in w
    # 15 layers cover the paper's 14.97 px; a volume of 6 mm · 8 / 14.97 = 3.21 mm fits 8 layers.
    assert "--layers 15" in w and "3.21 mm" in w
    assert retrain.receptive_field_warning(PAPER, 15) is None
    assert retrain.receptive_field_warning(PAPER, 30) is None
    # A deep volume that no CNN depth covers: only the volume is suggested.
    deep = Display(PAPER.wavelengths_m, 8e-6, 20e-3)
    w = retrain.receptive_field_warning(deep, 30)
    assert w is not None and "--layers" not in w and f"{20 * 30 / retrain.edge_spread_px(deep, 638e-9):.3g} mm" in w


@pytest.mark.parametrize("over, key", [
    ({"pixel_pitch_m": None}, "pixel_pitch_m"),
    ({"pixel_pitch_m": -4e-6}, "pixel_pitch_m"),
    ({"wavelengths_m": [638e-9, 520e-9]}, "wavelengths_m"),
    ({"volume_depth_m": "1.5mm"}, "volume_depth_m"),
    ({"offsets_m": []}, "offsets_m"),
    ({"offsets_m": [-1e-3]}, "offsets_m"),
])
def test_a_bad_profile_is_refused_naming_the_key(tmp_path, over, key):
    with pytest.raises(retrain.RetrainError, match=f"`{key}`"):
        retrain.read_profile(profile_file(tmp_path, **over))


def test_a_missing_or_broken_profile_is_refused_naming_the_file(tmp_path):
    with pytest.raises(retrain.RetrainError, match="nowhere.json"):
        retrain.read_profile(str(tmp_path / "nowhere.json"))
    bad = tmp_path / "bad.json"
    bad.write_text("{ not json")
    with pytest.raises(retrain.RetrainError, match="bad.json.*not JSON"):
        retrain.read_profile(str(bad))


def plan_for(tmp_path, *extra):
    args = retrain.parse_args(["--display", profile_file(tmp_path), "--out", str(tmp_path / "out"),
                               "--holo", "holo", "--root", ROOT, *extra])
    return retrain.build_plan(args, retrain.read_profile(args.display))


def test_the_plan_shards_the_dataset_and_trains_every_offset_of_the_profile(tmp_path):
    plan = plan_for(tmp_path, "--scale", "smoke", "--shards", "3", "--layers", "15")
    titles = [t for t, _ in plan.steps]
    assert titles[:4] == ["dataset part 0/3", "dataset part 1/3", "dataset part 2/3", "dataset merge"]
    parts = [argv[argv.index("--shard") + 1] for _, argv in plan.steps[:3]]
    assert parts == ["0/3", "1/3", "2/3"]
    assert all("--display" in argv for _, argv in plan.steps[:3])
    # Stage 1 once; stage 2, export and evaluation for 1.5 and 3 mm (the profile's offsets, in mm).
    assert titles.count("stage 1") == 1
    assert [t for t in titles if t.startswith("stage 2")] == ["stage 2, offset 1.5 mm", "stage 2, offset 3 mm"]
    assert plan.names() == ["holo15_rgbd_1.5mm", "holo15_rgbd_3mm"]
    stage2 = dict(plan.steps)["stage 2, offset 3 mm"]
    assert "offset_mm=3.0" in stage2 and "num_layers=15" in stage2
    assert any(a.startswith("init_from=") and a.endswith('stage1.pt"') for a in stage2)
    line = retrain.render_line(plan)
    assert "--model" in line and "holo15_rgbd_1.5mm.prefilter.onnx" in line and "--offset-mm" not in line


def test_offsets_flag_and_nproc_change_the_plan(tmp_path):
    plan = plan_for(tmp_path, "--offsets-mm", "0 2", "--nproc", "2")
    assert plan.names() == ["holo8_rgbd_0mm", "holo8_rgbd_2mm"]
    train = dict(plan.steps)["stage 1"]
    assert train[1:7] == ["-m", "torch.distributed.run", "--standalone", "--nproc-per-node", "2", "--max-restarts"]
    # The paper scale: its dataset and the GPU configurations.
    ds = dict(plan.steps)["dataset"]
    assert ds[ds.index("--levels") + 1] == "10000" and ds[ds.index("--size") + 1] == "384"
    assert any(a.endswith("gpu_stage1.json") for a in train)
    # A 0 mm first offset has no pre-filter; an offset other than the profile's is passed to holo render.
    line = retrain.render_line(plan)
    assert "--prefilter-model" not in line and "--offset-mm 0" in line


def test_an_output_folder_of_another_display_or_scale_is_refused(tmp_path):
    plan = plan_for(tmp_path, "--scale", "smoke")
    retrain.check_record(plan)
    retrain.check_record(plan)  # the same command again: resumes
    other = plan_for(tmp_path, "--scale", "paper")
    with pytest.raises(retrain.RetrainError, match="another scale.*smoke.*paper"):
        retrain.check_record(other)
    retrain.check_record(plan_for(tmp_path, "--scale", "smoke", "--input", "ldi", "--layers", "15"))
    moved = retrain.build_plan(plan.args, retrain.read_profile(profile_file(tmp_path, volume_depth_m=2e-3)))
    with pytest.raises(retrain.RetrainError, match="another display"):
        retrain.check_record(moved)


def test_a_dataset_of_another_display_is_refused(tmp_path):
    plan = plan_for(tmp_path, "--scale", "smoke")
    os.makedirs(plan.data)
    with open(os.path.join(plan.data, "manifest.json"), "w") as f:
        json.dump({"optics": PAPER.to_dict()}, f)
    with pytest.raises(retrain.RetrainError, match="another display"):
        retrain.check_manifest(plan.data, plan.profile)
    with open(os.path.join(plan.data, "manifest.json"), "w") as f:
        json.dump({"optics": plan.profile.display.to_dict()}, f)
    retrain.check_manifest(plan.data, plan.profile)


def test_the_render_line_keeps_the_profile_offset_and_passes_another_exactly(tmp_path):
    # 3.74 µm: offsets 1.3113375 and 2.622675 mm; six significant digits would miss holo's 1e-6 match.
    path = os.path.join(ROOT, "displays", "lcos-3.74um-4k.json")
    args = retrain.parse_args(["--display", path, "--out", str(tmp_path), "--holo", "holo", "--root", ROOT])
    plan = retrain.build_plan(args, retrain.read_profile(path))
    assert "--offset-mm" not in retrain.render_line(plan)
    args = retrain.parse_args(["--display", path, "--out", str(tmp_path), "--holo", "holo", "--root", ROOT,
                               "--offsets-mm", "2.622675"])
    line = retrain.render_line(retrain.build_plan(args, retrain.read_profile(path)))
    assert "--offset-mm 2.622675 " in line and "holo8_rgbd_2.62268mm.prefilter.onnx" in line

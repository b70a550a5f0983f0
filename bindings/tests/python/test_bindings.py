"""The generated Python bindings (module `tensorholo`, from bindings/generate.sh) on real phone frames.

Run by bindings/tests/python/check.sh with PYTHONPATH pointing at the generated module and HOLO at a holo
binary. Real frames come from ../shared/data through ../frames.py, which also runs `holo render` on the same
scene: the bindings must produce the same SLM codes (within frames.compare_codes' tolerance).
"""

import json
import sys
import threading
import tomllib
from pathlib import Path

import numpy as np
import pytest

import tensorholo
from tensorholo import (CnnEngine, ColorFormat, DepthFormat, DepthUpsampling, DisplayProfile, Fit, Foveation, Gaze,
                        GeneratorConfig, HologramGenerator, PatternsListener, PrefilterMode, RgbdFrame, Rotation, SceneInput,
                        TensorholoError)

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
import frames  # noqa: E402

REPO_ROOT = HERE.parents[2]
# The iPhone photo's multi-picture (MPO) header: Pillow reads its base JPEG, which is all the tests need.
pytestmark = pytest.mark.filterwarnings("ignore:Image appears to be a malformed MPO file")


def workspace_version() -> str:
    with open(REPO_ROOT / "Cargo.toml", "rb") as f:
        return tomllib.load(f)["workspace"]["package"]["version"]


def rgbd_frame(case: frames.Case, color: bytes, depth: bytes) -> RgbdFrame:
    return RgbdFrame(
        color=color, color_format=getattr(ColorFormat, case.color_format), color_width=case.color_width,
        color_height=case.color_height, color_row_stride=case.color_row_stride,
        depth=depth, depth_format=getattr(DepthFormat, case.depth_format), depth_width=case.depth_width,
        depth_height=case.depth_height, depth_row_stride=case.depth_row_stride,
        rotation=getattr(Rotation, case.rotation))


def codes_of(p) -> np.ndarray:
    return np.stack([np.frombuffer(b, np.uint8).reshape(p.height, p.width) for b in (p.red, p.green, p.blue)])


@pytest.fixture(scope="module", params=list(frames.CASES))
def case(request, tmp_path_factory):
    tmp = tmp_path_factory.mktemp(request.param)
    c, color, depth = frames.CASES[request.param](tmp / "inputs")
    want = frames.holo_codes(c, tmp / "holo")
    gen = HologramGenerator(GeneratorConfig(width=c.out_width, height=c.out_height))
    return c, rgbd_frame(c, color, depth), want, gen


def test_version_is_the_workspace_version():
    assert tensorholo.version() == workspace_version()


def test_phone_frame_renders_the_codes_of_holo_render(case):
    c, frame, want, gen = case
    out = gen.render(frame)
    assert (out.width, out.height) == (c.out_width, c.out_height)
    assert all(isinstance(b, bytes) and len(b) == c.out_width * c.out_height for b in (out.red, out.green,
                                                                                       out.blue))
    stats = frames.compare_codes(codes_of(out), want)
    print(f"{c.name}: vs holo render {stats}")
    assert out.z_near_m is not None and 0 < out.z_near_m < out.z_far_m
    assert out.timings.cnn_ms > 0 and out.timings.convert_ms > 0
    info = gen.info()
    assert info.layers == 8 and info.prefilter_model is not None, info.prefilter_reason
    assert info.cnn_layout in ("nchw", "nhwc")
    rgba = tensorholo.pack_rgba(out)
    px = np.frombuffer(rgba, np.uint8).reshape(c.out_height, c.out_width, 4)
    np.testing.assert_array_equal(px[..., :3].transpose(2, 0, 1), codes_of(out))
    assert (px[..., 3] == 255).all()


def test_joint_bilateral_upsampling_renders_the_codes_of_holo_render_from_the_camera_resolution_depth(case, tmp_path):
    """The frame's depth is at half the colour's resolution. With `depth_upsampling=JOINT_BILATERAL` a generator
    brings it to the colour's as `holo render` does with the same half-resolution depth file (the files'
    default), with the same SDK function; `holo render` upsamples at the output size when that is smaller
    (docs/CONVENTIONS.md §6.1: the depth within a stated bound of upsampling at the colour's size), so the
    codes agree to a mean of 0.1 step (0.04 measured) rather than the bindings' usual 0.02; nearest neighbour
    (the generator's default) gives other codes, if few at this size."""
    c, frame, _, nearest_gen = case
    want = frames.holo_codes(c, tmp_path / "holo", depth=str(Path(c.holo_depth).with_name(frames.LOW_DEPTH)))
    gen = HologramGenerator(GeneratorConfig(width=c.out_width, height=c.out_height,
                                            depth_upsampling=DepthUpsampling.JOINT_BILATERAL))
    got = codes_of(gen.render(frame))
    d = frames.circular_diff(got, want)
    stats = {"mean": float(d.mean()), "within_one": float((d <= 1).mean()), "max": int(d.max())}
    print(f"{c.name}: joint bilateral vs holo render {stats}")
    assert stats["mean"] <= 0.1 and stats["within_one"] >= frames.MIN_WITHIN_ONE, stats
    nearest_codes = codes_of(nearest_gen.render(frame))
    # At this size (the depth's own) the two upsamplings differ by little after the fit: 0.04 step measured.
    assert frames.circular_diff(got, nearest_codes).mean() > 0.01, stats
    converted = tensorholo.convert_frame(frame, c.out_width, c.out_height, None, DepthUpsampling.JOINT_BILATERAL)
    nearest = tensorholo.convert_frame(frame, c.out_width, c.out_height, None)
    assert converted.depth != nearest.depth


def test_a_foveated_frame_is_holo_renders_on_the_same_gaze_and_differs_from_the_full_frame(case, tmp_path):
    c, frame, full, _ = case
    # A fovea of a sixth of the frame's shorter side, off-centre: the tile is smaller than the frame.
    radius = min(c.out_width, c.out_height) / 6
    x, y = c.out_width * 0.3, c.out_height * 0.6
    want = frames.holo_codes(c, tmp_path / "holo", extra=["--gaze", f"{x},{y}", "--fovea-px", str(radius)])
    gen = HologramGenerator(GeneratorConfig(width=c.out_width, height=c.out_height,
                                            foveation=Foveation(radius_px=radius)))
    out = codes_of(gen.render_foveated(frame, Gaze(x=x, y=y)))
    stats = frames.compare_codes(out, want)
    print(f"{c.name}: foveated vs holo render --gaze {stats}")
    # Far from the gaze the periphery is a 2D hologram: codes unlike the full 3D frame's.
    yy, xx = np.mgrid[:c.out_height, :c.out_width]
    far = np.hypot(xx - x, yy - y) > 2 * radius + 32
    diff = frames.circular_diff(out, full)[:, far]
    assert diff.mean() > 4, diff.mean()
    # A gaze outside the hologram, or a generator without foveation, raise naming them.
    with pytest.raises(TensorholoError.InvalidInput, match="gaze"):
        gen.render_foveated(frame, Gaze(x=-5.0, y=y))
    with pytest.raises(TensorholoError.InvalidInput, match="foveation"):
        case[3].render_foveated(frame, Gaze(x=x, y=y))


def test_preview_is_an_image_of_the_scene(case):
    c, frame, _, gen = case
    p = gen.preview(frame, 0.5)
    img = np.frombuffer(p.rgba, np.uint8).reshape(p.height, p.width, 4)
    assert (p.width, p.height) == (c.out_width, c.out_height)
    assert (img[..., 3] == 255).all() and img[..., :3].std() > 5
    with pytest.raises(TensorholoError.InvalidInput):
        gen.preview(frame, 1.5)


def test_a_calibration_file_gives_the_codes_of_holo_render_through_it(case, tmp_path):
    c, frame, want, gen = case
    cal = frames.panel_calibration(c, tmp_path / "panel.holocal")
    want_cal = frames.holo_codes(c, tmp_path / "holo", cal)
    with pytest.raises(TensorholoError.InvalidInput) as e:
        gen.set_calibration(b"HOLOCAL\0 but then nothing")
    assert "calibration" in str(e.value)
    gen.set_calibration(cal.read_bytes())
    try:
        assert "global" in gen.info().calibration
        got = codes_of(gen.render(frame))
        stats = frames.compare_codes(got, want_cal)
        print(f"{c.name}: calibrated vs holo render --calibration {stats}")
        # The panel shows (nearly) the phase an ideal one shows for the uncalibrated codes.
        shown = frames.PANEL_RANGE_RAD * (got / 255.0) ** frames.PANEL_GAMMA
        ideal = 2 * np.pi * want.astype(np.float64) / 256
        err = np.abs(np.angle(np.exp(1j * (shown - ideal))))
        assert np.median(err) < 0.05, np.median(err)
        assert (got != want).mean() > 0.5
    finally:
        gen.set_calibration(None)
    assert gen.info().calibration is None
    frames.compare_codes(codes_of(gen.render(frame)), want)


def _bad_frames(frame: RgbdFrame):
    def with_(**kw):
        d = {k: getattr(frame, k) for k in ("color", "color_format", "color_width", "color_height",
                                             "color_row_stride", "depth", "depth_format", "depth_width",
                                             "depth_height", "depth_row_stride", "rotation")}
        d.update(kw)
        return RgbdFrame(**d)
    nan = np.full(frame.depth_width * frame.depth_height, np.nan, "<f2").tobytes()
    zero = bytes(len(frame.depth))
    return {
        "short colour buffer": with_(color=frame.color[:-1000]),
        "short depth buffer": with_(depth=frame.depth[:-2]),
        "zero width": with_(color_width=0),
        "zero depth height": with_(depth_height=0),
        "stride shorter than a row": with_(color_row_stride=frame.color_width * 4 - 4),
        "width*height*4 overflows u32": with_(color_width=70_000, color_height=70_000),
        "every depth pixel invalid (0)": with_(depth=zero),
        "every depth pixel NaN": with_(depth=nan, depth_format=DepthFormat.DISPARITY_F16),
    }


def test_bad_frames_raise_and_the_generator_goes_on(case):
    c, frame, want, gen = case
    for what, bad in _bad_frames(frame).items():
        with pytest.raises(TensorholoError.InvalidInput) as e:
            gen.render(bad)
        assert str(e.value), what
    frames.compare_codes(codes_of(gen.render(frame)), want)


def test_an_ldi_generator_renders_layers_and_an_rgbd_one_refuses_them(case):
    c, frame, _, gen = case
    ldi_gen = HologramGenerator(GeneratorConfig(width=c.out_width, height=c.out_height, input=SceneInput.LDI,
                                                threads=1, engine=CnnEngine.NATIVE))
    assert "holo8_ldi" in ldi_gen.info().hologram_model
    one = ldi_gen.render_ldi([frame])
    # A frame is a one-layer LDI: the same codes either way.
    np.testing.assert_array_equal(codes_of(one), codes_of(ldi_gen.render(frame)))
    # The same surface twice (a back layer no nearer than the front): five layers at most.
    two = ldi_gen.render_ldi([frame, frame])
    assert (two.width, two.height) == (c.out_width, c.out_height)
    with pytest.raises(TensorholoError.InvalidInput) as e:
        ldi_gen.render_ldi([frame] * 6)
    assert "takes 5" in str(e.value)
    with pytest.raises(TensorholoError.InvalidInput) as e:
        gen.render_ldi([frame, frame])
    assert "holo8_ldi" in str(e.value)
    with pytest.raises(TensorholoError.InvalidInput):
        ldi_gen.render_ldi([])


@pytest.mark.parametrize("kw, field", [
    (dict(width=0, height=64), "width"),
    (dict(width=64, height=64, offset_mm=float("nan")), "offset_m"),
    (dict(width=64, height=64, offset_mm=-6.0), "offset_m"),
    (dict(width=64, height=64, pixel_pitch_m=-8e-6), "pixel_pitch_m"),
    (dict(width=64, height=64, pixel_pitch_m=float("nan")), "pixel_pitch_m"),
    (dict(width=64, height=64, volume_depth_m=0.0), "volume_depth_m"),
    (dict(width=64, height=64, layers=9), "layers"),
    (dict(width=64, height=64, prefilter=PrefilterMode.REQUIRED, offset_mm=7.0), "prefilter"),
    (dict(width=64, height=64, wavelengths_m=[5e-7]), "wavelengths_m"),
    (dict(width=64, height=64, z_near_m=1.0), "z_far_m"),
    (dict(width=64, height=64, z_near_m=2.0, z_far_m=1.0), "depth_range"),
    (dict(width=100_000, height=100_000), "width"),
])
def test_bad_configurations_raise_invalid_input_naming_the_field(kw, field):
    with pytest.raises(TensorholoError.InvalidInput) as e:
        HologramGenerator(GeneratorConfig(**kw))
    assert field in str(e.value), str(e.value)


class Recorder(PatternsListener):
    def __init__(self):
        self.indices, self.errors, self.patterns = [], [], []
        self.threads = set()
        self.done = threading.Event()

    def on_patterns(self, index, patterns):
        self.threads.add(threading.get_ident())
        self.indices.append(index)
        self.patterns.append(patterns)

    def on_error(self, error):
        self.errors.append(error.message)


def test_stream_delivers_frames_in_order_from_its_own_thread(case):
    c, frame, want, gen = case
    rec = Recorder()
    stream = gen.stream(rec)
    n = 4
    for i in range(n):
        assert stream.push(frame) == i
        # A camera pushes at its own pace; waiting keeps this test free of drops.
        while len(rec.indices) + len(rec.errors) <= i:
            threading.Event().wait(0.01)
    stream.close()
    assert rec.indices == list(range(n)) and not rec.errors
    assert threading.get_ident() not in rec.threads
    assert stream.dropped_frames() == 0
    for p in rec.patterns:
        frames.compare_codes(codes_of(p), want)
    with pytest.raises(TensorholoError.InvalidInput):
        stream.push(frame)


def test_a_stream_burst_drops_the_oldest_and_reports_bad_frames_in_place(case):
    c, frame, _, gen = case
    rec = Recorder()
    stream = gen.stream(rec)
    bad = _bad_frames(frame)["short depth buffer"]
    pushed = [stream.push(bad if i == 0 else frame) for i in range(8)]
    stream.close()
    assert pushed == list(range(8))
    delivered = len(rec.indices) + len(rec.errors)
    assert delivered + stream.dropped_frames() == 8
    assert rec.indices == sorted(rec.indices) and rec.indices[-1] == 7
    assert all(e.startswith("frame 0:") for e in rec.errors), rec.errors


# A 4 µm SLM at the paper's lasers (docs/DISPLAYS.md): σ = (4/8)² = 0.25, so the shipped 8 µm / 6 mm CNNs
# serve a 1.5 mm volume at offsets of 1.5 and 3 mm. Small, so that a frame renders quickly.
PROFILE_4UM = {
    "name": "4 µm SLM",
    "pixel_pitch_m": 4e-6,
    "resolution": [48, 64],
    "wavelengths_m": [638e-9, 520e-9, 450e-9],
    "volume_depth_m": 1.5e-3,
    "offsets_m": [1.5e-3, 3e-3],
}


def small_frame(width=64, height=48) -> RgbdFrame:
    """RGB8 texture with metric depth: a ramp from 0.5 m to 1.5 m across the width."""
    y, x = np.mgrid[0:height, 0:width]
    rgb = np.stack([x * 4, y * 5, (x ^ y) * 7], axis=-1).astype(np.uint8)
    depth = np.broadcast_to(0.5 + x / width, (height, width)).astype("<f4")
    return RgbdFrame(color=rgb.tobytes(), color_format=ColorFormat.RGB8, color_width=width, color_height=height,
                     depth=depth.tobytes(), depth_format=DepthFormat.METRES_F32, depth_width=width,
                     depth_height=height)


def profile_record(**changes) -> DisplayProfile:
    """PROFILE_4UM as a record built field by field, with `changes`."""
    d = {**PROFILE_4UM, **changes}
    return DisplayProfile(pixel_pitch_m=d["pixel_pitch_m"], resolution=d["resolution"],
                          wavelengths_m=d["wavelengths_m"], volume_depth_m=d["volume_depth_m"],
                          offsets_m=d["offsets_m"], name=d["name"])


def test_a_4um_display_profile_renders_with_the_shipped_models_at_sigma_a_quarter():
    profile = tensorholo.display_profile_from_json(json.dumps(PROFILE_4UM))
    assert profile == profile_record()
    assert profile.resolution == [48, 64] and profile.calibration is None
    config = tensorholo.generator_config_for_display(profile)
    assert (config.width, config.height) == (64, 48)
    assert config.pixel_pitch_m == 4e-6 and config.volume_depth_m == 1.5e-3
    assert config.wavelengths_m == [638e-9, 520e-9, 450e-9]
    assert config.offset_mm == pytest.approx(1.5)
    assert config.wavelength_ratio_tolerance is None  # the serving rule's
    config.threads, config.engine = 1, CnnEngine.NATIVE
    gen = HologramGenerator(config)
    out = gen.render(small_frame())
    assert (out.width, out.height) == (64, 48)
    assert len(set(out.red)) > 1
    info = gen.info()
    assert "σ = 0.25" in info.display_mapping, info.display_mapping
    assert "serves 4 µm with a 1.5 mm volume" in info.display_mapping, info.display_mapping
    assert info.prefilter_model is not None and "6mm" in info.prefilter_model, info.prefilter_reason
    assert json.loads(info.json)["display_mapping"] == info.display_mapping
    # Which shipped CNNs serve it, before a generator: every hologram CNN, at no cost (the paper's lasers).
    checks = tensorholo.check_display(profile, None)
    holo = [c for c in checks if c.kind == "hologram-cnn"]
    assert holo and all(c.served and c.cost_db == 0.0 for c in holo), checks
    assert any(c.file == "prefilter_6mm.onnx" and c.served for c in checks), checks


# Each bad display: the change to PROFILE_4UM, the error class and the key its message must name. The first
# two break the profile rules (refused when the profile is read or converted); the last two are profiles the
# shipped CNNs cannot serve (refused when the generator checks its models).
BAD_DISPLAYS = {
    "negative pitch": (dict(pixel_pitch_m=-4e-6), TensorholoError.InvalidInput, "pixel_pitch_m"),
    "resolution not [height, width]": (dict(resolution=[48]), TensorholoError.InvalidInput, "resolution"),
    "a green laser 8 % off 520 nm (costs more than the rule allows)": (
        dict(wavelengths_m=[638e-9, 561.6e-9, 450e-9]), TensorholoError.InvalidModel, "wavelengths_m"),
    "2 mm volume (σ·6 mm is 1.5 mm)": (dict(volume_depth_m=2e-3), TensorholoError.InvalidModel,
                                        "volume_depth_m"),
}


def _generator_for(profile_source):
    """JSON text or a record → profile → configuration → generator, as an app does."""
    profile = (tensorholo.display_profile_from_json(profile_source) if isinstance(profile_source, str)
               else profile_source)
    config = tensorholo.generator_config_for_display(profile)
    config.threads, config.engine = 1, CnnEngine.NATIVE
    return HologramGenerator(config)


@pytest.mark.parametrize("what", list(BAD_DISPLAYS))
@pytest.mark.parametrize("source", ["json", "record"])
def test_a_bad_display_profile_is_an_error_naming_the_key(what, source):
    changes, error, key = BAD_DISPLAYS[what]
    profile = json.dumps({**PROFILE_4UM, **changes}) if source == "json" else profile_record(**changes)
    with pytest.raises(error) as e:
        _generator_for(profile)
    assert key in str(e.value), str(e.value)
    print(f"{what} ({source}): {e.value}")


def test_a_profile_typo_is_refused_by_name():
    text = json.dumps(PROFILE_4UM).replace("pixel_pitch_m", "pixel_pich_m")
    with pytest.raises(TensorholoError.InvalidInput) as e:
        tensorholo.display_profile_from_json(text)
    assert "pixel_pich_m" in str(e.value)
    with pytest.raises(TensorholoError.InvalidInput):
        tensorholo.display_profile_from_json("not json")


class _Progress(tensorholo.RefineProgress):
    """Records every iteration; cancels after `stop_after` iterations (None: never)."""

    def __init__(self, stop_after=None):
        self.seen = []
        self.stop_after = stop_after

    def on_iteration(self, iteration, iterations, psnr_db):
        self.seen.append((iteration, iterations, psnr_db))
        return self.stop_after is None or iteration < self.stop_after


def test_the_photo_mode_refines_reports_progress_and_cancels(case):
    c, frame, _, gen = case
    plain = codes_of(gen.render(frame))
    progress = _Progress()
    refined = codes_of(gen.render_refined(frame, tensorholo.RefineSettings(iterations=4), progress))
    assert refined.shape == plain.shape
    # The refinement changes the pattern, and its loss falls: the PSNR against the target rises.
    assert np.mean(refined != plain) > 0.05
    assert [s[0] for s in progress.seen] == [0, 1, 2, 3, 4]
    assert all(s[1] == 4 for s in progress.seen)
    assert progress.seen[-1][2] > progress.seen[0][2] + 1.0, progress.seen
    # Cancelled after iteration 1: an error, and the generator goes on.
    with pytest.raises(TensorholoError.Cancelled) as e:
        gen.render_refined(frame, tensorholo.RefineSettings(iterations=4), _Progress(stop_after=1))
    assert "after 1 of 4" in str(e.value)
    for bad, field in [(dict(iterations=0), "iterations"), (dict(iterations=10001), "iterations"),
                       (dict(step_rad=float("nan")), "step_rad"), (dict(planes=0), "planes"),
                       (dict(target_levels=0), "levels")]:
        with pytest.raises(TensorholoError.InvalidInput) as e:
            gen.render_refined(frame, tensorholo.RefineSettings(**bad), None)
        assert field in str(e.value), (bad, str(e.value))
    assert np.array_equal(codes_of(gen.render(frame)), plain)


def test_the_photo_mode_refines_through_a_display_model_and_a_bad_one_is_refused_by_name(case):
    c, frame, _, gen = case
    model = json.dumps({"format": "tensorholo.display-model", "version": 1,
                        "slm_size": [c.out_height, c.out_width],
                        "green": {"crosstalk": {"size": [3, 3], "weights": [0, .05, 0, .05, .8, .05, 0, .05, 0]},
                                  "zero_order": [0.05, 0.0]}})
    fitted = HologramGenerator(GeneratorConfig(width=c.out_width, height=c.out_height, display_model=model))
    settings = tensorholo.RefineSettings(iterations=2)
    ideal = codes_of(gen.render_refined(frame, settings, None))
    through = codes_of(fitted.render_refined(frame, settings, None))
    # The green pattern is refined for the crosstalk and zero order: other codes.
    assert np.mean(ideal[1] != through[1]) > 0.1
    for bad in ['{"format": "tensorholo.display-model", "version": 1, "slm_size": [4, 4]}',
                model.replace('"size": [3, 3]', '"size": [2, 2]')]:
        with pytest.raises(TensorholoError.InvalidInput) as e:
            HologramGenerator(GeneratorConfig(width=c.out_width, height=c.out_height, display_model=bad))
        assert "model" in str(e.value), str(e.value)

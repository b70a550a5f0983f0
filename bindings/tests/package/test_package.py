"""The installed Python package (`pip install ./bindings`), numpy in and out, from outside the repository.

Run by bindings/tests/package/check.sh in a fresh venv, with the current directory a temp folder: `tensorholo`
must come from the venv's site-packages, never from the source tree. Real frames come from ../shared/data
through ../frames.py, which also runs `holo render` ($HOLO) on the same scene: `render_arrays` must give the
codes holo gives (within frames.compare_codes' tolerance, the one of the bindings' own tests).
"""

import importlib.metadata
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import tensorholo as th

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
import frames  # noqa: E402

REPO_ROOT = HERE.parents[2]
pytestmark = pytest.mark.filterwarnings("ignore:Image appears to be a malformed MPO file")


def test_the_package_is_the_installed_wheel_with_the_workspace_version():
    module = Path(th.__file__).resolve()
    assert "site-packages" in module.parts, module
    assert REPO_ROOT not in module.parents, module
    cwd = Path.cwd().resolve()
    assert cwd != REPO_ROOT and REPO_ROOT not in cwd.parents, f"run from outside the repository, not {cwd}"
    with open(REPO_ROOT / "Cargo.toml", "rb") as f:
        version = tomllib.load(f)["workspace"]["package"]["version"]
    assert th.version() == version == importlib.metadata.version("tensorholo")
    assert (module.parent / "py.typed").is_file()
    requires = importlib.metadata.requires("tensorholo") or []
    assert any(r.startswith("numpy") for r in requires), requires
    # The uniffi API and the numpy helpers, under one name.
    for name in ("HologramGenerator", "GeneratorConfig", "RgbdFrame", "TensorholoError", "pack_rgba",
                 "render_arrays", "patterns_array"):
        assert name in th.__all__ and hasattr(th, name), name


def _holo_case(name: str, tmp: Path) -> frames.Case:
    """frames.py's case `name`: holo's input files (upright colour PNG, half-resolution depth upsampled back)."""
    case, _, _ = frames.CASES[name](tmp)
    return case


def redwood_arrays(case: frames.Case) -> tuple[np.ndarray, np.ndarray]:
    """Redwood as numpy: RGB uint8 [480, 640, 3] and uint16 millimetres at half resolution [240, 320]."""
    rgb = np.asarray(Image.open(case.holo_rgb).convert("RGB"))
    mm = np.asarray(Image.open(case.holo_depth)).astype(np.uint16)[::2, ::2]
    return rgb, mm


def iphone_arrays(case: frames.Case) -> tuple[np.ndarray, np.ndarray]:
    """The iPhone portrait as numpy: RGBA uint8 [768, 576, 4] and float32 metres at half resolution."""
    rgb = np.asarray(Image.open(case.holo_rgb).convert("RGB"))
    rgba = np.concatenate([rgb, np.full(rgb.shape[:2] + (1,), 255, np.uint8)], axis=2)
    v = np.asarray(Image.open(case.holo_depth).convert("L"))[::2, ::2].astype(np.float64)
    a, b = frames.IPHONE_DISPARITY
    metres = (1.0 / (a + v / 255 * b)).astype(np.float32)
    return rgba, metres


ARRAYS = {"redwood": redwood_arrays, "iphone": iphone_arrays}


@pytest.fixture(scope="module", params=list(ARRAYS))
def real(request, tmp_path_factory):
    tmp = tmp_path_factory.mktemp(request.param)
    case = _holo_case(request.param, tmp / "inputs")
    rgb, depth = ARRAYS[request.param](case)
    want = frames.holo_codes(case, tmp / "holo")
    gen = th.HologramGenerator(th.GeneratorConfig(width=case.out_width, height=case.out_height))
    return case, rgb, depth, want, gen


def test_a_real_frame_renders_the_codes_of_holo_render(real):
    case, rgb, depth, want, gen = real
    assert depth.shape != rgb.shape[:2]  # half the colour's resolution, as a phone's depth
    codes = th.render_arrays(gen, rgb, depth)
    assert codes.dtype == np.uint8 and codes.shape == (3, case.out_height, case.out_width)
    assert codes.flags.writeable and codes.flags.c_contiguous
    stats = frames.compare_codes(codes, want)
    print(f"{case.name} ({rgb.shape} {rgb.dtype}, {depth.shape} {depth.dtype}): vs holo render {stats}")
    if depth.dtype == np.uint16:
        # Millimetres cross as the very bytes holo reads from the PNG: not one code differs (measured).
        np.testing.assert_array_equal(codes, want)
    # The same as the uniffi call it wraps.
    np.testing.assert_array_equal(codes, th.patterns_array(gen.render(th.RgbdFrame(
        color=rgb.tobytes(), color_format=th.ColorFormat.RGB8 if rgb.shape[2] == 3 else th.ColorFormat.RGBA8,
        color_width=rgb.shape[1], color_height=rgb.shape[0], depth=depth.tobytes(),
        depth_format=th.DepthFormat.MILLIMETRES_U16 if depth.dtype == np.uint16 else th.DepthFormat.METRES_F32,
        depth_width=depth.shape[1], depth_height=depth.shape[0]))))


def test_layout_and_byte_order_do_not_change_the_codes(real):
    case, rgb, depth, want, gen = real
    codes = th.render_arrays(gen, rgb, depth)
    # Fortran order, a strided view (every other column of a doubled array), big-endian depth.
    rgb_f = np.asfortranarray(rgb)
    wide = np.repeat(depth, 2, axis=1)[:, ::2]
    assert not wide.flags.c_contiguous
    big = depth.astype(depth.dtype.newbyteorder(">"))
    np.testing.assert_array_equal(th.render_arrays(gen, rgb_f, wide), codes)
    np.testing.assert_array_equal(th.render_arrays(gen, rgb, big), codes)


def test_millimetres_and_metres_of_one_scene_give_the_same_codes():
    """A small synthetic frame (fast): uint16 mm and the same depths as float32 metres."""
    h, w = 48, 64
    y, x = np.mgrid[0:h, 0:w]
    rgb = np.stack([x * 4, y * 5, (x ^ y) * 7], axis=-1).astype(np.uint8)
    mm = (500 + 1000 * x // w).astype(np.uint16)
    gen = th.HologramGenerator(th.GeneratorConfig(width=w, height=h, threads=1, engine=th.CnnEngine.NATIVE))
    a = th.render_arrays(gen, rgb, mm)
    b = th.render_arrays(gen, rgb, mm.astype(np.float32) / 1000)
    frames.compare_codes(a, b)
    assert len(np.unique(a)) > 16


def _ok():
    h, w = 16, 24
    return np.zeros((h, w, 3), np.uint8) + 128, np.full((h // 2, w // 2), 1.0, np.float32)


def _with_nan():
    d = _ok()[1].copy()
    d[3, 4] = np.nan
    return d


RGB, DEPTH = _ok()
BAD = {
    # what: (rgb, depth, error, words the message must hold)
    "rgb float": (RGB.astype(np.float32) / 255, DEPTH, TypeError, ["rgb", "uint8", "float32"]),
    "rgb a list": (RGB.tolist(), DEPTH, TypeError, ["rgb", "numpy"]),
    "rgb uint16": (RGB.astype(np.uint16), DEPTH, TypeError, ["rgb", "uint16"]),
    "rgb grey [H, W]": (RGB[..., 0], DEPTH, ValueError, ["rgb", "[16, 24]"]),
    "rgb two channels": (RGB[..., :2], DEPTH, ValueError, ["rgb", "[16, 24, 2]"]),
    "rgb channels first": (np.ascontiguousarray(RGB.transpose(2, 0, 1)), DEPTH, ValueError, ["rgb"]),
    "rgb empty": (RGB[:0], DEPTH, ValueError, ["rgb", "empty"]),
    "depth float64": (RGB, DEPTH.astype(np.float64), TypeError, ["depth", "float64", "float32"]),
    "depth int32": (RGB, DEPTH.astype(np.int32), TypeError, ["depth", "int32", "uint16"]),
    "depth None": (RGB, None, TypeError, ["depth", "NoneType"]),
    "depth [h, w, 1]": (RGB, DEPTH[..., None], ValueError, ["depth", "[h, w]", "depth[..., 0]"]),
    "depth empty": (RGB, DEPTH[:, :0], ValueError, ["depth", "empty"]),
    "depth NaN": (RGB, _with_nan(), ValueError, ["depth", "1 NaN", "nan_to_num"]),
    "depth infinite": (RGB, DEPTH * np.float32(np.inf), ValueError, ["depth", "infinite"]),
    "depth negative": (RGB, -DEPTH, ValueError, ["depth", "negative"]),
    "depth all 0": (RGB, np.zeros_like(DEPTH), ValueError, ["depth", "no valid pixel"]),
    "depth all 0 mm": (RGB, np.zeros(DEPTH.shape, np.uint16), ValueError, ["depth", "no valid pixel"]),
    # Broadcast views of 20000 x 20000 hold 3 and 4 bytes until copied (1.2 GB, then again for the crossing):
    # refused by their pixel count before any copy, naming the argument, dtype, shape and the limit.
    "rgb 400 MP view": (np.broadcast_to(np.uint8(128), (20000, 20000, 3)), DEPTH, ValueError,
                        ["rgb", "400000000 pixels", "uint8", "[20000, 20000, 3]", "max_frame_pixels"]),
    "depth 400 MP view": (RGB, np.broadcast_to(np.float32(1.0), (20000, 20000)), ValueError,
                          ["depth", "400000000 pixels", "float32", "[20000, 20000]", "max_frame_pixels"]),
}


@pytest.fixture(scope="module")
def small_gen():
    return th.HologramGenerator(th.GeneratorConfig(width=24, height=16, threads=1, engine=th.CnnEngine.NATIVE))


@pytest.mark.parametrize("what", list(BAD))
def test_bad_arrays_raise_naming_the_argument(small_gen, what):
    rgb, depth, error, words = BAD[what]
    with pytest.raises(error) as e:
        th.render_arrays(small_gen, rgb, depth)
    for word in words:
        assert word in str(e.value), (what, str(e.value))
    print(f"{what}: {type(e.value).__name__}: {e.value}")


def test_good_small_arrays_render_and_the_core_errors_stay_tensorholo_errors(small_gen):
    codes = th.render_arrays(small_gen, *_ok())
    assert codes.shape == (3, 16, 24) and codes.dtype == np.uint8
    # RGBA of the same pixels: alpha is ignored.
    rgba = np.concatenate([RGB, np.zeros(RGB.shape[:2] + (1,), np.uint8)], axis=2)
    np.testing.assert_array_equal(th.render_arrays(small_gen, rgba, DEPTH), codes)
    # What only the core can judge is still its typed error: a black frame (a covered lens).
    with pytest.raises(th.TensorholoError.InvalidInput):
        th.render_arrays(small_gen, np.zeros_like(RGB), DEPTH)


def test_refine_is_the_photo_mode_and_bad_counts_are_refused(small_gen):
    plain = th.render_arrays(small_gen, *_ok())
    refined = th.render_arrays(small_gen, *_ok(), refine=3)
    assert refined.shape == plain.shape and refined.dtype == np.uint8
    assert not np.array_equal(refined, plain)
    for bad, error in [(-1, ValueError), (2.5, TypeError), (True, TypeError)]:
        with pytest.raises(error) as e:
            th.render_arrays(small_gen, *_ok(), refine=bad)
        assert "refine" in str(e.value)
    with pytest.raises(th.TensorholoError.InvalidInput) as e:
        th.render_arrays(small_gen, *_ok(), refine=10001)
    assert "iterations" in str(e.value)


def test_a_gaze_renders_a_foveated_frame_and_bad_gazes_are_refused():
    # 64 x 96 with a 10-pixel fovea: its tile is smaller than the frame.
    rgb = np.zeros((64, 96, 3), np.uint8)
    rgb[::2] = 200
    rgb[:, ::3, 1] = 90
    depth = np.full((64, 96), 1.5, np.float32)
    depth[:, :48] = 0.8
    gen = th.HologramGenerator(th.GeneratorConfig(width=96, height=64, threads=1, engine=th.CnnEngine.NATIVE,
                                                  foveation=th.Foveation(radius_px=10.0)))
    full = th.render_arrays(gen, rgb, depth)
    fov = th.render_arrays(gen, rgb, depth, gaze=(30, 20))
    # The same as the uniffi call it wraps, with or without the vergence depth given as a third number.
    frame = th.RgbdFrame(color=rgb.tobytes(), color_format=th.ColorFormat.RGB8, color_width=96, color_height=64,
                         depth=depth.tobytes(), depth_format=th.DepthFormat.METRES_F32, depth_width=96,
                         depth_height=64)
    np.testing.assert_array_equal(fov, th.patterns_array(gen.render_foveated(frame, th.Gaze(x=30, y=20))))
    np.testing.assert_array_equal(
        th.render_arrays(gen, rgb, depth, gaze=(30, 20, 0.001)),
        th.patterns_array(gen.render_foveated(frame, th.Gaze(x=30, y=20, depth_m=0.001))))
    # Far from the gaze the periphery is a 2D hologram, not the full frame's.
    assert (fov[:, 40:, 70:] != full[:, 40:, 70:]).mean() > 0.5
    for bad, error in [((30,), TypeError), ("30,20", TypeError), ((30, True), TypeError),
                       ((500, 20), th.TensorholoError.InvalidInput), ((30, 20), ValueError)]:
        with pytest.raises(error) as e:
            th.render_arrays(gen, rgb, depth, gaze=bad, refine=1 if error is ValueError else 0)
        assert "gaze" in str(e.value), str(e.value)


MYPY_SNIPPET = """
import numpy as np
import tensorholo as th

gen = th.HologramGenerator(th.GeneratorConfig(width=8, height=8))
codes = th.render_arrays(gen, np.zeros((8, 8, 3), np.uint8), np.ones((8, 8), np.float32))
reveal_type(codes)
reveal_type(gen.render)
th.render_arrays(gen, np.zeros((8, 8, 3), np.uint8), "depth.png")
"""


def test_mypy_sees_the_typed_api(tmp_path):
    """py.typed: mypy reads the numpy helpers' and the generated bindings' annotations (mypy installed only)."""
    pytest.importorskip("mypy")
    snippet = tmp_path / "snippet.py"
    snippet.write_text(MYPY_SNIPPET)
    r = subprocess.run([sys.executable, "-m", "mypy", "--no-error-summary", "--cache-dir",
                        str(tmp_path / "cache"), str(snippet)], capture_output=True, text=True, cwd=tmp_path,
                       env={**os.environ, "MYPYPATH": ""})
    out = r.stdout + r.stderr
    print(out)
    lines = out.splitlines()
    assert any('Revealed type is "numpy.ndarray[' in ln and "unsignedinteger[" in ln and "_8Bit]" in ln
               for ln in lines), out
    assert any("RgbdFrame" in ln and "SlmPatterns" in ln for ln in lines if "Revealed" in ln), out
    assert any("arg-type" in ln and "render_arrays" in ln for ln in lines), out
    assert r.returncode == 1 and sum("error:" in ln for ln in lines) == 1, out


@pytest.mark.parametrize("value, words", [
    # Beyond any SLM grid's sampling of the correction (a unit error): the sample, colour and term.
    ("1e308", ["aberration", "focus", "beyond"]),
    # Beyond f64 itself: the key path, not an error blamed on the scene or the frame.
    ("1e999", ["aberration", "samples[0].coefficients.focus"]),
])
def test_an_aberration_beyond_any_slm_is_refused_naming_the_term(value, words):
    text = ('{"format": "tensorholo.aberration", "version": 1, "samples": '
            '[{"distance_m": 0.0, "coefficients": {"focus": %s}}]}' % value)
    with pytest.raises(th.TensorholoError.InvalidInput) as e:
        th.HologramGenerator(th.GeneratorConfig(width=24, height=16, threads=1, aberration=text))
    for word in words:
        assert word in str(e.value), (value, str(e.value))

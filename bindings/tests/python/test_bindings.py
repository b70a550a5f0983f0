"""Checks of the generated Python bindings (module `tensorholo`, from bindings/generate.sh).

Run by bindings/tests/python/check.sh with PYTHONPATH pointing at the generated module. The demo items
(Echo, Bytes8Demo, DemoListener, demo_panic) are placeholders proving the FFI paths; replace these tests
together with them.
"""

import threading
import tomllib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image, ImageOps

import tensorholo

REPO_ROOT = Path(__file__).resolve().parents[3]


def workspace_version() -> str:
    with open(REPO_ROOT / "Cargo.toml", "rb") as f:
        return tomllib.load(f)["workspace"]["package"]["version"]


def test_version_is_the_workspace_version():
    assert tensorholo.version() == workspace_version()


def test_invert_numpy_round_trip_is_the_negative():
    rng = np.random.default_rng(7)
    a = rng.integers(0, 256, size=(5, 7), dtype=np.uint8)
    echo = tensorholo.Echo(1000)
    out = echo.invert(tensorholo.Bytes8Demo(width=7, height=5, data=a.tobytes()))
    assert isinstance(out.data, bytes)
    assert (out.width, out.height) == (7, 5)
    b = np.frombuffer(out.data, dtype=np.uint8).reshape(5, 7)
    np.testing.assert_array_equal(b, 255 - a)
    # Inverting twice gives the input back.
    again = echo.invert(out)
    assert again.data == a.tobytes()


def test_every_byte_value_crosses_unchanged():
    data = bytes(range(256))
    out = tensorholo.Echo(256).invert(tensorholo.Bytes8Demo(width=16, height=16, data=data))
    assert out.data == bytes(range(255, -1, -1))


def test_invert_matches_pillow_on_a_row_major_image():
    rng = np.random.default_rng(3)
    img = Image.fromarray(rng.integers(0, 256, size=(9, 13), dtype=np.uint8), mode="L")
    out = tensorholo.Echo(10_000).invert(
        tensorholo.Bytes8Demo(width=img.width, height=img.height, data=img.tobytes())
    )
    neg = Image.frombytes("L", (out.width, out.height), out.data)
    assert neg.tobytes() == ImageOps.invert(img).tobytes()


def test_wrong_size_raises_invalid_input():
    echo = tensorholo.Echo(100)
    with pytest.raises(tensorholo.TensorholoError.InvalidInput) as e:
        echo.invert(tensorholo.Bytes8Demo(width=3, height=2, data=bytes(5)))
    assert isinstance(e.value, tensorholo.TensorholoError)
    assert isinstance(e.value, Exception)
    assert e.value.message == "image data has 5 bytes, expected width * height = 3 * 2 = 6"
    assert "5 bytes" in str(e.value)
    with pytest.raises(tensorholo.TensorholoError.InvalidInput, match="at most 100"):
        echo.invert(tensorholo.Bytes8Demo(width=20, height=20, data=bytes(400)))


def test_fallible_constructor_raises_invalid_input():
    with pytest.raises(tensorholo.TensorholoError.InvalidInput, match="max_pixels"):
        tensorholo.Echo(0)


def test_a_rust_panic_is_internal_not_a_crash():
    with pytest.raises(tensorholo.TensorholoError.Internal, match="panicked: boom"):
        tensorholo.demo_panic("boom")
    # The library is still usable afterwards.
    assert tensorholo.version() == workspace_version()


class Recorder(tensorholo.DemoListener):
    def __init__(self):
        self.values = []
        self.errors = []
        self.threads = set()

    def on_value(self, index, value):
        self.threads.add(threading.get_ident())
        self.values.append((index, value))

    def on_error(self, error):
        self.errors.append(error)


def test_listener_gets_every_value_in_order_from_a_rust_thread():
    rec = Recorder()
    n = 500
    tensorholo.Echo(1).stream(rec, n, True)
    assert [i for i, _ in rec.values] == list(range(n))
    for i, v in rec.values:
        assert (v.width, v.height) == (8, 1)
        assert v.data == i.to_bytes(8, "little")
    # Called from one thread that is not the caller's.
    assert len(rec.threads) == 1
    assert threading.get_ident() not in rec.threads
    assert len(rec.errors) == 1
    assert isinstance(rec.errors[0], tensorholo.TensorholoError.InvalidInput)
    assert f"after {n} values" in str(rec.errors[0])


def test_no_values_no_error():
    rec = Recorder()
    tensorholo.Echo(1).stream(rec, 0, False)
    assert rec.values == [] and rec.errors == []


def test_stream_count_limit_is_invalid_input():
    with pytest.raises(tensorholo.TensorholoError.InvalidInput, match="exceeds"):
        tensorholo.Echo(1).stream(Recorder(), 1 << 21, False)


class Raising(Recorder):
    def on_value(self, index, value):
        super().on_value(index, value)
        if index == 2:
            raise RuntimeError("listener broke")


def test_an_exception_in_the_listener_is_internal_and_stops_the_stream():
    rec = Raising()
    with pytest.raises(tensorholo.TensorholoError.Internal):
        tensorholo.Echo(1).stream(rec, 10, True)
    assert [i for i, _ in rec.values] == [0, 1, 2]
    assert rec.errors == []

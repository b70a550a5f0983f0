"""numpy in and out on top of the uniffi API: an RGB-D frame as arrays → the three SLM patterns as one array.

``render_arrays(generator, rgb, depth)`` checks the arrays (dtype, shape, values) and raises ``TypeError`` /
``ValueError`` naming the argument before anything crosses into Rust; what the core refuses after that is a
``TensorholoError`` (e.g. ``TensorholoError.InvalidInput`` for a frame larger than the core accepts).
"""

from __future__ import annotations

from typing import Union

import numpy as np
import numpy.typing as npt

from ._uniffi.tensorholo import (
    ColorFormat,
    DepthFormat,
    Gaze,
    HologramGenerator,
    RefineProgress,
    RefineSettings,
    RgbdFrame,
    SlmPatterns,
    max_frame_pixels,
)

__all__ = ["patterns_array", "render_arrays"]

#: Depth accepted by :func:`render_arrays`: float32 metres or uint16 millimetres, ``[h, w]``.
DepthArray = Union[npt.NDArray[np.float32], npt.NDArray[np.uint16]]


def _array(name: str, value: object) -> np.ndarray:
    if not isinstance(value, np.ndarray):
        raise TypeError(f"{name} must be a numpy.ndarray, not {type(value).__name__}")
    return value


def _within_limit(name: str, a: np.ndarray, h: int, w: int) -> None:
    """Refuses a frame above the core's pixel limit before anything is copied or scanned (a broadcast view of
    20000 x 20000 holds no memory until it is copied: 1.2 GB for the bytes, again for the crossing)."""
    limit = max_frame_pixels()
    if h * w > limit:
        raise ValueError(f"{name} is {h} x {w} = {h * w} pixels ({a.dtype}, shape {list(a.shape)}), more "
                         f"than the {limit} a frame may have (tensorholo.max_frame_pixels()); downscale it")


def _color(rgb: object) -> tuple[bytes, ColorFormat, int, int]:
    a = _array("rgb", rgb)
    if a.dtype != np.uint8:
        raise TypeError(f"rgb must be uint8 sRGB codes (0–255), not {a.dtype}"
                        + ("; from floats in [0, 1]: (rgb * 255).round().astype(np.uint8)"
                           if a.dtype.kind == "f" else ""))
    if a.ndim != 3 or a.shape[2] not in (3, 4):
        raise ValueError(f"rgb must have the shape [H, W, 3] (RGB) or [H, W, 4] (RGBA), not {list(a.shape)}")
    h, w, c = a.shape
    if h == 0 or w == 0:
        raise ValueError(f"rgb is empty: shape {list(a.shape)}")
    _within_limit("rgb", a, h, w)
    fmt = ColorFormat.RGB8 if c == 3 else ColorFormat.RGBA8
    return np.ascontiguousarray(a).tobytes(), fmt, w, h


def _depth(depth: object) -> tuple[bytes, DepthFormat, int, int]:
    a = _array("depth", depth)
    # Either byte order: the bytes cross little-endian.
    if a.dtype.kind == "f" and a.dtype.itemsize == 4:
        fmt, le = DepthFormat.METRES_F32, "<f4"
    elif a.dtype.kind == "u" and a.dtype.itemsize == 2:
        fmt, le = DepthFormat.MILLIMETRES_U16, "<u2"
    else:
        hint = "; metres as floats: depth.astype(np.float32)" if a.dtype.kind == "f" else ""
        raise TypeError(f"depth must be float32 (metres) or uint16 (millimetres), not {a.dtype}{hint}")
    if a.ndim != 2:
        hint = "; a single channel: depth[..., 0]" if a.ndim == 3 and a.shape[2] == 1 else ""
        raise ValueError(f"depth must have the shape [h, w], not {list(a.shape)}{hint}")
    h, w = a.shape
    if h == 0 or w == 0:
        raise ValueError(f"depth is empty: shape {list(a.shape)}")
    _within_limit("depth", a, h, w)
    if fmt is DepthFormat.METRES_F32:
        nan = int(np.isnan(a).sum())
        if nan:
            raise ValueError(f"depth holds {nan} NaN pixel(s): mark pixels without depth with 0 "
                             "(np.nan_to_num(depth, nan=0.0)); the generator fills them")
        if np.isinf(a).any():
            raise ValueError("depth holds infinite values: depth is a distance in metres (0 = no depth)")
        if (a < 0).any():
            raise ValueError(f"depth holds negative values (min {float(a.min())}): depth is a distance in "
                             "metres (0 = no depth)")
    if not a.any():
        raise ValueError("depth has no valid pixel: every value is 0 (no depth)")
    return np.ascontiguousarray(a, dtype=le).tobytes(), fmt, w, h


def patterns_array(patterns: SlmPatterns) -> npt.NDArray[np.uint8]:
    """The SLM codes of ``patterns`` (from ``HologramGenerator.render``) as one array.

    Returns ``uint8 [3, height, width]``: the red, green and blue lasers' patterns, row-major; code ``c`` is
    the phase ``2πc/256``. A new, writable array (the bytes are copied).
    """
    h, w = patterns.height, patterns.width
    return np.stack([np.frombuffer(b, np.uint8).reshape(h, w)
                     for b in (patterns.red, patterns.green, patterns.blue)])


def render_arrays(generator: HologramGenerator, rgb: npt.NDArray[np.uint8],
                  depth: DepthArray, refine: int = 0,
                  progress: RefineProgress | None = None,
                  gaze: tuple[float, float] | tuple[float, float, float] | None = None
                  ) -> npt.NDArray[np.uint8]:
    """Renders one RGB-D frame given as numpy arrays into the three SLM patterns.

    Args:
        generator: a ``HologramGenerator``; its ``GeneratorConfig`` sets the hologram's ``width`` and
            ``height``, how the frame fits them (``fit``, default a centred crop), the display and the CNNs.
        rgb: ``uint8 [H, W, 3]`` (RGB) or ``[H, W, 4]`` (RGBA, alpha ignored) sRGB codes, upright.
        depth: ``[h, w]`` of the same field of view, ``float32`` metres or ``uint16`` millimetres (z-depth,
            larger = farther); 0 marks a pixel without depth (filled from its neighbours). It may have
            another resolution than ``rgb`` (a phone's depth is often a quarter of the colour's): it is
            resampled to the colour grid (nearest neighbour). Byte order and strides do not matter.
        refine: the photo mode: ``N > 0`` refines the patterns with N iterations of focal-stack
            optimisation warm-started from the CNN's (``generator.render_refined``, docs/REFINE.md; about
            +4 dB at 10 on real photos, seconds of work); 0 (default) renders as the camera path does.
        progress: with ``refine``, a ``RefineProgress`` whose ``on_iteration(iteration, iterations,
            psnr_db)`` hears of every iteration and returns ``False`` to cancel.
        gaze: a foveated frame (docs/FOVEATION.md; ``generator.render_foveated``): ``(x, y)`` where the
            viewer looks, in pixels of the hologram (``0, 0`` the top-left pixel's centre, x right, y down),
            or ``(x, y, depth_m)`` with an eye tracker's vergence depth in metres from the midpoint plane
            (positive towards the viewer). Needs a generator made with ``GeneratorConfig.foveation``; not
            with ``refine``. ``None`` (default): the full 3D frame.

    Returns:
        ``uint8 [3, height, width]`` at the generator's size: the red, green and blue SLM patterns (code
        ``c`` = phase ``2πc/256``), as ``patterns_array(generator.render(frame))``.

    Raises:
        TypeError: ``rgb`` or ``depth`` is not a numpy array, or has another dtype (the message names it);
            ``gaze`` is not a tuple of 2 or 3 numbers.
        ValueError: a wrong shape, an empty array, more pixels than ``max_frame_pixels()`` (refused before
            any copy), NaN, infinite or negative depths, or a depth without one valid (non-zero) pixel (the
            message names the argument).
        TensorholoError.InvalidInput: what the core refuses beyond that (e.g. a frame too large, more than
            10000 refinement iterations, a gaze outside the hologram, a generator without foveation).
        TensorholoError.Cancelled: ``progress`` returned ``False``.
    """
    if isinstance(refine, bool) or not isinstance(refine, int):
        raise TypeError(f"refine must be an int (iterations), not {type(refine).__name__}")
    if refine < 0:
        raise ValueError(f"refine must be >= 0 iterations, got {refine}")
    point = _gaze(gaze)
    if point is not None and refine:
        raise ValueError("gaze and refine cannot be combined: a refined frame is a full 3D frame")
    color, color_format, cw, ch = _color(rgb)
    data, depth_format, dw, dh = _depth(depth)
    frame = RgbdFrame(color=color, color_format=color_format, color_width=cw, color_height=ch,
                      depth=data, depth_format=depth_format, depth_width=dw, depth_height=dh)
    if refine:
        return patterns_array(generator.render_refined(frame, RefineSettings(iterations=refine), progress))
    if point is not None:
        return patterns_array(generator.render_foveated(frame, point))
    return patterns_array(generator.render(frame))


def _gaze(gaze: object) -> Gaze | None:
    """``render_arrays``'s ``gaze`` as a ``Gaze`` record (``None`` stays ``None``)."""
    if gaze is None:
        return None
    if not isinstance(gaze, (tuple, list)) or len(gaze) not in (2, 3) or not all(
            isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) for v in gaze):
        raise TypeError(f"gaze must be (x, y) or (x, y, depth_m) numbers, got {gaze!r}")
    x, y = float(gaze[0]), float(gaze[1])
    depth_m = float(gaze[2]) if len(gaze) == 3 else None
    return Gaze(x=x, y=y, depth_m=depth_m)

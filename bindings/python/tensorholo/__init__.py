"""Tensor Holography V2: RGB-D frames to 8-bit phase-only hologram patterns for an SLM.

The whole app API of the uniffi bindings (``HologramGenerator``, ``GeneratorConfig``, ``RgbdFrame``,
``SlmPatterns``, ``pack_rgba``, ``TensorholoError`` …; bindings/README.md) plus numpy in and out:

>>> import numpy as np, tensorholo as th
>>> gen = th.HologramGenerator(th.GeneratorConfig(width=512, height=384))
>>> codes = th.render_arrays(gen, rgb, depth)  # rgb uint8 [H, W, 3|4], depth float32 m / uint16 mm [h, w]
>>> codes.shape, codes.dtype                   # R, G, B SLM patterns, code c = phase 2πc/256
((3, 384, 512), dtype('uint8'))
"""

from ._uniffi.tensorholo import *  # noqa: F401,F403 (the generated bindings, typed inline)
from ._uniffi.tensorholo import __all__ as _uniffi_all
from .arrays import patterns_array, render_arrays

__all__ = _uniffi_all + ["patterns_array", "render_arrays"]

"""training/ldi_probe.py: the bar-over-wall probe of sdk/tests/generator.rs, in PyTorch."""
import os
import sys

import numpy as np
import pytest
import torch

sys.path.insert(0, os.path.abspath(os.path.join(os.path.dirname(__file__), "..")))
import ldi_probe  # noqa: E402

MODELS = os.path.join(os.path.dirname(__file__), "..", "..", "models")


def test_the_scene_differs_only_in_the_hidden_wall_behind_the_bar():
    front, both = ldi_probe.scene(5)
    assert front.shape == (20, 64, 96)
    diff = np.argwhere(front != both)
    assert set(diff[:, 0]) <= {4, 5, 6, 7}  # layer 1 only
    assert set(diff[:, 2]) == set(range(44, 52))  # behind the bar only
    assert (front[3][:, 44:52] == 0.1).all() and (both[7][:, 44:52] == 0.9).all()
    assert (front[7] == 1).all() and (front[4:7] == 0).all()  # an empty layer: amplitude 0, depth 1


def test_the_shipped_files_give_the_rust_tests_figures_and_a_cnn_that_uses_layer_1_shows_the_wall():
    ldi = ldi_probe.probe(os.path.join(MODELS, "holo8_ldi.onnx"))
    rgbd = ldi_probe.probe(os.path.join(MODELS, "holo8_rgbd.onnx"))
    # sdk/tests/generator.rs measures 0.159 for the LDI CNN either way and 0.158 for the RGB-D CNN
    assert ldi["input_layers"] == 5 and rgbd["both"] is None
    assert ldi["both"] == pytest.approx(0.159, abs=2e-3) and ldi["front"] == pytest.approx(0.159, abs=2e-3)
    assert rgbd["front"] == pytest.approx(0.158, abs=2e-3)
    # the probe can tell: a network whose first convolution adds layer 1 to layer 0 (at the bar: the wall's
    # amplitude at depth 0.1 + 0.9) shows the wall there
    net, layers, display = ldi_probe.load(os.path.join(MODELS, "holo8_ldi.onnx"))
    with torch.no_grad():
        w = net.convs[0].weight
        w[:, 4:8] = w[:, 0:4]
    front, both = ldi_probe.scene(layers)
    assert ldi_probe.ratio(net, both, display) > 1.25 * ldi_probe.ratio(net, front, display)

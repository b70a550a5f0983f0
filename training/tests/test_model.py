"""Model shapes, parameter counts, head ranges and residual wiring (paper / DESIGN.md §3)."""
import math

import pytest
import torch

from tensorholo_training.model import (
    count_parameters, hologram_cnn, macs_per_pixel, prefilter_cnn, prefilter_input, ResidualCNN,
)


def test_parameter_counts():
    counts = {}
    for layers in (8, 15, 30):
        for inputs in (1, 5):
            counts[(layers, inputs)] = count_parameters(hologram_cnn(layers, inputs))
    pre = count_parameters(prefilter_cnn())
    for (layers, inputs), n in sorted(counts.items()):
        print(f"hologram CNN {layers} layers, {'RGB-D' if inputs == 1 else 'LDI'}: {n} parameters")
    print(f"pre-filter CNN: {pre} parameters")
    # 30 layers, 24 filters, RGB-D: ≈150k (first 4→24, 28 × 24→24, last (24+4)→6, with biases)
    assert counts[(30, 1)] == 9 * 4 * 24 + 24 + 28 * (9 * 24 * 24 + 24) + 9 * 28 * 6 + 6 == 148_230
    assert abs(counts[(30, 1)] - 150_000) / 150_000 < 0.02
    assert counts[(8, 1)] < counts[(15, 1)] < counts[(30, 1)] < counts[(30, 5)]
    assert pre == 9 * 6 * 8 + 8 + 6 * (9 * 8 * 8 + 8) + 9 * 14 * 6 + 6 == 4706
    assert macs_per_pixel(hologram_cnn(30, 1)) == 147_528  # DESIGN.md §7: ~147.5k MAC per pixel


@pytest.mark.parametrize("layers,inputs", [(8, 1), (15, 1), (30, 1), (8, 5)])
def test_shapes_and_head_ranges(layers, inputs):
    net = hologram_cnn(layers, inputs)
    x = torch.rand(2, 4 * inputs, 12, 20)
    amp, phs = net(x)
    assert amp.shape == (2, 3, 12, 20) and phs.shape == (2, 3, 12, 20)
    # push the heads to saturation: ranges must hold at the extremes
    with torch.no_grad():
        for p in net.convs[-1].parameters():
            p.mul_(1e4)
    amp, phs = net(x)
    assert amp.min() >= 0 and amp.max() <= math.sqrt(2) + 1e-6
    assert phs.min() >= 0 and phs.max() <= 1
    assert amp.max() > 1.4 and amp.min() < 0.01  # saturated on both sides somewhere


def test_prefilter_io():
    pre = prefilter_cnn()
    field = torch.polar(torch.rand(1, 3, 10, 10) + 0.1, torch.rand(1, 3, 10, 10) * 6 - 3)
    x = prefilter_input(field)
    assert x.shape == (1, 6, 10, 10) and x[:, 3:].min() >= 0 and x[:, 3:].max() <= 1
    a, p = pre(x)
    assert a.shape == p.shape == (1, 3, 10, 10)


def test_residual_wiring_and_input_reinjection():
    torch.manual_seed(0)
    net = hologram_cnn(8, 1)
    seen = {}
    for i, conv in enumerate(net.convs):
        conv.register_forward_hook(lambda m, inp, out, i=i: seen.__setitem__(i, (inp[0].detach(), out.detach())))
    x = torch.rand(1, 4, 9, 9)
    net(x)
    y = {i: torch.relu(seen[i][1]) for i in range(7)}
    s = {i: seen[i][0] for i in range(8)}
    assert torch.allclose(s[0], x - 0.5)
    for i in (1, 2, 4, 6):
        assert torch.allclose(s[i], y[i - 1]), i
    for i in (3, 5):  # residual connection every two layers
        assert torch.allclose(s[i], y[i - 1] + s[i - 2]), i
    # last layer: concat(y_6 + s_5, input)
    assert s[7].shape[1] == 24 + 4
    assert torch.allclose(s[7][:, :24], y[6] + s[5])
    assert torch.allclose(s[7][:, 24:], x - 0.5)
    assert net.layer_inputs_are_residual() == [False, False, False, True, False, True, False, True]


def test_rejects_wrong_input_channels():
    with pytest.raises(ValueError, match="input channels"):
        hologram_cnn(8, 1)(torch.rand(1, 20, 8, 8))
    with pytest.raises(ValueError):
        ResidualCNN(num_layers=1)

"""Model shapes, parameter counts, head ranges and residual wiring (paper / docs/CONVENTIONS.md §7)."""
import math

import pytest
import torch

from tensorholo_training.model import (
    count_parameters, hologram_cnn, load_prefilter_state, macs_per_pixel, prefilter_cnn, prefilter_input,
    prefilter_output, ResidualCNN,
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
    assert macs_per_pixel(hologram_cnn(30, 1)) == 147_528  # ~147.5k MAC per pixel (the paper's 30-layer CNN; docs/BENCHMARKS.md)


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


def test_prefilter_input_is_cartesian():
    field = torch.polar(torch.rand(1, 3, 10, 10) + 0.1, torch.rand(1, 3, 10, 10) * 6 - 3)
    x = prefilter_input(field)
    assert x.shape == (1, 6, 10, 10) and x.dtype == torch.float32
    assert torch.equal(x[:, :3], field.real) and torch.equal(x[:, 3:], field.imag)
    assert torch.equal(prefilter_output(x[:, :3], x[:, 3:]), field)


def test_untrained_prefilter_is_exactly_its_base():
    from tensorholo_training.optics import anti_alias_blur

    g = torch.Generator().manual_seed(5)
    field = torch.polar(torch.rand(2, 3, 13, 17, generator=g) + 0.1, torch.randn(2, 3, 13, 17, generator=g))
    for sigma, size in [(0.7, 5), (1.2, 7)]:
        pre = prefilter_cnn(base="aa-dpm", sigma_px=sigma, size=size)
        out = prefilter_output(*pre(prefilter_input(field)))
        # the depthwise 2D blur of [Re, Im] is the separable complex AA-DPM blur (a linear filter)
        assert (out - anti_alias_blur(field, sigma, size)).abs().max() < 1e-6, (sigma, size)
    ident = prefilter_cnn(base="identity")
    assert torch.equal(prefilter_output(*ident(prefilter_input(field))), field)
    with pytest.raises(ValueError, match="base"):
        prefilter_cnn(base="blur")


def test_prefilter_adds_its_correction_to_the_base():
    torch.manual_seed(1)
    pre = prefilter_cnn(base="aa-dpm")
    with torch.no_grad():
        for p in pre.net.convs[-1].parameters():
            p.normal_(0, 0.1)
    x = torch.randn(1, 6, 9, 11)
    re, im = pre(x)
    want = pre.base_filter(x) + pre.net.raw(x)
    assert torch.allclose(torch.cat([re, im], 1), want, atol=1e-6)
    assert float((want - pre.base_filter(x)).abs().max()) > 1e-3  # the correction is not zero any more
    assert count_parameters(pre) == count_parameters(pre.net)  # the blur is a fixed buffer
    assert "blur" not in pre.state_dict()  # rebuilt from the configuration, not stored


def test_old_amplitude_phase_prefilter_weights_are_refused_clearly():
    old = ResidualCNN(8, 8, 6, 6).state_dict()
    with pytest.raises(ValueError, match="old amplitude/phase pre-filter"):
        load_prefilter_state(prefilter_cnn(), old, "old.pt")
    state = prefilter_cnn().state_dict()
    load_prefilter_state(prefilter_cnn(), state, "new.pt")


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

"""Loss properties: global-phase invariance, zero for identical fields, focal depth selection, stage 2."""
import math

import pytest
import torch

from tensorholo_training import losses as L
from tensorholo_training import optics as O
from tensorholo_training.model import hologram_cnn, prefilter_cnn
from tensorholo_training.optics import PropagationOptions

D = O.Display()


def fields(b=2, h=24, w=24, seed=0):
    g = torch.Generator().manual_seed(seed)
    gt = torch.polar(torch.rand(b, 3, h, w, generator=g) + 0.1, torch.randn(b, 3, h, w, generator=g))
    pred = torch.polar(torch.rand(b, 3, h, w, generator=g) + 0.1, torch.randn(b, 3, h, w, generator=g))
    depth = torch.rand(b, h, w, generator=g)
    return gt, pred, depth


@pytest.mark.parametrize("kind", ["l2", "l1"])
def test_data_fidelity_is_blind_to_a_global_phase(kind):
    gt, pred, _ = fields()
    base = L.data_fidelity_loss(pred, gt, "complex", kind)
    for c in (0.3, 2.0, -2.9):
        rotated = pred * complex(math.cos(c), math.sin(c))
        assert float(L.data_fidelity_loss(rotated, gt, "complex", kind)) == pytest.approx(float(base), rel=1e-5)
    # per-channel constants too
    per = torch.polar(torch.ones(1, 3, 1, 1), torch.tensor([0.5, -1.0, 2.5]).view(1, 3, 1, 1))
    assert float(L.data_fidelity_loss(pred * per, gt, "complex", kind)) == pytest.approx(float(base), rel=1e-5)
    assert float(L.data_fidelity_loss(gt * complex(0, 1), gt, "complex", kind)) < 1e-6
    assert float(base) > 0.1


def test_tensorholo_form_is_zero_for_rotated_gt():
    gt, _, _ = fields()
    assert float(L.data_fidelity_loss(gt * complex(math.cos(1.1), math.sin(1.1)), gt, "tensorholo")) < 1e-10


def test_focal_stack_loss_zero_for_identical_positive_otherwise():
    gt, pred, depth = fields()
    focal = L.select_focal_depths(depth, generator=torch.Generator().manual_seed(0))
    same, tv0 = L.focal_stack_loss(gt, gt.clone(), depth, focal, D)
    assert float(same) == 0.0 and float(tv0) == 0.0
    diff, tv = L.focal_stack_loss(pred, gt, depth, focal, D)
    assert float(diff) > 1e-4 and float(tv) > 1e-5
    # amplitude focal stacks ignore a global phase as well
    rot, _ = L.focal_stack_loss(gt * complex(0, 1), gt, depth, focal, D)
    assert float(rot) < 1e-10


def test_focal_depth_selection():
    depth = torch.full((1, 40, 40), 0.8)
    depth[0, :10] = 0.123
    depth[0, 10:15] = 0.5
    g = torch.Generator().manual_seed(1)
    f = L.select_focal_depths(depth, bins=200, top=15, random=5, generator=g)
    assert f.shape == (1, 20)
    assert int(f[0, 0] * 200) == int(0.8 * 200)  # most populated bin first
    assert int(f[0, 1] * 200) == int(0.123 * 200)
    assert int(f[0, 2] * 200) == int(0.5 * 200)
    assert (f >= 0).all() and (f < 1).all()
    assert len(set((f[0] * 200).long().tolist())) == 20  # distinct bins
    again = L.select_focal_depths(depth, generator=torch.Generator().manual_seed(1))
    assert torch.equal(f, again)


def test_attention_mask_peaks_at_the_focal_plane():
    depth = torch.linspace(0, 1, 50).view(1, 1, 50).expand(1, 10, 50)
    w = L.attention_masks(depth, torch.tensor([[0.3]]), 5.0)
    assert w.shape == (1, 1, 1, 10, 50)
    assert float(w.max()) == pytest.approx(1.0)
    row = w[0, 0, 0, 0]
    assert int(row.argmax()) == int(round(0.3 * 49))
    assert float(row[-1]) == pytest.approx(math.exp(-5 * (1 - 15 / 49)), rel=1e-3)


def test_layered_attention_counts_a_hidden_point_where_it_is_in_focus():
    # A near bar (depth 0.1, columns 4..8) in front of a wall (0.9) that the LDI's second layer holds behind it.
    front = torch.full((1, 6, 12), 0.9)
    front[..., 4:8] = 0.1
    depth = torch.stack([front, torch.full((1, 6, 12), 0.9)], dim=1)  # [B, L, H, W]
    valid = torch.zeros(1, 2, 6, 12, dtype=torch.uint8)
    valid[:, 0] = 1
    valid[:, 1, :, 4:8] = 1
    focal = torch.tensor([[0.9, 0.1]])
    layered = L.attention_masks(depth, focal, 5.0, valid)
    paper = L.attention_masks(front, focal, 5.0)
    # focused on the wall: the paper's mask gives the bar's pixels e^(-5·0.8); the layered one counts the
    # wall hidden there fully
    assert float(paper[0, 0, 0, 0, 5]) == pytest.approx(math.exp(-4.0), rel=1e-5)
    assert float(layered[0, 0, 0, 0, 5]) == pytest.approx(1.0)
    # focused on the bar, both masks agree: the wall beside the bar is 0.8 away either way
    assert torch.allclose(layered[:, 1], paper[:, 1])
    # invalid points are ignored: with the second layer invalid everywhere the masks are the paper's
    assert torch.allclose(L.attention_masks(depth, focal, 5.0, valid * torch.tensor([1, 0]).view(1, 2, 1, 1)),
                          paper)
    with pytest.raises(ValueError, match="valid"):
        L.attention_masks(depth, focal, 5.0)


def test_layered_focal_depths_come_from_every_valid_point():
    front = torch.full((1, 10, 10), 0.3)
    depth = torch.stack([front, torch.full((1, 10, 10), 0.7), torch.full((1, 10, 10), 0.95)], dim=1)
    valid = torch.ones(1, 3, 10, 10, dtype=torch.uint8)
    valid[:, 1, :, 5:] = 0  # the middle layer holds half the pixels
    valid[:, 2] = 0  # the back layer none: its depth never counts
    f = L.select_focal_depths(depth, bins=100, top=2, random=0, generator=torch.Generator().manual_seed(0),
                              valid=valid)
    assert sorted(int(v * 100) for v in f[0]) == [30, 70]  # the front's bin first, then the hidden layer's
    assert int(f[0, 0] * 100) == 30
    with pytest.raises(ValueError, match="valid"):
        L.select_focal_depths(depth)


def test_phase_regulariser():
    flat = torch.full((1, 3, 8, 8), 0.5)
    assert float(L.phase_regulariser(flat)) < 1e-5
    shifted = torch.full((1, 3, 8, 8), 0.6)
    assert float(L.phase_regulariser(shifted)) == pytest.approx(0.1, abs=1e-5)
    noisy = 0.5 + 0.1 * torch.randn(2, 3, 16, 16)
    assert float(L.phase_regulariser(noisy)) > 0.08


def test_stage2_chain_is_differentiable_and_close_to_gt_for_smooth_fields():
    torch.manual_seed(0)
    net, pre = hologram_cnn(8, 1), prefilter_cnn()
    rgbd = torch.rand(1, 4, 24, 24)
    amp, phs = net(rgbd)
    out = L.ddpm_forward(amp, phs, pre, 6e-3, D)
    gt, _, depth = fields(b=1)
    loss = L.stage2_loss(out, gt, depth, D, generator=torch.Generator().manual_seed(0))
    loss["total"].backward()
    grads = [p.grad for p in list(net.parameters()) + list(pre.parameters())]
    assert all(g is not None and torch.isfinite(g).all() for g in grads)
    assert any(float(g.abs().max()) > 0 for g in grads[-4:])  # the pre-filter learns too
    # Without a pre-filter at 0 mm, a smooth hologram survives DPM + filter nearly unchanged.
    yy, xx = torch.meshgrid(torch.linspace(-1, 1, 32), torch.linspace(-1, 1, 32), indexing="ij")
    a = (0.6 + 0.3 * torch.cos(2 * xx) * torch.cos(yy)).expand(1, 3, 32, 32)
    p = (0.5 + 0.1 * torch.sin(2 * yy)).expand(1, 3, 32, 32)
    dd = L.ddpm_forward(a, p, None, 0.0, D)
    rel = ((dd.post_midpoint.abs() - a).abs().max() / a.max()).item()
    assert rel < 0.1, rel


def _blur_numpy(field, sigma, size):
    """Reference AA-DPM blur: separable Gaussian, edge pixels replicated (the SDK's `blur_separable`)."""
    import numpy as np

    r = size // 2
    k = np.exp(-np.arange(-r, r + 1) ** 2 / (2 * sigma * sigma))
    k /= k.sum()
    f = np.pad(field, [(0, 0)] * (field.ndim - 2) + [(r, r), (r, r)], mode="edge")
    h, w = field.shape[-2:]
    rows = sum(k[j] * f[..., :, j:j + w] for j in range(size))
    return sum(k[j] * rows[..., j:j + h, :] for j in range(size))


def test_anti_alias_blur_matches_a_numpy_reference_and_keeps_constants():
    g = torch.Generator().manual_seed(3)
    field = torch.polar(torch.rand(2, 3, 13, 17, generator=g) + 0.1, torch.randn(2, 3, 13, 17, generator=g))
    for sigma, size in [(0.7, 5), (1.5, 7), (0.3, 1)]:
        got = O.anti_alias_blur(field, sigma, size).numpy()
        want = _blur_numpy(field.numpy().astype("complex128"), sigma, size)
        assert abs(got - want).max() < 1e-5, (sigma, size)
    # Replicated edges: a constant field stays constant, and the blur conserves a delta's energy in the middle.
    const = torch.full((1, 1, 9, 9), 0.3 - 0.4j, dtype=torch.complex64)
    assert torch.allclose(O.anti_alias_blur(const), const, atol=1e-6)
    delta = torch.zeros(1, 1, 11, 11, dtype=torch.complex64)
    delta[..., 5, 5] = 1.0
    assert abs(O.anti_alias_blur(delta).sum().item() - 1.0) < 1e-5
    with pytest.raises(ValueError):
        O.anti_alias_blur(field, 0.7, 4)


def test_ddpm_with_an_untrained_aa_prefilter_is_aa_dpm():
    """The chain with a fresh AA-based pre-filter equals double phase of the blurred SLM field (AA-DPM)."""
    g = torch.Generator().manual_seed(4)
    amp = 0.2 + torch.rand(1, 3, 16, 16, generator=g)
    phs = torch.rand(1, 3, 16, 16, generator=g)
    dd = L.ddpm_forward(amp, phs, prefilter_cnn(base="aa-dpm"), 6e-3, D)
    slm = O.offset_to_slm(O.amp_phase_to_complex(amp, phs), 6e-3, D, PropagationOptions(pad=True))
    blurred = O.anti_alias_blur(slm)
    assert torch.allclose(O.amp_phase_to_complex(dd.pre_amplitude, dd.pre_phase01), blurred, atol=1e-5)
    dp = O.double_phase_encode(blurred, wrap=False, clamp_eps=1e-6)
    assert torch.allclose(dd.phase, dp.phase, atol=1e-4)
    plain = L.ddpm_forward(amp, phs, None, 6e-3, D)
    assert float((plain.phase - dd.phase).abs().max().detach()) > 1e-2  # the blur changes the encoding

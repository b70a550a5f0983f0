"""Properties of the torch optics that do not need fixtures."""
import math

import numpy as np
import torch

from tensorholo_training import optics as O

D = O.Display()


def smooth(c=3, h=24, w=40, seed=0):
    g = torch.Generator().manual_seed(seed)
    a = 0.3 + torch.rand(c, h, w, generator=g)
    p = torch.cumsum(torch.randn(c, h, w, generator=g) * 0.2, dim=-1)
    return torch.polar(a, p)


def test_asm_forward_then_back_is_identity():
    f = smooth()
    for carrier in ("keep", "remove"):
        there = O.propagate(f, 3e-3, D.wavelengths_m, D.pixel_pitch_m, carrier)
        back = O.propagate(there, -3e-3, D.wavelengths_m, D.pixel_pitch_m, carrier)
        assert (there - f).abs().max() > 0.05
        assert (back - f).abs().max() < 1e-4, carrier


def test_carrier_removal_is_a_constant_phase_per_colour():
    f = smooth()
    keep = O.propagate(f, 2e-3, D.wavelengths_m, D.pixel_pitch_m, "keep")
    remove = O.propagate(f, 2e-3, D.wavelengths_m, D.pixel_pitch_m, "remove")
    for c, lam in enumerate(D.wavelengths_m):
        ph = -2 * math.pi * 2e-3 / lam
        expected = keep[c] * complex(math.cos(ph), math.sin(ph))
        assert (expected - remove[c]).abs().max() < 1e-4


def test_transfer_function_zeroes_evanescent_waves():
    # pitch below λ/2 makes the outer frequencies evanescent
    tf = O.transfer_function(16, 16, 0.2e-6, [638e-9], 1e-6)
    assert (tf.abs() == 0).any() and tf.abs().max() <= 1.0 + 1e-6
    assert tf[0, 0, 0].abs() == 1.0


def test_double_phase_pairs_average_to_the_normalised_field():
    f = smooth(h=8, w=8)
    dp = O.double_phase_encode(f)
    a = float(dp.amplitude_scale)
    plus = torch.polar(torch.ones(()), dp.phase)
    # neighbours along x have opposite parity: (e^{i(φ+θ)} + e^{i(φ−θ)})/2 = Ã e^{iφ} when φ, Ã agree
    theta = torch.acos((f.abs() / a).clamp(max=1))
    phi = torch.atan2(f.imag, f.real) - dp.mean_phase[:, None, None]
    avg = (torch.polar(torch.ones(()), phi + theta) + torch.polar(torch.ones(()), phi - theta)) / 2
    assert (avg - torch.polar(f.abs() / a, phi)).abs().max() < 1e-5
    odd = O.checkerboard(8, 8)
    expected = torch.where(odd, phi - theta, phi + theta)
    assert (plus - torch.polar(torch.ones(()), expected)).abs().max() < 1e-4


def test_double_phase_is_differentiable_when_clamped():
    f = smooth(h=16, w=16).requires_grad_(False)
    x = f.clone().requires_grad_(True)
    dp = O.double_phase_encode(x, wrap=False, clamp_eps=1e-6)
    post = O.simulate_phase_only(dp.phase, 6e-3, D, O.PropagationOptions(pad=True))
    (post.abs() ** 2).mean().backward()
    assert torch.isfinite(torch.view_as_real(x.grad)).all()


def test_wrap_phase_range_and_values():
    v = torch.tensor([-3 * math.pi, -1e-9, 0.0, 2 * math.pi, 7.0, 40.0, -40.0])
    w = O.wrap_phase(v)
    assert (w >= 0).all() and (w < 2 * math.pi).all()
    assert np.allclose(np.exp(1j * w.numpy()), np.exp(1j * v.numpy()), atol=1e-5)


def test_aperture_radius_is_half_the_smaller_side():
    m = O.aperture_mask(20, 30)
    assert m[0, 10] == 1 and m[0, 11] == 0  # kx = 10 = r passes, 11 does not
    assert m[10, 0] == 1 and m[-10, 0] == 1
    padded = O.aperture_mask(20, 30, pad=True)
    assert int(padded.sum()) > int(m.sum()) * 3  # same physical disc on a 4x finer spectral grid


def test_focal_stack_of_a_midpoint_refocuses_a_plane():
    # A sharp square propagated from z(d) to the midpoint refocuses at d.
    sq = torch.zeros(3, 48, 48, dtype=torch.complex64)
    sq[:, 20:28, 20:28] = 1
    d = 0.2
    mid = O.propagate(sq, -D.depth_to_z(d), D.wavelengths_m, D.pixel_pitch_m, "remove", O.PropagationOptions(pad=True))
    stack = O.focal_stack(mid[None], [0.0, d, 0.9], D, 0.0, O.PropagationOptions(pad=True))[0]
    errs = [(s - sq.abs()).abs().mean().item() for s in stack]
    assert errs[1] < 1e-4 and errs[0] > 1e-2 and errs[2] > 1e-2

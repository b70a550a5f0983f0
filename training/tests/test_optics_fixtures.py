"""Torch optics vs fixtures written by `holo propagate` / `holo encode` (tests/fixtures/make_fixtures.sh).

Tolerances: fields 1e-4 relative to the field's maximum (measured ~2e-7 for ASM, ~5e-5 after double phase);
double-phase pattern 1e-3 rad circular, because acos has infinite slope at the maximum pixel (Ã = 1), where one
float32 rounding of |H|/a moves the phase by ~3e-4 rad (measured max 1.4e-4 rad).
"""
import json
import os

import numpy as np
import pytest
import torch

from tensorholo_training import optics as O

D = O.Display()
REL = 1e-4

PROPAGATE = [
    ("keep_2mm", "field_a", 2e-3, "keep", O.PropagationOptions()),
    ("keep_m3mm_pad", "field_a", -3e-3, "keep", O.PropagationOptions(pad=True)),
    ("remove_6mm_pad_bl", "field_a", 6e-3, "remove", O.PropagationOptions(pad=True, band_limit=True)),
    ("remove_m12mm_bl", "field_a", -12e-3, "remove", O.PropagationOptions(band_limit=True)),
    ("odd_keep_1p5mm_pad", "field_odd", 1.5e-3, "keep", O.PropagationOptions(pad=True)),
]

ENCODE = [
    ("dpm_0mm", "field_a", 0.0, O.PropagationOptions()),
    ("dpm_6mm_pad", "field_a", 6e-3, O.PropagationOptions(pad=True)),
    ("dpm_m12mm_bl_odd", "field_odd", -12e-3, O.PropagationOptions(band_limit=True)),
]


def load(fixtures_dir, name):
    return np.load(os.path.join(fixtures_dir, name))


def rel_err(got, want):
    got, want = np.asarray(got), np.asarray(want)
    return float(np.abs(got - want).max() / np.abs(want).max())


@pytest.mark.parametrize("name,field,z,carrier,opts", PROPAGATE, ids=[p[0] for p in PROPAGATE])
def test_propagate_matches_holo(fixtures_dir, name, field, z, carrier, opts):
    f = torch.from_numpy(load(fixtures_dir, f"{field}.npy"))
    got = O.propagate(f, z, D.wavelengths_m, D.pixel_pitch_m, carrier, opts)
    err = rel_err(got.numpy(), load(fixtures_dir, f"prop/{name}.npy"))
    print(f"{name}: max relative error {err:.2e}")
    assert err < REL


@pytest.mark.parametrize("name,field,offset,opts", ENCODE, ids=[e[0] for e in ENCODE])
def test_encode_matches_holo(fixtures_dir, name, field, offset, opts):
    d = os.path.join(fixtures_dir, "enc", name)
    meta = json.load(open(os.path.join(d, "encode.json")))
    assert meta["offset_m"] == pytest.approx(offset) and meta["propagation"]["pad"] == opts.pad
    f = torch.from_numpy(load(fixtures_dir, f"{field}.npy"))
    slm = O.offset_to_slm(f, offset, D, opts)
    if offset != 0.0:
        assert rel_err(slm.numpy(), np.load(os.path.join(d, "slm_field.npy"))) < REL
    dp = O.double_phase_encode(slm)
    want = np.load(os.path.join(d, "phase.npy"))
    circ = np.abs(np.angle(np.exp(1j * (dp.phase.numpy().astype(np.float64) - want))))
    print(f"{name}: phase max circular error {circ.max():.2e} rad")
    assert circ.max() < 1e-3
    assert dp.phase.min() >= 0 and dp.phase.max() < 2 * np.pi
    assert float(dp.amplitude_scale) == pytest.approx(meta["amplitude_scale"], rel=1e-6)
    np.testing.assert_allclose(dp.mean_phase.numpy(), meta["mean_phase_rad"], atol=1e-6)
    # Simulate the holo pattern itself, so that the comparison isolates filter + back-propagation.
    post = O.simulate_phase_only(torch.from_numpy(want), offset, D, opts)
    err = rel_err(post.numpy(), np.load(os.path.join(d, "post_midpoint.npy")))
    print(f"{name}: post-encoding midpoint max relative error {err:.2e}")
    assert err < REL
    stack = O.focal_stack(post[None], meta["depths"], D, 0.0, opts)[0]
    assert rel_err(stack.numpy(), np.load(os.path.join(d, "focal_stack.npy"))) < REL
    target = O.focal_stack(f[None], meta["depths"], D, 0.0, opts)[0]
    assert rel_err(target.numpy(), np.load(os.path.join(d, "target_focal_stack.npy"))) < REL
    # And the whole torch chain from the torch pattern (as training runs it).
    post_torch = O.simulate_phase_only(dp.phase, offset, D, opts)
    assert rel_err(post_torch.numpy(), np.load(os.path.join(d, "post_midpoint.npy"))) < 5 * REL


def test_fixtures_stay_small(fixtures_dir):
    total = sum(os.path.getsize(os.path.join(r, f)) for r, _, fs in os.walk(fixtures_dir) for f in fs)
    assert total < 1_000_000, total

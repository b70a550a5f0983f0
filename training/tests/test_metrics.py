"""Torch PSNR/SSIM against the scikit-image fixture shared with the SDK (sdk/tests/fixtures)."""
import json
import os

import numpy as np
import pytest
import torch

from tensorholo_training.metrics import psnr, ssim

FIXTURE = os.path.join(os.path.dirname(__file__), "..", "..", "sdk", "tests", "fixtures", "metrics_fixture.json")


@pytest.mark.skipif(not os.path.exists(FIXTURE), reason="SDK metrics fixture not in this checkout")
def test_matches_scikit_image_fixture():
    v = json.load(open(FIXTURE))
    denom = v["denominator"]
    checked = 0
    for c in v["cases"]:
        shape = c["shape"]
        ref = torch.tensor(np.array(c["reference"], np.float64) / denom).float().view(shape)
        test = torch.tensor(np.array(c["test"], np.float64) / denom).float().view(shape)
        stack = (lambda t: t[None, None]) if len(shape) == 2 else (lambda t: t[None])
        r, t = stack(ref), stack(test)
        if np.isfinite(c["psnr"]):
            assert float(psnr(r, t, c["data_range"])[0]) == pytest.approx(c["psnr"], abs=1e-3), c["name"]
        if min(shape[-2:]) >= 11:
            assert float(ssim(r, t, c["data_range"])[0]) == pytest.approx(c["ssim"], abs=1e-5), c["name"]
            checked += 1
    assert checked > 0

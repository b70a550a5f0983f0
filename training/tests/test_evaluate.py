"""Table 2 protocol: metrics on the same scenes for the model and a baseline hook."""

import numpy as np
import pytest
import torch

from tensorholo_training.data import LdiDataset
from tensorholo_training.evaluate import cnn_predictor, evaluate, npy_baseline
from tensorholo_training.model import hologram_cnn


def test_protocol_with_model_and_npy_baseline(tmp_path, tiny_dataset):
    ds = LdiDataset(tiny_dataset, "val")
    folder = tmp_path / "baseline"
    folder.mkdir()
    for i in range(len(ds)):  # a "baseline" that is the ground truth with a little noise
        gt = ds[i]["midpoint"].numpy()
        noise = 0.01 * np.random.default_rng(i).standard_normal(gt.shape)
        np.save(folder / f"{i:05d}.npy", (gt + noise).astype(np.complex64))
    torch.manual_seed(0)
    report = evaluate(ds, {"model": cnn_predictor(hologram_cnn(8, 1)), "noisy_gt": npy_baseline(str(folder))},
                      limit=2)
    assert report["scenes"] == 2
    m, b = report["model"]["mean"], report["noisy_gt"]["mean"]
    assert set(m) == {"psnr_amp", "ssim_amp", "psnr_fs", "ssim_fs"}
    assert b["psnr_amp"] > 35 and b["psnr_fs"] > 35 and b["ssim_amp"] > m["ssim_amp"]
    assert len(report["model"]["per_scene"]) == 2
    with pytest.raises(FileNotFoundError):
        npy_baseline(str(tmp_path / "nothing"))(0, ds[0])

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


def test_onnx_predictor_with_an_aa_prefilter_file_equals_aa_dpm(tmp_path, tiny_dataset):
    """The displayed hologram through an exported (untrained, AA-based) pre-filter file equals ``aa_dpm=True``
    (the blur alone), and differs from plain double phase: the ONNX pre-filter's (real, imag) outputs are read
    as the filtered field."""
    from tensorholo_training.evaluate import onnx_predictor
    from tensorholo_training.export import export_onnx, model_metadata
    from tensorholo_training.model import prefilter_cnn

    common = dict(wavelengths_m=[638e-9, 520e-9, 450e-9], pixel_pitch_m=8e-6, volume_depth_m=6e-3, offset_m=6e-3,
                  input_layers=1, trained_resolution=[16, 16], training_commit="t")
    torch.manual_seed(0)
    net, pre = hologram_cnn(8, 1).eval(), prefilter_cnn(base="aa-dpm").eval()
    holo = export_onnx(net, str(tmp_path / "h.onnx"), "hologram-cnn", model_metadata("hologram-cnn", net, **common))
    pre_path = export_onnx(pre, str(tmp_path / "p.onnx"), "prefilter-cnn",
                           model_metadata("prefilter-cnn", pre, **common))
    item = LdiDataset(tiny_dataset, "val")[0]
    file_pre = onnx_predictor(holo, pre_path, 6e-3, phase_only=True)(0, item)
    aa = onnx_predictor(holo, None, 6e-3, phase_only=True, aa_dpm=True)(0, item)
    dpm = onnx_predictor(holo, None, 6e-3, phase_only=True)(0, item)
    assert (file_pre - aa).abs().max() < 1e-4
    assert (dpm - aa).abs().max() > 1e-2

"""Quantisation-aware fine-tuning: the fake-quantised network computes what the exporter's int8 QDQ file does."""
import numpy as np
import onnx
import pytest
import torch
from onnx import numpy_helper

from tensorholo_training import qat
from tensorholo_training.export import export_onnx, exporter_grids, quantize_int8, run_onnx

from test_export import meta, slm_like, trained_like_prefilter


def quantize_linear_grids(path):
    """The u8 grid of every QuantizeLinear of a QDQ file, in graph order (one per convolution input)."""
    m = onnx.load(path)
    inits = {i.name: numpy_helper.to_array(i) for i in m.graph.initializer}
    return [(float(inits[n.input[1]]), int(inits[n.input[2]])) for n in m.graph.node if n.op_type == "QuantizeLinear"]


def file_grids(path):
    return [(g.scale, g.zero_point) for g in qat.file_grids(path)]


def test_file_grids_follow_each_convolution_and_refuse_a_float_file(tmp_path):
    net = trained_like_prefilter()
    path = export_onnx(net, str(tmp_path / "f32.onnx"), "prefilter-cnn", meta(net, "prefilter-cnn"))
    calib = [slm_like(32, 32, 10 + i) for i in range(4)]
    q = quantize_int8(path, str(tmp_path / "q.onnx"), calib, "qdq")
    assert file_grids(q) == quantize_linear_grids(q) and len(file_grids(q)) == 8
    with pytest.raises(ValueError, match="not a dequantised tensor"):
        qat.file_grids(path)
    # the grids of a percentile calibration are the file's of that method, and no wider than MinMax's
    pct = exporter_grids(net, "prefilter-cnn", calib, "percentile")
    q_pct = quantize_int8(path, str(tmp_path / "p.onnx"), calib, "qdq", calib_method="percentile")
    assert [(g.scale, g.zero_point) for g in pct] == file_grids(q_pct)
    assert all(p.scale <= s * (1 + 1e-6) for p, (s, _) in zip(pct, file_grids(q)))


@pytest.mark.parametrize("kind", ["hologram", "prefilter"])
def test_fake_quantisation_computes_the_exporters_int8_file(tmp_path, kind):
    if kind == "prefilter":
        net = trained_like_prefilter()
        calib = [slm_like(32, 32, 10 + i) for i in range(6)]
        x = slm_like(24, 28, 99)
        outputs = lambda n, t: torch.cat(n(t), 1)  # noqa: E731
    else:
        from tensorholo_training.model import hologram_cnn

        torch.manual_seed(4)
        net = hologram_cnn(8, 1).eval()
        rng = np.random.default_rng(3)
        calib = [rng.random((1, 4, 32, 32), dtype=np.float32) for _ in range(6)]
        x = rng.random((1, 4, 24, 28), dtype=np.float32)
        outputs = lambda n, t: torch.cat(n(t), 1)  # noqa: E731
    name = f"{kind}-cnn" if kind == "hologram" else "prefilter-cnn"
    path = export_onnx(net, str(tmp_path / "f32.onnx"), name, meta(net, name))
    q = quantize_int8(path, str(tmp_path / "q.onnx"), calib, "qdq")
    grids = exporter_grids(net, name, calib)
    assert len(grids) == len(qat.learned_convs(net)) and [(g.scale, g.zero_point) for g in grids] == file_grids(q)
    state = {k: v.clone() for k, v in net.state_dict().items()}
    t = torch.from_numpy(x)
    with torch.no_grad():
        f32 = outputs(net, t).numpy()
        qat.fake_quantise(net, grids)
        fq = outputs(net, t).numpy()
    int8 = np.concatenate(run_onnx(q, x, exact=True), 1)
    far, near = np.abs(f32 - int8).mean(), np.abs(fq - int8).mean()
    print(f"{kind}: |f32 − int8 file| {far:.2e}, |fake-quantised − int8 file| {near:.2e}")
    # the fake quantisation computes the file's roundings, not merely similar ones: measured 10× (hologram CNN)
    # and 30× (pre-filter) closer to the file than the float network is
    assert near < 0.2 * far
    assert net.state_dict().keys() == state.keys()  # parameters untouched in form (checkpoints, export)
    assert all(torch.equal(net.state_dict()[k], v) for k, v in state.items())
    qat.remove_fake_quantisation(net)
    with torch.no_grad():
        assert np.array_equal(outputs(net, t).numpy(), f32)
    with pytest.raises(ValueError, match="grids"):
        qat.fake_quantise(net, grids[:-1])


def test_fake_quantised_weights_are_s8_per_output_channel_with_straight_through_gradients():
    w = torch.randn(6, 4, 3, 3, requires_grad=True)
    wq = qat.fake_quantised_weight(w)
    scale = w.detach().abs().flatten(1).amax(1) / 127
    codes = wq.detach() / scale[:, None, None, None]
    assert torch.allclose(codes, codes.round(), atol=1e-4) and codes.abs().max() <= 127 + 1e-4
    assert (wq.detach() - w.detach()).abs().max() <= 0.5 * scale.max() + 1e-7
    wq.sum().backward()
    assert torch.equal(w.grad, torch.ones_like(w))


def test_a_qat_run_rounds_on_the_grids_of_an_exported_int8_file_and_exports_int8_files_only(tmp_path, tiny_dataset):
    from tensorholo_training.export import main, read_metadata
    from tensorholo_training.train import TrainConfig, Trainer

    base = dict(dataset=tiny_dataset, num_layers=8, channels=12, crop=[16, 16], fs_top=3, fs_random=2,
                offset_mm=6.0, stage2_train_hologram=False, val_every=100, ckpt_every=100, seed=2)
    first = TrainConfig(run_dir=str(tmp_path / "f32"), stages=["stage1", "stage2"], stage1_steps=2,
                        stage2_steps=1, **base)
    Trainer(first, log=lambda m: None).run()
    calib = ["--calib-samples", "4", "--calib-size", "16"]
    grids_file = tmp_path / "grids" / "pre6.int8-qdq.onnx"
    assert main(["--checkpoint", str(tmp_path / "f32" / "final.pt"), "--out-dir", str(tmp_path / "grids"),
                 "--name", "pre6", "--prefilter-only", "--int8-only", *calib]) == 0
    cfg = TrainConfig(run_dir=str(tmp_path / "qat"), stages=["stage2"], stage2_steps=2,
                      init_from=str(tmp_path / "f32" / "final.pt"), qat_grids_from=str(grids_file), **base)
    tr = Trainer(cfg, log=lambda m: None)
    assert tr.prefilter.net.activation_quant is not None  # the pre-filter computes the int8 roundings
    assert tr.net.activation_quant is None  # the frozen hologram CNN stays float
    tr.run()
    out = tmp_path / "models"
    assert main(["--checkpoint", str(tmp_path / "qat" / "final.pt"), "--out-dir", str(out), "--name", "pre6",
                 "--prefilter-only", "--int8-only", *calib]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["pre6.int8-qdq.onnx", "pre6.int8-qop.onnx"]
    meta = read_metadata(str(out / "pre6.int8-qdq.onnx"))
    assert meta["tensorholo.kind"] == "prefilter-cnn" and meta["tensorholo.int8_weights"] == "quantisation-aware"
    # the input grid does not depend on the pre-filter's weights: the run rounded on the file's own
    assert file_grids(str(out / "pre6.int8-qdq.onnx"))[0] == pytest.approx(file_grids(str(grids_file))[0], rel=1e-5)
    with pytest.raises(ValueError, match="qat_grids_from needs a pre-filter"):
        Trainer(TrainConfig(run_dir=str(tmp_path / "x"), stages=["stage1"], qat_grids_from=str(grids_file),
                            **{**base, "offset_mm": 0.0}), log=lambda m: None)

def test_bias_correction_brings_the_int8_network_closer_to_the_f32_one_on_other_inputs():
    net = trained_like_prefilter()
    calib = [slm_like(24, 24, 40 + i) for i in range(8)]
    held_out = [slm_like(24, 24, 80 + i) for i in range(8)]
    grids = exporter_grids(net, "prefilter-cnn", calib)
    corrected = qat.bias_correction(net, grids, calib)
    # only biases change, and the returned network is float
    assert corrected.net.activation_quant is None
    for c, f in zip(qat.learned_convs(corrected), qat.learned_convs(net)):
        assert torch.equal(c.weight, f.weight)
    assert any(not torch.equal(c.bias, f.bias) for c, f in zip(qat.learned_convs(corrected), qat.learned_convs(net)))

    def int8_error(candidate):
        import copy

        q = copy.deepcopy(candidate)
        qat.fake_quantise(q, grids)
        with torch.no_grad():
            return float(np.mean([(torch.cat(q(torch.from_numpy(x)), 1) - torch.cat(net(torch.from_numpy(x)), 1))
                                  .pow(2).mean() for x in held_out]))

    before, after = int8_error(net), int8_error(corrected)
    print(f"int8 vs f32 on held-out inputs, mse: rounded {before:.3e}, bias-corrected {after:.3e}")
    assert after < 0.9 * before


def test_export_bias_correction_changes_only_the_biases_of_the_int8_files(tmp_path, tiny_dataset):
    from tensorholo_training.export import main, read_metadata
    from tensorholo_training.train import TrainConfig, Trainer

    cfg = TrainConfig(run_dir=str(tmp_path / "run"), dataset=tiny_dataset, num_layers=8, channels=12, crop=[16, 16],
                      fs_top=3, fs_random=2, stages=["stage1", "stage2"], stage1_steps=1, stage2_steps=1,
                      offset_mm=6.0, stage2_train_hologram=False, val_every=100, ckpt_every=100)
    Trainer(cfg, log=lambda m: None).run()
    common = ["--checkpoint", str(tmp_path / "run" / "final.pt"), "--name", "pre6", "--prefilter-only",
              "--int8-only", "--calib-samples", "4", "--calib-size", "16"]
    assert main([*common, "--out-dir", str(tmp_path / "plain")]) == 0
    assert main([*common, "--out-dir", str(tmp_path / "bc"), "--bias-correction"]) == 0

    def inits(path):
        return {i.name: numpy_helper.to_array(i) for i in onnx.load(path).graph.initializer}

    plain, bc = inits(str(tmp_path / "plain" / "pre6.int8-qdq.onnx")), inits(str(tmp_path / "bc" / "pre6.int8-qdq.onnx"))
    assert plain.keys() == bc.keys()
    changed = {k for k in plain if plain[k].shape != bc[k].shape or not np.array_equal(plain[k], bc[k])}
    assert changed and all("bias" in k or "scale" in k or "zero_point" in k for k in changed)
    assert not any("weight_quantized" in k for k in changed)  # the s8 weight codes are the same
    assert read_metadata(str(tmp_path / "bc" / "pre6.int8-qdq.onnx"))["tensorholo.int8_weights"] == "bias-corrected"
    assert read_metadata(str(tmp_path / "plain" / "pre6.int8-qdq.onnx"))["tensorholo.int8_weights"] == "f32-file"

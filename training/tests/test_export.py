"""ONNX export round trip (f32 and int8) and metadata (docs/CONVENTIONS.md §7)."""
import json
import numpy as np
import onnx
import pytest
import torch

from tensorholo_training.export import (
    export_onnx, frame_calibration_inputs, load_onnx_network, model_metadata, quantize_int8, read_metadata,
    run_onnx,
)
from tensorholo_training.model import hologram_cnn, prefilter_cnn, prefilter_input

KEYS = ["kind", "layers", "wavelengths_m", "pixel_pitch_m", "volume_depth_m", "offset_m", "input_layers",
        "trained_resolution", "training_commit"]

# int8 tolerance: weights (per output channel) and activations (per tensor) are quantised to 8 bits; on random-init networks the heads
# move by up to a few percent of their range. Mean |error| must stay below 0.01 and max below 0.1 (amplitude
# range √2, phase range 1); measured ≈0.001 mean, ≈0.05 max.
INT8_MEAN, INT8_MAX = 0.01, 0.1


def meta(net, kind="hologram-cnn"):
    return model_metadata(kind, net, [638e-9, 520e-9, 450e-9], 8e-6, 6e-3, 6e-3, 1, [384, 384], "abc123")


def rgbd_calib(seed, count=4):
    """``count`` random RGB-D calibration inputs ``[1, 4, 32, 32]``."""
    rng = np.random.default_rng(seed)
    return [rng.random((1, 4, 32, 32), dtype=np.float32) for _ in range(count)]


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    torch.manual_seed(0)
    net = hologram_cnn(8, 1).eval()
    d = tmp_path_factory.mktemp("onnx")
    path = export_onnx(net, str(d / "holo8.onnx"), "hologram-cnn", meta(net))
    return net, path, d


def test_f32_round_trip_with_symbolic_size(exported):
    net, path, _ = exported
    m = onnx.load(path)
    onnx.checker.check_model(m)
    assert m.opset_import[0].version == 17
    assert [i.name for i in m.graph.input] == ["rgbd"] and [o.name for o in m.graph.output] == ["amplitude", "phase"]
    dims = [d.dim_param or d.dim_value for d in m.graph.input[0].type.tensor_type.shape.dim]
    assert dims == [1, 4, "H", "W"]
    for h, w in ((24, 40), (37, 19)):
        x = np.random.default_rng(h).random((1, 4, h, w), dtype=np.float32)
        with torch.no_grad():
            a, p = net(torch.from_numpy(x))
        oa, op = run_onnx(path, x)
        err = max(np.abs(oa - a.numpy()).max(), np.abs(op - p.numpy()).max())
        print(f"f32 ONNX vs PyTorch at {h}x{w}: max abs error {err:.1e}")
        assert err < 1e-5


def test_metadata_present(exported):
    _, path, _ = exported
    md = read_metadata(path)
    for k in KEYS:
        assert "tensorholo." + k in md, k
    assert md["tensorholo.kind"] == "hologram-cnn" and md["tensorholo.layers"] == "8"
    assert [float(v) for v in md["tensorholo.wavelengths_m"].split(",")] == [638e-9, 520e-9, 450e-9]
    assert md["tensorholo.trained_resolution"] == "384x384" and md["tensorholo.precision"] == "f32"


@pytest.mark.parametrize("fmt", ["qoperator", "qdq"])
def test_int8_round_trip(exported, fmt):
    net, path, d = exported
    rng = np.random.default_rng(1)
    calib = [rng.random((1, 4, 32, 32), dtype=np.float32) for _ in range(8)]
    out = quantize_int8(path, str(d / f"holo8.{fmt}.onnx"), calib, fmt)
    nodes = onnx.load(out).graph.node
    ops = {n.op_type for n in nodes}
    convs = [n for n in nodes if n.op_type in ("Conv", "QLinearConv")]
    if fmt == "qoperator":
        # every convolution int8 but the last, whose output (the heads' input) a QLinearConv would round
        assert [n.op_type for n in convs] == ["QLinearConv"] * 7 + ["Conv"] and "QLinearAdd" not in ops
    else:
        assert "QuantizeLinear" in ops and "DequantizeLinear" in ops and "QLinearConv" not in ops
        # activations are rounded where a convolution reads them, never a convolution's raw output
        quantised = {n.input[0] for n in nodes if n.op_type == "QuantizeLinear"}
        assert len(convs) == 8 and not quantised & {c.output[0] for c in convs}
    assert "Add" in ops  # residual additions stay float (tract 0.23 has no QLinearAdd)
    md = read_metadata(out)
    assert md["tensorholo.precision"].startswith("int8") and md["tensorholo.kind"] == "hologram-cnn"
    x = rng.random((1, 4, 28, 36), dtype=np.float32)
    with torch.no_grad():
        a, p = net(torch.from_numpy(x))
    oa, op = run_onnx(out, x, exact=True)
    errs = np.concatenate([np.abs(oa - a.numpy()).ravel(), np.abs(op - p.numpy()).ravel()])
    print(f"int8 {fmt}: mean abs error {errs.mean():.4f}, max {errs.max():.4f}")
    assert errs.mean() < INT8_MEAN and errs.max() < INT8_MAX


@pytest.mark.parametrize("per_channel", [True, False])
def test_int8_weight_scales_per_output_channel_or_per_tensor(exported, per_channel):
    net, path, d = exported
    out = quantize_int8(path, str(d / f"holo8.pc{per_channel}.onnx"), rgbd_calib(1), "qdq", per_channel=per_channel)
    model = onnx.load(out)
    inits = {i.name: onnx.numpy_helper.to_array(i) for i in model.graph.initializer}
    convs = [c for c in net.modules() if isinstance(c, torch.nn.Conv2d)]
    weights = [n for n in model.graph.node if n.op_type == "DequantizeLinear" and inits.get(n.input[0]) is not None
               and inits[n.input[0]].dtype == np.int8]
    assert len(weights) == len(convs)
    for n, conv in zip(weights, convs):
        q, scale = inits[n.input[0]], inits[n.input[1]]
        w = conv.weight.detach().numpy()
        if per_channel:
            axis = {a.name: a.i for a in n.attribute}.get("axis", 1)
            assert axis == 0 and scale.shape == (w.shape[0],)
            # symmetric MinMax per channel: each channel's largest weight maps to ±127
            np.testing.assert_allclose(scale, np.abs(w).reshape(w.shape[0], -1).max(1) / 127, rtol=1e-5)
            assert (np.abs(q).reshape(w.shape[0], -1).max(1) == 127).all()
        else:
            assert scale.size == 1
            np.testing.assert_allclose(scale.item(), np.abs(w).max() / 127, rtol=1e-5)
        deq = q.astype(np.float32) * (scale.reshape(-1, 1, 1, 1) if per_channel else scale)
        assert np.abs(deq - w).max() <= 0.5 * scale.max() * 1.001
    assert read_metadata(out)["tensorholo.int8_weight_scales"] == (
        "per-output-channel" if per_channel else "per-tensor")


def test_frame_calibration_inputs_crop_real_frames_and_pad_an_ldi(tmp_path):
    rng = np.random.default_rng(3)
    frame = rng.random((4, 40, 50), dtype=np.float32)
    np.save(tmp_path / "f.npy", frame)
    crops = frame_calibration_inputs([str(tmp_path / "f.npy")], 1, 3, 16)
    assert len(crops) == 3 and all(c.shape == (1, 4, 16, 16) for c in crops)
    for c in crops:  # each crop is a window of the frame
        hits = [(i, j) for i in range(25) for j in range(35) if np.array_equal(frame[:, i:i + 16, j:j + 16], c[0])]
        assert hits
    whole = frame_calibration_inputs([str(tmp_path / "f.npy")], 1, 3, None)
    assert len(whole) == 1 and np.array_equal(whole[0][0], frame)
    ldi = frame_calibration_inputs([str(tmp_path / "f.npy")], 5, 1, None)[0][0]
    assert ldi.shape == (20, 40, 50) and np.array_equal(ldi[:4], frame)
    assert (ldi[4:][3::4] == 1).all() and (np.delete(ldi[4:], np.s_[3::4], 0) == 0).all()  # empty layers
    np.save(tmp_path / "bad.npy", frame[:3])
    with pytest.raises(ValueError, match="expected \\[4, H, W\\]"):
        frame_calibration_inputs([str(tmp_path / "bad.npy")], 1, 1, None)


def trained_like_prefilter():
    """A pre-filter whose correction is not zero (an untrained one would hide the CNN from the checks)."""
    torch.manual_seed(2)
    pre = prefilter_cnn().eval()
    with torch.no_grad():
        for p in pre.net.convs[-1].parameters():
            p.normal_(0, 0.05)
    return pre


def slm_like(h, w, seed=0):
    """``[Re H, Im H]`` of a random field with |H| up to ≈1.2, as after offset propagation."""
    g = torch.Generator().manual_seed(seed)
    field = torch.polar(1.2 * torch.rand(1, 3, h, w, generator=g), 6.3 * torch.rand(1, 3, h, w, generator=g))
    return prefilter_input(field).numpy()


def test_prefilter_export(tmp_path):
    pre = trained_like_prefilter()
    path = export_onnx(pre, str(tmp_path / "pre.onnx"), "prefilter-cnn", meta(pre, "prefilter-cnn"))
    m = onnx.load(path)
    onnx.checker.check_model(m)
    assert [i.name for i in m.graph.input] == ["slm_field"] and [o.name for o in m.graph.output] == ["real", "imag"]
    pads = [n for n in m.graph.node if n.op_type == "Pad"]
    assert [a.s for n in pads for a in n.attribute if a.name == "mode"] == [b"edge"]  # the AA-DPM blur's edges
    for h, w in ((20, 20), (17, 29)):
        x = slm_like(h, w, h)
        with torch.no_grad():
            re, im = pre(torch.from_numpy(x))
        ore, oim = run_onnx(path, x)
        assert np.abs(ore - re.numpy()).max() < 1e-5 and np.abs(oim - im.numpy()).max() < 1e-5
    md = read_metadata(path)
    assert md["tensorholo.kind"] == "prefilter-cnn" and md["tensorholo.format_version"] == "2"
    assert md["tensorholo.prefilter_base"] == "aa-dpm(sigma_px=0.7,taps=5)"
    assert md["tensorholo.layers"] == "8" and md["tensorholo.channels"] == "8"


@pytest.mark.parametrize("fmt", ["qoperator", "qdq"])
def test_prefilter_int8_keeps_the_blur_in_float(tmp_path, fmt):
    pre = trained_like_prefilter()
    path = export_onnx(pre, str(tmp_path / "pre.onnx"), "prefilter-cnn", meta(pre, "prefilter-cnn"))
    calib = [slm_like(32, 32, 10 + i) for i in range(8)]
    out = quantize_int8(path, str(tmp_path / f"pre.{fmt}.onnx"), calib, fmt)
    nodes = onnx.load(out).graph.node
    float_convs = [n for n in nodes if n.op_type == "Conv"]
    grouped = [n for n in float_convs if any(a.name == "group" and a.i == 6 for a in n.attribute)]
    assert len(grouped) == 1  # the fixed blur
    pad = next(n for n in nodes if n.op_type == "Pad")
    assert pad.input[0] == "slm_field"  # ... of the float input, not of its u8 rounding (QDQ's first conv reads)
    if fmt == "qoperator":  # the blur and the last learned convolution (the correction) stay float
        assert len(float_convs) == 2 and sum(n.op_type == "QLinearConv" for n in nodes) == 7
    x = slm_like(24, 24, 99)
    with torch.no_grad():
        re, im = pre(torch.from_numpy(x))
        base = pre.base_filter(torch.from_numpy(x))
    ore, oim = run_onnx(out, x, exact=True)
    err = np.abs(np.concatenate([ore, oim], 1) - np.concatenate([re, im], 1))
    corr = np.abs(np.concatenate([re, im], 1) - base.numpy())
    print(f"pre-filter int8 {fmt}: mean abs error {err.mean():.4f} (correction itself {corr.mean():.4f})")
    # only the correction is quantised: the error is a fraction of the correction, not of the field
    assert err.mean() < 0.25 * corr.mean() and err.max() < INT8_MAX


def test_cli_exports_hologram_and_prefilter_separately(tmp_path, tiny_dataset):
    from tensorholo_training.export import main
    from tensorholo_training.train import TrainConfig, Trainer

    cfg = TrainConfig(run_dir=str(tmp_path / "run"), dataset=tiny_dataset, num_layers=8, channels=12,
                      crop=[16, 16], fs_top=3, fs_random=2, stages=["stage1", "stage2"], stage1_steps=1,
                      stage2_steps=1, offset_mm=6.0, stage2_train_hologram=False, val_every=100,
                      ckpt_every=100)
    Trainer(cfg, log=lambda m: None).run()
    ck = str(tmp_path / "run" / "final.pt")
    out = tmp_path / "models"
    assert main(["--checkpoint", ck, "--out-dir", str(out), "--name", "holo8", "--no-prefilter"]) == 0
    assert main(["--checkpoint", ck, "--out-dir", str(out), "--name", "pre6", "--prefilter-only"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["holo8.onnx", "pre6.onnx"]
    assert read_metadata(str(out / "holo8.onnx"))["tensorholo.kind"] == "hologram-cnn"
    pre = read_metadata(str(out / "pre6.onnx"))
    assert pre["tensorholo.kind"] == "prefilter-cnn" and float(pre["tensorholo.offset_m"]) == 6e-3


def test_a_run_starts_from_a_shipped_onnx_file_with_the_same_outputs(exported, tmp_path):
    """train.initial_state reads an f32 ONNX file's weights back into PyTorch (the initialisers carry the
    parameter names), refuses int8 files, and tells hologram CNNs from pre-filters."""
    from tensorholo_training.train import initial_state

    net, path, _ = exported
    state = initial_state(path, "cpu")
    assert state["prefilter"] is None
    back = hologram_cnn(8, 1).eval()
    back.load_state_dict(state["net"])
    x = np.random.default_rng(3).random((1, 4, 12, 20), dtype=np.float32)
    with torch.no_grad():
        for a, b in zip(net(torch.from_numpy(x)), back(torch.from_numpy(x))):
            assert torch.equal(a, b)
    pre = trained_like_prefilter()
    pre_path = export_onnx(pre, str(tmp_path / "pre.onnx"), "prefilter-cnn", meta(pre, "prefilter-cnn"))
    pre_state = initial_state(pre_path, "cpu")
    assert pre_state["net"] is None and set(pre_state["prefilter"]) == set(pre.state_dict())
    q = quantize_int8(path, str(tmp_path / "q.onnx"), [x], "qdq")
    with pytest.raises(ValueError, match="initialise from the f32 ONNX file"):
        initial_state(q, "cpu")


def test_an_ldi_cnn_widened_from_an_rgbd_one_starts_as_it_whatever_the_back_layers_hold():
    from tensorholo_training.train import widen_input_layers

    torch.manual_seed(1)
    rgbd, ldi = hologram_cnn(8, 1).eval(), hologram_cnn(8, 5).eval()
    ldi.load_state_dict(widen_input_layers(rgbd.state_dict(), ldi))
    x = torch.rand(2, 4, 10, 14)
    with torch.no_grad():
        want = rgbd(x)
        for back in (torch.zeros(2, 16, 10, 14), torch.rand(2, 16, 10, 14)):
            got = ldi(torch.cat([x, back], 1))
            for a, b in zip(want, got):
                assert (a - b).abs().max() < 1e-6
    # Anything else is left as it is (an LDI state into an LDI CNN, an RGB-D state into an RGB-D CNN).
    same = ldi.state_dict()
    assert widen_input_layers(same, ldi) is same
    same = rgbd.state_dict()
    assert widen_input_layers(same, rgbd) is same


def test_an_exported_file_rebuilds_in_pytorch_with_the_same_outputs(exported, tmp_path):
    net, path, _ = exported
    pre = trained_like_prefilter()
    pre_path = export_onnx(pre, str(tmp_path / "pre.onnx"), "prefilter-cnn", meta(pre, "prefilter-cnn"))
    rng = np.random.default_rng(5)
    for original, file, x in ((net, path, rng.random((1, 4, 12, 20), dtype=np.float32)),
                              (pre, pre_path, slm_like(12, 20, 6))):
        rebuilt, md = load_onnx_network(file)
        assert type(rebuilt) is type(original) and md["tensorholo.kind"] in ("hologram-cnn", "prefilter-cnn")
        with torch.no_grad():
            for a, b in zip(original(torch.from_numpy(x)), rebuilt(torch.from_numpy(x))):
                assert torch.equal(a, b)
    m = onnx.load(pre_path)
    keep = [p for p in m.metadata_props if p.key != "tensorholo.prefilter_base"]
    del m.metadata_props[:]
    m.metadata_props.extend(keep)
    onnx.save(m, str(tmp_path / "nobase.onnx"))
    with pytest.raises(ValueError, match="prefilter_base '<missing>'"):
        load_onnx_network(str(tmp_path / "nobase.onnx"))


def test_percentile_calibration_narrows_activation_ranges_and_bad_methods_are_refused(exported):
    net, path, d = exported
    rng = np.random.default_rng(2)
    calib = [rng.random((1, 4, 32, 32), dtype=np.float32) for _ in range(4)]

    def activation_scales(method):
        out = quantize_int8(path, str(d / f"holo8.{method}.onnx"), calib, "qdq", True, method)
        want = {"minmax": "minmax", "percentile": "percentile-99.99"}[method]
        assert read_metadata(out)["tensorholo.int8_calibration"] == want
        m = onnx.load(out)
        inits = {i.name: onnx.numpy_helper.to_array(i) for i in m.graph.initializer}
        return {n.input[0]: float(inits[n.input[1]]) for n in m.graph.node if n.op_type == "QuantizeLinear"}

    minmax, pct = activation_scales("minmax"), activation_scales("percentile")
    assert minmax.keys() == pct.keys()
    assert all(pct[k] <= minmax[k] * (1 + 1e-6) for k in minmax)  # a percentile never exceeds the maximum
    assert any(pct[k] < 0.99 * minmax[k] for k in minmax)
    with pytest.raises(ValueError, match="calib_method"):
        quantize_int8(path, str(d / "x.onnx"), calib, "qdq", True, "entropy")


@pytest.mark.parametrize("which", [["first"], ["last"], ["first", "last"]])
def test_float_convs_leave_the_named_learned_convolutions_float(exported, which):
    net, path, d = exported
    calib = rgbd_calib(5)
    out = quantize_int8(path, str(d / f"holo8.{'_'.join(which)}.onnx"), calib, "qdq", float_convs=which)
    model = onnx.load(out)
    made_by = {o: n.op_type for n in model.graph.node for o in n.output}
    convs = [n for n in model.graph.node if n.op_type == "Conv"]
    float_weights = [made_by.get(c.input[1]) != "DequantizeLinear" for c in convs]
    assert float_weights == [("first" in which and i == 0) or ("last" in which and i == 7) for i in range(8)]
    with pytest.raises(ValueError, match="float_convs"):
        quantize_int8(path, str(d / "x.onnx"), calib, "qdq", float_convs=["middle"])


def test_mixed_precision_rounds_the_last_hidden_state_on_its_own_grid_and_errs_less(exported):
    # export --float-convs first last (the shipped int8 pre-filters' layout, the native engine's mixed
    # precision): the concat reads the float input and the last hidden state rounded to a grid calibrated on it
    # (>= 0: zero point 0, its maximum over the calibration inputs at code 255); on other inputs the file is
    # closer to the f32 network than the all-int8 file of the same calibration.
    net, path, d = exported
    calib = rgbd_calib(6, 8)
    mixed = quantize_int8(path, str(d / "holo8.mixed.onnx"), calib, "qdq", float_convs=["first", "last"])
    int8 = quantize_int8(path, str(d / "holo8.all.onnx"), calib, "qdq")
    assert read_metadata(mixed)["tensorholo.int8_float_convs"] == "first last"
    assert read_metadata(int8)["tensorholo.int8_float_convs"] == "none"
    model = onnx.load(mixed)
    inits = {i.name: onnx.numpy_helper.to_array(i) for i in model.graph.initializer}
    made_by = {o: n for n in model.graph.node for o in n.output}
    cat = next(n for n in model.graph.node if n.op_type == "Concat")
    dq = made_by[cat.input[0]]
    q = made_by[dq.input[0]]
    assert (dq.op_type, q.op_type) == ("DequantizeLinear", "QuantizeLinear")
    assert made_by[cat.input[1]].op_type == "Sub"  # the centred input x − 0.5, float
    scale, zero = float(inits[q.input[1]]), int(inits[q.input[2]])
    hidden = []
    with torch.no_grad():
        def keep(i, t):
            if i == net.num_layers - 1:
                hidden.append(t[:, :net.channels])
            return t
        net.activation_quant = keep
        for x in calib:
            net(torch.from_numpy(x))
        net.activation_quant = None
    top = max(float(h.max()) for h in hidden)
    assert zero == 0 and scale == pytest.approx(top / 255, rel=1e-5)
    errors = {}
    for name, p in (("mixed", mixed), ("int8", int8)):
        e = []
        for x in rgbd_calib(11, 4):
            with torch.no_grad():
                ref = [t.numpy() for t in net(torch.from_numpy(x))]
            e += [np.abs(a - r).mean() for a, r in zip(run_onnx(p, x, exact=True), ref)]
        errors[name] = float(np.mean(e))
    assert errors["mixed"] < 0.9 * errors["int8"], errors


def test_the_aberrations_of_the_training_data_reach_the_exported_metadata():
    """A dataset corrected for aberrations (manifest ``synthesis.aberration.profile``) is recorded in the
    training configuration and in the exported models' ``tensorholo.aberration`` (compact JSON, parsed back to
    the same profile); without one the key is absent."""
    from tensorholo_training.train import TrainConfig, resolve_optics

    profile = {"format": "tensorholo.aberration", "version": 1,
               "samples": [{"distance_m": -0.009, "coefficients": {"astigmatism_vertical": 1.0}},
                           {"distance_m": -0.003, "coefficients": {"astigmatism_vertical": 2.0}}]}
    manifest = {"optics": {"wavelengths_m": [638e-9, 520e-9, 450e-9], "pixel_pitch_m": 8e-6,
                           "volume_depth_m": 6e-3},
                "synthesis": {"pad": False, "aberration": {"file": "a.json", "slm_offset_m": 0.006,
                                                           "profile": profile}}}
    cfg = resolve_optics(TrainConfig(), manifest)
    assert cfg.aberration == profile
    assert resolve_optics(TrainConfig(), {"optics": manifest["optics"]}).aberration is None
    net = hologram_cnn(8)
    common = dict(wavelengths_m=cfg.wavelengths_m, pixel_pitch_m=cfg.pixel_pitch_m,
                  volume_depth_m=cfg.volume_depth_m, offset_m=0.0, input_layers=1,
                  trained_resolution=(24, 24), training_commit="test")
    md = model_metadata("hologram-cnn", net, **common, aberration=cfg.aberration)
    assert json.loads(md["tensorholo.aberration"]) == profile
    assert "\n" not in md["tensorholo.aberration"]
    assert "tensorholo.aberration" not in model_metadata("hologram-cnn", net, **common)

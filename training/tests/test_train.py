"""Training smoke run (loss decreases), stage 2 and checkpoint resume (same final state)."""
import csv
import json
import os

import numpy as np
import pytest
import torch

from tensorholo_training.train import TrainConfig, Trainer, load_config, main


def small_cfg(tmp_path, dataset, **kw):
    base = dict(run_dir=str(tmp_path / "run"), dataset=dataset, num_layers=8, channels=12, batch_size=2,
                crop=[16, 16], lr=1e-3, fs_top=3, fs_random=2, log_every=1, val_every=10, val_batches=1,
                ckpt_every=1000, stages=["stage1"], stage1_steps=20, seed=1)
    base.update(kw)
    return TrainConfig(**base)


def test_smoke_training_reduces_the_loss(tmp_path, tiny_dataset):
    cfg = small_cfg(tmp_path, tiny_dataset, hflip=False, vflip=False)
    tr = Trainer(cfg, log=lambda m: None)
    tr.run()
    rows = list(csv.DictReader(open(os.path.join(cfg.run_dir, "learning_curve.csv"))))
    losses = [float(r["train_loss"]) for r in rows]
    assert len(losses) == 20
    first, last = sum(losses[:5]) / 5, sum(losses[-5:]) / 5
    print(f"smoke run: mean train loss steps 1-5 {first:.4f} -> steps 16-20 {last:.4f}; "
          f"val PSNR {rows[-1]['val_psnr_amp']} dB")
    assert last < 0.8 * first
    assert rows[-1]["val_psnr_amp"] != ""
    saved = json.load(open(os.path.join(cfg.run_dir, "config.json")))
    assert saved["num_layers"] == 8 and "training_commit" in saved
    assert os.path.exists(os.path.join(cfg.run_dir, "final.pt"))


def test_resume_gives_the_same_state_across_all_phases(tmp_path, tiny_dataset):
    kw = dict(stages=["stage1", "stage2"], stage1_steps=3, stage2_steps=4, offset_mm=6.0, hflip=True, vflip=True,
              val_every=2)
    straight = small_cfg(tmp_path / "a", tiny_dataset, **kw)
    Trainer(straight, log=lambda m: None).run()
    resumed = small_cfg(tmp_path / "b", tiny_dataset, **kw)
    for stop in (2, 5):  # inside stage 1, inside stage 2 (after a best.pt)
        Trainer(resumed, log=lambda m: None).run(max_steps=stop)
    Trainer(resumed, log=lambda m: None).run()
    a = torch.load(os.path.join(straight.run_dir, "final.pt"), weights_only=False)
    b = torch.load(os.path.join(resumed.run_dir, "final.pt"), weights_only=False)
    assert a["global_step"] == b["global_step"] == 7
    for key in ("net", "prefilter"):
        for name, t in a[key].items():
            assert torch.equal(t, b[key][name]), (key, name)
    rows = list(csv.DictReader(open(os.path.join(resumed.run_dir, "learning_curve.csv"))))
    assert [int(r["global_step"]) for r in rows] == list(range(1, 8))
    assert {r["phase"] for r in rows} == {"stage1", "stage2"}
    # best.pt: the best stage-2 validation, the same in both runs (its record survives the resume)
    assert a["best"] == b["best"] and a["best"]["phase"] == "stage2"
    best = torch.load(os.path.join(resumed.run_dir, "best.pt"), weights_only=False)
    assert best["global_step"] == a["best"]["global_step"] in (4, 6, 7)
    fs = {int(r["global_step"]): float(r["val_psnr_fs"]) for r in rows if r["phase"] == "stage2" and r["val_psnr_fs"]}
    assert a["best"]["value"] == pytest.approx(max(fs.values()), abs=1e-9)


def test_stage2_with_frozen_hologram_cnn_trains_only_the_prefilter(tmp_path, tiny_dataset):
    cfg = small_cfg(tmp_path, tiny_dataset, stages=["stage1", "stage2"], stage1_steps=2, stage2_steps=3,
                    offset_mm=6.0, stage2_train_hologram=False)
    tr = Trainer(cfg, log=lambda m: None)
    tr.run(max_steps=2)
    net0 = {k: v.clone() for k, v in tr.net.state_dict().items()}
    pre0 = {k: v.clone() for k, v in tr.prefilter.state_dict().items()}
    tr.run()
    assert all(torch.equal(net0[k], v) for k, v in tr.net.state_dict().items())
    assert any(not torch.equal(pre0[k], v) for k, v in tr.prefilter.state_dict().items())


def test_a_finished_run_is_extended_by_raising_its_steps(tmp_path, tiny_dataset):
    cfg = small_cfg(tmp_path, tiny_dataset, stage1_steps=3)
    Trainer(cfg, log=lambda m: None).run()
    first = torch.load(os.path.join(cfg.run_dir, "final.pt"), weights_only=False)
    longer = small_cfg(tmp_path, tiny_dataset, stage1_steps=5)
    tr = Trainer(longer, log=lambda m: None)
    tr.run()
    assert tr.global_step == 5
    rows = list(csv.DictReader(open(os.path.join(cfg.run_dir, "learning_curve.csv"))))
    assert [int(r["global_step"]) for r in rows] == [1, 2, 3, 4, 5]
    final = torch.load(os.path.join(cfg.run_dir, "final.pt"), weights_only=False)
    assert any(not torch.equal(t, final["net"][k]) for k, t in first["net"].items())


def test_cli_config_and_overrides(tmp_path, capsys):
    path = tmp_path / "c.json"
    path.write_text(json.dumps({"num_layers": 15, "offset_mm": 6}))
    cfg = load_config(str(path), ["batch_size=4", "crop=[32,32]"], str(tmp_path / "r"))
    assert cfg.num_layers == 15 and cfg.batch_size == 4 and cfg.crop == [32, 32] and cfg.prefilter_enabled
    with pytest.raises(ValueError, match="unknown"):
        load_config(None, ["num_layer=3"])
    assert main(["--config", str(path), "--print-config"]) == 0
    assert json.loads(capsys.readouterr().out)["num_layers"] == 15


def test_the_removed_identity_stage_is_refused_and_old_keys_are_ignored(tmp_path, tiny_dataset):
    with pytest.raises(ValueError, match="identity"):
        Trainer(small_cfg(tmp_path, tiny_dataset, stages=["stage1", "identity"], offset_mm=6.0), log=lambda m: None)
    cfg = TrainConfig.from_dict({"num_layers": 8, "identity_steps": 300, "identity_target": "aa-dpm"})
    assert cfg.num_layers == 8
    with pytest.raises(ValueError, match="select_metric"):
        Trainer(small_cfg(tmp_path / "m", tiny_dataset, select_metric="loss"), log=lambda m: None)


def test_prefilter_floor_compares_ddpm_with_aa_dpm_and_plain_dpm(tmp_path, tiny_dataset):
    from tensorholo_training.prefilter_floor import compare

    cfg = small_cfg(tmp_path, tiny_dataset, stages=["stage1", "stage2"], stage1_steps=1, stage2_steps=2,
                    offset_mm=6.0, lr=1e-2)
    Trainer(cfg, log=lambda m: None).run()
    rows = compare(cfg.run_dir, batches=1)
    assert set(rows) == {"ddpm", "aa-dpm", "dpm"}
    for r in rows.values():
        assert np.isfinite(r["val_psnr_amp"]) and np.isfinite(r["val_psnr_fs"])
        assert r["loss_regulariser"] >= 0.0
    # The three encodings are different operations, so they score differently.
    assert len({round(r["val_psnr_fs"], 6) for r in rows.values()}) == 3


def test_cosine_schedule_runs_from_lr_to_its_final_ratio_and_is_applied(tmp_path, tiny_dataset):
    cfg = small_cfg(tmp_path, tiny_dataset, lr=2e-3, lr_schedule="cosine", lr_final_ratio=0.25, stage1_steps=5)
    tr = Trainer(cfg, log=lambda m: None)
    assert [tr.lr_at(k, 5) for k in range(5)] == pytest.approx(
        [2e-3 * (0.25 + 0.75 * 0.5 * (1 + np.cos(np.pi * k / 4))) for k in range(5)])
    assert tr.lr_at(0, 5) == pytest.approx(2e-3) and tr.lr_at(4, 5) == pytest.approx(5e-4)
    tr.run(max_steps=3)  # the optimizer ran step 2 (0-based) at its scheduled rate
    assert tr.optimizer.param_groups[0]["lr"] == pytest.approx(tr.lr_at(2, 5))
    constant = Trainer(small_cfg(tmp_path / "c", tiny_dataset, lr=2e-3), log=lambda m: None)
    assert constant.lr_at(0, 5) == constant.lr_at(4, 5) == 2e-3
    with pytest.raises(ValueError, match="lr_schedule"):
        Trainer(small_cfg(tmp_path / "x", tiny_dataset, lr_schedule="step"), log=lambda m: None)


def test_layered_attention_reads_every_ldi_layer_and_changes_only_the_focal_stack_terms(tmp_path, tiny_dataset):
    front = Trainer(small_cfg(tmp_path / "f", tiny_dataset, input_layers=2), log=lambda m: None)
    layers = Trainer(small_cfg(tmp_path / "l", tiny_dataset, input_layers=2, fs_attention="layers"),
                     log=lambda m: None)
    layers.net.load_state_dict(front.net.state_dict())
    batch = next(iter(front.val_batches()))[2]
    depth, valid = layers.attention_depth(batch)
    assert depth.shape == valid.shape and depth.ndim == 4 and torch.equal(depth[:, 0], batch["depth"])
    assert bool(valid[:, 1:].any())  # the tiny dataset has hidden points
    assert front.attention_depth(batch)[1] is None
    with torch.no_grad():
        a = front.compute_loss(batch, "stage1", torch.Generator().manual_seed(3))
        b = layers.compute_loss(batch, "stage1", torch.Generator().manual_seed(3))
    assert float(a["data"]) == pytest.approx(float(b["data"]))
    assert float(a["focal_stack"]) != pytest.approx(float(b["focal_stack"]), rel=1e-4)
    layers.run(max_steps=2)
    with pytest.raises(ValueError, match="attention"):
        Trainer(small_cfg(tmp_path / "x", tiny_dataset, fs_attention="hidden"), log=lambda m: None)


def test_optics_come_from_the_manifest_and_a_contradiction_is_refused_by_key(tmp_path):
    from tensorholo_training.data import write_synthetic_dataset
    from tensorholo_training.optics import Display

    display = Display((640e-9, 532e-9, 450e-9), 6.4e-6, 4e-3)
    root = write_synthetic_dataset(str(tmp_path / "ds"), {"train": 4, "val": 2}, 16, 16, per_shard=4,
                                   display=display, seed=2)
    tr = Trainer(small_cfg(tmp_path / "a", root), log=lambda m: None)  # the config states no optics
    assert tr.display == display
    assert tr.cfg.pixel_pitch_m == 6.4e-6 and tr.cfg.wavelengths_m == [640e-9, 532e-9, 450e-9]
    tr.run(max_steps=1)
    saved = json.load(open(os.path.join(tr.cfg.run_dir, "config.json")))
    assert saved["volume_depth_m"] == 4e-3  # the run records what it trained for (export reads it)
    Trainer(small_cfg(tmp_path / "b", root, pixel_pitch_m=6.4e-6), log=lambda m: None)  # agreeing: fine
    for key, value in (("pixel_pitch_m", 8e-6), ("wavelengths_m", [638e-9, 520e-9, 450e-9]),
                       ("volume_depth_m", 6e-3)):
        with pytest.raises(ValueError, match=f"^{key}: .*manifest.*optics_override"):
            Trainer(small_cfg(tmp_path / key, root, **{key: value}), log=lambda m: None)
    over = Trainer(small_cfg(tmp_path / "o", root, pixel_pitch_m=8e-6, optics_override=True), log=lambda m: None)
    assert over.display.pixel_pitch_m == 8e-6 and over.display.volume_depth_m == 4e-3


def test_the_learning_rate_follows_the_global_batch(tmp_path, tiny_dataset):
    tr = Trainer(small_cfg(tmp_path / "a", tiny_dataset, batch_size=4, lr=1e-3), log=lambda m: None)
    assert tr.global_batch == 4 and tr.base_lr == pytest.approx(2e-3) and tr.lr_at(0, 5) == pytest.approx(2e-3)
    tr.run(max_steps=1)
    assert tr.optimizer.param_groups[0]["lr"] == pytest.approx(2e-3)
    flat = Trainer(small_cfg(tmp_path / "b", tiny_dataset, batch_size=4, lr=1e-3, lr_scaling="none"),
                   log=lambda m: None)
    assert flat.base_lr == 1e-3
    # the paper's batch (2) keeps lr as given: the shipped configurations are unchanged
    assert Trainer(small_cfg(tmp_path / "c", tiny_dataset, lr=1e-3), log=lambda m: None).base_lr == 1e-3

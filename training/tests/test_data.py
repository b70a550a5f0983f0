"""Dataset reader: the documented npz format, both midpoint encodings, augmentation consistency."""
import json
import os

import numpy as np
import pytest
import torch

from tensorholo_training.data import (
    Augment, LdiDataset, ShardGroupedBatchSampler, check_display, collate, load_shard, manifest_propagation,
    read_manifest, split_names, write_synthetic_dataset,
)
from tensorholo_training.optics import Display


def test_reads_what_it_documents(tiny_dataset):
    ds = LdiDataset(tiny_dataset, "train", input_layers=1)
    assert len(ds) == 8 and ds.layers == 2 and ds.shape == (24, 24)
    it = ds[0]
    assert it["rgbd"].shape == (4, 24, 24) and it["rgbd"].dtype == torch.float32
    assert it["midpoint"].shape == (3, 24, 24) and it["midpoint"].dtype == torch.complex64
    assert it["valid"].shape == (2, 24, 24) and it["depth"].shape == (24, 24)
    assert torch.equal(it["depth"], it["rgbd"][3])
    ldi = LdiDataset(tiny_dataset, "train", input_layers=2)[0]["rgbd"]
    assert ldi.shape == (8, 24, 24) and torch.equal(ldi[:4], it["rgbd"])
    # invalid pixels of layer 2: amplitude 0, depth 1
    v = LdiDataset(tiny_dataset, "train", input_layers=2)[0]["valid"][1].bool()
    assert (ldi[4:7][:, ~v] == 0).all() and (ldi[7][~v] == 1).all()
    with pytest.raises(ValueError):
        LdiDataset(tiny_dataset, "train", input_layers=3)


def test_split_midpoint_and_no_manifest(tmp_path):
    root = write_synthetic_dataset(str(tmp_path), {"train": 3}, 16, 16, per_shard=2, complex_key=False)
    d = load_shard(os.path.join(root, "train-00000.npz"))
    assert d["midpoint"].dtype == np.complex64 and d["midpoint"].shape == (2, 3, 16, 16)
    os.remove(os.path.join(root, "manifest.json"))
    ds = LdiDataset(root, "train")  # found by the <split>-*.npz pattern
    assert len(ds) == 3


def test_crop_and_flips_keep_scene_and_hologram_aligned(tiny_dataset):
    plain = LdiDataset(tiny_dataset, "train")
    aug = LdiDataset(tiny_dataset, "train", augment=Augment((16, 12), hflip=True, vflip=True))
    full = plain[2]
    for seed in range(6):
        aug.rng = np.random.default_rng(seed)
        it = aug[2]
        assert it["rgbd"].shape == (4, 16, 12) and it["midpoint"].shape == (3, 16, 12)
        # find where the crop came from, with the same transform on the hologram
        found = False
        for fy in (False, True):
            for fx in (False, True):
                r, m = full["rgbd"], full["midpoint"]
                if fy:
                    r, m = r.flip(-2), m.flip(-2)
                if fx:
                    r, m = r.flip(-1), m.flip(-1)
                for y0 in range(24 - 16 + 1):
                    for x0 in range(24 - 12 + 1):
                        if torch.equal(r[:, y0:y0 + 16, x0:x0 + 12], it["rgbd"]):
                            found |= torch.equal(m[:, y0:y0 + 16, x0:x0 + 12], it["midpoint"])
        assert found, seed


def test_dataloader_batches_cover_an_epoch_with_the_same_data_in_workers(tiny_dataset):
    ds = LdiDataset(tiny_dataset, "train", augment=Augment((16, 16), hflip=True, vflip=True), seed=5)
    sampler = ShardGroupedBatchSampler(ds.shard_sizes, 3, seed=2)
    sampler.set_epoch(4)
    loaders = [torch.utils.data.DataLoader(ds, batch_sampler=sampler, num_workers=w, collate_fn=collate)
               for w in (0, 2)]
    a, b = (list(loader) for loader in loaders)
    assert [x["rgbd"].shape for x in a] == [(3, 4, 16, 16)] * 2  # 8 scenes, batch 3: the tail of 2 is dropped
    for x, y in zip(a, b):  # the same crops and flips whichever process reads them
        assert all(torch.equal(x[k], y[k]) for k in x)
    # the items are those the sampler names, each augmented by (seed, epoch, index)
    first = sampler.rank_batches(4)[0]
    assert torch.equal(a[0]["rgbd"][1], ds[(first[1], 4)]["rgbd"])


def test_display_mismatch_is_refused(tiny_dataset):
    manifest = json.load(open(os.path.join(tiny_dataset, "manifest.json")))
    check_display(manifest, Display())
    with pytest.raises(ValueError, match="generated for"):
        check_display(manifest, Display(pixel_pitch_m=6.4e-6))


def test_manifest_of_docs_dataset_md(tiny_dataset, tmp_path):
    m = read_manifest(tiny_dataset)
    assert m["format"] == "tensorholo-ldi-hologram-dataset" and split_names(m) == ["train", "val"]
    assert manifest_propagation(m).pad is True
    bad = dict(m, format_version=2)
    (tmp_path / "manifest.json").write_text(json.dumps(bad))
    with pytest.raises(ValueError, match="newer"):
        read_manifest(str(tmp_path))
    (tmp_path / "manifest.json").write_text(json.dumps(dict(m, format="something-else")))
    with pytest.raises(ValueError, match="format"):
        read_manifest(str(tmp_path))
    # the older dict form of "splits" is read too
    legacy = dict(m, splits={"train": {"shards": ["train-00000.npz"]}})
    assert split_names(legacy) == ["train"]


def test_reads_a_dataset_written_by_holo(fixtures_dir, tmp_path):
    root = os.path.join(fixtures_dir, "holo_dataset")
    if not os.path.exists(os.path.join(root, "manifest.json")):
        pytest.skip("no holo dataset fixture (holo without the dataset subcommand)")
    m = read_manifest(root)
    assert split_names(m) == ["train", "val", "test"]
    assert manifest_propagation(m).pad == bool(m["synthesis"]["pad"])
    check_display(m, Display())
    ds = LdiDataset(root, "train", input_layers=5)
    assert len(ds) == m["splits"][0]["samples"] and ds.layers == m["ldi_layers"]
    for i in range(len(ds)):
        it = ds[i]
        layers = it["rgbd"].view(5, 4, *ds.shape)
        valid = it["valid"].bool()
        assert valid[0].all()
        assert ((layers[:, :3] >= 0) & (layers[:, :3] <= 1)).all()
        assert (layers[:, 3][~valid] == 1).all() and (layers[:, :3].permute(1, 0, 2, 3)[:, ~valid] == 0).all()
        assert it["midpoint"].dtype == torch.complex64 and torch.isfinite(it["midpoint"].abs()).all()
    # the trainer runs on it, with the dataset's own ASM options
    from tensorholo_training.train import TrainConfig, Trainer

    cfg = TrainConfig(run_dir=str(tmp_path / "run"), dataset=root, num_layers=8, channels=8, input_layers=5,
                      stages=["stage1", "stage2"], stage1_steps=2, stage2_steps=2, fs_top=3, fs_random=2,
                      log_every=1, val_every=2, val_batches=1)
    tr = Trainer(cfg, log=lambda msg: None)
    assert tr.cfg.asm_pad is False and tr.prefilter is None
    metrics = tr.run()
    assert np.isfinite(metrics["val_psnr_amp"]) and tr.trained_resolution == [16, 24]

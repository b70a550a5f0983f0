"""Data-parallel training under ``torchrun --standalone --nproc-per-node 2`` (gloo, CPU) and the shard-grouped
sampler that partitions an epoch across ranks.

The torchrun jobs run through a launcher that installs a Python audit hook reporting every file a rank opens
for writing, renames, creates or removes, or that torch.save writes, under the test's folder ("WRITE rank R PATH" on stderr), so that the
tests see which rank wrote what. Each job trains a tiny CNN for 6 steps (8 scenes, global batch 2: 4 steps
per epoch, so the runs cross an epoch boundary) with one DataLoader worker per rank.
"""
import json
import os
import re
import subprocess
import sys

import pytest
import torch

from tensorholo_training.data import ShardGroupedBatchSampler
from tensorholo_training.train import TrainConfig, Trainer

TRAINING = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))

LAUNCHER = r'''
import os, runpy, sys
root, rank = os.environ["WRITE_WATCH_ROOT"], os.environ.get("RANK", "?")
def hook(event, args):
    path = None
    if event == "open":
        p, mode, flags = args
        if isinstance(mode, str) and any(c in mode for c in "wax+"):
            path = p
        elif mode is None and isinstance(flags, int) and flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT):
            path = p
    elif event in ("os.rename", "os.replace"):
        path = args[1]
    elif event in ("os.mkdir", "os.remove", "os.rmdir", "shutil.rmtree"):
        path = args[0]
    if isinstance(path, (str, bytes, os.PathLike)) and os.fsdecode(path).startswith(root):
        sys.stderr.write(f"WRITE rank {rank} {os.fsdecode(path)}\n")
        sys.stderr.flush()
sys.addaudithook(hook)
import torch  # torch.save writes through C++, which the audit hook does not see
_save = torch.save
def save(obj, f, *a, **k):
    if isinstance(f, (str, os.PathLike)):
        hook("os.mkdir", (f,))  # reported as a write
    return _save(obj, f, *a, **k)
torch.save = save
sys.argv = ["tensorholo_training.train"] + sys.argv[1:]
runpy.run_module("tensorholo_training.train", run_name="__main__")
'''

STEPS = 6


def settings(dataset, **kw):
    """The configuration of every run here (``--set`` values and the in-process TrainConfig agree)."""
    base = dict(dataset=dataset, num_layers=8, channels=8, batch_size=1, crop=[16, 16], lr=1e-3, fs_top=3,
                fs_random=2, log_every=1, val_every=3, val_batches=1, ckpt_every=2, stages=["stage1"],
                stage1_steps=STEPS, seed=4, num_workers=1)
    base.update(kw)
    return base


def torchrun(tmp, run_dir, cfg, *extra, env=None, restarts=0):
    """Runs the trainer on 2 ranks; returns (returncode, stdout, stderr)."""
    launcher = tmp / "launcher.py"
    launcher.write_text(LAUNCHER)
    sets = []
    for k, v in cfg.items():
        sets += ["--set", f"{k}={json.dumps(v)}"]
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc-per-node", "2",
           "--max-restarts", str(restarts), str(launcher), "--run-dir", str(run_dir), *sets, *extra]
    e = {k: v for k, v in os.environ.items() if k != "TENSORHOLO_FAULT"}
    e.update(PYTHONPATH=TRAINING, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", WRITE_WATCH_ROOT=str(tmp), **(env or {}))
    p = subprocess.run(cmd, capture_output=True, text=True, env=e, timeout=120)
    return p.returncode, p.stdout, p.stderr


def final_net(run_dir):
    return torch.load(os.path.join(run_dir, "final.pt"), weights_only=False)["net"]


@pytest.fixture(scope="module")
def reference(tmp_path_factory, tiny_dataset):
    """One fault-free 2-rank run (batch 1 per rank) and its outputs."""
    tmp = tmp_path_factory.mktemp("ddp")
    run = tmp / "two_ranks"
    cfg = settings(tiny_dataset)
    rc, out, err = torchrun(tmp, run, cfg)
    assert rc == 0, out + err
    return {"tmp": tmp, "run": run, "cfg": cfg, "out": out, "err": err}


def test_sampler_partitions_each_epoch_disjointly_and_completely_across_ranks():
    shards = [5, 4, 6, 3]  # 18 samples
    n = sum(shards)
    for world, b in ((1, 2), (2, 1), (2, 2), (3, 2), (4, 1)):
        g = world * b
        samplers = [ShardGroupedBatchSampler(shards, b, r, world, seed=9) for r in range(world)]
        for epoch in range(3):
            per_rank = [[k for batch in s.rank_batches(epoch) for k in batch] for s in samplers]
            flat = [k for ks in per_rank for k in ks]
            assert len(flat) == len(set(flat)) == (n // g) * g  # disjoint; the tail of < g dropped
            assert all(len(ks) == n // g * b for ks in per_rank)  # every rank does the same number of steps
            order = samplers[0].epoch_order(epoch)
            assert sorted(order) == list(range(n))
            assert set(flat) == set(order[: (n // g) * g])  # they cover the epoch but its dropped tail
            # the ranks' batches are the global batches (what one process with batch g reads)
            one = ShardGroupedBatchSampler(shards, g, 0, 1, seed=9).rank_batches(epoch)
            assert [sum((s.rank_batches(epoch)[t] for s in samplers), []) for t in range(n // g)] == one
            # shard-grouped: along each of a rank's b lanes the shard changes at most once per shard visited
            shard_of = [s for s, m in enumerate(shards) for _ in range(m)]
            for s in samplers:
                for lane in range(b):
                    seq = [shard_of[batch[lane]] for batch in s.rank_batches(epoch)]
                    switches = sum(x != y for x, y in zip(seq, seq[1:]))
                    assert switches <= len(set(seq)) - 1
        # epochs are reshuffled, and the same (seed, epoch) gives the same order
        s0 = samplers[0]
        assert s0.epoch_order(0) != s0.epoch_order(1) and s0.epoch_order(1) == s0.epoch_order(1)
    # resuming inside an epoch yields the rest of that epoch
    s = ShardGroupedBatchSampler(shards, 2, 1, 2, seed=9)
    s.set_epoch(2, start=3)
    assert [[k for k, e in batch] for batch in s] == s.rank_batches(2)[3:] and len(s) == len(s.rank_batches(2)) - 3
    with pytest.raises(ValueError, match="global batch"):
        ShardGroupedBatchSampler([3], 2, 0, 2)


def test_two_ranks_of_batch_1_give_the_weights_of_one_process_of_batch_2(reference, tiny_dataset, tmp_path):
    cfg = dict(reference["cfg"], batch_size=2, num_workers=0)
    single = Trainer(TrainConfig(run_dir=str(tmp_path / "one"), **cfg), log=lambda m: None)
    single.run()
    a, b = final_net(reference["run"]), single.net.state_dict()
    worst = max(float((a[k] - b[k]).abs().max()) for k in a)
    print(f"2 ranks x batch 1 vs 1 process x batch 2 after {STEPS} steps: max weight difference {worst:.3g}")
    assert worst <= 1e-6
    assert any(not torch.equal(a[k], Trainer(TrainConfig(run_dir=str(tmp_path / "init"), **cfg),
                                             log=lambda m: None).net.state_dict()[k]) for k in a)  # it trained
    # the checkpoint records the world size
    ck = torch.load(os.path.join(reference["run"], "final.pt"), weights_only=False)
    assert ck["world_size"] == 2 and ck["global_batch"] == 2 and ck["global_step"] == STEPS


def test_the_ranks_hold_identical_weights(reference):
    from tensorholo_training.model import hologram_cnn
    from tensorholo_training.train import weights_digest

    line = next(l for l in reference["out"].splitlines() if l.startswith("weights sha256 per rank:"))
    digests = line.split(":", 1)[1].split()
    assert len(digests) == 2 and digests[0] == digests[1], line
    net = hologram_cnn(8, 1, 8)
    net.load_state_dict(final_net(reference["run"]))
    assert digests[0] == weights_digest(net)  # what the ranks compared is the saved network


def test_stop_and_resume_under_torchrun_is_bit_identical(reference, tiny_dataset):
    tmp, run = reference["tmp"], reference["tmp"] / "stopped"
    rc, out, err = torchrun(tmp, run, reference["cfg"], "--max-steps", "3")  # inside the first epoch
    assert rc == 0, out + err
    assert torch.load(os.path.join(run, "checkpoint.pt"), weights_only=False)["global_step"] == 3
    rc, out2, err2 = torchrun(tmp, run, reference["cfg"])
    assert rc == 0, out2 + err2
    assert "resumed from" in out2
    a, b = final_net(reference["run"]), final_net(run)
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert "WRITE rank 1" not in err + err2


def test_a_killed_rank_is_restarted_by_torchrun_and_ends_with_the_fault_free_weights(reference, tmp_path):
    tmp, run = reference["tmp"], reference["tmp"] / "faulty"
    marker = tmp_path / "fault_marker"  # outside the watched folder
    rc, out, err = torchrun(tmp, run, reference["cfg"], restarts=1,
                            env={"TENSORHOLO_FAULT": f"1:5:{marker}"})
    assert rc == 0, out + err
    assert marker.exists() and "injected fault after step 5" in out + err
    assert re.search(r"resumed from .* at step [1-5] .*after torchrun restart 1", out), out
    a, b = final_net(reference["run"]), final_net(run)
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_only_rank_0_writes_files(reference):
    writes = re.findall(r"WRITE rank (\S+) (\S+)", reference["err"])
    by_rank = {}
    for rank, path in writes:
        by_rank.setdefault(rank, set()).add(os.path.basename(path))
    assert "1" not in by_rank, by_rank["1"]
    # the hook sees rank 0's files, so it would see rank 1's
    assert {"checkpoint.pt.tmp", "final.pt.tmp", "learning_curve.csv", "config.json"} <= by_rank["0"]
    run_files = set(os.listdir(reference["run"]))
    assert {"checkpoint.pt", "final.pt", "learning_curve.csv", "config.json", "best.pt"} <= run_files
    rows = open(os.path.join(reference["run"], "learning_curve.csv")).read().splitlines()
    assert len(rows) == 1 + STEPS  # one writer: one row per step


def test_resuming_under_another_world_size_is_refused_unless_allowed(reference, tmp_path):
    import shutil

    run = tmp_path / "run"
    shutil.copytree(reference["run"], run)
    cfg = dict(reference["cfg"], stage1_steps=STEPS + 1, batch_size=2, num_workers=0)
    with pytest.raises(ValueError, match="world size 2.*allow_world_size_change"):
        Trainer(TrainConfig(run_dir=str(run), **cfg), log=lambda m: None).run()
    tr = Trainer(TrainConfig(run_dir=str(run), allow_world_size_change=True, **cfg), log=lambda m: None)
    tr.run()
    assert tr.global_step == STEPS + 1

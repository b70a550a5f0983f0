"""Batches per second of the training data path and training steps per second at 384x384 (crop 384, batch 2,
8-layer CNN, stage 1), for the before/after figures of training/README.md, "Data loading".

    python training/experiments/data_loading.py SRC_TRAINING_DIR DATASET [NUM_WORKERS]

SRC_TRAINING_DIR is the `training/` folder of the source to measure (a checkout of the old loop, commit 37109b4,
takes no NUM_WORKERS); DATASET a folder of 48 training scenes, e.g. written by
`data.write_synthetic_dataset(root, {"train": 48, "val": 2}, 384, 384, layers=2, per_shard=16, seed=7)`.
It times one epoch of batches after the first (23) through `Trainer._batches()`, then 6 training steps.
Run with OMP_NUM_THREADS=1.
"""
import sys, time, os
sys.path.insert(0, sys.argv[1])
import torch
torch.set_num_threads(1)
from tensorholo_training.train import TrainConfig, Trainer
ds = sys.argv[2]
kw = dict(run_dir=f"/tmp/bench_run_{os.getpid()}", dataset=ds, crop=[384, 384], batch_size=2, stages=["stage1"],
          stage1_steps=1000, num_layers=8, seed=0)
if len(sys.argv) > 3:
    kw["num_workers"] = int(sys.argv[3])
tr = Trainer(TrainConfig(**kw), log=lambda m: None)
it = tr._batches()
next(it)  # warm-up: first shard, worker start
n = 23    # the rest of the epoch (48 scenes, batch 2)
t = time.perf_counter()
for _ in range(n):
    b = next(it)
dt = time.perf_counter() - t
print(f"data only: {n} batches in {dt:.2f} s = {n/dt:.2f} batches/s")
steps = 6
t = time.perf_counter()
for _ in range(steps):
    tr.train_step(next(it))
dt = time.perf_counter() - t
print(f"training: {steps} steps in {dt:.2f} s = {steps/dt:.3f} steps/s")

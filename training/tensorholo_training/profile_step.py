"""Where a training step's time goes: ``python -m tensorholo_training.profile_step``.

Builds a :class:`~.train.Trainer` on a synthetic dataset (``training/configs/small_cpu.json`` with the
arguments' device, network depth and scene size), then for stage 1 and stage 2 (the pre-filter, trained
jointly) times ``--repeats`` rounds of ``--steps`` optimizer steps after a warm-up, synchronising the device
around each round, and prints ``torch.profiler``'s operators for ``--steps`` more steps: by device time (CUDA)
or CPU time, and by CPU time. The step time and the two totals say whether a step is bound by the device's work
or by the host (Python, kernel launches, copies, data loading).

Measured on an NVIDIA H200 (training/README.md, "Measured on an NVIDIA H200")::

    PYTHONPATH=training python3 -m tensorholo_training.profile_step --device cuda --size 384
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import torch

from .train import Trainer, load_config


# The small CPU run's configuration (training/configs/), found from this file: any working directory will do.
SMALL_CPU = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "configs", "small_cpu.json")


def _sync(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize()


def time_steps(trainer: Trainer, batches, steps: int, device: str) -> float:
    """Milliseconds per optimizer step over ``steps`` steps of the trainer's current phase."""
    _sync(device)
    t = time.perf_counter()
    for _ in range(steps):
        trainer.train_step(next(batches))
    _sync(device)
    return (time.perf_counter() - t) / steps * 1e3


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (see the module docstring)."""
    ap = argparse.ArgumentParser(prog="python -m tensorholo_training.profile_step",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    ap.add_argument("--layers", type=int, default=8, help="hologram CNN depth (8, 15, 30)")
    ap.add_argument("--size", type=int, default=384, help="synthetic scene size in pixels (square)")
    ap.add_argument("--steps", type=int, default=20, help="steps per timed round and in the profile")
    ap.add_argument("--repeats", type=int, default=3, help="timed rounds per stage")
    ap.add_argument("--rows", type=int, default=14, help="operators per profiler table")
    ap.add_argument("--run-dir", help="where the synthetic dataset goes (default: a temporary folder)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        run_dir = args.run_dir or os.path.join(tmp, "run")
        sets = [f'device="{args.device}"', f"num_layers={args.layers}", f"synthetic_size={args.size}",
                'synthetic_counts={"train":16,"val":2}', "stage1_steps=1000000", "stage2_steps=1000000",
                "log_every=1000000", "val_every=1000000", "ckpt_every=1000000"]
        trainer = Trainer(load_config(SMALL_CPU, sets, run_dir), log=lambda m: None)
        batches = trainer._batches()
        for index, name in enumerate(["stage1", "stage2"]):
            if index:
                trainer.phase_index = index
                trainer._new_optimizer()
            time_steps(trainer, batches, max(1, args.steps // 4), args.device)
            ms = [time_steps(trainer, batches, args.steps, args.device) for _ in range(args.repeats)]
            print(f"{name}: {args.layers} layers, {args.size}x{args.size}, batch {trainer.cfg.batch_size}, "
                  f"{args.device}: ms per step " + ", ".join(f"{m:.1f}" for m in ms), flush=True)
            cuda = args.device.startswith("cuda")
            acts = [torch.profiler.ProfilerActivity.CPU] + ([torch.profiler.ProfilerActivity.CUDA] if cuda else [])
            with torch.profiler.profile(activities=acts) as prof:
                time_steps(trainer, batches, args.steps, args.device)
            table = prof.key_averages()
            for key in (["cuda_time_total"] if cuda else []) + ["cpu_time_total"]:
                print(f"{name}: {args.steps} steps by {key}", flush=True)
                print(table.table(sort_by=key, row_limit=args.rows, max_name_column_width=40), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

#!/usr/bin/env bash
# Retrains the hologram (and pre-filter) CNNs for the display a profile describes, in one command:
#
#   training/retrain.sh --display FILE [--layers 8|15|30] [--offsets-mm "6 12"] [--scale smoke|paper]
#                       [--nproc N] [--shards N] --out DIR
#
# Runs the dataset (`holo dataset --display FILE`; --shards N: N local `--shard I/N` processes, then --merge),
# stage 1, stage 2 for each offset (default: the profile's offsets_m), the f32 and int8 ONNX exports and the
# Table 2 evaluation, then prints the `holo render --display FILE --model …` line that uses the result.
# --scale smoke runs end to end in minutes on 2 CPU cores (a check, for CI and a first try); paper (default) is
# the paper's dataset and schedule. --nproc N trains under torchrun on N GPUs (or CPU processes) of this node.
# Rerunning the same command resumes. `--help` lists every option; docs/DISPLAYS.md, "Retraining for another
# display", gives the costs and the cluster versions (Slurm, Kubernetes).
#
# Environment: PYTHON (default <repo>/.venv/bin/python, created by training/install_ci.sh when missing, with
# PyTorch's CUDA build where nvidia-smi exists), HOLO (default: cargo build --release -p holo).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
py="${PYTHON:-$root/.venv/bin/python}"
if [ ! -x "$py" ]; then
  [ -z "${PYTHON:-}" ] || { echo "retrain: PYTHON=$PYTHON is not an executable" >&2; exit 2; }
  echo "== Python environment → $root/.venv (training/install_ci.sh)" >&2
  if command -v nvidia-smi >/dev/null; then export TENSORHOLO_TORCH_FULL=1; fi
  "$root/training/install_ci.sh" "$root/.venv"
fi
if [ -z "${HOLO:-}" ]; then
  echo "== holo → cargo build --release -p holo" >&2
  (cd "$root" && cargo build --release --locked -q -p holo)
  HOLO="${CARGO_TARGET_DIR:-$root/target}/release/holo"
fi
export HOLO PYTHONPATH="$root/training${PYTHONPATH:+:$PYTHONPATH}"
exec "$py" -m tensorholo_training.retrain "$@"

#!/usr/bin/env bash
# Reproduces one shipped model from scratch: dataset → stage 1 → stage 2 (DDPM; the pre-filter starts as AA-DPM) →
# ONNX f32 + int8 of the best validation checkpoint → Table 2 evaluation on the test split. It is
# training/retrain.sh at the paper's display and scale, with the shipped models' folders:
#
#   training/reproduce.sh LAYERS INPUT OFFSET_MM        e.g. training/reproduce.sh 30 rgbd 6
#
#   LAYERS 8 | 15 | 30;  INPUT rgbd | ldi;  OFFSET_MM 0 | 6 | 12 (0 = no pre-filter CNN)
#
# Environment (defaults = the paper): DATA (dataset folder, generated with `holo dataset` if missing;
# default data/mit-cgh-4k-v2), DISPLAY_PROFILE (default displays/pluto-8um.json, the paper's display; another
# profile makes the dataset at that display, and training takes the optics from the dataset's manifest), HOLO
# (holo binary; default: cargo build --release -p holo), STAGE1_EPOCHS (3000), STAGE2_EPOCHS (1000), PYTHON
# (default: .venv/bin/python), MODELS (models), RUNS (runs; give each display its own), NPROC (train on NPROC
# GPUs of this node: torchrun --standalone --nproc-per-node NPROC; the learning rate follows the global batch,
# training/README.md "Several GPUs or nodes"), SHARDS (make the dataset in SHARDS local processes).
# Runs resume: rerunning the same command continues from the last checkpoint of each step.
# Outputs: $RUNS/holo${LAYERS}_${INPUT}/stage1 (shared by the offsets), $RUNS/holo${LAYERS}_${INPUT}_${OFFSET}mm,
# $MODELS/holo${LAYERS}_${INPUT}_${OFFSET}mm{.onnx,.int8-qop.onnx,.int8-qdq.onnx,.prefilter*.onnx,.eval.json}.
set -euo pipefail
if [ $# -ne 3 ]; then sed -n '2,20p' "$0"; exit 2; fi
case "$1" in 8|15|30) ;; *) echo "LAYERS must be 8, 15 or 30" >&2; exit 2;; esac
case "$2" in rgbd|ldi) ;; *) echo "INPUT must be rgbd or ldi" >&2; exit 2;; esac
root="$(cd "$(dirname "$0")/.." && pwd)"
cd "$root"
runs="${RUNS:-runs}"
exec training/retrain.sh --display "${DISPLAY_PROFILE:-displays/pluto-8um.json}" --layers "$1" --input "$2" \
  --offsets-mm "$3" --scale paper --out "$runs" --data "${DATA:-data/mit-cgh-4k-v2}" --runs "$runs" \
  --models "${MODELS:-models}" --nproc "${NPROC:-0}" --shards "${SHARDS:-1}" \
  --stage1-epochs "${STAGE1_EPOCHS:-0}" --stage2-epochs "${STAGE2_EPOCHS:-0}"

#!/usr/bin/env bash
# Reproduces one shipped model from scratch: dataset → stage 1 → stage 2 (DDPM; the pre-filter starts as AA-DPM) →
# ONNX f32 + int8 of the best validation checkpoint → Table 2 evaluation on the test split.
#
#   training/reproduce.sh LAYERS INPUT OFFSET_MM        e.g. training/reproduce.sh 30 rgbd 6
#
#   LAYERS 8 | 15 | 30;  INPUT rgbd | ldi;  OFFSET_MM 0 | 6 | 12 (0 = no pre-filter CNN)
#
# Environment (defaults = the paper): DATA (dataset folder, generated with `holo dataset` if missing;
# default data/mit-cgh-4k-v2), DISPLAY_PROFILE (a display profile, docs/DISPLAYS.md: the dataset is made at
# that display; training takes the optics from the dataset's manifest), HOLO (holo binary; default:
# cargo run --release -p holo), STAGE1_EPOCHS (3000), STAGE2_EPOCHS (1000), PYTHON (default:
# .venv/bin/python), MODELS (models), RUNS (runs; give each display its own), NPROC (train on NPROC GPUs of
# this node: torchrun --standalone --nproc-per-node NPROC; the learning rate follows the global batch,
# training/README.md "Several GPUs or nodes").
# Runs resume: rerunning the same command continues from the last checkpoint of each step.
# Outputs: $RUNS/holo${LAYERS}_${INPUT}/stage1 (shared by the offsets), $RUNS/holo${LAYERS}_${INPUT}_${OFFSET}mm,
# $MODELS/holo${LAYERS}_${INPUT}_${OFFSET}mm{.onnx,.int8-qop.onnx,.int8-qdq.onnx,.prefilter*.onnx,.eval.json}.
set -euo pipefail
if [ $# -ne 3 ]; then sed -n '2,18p' "$0"; exit 2; fi
layers=$1 input=$2 offset=$3
case "$layers" in 8|15|30) ;; *) echo "LAYERS must be 8, 15 or 30" >&2; exit 2;; esac
case "$input" in rgbd) il=1;; ldi) il=5;; *) echo "INPUT must be rgbd or ldi" >&2; exit 2;; esac
root="$(cd "$(dirname "$0")/.." && pwd)"
cd "$root"
py="${PYTHON:-$root/.venv/bin/python}"
data="${DATA:-data/mit-cgh-4k-v2}"
models="${MODELS:-models}"
runs="${RUNS:-runs}"
name="holo${layers}_${input}_${offset}mm"
export PYTHONPATH="$root/training${PYTHONPATH:+:$PYTHONPATH}"

if [ ! -f "$data/manifest.json" ]; then
  echo "== dataset → $data (paper configuration: 3800/100/100 scenes, 384x384, 5 layers, 10000 planes)"
  if [ -n "${HOLO:-}" ]; then holo=("$HOLO"); else holo=(cargo run --release --locked -p holo --); fi
  "${holo[@]}" dataset --out "$data" --train 3800 --val 100 --test 100 --size 384 --layers 5 --levels 10000 \
    ${DISPLAY_PROFILE:+--display "$DISPLAY_PROFILE"}
fi
# The display the dataset was made for (manifest.json `optics`) is the one trained for: the trainer reads it
# from the manifest (stated once, in the dataset).
echo "== optics of $data: $("$py" -c 'import json, sys; print(json.load(open(sys.argv[1]))["optics"])' "$data/manifest.json")"

if [ -n "${NPROC:-}" ]; then
  train=("$py" -m torch.distributed.run --standalone --nproc-per-node "$NPROC" -m tensorholo_training.train)
else
  train=("$py" -m tensorholo_training.train)
fi

stage1="$runs/holo${layers}_${input}/stage1"
echo "== stage 1 → $stage1"
"${train[@]}" --config training/configs/gpu_stage1.json --run-dir "$stage1" \
  --set dataset="\"$data\"" --set num_layers="$layers" --set input_layers="$il" \
  --set stage1_epochs="${STAGE1_EPOCHS:-3000}"

run="$runs/$name"
echo "== stage 2 (offset $offset mm) → $run"
"${train[@]}" --config training/configs/gpu_stage2.json --run-dir "$run" \
  --set dataset="\"$data\"" --set num_layers="$layers" --set input_layers="$il" --set offset_mm="$offset" \
  --set init_from="\"$stage1/stage1.pt\"" \
  --set stage2_epochs="${STAGE2_EPOCHS:-1000}"

echo "== export → $models/$name*.onnx"
"$py" -m tensorholo_training.export --checkpoint "$run/best.pt" --out-dir "$models" --name "$name" --int8 \
  --calib-dataset "$data" --calib-samples 64

echo "== evaluate (Table 2 protocol, test split, what the SLM shows) → $models/$name.eval.json"
"$py" -m tensorholo_training.evaluate --checkpoint "$run/best.pt" --dataset "$data" --split test \
  --phase-only --out "$models/$name.eval.json"

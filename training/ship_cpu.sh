#!/usr/bin/env bash
# Reproduces the interim models shipped in models/ (trained on 2 CPU cores, no GPU; see models/MODEL_CARD.md):
#   hologram CNNs holo{8,15,30}_rgbd.onnx (stage 1, midpoint hologram, offset-independent) and the pre-filter
#   CNNs prefilter_{6,12}mm.onnx (DDPM stage 2 with the 8-layer hologram CNN frozen; the pre-filter corrects AA-DPM
#   and starts as AA-DPM; the best validation checkpoint best.pt is exported),
#   each in f32 and int8 (QOperator conv-only and QDQ), then the Table 2 evaluation on the test split.
#
#   the LDI hologram CNN holo8_ldi.onnx (stage 1 on 5-layer LDI input, on the photo-textured dataset),
#   the pre-filters of the 15- and 30-layer CNNs prefilter_{6,12}mm_holo{15,30}.onnx (DDPM stage 2 with that CNN
#   frozen, started from the shipped CNN and the 8-layer CNN's pre-filter, on the photo-textured dataset),
#
#   training/ship_cpu.sh [STEP ...]      STEP: dataset holo8 holo15 holo30 pre6 pre12 photos photo-dataset ldi8
#                                        pairs export eval eval-pairs (default: all)
#   then: training/make_shipped_fixtures.py (models/fixtures), holo baselines + evaluate (models/MODEL_CARD.md)
#
# Environment: DATA (default data/cpu256), PHOTO_DATA (default data/photo256: 1000/40/40 scenes of 256x256 with
# 60 % of the textures from the 10 public-domain/CC0 photos of scikit-image 0.26.0 that `photos` extracts into
# data/photos; models/MODEL_CARD.md lists them), HOLO (holo binary; default target/release/holo, built if missing),
# PYTHON (default .venv/bin/python), MODELS (default models), RUNS (default runs/cpu),
# STEPS8/STEPS15/STEPS30 (stage-1 steps, default 4000/4000/5000), PRE_STEPS (stage 2, default 4000),
# EVAL_LIMIT (test scenes evaluated, default 10).
# Every step resumes from its last checkpoint when rerun.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
cd "$root"
py="${PYTHON:-$root/.venv/bin/python}"
data="${DATA:-data/cpu256}"
photo_data="${PHOTO_DATA:-data/photo256}"
models="${MODELS:-models}"
runs="${RUNS:-runs/cpu}"
holo="${HOLO:-target/release/holo}"
export PYTHONPATH="$root/training${PYTHONPATH:+:$PYTHONPATH}"
steps=("$@")
[ ${#steps[@]} -eq 0 ] && steps=(dataset holo8 holo15 holo30 pre6 pre12 photos photo-dataset ldi8 pairs export eval
  eval-pairs)

stage1() {  # LAYERS STEPS
  "$py" -m tensorholo_training.train --config training/configs/cpu_stage1.json --run-dir "$runs/holo$1" \
    --set dataset="\"$data\"" --set num_layers="$1" --set stage1_steps="$2"
}
prefilter() {  # OFFSET_MM
  "$py" -m tensorholo_training.train --config training/configs/cpu_prefilter.json --run-dir "$runs/pre$1" \
    --set dataset="\"$data\"" --set offset_mm="$1" --set init_from="\"$runs/holo8/stage1.pt\"" \
    --set stage2_steps="${PRE_STEPS:-4000}"
}
for step in "${steps[@]}"; do
  echo "== $step"
  case "$step" in
    dataset)
      if [ ! -f "$data/manifest.json" ]; then
        [ -x "$holo" ] || cargo build --release --locked -p holo
        "$holo" dataset --out "$data" --train 600 --val 40 --test 40 --size 256 --levels 2048 --seed 2026
      fi ;;
    photos)  # public-domain / CC0 sample images of scikit-image's wheel (sources and licences: MODEL_CARD.md)
      if [ ! -f data/photos/gravel.png ]; then
        tmp="$(mktemp -d)"
        "$py" -m pip download --quiet --no-deps --dest "$tmp" scikit-image==0.26.0
        mkdir -p data/photos
        "$py" - "$tmp" <<'PY'
import sys, zipfile, pathlib
wheel = next(pathlib.Path(sys.argv[1]).glob("scikit_image-*.whl"))
names = ["astronaut.png", "chelsea.png", "coffee.png", "rocket.jpg", "hubble_deep_field.jpg", "retina.jpg",
         "brick.png", "grass.png", "gravel.png", "camera.png"]
with zipfile.ZipFile(wheel) as z:
    for n in names:
        pathlib.Path("data/photos", n).write_bytes(z.read(f"skimage/data/{n}"))
PY
        rm -rf "$tmp"
      fi ;;
    photo-dataset)
      if [ ! -f "$photo_data/manifest.json" ]; then
        [ -x "$holo" ] || cargo build --release --locked -p holo
        "$holo" dataset --out "$photo_data" --train 1000 --val 40 --test 40 --size 256 --levels 2048 --seed 2027 \
          --photos data/photos --photo-probability 0.6
      fi ;;
    pairs)  # a pre-filter per CNN depth and offset, from the shipped files (no checkpoint of them is needed)
      for l in 30 15; do
        for o in 6 12; do
          "$py" -m tensorholo_training.train --config training/configs/cpu_prefilter.json \
            --run-dir "runs/photo/pre${o}_holo$l" --set dataset="\"$photo_data\"" --set num_layers="$l" \
            --set offset_mm="$o" --set init_from="\"$models/holo${l}_rgbd.onnx\"" \
            --set init_prefilter_from="\"$models/prefilter_${o}mm.onnx\"" --set stage2_steps="${PAIR_STEPS:-2000}"
        done
      done ;;
    ldi8)  # an RGB-D CNN on the photo data, the LDI CNN started from it (holo8_ldi), the RGB-D one continued
      ldi_stage1() {  # RUN INPUT_LAYERS STEPS [INIT]
        "$py" -m tensorholo_training.train --config training/configs/cpu_stage1.json --run-dir "runs/photo/$1" \
          --set dataset="\"$photo_data\"" --set num_layers=8 --set input_layers="$2" --set stage1_steps="$3" \
          ${4:+--set init_from="\"$4\""}
      }
      ldi_stage1 holo8 1 4000
      ldi_stage1 holo8_ldi_ws 5 4000 runs/photo/holo8/best.pt
      ldi_stage1 holo8 1 8000 ;;
    holo8) stage1 8 "${STEPS8:-4000}" ;;
    holo15) stage1 15 "${STEPS15:-4000}" ;;
    holo30) stage1 30 "${STEPS30:-5000}" ;;
    pre6) prefilter 6 ;;
    pre12) prefilter 12 ;;
    export)
      mkdir -p "$models"
      for l in 8 15 30; do
        # the best validation checkpoint; final.pt for runs older than best.pt (the shipped holo8)
        ck="$runs/holo$l/best.pt"; [ -f "$ck" ] || ck="$runs/holo$l/final.pt"
        "$py" -m tensorholo_training.export --checkpoint "$ck" --out-dir "$models" \
          --name "holo${l}_rgbd" --no-prefilter --int8 --calib-dataset "$data" --calib-samples 32 --calib-size 128
      done
      for l in 15 30; do
        for o in 6 12; do
          "$py" -m tensorholo_training.export --checkpoint "runs/photo/pre${o}_holo$l/best.pt" --out-dir "$models" \
            --name "prefilter_${o}mm_holo$l" --prefilter-only --int8 --calib-dataset "$photo_data" --calib-samples 32 \
            --calib-size 128
        done
      done
      "$py" -m tensorholo_training.export --checkpoint runs/photo/holo8_ldi_ws/best.pt --out-dir "$models" \
        --name holo8_ldi --no-prefilter --int8 --calib-dataset "$photo_data" --calib-samples 32 --calib-size 128
      for o in 6 12; do
        "$py" -m tensorholo_training.export --checkpoint "$runs/pre$o/best.pt" --out-dir "$models" \
          --name "prefilter_${o}mm" --prefilter-only --int8 --calib-dataset "$data" --calib-samples 32 --calib-size 128
      done ;;
    eval)
      mkdir -p "$models/eval"
      for l in 8 15 30; do
        for prec in "" .int8-qop .int8-qdq; do
          "$py" -m tensorholo_training.evaluate --onnx "$models/holo${l}_rgbd$prec.onnx" --dataset "$data" \
            --split test --limit "${EVAL_LIMIT:-10}" --out "$models/eval/holo${l}_rgbd$prec.json"
        done
        for o in 6 12; do  # displayed: DDPM (the pre-filter CNN) and AA-DPM (the non-learned blur) of the same CNN
          "$py" -m tensorholo_training.evaluate --onnx "$models/holo${l}_rgbd.onnx" \
            --prefilter-onnx "$models/prefilter_${o}mm.onnx" --offset-mm "$o" --phase-only --dataset "$data" \
            --split test --limit "${EVAL_LIMIT:-10}" --out "$models/eval/holo${l}_rgbd+prefilter_${o}mm.json"
          "$py" -m tensorholo_training.evaluate --onnx "$models/holo${l}_rgbd.onnx" --aa-dpm \
            --offset-mm "$o" --phase-only --dataset "$data" \
            --split test --limit "${EVAL_LIMIT:-10}" --out "$models/eval/holo${l}_rgbd+aadpm_${o}mm.json"
        done
      done
      for o in 6 12; do  # the int8 pipeline: int8 hologram CNN + int8 pre-filter of the same form
        for prec in .int8-qop .int8-qdq; do
          "$py" -m tensorholo_training.evaluate --onnx "$models/holo8_rgbd$prec.onnx" \
            --prefilter-onnx "$models/prefilter_${o}mm$prec.onnx" --offset-mm "$o" --phase-only --dataset "$data" \
            --split test --limit "${EVAL_LIMIT:-10}" --out "$models/eval/holo8_rgbd+prefilter_${o}mm$prec.json"
        done
      done ;;
    eval-pairs)  # displayed quality of each CNN depth: AA-DPM, the 8-layer CNN's pre-filter, its own (f32, int8)
      out="$models/eval/pairs"; mkdir -p "$out"
      pair_eval() {  # NAME EVALUATE-ARGS...
        local name=$1; shift
        "$py" -m tensorholo_training.evaluate "$@" --phase-only --dataset "$photo_data" --split test \
          --limit "${PAIR_EVAL_LIMIT:-20}" --out "$out/$name.json"
      }
      for o in 6 12; do
        pair_eval "holo8+pre${o}" --onnx "$models/holo8_rgbd.onnx" --prefilter-onnx "$models/prefilter_${o}mm.onnx" \
          --offset-mm "$o"
        pair_eval "holo8+aadpm${o}" --onnx "$models/holo8_rgbd.onnx" --aa-dpm --offset-mm "$o"
        for l in 15 30; do
          for prec in "" .int8-qdq; do
            pair_eval "holo$l+own$o$prec" --onnx "$models/holo${l}_rgbd$prec.onnx" \
              --prefilter-onnx "$models/prefilter_${o}mm_holo$l$prec.onnx" --offset-mm "$o"
          done
          pair_eval "holo$l+pre8_$o" --onnx "$models/holo${l}_rgbd.onnx" \
            --prefilter-onnx "$models/prefilter_${o}mm.onnx" --offset-mm "$o"
          pair_eval "holo$l+aadpm$o" --onnx "$models/holo${l}_rgbd.onnx" --aa-dpm --offset-mm "$o"
        done
      done ;;
    *) echo "unknown step $step" >&2; exit 2 ;;
  esac
done

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
#   the photo-trained CNNs: holo30 and holo15 continued on the photo-textured dataset (holo8's photo run is
#   ldi8's RGB-D one), and a pre-filter per offset for each of them (their CNN frozen),
#
#   training/ship_cpu.sh [STEP ...]      STEP: dataset holo8 holo15 holo30 pre6 pre12 photos photo-dataset ldi8
#                                        pairs photo-cnn photo-pairs real-inputs export eval eval-pairs
#                                        eval-real; qat (an experiment, not in the default list)
#                                        (default: all)
#   then: training/make_shipped_fixtures.py (models/fixtures), holo baselines + evaluate (models/MODEL_CARD.md)
#
# Environment: DATA (default data/cpu256), PHOTO_DATA (default data/photo256: 1000/40/40 scenes of 256x256 with
# 60 % of the textures from the 10 public-domain/CC0 photos of scikit-image 0.26.0 that `photos` extracts into
# data/photos; models/MODEL_CARD.md lists them), HOLO (holo binary; default target/release/holo, built if missing),
# PYTHON (default .venv/bin/python), MODELS (default models), RUNS (default runs/cpu),
# STEPS8/STEPS15/STEPS30 (stage-1 steps, default 4000/4000/5000), PRE_STEPS (stage 2, default 4000),
# STEPS_PHOTO30/STEPS_PHOTO15 (photo-cnn, default 6000 each), PAIR_STEPS / PHOTO_PAIR_STEPS (pairs / photo-pairs,
# default 2000 / 3000), QAT_STEPS (qat, default 600), SHIPPED_BEFORE (see below),
# EVAL_LIMIT (test scenes evaluated, default 10), EVAL_LAYERS (the CNN depths of eval, eval-pairs and eval-real,
# default "8 15 30").
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
# the commit whose models/ the photo-cnn and photo-pairs steps start from (the files shipped before them)
SHIPPED_BEFORE="${SHIPPED_BEFORE:-c2e4cdb}"
export PYTHONPATH="$root/training${PYTHONPATH:+:$PYTHONPATH}"
steps=("$@")
[ ${#steps[@]} -eq 0 ] && steps=(dataset holo8 holo15 holo30 pre6 pre12 photos photo-dataset ldi8 pairs photo-cnn
  photo-pairs real-inputs export eval eval-pairs eval-real)

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
      ldi_stage1() {  # RUN INPUT_LAYERS STEPS [INIT [TRAIN-ARGS...]]
        local run=$1 layers=$2 n=$3 init=${4:-}
        shift $(( $# < 4 ? $# : 4 ))
        "$py" -m tensorholo_training.train --config training/configs/cpu_stage1.json --run-dir "runs/photo/$run" \
          --set dataset="\"$photo_data\"" --set num_layers=8 --set input_layers="$layers" --set stage1_steps="$n" \
          ${init:+--set init_from="\"$init\""} "$@"
      }
      ldi_stage1 holo8 1 4000
      ldi_stage1 holo8_ldi_ws 5 4000 runs/photo/holo8/best.pt
      ldi_stage1 holo8 1 8000
      # the shipped holo8_ldi: started again from the RGB-D CNN's best checkpoint (step 7500, the shipped
      # holo8), 2000 steps with a cosine learning rate
      ldi_stage1 holo8_ldi_v2 5 "${STEPS_LDI:-2000}" runs/photo/holo8/best.pt --set lr_schedule='"cosine"' ;;
    photo-cnn)  # holo30 and holo15 continued on the photo data from the files shipped before (cosine decay)
      mkdir -p runs/photo/init
      for l in 30 15; do
        init="runs/photo/init/holo${l}_rgbd.onnx"
        [ -f "$init" ] || git show "$SHIPPED_BEFORE:models/holo${l}_rgbd.onnx" > "$init"
        n="${STEPS_PHOTO30:-6000}"; [ "$l" = 15 ] && n="${STEPS_PHOTO15:-6000}"
        "$py" -m tensorholo_training.train --config training/configs/cpu_stage1.json --run-dir "runs/photo/holo$l" \
          --set dataset="\"$photo_data\"" --set num_layers="$l" --set stage1_steps="$n" \
          --set init_from="\"$init\"" --set lr_schedule='"cosine"'
      done ;;
    photo-pairs)  # a pre-filter per offset for each photo-trained CNN (runs/photo/holo{30,8,15}), CNN frozen,
      # started from the pre-filter of the same depth trained before (pairs; for 8 layers the shipped file)
      mkdir -p runs/photo/init
      for l in 30 8 15; do
        for o in 6 12; do
          pre="runs/photo/pre${o}_holo$l/best.pt"
          if [ "$l" = 8 ]; then
            pre="runs/photo/init/prefilter_${o}mm.onnx"
            [ -f "$pre" ] || git show "$SHIPPED_BEFORE:models/prefilter_${o}mm.onnx" > "$pre"
          fi
          "$py" -m tensorholo_training.train --config training/configs/cpu_prefilter.json \
            --run-dir "runs/photo/pre${o}_photo$l" --set dataset="\"$photo_data\"" --set num_layers="$l" \
            --set offset_mm="$o" --set init_from="\"runs/photo/holo$l/best.pt\"" \
            --set init_prefilter_from="\"$pre\"" --set stage2_steps="${PHOTO_PAIR_STEPS:-3000}" \
            --set lr_schedule='"cosine"'
        done
      done ;;
    holo8) stage1 8 "${STEPS8:-4000}" ;;
    holo15) stage1 15 "${STEPS15:-4000}" ;;
    holo30) stage1 30 "${STEPS30:-5000}" ;;
    pre6) prefilter 6 ;;
    pre12) prefilter 12 ;;
    qat)  # an experiment, not shipped (models/MODEL_CARD.md, "int8: what did not help"): each pre-filter fine-tuned
      # with its int8 roundings in the loop (tensorholo_training.qat), CNN frozen, 600 steps: its convolutions read
      # u8-rounded inputs on the grids of its own int8 file (exported first, percentile calibration) with s8 weights
      for l in 8 15 30; do
        for o in 6 12; do
          run="runs/photo/qat_pre${o}_photo$l"
          "$py" -m tensorholo_training.export --checkpoint "runs/photo/pre${o}_photo$l/best.pt" --out-dir "$run" \
            --name grids --prefilter-only --int8-only --calib-dataset "$photo_data" --calib-samples 32 \
            --calib-size 128 --calib-npy runs/real_inputs/rgbd/*.npy --calib-method percentile
          "$py" -m tensorholo_training.train --config training/configs/cpu_prefilter.json --run-dir "$run" \
            --set dataset="\"$photo_data\"" --set num_layers="$l" --set offset_mm="$o" \
            --set init_from="\"runs/photo/pre${o}_photo$l/best.pt\"" --set stage2_steps="${QAT_STEPS:-600}" \
            --set lr=5e-5 --set lr_schedule='"cosine"' --set val_every=100 \
            --set qat_grids_from="\"$run/grids.int8-qdq.onnx\""
        done
      done ;;
    real-inputs)  # the hologram CNN inputs of the real frames of ../shared/data (int8 calibration)
      [ -x "$holo" ] || cargo build --release --locked -p holo
      HOLO="$holo" "$py" training/real_frames.py inputs --dir runs/real_inputs/rgbd -- --layers 8 ;;
    export)  # best.pt of each photo run; int8: 32 dataset crops + 4 crops of each real frame, per-channel weights;
      # the pre-filters' int8 files in mixed precision (first and last convolutions float, MODEL_CARD.md)
      mkdir -p "$models"
      calib=(--int8 --calib-dataset "$photo_data" --calib-samples 32 --calib-size 128)
      for l in 8 15 30; do
        "$py" -m tensorholo_training.export --checkpoint "runs/photo/holo$l/best.pt" --out-dir "$models" \
          --name "holo${l}_rgbd" --no-prefilter "${calib[@]}" --calib-npy runs/real_inputs/rgbd/*.npy
        for o in 6 12; do
          name="prefilter_${o}mm_holo$l"; [ "$l" = 8 ] && name="prefilter_${o}mm"
          "$py" -m tensorholo_training.export --checkpoint "runs/photo/pre${o}_photo$l/best.pt" --out-dir "$models" \
            --name "$name" --prefilter-only "${calib[@]}" --calib-npy runs/real_inputs/rgbd/*.npy \
            --float-convs first last
        done
      done
      "$py" -m tensorholo_training.export --checkpoint runs/photo/holo8_ldi_v2/best.pt --out-dir "$models" \
        --name holo8_ldi --no-prefilter "${calib[@]}" --calib-npy runs/real_inputs/rgbd/*.npy ;;
    eval)  # the original split (data/cpu256): midpoint per precision; displayed with its own pre-filter (f32 and
      # both int8 forms) and with AA-DPM
      mkdir -p "$models/eval"
      ev() {  # OUT EVALUATE-ARGS...
        local name=$1; shift
        "$py" -m tensorholo_training.evaluate "$@" --dataset "$data" --split test --limit "${EVAL_LIMIT:-10}" \
          --out "$models/eval/$name.json"
      }
      for l in ${EVAL_LAYERS:-8 15 30}; do
        for prec in "" .int8-qop .int8-qdq; do
          ev "holo${l}_rgbd$prec" --onnx "$models/holo${l}_rgbd$prec.onnx"
        done
        for o in 6 12; do
          own="prefilter_${o}mm_holo$l"; [ "$l" = 8 ] && own="prefilter_${o}mm"
          for prec in "" .int8-qop .int8-qdq; do  # int8: both CNNs in the same form
            ev "holo${l}_rgbd+prefilter_${o}mm$prec" --onnx "$models/holo${l}_rgbd$prec.onnx" \
              --prefilter-onnx "$models/$own$prec.onnx" --offset-mm "$o" --phase-only
          done
          ev "holo${l}_rgbd+aadpm_${o}mm" --onnx "$models/holo${l}_rgbd.onnx" --aa-dpm --offset-mm "$o" --phase-only
        done
      done ;;
    eval-pairs)  # the natural-texture split (data/photo256): each CNN with its own pre-filter, f32 and int8 QDQ
      out="$models/eval/pairs"; mkdir -p "$out"
      for l in ${EVAL_LAYERS:-8 15 30}; do
        for o in 6 12; do
          own="prefilter_${o}mm_holo$l"; [ "$l" = 8 ] && own="prefilter_${o}mm"
          for prec in "" .int8-qdq; do
            "$py" -m tensorholo_training.evaluate --onnx "$models/holo${l}_rgbd$prec.onnx" \
              --prefilter-onnx "$models/$own$prec.onnx" --offset-mm "$o" --phase-only --dataset "$photo_data" \
              --split test --limit "${PAIR_EVAL_LIMIT:-20}" --out "$out/holo$l+own$o$prec.json"
          done
        done
      done ;;
    eval-real)  # Table 2 on the real frames of ../shared/data (holo render --evaluate, SM-LBM 2048 planes), 6 mm,
      # each CNN with its own pre-filter, f32 and int8 QDQ on the native engine (training/real_frames.py)
      [ -x "$holo" ] || cargo build --release --locked -p holo
      for l in ${EVAL_LAYERS:-8 15 30}; do
        HOLO="$holo" "$py" training/real_frames.py evaluate --out "$models/eval/real" --name "holo$l" -- \
          --layers "$l"
        HOLO="$holo" "$py" training/real_frames.py evaluate --out "$models/eval/real" --name "holo$l.int8-qdq" -- \
          --layers "$l" --precision int8-qdq --engine native
      done
      "$py" training/real_frames.py table --out "$models/eval/real" holo8 holo8.int8-qdq holo15 holo15.int8-qdq \
        holo30 holo30.int8-qdq ;;
    *) echo "unknown step $step" >&2; exit 2 ;;
  esac
done

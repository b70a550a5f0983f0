#!/usr/bin/env bash
# Two `holo` release builds compared, A/B, on any machine (figures: docs/GPU.md "NVIDIA H100 through Vulkan",
# docs/BENCHMARKS.md "The H100 machine's Intel Xeon"): the two builds alternated, two rounds each:
#   1. the GPU path (Vulkan) at 384² and 1080×1920, holo8 and holo30 (frames, then each stage on its own);
#   2. the CPU frame at 1080×1920, holo8 + 6 mm pre-filter, int8 and f32, on 2 cores (taskset) and on all;
#   3. the new build's f32 CNN with its measured algorithm choice against TENSORHOLO_CONV=direct and
#      =winograd (F(2×2, 3×3)), with the choices it logged.
#
#   benchmarks/ab_compare.sh OLD_HOLO NEW_HOLO [OUT_DIR]
#
# Where the Vulkan loader is missing, unpack Debian's libvulkan1 first (the GPU rows then fail with a clear
# "no adapter" error and the CPU rows still run; SKIP_GPU=1 leaves them out). Prints Markdown rows (frame
# columns: CNN, offset, pre-filter, DPM + LUT, frame, FPS, stream FPS, setup ms); OUT_DIR (default .) keeps the
# logs. On a machine of 2 cores the two CPU tables are the same case twice.
set -uo pipefail
OLD="${1:?old holo}"; NEW="${2:?new holo}"; OUT="${3:-.}"
mkdir -p "$OUT"
export RUST_LOG=warn
N=$(nproc)
lscpu | grep -E "Model name|^CPU\(s\)"
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
for r in 1 2; do
  [ -n "${SKIP_GPU:-}" ] && break
  for b in "$OLD" "$NEW"; do
    echo "== GPU, round $r: $b"
    timeout 120 "$b" bench --skip-cnn --backend gpu --precision f32 --sizes 384x384,1080x1920 --layers 8,30 \
      --repeat 10 --max-seconds 4 --gpu-precision auto 2>&1 | grep -E "^\| holo" | tee -a "$OUT/gpu.txt"
  done
done
# cpu_rounds LABEL LOG FIELDS PREFIX ARGS: two rounds of int8 and f32, old and new alternated; each run's
# `holo bench` rows (columns FIELDS) appended to $OUT/LOG. PREFIX (e.g. taskset) and ARGS are word lists.
cpu_rounds() {
  local label=$1 log=$2 fields=$3 prefix=$4 args=$5
  for r in 1 2; do
    for p in int8-qdq f32; do
      for b in "$OLD" "$NEW"; do
        echo -n "CPU, $label, round $r, $p, $b: "
        # shellcheck disable=SC2086
        timeout 120 $prefix "$b" bench --skip-cnn --layers 8 --precision "$p" $args 2>&1 | grep "^| holo8" \
          | cut -d'|' -f"$fields" | tr '\n' ' ' | tee -a "$OUT/$log"
        echo
      done
    done
  done
}
cpu_rounds "2 cores" cpu2.txt 7-14 "taskset -c 0,1" "--sizes 1080x1920 --threads 2 --repeat 7"
cpu_rounds "$N threads" cpuN.txt 5-14 "" "--sizes 1080x1920,384x384 --threads $N --repeat 9"
RUST_LOG=tensorholo::cnn::native::algorithm=debug timeout 60 "$NEW" bench --skip-cnn --sizes 1080x1920 \
  --layers 8 --precision f32 --threads "$N" --repeat 1 2>&1 | grep -E "conv [0-9]" | tee "$OUT/choices.txt"
for r in 1 2; do
  for c in auto direct winograd; do
    echo -n "f32 CNN, $N threads, round $r, TENSORHOLO_CONV=$c: "
    TENSORHOLO_CONV=$c timeout 60 "$NEW" bench --skip-cnn --sizes 1080x1920 --layers 8 --precision f32 \
      --threads "$N" --repeat 5 2>&1 | grep "^| holo8" | cut -d'|' -f7-11 | tee -a "$OUT/algorithms.txt"
  done
  for c in auto direct; do
    echo -n "f32 CNN, 2 cores, round $r, TENSORHOLO_CONV=$c: "
    TENSORHOLO_CONV=$c timeout 60 taskset -c 0,1 "$NEW" bench --skip-cnn --sizes 1080x1920 --layers 8 \
      --precision f32 --threads 2 --repeat 3 2>&1 | grep "^| holo8" | cut -d'|' -f7-11 | tee -a "$OUT/algorithms.txt"
  done
done

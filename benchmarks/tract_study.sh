#!/usr/bin/env bash
# The tract speed study of docs/BENCHMARKS.md: one CNN case under each convolution path tract 0.23 offers,
# selected with tract's own knobs (environment variables read when a plan is optimised) and with
# `holo bench --layout`. Prints one Markdown row per configuration and thread count.
#
#   benchmarks/tract_study.sh                      # holo8 f32 at 384x384, 1 and 2 threads
#   LAYERS=30 SIZES=1080x1920 REPEAT=1 benchmarks/tract_study.sh
#
# HOLO (default target/release/holo) must be a release build: cargo build --release -p holo
set -euo pipefail
cd "$(dirname "$0")/.."
HOLO="${HOLO:-target/release/holo}"
[ -x "$HOLO" ] || { echo "no $HOLO: run cargo build --release -p holo first" >&2; exit 1; }
EAGER="TRACT_LAZY_IM2COL_MIN_KERNEL=1000000 TRACT_LAZY_IM2COL_MAX_EAGER_BYTES=1000000000000"
# name | layout | environment
CONFIGS=(
  "nchw direct spatial conv (tract's default)|nchw|"
  "nchw lazy im2col + matmul|nchw|TRACT_DISABLE_DIRECT_SPATIAL=1"
  "nchw eager im2col + matmul|nchw|TRACT_DISABLE_DIRECT_SPATIAL=1 $EAGER"
  "nchw lazy im2col + AMX bf16 matmul|nchw|TRACT_DISABLE_DIRECT_SPATIAL=1 TRACT_AMX_BF16=1"
  "nchw eager im2col + AMX bf16 matmul|nchw|TRACT_DISABLE_DIRECT_SPATIAL=1 $EAGER TRACT_AMX_BF16=1"
  "nhwc lazy im2col + matmul (--layout nhwc)|nhwc|"
  "nhwc eager im2col + matmul|nhwc|$EAGER"
  "nhwc lazy im2col + AMX bf16 matmul|nhwc|TRACT_AMX_BF16=1"
)
echo "| configuration | threads | ms | GFLOP/s |"
echo "|---|---:|---:|---:|"
for c in "${CONFIGS[@]}"; do
  IFS='|' read -r name layout envs <<<"$c"
  # shellcheck disable=SC2086
  env $envs "$HOLO" bench --skip-pipeline --layers "${LAYERS:-8}" --precision f32 --layout "$layout" \
      --sizes "${SIZES:-384x384}" --threads "${THREADS:-1,2}" --repeat "${REPEAT:-5}" --max-seconds 60 |
    awk -F'|' -v n="$name" '/^\| holo/ { gsub(/ /, "", $6); printf "| %s | %s | %s | %s |\n", n, $6, $7, $9 }'
done

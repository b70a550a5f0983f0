#!/usr/bin/env bash
# Runs every cargo-fuzz target of tensorholo for SECONDS each (default 240), one after the other, and prints a
# summary line per target: executions, coverage (edges, features), corpus size, peak memory, findings.
# Needs nightly and cargo-fuzz (`cargo install cargo-fuzz`); seeds: docs/FUZZING.md. Usage:
#   fuzz/run.sh [SECONDS] [TARGET...]
set -euo pipefail
cd "$(dirname "$0")"
seconds=${1:-240}
shift || true
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(depth_decode rgb_decode npy holocal camera_frame onnx_model display_profile aberration shard_record manifest spot_plan saved_plans exr_depth record3d_metadata stray_odometry stray_camera_matrix)
fi
cargo +nightly fuzz build -O
mkdir -p logs
for t in "${targets[@]}"; do
    mkdir -p "corpus/$t" "artifacts/$t"
    touch "logs/$t.start"
    # -malloc_limit_mb: a single allocation above 2 GiB is a finding (the input limits should prevent it).
    cargo +nightly fuzz run -O "$t" "corpus/$t" -- -max_total_time="$seconds" -timeout=20 \
        -rss_limit_mb=3072 -malloc_limit_mb=2048 -print_final_stats=1 \
        -artifact_prefix="artifacts/$t/" >"logs/$t.log" 2>&1 || true
    done_line=$(grep -E '^#[0-9]+\s+DONE' "logs/$t.log" | tail -1 || true)
    execs=$(grep -oE 'stat::number_of_executed_units:\s+[0-9]+' "logs/$t.log" | grep -oE '[0-9]+$' || echo "?")
    rss=$(grep -oE 'stat::peak_rss_mb:\s+[0-9]+' "logs/$t.log" | grep -oE '[0-9]+$' || echo "?")
    cov=$(grep -oE 'cov: [0-9]+ ft: [0-9]+ corp: [0-9]+/[0-9]+[a-zA-Z]*' <<<"$done_line" || echo "?")
    # Coverage when 80 % of the executions had run: how close the target is to a plateau.
    total=${execs:-0}
    cov80=$(awk -v T="$total" '/^#[0-9]+/ { n = substr($1, 2) + 0; for (i = 1; i <= NF; i++) if ($i == "cov:") c = $(i + 1); if (n <= 0.8 * T) c80 = c } END { print c80 }' "logs/$t.log")
    findings=$(find "artifacts/$t" -type f -newer "logs/$t.start" | wc -l)
    echo "$t: ${seconds} s, ${execs} executions, ${cov} (cov ${cov80} at 80 % of the executions), peak RSS ${rss} MB, findings ${findings}"
done

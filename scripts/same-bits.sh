#!/usr/bin/env bash
# Usage: scripts/same-bits.sh [HOLO] [SIZE ...]
#
# The same command gives the same bits: runs `holo render` with its defaults three times at each size
# (default 384x384 and 1080x1920), each run a process of its own, with a busy loop on one core beside them
# (what a loaded machine does to anything that times its choices), and compares midpoint.npy and the three
# SLM code planes byte for byte. Exit 1, naming the file and the runs, where any differ.
#
# HOLO: the binary (default target/debug/holo, what `cargo test` builds; CI runs this after the tests).
# Each run's report says where its CNN plans came from (report.json → cnn_plan.source: the plan table).
set -euo pipefail
cd "$(dirname "$0")/.."

holo="${1:-target/debug/holo}"
shift || true
sizes=("$@")
[ ${#sizes[@]} -gt 0 ] || sizes=(384x384 1080x1920)
if [ ! -x "$holo" ]; then
  echo "same-bits.sh: no holo binary at $holo (cargo build -p holo first)" >&2
  exit 2
fi

out="$(mktemp -d "${TMPDIR:-/tmp}/same-bits.XXXXXX")"
# The busy loop: one core spinning for as long as the runs take.
bash -c 'while :; do :; done' &
busy=$!
trap 'kill "$busy" 2>/dev/null || true; rm -rf "$out"' EXIT

status=0
for size in "${sizes[@]}"; do
  for run in 1 2 3; do
    start=$(date +%s)
    "$holo" render --size "$size" --repeat 0 --out "$out/$size-$run" >"$out/$size-$run.log" 2>&1 || {
      cat "$out/$size-$run.log" >&2
      echo "same-bits.sh: holo render --size $size failed (run $run)" >&2
      exit 1
    }
    source=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["cnn_plan"]["source"])' \
      "$out/$size-$run/report.json" 2>/dev/null || echo "?")
    echo "== $size, run $run: $(( $(date +%s) - start )) s, plans from the $source"
  done
  for run in 2 3; do
    for f in midpoint.npy phase_r.png phase_g.png phase_b.png; do
      if ! cmp -s "$out/$size-1/$f" "$out/$size-$run/$f"; then
        echo "same-bits.sh: $size: $f differs between run 1 and run $run" >&2
        status=1
      fi
    done
  done
  [ "$status" = 0 ] && echo "== $size: midpoint.npy and phase_{r,g,b}.png byte-identical in 3 runs"
done
exit "$status"

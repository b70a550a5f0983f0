#!/usr/bin/env bash
# Usage: scripts/cluster/test-slurm.sh [HOLO]
#
# Runs the shipped Slurm files on a real one-node cluster (scripts/cluster/slurm-local.sh: Debian's slurm-wlm
# and munge on localhost): submit-dataset.sh submits a 3-task job array of `holo dataset --shard auto` and
# its merge job (--dependency=afterok), waits for them, and checks that the dataset equals a one-process
# run: every shard byte for byte, the manifest up to timings and command line. Then a merge job whose
# array fails must never run (its dependency is never satisfied). HOLO: the `holo` to run (default
# target/debug/holo). Needs root (or password-less sudo) for the daemons; stops them at the end unless
# KEEP_SLURM=1.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
holo="$(realpath "${1:-$root/target/debug/holo}")"
[ -x "$holo" ] || { echo "test-slurm: build holo first (cargo build -p holo), or pass its path" >&2; exit 2; }
sudo=()
[ "$(id -u)" = 0 ] || sudo=(sudo -n)
"${sudo[@]}" "$here/slurm-local.sh" start
work="$(mktemp -d /tmp/holo-slurm.XXXXXX)"
chmod 755 "$work"
tiny=(--train 5 --val 2 --test 1 --size 32 --levels 16 --shard-size 2 --previews 0)

"$holo" dataset "${tiny[@]}" --threads 1 --out "$work/one" 2>/dev/null
cd "$work"
read -r array merge < <(HOLO="$holo" SBATCH_ARGS="--cpus-per-task=1" "$here/submit-dataset.sh" 3 \
  "$work/sharded" "${tiny[@]}" | tail -1)
echo "test-slurm: array job $array, merge job $merge"

# Wait until both jobs have left the queue; a merge held by a dependency that can never be met fails.
wait_jobs() {
  local t
  for t in $(seq 600); do
    local left
    left="$(squeue -h -j "$1" -o '%i %T %r' 2>/dev/null || true)"
    [ -z "$left" ] && return 0
    if grep -q DependencyNeverSatisfied <<<"$left"; then
      echo "$left"
      return 3
    fi
    sleep 1
  done
  echo "test-slurm: jobs $1 still queued after 600 s" >&2
  return 1
}
wait_jobs "$array,$merge"
for f in "$work"/holo-dataset*.out; do
  [ -s "$f" ] && { echo "--- $f"; cat "$f"; }
done
[ -f "$work/sharded/manifest.json" ] || { echo "test-slurm: the merge job wrote no manifest" >&2; exit 1; }
shards=0
for f in "$work"/one/*.npz; do
  cmp "$f" "$work/sharded/$(basename "$f")"
  shards=$((shards + 1))
done
python3 - "$work/one/manifest.json" "$work/sharded/manifest.json" <<'PY'
import json, sys
def content(path):
    m = json.load(open(path))
    m["created_unix_s"] = m["generator"]["command"] = None
    for k in ("mean_sample_seconds", "wall_seconds", "threads"):
        m["statistics"][k] = None
    return m
a, b = (content(p) for p in sys.argv[1:3])
assert a == b, "the merged manifest differs from the one-process run's"
PY
echo "test-slurm: 3-task array + afterok merge equal the one-process run ($shards shards, manifest)"

# A failing array (an unknown flag): its merge job never runs.
read -r array merge < <(HOLO="$holo" SBATCH_ARGS="--cpus-per-task=1" "$here/submit-dataset.sh" 2 \
  "$work/failing" "${tiny[@]}" --no-such-flag | tail -1)
if wait_jobs "$array"; then :; fi
status=0
wait_jobs "$merge" >/dev/null || status=$?
scancel "$merge" 2>/dev/null || true
[ "$status" = 3 ] || { echo "test-slurm: the merge of a failed array was not held (status $status)" >&2; exit 1; }
[ ! -f "$work/failing/manifest.json" ] || { echo "test-slurm: a failed array got a manifest" >&2; exit 1; }
echo "test-slurm: the merge of a failed array is held (DependencyNeverSatisfied) and writes nothing"
cd /
rm -rf "$work"
[ "${KEEP_SLURM:-0}" = 1 ] || "${sudo[@]}" "$here/slurm-local.sh" stop

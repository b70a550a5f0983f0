#!/usr/bin/env bash
# Usage: scripts/cluster/submit-dataset.sh PARTS OUT [holo dataset flags...]
#
# Submits a sharded `holo dataset` run to Slurm: a job array of PARTS tasks (scripts/cluster/dataset.sbatch,
# each `holo dataset FLAGS --out OUT --shard auto`), then the merge job (dataset-merge.sbatch) with
# --dependency=afterok on the whole array. Prints the two job ids (array, merge). Extra sbatch options go in
# SBATCH_ARGS (e.g. "--partition=cpu --cpus-per-task=16"); HOLO names the `holo` binary the nodes run. The
# jobs' logs (holo-dataset-<array>_<task>.out, holo-dataset-merge-<job>.out) go to the current folder.
#
# Example: scripts/cluster/submit-dataset.sh 16 /shared/data/mit --train 3800 --val 100 --test 100 --levels 10000
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
parts="${1:?usage: submit-dataset.sh PARTS OUT [holo dataset flags...]}"
out="${2:?usage: submit-dataset.sh PARTS OUT [holo dataset flags...]}"
shift 2
case "$parts" in '' | *[!0-9]* | 0) echo "PARTS must be a positive integer, got \`$parts\`" >&2; exit 2 ;; esac
out="$(mkdir -p "$out" && cd "$out" && pwd)"
export OUT="$out" DATASET_ARGS="$*" HOLO="${HOLO:-holo}"
# SBATCH_ARGS is a list of options: split on spaces on purpose.
# shellcheck disable=SC2086
array=$(sbatch --parsable ${SBATCH_ARGS:-} --array="0-$((parts - 1))" --export=ALL \
  "$here/dataset.sbatch")
array="${array%%;*}"
# shellcheck disable=SC2086
merge=$(sbatch --parsable ${SBATCH_ARGS:-} --dependency="afterok:$array" --export=ALL \
  "$here/dataset-merge.sbatch")
merge="${merge%%;*}"
echo "array job $array ($parts parts), merge job $merge (after every part succeeds): $out"
echo "$array $merge"

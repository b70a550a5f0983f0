#!/usr/bin/env bash
# Usage: benchmarks/plan_table.sh HOLO [RUNS] [ISA ...]
#
# How the plan table's kernel rows (sdk/src/cnn/table.rs) are made: for each kernel ISA level (default: every
# level this CPU has among avx512vnni, avx2, scalar; TENSORHOLO_ISA lowers the level) and each shipped network
# (the 8/15/30-layer hologram CNNs with their 6 and 12 mm pre-filters, the LDI CNN, the int8 QDQ files' f32
# layers), RUNS processes (default 5) run `holo render --tune` and save the rows their timing chose
# (OUT/tuning.json). Prints, per ISA level and layer shape, how often each row was chosen: the table takes
# the row most processes chose. Run it on an otherwise idle machine (the timings are what it measures), and
# say which CPU in the table's entries.
set -euo pipefail

holo="${1:?usage: $0 HOLO [RUNS] [ISA ...]}"
runs="${2:-5}"
shift $(( $# >= 2 ? 2 : 1 ))
isas=("$@")
[ ${#isas[@]} -gt 0 ] || isas=(avx512vnni avx2 scalar)

out="$(mktemp -d "${TMPDIR:-/tmp}/plan-table.XXXXXX")"
trap 'rm -rf "$out"' EXIT
configs=(
  "--layers 8" "--layers 15" "--layers 30"
  "--layers 8 --offset-mm 12" "--layers 15 --offset-mm 12" "--layers 30 --offset-mm 12"
  "--ldi" "--precision int8-qdq" "--precision int8-qdq --layers 30 --offset-mm 12"
)
echo "plan_table.sh: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), $(nproc) cores; $runs runs per network"
n=0
for isa in "${isas[@]}"; do
  if ! TENSORHOLO_ISA=$isa "$holo" render --size 16x16 --repeat 0 --engine native --out "$out/probe" >/dev/null 2>&1; then
    echo "(skipping $isa: not available on this CPU)"
    continue
  fi
  for cfg in "${configs[@]}"; do
    for run in $(seq "$runs"); do
      n=$((n + 1))
      # shellcheck disable=SC2086
      TENSORHOLO_ISA=$isa "$holo" render $cfg --size 64x64 --engine native --threads 1 --repeat 0 --tune \
        --out "$out/run$n" >/dev/null 2>&1
      echo "$isa" >"$out/run$n/isa.txt"
    done
  done
done

python3 - "$out" <<'EOF'
import collections, json, pathlib, sys
counts = collections.defaultdict(collections.Counter)
for run in sorted(pathlib.Path(sys.argv[1]).glob("run*")):
    isa = (run / "isa.txt").read_text().strip()
    for r in json.loads((run / "tuning.json").read_text())["rows"]:
        counts[(isa, r["c_in"], r["c_out"], r["algorithms"])][r["row"]] += 1
print("| ISA level | layer | chosen among | rows chosen (processes) | the table's row |")
print("|---|---|---|---|---|")
for (isa, c_in, c_out, algs), c in sorted(counts.items()):
    chosen = ", ".join(f"`{row}` {k}" for row, k in c.most_common())
    print(f"| {isa} | {c_in}→{c_out} | {algs} | {chosen} | `{c.most_common(1)[0][0]}` |")
EOF

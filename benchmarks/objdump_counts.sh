#!/usr/bin/env bash
# Usage: benchmarks/objdump_counts.sh [--mix] [RLIB]
#
# Instruction counts of the kernels crate's ISA entry points (the `#[target_feature]` functions the dispatch
# tables point at: double phase, conv3x3 f32/int8, depthwise, spectral, phasor, heads, buffer rows), read from
# the release rlib with `objdump -d --no-show-raw-insn`. Without RLIB it builds `tensorholo-kernels --release`
# (in $CARGO_TARGET_DIR, default target/) and reads the newest rlib. Each function is named by the last two
# parts of its path (module::function). Prints one line per function: name, instruction count, and the ten
# most frequent mnemonics; with --mix, every mnemonic with its count (one `name mnemonic count` line each),
# for `diff` between two builds. Also lists any other function of the double_phase, conv3x3 f32 and simd
# modules that was not inlined (an outlined helper would move instructions out of an entry point).
#
#   benchmarks/objdump_counts.sh > before.txt; (edit); benchmarks/objdump_counts.sh > after.txt; diff before.txt after.txt
set -euo pipefail

mix=0
if [ "${1:-}" = "--mix" ]; then mix=1; shift; fi
rlib="${1:-}"
if [ -z "$rlib" ]; then
  cd "$(dirname "$0")/.."
  cargo build -p tensorholo-kernels --release --locked >&2
  rlib="$(ls -t "${CARGO_TARGET_DIR:-target}"/release/deps/libtensorholo_kernels-*.rlib | head -n1)"
fi
rlib="$(realpath "$rlib")"
work="$(mktemp -d "${TMPDIR:-/tmp}/objdump-counts.XXXXXX")"
trap 'rm -rf "$work"' EXIT
(cd "$work" && ar x "$rlib")

# One disassembly of every object; awk splits it by function and keeps the ISA entry points.
for o in "$work"/*.o; do objdump -d --no-show-raw-insn -C "$o"; done | awk -v mix="$mix" '
  function flush(   n, k, line, i, j, t, keys) {
    if (name == "") return
    if (mix) { for (k in cnt) printf "%s %s %d\n", name, k, cnt[k] }
    else {
      n = 0; for (k in cnt) keys[++n] = k
      for (i = 2; i <= n; i++) { t = keys[i]; for (j = i - 1; j >= 1 && (cnt[keys[j]] < cnt[t] || (cnt[keys[j]] == cnt[t] && keys[j] > t)); j--) keys[j + 1] = keys[j]; keys[j + 1] = t }
      line = ""; for (i = 1; i <= n && i <= 10; i++) line = line " " keys[i] ":" cnt[keys[i]]
      printf "%-44s %5d %s\n", name, total, line
    }
    name = ""; total = 0; delete cnt
  }
  /^[0-9a-f]+ <.*>:$/ {
    flush()
    full = $0; sub(/^[0-9a-f]+ </, "", full); sub(/>:$/, "", full)
    if (full !~ /^tensorholo_kernels::/) next
    isa = full ~ /(avx|neon|sse|vnni)/
    helper = full ~ /::(double_phase|simd)::/ || full ~ /::conv3x3::(f32|simd_f32|wino)/
    if (!isa && !helper) next
    short = full; sub(/::\{\{closure\}\}$/, "::closure", short); sub(/<.*$/, "", short)
    np = split(short, p, "::"); name = (np >= 2 ? p[np - 1] "::" p[np] : short)
    if (!isa) name = "(helper) " name
    total = 0; delete cnt; next
  }
  name != "" && /^ *[0-9a-f]+:\t/ {
    split($0, f, "\t"); m = f[2]; sub(/ .*/, "", m)
    if (m ~ /^(rep|repz|repnz|lock|notrack|bnd|data16|cs|ds)$/) { split(f[2], g, " "); m = m " " g[2] }
    cnt[m]++; total++
  }
  END { flush() }
' | sort

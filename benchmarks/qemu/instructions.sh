#!/usr/bin/env bash
# Usage: benchmarks/qemu/instructions.sh [HOLO_AARCH64] [SIZE] [all|frames|cnn]
#
# Guest instructions per frame of the aarch64 build of `holo render`, counted under qemu-aarch64 with this
# directory's TCG plugin (insn_count.c). A PROXY FOR ARM COST, NOT A TIME: qemu counts the instructions the
# Arm code executes (NEON kernels included), the same on every x86 machine for the same binary and inputs,
# so a change to the ARM path (tract, rustfft, our loops) can be compared here before it reaches a phone.
# It says nothing of caches, memory bandwidth, issue width or the cost of each instruction; time a real
# device for speed (`holo bench` built for aarch64, docs/GUIDE.md "ARM and phones"; the bindings' benchmark() on a phone).
#
# Each case renders the built-in scene at SIZE (default 192x192) with the 8-layer CNN, the 6 mm DDPM
# pre-filter, one thread, a fixed engine (tract with a fixed layout, or the native kernels) and an emulated
# CPU (qemu's `max`: dot product and i8mm; `cortex-a76`: dot product only), twice: with --repeat 1 and
# --repeat 3. The difference, halved, is one steady-state frame (loading, plan optimisation and output writing cancel out).
# HOLO_AARCH64 defaults to target/aarch64-unknown-linux-gnu/release/holo (build it first as docs/GUIDE.md "ARM and phones"
# says; a build without tract, `--no-default-features`, runs the native cases: pick them with FRAME_CASES /
# CNN_CASES, each a `;`-separated list of the cases below). The native f32 engine measures direct against
# Winograd F(2×2, 3×3) per layer shape at its first plan, here by emulated time: pin it with
# TENSORHOLO_CONV=direct, winograd2x2 or winograd4x4 (passed through to holo) to count each. Prints two Markdown tables (whole frames, then the hologram CNN alone); needs qemu-user, gcc,
# python3. Each case takes ~1 min here.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
holo="${1:-$root/target/aarch64-unknown-linux-gnu/release/holo}"
size="${2:-192x192}"
part="${3:-all}" # all: both tables; frames: whole frames only; cnn: the hologram CNN alone only
case "$part" in all | frames | cnn) ;; *) echo "third argument: all, frames or cnn (got '$part')" >&2; exit 1 ;; esac
[ -x "$holo" ] || { echo "no aarch64 holo at $holo: cargo build --release --target aarch64-unknown-linux-gnu -p holo" >&2; exit 1; }
command -v qemu-aarch64 >/dev/null || { echo "needs qemu-aarch64 (Debian qemu-user)" >&2; exit 1; }

# holo sets glibc's mmap threshold in-process (1 MiB) unless this variable is set; setting it here keeps older
# binaries (which re-executed themselves, escaping the plugin) countable too.
export MALLOC_MMAP_THRESHOLD_=1048576

work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
gcc -O2 -shared -fPIC -o "$work/libinsn_count.so" "$here/insn_count.c"

count() { # engine precision layout qemu-cpu repeat → instruction count (and report.json in $work/out)
  QEMU_CPU="$4" qemu-aarch64 -L /usr/aarch64-linux-gnu -plugin "$work/libinsn_count.so" -d plugin \
    -D "$work/plugin.log" "$holo" render --size "$size" --engine "$1" --precision "$2" --layout "$3" \
    --threads 1 --repeat "$5" --out "$work/out" >/dev/null 2>"$work/holo.log" ||
    { cat "$work/holo.log" >&2; exit 1; }
  sed -n 's/^insn_count: //p' "$work/plugin.log"
}

if [ "$part" != cnn ]; then
echo "Guest instructions per frame, holo8 + DDPM pre-filter, built-in scene $size, 1 thread (qemu-aarch64 $(qemu-aarch64 --version | head -1 | awk '{print $3}'); a proxy for ARM cost, not a time)"
echo
echo "| engine | precision | layout | qemu CPU | kernel | M instructions / frame | CNN multiply-adds / instruction |"
echo "|---|---|---|---|---|---:|---:|"
# tract's rows (its own NEON kernels), then the native engine's: f32 (NEON row), int8 with i8mm (USDOT, the
# default CPU `max`) and with dot product only (SDOT, `cortex-a76`). The native rows ignore the layout.
frame_cases=("tract f32 nchw max" "tract f32 nhwc max" "tract int8-qop nchw max" "tract int8-qdq nchw max"
  "tract int8-qdq nhwc max" "native f32 nchw max" "native int8-qdq nchw max" "native int8-qdq nchw cortex-a76")
[ -n "${FRAME_CASES:-}" ] && IFS=';' read -r -a frame_cases <<<"$FRAME_CASES"
for case in "${frame_cases[@]}"; do
  read -r engine precision layout cpu <<<"$case"
  one="$(count "$engine" "$precision" "$layout" "$cpu" 1)"
  three="$(count "$engine" "$precision" "$layout" "$cpu" 3)"
  python3 - "$engine" "$precision" "$layout" "$cpu" "$one" "$three" "$work/out/report.json" <<'PY'
import json, sys
engine, precision, layout, cpu = sys.argv[1:5]
one, three, report = int(sys.argv[5]), int(sys.argv[6]), sys.argv[7]
r = json.load(open(report))
h, w = r["size"]
macs = (r["models"]["hologram_cnn"].get("macs_per_pixel") or 0) * h * w
kernel = r.get("cnn_plan", {}).get("kernel") or "–"
layout = layout if engine == "tract" else "–"
per_frame = (three - one) / 2
print(f"| {engine} | {precision} | {layout} | {cpu} | {kernel} | {per_frame / 1e6:.0f} | {macs / per_frame:.2f} |")
PY
done
fi
[ "$part" = frames ] && exit 0

# The hologram CNN alone: `holo bench --skip-pipeline` runs one warm-up and then --repeat runs of the CNN, so the
# difference of --repeat 3 and --repeat 1, halved, is one CNN run (nothing else of a frame). tract's layout is
# pinned to channels-first (its own tuning would pick by emulated time); the native rows ignore it.
bench_count() { # engine precision layers qemu-cpu repeat → instruction count (and the table in $work/bench.txt)
  QEMU_CPU="$4" qemu-aarch64 -L /usr/aarch64-linux-gnu -plugin "$work/libinsn_count.so" -d plugin \
    -D "$work/plugin.log" "$holo" bench --skip-pipeline --sizes "$size" --layers "$3" --precision "$2" \
    --threads 1 --engine "$1" --layout nchw --repeat "$5" --max-seconds 100000 >"$work/bench.txt" \
    2>"$work/holo.log" ||
    { cat "$work/holo.log" >&2; exit 1; }
  sed -n 's/^insn_count: //p' "$work/plugin.log"
}

[ "$part" = all ] && echo
echo "Guest instructions of one hologram CNN run alone ($size, 1 thread; \`holo bench --skip-pipeline\`)"
echo
echo "| CNN | engine | precision | qemu CPU | kernel / layout | M instructions / run | multiply-adds / instruction |"
echo "|---|---|---|---|---|---:|---:|"
h="${size%x*}"
w="${size#*x}"
cnn_cases=("8 tract f32 max" "8 native f32 max" "8 native int8-qdq max" "8 native int8-qdq cortex-a76"
  "8 native int8-qdq cortex-a53" "30 native f32 max" "30 native int8-qdq max" "30 native int8-qdq cortex-a76")
[ -n "${CNN_CASES:-}" ] && IFS=';' read -r -a cnn_cases <<<"$CNN_CASES"
for case in "${cnn_cases[@]}"; do
  read -r layers engine precision cpu <<<"$case"
  one="$(bench_count "$engine" "$precision" "$layers" "$cpu" 1)"
  three="$(bench_count "$engine" "$precision" "$layers" "$cpu" 3)"
  kernel="$(awk -F'|' '/^\| holo/ {gsub(/^ +| +$/, "", $5); print $5; exit}' "$work/bench.txt")"
  macs=$([ "$layers" = 8 ] && echo 33480 || ([ "$layers" = 15 ] && echo 69768 || echo 147528))
  python3 -c "import sys; one, three, macs = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]) * $h * $w
per = (three - one) / 2
print(f'| holo$layers | $engine | $precision | $cpu | \`$kernel\` | {per / 1e6:.0f} | {macs / per:.2f} |')" \
    "$one" "$three" "$macs"
done

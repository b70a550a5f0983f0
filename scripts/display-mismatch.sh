#!/usr/bin/env bash
# Usage: scripts/display-mismatch.sh [OUT_DIR] [-- extra `holo render` flags, e.g. --rgb F --depth F ...]
#
# What a laser-ratio mismatch costs (docs/DISPLAYS.md, "Tolerances, and why"): the shipped 8 µm holo8 CNN with
# its 6 mm pre-filter serves an 8 µm SLM whose green laser is moved off 520 nm by E % (red 638, blue 450 nm),
# with the tolerance widened so that it runs; volume and offset are the common scale's (σ·6 mm). Each display
# is scored with `holo render --evaluate` against SM-LBM computed at that display itself (Table 2 protocol,
# what the SLM shows), next to SM-LBM + AA-DPM at the same display, and the mapping's ceiling: SM-LBM at the
# model's own display shown on this one (what a perfect model reaches through the mapping; the CNN's own
# error at this scene masks small losses in the shown scores). One table row per E: the per-colour
# mismatch the SDK reports, the displayed PSNR (amplitude and focal stack), and the dB lost against E = 0;
# a last row for lasers at 633/532/450 nm.
#
# Environment: HOLO (a built `holo`; default: target/release/holo, else target/debug/holo), LEVELS (SM-LBM
# planes, default 2048), SIZE (default 384x384), GREEN_OFFSETS_PCT (default "0 0.25 0.5 1 2 4 8").
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
out="${1:-$root/out/display-mismatch}"
shift || true
[ "${1:-}" = "--" ] && shift
holo="${HOLO:-}"
if [ -z "$holo" ]; then
  for h in "$root/target/release/holo" "$root/target/debug/holo"; do
    if [ -x "$h" ]; then holo="$h"; break; fi
  done
fi
[ -n "$holo" ] || { echo "build holo first (cargo build --release -p holo) or set HOLO" >&2; exit 2; }
levels="${LEVELS:-2048}"
size="${SIZE:-384x384}"
mkdir -p "$out"
echo "holo: $holo; CPU: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')"
printf '%-14s %-20s %-11s %-22s %-22s %-22s %s\n' "display" "lasers nm" "mismatch %" "ceiling dB (amp/fs)" "shown dB (amp/fs)" "SM-LBM+AA-DPM (amp/fs)" "lost dB (amp/fs)"
# One display per line: label, then red, green, blue in metres. Green moved off 520 nm by E %, then the
# issue's example of common lasers, 633/532/450 nm.
displays=""
for e in ${GREEN_OFFSETS_PCT:-0 0.25 0.5 1 2 4 8}; do
  displays+="green+$e% 6.38e-7 $(awk -v e="$e" 'BEGIN { printf "%.10e", 520e-9 * (1 + e / 100) }') 4.5e-7"$'\n'
done
displays+="633/532/450 6.33e-7 5.32e-7 4.5e-7"$'\n'
base_amp="" base_fs=""
while read -r label red green blue; do
  [ -n "$label" ] || continue
  # σ_c = λ_c/λ'_c at the same pitch; the common σ is √(min·max), as the SDK computes it.
  sigma=$(awk -v r="$red" -v g="$green" -v b="$blue" 'BEGIN { s[0] = 638e-9 / r; s[1] = 520e-9 / g;
    s[2] = 450e-9 / b; lo = s[0]; hi = s[0]; for (i = 1; i < 3; i++) { if (s[i] < lo) lo = s[i];
    if (s[i] > hi) hi = s[i] } printf "%.12f", sqrt(lo * hi) }')
  vol=$(awk -v s="$sigma" 'BEGIN { printf "%.12e", 6e-3 * s }')
  off=$(awk -v s="$sigma" 'BEGIN { printf "%.12f", 6 * s }')
  dir="$out/$(echo "$label" | sed 's/+/_/; s/%/pct/; s#/#_#g')"
  "$holo" render --size "$size" --repeat 0 --evaluate --levels "$levels" --backend cpu \
    --wavelengths-m "$red,$green,$blue" --volume-depth-m "$vol" --offset-mm "$off" \
    --wavelength-ratio-tolerance 0.2 --out "$dir" "$@" >/dev/null 2>"$dir.log" \
    || { cat "$dir.log" >&2; exit 1; }
  python3 - "$dir/report.json" "$label" "$red" "$green" "$blue" "${base_amp:-}" "${base_fs:-}" <<'PY' > "$dir.row"
import json, re, sys
r = json.load(open(sys.argv[1]))
ev = r["evaluation"]
m = re.search(r"wavelength mismatch ([0-9.]+) %", r["models"]["display_mapping"])
amp, fs = ev["displayed"]["psnr_amp"], ev["displayed"]["psnr_fs"]
ref = ev["smlbm_encoded_displayed"]["scores"]
base_amp = float(sys.argv[6]) if sys.argv[6] else amp
base_fs = float(sys.argv[7]) if sys.argv[7] else fs
nm = "/".join(f"{float(x) * 1e9:g}" for x in sys.argv[3:6])
ceil = ev.get("mapping_ceiling")
ceiling = f"{ceil['psnr_amp']:6.2f} / {ceil['psnr_fs']:6.2f}" if ceil else "  (same display)"
print(f"{sys.argv[2]:<14} {nm:<20} {m.group(1) if m else '?':<11} {ceiling:<22} "
      f"{amp:6.2f} / {fs:6.2f}{'':<6} {ref['psnr_amp']:6.2f} / {ref['psnr_fs']:6.2f}{'':<6} "
      f"{base_amp - amp:5.2f} / {base_fs - fs:5.2f}")
print(amp, fs)
PY
  head -1 "$dir.row"
  if [ -z "$base_amp" ]; then read -r base_amp base_fs < <(tail -1 "$dir.row"); fi
done <<< "$displays"

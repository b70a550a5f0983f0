#!/usr/bin/env bash
# Usage: scripts/display-table.sh [HOLO]
#
# The table of docs/DISPLAYS.md, "Common SLMs and laser sets": for each SLM (pitch and resolution from its
# maker's data sheet) and each common laser set, a display profile with the volume and the 6 mm pre-filter's
# offset at the common depth scale σ (σ·6 mm, what the shipped models serve), checked by
# `holo display check --json`: served or not by the shipped 8-layer CNN (f32), σ, the lasers' spread, the
# mapping's predicted ceiling and its estimated cost (the serving rule: within 0.3 dB of the model's
# test-split score), and whether the 6 mm pre-filter pairs. The figures come from the SDK's formulas, not
# from a machine: any CPU gives the same table.
#
# HOLO: a built `holo` (default: target/release/holo, else target/debug/holo).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
holo="${1:-${HOLO:-}}"
if [ -z "$holo" ]; then
  for h in "$root/target/release/holo" "$root/target/debug/holo"; do
    if [ -x "$h" ]; then holo="$h"; break; fi
  done
fi
[ -n "$holo" ] || { echo "build holo first (cargo build --release -p holo) or pass it" >&2; exit 2; }
dir="$(mktemp -d "${TMPDIR:-/tmp}/display-table.XXXXXX")"
trap 'rm -rf "$dir"' EXIT

python3 - "$holo" "$dir" <<'EOF'
import json, math, subprocess, sys
holo, tmp = sys.argv[1], sys.argv[2]
slms = [
    ("HOLOEYE PLUTO-2", 8.0e-6, [1080, 1920]),
    ("HOLOEYE GAEA-2", 3.74e-6, [2464, 4160]),
    ("HOLOEYE LETO-3", 6.4e-6, [1080, 1920]),
    ("Meadowlark 1920×1152", 9.2e-6, [1152, 1920]),
    ("Santec SLM-200", 8.0e-6, [1200, 1920]),
    ("Thorlabs EXULUS-4K", 3.74e-6, [2160, 3840]),
    ("Jasper 4K (JD7714)", 3.74e-6, [2400, 4096]),
]
lasers = [(638, 520, 450), (633, 532, 473), (640, 532, 445), (635, 532, 450)]
trained = (638e-9, 520e-9, 450e-9)
print("| SLM | pitch | lasers (nm) | served | σ | spread | ceiling (dB) | est. cost (dB) | volume, offset (mm) | 6 mm pre-filter |")
print("|---|---:|---|---|---:|---:|---:|---:|---|---|")
for name, pitch, res in slms:
    for nm in lasers:
        lam = [x * 1e-9 for x in nm]
        scales = [trained[c] / lam[c] * (pitch / 8e-6) ** 2 for c in range(3)]
        lo, hi = min(scales), max(scales)
        sigma = lo if lo == hi else math.sqrt(lo * hi)
        v = 6e-3 * sigma
        profile = {"name": name, "pixel_pitch_m": pitch, "resolution": res,
                   "wavelengths_m": lam, "volume_depth_m": v, "offsets_m": [v]}
        path = f"{tmp}/p.json"
        with open(path, "w") as f:
            json.dump(profile, f)
        out = subprocess.run([holo, "display", "check", path, "--json"], capture_output=True, text=True)
        if out.returncode not in (0, 1):
            sys.exit(f"holo display check failed for {name} {nm}: {out.stderr}")
        checks = json.loads(out.stdout)["checks"]
        row = next(c for c in checks if c["file"] == "holo8_rgbd.onnx")
        pre = next(c for c in checks if c["kind"] == "prefilter-cnn" and c["layers"] == 8
                   and c["precision"] == "f32")
        pre_cell = "yes" if pre["mapping"] else ("refused" if pre["refusal"] else "none")
        lasers_cell = "/".join(str(x) for x in nm)
        if row["mapping"]:
            m = row["mapping"]
            ceiling = "∞" if m["ceiling_db"] is None or m["ceiling_db"] > 1e300 else f"{m['ceiling_db']:.1f}"
            spread = max(abs(x) for x in m["ratio_mismatch_pct"])
            print(f"| {name} | {pitch*1e6:g} µm | {lasers_cell} | yes | {m['scale']:.5f} | {spread:.2f} % | "
                  f"{ceiling} | {m['cost_db']:.2f} | {v*1e3:.4f} | {pre_cell} |")
        else:
            r = row["refusal"]
            why = r["key"].replace("tensorholo.", "")
            tol = r.get("tolerance")
            extra = f": tolerance {tol[0]*100:.2f} % would serve at {tol[1]:.2f} dB" if tol else ""
            print(f"| {name} | {pitch*1e6:g} µm | {lasers_cell} | no ({why}{extra}) | {sigma:.5f} | | | | "
                  f"{v*1e3:.4f} | {pre_cell} |")
EOF

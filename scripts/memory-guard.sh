#!/usr/bin/env bash
# Usage: scripts/memory-guard.sh HOLO
#
# Peak resident memory (Linux VmHWM) against stated limits; prints every figure, fails above a limit:
#   - a hologram session per case (`holo bench`: the peak from a reset before the session is made to its last
#     single frame; the shipped 8-layer CNN with its 6 mm pre-filter, f32 and int8, 2 threads) at 384² and
#     1080p, and the same session's stream (`render_stream`: the CNN of frame n + 1 beside the optics of frame
#     n, so two frames' heads and a second CNN plan are alive) on top;
#   - a whole `holo render` at 1080p: up to its last frame (the inputs and the session), and with its previews
#     and report images (report.json's `frames_peak_rss_mib`, `peak_rss_mib`; `previews_added_mib` is the
#     difference);
#   - a whole `holo render --refine 1 --refine-target cnn` at 1080p (the focal-stack refinement, docs/REFINE.md:
#     its 7 loss planes' target and multipliers, per colour the spectra, fields and Adam's moments, the
#     held-out planes scored with the same buffers; memory does not grow with the iterations), report.json's
#     `peak_rss_mib`: 1203 MiB measured (Intel Xeon VM, debug build): 248 up to the last frame, then ~105 of
#     previews and ~850 of the refinement.
# Today's figures (AMD EPYC Zen 4, 2 threads, release build; the debug build CI runs is within a few MiB):
# session 1080p 235 MiB (f32) / 222 MiB (int8), 384² 39 / 32 MiB; streams 1080p 324 / 308, 384² 53 / 39;
# `holo render` 1080p 241 MiB up to its last frame, 345 MiB with the previews (+105). The session limits are
# the goal (a phone shares its memory with the camera and the renderer): 256 MiB at 1080p, 48 MiB at 384².
set -euo pipefail
holo="${1:?usage: scripts/memory-guard.sh HOLO}"
limit_1080=256
limit_384=48
limit_stream_1080=360
limit_stream_384=64
limit_render_frames_1080=270
limit_render_1080=390
limit_refine_1080=1300

work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
"$holo" bench --layers 8 --precision f32,int8-qdq --sizes 384x384,1080x1920 --repeat 1 --skip-cnn \
  --threads 2 --json "$work/bench.json" > "$work/bench.md"
"$holo" render --size 1080x1920 --repeat 1 --out "$work/render" 2> "$work/render.log" \
  || { cat "$work/render.log" >&2; exit 1; }
"$holo" render --size 1080x1920 --repeat 1 --refine 1 --refine-target cnn --out "$work/refine" \
  2> "$work/refine.log" || { cat "$work/refine.log" >&2; exit 1; }

python3 - "$work/bench.json" "$work/render/report.json" "$work/refine/report.json" "$limit_1080" "$limit_384" \
  "$limit_stream_1080" "$limit_stream_384" "$limit_render_frames_1080" "$limit_render_1080" \
  "$limit_refine_1080" <<'PY'
import json, sys
bench, report, refined = (json.load(open(p)) for p in sys.argv[1:4])
l1080, l384, s1080, s384, render_frames_limit, render_limit, refine_limit = map(float, sys.argv[4:11])
limit = {(1080, 1920): (l1080, s1080), (384, 384): (l384, s384)}
failed = []
def check(what, peak, cap):
    print(f"{what}: peak {peak:.0f} MiB (limit {cap:.0f})")
    if peak > cap:
        failed.append(f"{what}: {peak:.0f} MiB > {cap:.0f}")
for r in bench["results"]:
    if r.get("kind") != "pipeline":
        continue
    size = tuple(r["size"])
    peak, stream = r.get("peak_rss_mib"), r.get("stream_peak_rss_mib")
    if peak is None or stream is None:
        sys.exit("memory-guard: holo bench reported no peak (no /proc/self/clear_refs?)")
    name = f"{size[0]}x{size[1]} {r['precision']}"
    check(f"session {name}, single frames", peak, limit[size][0])
    check(f"session {name}, stream", stream, limit[size][1])
peak, frames = report.get("peak_rss_mib"), report.get("frames_peak_rss_mib")
if peak is None or frames is None:
    sys.exit("memory-guard: holo render reported no peak_rss_mib / frames_peak_rss_mib")
check("holo render 1080x1920 up to its last frame", frames, render_frames_limit)
check("holo render 1080x1920 with previews and report images", peak, render_limit)
print(f"holo render 1080x1920: the previews and report images add {max(peak - frames, 0):.0f} MiB")
if refined.get("peak_rss_mib") is None or "refine" not in refined:
    sys.exit("memory-guard: holo render --refine reported no peak_rss_mib or no refine section")
check("holo render 1080x1920 --refine 1 --refine-target cnn", refined["peak_rss_mib"], refine_limit)
if failed:
    sys.exit("memory-guard: above the limits: " + "; ".join(failed))
PY

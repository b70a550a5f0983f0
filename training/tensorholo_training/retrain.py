"""One command from a display profile to models in the shipped format: ``training/retrain.sh`` runs this.

For the display a profile describes (``docs/DISPLAYS.md``: ``pixel_pitch_m``, ``resolution``, ``wavelengths_m``,
``volume_depth_m``, ``offsets_m``, SI units) it runs, resuming whatever an earlier run of the same command
finished:

1. the dataset: ``holo dataset --display FILE`` (``--shards N``: N local ``--shard I/N`` processes at once,
   then ``--merge``; ``docs/DATASET.md``);
2. stage 1 (the hologram CNN on the midpoint hologram, paper §"Training"), once for every offset;
3. stage 2 for each offset (the deep double phase method, DDPM, with the pre-filter CNN where the offset is not
   0; the paper's Eq. 6 offset propagation);
4. the f32 and int8 ONNX exports and the Table 2 evaluation on the test split;

then prints the ``holo render --display FILE --model …`` line that uses the result. The optics are stated
once, in the profile: the dataset's manifest records them and the trainer reads them from it.

Scales: ``smoke`` (a 32×32 dataset of 12 scenes, a few dozen steps: minutes on 2 CPU cores; for CI and a
first try; the models are not useful) and ``paper`` (the paper's dataset, 3800/100/100 scenes at 384×384 with
10,000 depth planes, and schedule, 3000 stage-1 and 1000 stage-2 epochs). Several GPUs of one node:
``--nproc N`` (``torchrun --standalone``; learning rate per ``training/README.md``, "Several GPUs or nodes").

Before anything runs it warns when a point's spread at the volume's edge, ``(D/2)·tan(asin(λ/2p))/p`` pixels
(the diffraction cone of the SLM's highest spatial frequency, ``sin θ = λ/2p``, over half the volume depth
``D/2`` from the midpoint hologram), exceeds the receptive field of the CNN's 3×3 convolutions (a radius of
``L`` pixels for ``L`` layers).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass, field

from .data import check_display, read_manifest
from .optics import Display

#: The dataset of each scale (``holo dataset`` flags besides ``--display``/``--out``): 5-layer LDIs, as the
#: paper's, so that one dataset trains both the RGB-D CNNs (the front layer) and the LDI CNN.
DATASET_FLAGS = {
    "smoke": ["--train", "8", "--val", "2", "--test", "2", "--size", "32", "--layers", "5", "--levels", "16",
              "--shard-size", "2", "--previews", "1"],
    "paper": ["--train", "3800", "--val", "100", "--test", "100", "--size", "384", "--layers", "5",
              "--levels", "10000"],
}
#: Training configurations of each scale (``training/configs``) for stage 1 and stage 2.
CONFIGS = {
    "smoke": ("smoke.json", "smoke.json"),
    "paper": ("gpu_stage1.json", "gpu_stage2.json"),
}
#: int8 calibration samples and evaluated test scenes (None: all) of each scale.
CALIBRATION = {"smoke": 2, "paper": 64}
EVALUATED = {"smoke": 2, "paper": None}
#: The record of what an output folder was made for: a rerun must be the same display and scale (its dataset).
RECORD = "retrain.json"


class RetrainError(Exception):
    """A refusal with the reason to show the user (no traceback)."""


@dataclass
class Profile:
    """The fields of a display profile this command reads (``docs/DISPLAYS.md``); ``holo dataset`` checks
    the whole profile."""

    path: str
    raw: dict
    display: Display
    offsets_m: list[float]


def read_profile(path: str) -> Profile:
    """Reads a display profile (JSON, SI units). Raises ``RetrainError`` naming the file and key when it is not
    one."""
    try:
        with open(path) as f:
            raw = json.load(f)
    except OSError as e:
        raise RetrainError(f"display profile `{path}`: {e.strerror}") from e
    except json.JSONDecodeError as e:
        raise RetrainError(f"display profile `{path}` is not JSON: {e}") from e
    if not isinstance(raw, dict):
        raise RetrainError(f"display profile `{path}` is not a JSON object (docs/DISPLAYS.md)")

    def number(key, value):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
            raise RetrainError(f"display profile `{path}`: `{key}` must be a positive number in SI units, got {value!r}")
        return float(value)

    for key in ("pixel_pitch_m", "wavelengths_m", "volume_depth_m", "offsets_m"):
        if key not in raw:
            raise RetrainError(f"display profile `{path}` has no `{key}` (docs/DISPLAYS.md, \"A profile\")")
    wl = raw["wavelengths_m"]
    if not isinstance(wl, list) or len(wl) != 3:
        raise RetrainError(f"display profile `{path}`: `wavelengths_m` must be [red, green, blue] in metres")
    offsets = raw["offsets_m"]
    if not isinstance(offsets, list) or not offsets:
        raise RetrainError(f"display profile `{path}`: `offsets_m` must be a non-empty list of metres")
    display = Display(
        wavelengths_m=tuple(number("wavelengths_m", v) for v in wl),
        pixel_pitch_m=number("pixel_pitch_m", raw["pixel_pitch_m"]),
        volume_depth_m=number("volume_depth_m", raw["volume_depth_m"]),
    )
    for v in offsets:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
            raise RetrainError(f"display profile `{path}`: `offsets_m` holds {v!r}, not a distance ≥ 0 in metres")
    return Profile(path, raw, display, [float(v) for v in offsets])


def edge_spread_px(display: Display, wavelength_m: float) -> float:
    """Radius in SLM pixels over which a point at the volume's edge spreads on the midpoint hologram:
    ``(D/2)·tan(asin(λ/2p))/p``, with ``D`` the volume depth (metres), ``λ`` the wavelength and ``p`` the pixel
    pitch (metres). ``λ/2p`` is the sine of the largest diffraction angle the SLM's sampling holds."""
    p = display.pixel_pitch_m
    return display.volume_depth_m / 2 * math.tan(math.asin(wavelength_m / (2 * p))) / p


def receptive_field_warning(display: Display, layers: int) -> str | None:
    """A warning when the widest colour's edge spread (``edge_spread_px``) exceeds the receptive field of
    ``layers`` 3×3 convolutions (a radius of ``layers`` pixels), saying what to change; ``None`` otherwise."""
    spreads = [edge_spread_px(display, w) for w in display.wavelengths_m]
    worst = max(range(3), key=lambda i: spreads[i])
    r, wl = spreads[worst], display.wavelengths_m[worst]
    if r <= layers:
        return None
    # The deepest volume whose spread fits: the spread is proportional to the depth.
    fits = display.volume_depth_m * layers / r
    deeper = [n for n in (15, 30) if n > layers and n >= r]
    more = f"--layers {deeper[0]} (a radius of {deeper[0]} px)" if deeper else None
    change = " or ".join(x for x in (more, f"a volume of at most {fits * 1e3:.3g} mm in the profile") if x)
    return (
        f"a point at the volume's edge spreads over a radius of {r:.1f} px on the midpoint hologram "
        f"({'RGB'[worst]}, {wl * 1e9:.0f} nm: (D/2)·tan(asin(λ/2p))/p with D = {display.volume_depth_m * 1e3:g} mm, "
        f"p = {display.pixel_pitch_m * 1e6:g} µm), more than the {layers}-layer CNN's receptive field "
        f"(a radius of {layers} px): expect less sharp far planes (the paper's 8-layer model has the same limit, "
        f"at 15 px). To cover it: {change}."
    )


def check_manifest(data: str, profile: Profile) -> None:
    """Refuses a dataset folder made for another display than ``profile`` (``RetrainError`` naming both)."""
    manifest = read_manifest(data)
    try:
        check_display(manifest, profile.display)
    except ValueError as e:
        raise RetrainError(f"`{data}` holds a dataset for another display: {e}; choose another --out") from e


@dataclass
class Plan:
    """Everything one retraining runs; ``steps`` are ``(title, argv)`` in order."""

    args: argparse.Namespace
    profile: Profile
    data: str
    runs: str
    models: str
    offsets_mm: list[float]
    steps: list[tuple[str, list[str]]] = field(default_factory=list)

    def names(self) -> list[str]:
        return [model_name(self.args.layers, self.args.input, o) for o in self.offsets_mm]


def model_name(layers: int, input_kind: str, offset_mm: float) -> str:
    """The models' file stem, as the shipped ones: ``holo8_rgbd_1.5mm``."""
    return f"holo{layers}_{input_kind}_{offset_mm:g}mm"


def build_plan(args: argparse.Namespace, profile: Profile) -> Plan:
    """The commands of one retraining (``args``: the parsed command line)."""
    out = args.out
    data = args.data or os.path.join(out, "dataset")
    runs = args.runs or os.path.join(out, "runs")
    models = args.models or os.path.join(out, "models")
    offsets = args.offsets_mm if args.offsets_mm is not None else [round(o * 1e3, 9) for o in profile.offsets_m]
    plan = Plan(args, profile, data, runs, models, offsets)
    py = [sys.executable]
    il = 5 if args.input == "ldi" else 1
    flags = list(DATASET_FLAGS[args.scale])
    threads = args.threads or (max(1, (os.cpu_count() or 1) // args.shards) if args.shards > 1 else 0)
    if threads:
        flags += ["--threads", str(threads)]
    dataset = [args.holo, "dataset", "--display", profile.path, *flags, "--out", data]
    if args.shards > 1:
        for i in range(args.shards):
            plan.steps.append((f"dataset part {i}/{args.shards}", dataset + ["--shard", f"{i}/{args.shards}"]))
        plan.steps.append(("dataset merge", [args.holo, "dataset", "--merge", "--out", data]))
    else:
        plan.steps.append(("dataset", dataset))
    if args.nproc:
        train = py + ["-m", "torch.distributed.run", "--standalone", "--nproc-per-node", str(args.nproc),
                      "--max-restarts", "1", "-m", "tensorholo_training.train"]
    else:
        train = py + ["-m", "tensorholo_training.train"]
    c1, c2 = (os.path.join(args.root, "training", "configs", c) for c in CONFIGS[args.scale])
    common = ["--set", f"dataset={json.dumps(data)}", "--set", f"num_layers={args.layers}",
              "--set", f"input_layers={il}"]
    stage1 = os.path.join(runs, f"holo{args.layers}_{args.input}", "stage1")
    extra1 = ["--set", f"stage1_epochs={args.stage1_epochs}"] if args.stage1_epochs else []
    extra2 = ["--set", f"stage2_epochs={args.stage2_epochs}"] if args.stage2_epochs else []
    plan.steps.append(("stage 1", train + ["--config", c1, "--run-dir", stage1, *common,
                                           "--set", 'stages=["stage1"]', *extra1]))
    for offset, name in zip(offsets, plan.names()):
        run = os.path.join(runs, name)
        plan.steps.append((f"stage 2, offset {offset:g} mm", train + [
            "--config", c2, "--run-dir", run, *common, "--set", 'stages=["stage2"]',
            "--set", f"offset_mm={offset!r}", "--set", f"init_from={json.dumps(os.path.join(stage1, 'stage1.pt'))}",
            *extra2]))
        best = os.path.join(run, "best.pt")
        plan.steps.append((f"export {name}", py + [
            "-m", "tensorholo_training.export", "--checkpoint", best, "--out-dir", models, "--name", name,
            "--int8", "--calib-dataset", data, "--calib-samples", str(CALIBRATION[args.scale])]))
        limit = EVALUATED[args.scale]
        plan.steps.append((f"evaluate {name} (Table 2 protocol, test split)", py + [
            "-m", "tensorholo_training.evaluate", "--checkpoint", best, "--dataset", data, "--split", "test",
            "--phase-only", "--out", os.path.join(models, f"{name}.eval.json"),
            *(["--limit", str(limit)] if limit else [])]))
    return plan


def render_line(plan: Plan) -> str:
    """The ``holo render`` command that uses the first offset's models at the profile's display."""
    name = plan.names()[0]
    argv = ["holo", "render", "--display", plan.profile.path, "--model", os.path.join(plan.models, f"{name}.onnx")]
    pre = os.path.join(plan.models, f"{name}.prefilter.onnx")
    if plan.offsets_mm[0] != 0:
        argv += ["--prefilter-model", pre]
    # The profile's first offset is holo's default; another one is passed exactly (repr, not rounded: the
    # model's metadata must match it to a relative 1e-6).
    if not math.isclose(plan.offsets_mm[0], plan.profile.offsets_m[0] * 1e3, rel_tol=1e-9, abs_tol=1e-12):
        argv += ["--offset-mm", repr(plan.offsets_mm[0])]
    return shlex.join(argv + ["--out", "out/retrained"])


def check_record(plan: Plan) -> None:
    """Refuses an output folder made for another display or scale (another dataset); records this one
    otherwise. Other layer counts, inputs and offsets share the folder: their runs and models have their own
    names."""
    os.makedirs(plan.args.out, exist_ok=True)
    path = os.path.join(plan.args.out, RECORD)
    record = {"display": plan.profile.raw, "scale": plan.args.scale}
    if os.path.exists(path):
        with open(path) as f:
            old = json.load(f)
        for key in record:
            if old.get(key) != record[key]:
                raise RetrainError(
                    f"`{plan.args.out}` holds a retraining for another {key} ({RECORD}: {json.dumps(old.get(key))}, "
                    f"here {json.dumps(record[key])}); choose another --out, or delete that folder")
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(record, f, indent=1)
    os.replace(tmp, path)


def run_steps(plan: Plan, log=print) -> list[dict]:
    """Runs the plan's steps (dataset parts at once, the rest in order); returns each step's wall time.
    Raises ``RetrainError`` naming the step that failed and its command."""
    timings = []
    steps = list(plan.steps)
    n = len(steps)
    k = 0
    if os.path.exists(os.path.join(plan.data, "manifest.json")):
        check_manifest(plan.data, plan.profile)
        log(f"== dataset: {plan.data} is complete (its manifest is this display's); kept")
        while steps and steps[0][0].startswith("dataset"):
            steps.pop(0)
            k += 1
    parts = [s for s in steps if s[0].startswith("dataset part")]
    if parts:
        t0 = time.monotonic()
        log(f"== [{k + 1}-{k + len(parts)}/{n}] {len(parts)} dataset parts at once → {plan.data}")
        procs = [(title, argv, subprocess.Popen(argv)) for title, argv in parts]
        failed = [(title, argv) for title, argv, p in procs if p.wait() != 0]
        if failed:
            title, argv = failed[0]
            raise RetrainError(f"{title} failed; rerun this command to resume (finished shards are kept): "
                               f"{shlex.join(argv)}")
        timings.append({"step": "dataset parts", "seconds": time.monotonic() - t0})
        steps = steps[len(parts):]
        k += len(parts)
    for title, argv in steps:
        k += 1
        log(f"== [{k}/{n}] {title}: {shlex.join(argv)}")
        t0 = time.monotonic()
        if subprocess.call(argv) != 0:
            raise RetrainError(f"{title} failed: {shlex.join(argv)}; rerun this command to resume")
        timings.append({"step": title, "seconds": time.monotonic() - t0})
        if title.startswith("dataset"):
            check_manifest(plan.data, plan.profile)
    return timings


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        prog="training/retrain.sh",
        description="Retrains the hologram (and pre-filter) CNNs for the display a profile describes: dataset, "
                    "stage 1, stage 2 per offset, f32 + int8 ONNX, Table 2 evaluation (docs/DISPLAYS.md, "
                    "\"Retraining for your display\"). Rerunning the same command resumes.")
    ap.add_argument("--display", required=True, metavar="FILE", help="display profile (docs/DISPLAYS.md)")
    ap.add_argument("--layers", type=int, choices=[8, 15, 30], default=8, help="CNN depth (default 8)")
    ap.add_argument("--input", choices=["rgbd", "ldi"], default="rgbd", help="RGB-D (default) or LDI input")
    ap.add_argument("--offsets-mm", type=lambda s: [float(v) for v in s.replace(",", " ").split()],
                    metavar='"A B"', help="offsets in mm at this display (default: the profile's offsets_m)")
    ap.add_argument("--scale", choices=["smoke", "paper"], default="paper",
                    help="smoke: minutes on 2 CPU cores, a check; paper: the paper's dataset and schedule")
    ap.add_argument("--nproc", type=int, default=0, metavar="N",
                    help="train on N processes of this node under torchrun (N GPUs; gloo on CPU)")
    ap.add_argument("--shards", type=int, default=1, metavar="N",
                    help="make the dataset in N local processes (holo dataset --shard I/N, then --merge)")
    ap.add_argument("--threads", type=int, default=0, help="holo dataset threads per process (0: all cores, shared among --shards)")
    ap.add_argument("--out", required=True, metavar="DIR", help="dataset/, runs/ and models/ go here")
    ap.add_argument("--data", help="dataset folder (default OUT/dataset)")
    ap.add_argument("--runs", help="training runs folder (default OUT/runs)")
    ap.add_argument("--models", help="exported models folder (default OUT/models)")
    ap.add_argument("--stage1-epochs", type=float, default=0, help="override the scale's stage-1 epochs")
    ap.add_argument("--stage2-epochs", type=float, default=0, help="override the scale's stage-2 epochs")
    ap.add_argument("--holo", default=os.environ.get("HOLO", "holo"), help="the holo binary (default $HOLO)")
    ap.add_argument("--root", default=os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                    help=argparse.SUPPRESS)
    ap.add_argument("--dry-run", action="store_true", help="print the commands and exit")
    args = ap.parse_args(argv)
    if args.nproc < 0 or args.shards < 1:
        ap.error("--nproc must be ≥ 0 and --shards ≥ 1")
    if args.offsets_mm is not None and (not args.offsets_mm or any(o < 0 or not math.isfinite(o)
                                                                     for o in args.offsets_mm)):
        ap.error(f"--offsets-mm must be distances ≥ 0 in mm, got {args.offsets_mm}")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        profile = read_profile(args.display)
        plan = build_plan(args, profile)
        warning = receptive_field_warning(profile.display, args.layers)
        if warning:
            print(f"retrain: warning: {warning}", file=sys.stderr)
        if args.dry_run:
            for title, argv_ in plan.steps:
                print(f"# {title}\n{shlex.join(argv_)}")
            print(f"# then\n{render_line(plan)}")
            return 0
        check_record(plan)
        t0 = time.monotonic()
        timings = run_steps(plan)
    except FileNotFoundError as e:
        print(f"retrain: error: `{e.filename}` not found (HOLO names the holo binary, PYTHON the Python)",
              file=sys.stderr)
        return 2
    except RetrainError as e:
        print(f"retrain: error: {e}", file=sys.stderr)
        return 2
    report = {"display": profile.raw, "scale": args.scale, "layers": args.layers, "input": args.input,
              "offsets_mm": plan.offsets_mm, "nproc": args.nproc, "shards": args.shards, "cpus": os.cpu_count(),
              "steps": timings, "wall_seconds": time.monotonic() - t0,
              "models": [os.path.join(plan.models, f"{n}.onnx") for n in plan.names()]}
    with open(os.path.join(args.out, "retrain-report.json"), "w") as f:
        json.dump(report, f, indent=1)
    print(f"== done in {report['wall_seconds'] / 60:.1f} min ({os.path.join(args.out, 'retrain-report.json')}): "
          + ", ".join(f"{t['step']} {t['seconds']:.0f} s" for t in timings))
    for name in plan.names():
        ev = os.path.join(plan.models, f"{name}.eval.json")
        if os.path.exists(ev):
            with open(ev) as f:
                scores = json.load(f)
            means = {k: round(v, 3) for k, v in scores.get("model", {}).get("mean", {}).items()}
            print(f"   {name}: {json.dumps(means)} (Table 2 protocol, {ev})")
    print("Render with the retrained models:\n  " + render_line(plan))
    return 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""onnxruntime reference for the hologram and pre-filter CNNs, plus the machine's float32 matmul peak.

What it measures
----------------
1. Matmul peak: NumPy float32 `a @ b` on square n×n matrices (default n = 1024, 2048), FLOPs = 2·n³,
   best of --matmul-repeat runs after one warm-up, for each thread count of --threads. Each thread count
   runs in a fresh subprocess of this script whose OPENBLAS/OMP/MKL/... thread variables are set before
   NumPy is imported (threadpoolctl, when installed, also caps the pool and reports what the BLAS really
   used). This is the ceiling any CPU convolution engine (onnxruntime's MLAS, tract) can approach.
2. onnxruntime, CPUExecutionProvider, `intra_op_num_threads` = each of --threads, `inter_op_num_threads`
   = 1, graph optimisation level ALL, sequential execution, on every ONNX file given (default:
   `models/holo{8,15,30}_rgbd{,.int8-qop,.int8-qdq}.onnx` and `models/prefilter_{6,12}mm{,.int8-qop,
   .int8-qdq}.onnx`; missing files are skipped with a note) at each --sizes resolution (H×W; default
   384×384, 540×960 and 1080×1920). The input is the session's single input (`rgbd` [1, 4, H, W] for
   hologram CNNs, `slm_field` [1, 6, H, W] for pre-filters), uniform [0, 1) float32 with a fixed seed.
   One untimed warm-up run, then up to --repeat timed runs (time.perf_counter around `session.run`),
   stopping early once the case (warm-up included) has used --max-seconds, but always with at least one
   timed run. Reported: median ms, FPS = 1000 / median ms, GFLOP/s.

   GFLOP/s counts the network's convolution multiply-adds, read from the ONNX graph itself: for every
   Conv / QLinearConv / ConvInteger node, MACs per output pixel = C_out · (C_in / groups) · kH · kW = the
   product of the weight's dims (the weight initializer, also when it is reached through a
   DequantizeLinear as in QDQ models; QLinearConv's weight is input 3). Every convolution in these nets is
   stride 1 with 'same' padding, so it has H·W output pixels: FLOPs = 2 · MACs/pixel · H · W (biases,
   activations, residual adds and the heads are not counted). The per-pixel MACs of each file are printed
   for cross-checking: the 30-layer RGB-D net is 147,528 MAC/pixel (training/README.md), i.e. 2 × 147,528
   × 1920 × 1080 ≈ 612 GFLOP per 1080p frame; the 8-layer one is 33,480.

Output: the matmul peak lines and a Markdown table on stdout (model, precision, size, threads, median ms,
FPS, GFLOP/s, runs); progress on stderr; --json FILE writes every result with the machine (CPU model,
core count, load average, NumPy / onnx / onnxruntime versions, BLAS, date).

How it maps to `holo bench`
---------------------------
`holo bench` runs the same ONNX files through tract (the Rust SDK's engine) at the same sizes and thread
counts, from the same kind of input, and its table has the same columns, so the two tables go side by side
in docs/BENCHMARKS.md: same model + size + threads row = same work (same FLOPs), so the GFLOP/s columns
compare the engines directly, and both compare against the matmul peak printed here.

Run (from the repository root; the CPU should otherwise be idle):

    .venv/bin/python benchmarks/cnn_onnxruntime.py --json cnn_onnxruntime.json
    .venv/bin/python benchmarks/cnn_onnxruntime.py models/holo30_rgbd.onnx --sizes 1080x1920 --threads 2
    .venv/bin/python benchmarks/cnn_onnxruntime.py --skip-matmul --sizes 64x64 --repeat 1 \\
        sdk/tests/fixtures/models/holo8_rgbd.onnx                                  # quick smoke test
"""

import os

# BLAS threads: set before NumPy is imported. The parent (onnxruntime) process pins its BLAS to one
# thread so that an idle OpenBLAS pool does not compete with onnxruntime's own threads; the matmul
# workers are re-executions of this script with _TENSORHOLO_BLAS_THREADS set to the thread count wanted.
_BLAS_THREADS = os.environ.get("_TENSORHOLO_BLAS_THREADS", "1")
THREAD_VARS = (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
    "BLIS_NUM_THREADS",
)
for _var in THREAD_VARS:
    os.environ[_var] = _BLAS_THREADS

import argparse  # noqa: E402
import datetime  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import re  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from machine import cpu_model  # noqa: E402  (benchmarks/machine.py, beside this script)

try:  # optional: only used to cap and report the BLAS pool of the matmul workers
    import threadpoolctl  # noqa: E402
except ImportError:
    threadpoolctl = None

REPO = Path(__file__).resolve().parent.parent
DEFAULT_MODELS = [
    f"models/{stem}{suffix}.onnx"
    for stem in ("holo8_rgbd", "holo15_rgbd", "holo30_rgbd", "prefilter_6mm", "prefilter_12mm")
    for suffix in ("", ".int8-qop", ".int8-qdq")
]
DEFAULT_SIZES = "384x384,540x960,1080x1920"
SEED = 0


# --------------------------------------------------------------------------------------------------
# Matmul peak
# --------------------------------------------------------------------------------------------------


def blas_name():
    """BLAS NumPy was built against (NumPy ≥ 1.25 exposes its build config as a dict)."""
    try:
        cfg = np.show_config(mode="dicts")
        blas = cfg["Build Dependencies"]["blas"]
        return f"{blas.get('name', '?')} {blas.get('version', '')}".strip()
    except Exception:  # older NumPy, or a layout change: not worth failing for
        return "unknown"


def matmul_worker(sizes, repeat):
    """Runs inside a fresh subprocess whose BLAS thread variables are already set; prints one JSON line."""
    threads = int(_BLAS_THREADS)
    limiter = threadpoolctl.threadpool_limits(limits=threads, user_api="blas") if threadpoolctl else None
    rng = np.random.default_rng(SEED)
    out = {"threads": threads, "results": []}
    for n in sizes:
        a = rng.random((n, n), dtype=np.float32)
        b = rng.random((n, n), dtype=np.float32)
        c = np.empty((n, n), np.float32)
        np.matmul(a, b, out=c)  # warm-up (also spins up the BLAS pool)
        best = float("inf")
        for _ in range(repeat):
            t0 = time.perf_counter()
            np.matmul(a, b, out=c)
            best = min(best, time.perf_counter() - t0)
        flops = 2.0 * n**3
        out["results"].append(
            {"n": n, "best_ms": 1e3 * best, "gflops": flops / best / 1e9, "repeat": repeat}
        )
    if threadpoolctl:
        out["threadpoolctl"] = [
            {k: p.get(k) for k in ("internal_api", "num_threads", "version", "architecture")}
            for p in threadpoolctl.threadpool_info()
            if p.get("user_api") == "blas"
        ]
    if limiter is not None:
        limiter.restore_original_limits()
    print(json.dumps(out))


def matmul_peak(threads_list, sizes, repeat):
    results = []
    for t in threads_list:
        env = dict(os.environ)
        env["_TENSORHOLO_BLAS_THREADS"] = str(t)
        for var in THREAD_VARS:
            env[var] = str(t)
        cmd = [
            sys.executable,
            os.path.abspath(__file__),
            "--_matmul-worker",
            "--matmul-sizes",
            ",".join(map(str, sizes)),
            "--matmul-repeat",
            str(repeat),
        ]
        print(f"  matmul, {t} thread(s), n = {sizes} ...", file=sys.stderr)
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            sys.exit(f"matmul worker failed ({proc.returncode}):\n{proc.stderr}")
        worker = json.loads(proc.stdout.strip().splitlines()[-1])
        for r in worker["results"]:
            r["threads"] = t
            if "threadpoolctl" in worker:
                r["blas_pools"] = worker["threadpoolctl"]
            results.append(r)
            print(f"    n={r['n']}: {r['gflops']:.1f} GFLOP/s", file=sys.stderr)
    return results


# --------------------------------------------------------------------------------------------------
# ONNX graph: multiply-adds per output pixel
# --------------------------------------------------------------------------------------------------

CONV_WEIGHT_INPUT = {"Conv": 1, "ConvInteger": 1, "QLinearConv": 3}
# Nodes a weight may pass through between its initializer and the convolution (QDQ models, exporters).
PASS_THROUGH = {"DequantizeLinear", "QuantizeLinear", "Identity", "Cast"}


def conv_macs(model):
    """(MACs per output pixel, number of convolutions, notes) of an onnx.ModelProto's main graph."""
    from onnx import numpy_helper  # imported with onnx by the caller

    g = model.graph
    shapes = {init.name: list(init.dims) for init in g.initializer}
    producer = {}
    for node in g.node:
        for out in node.output:
            producer[out] = node
        if node.op_type == "Constant":
            for attr in node.attribute:
                if attr.name == "value":
                    shapes[node.output[0]] = list(numpy_helper.to_array(attr.t).shape)

    def weight_shape(name, depth=0):
        if name in shapes:
            return shapes[name]
        node = producer.get(name)
        if node is not None and node.op_type in PASS_THROUGH and depth < 8:
            return weight_shape(node.input[0], depth + 1)
        return None

    macs, convs, notes = 0, 0, []
    for node in g.node:
        idx = CONV_WEIGHT_INPUT.get(node.op_type)
        if idx is None:
            continue
        shape = weight_shape(node.input[idx])
        if shape is None or len(shape) != 4:
            notes.append(f"{node.op_type} {node.name!r}: weight shape {shape} not resolved, not counted")
            continue
        attrs = {a.name: a for a in node.attribute}
        strides = list(attrs["strides"].ints) if "strides" in attrs else [1, 1]
        dilations = list(attrs["dilations"].ints) if "dilations" in attrs else [1, 1]
        if any(s != 1 for s in strides):
            notes.append(f"{node.op_type} {node.name!r}: strides {strides}; counted as H·W outputs anyway")
        if any(d != 1 for d in dilations):
            notes.append(f"{node.op_type} {node.name!r}: dilations {dilations}")
        # weight [C_out, C_in/groups, kH, kW]: MACs per output pixel = product of its dims
        macs += shape[0] * shape[1] * shape[2] * shape[3]
        convs += 1
    return macs, convs, notes


def precision_of(path, meta):
    if "tensorholo.precision" in meta:
        return meta["tensorholo.precision"]
    name = path.name
    if ".int8-qop" in name:
        return "int8-qop (name)"
    if ".int8-qdq" in name:
        return "int8-qdq (name)"
    return "f32 (name)"


# --------------------------------------------------------------------------------------------------
# onnxruntime
# --------------------------------------------------------------------------------------------------


def make_session(ort, path, threads):
    so = ort.SessionOptions()
    so.intra_op_num_threads = threads
    so.inter_op_num_threads = 1
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    so.log_severity_level = 3  # errors only
    return ort.InferenceSession(str(path), sess_options=so, providers=["CPUExecutionProvider"])


def time_case(sess, feed, repeat, max_seconds):
    """One warm-up run, then up to `repeat` timed runs within `max_seconds` (at least one timed run)."""
    t_case = time.perf_counter()
    t0 = time.perf_counter()
    sess.run(None, feed)
    warmup_ms = 1e3 * (time.perf_counter() - t0)
    times = []
    while len(times) < repeat:
        if times and time.perf_counter() - t_case > max_seconds:
            break
        t0 = time.perf_counter()
        sess.run(None, feed)
        times.append(1e3 * (time.perf_counter() - t0))
    return warmup_ms, times


def bench_models(ort, onnx, paths, sizes, threads_list, repeat, max_seconds):
    models, results = [], []
    for path in paths:
        if not path.exists():
            print(f"note: {path} not found, skipped", file=sys.stderr)
            models.append({"file": str(path), "skipped": "not found"})
            continue
        model = onnx.load(str(path))
        meta = {p.key: p.value for p in model.metadata_props}
        macs, convs, notes = conv_macs(model)
        del model
        name = path.name[: -len(".onnx")] if path.name.endswith(".onnx") else path.name
        info = {
            "file": str(path),
            "model": name,
            "precision": precision_of(path, meta),
            "macs_per_pixel": macs,
            "convs": convs,
            "metadata": meta,
            "notes": notes,
        }
        models.append(info)
        for note in notes:
            print(f"note: {path.name}: {note}", file=sys.stderr)
        for t in threads_list:
            sess = make_session(ort, path, t)
            inputs = sess.get_inputs()
            if len(inputs) != 1:
                sys.exit(f"{path}: {len(inputs)} inputs, expected 1")
            inp = inputs[0]
            info["input"] = {"name": inp.name, "shape": [str(d) for d in inp.shape], "type": inp.type}
            channels = inp.shape[1]
            if not isinstance(channels, int):
                sys.exit(f"{path}: input {inp.name} has a symbolic channel dim {channels!r}")
            for h, w in sizes:
                fixed = [(i, d) for i, d in ((2, h), (3, w)) if isinstance(inp.shape[i], int)]
                if any(inp.shape[i] != d for i, d in fixed):
                    print(f"note: {name}: fixed input shape {inp.shape}, {h}x{w} skipped", file=sys.stderr)
                    continue
                x = np.random.default_rng(SEED).random((1, channels, h, w), dtype=np.float32)
                warmup_ms, times = time_case(sess, {inp.name: x}, repeat, max_seconds)
                med = statistics.median(times)
                gflop = 2.0 * macs * h * w / 1e9
                r = {
                    "model": name,
                    "file": str(path),
                    "precision": info["precision"],
                    "height": h,
                    "width": w,
                    "threads": t,
                    "input": inp.name,
                    "input_shape": [1, channels, h, w],
                    "macs_per_pixel": macs,
                    "gflop_per_run": gflop,
                    "warmup_ms": warmup_ms,
                    "runs": len(times),
                    "times_ms": times,
                    "median_ms": med,
                    "min_ms": min(times),
                    "fps": 1e3 / med,
                    "gflops": gflop / (med / 1e3),
                }
                results.append(r)
                print(
                    f"  {name} {h}x{w} {t}T: median {med:.2f} ms over {len(times)} run(s), "
                    f"{r['gflops']:.1f} GFLOP/s",
                    file=sys.stderr,
                )
            del sess
    return models, results


# --------------------------------------------------------------------------------------------------
# Environment, output
# --------------------------------------------------------------------------------------------------


def loadavg():
    try:
        return list(os.getloadavg())
    except (OSError, AttributeError):
        return None


def environment(ort, onnx):
    env = {
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "processor": cpu_model(),
        "cpu_count": os.cpu_count(),
        "machine": platform.machine(),
        "system": platform.platform(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "blas": blas_name(),
        "threadpoolctl": getattr(threadpoolctl, "__version__", None),
        "onnx": getattr(onnx, "__version__", None),
        "onnxruntime": getattr(ort, "__version__", None),
        "loadavg_start": loadavg(),
    }
    if hasattr(os, "sched_getaffinity"):
        env["cpus_available"] = len(os.sched_getaffinity(0))
    return env


def parse_sizes(text):
    sizes = []
    for item in text.split(","):
        item = item.strip().lower().replace("×", "x")
        if not item:
            continue
        try:
            h, w = (int(v) for v in item.split("x"))
        except ValueError:
            raise argparse.ArgumentTypeError(f"size {item!r} is not HxW") from None
        if h <= 0 or w <= 0:
            raise argparse.ArgumentTypeError(f"size {item!r} is not positive")
        sizes.append((h, w))
    return sizes


def parse_ints(text):
    try:
        vals = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a comma-separated list of integers") from None
    if any(v <= 0 for v in vals):
        raise argparse.ArgumentTypeError(f"{text!r}: values must be positive")
    return vals


def print_report(env, matmul, models, results, args):
    print(
        f"Machine: {env['processor']}, {env['cpu_count']} CPUs; NumPy {env['numpy']} ({env['blas']}), "
        f"onnxruntime {env['onnxruntime']}, onnx {env['onnx']}; {env['date']}\n"
    )
    if matmul:
        print(f"Matmul peak (NumPy float32 n×n @ n×n, 2·n³ FLOPs, best of {args.matmul_repeat}):\n")
        for t in sorted({r["threads"] for r in matmul}):
            rows = [r for r in matmul if r["threads"] == t]
            parts = ", ".join(f"n={r['n']} {r['gflops']:.1f} GFLOP/s ({r['best_ms']:.1f} ms)" for r in rows)
            best = max(r["gflops"] for r in rows)
            print(f"- {t} thread{'s' if t > 1 else ''}: {parts}; peak {best:.1f} GFLOP/s")
        print()
    counted = [m for m in models if "skipped" not in m]
    if counted:
        print("Convolution multiply-adds per output pixel (from the ONNX graph):\n")
        for m in counted:
            layers = m["metadata"].get("tensorholo.layers")
            extra = f", tensorholo.layers = {layers}" if layers else ""
            named = re.match(r"holo(\d+)_", m["model"])
            if named and int(named.group(1)) != m["convs"]:
                extra += f"; NOTE: the file name says {named.group(1)} layers"
            print(f"- {m['model']}: {m['macs_per_pixel']:,} MAC/pixel ({m['convs']} convolutions{extra})")
        print()
    skipped = [m for m in models if "skipped" in m]
    for m in skipped:
        print(f"- skipped {m['file']}: {m['skipped']}")
    if skipped:
        print()
    if not results:
        return
    print(
        f"onnxruntime {env['onnxruntime']}, CPUExecutionProvider, inter-op 1 thread, ORT_ENABLE_ALL, "
        f"sequential; 1 warm-up, median of ≤ {args.repeat} runs (≤ {args.max_seconds:g} s per case)\n"
    )
    print("| model | precision | size (HxW) | threads | ms (median) | FPS | GFLOP/s | runs |")
    print("|---|---|---|---:|---:|---:|---:|---:|")
    order = {m["file"]: i for i, m in enumerate(counted)}
    size_order = {s: i for i, s in enumerate(args.sizes)}
    for r in sorted(
        results, key=lambda r: (order[r["file"]], size_order[(r["height"], r["width"])], r["threads"])
    ):
        print(
            f"| {r['model']} | {r['precision']} | {r['height']}x{r['width']} | {r['threads']} | "
            f"{r['median_ms']:.2f} | {r['fps']:.2f} | {r['gflops']:.1f} | {r['runs']} |"
        )


def main():
    ap = argparse.ArgumentParser(
        description="onnxruntime CPU reference for the tensorholo CNNs (ms, FPS, GFLOP/s) and the "
        "machine's NumPy float32 matmul peak.",
        epilog="See the module docstring and benchmarks/README.md.",
    )
    ap.add_argument(
        "models",
        nargs="*",
        type=Path,
        help="ONNX files (default: models/holo{8,15,30}_rgbd{,.int8-qop,.int8-qdq}.onnx and "
        "models/prefilter_{6,12}mm{,.int8-qop,.int8-qdq}.onnx, missing ones skipped)",
    )
    ap.add_argument(
        "--sizes",
        type=parse_sizes,
        default=parse_sizes(DEFAULT_SIZES),
        metavar="HxW,...",
        help=f"resolutions as height x width (default {DEFAULT_SIZES})",
    )
    ap.add_argument(
        "--threads",
        type=parse_ints,
        default=[1, 2],
        metavar="N,...",
        help="intra-op threads for onnxruntime and BLAS threads for the matmul (default 1,2)",
    )
    ap.add_argument("--repeat", type=int, default=3, help="timed runs per case (default 3)")
    ap.add_argument(
        "--max-seconds",
        type=float,
        default=60.0,
        help="time budget per case, warm-up included: stop repeating once spent (at least one timed "
        "run is kept; default 60)",
    )
    ap.add_argument(
        "--matmul-sizes",
        type=parse_ints,
        default=[1024, 2048],
        metavar="N,...",
        help="square matmul sizes (default 1024,2048)",
    )
    ap.add_argument("--matmul-repeat", type=int, default=5, help="matmul runs, best kept (default 5)")
    ap.add_argument("--skip-matmul", action="store_true", help="do not measure the matmul peak")
    ap.add_argument("--skip-onnx", action="store_true", help="only measure the matmul peak")
    ap.add_argument("--json", metavar="FILE", help="write all results and the machine info as JSON")
    ap.add_argument("--_matmul-worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.repeat < 1 or args.matmul_repeat < 1:
        ap.error("--repeat and --matmul-repeat must be at least 1")

    if args._matmul_worker:
        matmul_worker(args.matmul_sizes, args.matmul_repeat)
        return

    try:
        import onnx
        import onnxruntime as ort
    except ImportError as e:
        sys.exit(f"{e}: install benchmarks/requirements.txt (numpy, onnx, onnxruntime)")

    if "CPUExecutionProvider" not in ort.get_available_providers():
        sys.exit("onnxruntime has no CPUExecutionProvider")

    env = environment(ort, onnx)
    matmul = [] if args.skip_matmul else matmul_peak(args.threads, args.matmul_sizes, args.matmul_repeat)
    models, results = [], []
    if not args.skip_onnx:
        paths = args.models or [REPO / p for p in DEFAULT_MODELS]
        models, results = bench_models(
            ort, onnx, paths, args.sizes, args.threads, args.repeat, args.max_seconds
        )
    env["loadavg_end"] = loadavg()
    print_report(env, matmul, models, results, args)

    if args.json:
        settings = {
            "sizes_hw": [list(s) for s in args.sizes],
            "threads": args.threads,
            "repeat": args.repeat,
            "max_seconds": args.max_seconds,
            "warmup": 1,
            "seed": SEED,
            "input": "uniform [0, 1) float32",
            "onnxruntime_session": {
                "providers": ["CPUExecutionProvider"],
                "inter_op_num_threads": 1,
                "graph_optimization_level": "ORT_ENABLE_ALL",
                "execution_mode": "ORT_SEQUENTIAL",
            },
            "matmul_sizes": args.matmul_sizes,
            "matmul_repeat": args.matmul_repeat,
        }
        with open(args.json, "w") as f:
            json.dump(
                {
                    "environment": env,
                    "settings": settings,
                    "matmul": matmul,
                    "models": models,
                    "results": results,
                },
                f,
                indent=2,
            )
            f.write("\n")


if __name__ == "__main__":
    main()

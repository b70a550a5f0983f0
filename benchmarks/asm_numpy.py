#!/usr/bin/env python3
"""NumPy reference for the angular spectrum method (ASM): benchmark and interop check.

ASM (docs/CONVENTIONS.md §5.1, paper Eq. 2):

    ASM(u, z) = ifft2( fft2(u) · exp(i·2π·z·sqrt(λ⁻² − fx² − fy²)) ),   evanescent (λ⁻² < fx² + fy²) zeroed,

with fx = np.fft.fftfreq(W, pitch), fy = np.fft.fftfreq(H, pitch) (cycles per metre), positive z along
the light. With --pad the field is zero-padded to 2H × 2W (centred: offset H//2, W//2), propagated and
cropped back (linear instead of circular convolution). Fields are complex64; NumPy ≥ 2 runs its
pocketfft in single precision for complex64, on one thread.

Benchmark mode (default): times fft2 · H · ifft2 (+ pad/crop) with the transfer function precomputed
(excluded, like the Rust propagator's cached plan), reports the median of --runs timed runs
(time.perf_counter) after --warmup untimed ones, as a markdown table; --json FILE writes the results.

    python benchmarks/asm_numpy.py [--runs 20] [--json asm_numpy.json]

Interop mode: propagate an input .npy (complex [H, W] or [C, H, W]) and write the result (complex64,
same shape) so that the Rust propagator can be compared with it:

    python benchmarks/asm_numpy.py --input field.npy --output out.npy \\
        --distance-m 3e-3 --wavelength-m 520e-9 --pitch-m 8e-6 [--pad]

(--wavelength-m takes one value for every channel, or one per channel, e.g. 638e-9 520e-9 450e-9.)
"""

import os

# Single thread: set before NumPy is imported (pocketfft is single-threaded anyway; this pins any
# BLAS that NumPy may load).
for _var in (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
    "BLIS_NUM_THREADS",
):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from machine import cpu_model  # noqa: E402  (benchmarks/machine.py, beside this script)

PITCH_M = 8e-6
WAVELENGTH_M = 520e-9
DISTANCE_M = 3e-3

# (name, height, width, pad)
CASES = [
    ("384x384", 384, 384, False),
    ("384x384 pad", 384, 384, True),
    ("1920x1080", 1080, 1920, False),
    ("1920x1080 pad", 1080, 1920, True),
]


def transfer_function(h, w, pitch_m, wavelength_m, distance_m):
    """ASM transfer function on the (h, w) FFT grid, complex64; evanescent frequencies are 0.

    Computed in float64 (the phase 2πz·sqrt(...) is large: z/λ ≈ 5800 turns at 3 mm, 520 nm), then
    rounded to complex64.
    """
    fx = np.fft.fftfreq(w, pitch_m)
    fy = np.fft.fftfreq(h, pitch_m)
    arg = wavelength_m**-2 - fy[:, None] ** 2 - fx[None, :] ** 2
    prop = arg > 0
    kz = np.sqrt(np.where(prop, arg, 0.0))
    tf = np.where(prop, np.exp(1j * 2 * np.pi * distance_m * kz), 0.0)
    return tf.astype(np.complex64)


class Propagator:
    """Precomputed ASM for one (H, W, pitch, λ, z, pad): transfer function and padding scratch."""

    def __init__(self, h, w, pitch_m, wavelength_m, distance_m, pad):
        self.h, self.w, self.pad = h, w, pad
        if pad:
            self.top, self.left = h // 2, w // 2
            self.tf = transfer_function(2 * h, 2 * w, pitch_m, wavelength_m, distance_m)
            # Reused zero scratch: only the centre is ever written, so the border stays 0.
            self.scratch = np.zeros((2 * h, 2 * w), np.complex64)
        else:
            self.tf = transfer_function(h, w, pitch_m, wavelength_m, distance_m)

    def __call__(self, u):
        assert u.shape == (self.h, self.w) and u.dtype == np.complex64
        if self.pad:
            t, l = self.top, self.left
            self.scratch[t : t + self.h, l : l + self.w] = u
            spec = np.fft.fft2(self.scratch)
            spec *= self.tf
            out = np.fft.ifft2(spec)
            return np.ascontiguousarray(out[t : t + self.h, l : l + self.w])
        spec = np.fft.fft2(u)
        spec *= self.tf
        return np.fft.ifft2(spec)


def random_field(h, w, seed=0):
    rng = np.random.default_rng(seed)
    amp = rng.uniform(0.0, 1.0, (h, w))
    phase = rng.uniform(0.0, 2 * np.pi, (h, w))
    return (amp * np.exp(1j * phase)).astype(np.complex64)


def bench(runs, warmup, cases):
    results = []
    for name, h, w, pad in cases:
        prop = Propagator(h, w, PITCH_M, WAVELENGTH_M, DISTANCE_M, pad)
        u = random_field(h, w)
        out = None
        for _ in range(warmup):
            out = prop(u)
        assert out is None or out.dtype == np.complex64, out.dtype
        times = []
        for _ in range(runs):
            t0 = time.perf_counter()
            prop(u)
            times.append(time.perf_counter() - t0)
        ms = [1e3 * t for t in times]
        results.append(
            {
                "case": name,
                "height": h,
                "width": w,
                "pad": pad,
                "fft_shape": [2 * h, 2 * w] if pad else [h, w],
                "runs": runs,
                "median_ms": statistics.median(ms),
                "min_ms": min(ms),
            }
        )
        print(f"  {name}: median {statistics.median(ms):.2f} ms", file=sys.stderr)
    return results


def environment():
    return {
        "numpy": np.__version__,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "processor": cpu_model(),
        "cpu_count": os.cpu_count(),
        "threads": 1,
        "pitch_m": PITCH_M,
        "wavelength_m": WAVELENGTH_M,
        "distance_m": DISTANCE_M,
        "dtype": "complex64",
    }


def interop(args):
    u = np.load(args.input)
    if not np.iscomplexobj(u):
        sys.exit(f"{args.input}: dtype {u.dtype.str} is not complex")
    if u.ndim == 2:
        stack = u[None]
    elif u.ndim == 3:
        stack = u
    else:
        sys.exit(f"{args.input}: shape {u.shape}, expected [H, W] or [C, H, W]")
    c, h, w = stack.shape
    wl = args.wavelength_m
    if len(wl) == 1:
        wl = wl * c
    if len(wl) != c:
        sys.exit(f"{len(wl)} wavelengths given for {c} channels")
    out = np.empty((c, h, w), np.complex64)
    for ch in range(c):
        prop = Propagator(h, w, args.pitch_m, wl[ch], args.distance_m, args.pad)
        out[ch] = prop(np.ascontiguousarray(stack[ch], dtype=np.complex64))
    np.save(args.output, out if u.ndim == 3 else out[0])
    print(
        f"wrote {args.output}: complex64 {out.shape if u.ndim == 3 else out.shape[1:]}, "
        f"z={args.distance_m} m, λ={wl} m, pitch={args.pitch_m} m, pad={args.pad}"
    )


def main():
    ap = argparse.ArgumentParser(
        description="NumPy angular spectrum method: benchmark (default) or propagate an .npy file.",
        epilog="See the module docstring and benchmarks/README.md.",
    )
    ap.add_argument("--runs", type=int, default=20, help="timed runs per case (default 20)")
    ap.add_argument("--warmup", type=int, default=2, help="untimed runs first (default 2)")
    ap.add_argument("--cases", nargs="+", metavar="NAME", help="subset of: " + ", ".join(
        repr(c[0]) for c in CASES))
    ap.add_argument("--json", metavar="FILE", help="write benchmark results as JSON")
    ap.add_argument("--input", metavar="NPY", help="interop: complex [H,W] or [C,H,W] field")
    ap.add_argument("--output", metavar="NPY", help="interop: where to write the propagated field")
    ap.add_argument("--distance-m", type=float, default=DISTANCE_M)
    ap.add_argument("--wavelength-m", type=float, nargs="+", default=[WAVELENGTH_M])
    ap.add_argument("--pitch-m", type=float, default=PITCH_M)
    ap.add_argument("--pad", action="store_true", help="2x zero padding (linear convolution)")
    args = ap.parse_args()

    if args.input or args.output:
        if not (args.input and args.output):
            ap.error("--input and --output go together")
        if os.path.exists(args.output) and os.path.samefile(args.input, args.output):
            ap.error("refusing to overwrite the input file")
        interop(args)
        return

    cases = CASES
    if args.cases:
        unknown = set(args.cases) - {c[0] for c in CASES}
        if unknown:
            ap.error(f"unknown case(s) {sorted(unknown)}")
        cases = [c for c in CASES if c[0] in args.cases]
    results = bench(args.runs, args.warmup, cases)
    env = environment()
    print(
        f"NumPy {env['numpy']} ASM, complex64, 1 thread, pitch {PITCH_M} m, λ {WAVELENGTH_M} m, "
        f"z {DISTANCE_M} m, median of {args.runs} runs ({env['processor']}, {env['cpu_count']} CPUs)\n"
    )
    print("| case | FFT size | median ms | min ms |")
    print("|---|---|---:|---:|")
    for r in results:
        fh, fw = r["fft_shape"]
        print(f"| {r['case']} | {fw}x{fh} | {r['median_ms']:.2f} | {r['min_ms']:.2f} |")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"environment": env, "results": results}, f, indent=2)
            f.write("\n")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""An independent NumPy implementation of the focal-stack refinement (docs/REFINE.md), to time it beside
`holo render --refine` and to check its loss trajectory.

Model, per colour: u = exp(iφ); U_d = ifft2(fft2(u) · M · H_d) with M the Fourier filter's circular aperture
(radius min(H, W)/2 frequency bins) and H_d the carrier-free angular spectrum transfer function over
z_d − s (z_d = (0.5 − d)·volume, s the SLM offset); loss Σ_d ‖k·|U_d| − T_d‖², k the least-squares scale;
its gradient through the adjoint of each U_d; Adam on φ (β₁ 0.9, β₂ 0.999, ε 1e-8). complex64 throughout,
one thread (NumPy's pocketfft is single-threaded).

    python benchmarks/refine_numpy.py --size 384x384 --iterations 10 [--runs 3] [--json F]

With --midpoint M.npy (complex [3, H, W], the target midpoint hologram) and --start P.npy (float32
[3, H, W] radians) it refines that start against that target and prints the PSNR at the loss planes per
iteration, as `holo render --refine` reports it; without, a random start and a smooth random target of
--size (timings do not depend on the data).
"""

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse
import json
import platform
import time

import numpy as np

WAVELENGTHS = (638e-9, 520e-9, 450e-9)


def transfer(h, w, pitch, lam, z):
    fx = np.fft.fftfreq(w, pitch)
    fy = np.fft.fftfreq(h, pitch)
    f2 = fy[:, None] ** 2 + fx[None, :] ** 2
    arg = 1.0 / lam**2 - f2
    ok = arg > 0
    kz = np.sqrt(np.where(ok, arg, 0.0))
    phase = -2.0 * np.pi * z * f2 / (kz + 1.0 / lam)
    return np.where(ok, np.exp(1j * phase), 0.0).astype(np.complex64)


def aperture(h, w):
    ky = np.fft.fftfreq(h) * h
    kx = np.fft.fftfreq(w) * w
    r = min(h, w) / 2.0
    return ((ky[:, None] ** 2 + kx[None, :] ** 2) <= r * r).astype(np.float32)


def plane_depths(planes):
    return [0.5] if planes == 1 else [k / (planes - 1) for k in range(planes)]


class Model:
    def __init__(self, h, w, pitch, volume, offset, depths):
        m = aperture(h, w)
        self.mult = [
            [m * transfer(h, w, pitch, lam, (0.5 - d) * volume - offset) for d in depths]
            for lam in WAVELENGTHS
        ]

    def loss_grad(self, phase, target, gradient=True):
        loss, grads = 0.0, []
        for c in range(3):
            u = np.exp(1j * phase[c]).astype(np.complex64)
            s = np.fft.fft2(u)
            fields = [np.fft.ifft2(s * m) for m in self.mult[c]]
            amps = [np.abs(f) for f in fields]
            a = sum(float(np.sum(am * t)) for am, t in zip(amps, target[c]))
            b = sum(float(np.sum(am * am)) for am in amps)
            e = sum(float(np.sum(t * t)) for t in target[c])
            k = a / b if b > 0 else 0.0
            loss += e - a * a / b if b > 0 else e
            if gradient:
                g = np.zeros_like(s)
                for f, am, t, m in zip(fields, amps, target[c], self.mult[c]):
                    gu = 2 * k * (k * am - t) * np.where(am > 0, f / np.where(am > 0, am, 1), 0)
                    # Adjoint of ifft2(fft2(·)·m): ifft2(fft2(·)·conj(m)).
                    g += np.fft.fft2(gu.astype(np.complex64)) * np.conj(m)
                g = np.fft.ifft2(g)
                grads.append(np.imag(g * np.conj(u)).astype(np.float32))
        return loss, grads


def refine(model, phase, target, iterations, step):
    m = np.zeros_like(phase)
    v = np.zeros_like(phase)
    history = []
    for t in range(1, iterations + 1):
        loss, grads = model.loss_grad(phase, target)
        history.append(loss)
        g = np.stack(grads)
        m = 0.9 * m + 0.1 * g
        v = 0.999 * v + 0.001 * g * g
        phase = phase - step * (m / (1 - 0.9**t)) / (np.sqrt(v / (1 - 0.999**t)) + 1e-8)
    history.append(model.loss_grad(phase, target, gradient=False)[0])
    return phase, history


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--size", default="384x384")
    p.add_argument("--iterations", type=int, default=10)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--planes", type=int, default=7)
    p.add_argument("--step", type=float, default=0.02)
    p.add_argument("--pitch-m", type=float, default=8e-6)
    p.add_argument("--volume-m", type=float, default=6e-3)
    p.add_argument("--offset-m", type=float, default=6e-3)
    p.add_argument("--midpoint")
    p.add_argument("--start")
    p.add_argument("--json")
    a = p.parse_args()
    depths = plane_depths(a.planes)
    if a.midpoint:
        mid = np.load(a.midpoint).astype(np.complex64)
        h, w = mid.shape[1:]
    else:
        h, w = (int(x) for x in a.size.split("x"))
        rng = np.random.default_rng(0)
        mid = (rng.random((3, h, w)) * np.exp(1j * rng.random((3, h, w)))).astype(np.complex64)
    start = (
        np.load(a.start).astype(np.float32)
        if a.start
        else np.random.default_rng(1).random((3, h, w)).astype(np.float32) * 2 * np.pi
    )
    tmodel = [[transfer(h, w, a.pitch_m, lam, (0.5 - d) * a.volume_m) for d in depths] for lam in WAVELENGTHS]
    target = [[np.abs(np.fft.ifft2(np.fft.fft2(mid[c]) * m)).astype(np.float32) for m in tmodel[c]] for c in range(3)]
    model = Model(h, w, a.pitch_m, a.volume_m, a.offset_m, depths)
    times = []
    for _ in range(a.runs):
        t = time.perf_counter()
        _, history = refine(model, start.copy(), target, a.iterations, a.step)
        times.append(time.perf_counter() - t)
    n = 3 * len(depths) * h * w
    psnr = [-10 * np.log10(loss / n) for loss in history]
    med = sorted(times)[len(times) // 2]
    print(f"{platform.processor() or platform.machine()}, NumPy {np.__version__}, 1 thread, {h}x{w}, "
          f"{len(depths)} planes: {a.iterations} iterations in {med:.3f} s (median of {a.runs}), "
          f"{med / a.iterations * 1e3:.1f} ms per iteration")
    print("PSNR at the loss planes per iteration:", " ".join(f"{x:.2f}" for x in psnr))
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"size": [h, w], "iterations": a.iterations, "planes": len(depths), "seconds": times,
                       "psnr_db": psnr}, f, indent=1)


if __name__ == "__main__":
    main()

#!/usr/bin/env bash
# Creates a Python virtual environment for training/ and its tests with a CPU-capable PyTorch from PyPI only
# (CI reaches PyPI, crates.io, npm and Debian; not download.pytorch.org).
#
#   training/install_ci.sh [VENV]        default VENV: <repo>/.venv
#
# How: `pip install --no-deps -r requirements-ci.txt` (torch + its pure-python deps, onnx, onnxruntime,
# pytest; ~0.6 GB download), then ci/make_cuda_stubs.py compiles tiny stand-ins for the CUDA libraries that
# PyPI's torch wheel links against, instead of the ~2.3 GB of nvidia-* wheels; torch.cuda.is_available() is
# False and everything else (CPU conv, FFT, autograd, ONNX export) is the real torch. Needs python3 >= 3.11
# with venv, cc and readelf (any machine that links Rust has them). Without cc/readelf, or with
# TENSORHOLO_TORCH_FULL=1 (GPU machines), torch is installed with its CUDA dependencies instead.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
venv="${1:-$here/../.venv}"
py="${PYTHON:-python3}"
start=$(date +%s)

if ! "$py" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)' 2>/dev/null; then
  echo "install_ci: needs python3 >= 3.11 (found: $("$py" --version 2>&1 || echo none))" >&2
  exit 2
fi
if [ ! -x "$venv/bin/python" ]; then
  if ! "$py" -m venv "$venv"; then
    echo "install_ci: '$py -m venv' failed (Debian/Ubuntu: apt-get install python3-venv)" >&2
    exit 2
  fi
fi
pip=("$venv/bin/python" -m pip --disable-pip-version-check)
full=${TENSORHOLO_TORCH_FULL:-0}
if [ "$full" != 1 ] && ! { command -v "${CC:-cc}" >/dev/null && command -v readelf >/dev/null; }; then
  echo "install_ci: no cc/readelf for the CUDA stubs; installing torch with its CUDA dependencies (~2.9 GB)" >&2
  full=1
fi
if [ "$full" = 1 ]; then
  "${pip[@]}" install -q -r "$here/requirements-ci.txt"
else
  "${pip[@]}" install -q --no-deps -r "$here/requirements-ci.txt"
  "$venv/bin/python" "$here/ci/make_cuda_stubs.py"
fi
"$venv/bin/python" - <<'PY'
import torch
x = torch.randn(1, 4, 32, 32, requires_grad=True)
y = torch.nn.Conv2d(4, 8, 3, padding=1)(x)
f = torch.fft.ifft2(torch.fft.fft2(y.to(torch.complex64)))
f.abs().sum().backward()
assert x.grad is not None and torch.isfinite(x.grad).all()
print(f"torch {torch.__version__}: CPU conv/FFT/autograd ok, CUDA available: {torch.cuda.is_available()}")
PY
du -sh "$venv" | awk '{print "install_ci: venv size " $1}'
echo "install_ci: done in $(( $(date +%s) - start )) s"

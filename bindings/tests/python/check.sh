#!/usr/bin/env bash
# Usage: bindings/tests/python/check.sh [BINDINGS_DIR]
#
# Runs the pytest checks of the generated Python bindings (test_bindings.py) in a small venv
# (bindings/tests/python/.venv, or $TENSORHOLO_BINDINGS_VENV) with the pinned requirements.txt, on real frames
# compared with `holo render` ($HOLO, default: the newest holo binary of the target dir).
# BINDINGS_DIR: output of bindings/generate.sh (default $TENSORHOLO_BINDINGS_DIR, else generated now).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
# shellcheck source=bindings/tests/lib.sh
. "$here/../lib.sh"

use_bindings "${1:-}"
py_venv

export HOLO="${HOLO:-$(holo_binary)}"
PYTHONPATH="$dir/python" "$py" -m pytest -q -p no:cacheprovider "$here"

#!/usr/bin/env bash
# Usage: bindings/tests/python/check.sh [BINDINGS_DIR]
#
# Runs the pytest checks of the generated Python bindings (test_bindings.py) in a small venv
# (bindings/tests/python/.venv, or $TENSORHOLO_BINDINGS_VENV) with the pinned requirements.txt.
# BINDINGS_DIR: output of bindings/generate.sh (default $TENSORHOLO_BINDINGS_DIR, else generated now).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
# shellcheck source=bindings/tests/lib.sh
. "$here/../lib.sh"

use_bindings "${1:-}"
venv="${TENSORHOLO_BINDINGS_VENV:-$here/.venv}"

command -v python3 >/dev/null 2>&1 || ensure_apt python3 || skip "python bindings: no python3 and it cannot be installed"
if [ ! -x "$venv/bin/python" ]; then
  if ! python3 -m venv "$venv" >/dev/null 2>&1; then
    rm -rf "$venv"
    ensure_apt python3-venv || skip "python bindings: python3 has no venv module and python3-venv cannot be installed"
    python3 -m venv "$venv"
  fi
fi
# Install only when requirements.txt changed since the last install (idempotent and quiet).
if ! cmp -s "$here/requirements.txt" "$venv/.tensorholo-requirements.txt"; then
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$here/requirements.txt"
  cp "$here/requirements.txt" "$venv/.tensorholo-requirements.txt"
fi

PYTHONPATH="$dir/python" "$venv/bin/python" -m pytest -q -p no:cacheprovider "$here"

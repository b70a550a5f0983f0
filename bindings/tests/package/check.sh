#!/usr/bin/env bash
# Usage: bindings/tests/package/check.sh [BINDINGS_DIR]
#
# The Python package as a user gets it, tested from outside the repository:
#   1. `pip install ./bindings` (PEP 517, maturin, from PyPI) into a fresh venv in a temp dir, with the pinned
#      test requirements (bindings/tests/python/requirements.txt: numpy, Pillow, pytest) and mypy;
#   2. in a temp folder outside the repository holding a real frame (../shared/data, Redwood) as color.jpg and
#      depth.png, README.md's Python example (the ```python block after "Python (`pip install ./bindings`"),
#      which must write slm.png;
#   3. from that folder, pytest test_package.py against the installed package (numpy in and out, compared with
#      `holo render`: $HOLO, default the newest holo of the target dir);
#   4. with BINDINGS_DIR (output of bindings/generate.sh): the packaged uniffi module must be byte-for-byte the
#      one generate.sh wrote.
# TENSORHOLO_PROFILE=debug (as CI, and as bindings/generate.sh) builds the wheel in cargo's dev profile
# (MATURIN_PEP517_ARGS="--profile dev --features cli"), reusing the debug build `cargo test` and
# bindings/generate.sh made; default: release, as users.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
# shellcheck source=bindings/tests/lib.sh
. "$here/../lib.sh"

bindings_dir="${1:-${TENSORHOLO_BINDINGS_DIR:-}}"
shared="${TENSORHOLO_SHARED_DATA:-$REPO_ROOT/../shared/data}"
frame="$shared/redwood_livingroom_seq"
[ -f "$frame/color/00000.jpg" ] || { echo "no Redwood frame in $shared (TENSORHOLO_SHARED_DATA)" >&2; exit 1; }
export HOLO="${HOLO:-$(holo_binary)}"

case "${TENSORHOLO_PROFILE:-release}" in
  release) ;;
  # `--features cli`: the dependency graph bindings/generate.sh built (its `cli` feature only adds the generator
  # binary; the library's symbols and uniffi metadata are the same), so the wheel reuses that build instead of
  # compiling tract and the rest again for a feature set without it (about 4 min on 2 cores).
  debug) export MATURIN_PEP517_ARGS="--profile dev --features cli${MATURIN_PEP517_ARGS:+ $MATURIN_PEP517_ARGS}" ;;
  *) echo "check.sh: TENSORHOLO_PROFILE is release or debug, not $TENSORHOLO_PROFILE" >&2; exit 2 ;;
esac

command -v python3 >/dev/null 2>&1 || ensure_apt python3 || skip "python: no python3 and it cannot be installed"
tmp_dir package
venv="$tmp/venv"
if ! python3 -m venv "$venv" >/dev/null 2>&1; then
  rm -rf "$venv"
  ensure_apt python3-venv || skip "python: python3 has no venv module and python3-venv cannot be installed"
  python3 -m venv "$venv"
fi
py="$venv/bin/python"

start=$SECONDS
"$py" -m pip install --quiet --disable-pip-version-check -r "$REPO_ROOT/bindings/tests/python/requirements.txt" \
  "mypy>=1.10,<2" "$REPO_ROOT/bindings"
echo "pip install ./bindings (${MATURIN_PEP517_ARGS:-release}): $((SECONDS - start)) s"

work="$tmp/work"
mkdir -p "$work"
cp "$frame/color/00000.jpg" "$work/color.jpg"
cp "$frame/depth/00000.png" "$work/depth.png"
awk '/^Python \(`pip install \.\/bindings`/ { found = 1; next }
     found && /^```python$/ { inside = 1; next }
     inside && /^```$/ { exit }
     inside' "$REPO_ROOT/README.md" >"$work/example.py"
[ -s "$work/example.py" ] || { echo "no Python example in README.md (heading 'Python (\`pip install ./bindings\`')" >&2; exit 1; }

cd "$work"
echo "README.md's Python example, in $work:"
"$py" example.py
[ -s slm.png ] || { echo "README.md's Python example wrote no slm.png" >&2; exit 1; }
"$py" -c 'from PIL import Image; im = Image.open("slm.png"); print(f"slm.png: {im.size[0]}x{im.size[1]} {im.mode}")'

"$py" -m pytest -q -p no:cacheprovider "$here/test_package.py"

if [ -n "$bindings_dir" ]; then
  packaged="$("$py" -c 'import tensorholo._uniffi.tensorholo as m; print(m.__file__)')"
  cmp "$packaged" "$bindings_dir/python/tensorholo.py" ||
    { echo "the wheel's uniffi module differs from bindings/generate.sh's ($bindings_dir)" >&2; exit 1; }
  echo "the wheel's uniffi module is bindings/generate.sh's, byte for byte"
fi

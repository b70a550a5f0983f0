# shellcheck shell=bash
# Helpers shared by the binding checks (sourced, not run).
#
#   use_bindings [DIR]   set $dir to the directory of generated bindings to test: DIR if given, else
#                        $TENSORHOLO_BINDINGS_DIR, else a temp dir filled now by bindings/generate.sh
#   tmp_dir NAME         set $tmp to a new temp dir, removed when the script exits
#   ensure_apt PKG...    install Debian packages if missing (quiet, idempotent); return 1 if impossible
#   py_venv              set $py to the python of the checks' venv (bindings/tests/python/.venv, or
#                        $TENSORHOLO_BINDINGS_VENV), created from python/requirements.txt when missing
#   holo_binary          print the path of the holo binary to compare with ($HOLO, else target/{release,debug})
#   skip MESSAGE         print a clear SKIPPED line and exit 0 (only where a tool cannot be installed)

BINDINGS_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck disable=SC2034 # used by the check scripts
REPO_ROOT="$(cd "$BINDINGS_ROOT/.." && pwd)"

CLEANUP=()
trap 'rm -rf "${CLEANUP[@]}"' EXIT

tmp_dir() {
  tmp="$(mktemp -d "${TMPDIR:-/tmp}/tensorholo-$1.XXXXXX")"
  CLEANUP+=("$tmp")
}

use_bindings() {
  dir="${1:-${TENSORHOLO_BINDINGS_DIR:-}}"
  if [ -z "$dir" ]; then
    tmp_dir bindings
    dir="$tmp"
    "$BINDINGS_ROOT/generate.sh" "$dir"
  fi
  [ -f "$dir/python/tensorholo.py" ] || { echo "no generated bindings in $dir (run bindings/generate.sh)" >&2; return 1; }
  dir="$(cd "$dir" && pwd)"
}

ensure_apt() {
  local missing=() p
  for p in "$@"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  local sudo=()
  if [ "$(id -u)" != 0 ]; then
    if command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then sudo=(sudo -n); else
      echo "cannot install ${missing[*]}: not root and no password-less sudo" >&2
      return 1
    fi
  fi
  command -v apt-get >/dev/null 2>&1 || { echo "cannot install ${missing[*]}: no apt-get" >&2; return 1; }
  echo "installing ${missing[*]} (apt)" >&2
  local log
  log="$(mktemp)"
  # The package lists may be stale or absent: update once and retry.
  if ! "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
    "${missing[@]}" >"$log" 2>&1; then
    if ! { "${sudo[@]}" apt-get update -qq >>"$log" 2>&1 &&
      "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
        "${missing[@]}" >>"$log" 2>&1; }; then
      tail -20 "$log" >&2
      rm -f "$log"
      return 1
    fi
  fi
  rm -f "$log"
}

skip() {
  echo "SKIPPED: $*"
  exit 0
}

py_venv() {
  local venv="${TENSORHOLO_BINDINGS_VENV:-$BINDINGS_ROOT/tests/python/.venv}"
  local req="$BINDINGS_ROOT/tests/python/requirements.txt"
  command -v python3 >/dev/null 2>&1 || ensure_apt python3 || skip "python: no python3 and it cannot be installed"
  if [ ! -x "$venv/bin/python" ]; then
    if ! python3 -m venv "$venv" >/dev/null 2>&1; then
      rm -rf "$venv"
      ensure_apt python3-venv || skip "python: python3 has no venv module and python3-venv cannot be installed"
      python3 -m venv "$venv"
    fi
  fi
  # Install only when requirements.txt changed since the last install (idempotent and quiet).
  if ! cmp -s "$req" "$venv/.tensorholo-requirements.txt"; then
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$req"
    cp "$req" "$venv/.tensorholo-requirements.txt"
  fi
  py="$venv/bin/python"
}

holo_binary() {
  if [ -n "${HOLO:-}" ]; then echo "$HOLO"; return; fi
  local target="${CARGO_TARGET_DIR:-$REPO_ROOT/target}" newest=""
  case "$target" in /*) ;; *) target="$REPO_ROOT/$target" ;; esac
  for f in "$target/release/holo" "$target/debug/holo"; do
    if [ -x "$f" ] && { [ -z "$newest" ] || [ "$f" -nt "$newest" ]; }; then newest="$f"; fi
  done
  [ -n "$newest" ] || { echo "no holo binary in $target: build it (cargo build -p holo) or set HOLO" >&2; return 1; }
  echo "$newest"
}

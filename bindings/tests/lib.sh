# Helpers shared by the binding checks (sourced, not run).
#
#   bindings_dir [DIR]   echo the directory of generated bindings to test: DIR if given, else
#                        $TENSORHOLO_BINDINGS_DIR, else a fresh temp dir filled by bindings/generate.sh
#   ensure_apt PKG...    install Debian packages if missing (quiet, idempotent); return 1 if impossible
#   skip MESSAGE         print a clear SKIPPED line and exit 0 (only where a tool cannot be installed)

BINDINGS_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
REPO_ROOT="$(cd "$BINDINGS_ROOT/.." && pwd)"

bindings_dir() {
  local dir="${1:-${TENSORHOLO_BINDINGS_DIR:-}}"
  if [ -z "$dir" ]; then
    dir="$(mktemp -d "${TMPDIR:-/tmp}/tensorholo-bindings.XXXXXX")"
    "$BINDINGS_ROOT/generate.sh" "$dir" >&2
  fi
  [ -f "$dir/python/tensorholo.py" ] || { echo "no generated bindings in $dir (run bindings/generate.sh)" >&2; return 1; }
  (cd "$dir" && pwd)
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

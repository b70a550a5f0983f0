#!/usr/bin/env bash
# Usage: bindings/tests/kotlin/check.sh [BINDINGS_DIR]
#
# Compiles the generated Kotlin (JVM) with Main.kt and runs it against the built library through JNA, on the
# real frames of bindings/tests/frames.py compared with `holo render` ($HOLO, as python/check.sh).
# Tools, installed here when missing (quietly, once): kotlinc from the npm package `kotlin-compiler` pinned
# in package.json/package-lock.json (into bindings/tests/kotlin/node_modules, git-ignored; a JVM kotlinc
# despite the package's name), JNA from Debian's libjna-java, a JRE (Debian's default-jre-headless).
# BINDINGS_DIR: output of bindings/generate.sh (default $TENSORHOLO_BINDINGS_DIR, else generated now).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
# shellcheck source=bindings/tests/lib.sh
. "$here/../lib.sh"

use_bindings "${1:-}"

command -v java >/dev/null 2>&1 || ensure_apt default-jre-headless ||
  skip "kotlin bindings: no java and it cannot be installed"
jna=/usr/share/java/jna.jar
[ -f "$jna" ] || ensure_apt libjna-java || skip "kotlin bindings: $jna missing and libjna-java cannot be installed"

kotlinc="$here/node_modules/kotlin-compiler/bin/kotlinc"
wanted="$(sed -n 's/.*"kotlin-compiler": *"\([^"]*\)".*/\1/p' "$here/package.json")"
installed="$(sed -n 's/.*"version": *"\([^"]*\)".*/\1/p' "$here/node_modules/kotlin-compiler/package.json" 2>/dev/null || true)"
if [ ! -x "$kotlinc" ] || [ "$installed" != "$wanted" ]; then
  command -v npm >/dev/null 2>&1 || ensure_apt npm || skip "kotlin bindings: no npm and it cannot be installed"
  echo "installing kotlin-compiler $wanted (npm)" >&2
  (cd "$here" && npm ci --no-audit --no-fund --loglevel=error >/dev/null)
fi

tmp_dir kotlin
build="$tmp"
# -include-runtime: the Kotlin standard library goes into the jar; JNA stays on the class path.
"$kotlinc" -nowarn -include-runtime -cp "$jna" -d "$build/check.jar" \
  "$dir/kotlin/tensorholo/tensorholo.kt" "$here/Main.kt" 2>&1 | grep -v '^info: ' || true
[ -f "$build/check.jar" ] || { echo "kotlin bindings: compilation failed" >&2; exit 1; }

# The real frames and holo render's patterns of the same scenes (bindings/tests/frames.py).
py_venv
HOLO="${HOLO:-$(holo_binary)}" "$py" "$here/../frames.py" "$build/cases" >/dev/null

version="$(sed -n '/^\[workspace.package\]/,/^\[/s/^version *= *"\([^"]*\)".*/\1/p' "$REPO_ROOT/Cargo.toml")"
java -Djna.library.path="$dir/python" -cp "$build/check.jar:$jna" MainKt "$version" "$build/cases"

#!/usr/bin/env bash
# Usage: bindings/tests/kotlin/check.sh [BINDINGS_DIR]
#
# The Kotlin tests, on the JVM against the built library through JNA: the JUnit 4 tests of the Android
# module (android/tensorholo/src/test/kotlin: the bindings on the real frames of bindings/tests/frames.py
# compared with `holo render` ($HOLO, as python/check.sh), and the pure-JVM camera helpers) compiled with
# kotlinc together with the generated Kotlin and the helper files that need no android.jar (PURE_MAIN below),
# then run by RunTests.kt (JUnitCore, one line per test, counts; --strict: a skipped test fails the check).
# Gradle runs the same tests on a machine with the Android SDK (android/README.md).
# Tools, installed here when missing (quietly, once): kotlinc from the npm package `kotlin-compiler` pinned
# in package.json/package-lock.json (into bindings/tests/kotlin/node_modules, git-ignored; a JVM kotlinc
# despite the package's name), JNA from Debian's libjna-java, JUnit 4 + Hamcrest from Debian's junit4, a JRE
# (Debian's default-jre-headless).
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
junit=/usr/share/java/junit4.jar
hamcrest=/usr/share/java/hamcrest.jar
{ [ -f "$junit" ] && [ -f "$hamcrest" ]; } || ensure_apt junit4 ||
  skip "kotlin bindings: $junit missing and junit4 cannot be installed"

kotlinc="$here/node_modules/kotlin-compiler/bin/kotlinc"
wanted="$(sed -n 's/.*"kotlin-compiler": *"\([^"]*\)".*/\1/p' "$here/package.json")"
installed="$(sed -n 's/.*"version": *"\([^"]*\)".*/\1/p' "$here/node_modules/kotlin-compiler/package.json" 2>/dev/null || true)"
if [ ! -x "$kotlinc" ] || [ "$installed" != "$wanted" ]; then
  command -v npm >/dev/null 2>&1 || ensure_apt npm || skip "kotlin bindings: no npm and it cannot be installed"
  echo "installing kotlin-compiler $wanted (npm)" >&2
  (cd "$here" && npm ci --no-audit --no-fund --loglevel=error >/dev/null)
fi

module="$REPO_ROOT/android/tensorholo/src"
# The library's Kotlin that runs on a plain JVM (java.nio only); the files that need android.jar are not here.
PURE_MAIN=("$module/main/kotlin/tensorholo/android/CameraPlanes.kt")
mapfile -t tests < <(find "$module/test/kotlin" -name '*.kt' | sort)
[ ${#tests[@]} -gt 0 ] || { echo "kotlin tests: no test sources under $module/test/kotlin" >&2; exit 1; }
# Test classes: files named *Test.kt declaring `class <file name>` in their package.
classes=()
for f in "${tests[@]}"; do
  name="$(basename "$f" .kt)"
  case "$name" in *Test) ;; *) continue ;; esac
  grep -q "^class $name\b" "$f" || { echo "kotlin tests: $f does not declare class $name" >&2; exit 1; }
  package="$(sed -n 's/^package \([A-Za-z0-9_.]*\).*/\1/p' "$f" | head -1)"
  classes+=("${package:+$package.}$name")
done

tmp_dir kotlin
build="$tmp"
cp="$jna:$junit:$hamcrest"
# -include-runtime: the Kotlin standard library goes into the jar; JNA and JUnit stay on the class path.
"$kotlinc" -nowarn -include-runtime -cp "$cp" -d "$build/check.jar" \
  "$dir/kotlin/tensorholo/tensorholo.kt" "${PURE_MAIN[@]}" "${tests[@]}" "$here/RunTests.kt" 2>&1 |
  grep -v '^info: ' || true
[ -f "$build/check.jar" ] || { echo "kotlin tests: compilation failed" >&2; exit 1; }

# The real frames and holo render's patterns of the same scenes (bindings/tests/frames.py).
py_venv
HOLO="${HOLO:-$(holo_binary)}" "$py" "$here/../frames.py" "$build/cases" >/dev/null

version="$(sed -n '/^\[workspace.package\]/,/^\[/s/^version *= *"\([^"]*\)".*/\1/p' "$REPO_ROOT/Cargo.toml")"
java -Djna.library.path="$dir/python" -Dtensorholo.cases="$build/cases" -Dtensorholo.version="$version" \
  -cp "$build/check.jar:$cp" RunTestsKt --strict "${classes[@]}"

#!/usr/bin/env bash
# Usage: bindings/tests/kotlin/check.sh [BINDINGS_DIR]
#
# The Kotlin tests, on the JVM against the built library through JNA: the JUnit 4 tests of the Android
# module (android/tensorholo/src/test/kotlin: the bindings on the real frames of bindings/tests/frames.py
# compared with `holo render` ($HOLO, as python/check.sh), and the pure-JVM camera helpers) compiled with
# kotlinc together with the generated Kotlin and the helper files that need no android.jar (PURE_MAIN below),
# then run by RunTests.kt (JUnitCore, one line per test, counts; --strict: a skipped test fails the check).
# Gradle runs the same tests on a machine with the Android SDK (android/README.md).
# In the same kotlinc run, compiled and never run: the ```kotlin examples of README.md and android/README.md
# (readme_examples.py: one file per README, each block in a function of its own, after the README's "given"
# declarations in readme/*.given.kt; a Gradle build-script block is skipped, and named), and the Android-only
# helpers (ANDROID_MAIN) against stand-ins of the few android.* / ARCore classes they and the examples use
# (readme/android-stand-ins/: names and types only; the Android APIs themselves are not checked). kotlinc's errors
# in an example are reported at the README's line. Self-test: one wrong name injected into a copy of each
# README's example must fail to compile there (kotlinc on the copies against the jar just built).
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
# The library's Kotlin that needs android.jar / ARCore: compiled against the stand-ins, for the README example.
ANDROID_MAIN=("$module/main/kotlin/tensorholo/android/ImageFrames.kt"
  "$module/main/kotlin/tensorholo/android/ArCoreFrames.kt" "$module/main/kotlin/tensorholo/android/SlmBitmaps.kt")
mapfile -t stand_ins < <(find "$here/readme/android-stand-ins" -name '*.kt' | sort)
# README:given pairs, relative to the repository root (each README's file has a package named after its path).
READMES=("README.md:bindings/tests/kotlin/readme/README.given.kt"
  "android/README.md:bindings/tests/kotlin/readme/android-README.given.kt")
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
echo "README examples (compiled with the bindings and the tests, not run):"
(cd "$REPO_ROOT" && python3 "$here/readme_examples.py" extract "$build/readme" "${READMES[@]}")
# -include-runtime: the Kotlin standard library goes into the jar; JNA and JUnit stay on the class path.
"$kotlinc" -nowarn -include-runtime -cp "$cp" -d "$build/check.jar" \
  "$dir/kotlin/tensorholo/tensorholo.kt" "${PURE_MAIN[@]}" "${tests[@]}" "$here/RunTests.kt" \
  "${ANDROID_MAIN[@]}" "${stand_ins[@]}" "$build"/readme/*.kt 2>&1 |
  grep -v '^info: ' | python3 "$here/readme_examples.py" map "$build/readme" || true
[ -f "$build/check.jar" ] ||
  { echo "kotlin tests: compilation failed (the bindings, the tests, the helpers or a README example)" >&2; exit 1; }

# Self-test: each line is README|TEXT|REPLACEMENT|the name kotlinc must report unresolved, at that README's line
# (TEXT must occur in the README: update the line when the example changes).
injections=(
  "README.md|packRgba(gen.render(frame))|packRgba(gen.rendr(frame))|rendr"
  "android/README.md|displayRotationDegrees, frontFacing = false)|displayRotationDegrees, frontFacng = false)|frontFacng"
)
self_test_start=$(date +%s)
broken=()
expect=()
for i in "${!injections[@]}"; do
  IFS='|' read -r file text replacement name <<<"${injections[i]}"
  copy="broken$i/$file"
  mkdir -p "$build/self-test/$(dirname "$copy")"
  python3 -c '
import sys
src, dst, text, replacement = sys.argv[1:]
source = open(src, encoding="utf-8").read()
if text not in source:
    sys.exit(f"kotlin check self-test: {text!r} is not in {src}: update the injection list")
open(dst, "w", encoding="utf-8").write(source.replace(text, replacement, 1))
' "$REPO_ROOT/$file" "$build/self-test/$copy" "$text" "$replacement"
  given=""
  for pair in "${READMES[@]}"; do [ "${pair%%:*}" = "$file" ] && given="${pair#*:}"; done
  broken+=("$copy:$REPO_ROOT/$given")
  line="$(grep -nF -- "$replacement" "$build/self-test/$copy" | head -1 | cut -d: -f1)"
  expect+=("$copy:$line:|'$name'")
done
if out="$(cd "$build/self-test" && python3 "$here/readme_examples.py" extract out "${broken[@]}" >/dev/null &&
  "$kotlinc" -nowarn -cp "$build/check.jar:$cp" -d out.jar out/*.kt 2>&1 |
  python3 "$here/readme_examples.py" map out && [ -f out.jar ])"; then
  echo "kotlin check self-test: README examples with a wrong name compiled; they must not" >&2
  exit 1
fi
for e in "${expect[@]}"; do
  # kotlinc prints `FILE:LINE:COLUMN: error: unresolved reference 'NAME'.`, FILE:LINE mapped to the README copy.
  if ! grep -F -- "${e%%|*}" <<<"$out" | grep -qF -- "${e#*|}"; then
    echo "kotlin check self-test: no error naming ${e#*|} at ${e%%|*} of the broken README copy:" >&2
    echo "$out" >&2
    exit 1
  fi
done
echo "  self-test: ${#injections[@]}/${#injections[@]} README examples with a wrong name fail to compile at the README's line ($(($(date +%s) - self_test_start)) s)"

# The real frames and holo render's patterns of the same scenes (bindings/tests/frames.py).
py_venv
HOLO="${HOLO:-$(holo_binary)}" "$py" "$here/../frames.py" "$build/cases" >/dev/null

version="$(sed -n '/^\[workspace.package\]/,/^\[/s/^version *= *"\([^"]*\)".*/\1/p' "$REPO_ROOT/Cargo.toml")"
java -Djna.library.path="$dir/python" -Dtensorholo.cases="$build/cases" -Dtensorholo.version="$version" \
  -cp "$build/check.jar:$cp" RunTestsKt --strict "${classes[@]}"

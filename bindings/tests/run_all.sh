#!/usr/bin/env bash
# Usage: bindings/tests/run_all.sh
#
# Every check of the app bindings, in order, one line per step with its duration:
# generate (release build + uniffi-bindgen, into a temp dir), check-generated (committed Kotlin/Swift up to
# date), python (pytest), package (pip install ./bindings in a fresh venv, then pytest from outside the repo),
# kotlin (the JUnit tests of android/ on the JVM + JNA), swift (header, symbols, checksums). Stops at the first
# failure.
# Tools each step needs are installed by the step itself when missing (see each check.sh).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
bindings="$(cd "$here/.." && pwd)"

out="$(mktemp -d "${TMPDIR:-/tmp}/tensorholo-bindings.XXXXXX")"
trap 'rm -rf "$out" "$out.log"' EXIT
export TENSORHOLO_BINDINGS_DIR="$out"

summary=()
step() {
  local name="$1"
  shift
  echo "== bindings: $name"
  local start=$SECONDS status=0 result=ok line
  "$@" 2>&1 | tee "$out.log" || status=${PIPESTATUS[0]}
  if [ "$status" != 0 ]; then
    result="FAILED (exit $status)"
  elif grep -q '^SKIPPED' "$out.log"; then
    result="SKIPPED (see above)"
  fi
  line="$(printf '%-16s %4ds  %s' "$name" $((SECONDS - start)) "$result")"
  summary+=("$line")
  echo "-- bindings: $line"
  if [ "$status" != 0 ]; then
    printf '%s\n' "== bindings summary" "${summary[@]}"
    exit "$status"
  fi
}

step generate "$bindings/generate.sh" "$out"
step check-generated "$bindings/check-generated.sh" "$out"
step python "$here/python/check.sh" "$out"
step package "$here/package/check.sh" "$out"
step kotlin "$here/kotlin/check.sh" "$out"
step swift "$here/swift/check.sh" "$out"
printf '%s\n' "== bindings summary" "${summary[@]}"

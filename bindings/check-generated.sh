#!/usr/bin/env bash
# Usage: bindings/check-generated.sh [--update] [BINDINGS_DIR]
#
# The Kotlin and Swift bindings are committed (bindings/generated/) so that app projects can take them
# without building Rust. This check regenerates them (bindings/generate.sh, into a temp dir unless
# BINDINGS_DIR already holds its output) and fails, showing the diff, if the committed copies differ.
# --update: overwrite the committed copies with the regenerated ones instead (then review and commit).
set -euo pipefail
root="$(cd "$(dirname "$0")" && pwd)"
update=0
if [ "${1:-}" = --update ]; then update=1; shift; fi
dir="${1:-}"
if [ -z "$dir" ]; then
  dir="$(mktemp -d "${TMPDIR:-/tmp}/tensorholo-bindings.XXXXXX")"
  trap 'rm -rf "$dir"' EXIT
  "$root/generate.sh" "$dir" >/dev/null
fi
committed="$root/generated"

if [ "$update" = 1 ]; then
  for lang in kotlin swift; do
    rm -rf "${committed:?}/$lang"
    mkdir -p "$committed"
    cp -r "$dir/$lang" "$committed/$lang"
  done
  echo "updated $committed/{kotlin,swift} from $dir"
  exit 0
fi

status=0
diffs="$(mktemp)"
for lang in kotlin swift; do
  if ! diff -ru "$committed/$lang" "$dir/$lang" >"$diffs" 2>&1; then
    status=1
    echo "bindings/generated/$lang is stale: it differs from what bindings/generate.sh writes now" >&2
    head -200 "$diffs" >&2
    [ "$(wc -l <"$diffs")" -le 200 ] || echo "... ($(wc -l <"$diffs") diff lines in all)" >&2
  fi
done
rm -f "$diffs"
if [ "$status" != 0 ]; then
  echo "run bindings/check-generated.sh --update, review the diff and commit it" >&2
  exit 1
fi
echo "bindings/generated/{kotlin,swift} are up to date"

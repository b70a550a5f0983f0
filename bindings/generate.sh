#!/usr/bin/env bash
# Usage: bindings/generate.sh OUT_DIR
#
# Builds the host library (release) and the crate's own uniffi-bindgen, then writes the bindings in library
# mode (read from the built library's metadata):
#   OUT_DIR/python/  tensorholo.py + the library beside it (PYTHONPATH=OUT_DIR/python python3 -c 'import tensorholo')
#   OUT_DIR/kotlin/  tensorholo/tensorholo.kt (package tensorholo; needs JNA at run time)
#   OUT_DIR/swift/   Tensorholo.swift, TensorholoFFI.h, TensorholoFFI.modulemap
# Honours CARGO_TARGET_DIR, and TENSORHOLO_PROFILE=debug (default release) to reuse a debug build, as CI
# does after `cargo test` (the bindings are the same; only the library's speed differs). Output is not formatted (--no-format), so it is byte-for-byte reproducible
# whatever formatters are installed (bindings/check-generated.sh compares it with bindings/generated/).
set -euo pipefail

if [ $# -ne 1 ] || [ -z "$1" ]; then
  echo "usage: $0 OUT_DIR" >&2
  exit 2
fi
out="$1"
root="$(cd "$(dirname "$0")/.." && pwd)"
cd "$root"

target="${CARGO_TARGET_DIR:-$root/target}"
case "$target" in /*) ;; *) target="$root/$target" ;; esac

case "$(uname -s)" in
  Darwin) lib_file=libtensorholo_ffi.dylib ;;
  *) lib_file=libtensorholo_ffi.so ;;
esac

# One build for both: the `cli` feature only adds the generator binary; the library's exported symbols and
# uniffi metadata are the same as without it.
profile="${TENSORHOLO_PROFILE:-release}"
case "$profile" in
  release) cargo build --release --locked --quiet -p tensorholo-ffi --features cli --lib --bin uniffi-bindgen ;;
  debug) cargo build --locked --quiet -p tensorholo-ffi --features cli --lib --bin uniffi-bindgen ;;
  *) echo "generate.sh: TENSORHOLO_PROFILE is release or debug, not $profile" >&2; exit 2 ;;
esac

lib="$target/$profile/$lib_file"
bindgen="$target/$profile/uniffi-bindgen"
for f in "$lib" "$bindgen"; do
  [ -f "$f" ] || { echo "generate.sh: $f was not built" >&2; exit 1; }
done

mkdir -p "$out"
for lang in python kotlin swift; do
  rm -rf "${out:?}/$lang"
  # --metadata-no-deps: every exported type lives in this crate; cargo metadata then needs no dependency graph.
  "$bindgen" generate --library "$lib" --language "$lang" --out-dir "$out/$lang" \
    --no-format --metadata-no-deps >/dev/null
done
cp "$lib" "$out/python/"

# What the callers rely on (fail here rather than in a later, more confusing step).
for f in python/tensorholo.py "python/$lib_file" kotlin/tensorholo/tensorholo.kt \
  swift/Tensorholo.swift swift/TensorholoFFI.h swift/TensorholoFFI.modulemap; do
  [ -f "$out/$f" ] || { echo "generate.sh: expected $out/$f, not generated (uniffi.toml?)" >&2; exit 1; }
done
echo "bindings written to $out (library: $lib)"

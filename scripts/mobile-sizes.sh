#!/usr/bin/env bash
# Usage: scripts/mobile-sizes.sh [TARGET…]
#
# Builds the app library (tensorholo-ffi) with the `mobile` profile (LTO, one codegen unit, stripped) and
# prints the sizes of README "Size on a phone" as a Markdown table:
#  - aarch64-unknown-linux-gnu: the linked shared library (libtensorholo_ffi.so, the closest thing to what an
#    Android or iOS app links that can be linked here) with the default models (8 layers + pre-filters), with
#    no models, with all models, and with the core's `research` feature; and its static library;
#  - the other TARGETs (default: aarch64-apple-ios aarch64-linux-android): the static library only (no Xcode
#    or NDK linker here; scripts/mobile-cc.sh has the compile-only C settings).
# Slow: every target is a full release build of tract with LTO (about 10-20 min each on two cores).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
# shellcheck source=bindings/tests/lib.sh
. "$root/bindings/tests/lib.sh"
# shellcheck source=scripts/mobile-cc.sh
. "$root/scripts/mobile-cc.sh"
cd "$root"
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(aarch64-apple-ios aarch64-linux-android)
target_dir="${CARGO_TARGET_DIR:-target}"
mb() { python3 -c "import os,sys; print(f'{os.path.getsize(sys.argv[1]) / 1e6:.1f} MB')" "$1"; }

echo "| target | what | features | size |"
echo "|---|---|---|---:|"
linux=aarch64-unknown-linux-gnu
rustup target list --installed | grep -qx "$linux" || rustup target add "$linux" >&2
for variant in "default:" "no models:--no-default-features" "all models:--features models-15,models-30" \
  "default + research:--features tensorholo/research"; do
  name="${variant%%:*}"
  flags="${variant#*:}"
  # shellcheck disable=SC2086 # flags are words
  cargo build --locked -q -p tensorholo-ffi --lib --profile mobile --target "$linux" $flags >&2
  out="$target_dir/$linux/mobile"
  echo "| $linux | \`libtensorholo_ffi.so\` (linked) | $name | $(mb "$out/libtensorholo_ffi.so") |"
done
# Static libraries alone (`cargo rustc --crate-type staticlib`): built beside the rlib and cdylib, rustc keeps
# one object per crate without cross-crate LTO (202 MB here); alone, the crate graph is one LTO'd object.
staticlib() {
  cargo rustc --locked -q -p tensorholo-ffi --lib --crate-type staticlib --profile mobile --target "$1" >&2
  echo "| $1 | \`libtensorholo_ffi.a\` | default | $(mb "$target_dir/$1/mobile/libtensorholo_ffi.a") |"
}
staticlib "$linux"
mobile_cc_env "${targets[@]}"
for t in "${targets[@]}"; do staticlib "$t"; done

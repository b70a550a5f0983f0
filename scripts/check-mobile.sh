#!/usr/bin/env bash
# Usage: scripts/check-mobile.sh [target…]
#
# `cargo check` of the app library (tensorholo-ffi: the core, tract, the bindings) for the phone targets, with
# its default features (tract included: what ios/build-xcframework.sh and android/build-aar.sh build) for the
# ABIs the phone packages ship, aarch64-apple-ios, aarch64-linux-android and x86_64-linux-android; and without
# tract (the small app library) for aarch64-apple-ios, aarch64-linux-android and armv7-linux-androideabi, the
# 32-bit ABI no package ships but an app may build (pointer width 32). Each target's dependencies are checked
# once per feature set: the pairs are what differs (tract on the shipped ABIs; without it, the cfg of the
# features and 32 bits), not every product of the two (docs: CONTRIBUTING.md "How long each step takes").
# Given targets (`scripts/check-mobile.sh TARGET…`), both feature sets are checked for each.
# It proves the Rust compiles for them; it builds no library (no Xcode or NDK here: ios/build-xcframework.sh
# and android/build-aar.sh do that on a Mac / with Android Studio).
# The C settings that make this possible without an SDK or NDK are in scripts/mobile-cc.sh.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
# shellcheck source=bindings/tests/lib.sh
. "$root/bindings/tests/lib.sh"
# shellcheck source=scripts/mobile-cc.sh
. "$root/scripts/mobile-cc.sh"
cd "$root"

with_tract=("$@")
without_tract=("$@")
if [ $# -eq 0 ]; then
  with_tract=(aarch64-apple-ios aarch64-linux-android x86_64-linux-android)
  without_tract=(aarch64-apple-ios aarch64-linux-android armv7-linux-androideabi)
fi
mapfile -t targets < <(printf '%s\n' "${with_tract[@]}" "${without_tract[@]}" | sort -u)
mobile_cc_env "${targets[@]}"
target_args() { for t in "$@"; do printf -- '--target\n%s\n' "$t"; done; }
mapfile -t args < <(target_args "${with_tract[@]}")
cargo check --locked -p tensorholo-ffi "${args[@]}"
# The small app library: no tract (docs/GUIDE.md "Size on a phone"), the native engine and the GPU only.
mapfile -t args < <(target_args "${without_tract[@]}")
cargo check --locked -p tensorholo-ffi --no-default-features --features embedded-models,gpu "${args[@]}"
echo "check-mobile: tensorholo-ffi checks with tract for ${with_tract[*]}; without tract for ${without_tract[*]}"

#!/usr/bin/env bash
# Usage: scripts/check-mobile.sh [target…]
#
# `cargo check` of the app library (tensorholo-ffi: the core, tract, the bindings; and again without tract) for
# the phone targets:
# aarch64-apple-ios, aarch64-linux-android, x86_64-linux-android, armv7-linux-androideabi (default: all four).
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

targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(aarch64-apple-ios aarch64-linux-android x86_64-linux-android armv7-linux-androideabi)
mobile_cc_env "${targets[@]}"
args=()
for t in "${targets[@]}"; do args+=(--target "$t"); done
cargo check --locked -p tensorholo-ffi "${args[@]}"
# The small app library: no tract (docs/GUIDE.md "Size on a phone"), the native engine and the GPU only.
cargo check --locked -p tensorholo-ffi --no-default-features --features embedded-models,gpu "${args[@]}"
echo "check-mobile: tensorholo-ffi checks for ${targets[*]}, with and without tract"

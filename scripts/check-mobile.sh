#!/usr/bin/env bash
# Usage: scripts/check-mobile.sh [target…]
#
# `cargo check` of the app library (tensorholo-ffi: the core, tract, the bindings) for the phone targets:
# aarch64-apple-ios, aarch64-linux-android, x86_64-linux-android, armv7-linux-androideabi (default: all four).
# It proves the Rust compiles for them; it builds no library (no Xcode or NDK here: ios/build-xcframework.sh
# and android/build-aar.sh do that on a Mac / with Android Studio).
#
# tract-linalg's build script assembles its ARM/x86 kernels with the target's C compiler even for a check.
# Without an SDK or NDK, LLVM's clang assembles them for any of these targets (the kernels include no system
# header): CC_<target>=clang, and for iOS an empty SDKROOT so that cc-rs does not call xcrun; armv7 gets the
# NEON/VFP flags of Android's armeabi-v7a ABI. These settings are for this check only; real builds use the
# NDK's and Xcode's compilers.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
# shellcheck source=bindings/tests/lib.sh
. "$root/bindings/tests/lib.sh"
cd "$root"

targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(aarch64-apple-ios aarch64-linux-android x86_64-linux-android armv7-linux-androideabi)
command -v clang >/dev/null 2>&1 || ensure_apt clang || { echo "check-mobile: needs clang" >&2; exit 1; }
command -v llvm-ar >/dev/null 2>&1 || ensure_apt llvm || { echo "check-mobile: needs llvm-ar" >&2; exit 1; }
installed="$(rustup target list --installed)"
tmp_dir nosdk
args=()
for t in "${targets[@]}"; do
  grep -qx "$t" <<<"$installed" || rustup target add "$t"
  var="${t//-/_}"
  export "CC_$var=clang" "AR_$var=llvm-ar"
  args+=(--target "$t")
done
export SDKROOT="$tmp" CFLAGS_armv7_linux_androideabi="-march=armv7-a -mfpu=neon -mfloat-abi=softfp"
cargo check --locked -p tensorholo-ffi "${args[@]}"
echo "check-mobile: tensorholo-ffi checks for ${targets[*]}"

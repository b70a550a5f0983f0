#!/usr/bin/env bash
# Usage: scripts/check-mobile.sh [target…]
#
# `cargo check` of the app library (tensorholo-ffi: the core, tract, the bindings) for the phone targets, with
# its default features (tract included: what ios/build-xcframework.sh and android/build-aar.sh build) for the
# two arm64 ABIs the phone packages ship, aarch64-apple-ios and aarch64-linux-android; and without tract (the
# small app library) for armv7-linux-androideabi, the 32-bit ABI no package ships but an app may build
# (pointer width 32, Android's cfg without tract). Each check covers what differs and nothing twice:
# - with tract, each OS of the arm64 packages (iOS and Android: their cfg, tract's aarch64 code);
# - the third packaged ABI, x86_64-linux-android, is the test build's x86-64 code (tract's x86-64 kernels)
#   under Android's cfg, which the two Android checks cover: it is left out (about a third of the with-tract
#   check's 247 s on a fresh machine, estimated from its share of the targets);
# - without tract, the `cfg(not(feature = "tract"))` code, also checked on x86-64 by CI's clippy of the
#   application build and run on aarch64 by scripts/test-aarch64.sh: once here, on 32 bits.
# Measured on a fresh target directory (Intel Xeon VM, 2 vCPUs): the six checks this replaced took 307 s.
# docs: CONTRIBUTING.md "How long each step takes".
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
  with_tract=(aarch64-apple-ios aarch64-linux-android)
  without_tract=(armv7-linux-androideabi)
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

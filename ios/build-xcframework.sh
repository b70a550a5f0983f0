#!/usr/bin/env bash
# Usage: ios/build-xcframework.sh            (on a Mac with Xcode, rustup and cargo)
#
# Builds the Rust library `tensorholo-ffi` (bindings/) as a static library for iOS and packs it for the Swift
# package in this directory:
#   ios/TensorholoFFI.xcframework/             ios-arm64 (device) and ios-arm64_x86_64-simulator slices, each with
#                                              libtensorholo_ffi.a and Headers/{TensorholoFFI.h, module.modulemap}
#   ios/Sources/Tensorholo/Generated/Tensorholo.swift   a copy of bindings/generated/swift/Tensorholo.swift
# Both are git-ignored: bindings/generated/swift/ holds the one committed copy of the generated code, and
# bindings/check-generated.sh keeps it equal to what the library exports (run that after changing the Rust API).
#
# Environment:
#   TENSORHOLO_PROFILE   cargo profile: mobile (default; the workspace's [profile.mobile]: release + LTO,
#                        one codegen unit, stripped, tract optimised for size), mobile-fast-tract (the same with
#                        tract at full speed: for apps whose own ONNX files only tract runs), release, or dev
#                        (fast to build, slow to run)
#   TENSORHOLO_FEATURES  extra cargo features of tensorholo-ffi, space-separated, e.g. "models-15 models-30";
#                        the names are the [features] of bindings/Cargo.toml
#   TENSORHOLO_MACOS=1   also build a macOS slice (aarch64 + x86_64), so that `swift build` / `swift test` run on
#                        the Mac itself
#   TENSORHOLO_MODULEMAP_KEEP_BUILTIN_USE=1   keep uniffi's `use "_Builtin_stdbool"` / `use "_Builtin_stdint"`
#                        lines in module.modulemap (dropped by default: Xcode 26 and later cannot resolve those
#                        module names and then cannot import TensorholoFFI, see uniffi-rs issue 2917; the lines only
#                        declare module uses and Xcode 15/16 build the module without them)
#   CARGO_TARGET_DIR     honoured (default: target/ at the workspace root)
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/.." && pwd)"

die() { echo "build-xcframework: $*" >&2; exit 1; }
step() { echo "== $*"; }

if [ "$(uname -s)" != Darwin ]; then
  die "this script builds an XCFramework and needs a Mac with Xcode (xcodebuild, lipo, the iOS SDKs); this is $(uname -s). On Linux, ios/check.sh checks the Swift sources without a compiler."
fi
for tool in xcodebuild lipo cargo rustup; do
  command -v "$tool" >/dev/null 2>&1 || die "$tool not found: install Xcode (xcode-select --install is not enough: the iOS SDKs come with Xcode.app) and rustup (https://rustup.rs)"
done
xcodebuild -version >/dev/null 2>&1 || die "xcodebuild does not run: select Xcode.app with 'sudo xcode-select -s /Applications/Xcode.app'"

profile="${TENSORHOLO_PROFILE:-mobile}"
case "$profile" in
  dev | debug) profile=dev; profile_dir=debug ;;
  *) profile_dir="$profile" ;;
esac
target_dir="${CARGO_TARGET_DIR:-$root/target}"
case "$target_dir" in /*) ;; *) target_dir="$root/$target_dir" ;; esac

features=()
if [ -n "${TENSORHOLO_FEATURES:-}" ]; then
  features=(--features "$TENSORHOLO_FEATURES")
fi

device=aarch64-apple-ios
simulators=(aarch64-apple-ios-sim x86_64-apple-ios)
macs=()
if [ "${TENSORHOLO_MACOS:-0}" = 1 ]; then
  macs=(aarch64-apple-darwin x86_64-apple-darwin)
fi
# ${a[@]+"${a[@]}"}: an empty array under set -u in macOS's bash 3.2.
targets=("$device" "${simulators[@]}" ${macs[@]+"${macs[@]}"})

# Match the package's deployment targets (Package.swift), so that the linker sees no newer-OS objects.
export IPHONEOS_DEPLOYMENT_TARGET="${IPHONEOS_DEPLOYMENT_TARGET:-15.0}"
export MACOSX_DEPLOYMENT_TARGET="${MACOSX_DEPLOYMENT_TARGET:-12.0}"

generated="$root/bindings/generated/swift"
for f in Tensorholo.swift TensorholoFFI.h TensorholoFFI.modulemap; do
  [ -f "$generated/$f" ] || die "$generated/$f is missing (bindings/generate.sh writes it)"
done

step "rustup targets: ${targets[*]}"
rustup target add "${targets[@]}"

cd "$root"
for t in "${targets[@]}"; do
  step "cargo rustc -p tensorholo-ffi --lib --crate-type staticlib --profile $profile --target $t ${TENSORHOLO_FEATURES:+(features: $TENSORHOLO_FEATURES)}"
  # Only the static library: built beside the crate's other types (rlib, cdylib), rustc leaves it one object
  # per crate without cross-crate LTO (measured 202 MB on aarch64 Linux); alone, it is one LTO'd object.
  cargo rustc --locked -p tensorholo-ffi --lib --crate-type staticlib --profile "$profile" --target "$t" \
    ${features[@]+"${features[@]}"}
  [ -f "$target_dir/$t/$profile_dir/libtensorholo_ffi.a" ] || die "$target_dir/$t/$profile_dir/libtensorholo_ffi.a was not built"
done
lib() { echo "$target_dir/$1/$profile_dir/libtensorholo_ffi.a"; }

build="$here/build"
rm -rf "$build"
mkdir -p "$build/headers" "$build/ios-simulator"

step "headers: TensorholoFFI.h + module.modulemap (module TensorholoFFI)"
cp "$generated/TensorholoFFI.h" "$build/headers/TensorholoFFI.h"
# An XCFramework's Headers directory is searched for a file named exactly module.modulemap.
if [ "${TENSORHOLO_MODULEMAP_KEEP_BUILTIN_USE:-0}" = 1 ]; then
  cp "$generated/TensorholoFFI.modulemap" "$build/headers/module.modulemap"
else
  grep -v -E '^[[:space:]]*use "_Builtin_[A-Za-z0-9_]+"[[:space:]]*$' "$generated/TensorholoFFI.modulemap" \
    >"$build/headers/module.modulemap"
fi
grep -q '^module TensorholoFFI ' "$build/headers/module.modulemap" || die "the module map does not declare module TensorholoFFI"

step "lipo: one simulator library for arm64 + x86_64"
lipo -create "$(lib aarch64-apple-ios-sim)" "$(lib x86_64-apple-ios)" -output "$build/ios-simulator/libtensorholo_ffi.a"
xcargs=(-library "$(lib "$device")" -headers "$build/headers"
  -library "$build/ios-simulator/libtensorholo_ffi.a" -headers "$build/headers")
if [ "${#macs[@]}" -gt 0 ]; then
  mkdir -p "$build/macos"
  lipo -create "$(lib aarch64-apple-darwin)" "$(lib x86_64-apple-darwin)" -output "$build/macos/libtensorholo_ffi.a"
  xcargs+=(-library "$build/macos/libtensorholo_ffi.a" -headers "$build/headers")
fi

out="$here/TensorholoFFI.xcframework"
step "xcodebuild -create-xcframework -> $out"
rm -rf "$out"
xcodebuild -create-xcframework "${xcargs[@]}" -output "$out"

step "generated Swift -> Sources/Tensorholo/Generated/Tensorholo.swift"
mkdir -p "$here/Sources/Tensorholo/Generated"
cp "$generated/Tensorholo.swift" "$here/Sources/Tensorholo/Generated/Tensorholo.swift"

echo
echo "built $out (profile $profile${TENSORHOLO_FEATURES:+, features: $TENSORHOLO_FEATURES}):"
find "$out" -name 'libtensorholo_ffi.a' -print0 | while IFS= read -r -d '' f; do
  printf '  %8s  %s  (%s)\n' "$(du -h "$f" | cut -f1)" "${f#"$here"/}" "$(lipo -archs "$f")"
done
echo "  total $(du -sh "$out" | cut -f1)"
echo "next: add the package with .package(path: \"$here\") or open $here/Package.swift in Xcode"

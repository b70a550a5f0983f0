#!/usr/bin/env bash
# Usage: android/build-aar.sh
#
# Builds the Android library (.aar) on a machine with the Android SDK and NDK:
#  1. libtensorholo_ffi.so for arm64-v8a (phones) and x86_64 (emulators) with cargo-ndk, into
#     android/tensorholo/src/main/jniLibs/<abi>/ (git-ignored), linked for 16 KB pages (Android 15+) with
#     packed relocations;
#  2. gradle :tensorholo:assembleRelease (./gradlew when a wrapper was made, else gradle on PATH);
#  3. prints the .aar's path and size.
#
# Needs: rustup, cargo-ndk (cargo install cargo-ndk), ANDROID_NDK_HOME (NDK r27 or newer), the Android SDK
# (ANDROID_HOME, or sdk.dir in android/local.properties), Gradle ≥ 8.13 (or a wrapper: `gradle wrapper` once
# in android/), JDK 17+.
# Environment: TENSORHOLO_PROFILE (cargo profile, default `mobile`: LTO, 1 codegen unit, stripped, tract
# optimised for size; `mobile-fast-tract`: the same with tract at full speed, for apps whose own ONNX files only
# tract runs; `release` works too), TENSORHOLO_FEATURES (extra cargo features of tensorholo-ffi,
# comma-separated), CARGO_TARGET_DIR.
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/.." && pwd)"
profile="${TENSORHOLO_PROFILE:-mobile}"
features="${TENSORHOLO_FEATURES:-}"
# ABI (Android name) → Rust target.
abis=(arm64-v8a x86_64)
triples=(aarch64-linux-android x86_64-linux-android)
jni="$here/tensorholo/src/main/jniLibs"

die() {
  echo "build-aar.sh: $*" >&2
  exit 1
}

# -- The JNA the .aar is built against (tensorholo/build.gradle.kts): 16 KB-aligned libjnidispatch.so from
# 5.17.0, and 5.18.1 fixes a deadlock (#1681) and a race (#1686) seen with multi-threaded uniffi callbacks.
jna="$(sed -n 's/^val jnaVersion = "\([0-9.]*\)".*/\1/p' "$here/tensorholo/build.gradle.kts")"
[ -n "$jna" ] || die "no 'val jnaVersion = \"…\"' in tensorholo/build.gradle.kts"
[ "$(printf '%s\n' 5.18.1 "$jna" | sort -V | head -1)" = 5.18.1 ] ||
  die "JNA $jna in tensorholo/build.gradle.kts is older than 5.18.1 (deadlock #1681, race #1686; 16 KB pages need >= 5.17.0)"

# -- Tools first: fail before any build.
command -v rustup >/dev/null 2>&1 || die "rustup not found (https://rustup.rs)"
cargo ndk --version >/dev/null 2>&1 || die "cargo-ndk not found: cargo install cargo-ndk"
[ -n "${ANDROID_NDK_HOME:-}" ] || die "ANDROID_NDK_HOME is not set (the NDK directory, e.g. \$ANDROID_HOME/ndk/27.2.12479018)"
[ -d "$ANDROID_NDK_HOME/toolchains/llvm/prebuilt" ] || die "ANDROID_NDK_HOME=$ANDROID_NDK_HOME is not an NDK (no toolchains/llvm/prebuilt)"
if [ -x "$here/gradlew" ]; then
  gradle=("$here/gradlew")
elif command -v gradle >/dev/null 2>&1; then
  gradle=(gradle)
else
  die "no gradle: install Gradle 8.13+ (or open android/ in Android Studio, or run 'gradle wrapper' once in android/)"
fi
if [ -z "${ANDROID_HOME:-${ANDROID_SDK_ROOT:-}}" ] && ! grep -qs '^sdk.dir=' "$here/local.properties"; then
  die "no Android SDK: set ANDROID_HOME or write sdk.dir=<path> in android/local.properties"
fi
if [ "$profile" != release ] && [ "$profile" != dev ] &&
  ! grep -q "^\[profile\.$profile\]" "$root/Cargo.toml"; then
  die "no [profile.$profile] in Cargo.toml: set TENSORHOLO_PROFILE=release"
fi

# -- 1. The native library per ABI.
rustup target add "${triples[@]}"
# 16 KB pages: NDK r28+ links so by default; r27 needs the flag (harmless where it is the default).
# Packed relative relocations (Android's APS2 format, read by Android 6+; the .aar's minSdk is 26): recent
# NDKs' clang packs them by default only from API 28 (RELR), older ones not at all, and unpacked they take 24
# bytes each, ~1 MB of the library with tract (docs/GUIDE.md "Size on a phone"; scripts/mobile-sizes.sh links the
# same way).
link_flags="-C link-arg=-Wl,-z,max-page-size=16384 -C link-arg=-Wl,--pack-dyn-relocs=android"
export CARGO_TARGET_AARCH64_LINUX_ANDROID_RUSTFLAGS="$link_flags"
export CARGO_TARGET_X86_64_LINUX_ANDROID_RUSTFLAGS="$link_flags"
# The shared library alone (`cargo rustc --crate-type cdylib`): `cargo build` would compile the crate's three
# types (lib, cdylib, staticlib) in one rustc run, whose LTO keeps every public Rust item of the rlib, 3 MB
# more with tract (docs/GUIDE.md "Size on a phone").
cargo_args=(rustc --locked -p tensorholo-ffi --lib --crate-type cdylib --profile "$profile")
[ -n "$features" ] && cargo_args+=(--features "$features")
ndk_targets=()
for abi in "${abis[@]}"; do ndk_targets+=(-t "$abi"); done
stamp="$(mktemp)"
trap 'rm -f "$stamp"' EXIT
(cd "$root" && cargo ndk "${ndk_targets[@]}" --platform 26 -o "$jni" "${cargo_args[@]}")

# cargo-ndk copies the library into jniLibs/<abi>/; check it did (and that it is this build's), else copy.
target_dir="${CARGO_TARGET_DIR:-$root/target}"
case "$target_dir" in /*) ;; *) target_dir="$root/$target_dir" ;; esac
out_profile="$profile"
[ "$profile" = dev ] && out_profile=debug
readelf="$(find "$ANDROID_NDK_HOME/toolchains/llvm/prebuilt" -maxdepth 3 -name llvm-readelf -type f | head -1)"
for i in "${!abis[@]}"; do
  lib="$jni/${abis[$i]}/libtensorholo_ffi.so"
  built="$target_dir/${triples[$i]}/$out_profile/libtensorholo_ffi.so"
  if [ ! -f "$lib" ] || [ -z "$(find "$lib" -newer "$stamp")" ]; then
    [ -f "$built" ] || die "no $built after cargo ndk"
    mkdir -p "$(dirname "$lib")"
    cp "$built" "$lib"
  fi
  if [ -n "$readelf" ]; then
    # Every LOAD segment aligned to 16 KB (0x4000) or more.
    aligns="$("$readelf" -lW "$lib" | awk '$1 == "LOAD" { print $NF }')"
    [ -n "$aligns" ] || die "llvm-readelf shows no LOAD segment in $lib"
    for a in $aligns; do
      [ $((a)) -ge 16384 ] || die "$lib has a LOAD segment aligned to $a, below 16 KB (use NDK r27+ and keep $link_flags)"
    done
    # Packed relative relocations: the dynamic section names Android's packed table (DT_ANDROID_RELA).
    "$readelf" -dW "$lib" | grep -q 'ANDROID_RELA' ||
      die "$lib has no packed relocations (DT_ANDROID_RELA): the NDK's linker ignored $link_flags"
    echo "${abis[$i]}: libtensorholo_ffi.so $(du -h "$lib" | cut -f1), LOAD segments 16 KB-aligned, relocations packed"
  fi
done

# -- 2. The .aar.
(cd "$here" && "${gradle[@]}" --console=plain :tensorholo:assembleRelease)

# -- 3. Where it is.
aar="$here/tensorholo/build/outputs/aar/tensorholo-release.aar"
[ -f "$aar" ] || die "gradle finished but $aar is missing"
echo "aar: $aar ($(du -h "$aar" | cut -f1), $(wc -c <"$aar" | tr -d ' ') bytes)"

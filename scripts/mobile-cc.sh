# shellcheck shell=bash
# Sourced by check-mobile.sh and mobile-sizes.sh: `mobile_cc_env TARGET…` sets the C compiler settings that
# let tract-linalg's build script assemble its kernels for phone targets WITHOUT an Xcode SDK or Android NDK.
# LLVM's clang assembles them for any of these targets (the kernels include no system header):
# CC_<target>=clang and AR_<target>=llvm-ar; for iOS an empty SDKROOT so that cc-rs does not call xcrun;
# for armv7 the NEON/VFP flags of Android's armeabi-v7a ABI. Compile-only: nothing built this way is linked
# into an app (ios/build-xcframework.sh and android/build-aar.sh use Xcode's and the NDK's compilers).
# Installs clang/llvm (apt) and the rustup targets when missing. Needs bindings/tests/lib.sh (ensure_apt,
# CLEANUP) sourced first.
mobile_cc_env() {
  command -v clang >/dev/null 2>&1 || ensure_apt clang || { echo "needs clang" >&2; return 1; }
  command -v llvm-ar >/dev/null 2>&1 || ensure_apt llvm || { echo "needs llvm-ar" >&2; return 1; }
  local installed t var
  installed="$(rustup target list --installed)"
  for t in "$@"; do
    grep -qx "$t" <<<"$installed" || rustup target add "$t" >&2
    var="${t//-/_}"
    export "CC_$var=clang" "AR_$var=llvm-ar"
  done
  MOBILE_NO_SDK="$(mktemp -d)"
  CLEANUP+=("$MOBILE_NO_SDK")
  export SDKROOT="$MOBILE_NO_SDK" CFLAGS_armv7_linux_androideabi="-march=armv7-a -mfpu=neon -mfloat-abi=softfp"
}

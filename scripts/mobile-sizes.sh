#!/usr/bin/env bash
# Usage: scripts/mobile-sizes.sh [--static] [TARGET…]
#
# Builds the app library (tensorholo-ffi) with the `mobile` profile (LTO, one codegen unit, stripped; the GPU
# stack and tract optimised for size, Cargo.toml) and prints the sizes of docs/GUIDE.md "Size on a phone" as a
# Markdown table:
#  - the linked shared library (libtensorholo_ffi.so) for the two Android ABIs that android/build-aar.sh ships,
#    built for their Linux twins, which can be linked here: aarch64-unknown-linux-gnu (the same arm64 code as
#    aarch64-linux-android: arm64-v8a, phones) for `gpu` on/off × `tract` on/off with the default models, and
#    with every model; x86_64-unknown-linux-gnu (x86_64, emulators) with the default features, tract on and
#    off. Linked as the NDK links an app library: by LLVM's lld (here rust-lld, shipped with the Rust
#    toolchain), with 16 KB pages (`-z max-page-size=16384`, what Android 15's 16 KB-page devices need) and
#    packed relative relocations (`--pack-dyn-relocs=android`, what android/build-aar.sh passes: Android 6+,
#    and the .aar's minSdk is 26). GNU ld, without packing, makes the same code 1-2 MB larger. Built as
#    build-aar.sh builds it, the cdylib alone (`cargo rustc --crate-type cdylib`): `cargo build` compiles the
#    crate's three types in one rustc run, whose LTO keeps the rlib's public items (3 MB more with tract);
#  - with --static, the TARGETs (default: the four of scripts/check-mobile.sh: aarch64-apple-ios,
#    aarch64-linux-android, x86_64-linux-android, armv7-linux-androideabi): the
#    static library with and without tract (no Xcode or NDK linker here; scripts/mobile-cc.sh has the
#    compile-only C settings). A static library is what the app's linker reads (an XCFramework ships it),
#    not what the app carries.
# Also prints what each crate adds to the default linked arm64 library (symbol sizes by crate, before
# stripping). Builds in target/mobile-sizes (its own flags would rebuild the main target dir). Slow: every row
# is a full LTO build (2-6 min each on two cores once the dependencies are built; 46 min in all with --static,
# docs/GUIDE.md "Size on a phone").
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
# shellcheck source=bindings/tests/lib.sh
. "$root/bindings/tests/lib.sh"
# shellcheck source=scripts/mobile-cc.sh
. "$root/scripts/mobile-cc.sh"
cd "$root"
static=0
if [ "${1:-}" = "--static" ]; then
  static=1
  shift
fi
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(aarch64-apple-ios aarch64-linux-android x86_64-linux-android armv7-linux-androideabi)
export CARGO_TARGET_DIR="$root/target/mobile-sizes"
mb() { python3 -c "import os,sys; print(f'{os.path.getsize(sys.argv[1]) / 1e6:.2f} MB')" "$1"; }

# lld as the NDK runs it: gcc's -fuse-ld=lld looks for `ld.lld` (a cross gcc also for `<triple>-ld.lld`) in
# its -B folder. A fixed folder, so that the flags (and cargo's fingerprints) stay the same between runs.
lld="$(rustc --print sysroot)/lib/rustlib/$(rustc -vV | sed -n 's/^host: //p')/bin/rust-lld"
[ -x "$lld" ] || { echo "mobile-sizes: no rust-lld in the Rust toolchain ($lld)" >&2; exit 1; }
lld_dir="$CARGO_TARGET_DIR/lld"
mkdir -p "$lld_dir"
for name in ld.lld aarch64-linux-gnu-ld.lld x86_64-linux-gnu-ld.lld; do ln -sf "$lld" "$lld_dir/$name"; done
ndk_link="-C link-arg=-B$lld_dir -C link-arg=-fuse-ld=lld -C link-arg=-Wl,-z,max-page-size=16384"
ndk_link="$ndk_link -C link-arg=-Wl,--pack-dyn-relocs=android"
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUSTFLAGS="$ndk_link"
export CARGO_TARGET_X86_64_UNKNOWN_LINUX_GNU_RUSTFLAGS="$ndk_link"
linux=aarch64-unknown-linux-gnu
x86=x86_64-unknown-linux-gnu
ensure_apt gcc-aarch64-linux-gnu libc6-dev-arm64-cross binutils-aarch64-linux-gnu ||
  { echo "mobile-sizes: needs Debian's aarch64 cross toolchain" >&2; exit 1; }
rustup target list --installed | grep -qx "$linux" || rustup target add "$linux" >&2

echo "| target | library | gpu | tract | embedded CNNs | size |"
echo "|---|---|---|---|---|---:|"
out="$CARGO_TARGET_DIR/$linux/mobile"
for variant in "on:on:default:" "on:off:default:--no-default-features --features embedded-models,gpu" \
  "off:on:default:--no-default-features --features embedded-models,tract" \
  "off:off:default:--no-default-features --features embedded-models" \
  "on:off:all:--no-default-features --features gpu,models-15,models-30" \
  "on:on:all:--features models-15,models-30"; do
  IFS=: read -r gpu tract models flags <<<"$variant"
  # shellcheck disable=SC2086 # flags are words
  cargo rustc --locked -q -p tensorholo-ffi --lib --crate-type cdylib --profile mobile --target "$linux" $flags >&2
  echo "| $linux (arm64-v8a) | \`libtensorholo_ffi.so\` (linked) | $gpu | $tract | $models | $(mb "$out/libtensorholo_ffi.so") |"
  if [ "$gpu:$tract:$models" = "on:on:default" ]; then
    # What each crate adds: one unstripped link of the default library, symbol sizes summed by crate.
    CARGO_PROFILE_MOBILE_STRIP=none cargo rustc --locked -q -p tensorholo-ffi --lib --crate-type cdylib \
      --profile mobile --target "$linux" >&2
    cp "$out/libtensorholo_ffi.so" "$CARGO_TARGET_DIR/unstripped.so"
  fi
done
# One row per `tract` on/off with the default models and `gpu`: TARGET, crate type (cdylib, staticlib), file
# name, label of the target column, library column.
tract_rows() {
  local tract flags
  for tract in on off; do
    flags=()
    [ "$tract" = on ] || flags=(--no-default-features --features "embedded-models,gpu")
    cargo rustc --locked -q -p tensorholo-ffi --lib --crate-type "$2" --profile mobile --target "$1" \
      ${flags[@]+"${flags[@]}"} >&2
    echo "| $4 | $5 | on | $tract | default | $(mb "$CARGO_TARGET_DIR/$1/mobile/$3") |"
  done
}
tract_rows "$x86" cdylib libtensorholo_ffi.so "$x86 (x86_64)" "\`libtensorholo_ffi.so\` (linked)"
if [ "$static" = 1 ]; then
  # Static libraries alone (`cargo rustc --crate-type staticlib`): built beside the rlib and cdylib, rustc
  # keeps one object per crate without cross-crate LTO; alone, the crate graph is one LTO'd object.
  mobile_cc_env "${targets[@]}"
  for t in "${targets[@]}"; do
    tract_rows "$t" staticlib libtensorholo_ffi.a "$t" "\`libtensorholo_ffi.a\`"
  done
fi
echo
echo "What each crate adds to the default linked library (symbols before stripping, by the crate of the"
echo "demangled name: generic code instantiated elsewhere counts under its defining crate):"
echo
aarch64-linux-gnu-nm -C --size-sort -S "$CARGO_TARGET_DIR/unstripped.so" | python3 -c '
import collections, re, sys
sizes = collections.Counter()
for line in sys.stdin:
    parts = line.split(" ", 3)
    if len(parts) < 4:
        continue
    name = parts[3].lstrip("<&*( ")
    m = re.match(r"([A-Za-z_][A-Za-z0-9_]*)::", name)
    sizes[m.group(1) if m else "(other)"] += int(parts[1], 16)
total = sum(sizes.values())
print("| crate | MB |\n|---|---:|")
for crate, size in sizes.most_common(15):
    print(f"| {crate} | {size / 1e6:.2f} |")
print(f"| all symbols | {total / 1e6:.2f} |")
'

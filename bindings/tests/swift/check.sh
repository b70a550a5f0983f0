#!/usr/bin/env bash
# Usage: bindings/tests/swift/check.sh [BINDINGS_DIR]
#
# Checks the generated Swift bindings without a Swift compiler (no Mac here):
#  1. the C header compiles with clang for arm64-apple-ios and aarch64-linux-android;
#  2. the module map imports as Swift would (`@import TensorholoFFI`, iOS target) and declares every FFI
#     symbol the Swift file calls;
#  3. the built library exports every one of those symbols, and every uniffi symbol it exports is declared;
#  4. the library's contract version and API checksums equal those in the Swift file (checksums.py).
# Tools (installed when missing): clang and llvm nm from Debian, python3.
# BINDINGS_DIR: output of bindings/generate.sh (default $TENSORHOLO_BINDINGS_DIR, else generated now).
#
# Why -ffreestanding -nostdlibinc: there is no iOS SDK or Android NDK here. The header only needs
# <stdbool.h>, <stddef.h> and <stdint.h>, which clang's own resource directory provides for any target;
# in hosted mode clang's <stdint.h> would #include_next the *host's* glibc headers (/usr/include), which
# belong to neither target and do not even parse for them. Freestanding + no system include dirs makes the
# check use exactly the compiler's target-aware headers.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
# shellcheck source=bindings/tests/lib.sh
. "$here/../lib.sh"

use_bindings "${1:-}"
swift_dir="$dir/swift"
swift="$swift_dir/Tensorholo.swift"
header="$swift_dir/TensorholoFFI.h"
modulemap="$swift_dir/TensorholoFFI.modulemap"
case "$(uname -s)" in Darwin) lib="$dir/python/libtensorholo_ffi.dylib" ;; *) lib="$dir/python/libtensorholo_ffi.so" ;; esac
for f in "$swift" "$header" "$modulemap" "$lib"; do
  [ -f "$f" ] || { echo "swift check: $f missing" >&2; exit 1; }
done

command -v clang >/dev/null 2>&1 || ensure_apt clang || skip "swift bindings: no clang and it cannot be installed"
command -v nm >/dev/null 2>&1 || ensure_apt binutils || skip "swift bindings: no nm and it cannot be installed"
command -v python3 >/dev/null 2>&1 || ensure_apt python3 || skip "swift bindings: no python3 and it cannot be installed"

tmp_dir swift
work="$tmp"
cflags=(-ffreestanding -nostdlibinc -fsyntax-only -std=c11 -Wall -Wextra -Werror -I "$swift_dir")

# 1. The header alone, included from a C file (as a bridging header or the module would include it).
for target in arm64-apple-ios aarch64-linux-android; do
  echo '#include "TensorholoFFI.h"' >"$work/header.c"
  clang -target "$target" "${cflags[@]}" "$work/header.c"
  echo "  header compiles for $target"
done

# 2. The symbols the Swift file calls, each one referenced through the module map (iOS).
grep -oE '\b(uniffi|ffi)_tensorholo_ffi_[A-Za-z0-9_]+' "$swift" | sort -u >"$work/swift.syms"
n_swift="$(wc -l <"$work/swift.syms")"
[ "$n_swift" -gt 0 ] || { echo "swift check: no FFI symbols found in $swift" >&2; exit 1; }
{
  echo '@import TensorholoFFI;'
  echo 'void *const tensorholo_swift_calls[] = {'
  sed 's/.*/    (void *)\&&,/' "$work/swift.syms"
  echo '};'
} >"$work/calls.m"
clang -target arm64-apple-ios "${cflags[@]}" -fmodules -fmodules-cache-path="$work/modules" \
  -fmodule-map-file="$modulemap" -x objective-c "$work/calls.m"
echo "  module TensorholoFFI imports (arm64-apple-ios) and declares all $n_swift symbols Tensorholo.swift calls"

# 3. Exported by the library (dynamic symbol table, defined) both ways.
nm -D --defined-only "$lib" | awk '{print $NF}' | grep -E '^(uniffi|ffi)_tensorholo_ffi_' | sort -u >"$work/lib.syms"
grep -oE '\b(uniffi|ffi)_tensorholo_ffi_[A-Za-z0-9_]+' "$header" | sort -u >"$work/header.syms"
not_exported="$(comm -23 "$work/swift.syms" "$work/lib.syms")"
[ -z "$not_exported" ] || { echo "swift check: called by Tensorholo.swift but not exported by $lib:" >&2; echo "$not_exported" >&2; exit 1; }
undeclared="$(comm -13 "$work/header.syms" "$work/lib.syms")"
[ -z "$undeclared" ] || { echo "swift check: exported by $lib but not in the header (stale bindings?):" >&2; echo "$undeclared" >&2; exit 1; }
echo "  $lib exports all $n_swift symbols; the header declares all $(wc -l <"$work/lib.syms") it exports"

# 4. Checksums and contract version.
python3 "$here/checksums.py" "$swift" "$header" "$lib"
echo "swift bindings: ok"

#!/usr/bin/env bash
# Usage: benchmarks/qemu/layer_instructions.sh [C_IN C_OUT WIDTH ROWS]
#
# Guest instructions of one aarch64 convolution layer under qemu-aarch64 (this directory's insn_count.c
# plugin), per kernel row: the direct NEON row against the Winograd F(2×2, 3×3) and F(4×4, 3×3) NEON rows (and the portable
# rows), on a band of ROWS rows × WIDTH (default 24 → 24, 384, 16: one strip of the 8-layer CNN's hidden
# layer at 384²). Each row runs its layer once and three times (`kernels/examples/conv_best_of.rs`); the
# difference, halved, is one layer (start-up and data filling cancel out). A proxy for ARM cost, not a time
# (see instructions.sh). Needs the aarch64 target, Debian's gcc-aarch64-linux-gnu and qemu-user.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
shape=("${1:-24}" "${2:-24}" "${3:-384}" "${4:-16}")
target=aarch64-unknown-linux-gnu
(cd "$root" && cargo build --release --locked --target "$target" -p tensorholo-kernels --example conv_best_of >&2)
bin="${CARGO_TARGET_DIR:-$root/target}/$target/release/examples/conv_best_of"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
gcc -O2 -shared -fPIC -o "$work/libinsn_count.so" "$here/insn_count.c"
count() { # row rounds → guest instructions
  qemu-aarch64 -L /usr/aarch64-linux-gnu -plugin "$work/libinsn_count.so" -d plugin \
    -D "$work/plugin.log" "$bin" "${shape[@]}" "$2" plain "$1" >/dev/null
  sed -n 's/^insn_count: //p' "$work/plugin.log"
}
echo "| row (${shape[0]}→${shape[1]}, ${shape[3]} rows × ${shape[2]}) | guest instructions per layer | per output pixel |"
echo "|---|---:|---:|"
for row in conv3x3.f32.8x3.neon conv3x3.f32.wino2x2.8x3.neon conv3x3.f32.wino4x4.8x3.neon conv3x3.f32.8x8.scalar conv3x3.f32.wino2x2.4x4.scalar conv3x3.f32.wino4x4.4x4.scalar; do
  one="$(count "$row" 1)"
  three="$(count "$row" 3)"
  per=$(((three - one) / 2))
  echo "| \`$row\` | $per | $(python3 -c "print(f'{$per / (${shape[2]} * ${shape[3]}):.0f}')") |"
done

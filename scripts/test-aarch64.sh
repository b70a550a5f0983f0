#!/usr/bin/env bash
# Usage: scripts/test-aarch64.sh [extra cargo test args…]
#
# Runs the SDK's model and pipeline tests compiled for aarch64 (tract's NEON kernels, rustfft's NEON
# butterflies) on this x86-64 machine, under qemu-user: .cargo/config.toml makes Debian's
# gcc-aarch64-linux-gnu the linker and the C compiler of tract's assembly, and `qemu-aarch64 -L
# /usr/aarch64-linux-gnu` the runner. Installs what is missing (apt: gcc-aarch64-linux-gnu,
# libc6-dev-arm64-cross, qemu-user; rustup: the target).
#
# What runs: the kernels crate under three emulated CPUs (see the end), the aarch64 `holo render` on a real
# frame against the x86-64 one (`holo compare`), the native CNN engine's unit tests (the `cnn::` tests), every
# shipped CNN (8/15/30 layers, pre-filters; f32 and int8 QDQ) and the fixture CNNs against their PyTorch outputs
# with the x86 tolerances (tests model, shipped_models), the pipeline tests (session vs the stand-alone stages,
# streaming, bad input), and platform_parity: the built-in scene rendered to the same midpoint hologram and SLM
# codes as the x86-64 reference files, within the tolerances that test states (it prints the differences). A
# debug build (deps optimised as in the dev profile), so it stays a few minutes on two cores. Emulated timings
# mean nothing: never read them as phone speed.
#
# tract under qemu: built and run (the same tests with its cases: tract against PyTorch, the native engine
# against tract, the int8 QOperator files, platform_parity's tract cases) only where it can have changed since
# the previous commit: Cargo.lock (tract's version), a Cargo.toml, tract's engine (sdk/src/cnn/tract) or the
# shipped models (models/); also without a previous commit, or with TENSORHOLO_ARM_TRACT=1. Otherwise the step
# builds what the native engine needs, no tract: tract's crates were half of the aarch64 build (tract-core alone
# 432 of 801 s from scratch here), and tract's own CI tests its NEON kernels. Set TENSORHOLO_ARM_TRACT=0 to leave
# it out regardless. The rule is scripts/arm-tract.sh's, which .ci/run also asks: the run without tract here is
# CI's run of the library without tract, and where this step builds tract, CI runs that on x86-64 instead.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
# shellcheck source=bindings/tests/lib.sh
. "$root/bindings/tests/lib.sh"
cd "$root"

target=aarch64-unknown-linux-gnu
tdir="${CARGO_TARGET_DIR:-target}"
ensure_apt gcc-aarch64-linux-gnu libc6-dev-arm64-cross qemu-user ||
  { echo "test-aarch64: cannot install the aarch64 cross toolchain and qemu-user" >&2; exit 1; }
rustup target list --installed | grep -qx "$target" || rustup target add "$target"

# One cargo invocation builds everything the SDK's part of this step runs, so that every crate is compiled once
# with one feature set: the SDK's integration tests and unit tests, and the aarch64 `holo` (built for the CLI
# check below because holo's `output_guard` test needs it; holo pulls the SDK's `research` feature in, and a
# separate `cargo build -p holo` resolved other features and rebuilt tract and the SDK: 6 min here, warm). No
# `gpu` feature: wgpu is not what this step tests, and it would double the cross build.
features="tensorholo/embedded-models tensorholo/models-15 tensorholo/models-30"
arm_tract="$(scripts/arm-tract.sh)"
if [ "$arm_tract" = 1 ]; then
  features+=" tensorholo/tract holo/tract"
  echo "== aarch64 with tract (TENSORHOLO_ARM_TRACT=1, or tract's version, a manifest, its engine or the models changed)"
else
  echo "== aarch64 without tract (the native engine; TENSORHOLO_ARM_TRACT=1 adds tract)"
fi
sdk=(--locked --target "$target" -p tensorholo -p holo --no-default-features --features "$features")
sdk_tests=(--test model --test shipped_models --test pipeline --test platform_parity)
cargo test "${sdk[@]}" --lib "${sdk_tests[@]}" --test output_guard --no-run "$@"

cargo test "${sdk[@]}" "${sdk_tests[@]}" "$@" -- --nocapture 2>&1 |
  grep -vE '^(running [0-9]+ tests?|)$'

# The native CNN engine (NEON kernel rows) on every shipped f32 CNN, threads and bad input, against tract where
# it is built: the SDK's unit tests of `cnn` (sdk/src/cnn/tests.rs); and the per-runtime suite
# (sdk/src/pipeline/suite.rs): one list of frames through the session on the native engine at every NEON row
# qemu's `max` CPU has (and on tract), each against the stand-alone reference. Built above.
cargo test "${sdk[@]}" --lib "$@" -- --nocapture cnn:: pipeline::suite 2>&1 |
  grep -vE '^(running [0-9]+ tests?|)$'

# The CLI itself on ARM: the aarch64 `holo` (dev profile, built above) starts under qemu-user without binfmt (it
# sets glibc's mmap threshold in-process, no re-execution) and renders a real RGB-D frame (TUM,
# ../shared/data), which `holo compare` then holds against the x86-64 render of the same command: at most
# 0.1 % of the SLM codes may differ, none by more than one step.
if [ "$#" -eq 0 ]; then
  frame=(--rgb ../shared/data/tum/TUM_color.png --depth ../shared/data/tum/TUM_depth.png
    --depth-encoding tum --size 96x128 --backend cpu --engine native --threads 1 --repeat 0)
  out="$(mktemp -d)"
  trap 'rm -rf "$out"' EXIT
  # The x86-64 reference is the workspace's own `holo`, as the README's `cargo test --workspace --locked` builds
  # it (the native engine's frame does not depend on the cargo features): in CI a no-op after the tests. A
  # `cargo build -p holo` resolves other features (no dev-dependencies) and rebuilt tract and the SDK for x86:
  # 6–8 min of a fresh CI machine.
  cargo test --workspace --locked --no-run
  # Both on the Winograd rows (AVX2/AVX-512 here, NEON there), the F(2×2, 3×3) path through the CLI on ARM.
  export TENSORHOLO_CONV=winograd
  "$tdir/debug/holo" render "${frame[@]}" --out "$out/x86" >/dev/null
  echo "== holo render (aarch64, qemu-user)"
  qemu-aarch64 -L /usr/aarch64-linux-gnu "$tdir/$target/debug/holo" render "${frame[@]}" --out "$out/arm"
  "$tdir/debug/holo" compare "$out/x86" "$out/arm" --max-code-fraction 0.001
fi

# The kernels crate (kernels/, tensorholo-kernels) under three emulated CPUs, so that every aarch64 kernel row
# runs: `max` has dot product and i8mm (rows neon, neondot, neoni8mm), `cortex-a76` dot product only (neon,
# neondot), `cortex-a53` neither (neon and the widening int8 path). qemu-user reads QEMU_CPU; the tests print
# the rows they skip for want of a feature.
for cpu in max cortex-a76 cortex-a53; do
  echo "== tensorholo-kernels, QEMU_CPU=$cpu"
  QEMU_CPU=$cpu cargo test --locked --target "$target" -p tensorholo-kernels "$@" -- --nocapture 2>&1 |
    grep -vE '^(running [0-9]+ tests?|)$'
done

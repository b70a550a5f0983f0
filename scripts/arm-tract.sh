#!/usr/bin/env bash
# Prints 1 when scripts/test-aarch64.sh builds tract for aarch64, else 0: TENSORHOLO_ARM_TRACT (1 or 0) where
# set; otherwise 1 only where tract can have changed since the previous commit (Cargo.lock, a Cargo.toml,
# tract's engine code sdk/src/cnn/tract, the models) or there is no previous commit. tract's crates are half of
# the aarch64 build (7.5 min of a fresh machine without them, 13.4 with).
#
# .ci/run uses the same answer: where the ARM step runs without tract, it is the library's test run without
# tract (the native engine's `cnn::` unit tests and the model, shipped-model, pipeline and parity tests, the
# tests whose code has a `cfg(feature = "tract")`), and the x86-64 run of the library without tract is left out;
# where the ARM step builds tract, that x86-64 run takes its place.
set -euo pipefail
cd "$(dirname "$0")/.."
case "${TENSORHOLO_ARM_TRACT:-}" in
  1 | 0) echo "$TENSORHOLO_ARM_TRACT"; exit 0 ;;
  "") ;;
  *) echo "arm-tract: TENSORHOLO_ARM_TRACT must be 1 or 0, not '$TENSORHOLO_ARM_TRACT'" >&2; exit 2 ;;
esac
if ! git rev-parse -q --verify HEAD~1 >/dev/null 2>&1 \
  || git diff --name-only HEAD~1 -- Cargo.lock '*Cargo.toml' sdk/src/cnn/tract models | grep -q .; then
  echo 1
else
  echo 0
fi

#!/usr/bin/env bash
# The SDK's public surface: the number of `pub fn` in sdk/src (tests included, as `grep` counts them) must stay
# under a ceiling, so that what docs.rs shows as API is a decision (CONTRIBUTING.md "The public API").
# Usage: scripts/api-size.sh [CEILING]   (default 450). Prints the count; exits 1 at or above the ceiling.
set -euo pipefail
cd "$(dirname "$0")/.."
ceiling=${1:-450}
count=$(grep -rEo '\bpub (const |unsafe )?fn ' sdk/src --include='*.rs' | wc -l)
echo "pub fn in sdk/src: $count (ceiling $ceiling)"
if [ "$count" -ge "$ceiling" ]; then
  echo "error: sdk/src has $count \`pub fn\`, at or above $ceiling. Make what no other crate calls \`pub(crate)\`" >&2
  echo "(CONTRIBUTING.md \"The public API\"), or raise the ceiling in .ci/run with a reason." >&2
  exit 1
fi

#!/usr/bin/env bash
# Usage: ios/check.sh            (from anywhere; CI runs it on Linux, where there is no Swift compiler)
#
# Checks the Swift of ios/ with tree-sitter-swift (ios/ci/check-swift.mjs):
#  1. every Swift file under ios/ and the generated bindings/generated/swift/Tensorholo.swift parse;
#  2. every name the hand-written Swift (Sources/Tensorholo, Tests, Example) takes from the bindings is declared
#     by them (or by the Swift layer): types, argument labels of initialisers/methods/functions, enum cases,
#     members of binding-typed values, free functions; other names must be the platform's
#     (ios/ci/platform-names.txt);
#  3. the examples of the READMEs: every ```swift block of README.md and ios/README.md, wrapped in a function
#     body when it is a fragment of statements, parses, and every binding name it uses is declared as in 2 (types,
#     argument labels, members, enum cases of binding enums, free functions), errors at the README's line; a
#     Package.swift fragment (`.package(path:)`) is parsed only;
#  4. the sample's external display (ios/ci/check-scenes.py, python3, Info.plist read as XML with plistlib): the
#     scene manifest declares the role UIWindowSceneSessionRoleExternalDisplayNonInteractive (configuration name
#     used by the Swift, delegate class declared as a UIWindowSceneDelegate) with multiple scenes on, and the
#     Swift sets `overscanCompensation = .none`;
#  5. self-test: the same checks on temporary copies with one wrong name injected (a member, an enum case of
#     the wrong enum, an argument label, a free function, a type, a method, a case in a tuple, labels in the
#     sample app; in the READMEs' examples a label, a method, an initialiser's label), one syntax error (also in a
#     README example), a scene manifest without the external-display role, multiple scenes off
#     and the overscan left at `.scale` must fail, naming the problem.
# The C header and module map of the bindings are checked by bindings/tests/swift/check.sh; compiling the Swift,
# the XCFramework, the XCTests and the sample need a Mac (ios/README.md, ios/ci/macos-workflow.yml).
#
# Tools: node >= 18 and npm; `npm ci --ignore-scripts` installs the pinned tree-sitter + tree-sitter-swift
# (ios/ci/package-lock.json, prebuilt native addons) into ios/ci/node_modules (git-ignored) when missing or stale.
# When node/npm or the registry is unavailable the check fails, or prints SKIPPED and exits 0 if
# TENSORHOLO_ALLOW_SKIP=1.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/.." && pwd)"
ci="$here/ci"
generated="$root/bindings/generated/swift/Tensorholo.swift"
start=$(date +%s)

skip_or_fail() {
  if [ "${TENSORHOLO_ALLOW_SKIP:-0}" = 1 ]; then
    echo "SKIPPED ios/check.sh: $*"
    exit 0
  fi
  echo "ios/check.sh: $* (set TENSORHOLO_ALLOW_SKIP=1 to skip instead)" >&2
  exit 1
}

command -v node >/dev/null 2>&1 || skip_or_fail "node is not installed"
command -v npm >/dev/null 2>&1 || skip_or_fail "npm is not installed"
node_major="$(node -p 'process.versions.node.split(".")[0]')"
[ "$node_major" -ge 18 ] || skip_or_fail "node $node_major is too old (need 18 or later)"
[ -f "$generated" ] || { echo "ios/check.sh: $generated is missing" >&2; exit 1; }

# Install the pinned parser unless node_modules already holds exactly this lock file's packages.
stamp="$ci/node_modules/.tensorholo-package-lock.json"
if ! cmp -s "$ci/package-lock.json" "$stamp" 2>/dev/null; then
  echo "== npm ci (tree-sitter, tree-sitter-swift) in ios/ci"
  # --ignore-scripts: tree-sitter-swift depends on tree-sitter-cli, whose install script downloads a binary
  # (no registry package); the parser itself ships prebuilt addons that load without any install script.
  if ! (cd "$ci" && npm ci --ignore-scripts --no-audit --no-fund --loglevel=error); then
    skip_or_fail "npm ci failed in $ci (is the npm registry reachable?)"
  fi
  cp "$ci/package-lock.json" "$stamp"
fi
if ! (cd "$ci" && node --input-type=module -e "import 'tree-sitter'; import 'tree-sitter-swift';") 2>/dev/null; then
  skip_or_fail "the tree-sitter native addons do not load on $(uname -sm) with node $(node --version) (no prebuilt binary?)"
fi

command -v python3 >/dev/null 2>&1 || skip_or_fail "python3 is not installed (Info.plist check)"
# $1: the ios/ folder (or a copy); the top-level README.md is $1/../README.md.
check() {
  node "$ci/check-swift.mjs" --ios "$1" --generated "$generated" --platform-names "$ci/platform-names.txt" \
    --readme "$1/../README.md" --readme "$1/README.md" &&
    python3 "$ci/check-scenes.py" "$1"
}

echo "== Swift sources and the READMEs' Swift examples: parse + binding names; the sample's external-display scene and overscan"
check "$here"

# Self-test: each line is FILE|TEXT|REPLACEMENT|what the failure must mention (several texts joined by `&`: each).
# FILE is relative to ios/ (../README.md: the top-level one). TEXT must occur in FILE (this script fails when
# the code no longer has it: update the line then).
echo "== self-test: injected mistakes must fail"
injections=(
  "Tests/TensorholoTests/SwiftLayerTests.swift|frame.colorRowStride|frame.colorRowStrid|RgbdFrame has no member \`colorRowStrid\`"
  "Sources/Tensorholo/RgbdFrame+ARKit.swift|colorFormat: .bgra8|colorFormat: .metresF32|\`.metresF32\` is not a case or static member of ColorFormat"
  "Tests/TensorholoTests/ErrorTests.swift|offsetMm: .nan|offsetMM: .nan|(width:height:offsetMM:)"
  "Sources/Tensorholo/SlmPatterns+CoreGraphics.swift|try packRgba(|try packRGBA(|function \`packRGBA\`"
  "Tests/TensorholoTests/GeneratorTests.swift|try RgbdFrame(colorBuffer|try RgbFrame(colorBuffer|type \`RgbFrame\`"
  "Tests/TensorholoTests/GeneratorTests.swift|gen.render(frame|gen.rendr(frame|HologramGenerator has no member \`rendr\`"
  "Tests/TensorholoTests/SwiftLayerTests.swift|(.right, .deg90, 90)|(.right, .deg91, 90)|\`.deg91\`"
  "Example/Sources/HologramModel.swift|depthData: depth.depthData|depthDat: depth.depthData|(sampleBuffer:depthDat:orientation:)"
  "Example/Sources/HologramModel.swift|generatorConfigForDisplay(profile: profile)|generatorConfigForDisplay(profil: profile)|\`generatorConfigForDisplay\` takes the arguments (profil:)"
  "Sources/Tensorholo/PatternsHandler.swift|handleError(error)|handleError(error|missing )"
  "Example/Info.plist|<key>UIWindowSceneSessionRoleExternalDisplayNonInteractive</key>|<key>UIWindowSceneSessionRoleApplication</key>|declares no UIWindowSceneSessionRoleExternalDisplayNonInteractive"
  "Example/Info.plist|<key>UIApplicationSupportsMultipleScenes</key>|<key>UIApplicationSupportsMultipleScenesOff</key>|UIApplicationSupportsMultipleScenes must be true"
  "Example/Info.plist|.ExternalDisplaySceneDelegate</string>|.ExternalDisplayDelegate</string>|declares no class ExternalDisplayDelegate"
  "Example/Sources/TensorholoSampleApp.swift|screen.overscanCompensation = .none|screen.overscanCompensation = .scale|no \`overscanCompensation = .none\`"
  "../README.md|packRgba(patterns: patterns)|packRgba(pattern: patterns)|README.md:&swift block of line&\`packRgba\` takes the arguments (pattern:)"
  "../README.md|depthBuffer: depthPixelBuffer|depthBuf: depthPixelBuffer|README.md:&\`RgbdFrame\` takes the arguments (colorBuffer:depthBuf:)"
  "README.md|generator.render(frame: frame)|generator.rendr(frame: frame)|README.md:&swift block of line&HologramGenerator has no member \`rendr\`"
  "README.md|PatternsHandler(onPatterns:|PatternsHandler(onPattern:|README.md:&\`PatternsHandler\` takes the arguments (onPattern:)"
  "README.md|_ = try stream.push(frame: frame)|_ = try stream.push(frame: frame|README.md:&swift block of line&missing )"
)
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
n=0
for line in "${injections[@]}"; do
  IFS='|' read -r file text replacement expected <<<"$line"
  rm -rf "$tmp/ios"
  mkdir -p "$tmp/ios"
  (cd "$here" && tar cf - --exclude=node_modules --exclude=.build --exclude=build --exclude='*.xcframework' .) | (cd "$tmp/ios" && tar xf -)
  cp "$root/README.md" "$tmp/README.md"
  python3 - "$tmp/ios/$file" "$text" "$replacement" <<'EOF'
import sys
path, text, replacement = sys.argv[1:]
source = open(path, encoding="utf-8").read()
if text not in source:
    sys.exit(f"ios/check.sh self-test: {text!r} is not in {path}: update the injection list")
open(path, "w", encoding="utf-8").write(source.replace(text, replacement, 1))
EOF
  if out="$(check "$tmp/ios" 2>&1)"; then
    echo "ios/check.sh: the check passed with $file: '$text' -> '$replacement'; it must fail" >&2
    exit 1
  fi
  IFS='&' read -ra wanted <<<"$expected"
  for w in "${wanted[@]}"; do
    case "$out" in
      *"$w"*) ;;
      *)
        echo "ios/check.sh: with $file: '$text' -> '$replacement' the check failed without mentioning '$w':" >&2
        echo "$out" >&2
        exit 1
        ;;
    esac
  done
  n=$((n + 1))
done
echo "  $n/${#injections[@]} injected mistakes fail as they should"
echo "ios/check.sh: ok ($(($(date +%s) - start)) s)"

#!/usr/bin/env python3
"""Usage: ios/ci/check-scenes.py IOS_DIR

Checks what the sample app (IOS_DIR/Example) needs for a pixel-exact external display, without Xcode or plutil
(Info.plist is read as XML with plistlib):

1. Info.plist declares a scene manifest (UIApplicationSceneManifest) with UIApplicationSupportsMultipleScenes
   true and, under UISceneConfigurations, the role UIWindowSceneSessionRoleExternalDisplayNonInteractive with at
   least one configuration: a UISceneConfigurationName and a UISceneDelegateClassName
   (`$(PRODUCT_MODULE_NAME).Class` or `Class`) whose class the sample's Swift declares as a
   UIWindowSceneDelegate. Without the role iOS mirrors the phone's screen instead of delivering the scene.
2. The configuration name appears in the sample's Swift as a string literal (the app delegate and the iOS 27
   scene accessory ask for the configuration by that name).
3. The sample's Swift sets `overscanCompensation = .none` (UIScreen's default `.scale` resamples every frame on
   displays that report overscan) and never assigns it another value.

Prints one line per problem and exits 1 if there is any, else prints a summary and exits 0.
"""

import pathlib
import plistlib
import re
import sys
from xml.parsers.expat import ExpatError

ROLE = "UIWindowSceneSessionRoleExternalDisplayNonInteractive"


def swift_sources(example: pathlib.Path) -> str:
    """The sample's Swift, with // comments removed (a commented-out line does not count)."""
    text = []
    for path in sorted(example.rglob("*.swift")):
        for line in path.read_text(encoding="utf-8").splitlines():
            text.append(re.sub(r"//.*$", "", line))
    return "\n".join(text)


def check(ios: pathlib.Path) -> list[str]:
    example = ios / "Example"
    plist_path = example / "Info.plist"
    problems: list[str] = []
    try:
        with open(plist_path, "rb") as f:
            info = plistlib.load(f)
    except (OSError, plistlib.InvalidFileException, ValueError, ExpatError) as e:
        return [f"{plist_path}: cannot read the property list: {e}"]
    swift = swift_sources(example)

    manifest = info.get("UIApplicationSceneManifest")
    if not isinstance(manifest, dict):
        return [f"{plist_path}: no UIApplicationSceneManifest dictionary (the external display's scene needs one)"]
    if manifest.get("UIApplicationSupportsMultipleScenes") is not True:
        problems.append(
            f"{plist_path}: UIApplicationSupportsMultipleScenes must be true (found "
            f"{manifest.get('UIApplicationSupportsMultipleScenes')!r}): with it off the external display's scene "
            "is reported never to arrive"
        )
    configurations = manifest.get("UISceneConfigurations")
    entries = configurations.get(ROLE) if isinstance(configurations, dict) else None
    if not isinstance(entries, list) or not entries:
        problems.append(
            f"{plist_path}: UISceneConfigurations declares no {ROLE} configuration: iOS then mirrors the phone "
            "instead of delivering the SLM's scene"
        )
        entries = []
    for i, entry in enumerate(entries):
        where = f"{plist_path}: {ROLE}[{i}]"
        if not isinstance(entry, dict):
            problems.append(f"{where} is not a dictionary")
            continue
        name = entry.get("UISceneConfigurationName")
        delegate = entry.get("UISceneDelegateClassName")
        if not isinstance(name, str) or not name:
            problems.append(f"{where} has no UISceneConfigurationName")
        elif f'"{name}"' not in swift:
            problems.append(
                f"{where}: configuration name {name!r} does not appear as a string literal in the sample's Swift "
                "(UISceneConfiguration(name:sessionRole:) must ask for it)"
            )
        if not isinstance(delegate, str) or not delegate:
            problems.append(f"{where} has no UISceneDelegateClassName")
            continue
        class_name = delegate.rsplit(".", 1)[-1]
        prefix = delegate[: -len(class_name)].rstrip(".")
        if prefix not in ("", "$(PRODUCT_MODULE_NAME)"):
            problems.append(f"{where}: UISceneDelegateClassName {delegate!r}: expected $(PRODUCT_MODULE_NAME).{class_name}")
        declared = re.search(
            rf"\bclass\s+{re.escape(class_name)}\s*:[^{{]*\bUIWindowSceneDelegate\b", swift
        )
        if not declared:
            problems.append(
                f"{where}: UISceneDelegateClassName {delegate!r}: the sample declares no class {class_name} "
                "conforming to UIWindowSceneDelegate"
            )

    assignments = re.findall(r"\.?overscanCompensation\s*=\s*\.?([A-Za-z_][A-Za-z0-9_.]*)", swift)
    if "none" not in assignments:
        problems.append(
            f"{example}: no `overscanCompensation = .none` in the sample's Swift: UIScreen's default .scale resamples "
            "every SLM frame on displays that report overscan"
        )
    others = sorted(set(a for a in assignments if a != "none"))
    if others:
        problems.append(f"{example}: overscanCompensation is also set to {', '.join('.' + a for a in others)}")
    return problems


def main() -> int:
    if len(sys.argv) != 2:
        print(__doc__.strip().splitlines()[0], file=sys.stderr)
        return 2
    problems = check(pathlib.Path(sys.argv[1]))
    for p in problems:
        print(f"check-scenes: {p}")
    if problems:
        return 1
    print(f"  Info.plist: {ROLE} scene configured, multiple scenes on; overscanCompensation = .none")
    return 0


if __name__ == "__main__":
    sys.exit(main())

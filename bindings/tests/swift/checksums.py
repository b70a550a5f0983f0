#!/usr/bin/env python3
"""Checks that the generated Swift bindings match a built library without a Swift compiler.

Usage: checksums.py SWIFT_FILE HEADER LIBRARY

The Swift file refuses to run (fatalError) unless, at start-up, the library's uniffi contract version and
every API checksum equal the numbers written in it. This script makes the same calls through ctypes:
`ffi_<crate>_uniffi_contract_version()` against `bindings_contract_version = N`, and each
`uniffi_<crate>_checksum_...()` against the `!= N` it is compared with. The return types are read from
the generated C header (uint16_t checksums, uint32_t contract version), not assumed.
"""

import ctypes
import re
import sys

CTYPES = {"uint16_t": ctypes.c_uint16, "uint32_t": ctypes.c_uint32}


def main(swift_path: str, header_path: str, lib_path: str) -> int:
    swift = open(swift_path, encoding="utf-8").read()
    header = open(header_path, encoding="utf-8").read()
    lib = ctypes.CDLL(lib_path)

    def call(symbol: str) -> int:
        m = re.search(r"\b(\w+)\s+" + re.escape(symbol) + r"\s*\(\s*void\s*\)", header)
        if not m or m.group(1) not in CTYPES:
            raise SystemExit(f"{header_path}: no `uint16_t/uint32_t {symbol}(void)` declaration")
        fn = getattr(lib, symbol)
        fn.argtypes = []
        fn.restype = CTYPES[m.group(1)]
        return fn()

    failures = []
    m = re.search(r"let bindings_contract_version = (\d+)", swift)
    c = re.search(r"\b(ffi_\w+_uniffi_contract_version)\(\)", swift)
    if not m or not c:
        raise SystemExit(f"{swift_path}: no contract version check found (uniffi changed its Swift template?)")
    expected, got = int(m.group(1)), call(c.group(1))
    status = "ok" if got == expected else "MISMATCH"
    print(f"  {c.group(1)}() = {got}, Swift expects {expected}: {status}")
    if got != expected:
        failures.append(c.group(1))

    checks = re.findall(r"\b(uniffi_\w+_checksum_\w+)\(\)\s*!=\s*(\d+)", swift)
    if not checks:
        raise SystemExit(f"{swift_path}: no API checksum comparisons found (uniffi changed its Swift template?)")
    for symbol, number in checks:
        got = call(symbol)
        if got != int(number):
            failures.append(symbol)
            print(f"  {symbol}() = {got}, Swift expects {number}: MISMATCH")
    print(f"  {len(checks) - sum(f != c.group(1) for f in failures)}/{len(checks)} API checksums match")
    if failures:
        print(f"checksum mismatch for {failures}: the Swift file was not generated from this library", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 4:
        raise SystemExit(__doc__)
    sys.exit(main(*sys.argv[1:]))

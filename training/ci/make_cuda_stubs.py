#!/usr/bin/env python3
"""Give a CPU-only machine the CUDA libraries that PyPI's Linux torch wheel links against, as tiny stubs.

PyPI's ``torch`` wheel for Linux x86_64 is one build for CPU and CUDA: ``libtorch_cuda.so`` is a hard
(``DT_NEEDED``) dependency of ``libtorch.so``, and it needs ``libcudart``, ``libcublas``, ``libcudnn``,
``libnccl``, ... that normally come from ~2.3 GB of ``nvidia-*`` wheels. On a machine without a GPU none of
that code ever runs, so this script builds one small stub ``.so`` per missing library instead:

1. list the ``DT_NEEDED`` libraries of ``torch/lib/*.so`` that neither torch nor the system provides;
2. collect every undefined dynamic symbol of torch's libraries (``readelf --dyn-syms``); a versioned one
   (``cudaMalloc@libcudart.so.13``) belongs to the library named by its version, an unversioned one that
   no present library defines is given to every stub (duplicates are legal for the dynamic linker);
3. compile each stub with ``cc -shared`` and a version script so that versioned references resolve.

Every stub function returns 100, which is ``cudaErrorNoDevice`` / ``CUDA_ERROR_NO_DEVICE`` (and an error code
for every other CUDA library), so ``torch.cuda.is_available()`` is quietly ``False``; functions that return a
message (``*GetErrorString``, ``*GetErrorName``, ...) return a valid static string instead. Data symbols are
zero-filled 256-byte blocks.
The stubs go into ``torch/lib`` (on torch's ``$ORIGIN`` RPATH), so no environment variable is needed.

Needs ``readelf`` and ``cc`` (binutils and gcc: any machine that links Rust has them).
Usage: ``python make_cuda_stubs.py [--torch-lib DIR]``; prints what it built. Idempotent.
"""
from __future__ import annotations

import argparse
import glob
import os
import re
import subprocess
import sys
import tempfile


# Functions returning ``const char*`` messages rather than status codes.
MESSAGE = re.compile(r"(Error|Status)(String|Name)|GetString|GetLastErrorString", re.IGNORECASE)


def _readelf(*args: str) -> str:
    return subprocess.run(["readelf", "-W", *args], check=True, capture_output=True, text=True).stdout


def needed(path: str) -> list[str]:
    """``DT_NEEDED`` entries of the shared object ``path``."""
    return re.findall(r"\(NEEDED\)\s+Shared library: \[([^\]]+)\]", _readelf("-d", path))


def dyn_symbols(path: str) -> tuple[set[tuple[str, str | None, str]], set[str]]:
    """Undefined ``(name, version or None, type)`` and defined names of the dynamic symbol table."""
    undefined, defined = set(), set()
    for line in _readelf("--dyn-syms", path).splitlines():
        f = line.split()
        if len(f) < 8 or not f[0].rstrip(":").isdigit():
            continue
        kind, bind, ndx, name = f[3], f[4], f[6], f[7]
        if not name or bind == "LOCAL":
            continue
        base, _, version = name.partition("@")
        version = version.lstrip("@") or None
        if ndx == "UND":
            undefined.add((base, version, kind))
        else:
            defined.add(base)
    return undefined, defined


def version_owners(path: str) -> dict[str, str]:
    """Version-need table (``.gnu.version_r``) of ``path``: version name -> library file that must define it."""
    owners, current = {}, None
    for line in _readelf("-V", path).splitlines():
        m = re.search(r"File: (\S+)", line)
        if m:
            current = m.group(1)
            continue
        m = re.search(r"Name: (\S+)", line)
        if m and current:
            owners[m.group(1)] = current
    return owners


_LDCONFIG_CACHE: dict[str, str] | None = None
_LIB_DIRS = ("/lib/x86_64-linux-gnu", "/usr/lib/x86_64-linux-gnu", "/lib64", "/usr/lib64", "/lib", "/usr/lib",
             "/usr/local/lib")

# Only libraries of the CUDA family are stubbed; any other missing library is an error.
CUDA_FAMILY = re.compile(r"^lib(cuda|cudart|cublas|cublasLt|cudnn|cufft|cufile|curand|cusolver|cusparse|"
                         r"cusparseLt|cupti|nccl|nvrtc|nvshmem|nvJitLink|nvToolsExt|nvjpeg)[._]")


def system_library(name: str) -> str | None:
    """Path of a system library (dynamic linker cache, else the usual library folders), or None."""
    global _LDCONFIG_CACHE
    if _LDCONFIG_CACHE is None:
        _LDCONFIG_CACHE = {}
        for exe in ("ldconfig", "/sbin/ldconfig", "/usr/sbin/ldconfig"):
            try:
                out = subprocess.run([exe, "-p"], capture_output=True, text=True).stdout
            except OSError:
                continue
            for line in out.splitlines():
                parts = line.strip().split(" => ")
                if len(parts) == 2 and "x86-64" in parts[0]:
                    _LDCONFIG_CACHE.setdefault(parts[0].split(" ")[0], parts[1])
            break
    if name in _LDCONFIG_CACHE:
        return _LDCONFIG_CACHE[name]
    for d in _LIB_DIRS + tuple(os.environ.get("LD_LIBRARY_PATH", "").split(":")):
        if d and os.path.exists(os.path.join(d, name)):
            return os.path.join(d, name)
    return None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--torch-lib", help="torch/lib folder (default: found via importlib without importing)")
    ap.add_argument("--cc", default=os.environ.get("CC", "cc"))
    args = ap.parse_args()
    lib_dir = args.torch_lib
    if lib_dir is None:
        import importlib.util

        spec = importlib.util.find_spec("torch")
        if spec is None or not spec.submodule_search_locations:
            print("torch is not installed", file=sys.stderr)
            return 1
        lib_dir = os.path.join(list(spec.submodule_search_locations)[0], "lib")
    manifest = os.path.join(lib_dir, "TENSORHOLO_CUDA_STUBS.txt")
    stubs_before: set[str] = set()
    if os.path.exists(manifest):
        with open(manifest) as f:
            stubs_before = {line.split()[0] for line in f if line.strip()}
    libs = sorted(p for p in glob.glob(os.path.join(lib_dir, "*.so*")) if os.path.basename(p) not in stubs_before)
    present = {os.path.basename(p) for p in libs}
    missing: set[str] = set()
    system: dict[str, str] = {}
    for lib in libs:
        for n in needed(lib):
            if n in present or n in system or n in missing:
                continue
            path = system_library(n)
            if path:
                system[n] = path
            else:
                missing.add(n)
    if not missing:
        print("nothing to stub: every library torch needs is present")
        return 0
    foreign = sorted(m for m in missing if not CUDA_FAMILY.match(m))
    if foreign:
        print(f"torch needs libraries that are neither CUDA nor on this system: {', '.join(foreign)}",
              file=sys.stderr)
        return 1
    undefined: set[tuple[str, str | None, str]] = set()
    provided: set[str] = set()
    owners: dict[str, str] = {}
    for lib in libs:
        if os.path.basename(lib) in missing:
            continue
        u, d = dyn_symbols(lib)
        undefined |= u
        provided |= d
        owners.update(version_owners(lib))
    for path in system.values():
        provided |= dyn_symbols(path)[1]
    versioned: dict[str, dict[str, set[tuple[str, str]]]] = {m: {} for m in missing}
    loose: set[tuple[str, str]] = set()
    for name, version, kind in undefined:
        if version is None:
            if name not in provided:
                loose.add((name, kind))
            continue
        owner = owners.get(version, version)
        if owner in missing:
            versioned[owner].setdefault(version, set()).add((name, kind))
    loose = {(n, k) for n, k in loose if not n.startswith("_ZN") or "cuda" in n.lower() or "nccl" in n.lower()}
    built = []
    with tempfile.TemporaryDirectory() as tmp:
        for lib in sorted(missing):
            nodes = versioned[lib]
            symbols = {s for syms in nodes.values() for s in syms} | loose
            src = [
                "/* generated by tensorholo make_cuda_stubs.py: CPU-only stand-in, never called */",
                'static const char msg[] = "CUDA stub library (CPU-only torch install): no GPU";',
            ]
            for name, kind in sorted(symbols):
                if kind == "OBJECT" or kind == "TLS":
                    src.append(f'char {name}[256] __attribute__((aligned(64)));')
                elif MESSAGE.search(name):
                    src.append(f"const void *{name}(void) {{ return msg; }}")
                else:
                    src.append(f"long {name}(void) {{ return 100; }}")
            c_file = os.path.join(tmp, "stub.c")
            map_file = os.path.join(tmp, "stub.map")
            with open(c_file, "w") as f:
                f.write("\n".join(src) + "\n")
            with open(map_file, "w") as f:
                for node, syms in sorted(nodes.items()):
                    names = "; ".join(sorted(n for n, _ in syms))
                    f.write(f"{node} {{ global: {names}; }};\n")
                if not nodes:
                    f.write("{ global: *; };\n")
            out = os.path.join(lib_dir, lib)
            cmd = [args.cc, "-shared", "-fPIC", "-O0", "-w", "-o", out, c_file, f"-Wl,-soname,{lib}"]
            if nodes:
                cmd.append(f"-Wl,--version-script={map_file}")
            subprocess.run(cmd, check=True)
            built.append(f"{lib} ({len(symbols)} symbols)")
    with open(manifest, "w") as f:
        f.write("".join(f"{b}\n" for b in built))
    print("built CUDA stubs in", lib_dir + ":", ", ".join(built))
    return 0


if __name__ == "__main__":
    sys.exit(main())

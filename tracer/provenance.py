"""What a measurement depends on, as one key: the source of the code that measured it, the thread
count, the clock, the CPU and the library versions.

* :func:`source_digest` hashes the sources of a package (every ``.py`` file, path and bytes). The
  tracer's digest names the folder Numba caches compiled kernels in (:mod:`tracer._jit`): Numba
  only invalidates a cached function when its *own* file changes, but the kernels inline
  ``geometry.ray_triangle``, the DDA set-up and ``store_ray`` from other files, so a cache keyed by
  one file can serve stale machine code after an edit elsewhere. A folder per digest of the whole
  package sees every edit.
* :func:`measurement_key` is the key every stored measurement carries (``experiments.results``);
  a stored point whose key differs from the current one is measured again.

This module imports nothing of tracer (it runs before Numba compiles anything; :mod:`tracer._jit`
and :mod:`tracer.timing` import it).
"""
from __future__ import annotations

import functools
import hashlib
import os
import platform
import socket
from importlib import metadata
from pathlib import Path

PACKAGE_ROOT = Path(__file__).resolve().parents[1]

#: library versions that change generated code or timing
KEY_LIBRARIES = ("numpy", "numba", "llvmlite", "embreex")


def _digest_files(files) -> str:
    h = hashlib.sha256()
    for f in sorted(set(Path(p).resolve() for p in files)):
        try:
            rel = f.relative_to(PACKAGE_ROOT).as_posix()
        except ValueError:
            rel = f.name
        h.update(rel.encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()


@functools.lru_cache(maxsize=None)
def source_digest(*packages: str) -> str:
    """sha256 over every ``.py`` file under the given package folders (relative to the repository),
    paths included, so a rename counts as a change."""
    files = []
    for pkg in packages:
        base = PACKAGE_ROOT / pkg
        if base.is_file():
            files.append(base)
        else:
            files.extend(p for p in base.rglob("*.py") if "__pycache__" not in p.parts)
    return _digest_files(files)


def tracer_digest() -> str:
    """Digest of all of ``tracer/`` (every kernel, the geometry they inline, scenes, rays, timing)."""
    return source_digest("tracer")


def numba_cache_dir() -> Path:
    """Where compiled kernels are cached: ``<base>/numba/<tracer digest[:16]>``, base being
    ``$GRIDCOST_NUMBA_CACHE`` or ``$GRIDCOST_CACHE`` or ``~/.cache/gridcost``."""
    base = os.environ.get("GRIDCOST_NUMBA_CACHE")
    if base:
        root = Path(base).expanduser()
    else:
        root = Path(os.environ.get("GRIDCOST_CACHE", Path.home() / ".cache" / "gridcost")).expanduser() / "numba"
    return root / tracer_digest()[:16]


@functools.lru_cache(maxsize=None)
def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def host() -> str:
    return socket.gethostname()


@functools.lru_cache(maxsize=None)
def library_versions() -> dict:
    out = {}
    for pkg in KEY_LIBRARIES:
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = None
    return out


def measurement_key(code_paths: tuple[str, ...], threads: int, clock: str) -> dict:
    """The key of a measurement: the digest of ``tracer/`` and of ``code_paths`` (files or package
    folders relative to the repository: the experiment and cost-model code that shapes the point),
    the Numba thread count, the clock, the CPU model and :data:`KEY_LIBRARIES` versions. Hosts with
    the same CPU share points (the host is recorded per row, not keyed).
    :func:`tracer.timing.measurement_key` fills in the current threads and clock."""
    return {"code": source_digest("tracer", *sorted(code_paths))[:16], "threads": int(threads),
            "clock": clock, "cpu": cpu_model(), "versions": library_versions()}


def key_digest(key: dict) -> str:
    import json
    return hashlib.sha256(json.dumps(key, sort_keys=True, default=str).encode()).hexdigest()[:16]

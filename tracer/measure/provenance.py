"""What a measurement depends on, as one key: the source of the code that measured it, the thread
count, the clock, the CPU and the library versions.

* :func:`kernel_digest` hashes the kernel sources: every module of ``tracer/accel/`` and every
  ``tracer`` module those import, transitively (:func:`kernel_files`). Each file is hashed as its
  syntax tree with docstrings removed (:func:`code_digest`), so an edit to a comment or a docstring,
  to the registry's table or to a scene loader changes nothing, while an edit to
  ``geometry.ray_triangle`` changes the digest. The digest names the folder Numba caches compiled
  kernels in (:mod:`tracer.accel._jit`): Numba only invalidates a cached function when its *own*
  file changes, but the kernels inline ``ray_triangle``, the DDA set-up and ``store_ray`` from
  other files, so one folder per digest of everything they can inline sees every edit that matters.
* :func:`measurement_key` is the key every stored point carries (:class:`experiments.core.store.PointStore`):
  the kernel digest, the code that makes rays and times them (:data:`MEASURE_FILES`) and the
  experiment code that shapes the point; a stored point whose key differs is measured again.

This module imports nothing of tracer (it runs before Numba compiles anything; :mod:`tracer.accel._jit`
and :mod:`tracer.measure.timing` import it).
"""
from __future__ import annotations

import ast
import functools
import hashlib
import platform
import socket
from importlib import metadata
from pathlib import Path

PACKAGE_ROOT = Path(__file__).resolve().parents[2]
TRACER = PACKAGE_ROOT / "tracer"

#: library versions that change generated code or timing
KEY_LIBRARIES = ("numpy", "numba", "llvmlite", "embreex")

#: beside the kernels, what shapes a measured point: the ray sets and the timing loop
MEASURE_FILES = ("tracer/scenes/rays.py", "tracer/measure/timing.py")


def _strip_docstrings(tree: ast.AST) -> ast.AST:
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and body
                and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)):
            node.body = body[1:] or [ast.Pass()]
    return tree


def code_digest(path: Path) -> bytes:
    """sha256 of a Python file's syntax tree without docstrings (comments are not in the tree):
    what the code does, not how it is described. A file that does not parse is hashed by bytes."""
    src = Path(path).read_bytes()
    try:
        dump = ast.dump(_strip_docstrings(ast.parse(src)), include_attributes=False).encode()
    except SyntaxError:
        dump = src
    return hashlib.sha256(dump).digest()


def _module_file(name: str) -> Path | None:
    """The file of module ``tracer.x.y`` (a module or a package's ``__init__``), or None."""
    parts = name.split(".")
    if parts[0] != "tracer":
        return None
    base = PACKAGE_ROOT.joinpath(*parts)
    for f in (base.with_suffix(".py"), base / "__init__.py"):
        if f.is_file():
            return f
    return None


def _tracer_imports(path: Path) -> set[Path]:
    """The tracer modules one file imports (at any depth of the file: lazy imports count)."""
    out = set()
    try:
        tree = ast.parse(path.read_bytes())
    except SyntaxError:
        return out
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
        for n in names:
            f = _module_file(n)
            if f is not None:
                out.add(f)
                # the packages on the way (``tracer.accel`` runs its __init__)
                for k in range(2, n.count(".") + 1):
                    g = _module_file(".".join(n.split(".")[:k]))
                    if g is not None:
                        out.add(g)
    return out


@functools.lru_cache(maxsize=None)
def kernel_files() -> tuple[Path, ...]:
    """Every module of ``tracer/accel/`` and, transitively, every tracer module they import."""
    todo = [p for p in (TRACER / "accel").rglob("*.py") if "__pycache__" not in p.parts]
    seen: set[Path] = set()
    while todo:
        f = todo.pop().resolve()
        if f in seen:
            continue
        seen.add(f)
        todo.extend(_tracer_imports(f) - seen)
    return tuple(sorted(seen))


def _digest_files(files) -> str:
    h = hashlib.sha256()
    for f in sorted(set(Path(p).resolve() for p in files)):
        try:
            rel = f.relative_to(PACKAGE_ROOT).as_posix()
        except ValueError:
            rel = f.name
        h.update(rel.encode() + b"\0" + code_digest(f) + b"\0")
    return h.hexdigest()


@functools.lru_cache(maxsize=None)
def source_digest(*paths: str) -> str:
    """Digest (:func:`code_digest`, paths included so a rename counts) of every ``.py`` file under the
    given files or folders, relative to the repository."""
    files = []
    for pkg in paths:
        base = PACKAGE_ROOT / pkg
        if base.is_file():
            files.append(base)
        else:
            files.extend(p for p in base.rglob("*.py") if "__pycache__" not in p.parts)
    return _digest_files(files)


@functools.lru_cache(maxsize=None)
def kernel_digest() -> str:
    """Digest of the kernel sources (:func:`kernel_files`)."""
    return _digest_files(kernel_files())


def plugin_digest() -> str:
    """Digest of the modules of the structures registered from outside gridcost (entry points of
    :data:`tracer.accel.base.ENTRY_POINT_GROUP`), "" when there are none: a point measured with a
    registered structure is keyed by that structure's source too. Found by their import spec, not
    imported; a module whose source cannot be found is keyed by its name and the package version."""
    import importlib.util

    from tracer.accel.base import _registered
    parts, files = [], []
    for name, value in _registered():
        mod = value.partition(":")[0]
        try:
            spec = importlib.util.find_spec(mod)
        except (ImportError, ValueError):
            spec = None
        if spec is not None and spec.origin and Path(spec.origin).is_file():
            files.append(Path(spec.origin))
        else:
            parts.append(f"{name}={value}")
    if not parts and not files:
        return ""
    return hashlib.sha256((";".join(parts) + (_digest_files(files) if files else "")).encode()).hexdigest()


def numba_cache_dir() -> Path:
    """Where compiled kernels are cached: ``<base>/numba/<kernel digest[:16]>``, base being
    ``$GRIDCOST_NUMBA_CACHE`` or ``$GRIDCOST_CACHE`` or ``~/.cache/gridcost``."""
    from tracer.settings import current
    s = current()
    if s.numba_cache:
        root = Path(s.numba_cache)
    else:
        root = Path(s.cache or Path.home() / ".cache" / "gridcost") / "numba"
    return root / kernel_digest()[:16]


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


@functools.lru_cache(maxsize=None)
def host_cpu_features() -> frozenset:
    """The CPU features LLVM reports for this host that are on (``avx``, ``avx2``, ``avx512f``...);
    the flags of /proc/cpuinfo when llvmlite cannot tell, empty when neither can."""
    try:
        import llvmlite.binding as llvm
        return frozenset(k for k, on in llvm.get_host_cpu_features().items() if on)
    except Exception:
        try:
            with open("/proc/cpuinfo") as f:
                return frozenset(w for line in f if line.startswith("flags") for w in line.split(":", 1)[1].split())
        except OSError:
            return frozenset()


def bvh_width() -> int:
    """Children per node of the wide BVH (:mod:`tracer.accel.wide_bvh`) on this CPU: 8 when the host
    has AVX2 (``<8 x float>`` is one register), else 4."""
    return 8 if "avx2" in host_cpu_features() else 4


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
    """The key of a measurement: the kernel digest (and :func:`plugin_digest`), and the digest of :data:`MEASURE_FILES` and
    ``code_paths`` (files or package folders relative to the repository: the experiment and
    cost-model code that shapes the point),
    the Numba thread count, the clock, the CPU model, the wide BVH's width and :data:`KEY_LIBRARIES` versions. Hosts with
    the same CPU share points (the host is recorded per row, not keyed).
    :func:`tracer.measure.timing.measurement_key` fills in the current threads and clock."""
    code = hashlib.sha256((kernel_digest() + plugin_digest() + source_digest(*MEASURE_FILES, *sorted(code_paths))).encode())
    return {"code": code.hexdigest()[:16], "threads": int(threads),
            "clock": clock, "cpu": cpu_model(), "bvh_width": bvh_width(), "versions": library_versions()}

"""Mesh files: reading OBJ, PLY, OFF, STL, GLB/GLTF (through trimesh; optionally .gz/.xz compressed)
into a validated :class:`~tracer.scenes.scenetype.Scene`, and the parsed-mesh cache.

:func:`load_mesh` reads one file. Parsed meshes are cached as ``.npz`` keyed by the file's sha256
under the user cache :func:`cache_root` (``$GRIDCOST_CACHE``, default
``platformdirs.user_cache_dir("gridcost")``, ``~/.cache/gridcost`` on Linux), never in git. Binary
PLY triangle strips and OBJ relative face indices are decoded here (trimesh gets both wrong).
Which file a *named* mesh is read from is :mod:`tracer.scenes.registry`'s business; scene names are
:mod:`tracer.scenes.scene`'s.
"""
from __future__ import annotations

import gzip
import functools
import hashlib
import io
import logging
import re
import sys
from pathlib import Path

import numpy as np

from tracer.errors import GridcostError
from tracer.storage import atomic_savez, cache_root, load_cached_npz  # noqa: F401 (cache_root re-exported)
from tracer.scenes.scenetype import Scene, validate, zero_area

FORMATS = {".obj", ".ply", ".off", ".stl", ".glb", ".gltf"}
CACHE_VERSION = 4  # 4: float32-collapse and truncated PLY/STL refusals (a v3 entry may hold such a mesh)


def _sha256(path: Path) -> str:
    """sha256 of the file's bytes (as stored), memoized per path, size and mtime."""
    st = path.stat()
    return _sha256_of(str(path.resolve()), st.st_size, st.st_mtime_ns)


@functools.lru_cache(maxsize=256)
def _sha256_of(path: str, size: int, mtime_ns: int) -> str:
    """(size and mtime are the cache key: a changed file is hashed again)"""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _formats(path: Path) -> tuple[str, str | None]:
    """(mesh format suffix, compression suffix or None): ``x.ply`` -> (".ply", None), ``x.ply.gz`` ->
    (".ply", ".gz")."""
    suffix = path.suffix.lower()
    if suffix in (".gz", ".xz"):
        return Path(path.stem).suffix.lower(), suffix
    return suffix, None


def _decompressed(path: Path, compression: str) -> bytes:
    try:
        if compression == ".gz":
            with gzip.open(path, "rb") as f:
                return f.read()
        import lzma
        with lzma.open(path, "rb") as f:
            return f.read()
    except (OSError, EOFError, ImportError) as exc:
        raise GridcostError(f"{path}: cannot decompress ({exc})") from None


def _decode_strips(strips) -> np.ndarray:
    """Triangle strips (index lists, -1 restarts) to triangles with alternating winding; strip
    triangles with a repeated index (stitching) are dropped."""
    out = []
    for strip in strips:
        strip = np.asarray(strip).ravel()
        for run in np.split(strip, np.flatnonzero(strip < 0)):
            run = run[run >= 0]
            for i in range(len(run) - 2):
                a, b, c = run[i], run[i + 1], run[i + 2]
                if a == b or b == c or a == c:
                    continue
                out.append((a, b, c) if i % 2 == 0 else (b, a, c))
    return np.asarray(out, dtype=np.int64).reshape(-1, 3)


def _list_rows(val) -> list:
    """Rows of a PLY list property as trimesh returns it: a 2-D array or list of rows (ASCII), or a
    structured array of (count, indices) pairs (binary: fields ``f0`` count, ``f1`` the indices)."""
    if isinstance(val, np.ndarray) and val.dtype.names:
        names = val.dtype.names
        counts = np.asarray(val[names[0]]).reshape(-1)
        idx = np.asarray(val[names[-1]]).reshape(len(counts), -1)
        return [row[:int(c)] for row, c in zip(idx, counts)]
    return list(val)


def _ply_strips(mesh) -> list | None:
    """The rows of the PLY's triangle-strip element (``tristrips``), or None. trimesh gives the element's
    data as a dict of properties (ASCII) or as one structured array (binary)."""
    raw = (getattr(mesh, "metadata", None) or {}).get("_ply_raw") or {}
    for name, element in raw.items():
        if "strip" not in name.lower():
            continue
        data = element.get("data", {}) if isinstance(element, dict) else element
        if isinstance(data, dict):
            items = list(data.items())
        elif isinstance(data, np.ndarray) and data.dtype.names:
            items = [(key, data[key]) for key in data.dtype.names]
        else:
            continue
        for key, val in items:
            if "vertex" in key or "indices" in key:
                return _list_rows(val)
    return None


_OBJ_REL = re.compile(rb"^\s*f\s.*(?:^|\s)-\d", re.M)


def _obj_relative(data: bytes):
    """Vertices and fan-triangulated faces of an OBJ that uses relative indices (``f -4 -3 -2 -1``),
    each resolved at its own line. trimesh 5 resolves them against the final vertex count (or fails
    on interleaved v/f blocks), which scrambles such files, so they are read here (v and f only)."""
    verts, faces = [], []
    for line in data.splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == b"v":
            verts.append([float(x) for x in parts[1:4]])
        elif parts[0] == b"f":
            idx = []
            for ref in parts[1:]:
                i = int(ref.split(b"/")[0])
                idx.append(len(verts) + i if i < 0 else i - 1)
            faces += [(idx[0], idx[k], idx[k + 1]) for k in range(1, len(idx) - 1)]
    return np.asarray(verts, np.float64).reshape(-1, 3), np.asarray(faces, np.int64).reshape(-1, 3)


def _head(path: Path, data: bytes | None) -> tuple[bytes, int]:
    """(first 64 KiB, size) of the (decompressed) file: enough for a PLY header or an STL's counts."""
    if data is not None:
        return data[:1 << 16], len(data)
    with open(path, "rb") as f:
        return f.read(1 << 16), path.stat().st_size


def _check_stl_size(path: Path, head: bytes, size: int) -> None:
    """A binary STL is 84 + 50 n bytes (80-byte header, uint32 n, 50 bytes a triangle); trimesh reads a
    short one as an empty mesh, which would be reported as "empty", not as the truncation it is."""
    if len(head) < 84 or (head.lstrip()[:5].lower() == b"solid" and (b"facet" in head or b"endsolid" in head)):
        return  # ASCII STL (or too short to hold a count): left to trimesh
    n = int.from_bytes(head[80:84], "little")
    if size < 84 + 50 * n:
        raise GridcostError(f"{path}: truncated STL: header declares {n:,} triangles, file holds {(size - 84) // 50:,}")


def _check_ply_counts(path: Path, head: bytes, mesh) -> None:
    """trimesh accepts an ASCII PLY that stops before its header's counts (binary ones it refuses), so
    compare the header's ``element vertex/face N`` (ASCII up to end_header in every PLY) with what loaded."""
    end = head.find(b"end_header")
    declared = {}
    for line in head[:max(end, 0)].splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[0] == b"element" and parts[2].isdigit():
            declared[parts[1].decode("ascii", "replace")] = int(parts[2])
    raw = ((getattr(mesh, "metadata", None) or {}).get("_ply_raw") or {}).get("face")
    data = raw.get("data") if isinstance(raw, dict) else None
    if isinstance(data, dict) and data:
        data = next(iter(data.values()))
    faces = len(data) if data is not None else len(mesh.faces)  # rows as in the file (trimesh splits quads)
    for element, noun, held in (("vertex", "vertices", len(mesh.vertices)), ("face", "faces", faces)):
        if element in declared and held < declared[element]:
            raise GridcostError(f"{path}: truncated PLY: header declares {declared[element]:,} {noun}, "
                                f"file holds {held:,}")


def _read(path: Path):
    import trimesh
    logging.getLogger("trimesh").setLevel(logging.ERROR)
    kwargs = {"process": False}
    suffix, compression = _formats(path)
    if suffix in (".obj", ".ply"):
        kwargs["skip_materials"] = True  # geometry never needs textures (and Pillow may be absent)
    data = _decompressed(path, compression) if compression else None
    head, size = _head(path, data) if suffix in (".ply", ".stl") else (b"", 0)
    if suffix == ".stl":
        _check_stl_size(path, head, size)
    try:
        if suffix == ".obj":
            data = path.read_bytes() if data is None else data
            if _OBJ_REL.search(data):
                v, f = _obj_relative(data)
                return trimesh.Trimesh(vertices=v, faces=f, process=False)
        if compression:
            loaded = trimesh.load(io.BytesIO(data), file_type=suffix[1:], **kwargs)
        else:
            loaded = trimesh.load(str(path), **kwargs)
    except Exception as exc:  # trimesh raises many types for malformed files
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise GridcostError(f"{path}: cannot parse ({msg})") from None
    if isinstance(loaded, trimesh.Scene):
        geoms = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh)] if loaded.geometry else []
        loaded = trimesh.util.concatenate(geoms) if geoms else trimesh.Trimesh()
    if isinstance(loaded, trimesh.PointCloud):  # no faces element: keep vertices and PLY elements (strips)
        loaded = trimesh.Trimesh(vertices=np.asarray(loaded.vertices), faces=np.zeros((0, 3), np.int64),
                                 metadata=dict(loaded.metadata), process=False)
    if not isinstance(loaded, trimesh.Trimesh):
        raise GridcostError(f"{path}: holds no triangle mesh (trimesh loaded a {type(loaded).__name__})")
    if suffix == ".ply":
        _check_ply_counts(path, head, loaded)
    return loaded


def load_mesh(path, name: str | None = None, use_cache: bool = True) -> Scene:
    """Load a mesh file (OBJ, PLY, OFF, STL, GLB/GLTF; optionally .gz/.xz compressed) into a validated
    :class:`Scene`."""
    path = Path(path)
    if not path.exists():
        raise GridcostError(f"{path}: no such file")
    if path.is_dir():
        raise GridcostError(f"{path}: is a directory, not a mesh file")
    suffix, compression = _formats(path)
    if suffix not in FORMATS:
        raise GridcostError(f"{path}: unknown mesh format {suffix or '(no extension)'!r}; "
                            f"known: {', '.join(sorted(FORMATS))} (optionally .gz or .xz)")
    name = name or (Path(path.stem).stem if compression else path.stem)
    digest = _sha256(path)
    cfile = cache_root() / f"{digest[:32]}-v{CACHE_VERSION}.npz"
    z = load_cached_npz(cfile, ("tris",), f"parse of {path.name}") if use_cache else None
    if z is not None:
        report = {k[2:]: int(z[k]) for k in z if k.startswith("r_")}
        scene = Scene(z["tris"], name, str(path), report)
        _say_degenerate(path, scene)
        return scene
    mesh = _read(path)
    report = {"faces_loaded": int(len(mesh.faces)), "faces_dropped": 0, "strips_decoded": 0}
    faces = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) == 0:
        strips = _ply_strips(mesh) if suffix == ".ply" else None
        if strips:
            faces = _decode_strips(strips)
            report["strips_decoded"] = len(strips)
            if len(faces) == 0:
                raise GridcostError(f"{path}: triangle strips decode to 0 triangles")
        elif len(mesh.vertices):
            raise GridcostError(f"{path}: {len(mesh.vertices)} vertices but 0 faces "
                                f"(faces in an unsupported element, e.g. point cloud or strips)")
    verts = np.asarray(mesh.vertices, dtype=np.float64)
    if len(faces) and (faces.max() >= len(verts) or faces.min() < 0):
        raise GridcostError(f"{path}: face indices out of range (max {faces.max()}, {len(verts)} vertices)")
    t64 = verts[faces] if len(faces) else np.zeros((0, 3, 3))
    with np.errstate(over="ignore", invalid="ignore"):  # beyond float32 range -> inf, refused just below
        tris = t64.astype(np.float32)
    bad = ~np.isfinite(tris).all(axis=(1, 2))
    if np.isfinite(verts).all() and bad.any():
        raise GridcostError(f"{path}: {int(bad.sum()):,} triangles have vertices beyond float32 range "
                            f"(first: triangle {int(np.flatnonzero(bad)[0])})")
    report["collapsed_f32"] = _float32_collapse(path, t64, tris)
    report.update(validate(tris, str(path)))
    scene = Scene(tris, name, str(path), report)
    if use_cache:
        atomic_savez(cfile, tris=scene.tris, **{f"r_{k}": v for k, v in report.items()})
    _say_degenerate(path, scene)
    return scene


def _float32_collapse(path: Path, t64: np.ndarray, tris: np.ndarray) -> int:
    """How many triangles the cast to float32 makes zero-area that were not in float64. Far from the
    origin for its size a mesh is destroyed by it (at 1e7 float32 steps by 1.0): over 1 % of the
    triangles is refused, as no answer about such a mesh is about the file's; fewer are reported."""
    if not len(tris) or not np.isfinite(t64).all():
        return 0  # empty or NaN/inf: validate refuses it
    collapsed = int((zero_area(tris) & ~zero_area(t64)).sum())
    if collapsed > 0.01 * len(tris):
        v = t64.reshape(-1, 3)
        raise GridcostError(f"{path}: {collapsed:,} of {len(tris):,} triangles collapse to zero area in float32 "
                            f"(float32 precision: coordinates up to {np.abs(v).max():.3g} with a mesh extent of "
                            f"{np.ptp(v, axis=0).max():.3g}); re-centre the mesh near the origin")
    return collapsed


def _say_degenerate(path: Path, scene: Scene) -> None:
    """One stderr line when the mesh holds zero-area triangles (a mesh of nothing else was refused
    by :func:`validate`): they are kept so triangle ids stay the file's, and no ray ever hits one."""
    k = scene.report.get("degenerate", 0)
    if k:
        c = scene.report.get("collapsed_f32", 0)
        why = f"; {c:,} of them only in float32, the mesh is far from the origin for its size" if c else ""
        print(f"{path}: {k:,} of {scene.n:,} triangles are degenerate (zero area{why}); kept, so triangle ids stay "
              "the file's, and never hit", file=sys.stderr)

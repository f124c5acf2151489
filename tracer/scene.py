"""Scenes: loading meshes through trimesh, validation, the parsed-mesh cache and the named scenes
(every mesh of the registry :mod:`tracer.registry`, plus the procedural scenes of :mod:`tracer.procedural`).

A named mesh is looked for in ``--models DIR`` / ``$GRIDCOST_MODELS``, then ``../shared/models`` beside
the repository, then the meshes shipped in the package (``tracer/data``), then the user cache, then
downloaded (pooch, sha256-verified); a mesh found nowhere is replaced by a labelled stand-in (see
:mod:`tracer.registry`). Parsed meshes are cached as ``.npz`` keyed by the file's sha256 under
``$GRIDCOST_CACHE`` (default ``platformdirs.user_cache_dir("gridcost")``, ``~/.cache/gridcost`` on
Linux), never in git. Mesh files may be gzip- or xz-compressed (``.ply.gz``, ``.obj.xz``).
"""
from __future__ import annotations

import csv
import gzip
import hashlib
import io
import logging
import os
import re
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tracer.errors import GridcostError

REPO = Path(__file__).resolve().parents[1]
FORMATS = {".obj", ".ply", ".off", ".stl", ".glb", ".gltf"}
#: a flat axis is padded to this fraction of the largest extent
FLAT_PAD = 1e-3
#: every side of the bounds is pushed out by this fraction of the largest extent
BOUNDS_PAD = 1e-5
CACHE_VERSION = 3


@dataclass
class Scene:
    """Triangles ``tris`` (N, 3, 3) float32, ``bounds`` (2, 3) float32, provenance and load report.

    ``view``: an optional region of interest ``(center xyz, radius)`` that cameras frame (camera and
    path rays, :func:`tracer.rays.camera_frame`); ``None`` (the default) frames the bounding sphere of
    the whole scene. It changes neither the bounds nor random rays (those stay defined on the whole
    scene's bounding sphere). ``teapot-in-stadium`` sets it to a close-up of the teapot."""
    tris: np.ndarray
    name: str
    source: str = ""
    report: dict = field(default_factory=dict)
    bounds: np.ndarray = None
    view: tuple | None = None

    def __post_init__(self):
        self.tris = np.ascontiguousarray(self.tris, dtype=np.float32).reshape(-1, 3, 3)
        if self.bounds is None:
            self.bounds = scene_bounds(self.tris)
        if self.view is not None:
            center, radius = self.view
            center = np.asarray(center, dtype=np.float64).reshape(3)
            radius = float(radius)
            if not (np.isfinite(center).all() and np.isfinite(radius) and radius > 0):
                raise GridcostError(f"{self.name}: view must be (finite center xyz, radius > 0), got {self.view!r}")
            self.view = (center, radius)

    @property
    def n(self) -> int:
        return int(self.tris.shape[0])

    def __repr__(self) -> str:
        return f"Scene({self.name!r}, N={self.n:,}, bounds={self.bounds.tolist()})"


def scene_bounds(tris: np.ndarray) -> np.ndarray:
    """Axis-aligned bounds; an axis along which the mesh is flat is padded (FLAT_PAD of the extent)."""
    v = tris.reshape(-1, 3)
    lo = v.min(axis=0).astype(np.float64)
    hi = v.max(axis=0).astype(np.float64)
    ext = hi - lo
    pad = FLAT_PAD * max(float(ext.max()), 1e-6)
    flat = ext < pad
    lo[flat] -= pad
    hi[flat] += pad
    # pad outward (BOUNDS_PAD of the largest extent) so rays through boundary vertices/edges
    # meet the box despite rounding in the slab test
    margin = BOUNDS_PAD * max(float(ext.max()), 1e-6)
    return np.stack([lo - margin, hi + margin]).astype(np.float32)


def validate(tris: np.ndarray, where: str) -> dict:
    """Refuse empty or non-finite meshes; count (keep) zero-area triangles."""
    if tris.size == 0:
        raise GridcostError(f"{where}: mesh is empty (0 triangles)")
    bad = ~np.isfinite(tris).all(axis=(1, 2))
    if bad.any():
        raise GridcostError(f"{where}: {int(bad.sum())} triangles have NaN or inf vertices "
                            f"(first: triangle {int(np.flatnonzero(bad)[0])})")
    t = tris.astype(np.float64)
    area2 = np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
    return {"degenerate": int((area2 == 0).sum())}


# ---------------------------------------------------------------- files
def models_dir() -> Path:
    """The first models directory of the lookup: ``$GRIDCOST_MODELS`` when set, else ``../shared/models``."""
    from tracer import registry
    return registry.env_models_dir() or registry.shared_models_dir() or Path(registry.SHARED_MODELS).resolve()


def cache_dir() -> Path:
    """The user cache (``$GRIDCOST_CACHE``, else ``platformdirs.user_cache_dir("gridcost")``)."""
    from tracer import registry
    return registry.cache_root()


_FILE_HASHES: dict = {}


def _sha256(path: Path) -> str:
    """sha256 of the file's bytes (as stored), memoized per path, size and mtime."""
    st = path.stat()
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns)
    if key not in _FILE_HASHES:
        h = hashlib.sha256()
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
        _FILE_HASHES[key] = h.hexdigest()
    return _FILE_HASHES[key]


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


def _read(path: Path):
    import trimesh
    logging.getLogger("trimesh").setLevel(logging.ERROR)
    kwargs = {"process": False}
    suffix, compression = _formats(path)
    if suffix in (".obj", ".ply"):
        kwargs["skip_materials"] = True  # geometry never needs textures (and Pillow may be absent)
    data = _decompressed(path, compression) if compression else None
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
    cfile = cache_dir() / f"{digest[:32]}-v{CACHE_VERSION}.npz"
    if use_cache and cfile.exists():
        try:
            z = np.load(cfile)
            report = {k[2:]: int(z[k]) for k in z.files if k.startswith("r_")}
            return Scene(z["tris"], name, str(path), report)
        except Exception:  # a corrupt cache entry is rebuilt
            pass
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
    tris = verts[faces].astype(np.float32) if len(faces) else np.zeros((0, 3, 3), np.float32)
    if np.isfinite(verts).all() and not np.isfinite(tris).all():
        raise GridcostError(f"{path}: vertices overflow float32")
    report.update(validate(tris, str(path)))
    scene = Scene(tris, name, str(path), report)
    if use_cache:
        _atomic_savez(cfile, tris=scene.tris, **{f"r_{k}": v for k, v in report.items()})
    return scene


def _atomic_savez(path: Path, **arrays) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".npz.tmp")
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)
        os.replace(tmp, path)
    except OSError:  # a read-only cache is not an error
        pass


# ---------------------------------------------------------------- named scenes
#: short names of the meshes (the registry's names; kept for code that maps MANIFEST files to names)
ALIASES = {
    "stanford/bun_zipper_res4.ply": "bunny-948",
    "stanford/bun_zipper_res3.ply": "bunny-3851",
    "stanford/bun_zipper_res2.ply": "bunny-16k",
    "stanford/stanford-bunny.obj": "bunny-69k",
    "stanford/dragon_vrip_res4.ply": "dragon-11k",
    "stanford/dragon_vrip_res3.ply": "dragon-48k",
    "stanford/dragon_vrip_res2.ply": "dragon-202k",
    "stanford/dragon_vrip.ply": "dragon-871k",
    "mcguire/cornell-box/CornellBox-Original.obj": "cornell",
    "mcguire/cornell-box/CornellBox-Sphere.obj": "cornell-sphere",
    "mcguire/cornell-box-measured/cornell_box.obj": "cornell-measured",
    "mcguire/teapot/teapot.obj": "teapot-textured",
}


def _short_name(rel: str) -> str:
    from tracer import registry
    return (registry.BY_FILE.get(rel) or ALIASES.get(rel)
            or re.sub(r"[^a-z0-9]+", "-", Path(rel).stem.lower()).strip("-"))


def _read_manifest(models: Path) -> dict[str, dict]:
    mf = Path(models) / "MANIFEST.tsv"
    if not mf.is_file():
        return {}
    out = {}
    with open(mf, newline="") as f:
        for row in csv.DictReader(f, delimiter="\t"):
            rel = row["file"]
            out[_short_name(rel)] = dict(row, path=str(Path(models) / rel))
    return out


def manifest(models: Path | None = None) -> dict[str, dict]:
    """Short name -> MANIFEST row (columns of ``MANIFEST.tsv``, with ``path``) for every named mesh.

    Without ``models``: every mesh of the registry (``path``: the first file the lookup would use, not
    yet verified, or None when the mesh is missing; ``found``: its lookup step), plus meshes listed in
    the ``MANIFEST.tsv`` of ``$GRIDCOST_MODELS`` or ``../shared/models`` that the registry lacks. With
    ``models``: the rows of that directory's ``MANIFEST.tsv`` only."""
    if models is not None:
        return _read_manifest(Path(models))
    from tracer import registry
    out = {}
    for name, mesh in registry.MESHES.items():
        cands = registry.candidates(name)
        out[name] = dict(mesh.row(), path=str(cands[0][1]) if cands else None,
                         found=cands[0][0] if cands else None)
    for d in (registry.env_models_dir(), registry.shared_models_dir()):
        if d is not None:
            for name, row in _read_manifest(d).items():
                out.setdefault(name, dict(row, found="models" if d == registry.env_models_dir() else "shared"))
    return out


def scene_names() -> list[str]:
    from tracer import procedural
    return sorted(manifest()) + procedural.names()


def load_scene(name_or_path: str) -> Scene:
    """A named scene (registry short name, a MANIFEST name, or procedural, e.g. ``cylinder-3996``) or a
    mesh path. A registry mesh found nowhere is replaced by a labelled stand-in (see
    :func:`tracer.registry.load`; ``GRIDCOST_NO_STAND_INS=1`` makes that an error)."""
    from tracer import procedural, registry
    spec = str(name_or_path)
    if procedural.matches(spec):
        return procedural.make(spec)
    if spec in registry.MESHES:
        return registry.load(spec)
    mf = manifest()
    if spec in mf and mf[spec].get("path"):
        row = mf[spec]
        path = Path(row["path"])
        if row.get("sha256") and path.is_file():
            got = registry.content_sha256(path)
            if got != row["sha256"]:
                raise GridcostError(f"{path}: sha256 {got} does not match its MANIFEST.tsv's {row['sha256']} "
                                    f"for {spec}")
        return load_mesh(path, name=spec)
    if Path(spec).suffix or os.sep in spec:
        return load_mesh(spec)
    raise GridcostError(f"unknown scene {spec!r}; known: {', '.join(scene_names())}")

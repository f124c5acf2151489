"""The registry of every named mesh, and where each one is found.

One table (:data:`MESHES`, in :mod:`tracer.scenes.registry_data` and re-exported here) lists every named
mesh: its short name (``bunny-948`` … ``dragon-871k``, ``cornell``, ``fandisk`` …), its file name
relative to a models directory (the layout of ``shared/models``), sha256, face and vertex counts,
licence and credit line, the original public source and the exact mirrors to download it from.
This module finds, verifies, downloads and loads them (files are read by :mod:`tracer.scenes.meshfile`),
and builds stand-ins; scene names in general are :mod:`tracer.scenes.scene`'s.

A named mesh is looked for, in this order (:data:`STEPS`; the first file found is used, and it must
have the registry's sha256, else a :class:`GridcostError` names both hashes):

1. ``models``   -- ``--models DIR`` / ``$GRIDCOST_MODELS`` (``DIR/<file>``, or the bare file name in ``DIR``)
2. ``shared``   -- ``../shared/models`` beside the repository (``$GRIDCOST_SHARED_MODELS`` or
   :data:`SHARED_MODELS` moves it; an empty ``$GRIDCOST_SHARED_MODELS`` turns the step off)
3. ``vendored`` -- the small meshes shipped in the package (``tracer/data/``, see its README.md)
4. ``cache``    -- meshes downloaded before, under the user cache (:func:`cache_root`:
   ``$GRIDCOST_CACHE`` or ``platformdirs.user_cache_dir("gridcost")``, then ``models/<file>``)
5. ``download`` -- with pooch, checksum-verified, into that cache (``GRIDCOST_OFFLINE=1`` turns it off;
   after the first connection error in a process the network is not tried again)

A file may be stored compressed (``<file>.gz`` or ``<file>.xz``); its sha256 is that of the
decompressed bytes. When none of the steps has the mesh, :func:`load` builds a deterministic, labelled
stand-in of about the same number of faces (:func:`stand_in`: a smaller scan of the same object,
subdivided) and says so on stderr, unless ``GRIDCOST_NO_STAND_INS=1``, which makes it one clear error
(:func:`missing_message`). Experiments mark stand-ins with :func:`stand_in_note`.
"""
from __future__ import annotations

import functools
import gzip
import hashlib
import os
import shutil
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import unquote, urlsplit

import numpy as np

from tracer.errors import GridcostError
from tracer.scenes.meshfile import load_mesh
from tracer.settings import current, run_log
from tracer.storage import atomic_savez, cache_root, load_cached_npz
from tracer.scenes.procedural import sphere
from tracer.scenes.registry_data import (  # the table, re-exported (tracer.scenes.registry.MESHES etc.)
    Source, Mesh, STANFORD_PAGE, BUNNY_TAR, DRAGON_TAR, STANFORD_LICENCE, BUNNY_CREDIT, DRAGON_CREDIT,
    KDTREE_RT, NPM_DRAGON, NPM_DRAGON_SHA, UNPKG_DRAGON, HUGHSK_DRAGON, COMMON, COMMON_PAGE,
    COMMON_LICENCE, MCGUIRE_PAGE, MCGUIRE_CORNELL_ZIP, MCGUIRE_TEAPOT_ZIP, LFP, LFP_CORNELL_ZIP_SHA,
    LFP_TEAPOT_ZIP_SHA, MCGUIRE_LICENCE, CORNELL_CREDIT, TINYOBJ, BUNNIES, DRAGONS,
    MESHES, BY_FILE,
)
from tracer.scenes.scenetype import Scene, validate

PACKAGE = Path(__file__).resolve().parents[1]  # tracer/
REPO = PACKAGE.parent
#: meshes shipped in the package (the layout of a models directory)
VENDORED_DIR = PACKAGE / "data"
#: ``../shared/models`` beside the repository (``$GRIDCOST_SHARED_MODELS`` overrides it)
SHARED_MODELS = REPO / ".." / "shared" / "models"
#: the lookup steps, in order
STEPS = ("models", "shared", "vendored", "cache", "download")
STEP_HELP = {
    "models": "--models DIR / $GRIDCOST_MODELS",
    "shared": "../shared/models beside the repository ($GRIDCOST_SHARED_MODELS)",
    "vendored": "shipped in the package (tracer/data)",
    "cache": "downloaded before (user cache, $GRIDCOST_CACHE)",
    "download": "downloaded now (pooch, sha256-verified)",
}
COMPRESSIONS = (".gz", ".xz")
#: bump when the stand-in recipe changes (cached stand-ins are rebuilt)
STAND_IN_VERSION = 1


def get(name: str) -> Mesh:
    try:
        return MESHES[name]
    except KeyError:
        raise GridcostError(f"unknown mesh {name!r}; registered: {', '.join(MESHES)}") from None


# ---------------------------------------------------------------- places
def env_models_dir() -> Path | None:
    """``--models DIR`` or ``$GRIDCOST_MODELS`` (:attr:`tracer.settings.Settings.models`); None when unset."""
    env = current().models
    return Path(env) if env else None


def shared_models_dir() -> Path | None:
    """``../shared/models`` beside the repository (:data:`SHARED_MODELS`), or ``$GRIDCOST_SHARED_MODELS``;
    None when that variable is set but empty (the step is off)."""
    env = current().shared_models_dir
    if env is not None:
        return Path(env) if env else None
    return Path(SHARED_MODELS).resolve()


def mesh_cache_dir() -> Path:
    return cache_root() / "models"


def downloads_allowed() -> bool:
    return not current().offline


def stand_ins_allowed() -> bool:
    return current().stand_ins


def _variants(directory: Path, rel: str, flat: bool = True) -> list[Path]:
    names = [rel] + ([Path(rel).name] if flat and Path(rel).name != rel else [])
    return [directory / (n + c) for n in names for c in ("",) + COMPRESSIONS]


def places(name: str) -> list[tuple[str, Path | None, str]]:
    """``(step, directory, description)`` of the local lookup steps for ``name``, in order."""
    mesh = get(name)
    env = env_models_dir()
    shared = shared_models_dir()
    return [("models", env, f"$GRIDCOST_MODELS={env}" if env else "$GRIDCOST_MODELS (unset)"),
            ("shared", shared, "../shared/models (off: $GRIDCOST_SHARED_MODELS is empty)" if shared is None
             else str(shared) + ("" if shared.is_dir() else " (absent)")),
            ("vendored", VENDORED_DIR if mesh.vendored else None,
             f"tracer/data/{mesh.vendored}" if mesh.vendored else "tracer/data (not shipped)"),
            ("cache", mesh_cache_dir(), str(mesh_cache_dir()))]


def candidates(name: str) -> list[tuple[str, Path]]:
    """Every existing file for mesh ``name`` as ``(step, path)``, in lookup order (not yet verified)."""
    mesh = get(name)
    out = []
    for step, directory, _ in places(name):
        if directory is None:
            continue
        if step == "vendored":
            paths = [directory / mesh.vendored]
        else:
            paths = _variants(directory, mesh.file, flat=(step == "models"))
        out += [(step, p) for p in paths if p.is_file()]
    return out


# ---------------------------------------------------------------- hashing, verification
def _open(path: Path):
    suffix = path.suffix.lower()
    if suffix == ".gz":
        return gzip.open(path, "rb")
    if suffix == ".xz":
        import lzma
        return lzma.open(path, "rb")
    return open(path, "rb")


def content_sha256(path) -> str:
    """sha256 of a file's content (of the decompressed bytes for .gz/.xz); memoized per size and mtime."""
    path = Path(path)
    st = path.stat()
    return _content_sha256(str(path.resolve()), st.st_size, st.st_mtime_ns)


@functools.lru_cache(maxsize=256)
def _content_sha256(path: str, size: int, mtime_ns: int) -> str:
    """(size and mtime are the cache key: a changed file is hashed again)"""
    h = hashlib.sha256()
    try:
        with _open(Path(path)) as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    except (OSError, EOFError, ImportError) as exc:  # a broken .gz/.xz
        raise GridcostError(f"{path}: cannot read ({exc})") from None
    return h.hexdigest()


def verify(name: str, path) -> None:
    """Raise when the file at ``path`` is not mesh ``name`` (sha256 differs from the registry's)."""
    mesh = get(name)
    got = content_sha256(path)
    if got != mesh.sha256:
        raise GridcostError(f"{path}: sha256 {got} does not match the registry's {mesh.sha256} for {name} "
                            f"({mesh.file}); this is not the published mesh: replace or remove the file")


# ---------------------------------------------------------------- lookup
@dataclass
class Found:
    """Where mesh ``name`` was found: ``step`` (one of :data:`STEPS`) and ``path``; both None when it
    was not found, with ``looked`` (the places looked at) and ``download_error``."""
    name: str
    step: str | None = None
    path: Path | None = None
    looked: list[str] = field(default_factory=list)
    download_error: str | None = None

    @property
    def found(self) -> bool:
        return self.path is not None


def find(name: str, download: bool | None = None) -> Found:
    """Look for mesh ``name`` (steps in :data:`STEPS` order); a file found is verified (sha256). With
    ``download`` (default: unless ``GRIDCOST_OFFLINE=1``) a mesh found nowhere is downloaded."""
    get(name)
    for step, path in candidates(name):
        verify(name, path)
        return Found(name, step, path)
    out = Found(name, looked=[desc for _, _, desc in places(name)])
    if download is None:
        download = downloads_allowed()
    if not download:
        out.download_error = "downloads are off (GRIDCOST_OFFLINE=1)" if not downloads_allowed() else "not tried"
        return out
    try:
        out.path = fetch(name)
        out.step = "download"
    except DownloadError as exc:
        out.download_error = str(exc)
    return out


def missing_message(found: Found) -> str:
    """One line: which mesh is missing, where it was looked for, its URL(s) and the environment variable."""
    mesh = get(found.name)
    why = f"; download failed ({found.download_error})" if found.download_error else ""
    return (f"{mesh.name}: mesh {mesh.file} ({mesh.faces:,} faces, sha256 {mesh.sha256[:12]}…) not found in "
            f"{', '.join(found.looked)}{why}. Get it from {' or '.join(mesh.urls)} and put it at "
            f"$GRIDCOST_MODELS/{mesh.file} (set GRIDCOST_MODELS or pass --models DIR)"
            + ("" if stand_ins_allowed() else "; stand-ins are off (GRIDCOST_NO_STAND_INS=1)"))


# ---------------------------------------------------------------- download
class DownloadError(Exception):
    """Every source of a mesh failed (the message lists why)."""


def _file_downloader(url, output_file, pooch_obj=None, check_only=False):
    """pooch downloader for ``file://`` URLs (tests, local mirrors)."""
    src = Path(unquote(urlsplit(url).path))
    if check_only:
        return src.is_file()
    if not src.is_file():
        raise FileNotFoundError(f"no such file {src}")
    if hasattr(output_file, "write"):
        output_file.write(src.read_bytes())
    else:
        shutil.copyfile(src, output_file)
    return None


def fetch_source(source: Source, mesh: Mesh, workdir: Path) -> Path:
    """Download ``source`` with pooch into ``workdir`` (checking its sha256 when known) and return the
    file, or the archive member, that holds the mesh (possibly .gz/.xz compressed)."""
    import pooch
    pooch.get_logger().setLevel("WARNING")
    url = source.url
    tag = hashlib.sha256(url.encode()).hexdigest()[:10]
    fname = f"{tag}-{Path(urlsplit(url).path).name or 'download'}"
    processor = None
    if source.member:
        lower = fname.lower()
        processor = (pooch.Unzip(members=[source.member]) if lower.endswith(".zip")
                     else pooch.Untar(members=[source.member]))
    if urlsplit(url).scheme == "file":
        downloader = _file_downloader
    else:
        downloader = pooch.HTTPDownloader(progressbar=False, timeout=60,
                                          headers={"User-Agent": "gridcost (https://pypi.org/project/pooch/)"})
    got = pooch.retrieve(url, known_hash=f"sha256:{source.sha256}" if source.sha256 else None, fname=fname,
                         path=str(workdir), processor=processor, downloader=downloader, progressbar=False)
    if source.member:
        matches = [Path(p) for p in got if Path(p).as_posix().endswith(source.member)]
        if not matches:
            raise DownloadError(f"{url}: no member {source.member}")
        return matches[0]
    return Path(got)


def _is_connection_error(exc: Exception) -> bool:
    try:
        import requests
        return isinstance(exc, (requests.exceptions.ConnectionError, requests.exceptions.Timeout))
    except ImportError:
        return False


def fetch(name: str) -> Path:
    """Download mesh ``name`` (its sources in order) into the user cache, verified; return its path."""
    mesh = get(name)
    import importlib.util
    if importlib.util.find_spec("pooch") is None:
        raise DownloadError("pooch is not installed (pip install pooch)")
    dest = mesh_cache_dir() / mesh.file
    work = cache_root() / "downloads"
    errors = []
    down = run_log().network_down  # the first connection error of this run: the network is not tried again
    for source in mesh.sources:
        remote = urlsplit(source.url).scheme not in ("file", "")
        if remote and down:
            errors.append(f"{source.url}: not tried, the network failed before ({down[0]})")
            continue
        try:
            work.mkdir(parents=True, exist_ok=True)
            got = fetch_source(source, mesh, work)
            digest = content_sha256(got)
            if digest != mesh.sha256:
                raise DownloadError(f"sha256 {digest} of the download is not the registry's {mesh.sha256}")
            dest.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=dest.parent, suffix=".part")
            with os.fdopen(fd, "wb") as out, _open(got) as src:
                shutil.copyfileobj(src, out)
            os.replace(tmp, dest)
            return dest
        except Exception as exc:  # noqa: BLE001 - each source may fail in its own way; the next one is tried
            msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            if remote and _is_connection_error(exc):
                down.append(type(exc).__name__)
                msg = f"no connection ({type(exc).__name__})"
            errors.append(f"{source.url}: {msg[:200]}")
    raise DownloadError("; ".join(errors) or "no download source")


# ---------------------------------------------------------------- loading, stand-ins
def load(name: str):
    """Scene of mesh ``name``: the real file (``scene.report["lookup"]`` says which step found it), else
    a labelled stand-in (unless ``GRIDCOST_NO_STAND_INS=1``: then one :class:`GridcostError`)."""
    found = find(name)
    if found.found:
        scene = load_mesh(found.path, name=name)
        scene.report["lookup"] = found.step
        return scene
    if not stand_ins_allowed():
        raise GridcostError(missing_message(found))
    return stand_in(name, found.download_error)


def subdivide_to(tris: np.ndarray, target: int) -> np.ndarray:
    """Triangles ``tris`` (m, 3, 3) subdivided to exactly ``target`` faces (when target >= m): whole
    1-to-4 midpoint subdivisions while they fit, then the largest faces one more time (each adds 3;
    a stable sort makes it deterministic). The surface is unchanged: every new face lies in its parent."""
    from trimesh.remesh import subdivide
    tris = np.ascontiguousarray(tris, np.float64).reshape(-1, 3, 3)
    verts, inverse = np.unique(tris.reshape(-1, 3), axis=0, return_inverse=True)
    faces = np.asarray(inverse).reshape(-1, 3)
    while len(faces) * 4 <= target:
        verts, faces = subdivide(verts, faces)
    extra = round((target - len(faces)) / 3)
    if extra > 0:
        t = verts[faces]
        area = np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
        pick = np.sort(np.argsort(-area, kind="stable")[:extra])
        verts, faces = subdivide(verts, faces, face_index=pick)
    return verts[faces].astype(np.float32)


def _stand_in_base(mesh: Mesh):
    """(base mesh, path) to build the stand-in from: the largest real mesh of ``stand_in_from`` found
    locally (verified, no download) with at most as many faces; (None, None) for a procedural sphere."""
    best = None
    for base in mesh.stand_in_from:
        b = MESHES[base]
        if b.faces > mesh.faces or (best and best[0].faces >= b.faces):
            continue
        try:
            found = find(base, download=False)
        except GridcostError:
            continue
        if found.found:
            best = (b, found.path)
    return best or (None, None)


def stand_in(name: str, reason: str | None = None):
    """A deterministic, labelled stand-in :class:`~tracer.scenes.scenetype.Scene` for mesh ``name`` (about its number
    of faces): a smaller real mesh of the same object (:attr:`Mesh.stand_in_from`) subdivided to the face
    count (:func:`subdivide_to`), or a procedural sphere. ``scene.report["stand_in_for"]`` is ``name``,
    ``scene.source`` starts with ``"stand-in:"``; one line on stderr says so (once per run)."""
    mesh = get(name)
    base, path = _stand_in_base(mesh)
    key = f"{STAND_IN_VERSION}|{name}|{mesh.faces}|{base.sha256 if base else 'sphere'}"
    cfile = cache_root() / f"standin-{name}-{hashlib.sha256(key.encode()).hexdigest()[:20]}.npz"
    z = load_cached_npz(cfile, ("tris",), f"stand-in for {name}")
    tris = None if z is None else z["tris"]
    if tris is None:
        if base is not None:
            tris = subdivide_to(load_mesh(path, name=base.name).tris, mesh.faces)
        else:
            tris = sphere(mesh.faces)
        atomic_savez(cfile, tris=tris)
    recipe = (f"{base.name} ({base.faces:,} faces) subdivided to {len(tris):,} faces" if base is not None
              else f"procedural sphere of {len(tris):,} faces")
    report = {"stand_in_for": name, "stand_in": recipe, "faces_real": mesh.faces, "faces_loaded": len(tris),
              "lookup": "stand-in"}
    report.update(validate(tris, f"stand-in for {name}"))
    scene = Scene(tris, name, f"stand-in: {recipe} (for {name}, {mesh.faces:,} faces, not found)", report)
    log = run_log()
    log.stand_ins[name] = stand_in_note(scene)
    if name not in log.announced:
        log.announced.add(name)
        if log.network_down:
            reason = f"no connection for the download ({log.network_down[0]})"
        why = f" ({reason if len(reason) <= 100 else reason[:100] + '…'})" if reason else ""
        print(f"gridcost: {name} ({mesh.file}, {mesh.faces:,} faces) not found{why}; STAND-IN: {recipe}. "
              f"For the real mesh: {how_to_get(mesh)} (`python -m experiments.run models` lists every mesh); "
              f"GRIDCOST_NO_STAND_INS=1 makes this an error", file=sys.stderr)
    return scene


def how_to_get(mesh: Mesh) -> str:
    """One phrase: where to download mesh ``mesh`` and where to put it."""
    src = mesh.sources[0] if mesh.sources else Source(mesh.urls[0] if mesh.urls else "")
    what = f"extract {src.member} from {src.url}" if src.member else f"download {src.url}"
    return f"{what} into $GRIDCOST_MODELS/{Path(mesh.file).parent.as_posix()}/ (a .gz or .xz of it works too)"


def stand_in_note(scene) -> str | None:
    """For experiment outputs (summary.md, CSV): a short note when ``scene`` is a stand-in, else None."""
    rep = getattr(scene, "report", None) or {}
    real = rep.get("stand_in_for")
    if not real:
        return None
    return f"STAND-IN for {real} (real mesh not found): {rep.get('stand_in', scene.source)}"


# ---------------------------------------------------------------- listing
def status(name: str, verify_hash: bool = True) -> dict:
    """Where mesh ``name`` is (no download): ``{"name", "file", "faces", "found", "step", "path", "ok",
    "error", "licence", "credit", "urls", "vendored"}``; ``ok`` is False on a sha256 mismatch."""
    mesh = get(name)
    cands = candidates(name)
    out = {"name": name, "file": mesh.file, "faces": mesh.faces, "found": bool(cands), "step": None, "path": None,
           "ok": None, "error": None, "licence": mesh.licence, "credit": mesh.credit, "urls": mesh.urls,
           "vendored": mesh.vendored, "kind": mesh.kind}
    if cands:
        step, path = cands[0]
        out.update(step=step, path=str(path))
        if verify_hash:
            try:
                verify(name, path)
                out["ok"] = True
            except GridcostError as exc:
                out.update(ok=False, error=str(exc))
    else:
        base, _ = _stand_in_base(mesh)
        out["stand_in"] = (f"{base.name} subdivided to {mesh.faces:,} faces" if base is not None
                           else f"procedural sphere of about {mesh.faces:,} faces")
    return out

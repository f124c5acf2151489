"""Scenes by name: the one registry of every scene name (:func:`scene_names`) and how it loads
(:func:`load_scene`).

=========================  ===========================================  ==========================
name                       scene                                        made by
=========================  ===========================================  ==========================
``bunny-948``, ``cornell``  a named mesh of the registry's table          :mod:`tracer.scenes.registry`
                           (found in ``--models``/``$GRIDCOST_MODELS``,
                           ``../shared/models``, ``tracer/data``, the
                           user cache, downloaded, or a labelled
                           stand-in)
a ``MANIFEST.tsv`` name    a mesh listed in the models directory's       :mod:`tracer.scenes.meshfile`
                           MANIFEST that the registry lacks
``cylinder-196``, ``room``  procedural scenes                             :mod:`tracer.scenes.procedural`
``sphereflake-2``,         Haines' Standard Procedural Databases         :mod:`tracer.scenes.spd`
``tetra-5``                (``sphereflake``, ``tetra``, ``gears``,
                           ``tree``)
``fandisk-x4``,            derived from another scene by name:           :mod:`tracer.scenes.derived`
``teapot-x4-in-stadium``,  subdivided, in a stadium, k copies in a
``array-24-60-bunny-69k``, lattice, far from the origin, at an extreme
``dragon-11k-far1e5``,     scale
``dragon-11k-size1e-4``
``path/to/mesh.ply``       any mesh file (OBJ, PLY, OFF, STL, GLB/GLTF,  :mod:`tracer.scenes.meshfile`
                           optionally .gz/.xz)
=========================  ===========================================  ==========================

Every loader builds a :class:`~tracer.scenes.scenetype.Scene`; this module sits above all of them and none
imports it back. For existing code it re-exports ``Scene``, ``scene_bounds``, ``validate``
(:mod:`tracer.scenes.scenetype`) and ``load_mesh``, ``cache_dir`` (:mod:`tracer.scenes.meshfile`).
"""
from __future__ import annotations

import csv
import os
import re
from pathlib import Path

from tracer.scenes import derived, procedural, registry, spd
from tracer.errors import GridcostError
from tracer.scenes.meshfile import FORMATS, _decode_strips, load_mesh  # noqa: F401 (re-exports)
from tracer.storage import cache_root as cache_dir  # noqa: F401 (re-export)
from tracer.scenes.scenetype import BOUNDS_PAD, FLAT_PAD, Scene, scene_bounds, validate  # noqa: F401 (re-exports)

REPO = Path(__file__).resolve().parents[2]


def models_dir() -> Path:
    """The first models directory of the lookup: ``$GRIDCOST_MODELS`` when set, else ``../shared/models``."""
    return registry.env_models_dir() or registry.shared_models_dir() or Path(registry.SHARED_MODELS).resolve()


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
    """Every scene name: the named meshes (registry and MANIFEST), the procedural examples and the
    SPD scenes."""
    return sorted(manifest()) + procedural.names() + spd.names()


def _named_mesh(name: str) -> Scene | None:
    """A named mesh for a procedural scene built around one (``teapot-in-stadium``), None when the
    name is unknown."""
    return load_scene(name) if name in manifest() else None


def load_scene(name_or_path: str) -> Scene:
    """A named scene (see the table above: a registry or MANIFEST mesh, procedural, e.g.
    ``cylinder-3996``, or SPD, e.g. ``sphereflake-2``) or a mesh path. A registry mesh found nowhere
    is replaced by a labelled stand-in (see :func:`tracer.scenes.registry.load`; ``GRIDCOST_NO_STAND_INS=1``
    makes that an error)."""
    spec = str(name_or_path)
    if derived.matches(spec) and not Path(spec).suffix:
        return derived.make(spec, load_scene)
    if procedural.matches(spec):
        return procedural.make(spec, mesh=_named_mesh)
    if spd.matches(spec):
        return spd.spd_scene(spec)
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

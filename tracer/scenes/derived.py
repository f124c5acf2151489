"""Scenes derived by name from another scene (deterministic, built in code).

==============================  ==============================================================
``<scene>-x4`` / ``-x16``       ``<scene>`` midpoint-subdivided once / twice (:func:`subdivide`): 4x /
                                16x the triangles on the same surface, so a family keeps its shape and
                                its spread of triangle sizes while N grows (``fandisk-x16``)
``<scene>-in-stadium``          ``<scene>`` inside the stadium of ``teapot-in-stadium`` (a subdivided
                                box 200x its size), viewed close up (``teapot-x4-in-stadium``)
``array-<k>-<gap>-<scene>``     k copies of ``<scene>`` on a cubic lattice (ceil(k^(1/3)) a side), each
                                turned by a seeded random rotation about its centre, centres ``1 +
                                gap/100`` times the copy's size apart. The gap sets how much empty
                                space separates the copies, so N (k copies) and Havran's sigma (the
                                spread of references per grid cell, which grows with the empty space)
                                can be matched to a scene of another paper (``array-24-60-bunny-69k``)
``<scene>-far<d>``              ``<scene>`` at unit size (largest extent 1, minimum corner at the
                                origin) moved by ``d`` on every axis (``dragon-11k-far1e5``: float32
                                coordinates 1/128 apart there, rays often lie in the vertices' planes)
``<scene>-size<s>``             ``<scene>`` at largest extent ``s`` with its minimum corner at the
                                origin (``dragon-11k-size1e-4``, ``dragon-11k-size1e4``: extreme scales)
==============================  ==============================================================

``<scene>`` is any scene name :func:`tracer.scenes.scene.load_scene` knows (itself possibly derived). The
loader of base scenes is passed in (``make(spec, load)``), so this module never imports the scene
registry back; a Dask worker rebuilds a derived scene from its name alone.
"""
from __future__ import annotations

import math
import re
from typing import Callable

import numpy as np

from tracer.errors import GridcostError
from tracer.scenes.scenetype import Scene

SUBDIVIDED = re.compile(r"^(?P<base>.+?)-x(?P<k>4|16)$")
STADIUM = re.compile(r"^(?P<base>.+)-in-stadium$")
ARRAY = re.compile(r"^array-(?P<k>\d+)-(?P<gap>\d+)-(?P<base>.+)$")
PLACED = re.compile(r"^(?P<base>.+)-(?P<op>far|size)(?P<v>\d+(?:e[+-]?\d+)?)$")
#: scenes this module builds for itself elsewhere (procedural's own teapot-in-stadium)
NOT_DERIVED = ("teapot-in-stadium",)


def matches(spec: str) -> bool:
    return spec not in NOT_DERIVED and any(p.match(spec) for p in (ARRAY, STADIUM, SUBDIVIDED, PLACED))


def subdivide(tris: np.ndarray, times: int = 1) -> np.ndarray:
    """Midpoint subdivision, each triangle into 4 (``times`` times): N -> 4^times N, same surface."""
    t = np.asarray(tris, np.float64)
    for _ in range(times):
        a, b, c = t[:, 0], t[:, 1], t[:, 2]
        ab, bc, ca = (a + b) / 2, (b + c) / 2, (c + a) / 2
        t = np.stack([np.stack(v, 1) for v in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))], 1).reshape(-1, 3, 3)
    return t.astype(np.float32)


def _rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random rotation matrix (QR of a Gaussian matrix, sign-fixed, det +1)."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def array(tris: np.ndarray, k: int, gap: float, seed: int = 7) -> np.ndarray:
    """k copies of ``tris`` on a cubic lattice of side ceil(k^(1/3)), filled in x, y, z order; copy i
    is turned about its centre by a seeded random rotation and its centre sits at ``(1 + gap)·size``
    times its lattice index (size: the diameter of the copy's bounding sphere, so turned copies never
    overlap)."""
    if k < 1:
        raise GridcostError(f"an array needs k >= 1 copies, got {k}")
    t = np.asarray(tris, np.float64)
    v = t.reshape(-1, 3)
    c = (v.min(0) + v.max(0)) / 2
    size = 2.0 * float(np.linalg.norm(v - c, axis=1).max())
    side = max(1, math.ceil(round(k ** (1 / 3), 9)))
    rng = np.random.default_rng(seed)
    out = []
    for i in range(k):
        ijk = np.array([i % side, (i // side) % side, i // (side * side)], np.float64)
        out.append((t - c) @ _rotation(rng).T + ijk * (1.0 + gap) * size)
    return np.concatenate(out).astype(np.float32)


def placed(tris: np.ndarray, scale: float = 1.0, shift: float = 0.0) -> np.ndarray:
    """``tris`` normalised to unit size (largest extent 1, minimum corner at the origin), scaled by
    ``scale`` and moved by ``shift`` on every axis, in float64, rounded once to float32."""
    v = np.asarray(tris, np.float64)
    lo = v.reshape(-1, 3).min(axis=0)
    ext = float((v.reshape(-1, 3).max(axis=0) - lo).max()) or 1.0
    out = ((v - lo) / ext * scale + shift).astype(np.float32)
    if not np.isfinite(out).all():
        raise GridcostError(f"scale {scale:g} and shift {shift:g} take the mesh beyond float32")
    return out


def make(spec: str, load: Callable[[str], Scene]) -> Scene:
    """The derived scene ``spec``; ``load(name)`` loads its base scene."""
    from tracer.scenes.procedural import in_stadium
    m = ARRAY.match(spec)
    if m:
        base = load(m["base"])
        return Scene(array(base.tris, int(m["k"]), int(m["gap"]) / 100.0), spec, "derived",
                     report={"base": base.name, "copies": int(m["k"]), "gap": int(m["gap"]) / 100.0})
    m = STADIUM.match(spec)
    if m and spec not in NOT_DERIVED:
        base = load(m["base"])
        tris, n_pot, view = in_stadium(base.tris)
        return Scene(tris, spec, "derived", report={"base": base.name, "teapot_triangles": n_pot}, view=view)
    m = PLACED.match(spec)
    if m:
        base = load(m["base"])
        v = float(m["v"])
        scale, shift = (1.0, v) if m["op"] == "far" else (v, 0.0)
        if not (scale > 0.0 and math.isfinite(scale) and math.isfinite(shift)):
            raise GridcostError(f"{spec!r}: the size must be a positive number")
        return Scene(placed(base.tris, scale, shift), spec, "derived",
                     report={"base": base.name, "scale": scale, "shift": shift})
    m = SUBDIVIDED.match(spec)
    if m:
        base = load(m["base"])
        return Scene(subdivide(base.tris, {"4": 1, "16": 2}[m["k"]]), spec, "derived", report={"base": base.name})
    raise GridcostError(f"{spec!r} is not a derived scene name (<scene>-x4, <scene>-x16, <scene>-in-stadium, "
                        f"array-<k>-<gap>-<scene>, <scene>-far<d>, <scene>-size<s>)")

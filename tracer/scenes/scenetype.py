"""The scene type every loader and generator returns: :class:`Scene` (triangles, bounds, provenance,
load report, optional view), with :func:`scene_bounds` and :func:`validate`.

This module imports nothing of ``tracer`` but its errors: mesh files (:mod:`tracer.scenes.meshfile`), the
mesh registry (:mod:`tracer.scenes.registry`), procedural (:mod:`tracer.scenes.procedural`) and SPD
(:mod:`tracer.scenes.spd`) scenes all build a :class:`Scene` from here, and :mod:`tracer.scenes.scene` (the one
registry of scene names, which re-exports this module's names) sits above them all.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from tracer.errors import GridcostError

#: a flat axis is padded to this fraction of the largest extent
FLAT_PAD = 1e-3
#: every side of the bounds is pushed out by this fraction of the largest extent
BOUNDS_PAD = 1e-5
#: triangles per block of :attr:`Scene.axis_sums` (its float64 copy of a large mesh stays small)
SUM_BLOCK = 1 << 13


@dataclass
class Scene:
    """Triangles ``tris`` (N, 3, 3) float32, ``bounds`` (2, 3) float32, provenance and load report.

    ``view``: an optional region of interest ``(center xyz, radius)`` that cameras frame (camera and
    path rays, :func:`tracer.scenes.rays.camera_frame`); ``None`` (the default) frames the bounding sphere of
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

    @functools.cached_property
    def axis_sums(self) -> tuple[np.ndarray, np.ndarray]:
        """``(P, E)``: per axis, summed over the triangles (float64), the absolute component of the
        edge cross product (twice the area projected on the plane normal to that axis) and the
        extent. Both scale with the cell size component by component, so a grid's expected
        references at any resolution follow from these six numbers
        (:func:`tracer.measure.footprint.expected_refs`); computed once per scene."""
        p, e = np.zeros(3), np.zeros(3)
        for s in range(0, self.n, SUM_BLOCK):
            t = self.tris[s:s + SUM_BLOCK].astype(np.float64)
            p += np.abs(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])).sum(axis=0)
            e += (t.max(axis=1) - t.min(axis=1)).sum(axis=0)
        return p, e

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
    box = np.stack([lo - margin, hi + margin]).astype(np.float32)
    # far from the origin the float32 spacing exceeds both pads and rounding to nearest loses them
    # (a flat mesh at z = 1e5 got a box of zero thickness); then step one float32 outward, so the
    # box always holds every vertex strictly inside
    vlo, vhi = v.min(axis=0), v.max(axis=0)
    box[0] = np.where(box[0] < vlo, box[0], np.nextafter(np.minimum(box[0], vlo), np.float32(-np.inf)))
    box[1] = np.where(box[1] > vhi, box[1], np.nextafter(np.maximum(box[1], vhi), np.float32(np.inf)))
    return box


def zero_area(tris: np.ndarray) -> np.ndarray:
    """Which triangles of ``tris`` (n, 3, 3) have zero area, computed in float64."""
    t = tris.astype(np.float64, copy=False)
    return np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1) == 0


def validate(tris: np.ndarray, where: str) -> dict:
    """Refuse empty, non-finite and all-degenerate meshes; count (keep) zero-area triangles."""
    if tris.size == 0:
        raise GridcostError(f"{where}: mesh is empty (0 triangles)")
    bad = ~np.isfinite(tris).all(axis=(1, 2))
    if bad.any():
        raise GridcostError(f"{where}: {int(bad.sum())} triangles have NaN or inf vertices "
                            f"(first: triangle {int(np.flatnonzero(bad)[0])})")
    degenerate = int(zero_area(tris).sum())
    if degenerate == len(tris):
        raise GridcostError(f"{where}: all {degenerate:,} triangles are degenerate (zero area: collinear or repeated "
                            "vertices); no ray can hit this mesh")
    # kept, not dropped: triangle ids stay the file's, and a zero-area triangle is never hit (it costs
    # a test when a ray meets its cells); the count travels in the load report
    return {"degenerate": degenerate}

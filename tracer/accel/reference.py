"""External reference tracers behind the same interface: Embree (``embreex``, optional extra
``gridcost[embree]``), trimesh's pure-Python/numpy ``ray_triangle`` and VTK's uniform-grid
``vtkStaticCellLocator`` (optional extra ``gridcost[vtk]``). No counters: gridcost did not write
them, which is what they are for (Embree: the speed anchor; VTK: a grid whose timings
``fit --timings`` is validated on)."""
from __future__ import annotations

import importlib
import time

import numpy as np

from tracer.accel import Accel
from tracer.errors import GridcostError


def _importable(module: str) -> bool:
    """Whether ``module`` imports (an optional extra is installed)."""
    try:
        importlib.import_module(module)
        return True
    except ImportError:
        return False


class EmbreeAccel(Accel):
    """Embree 4 BVH through embreex's raw API (float32, single-ray ``rtcIntersect1`` loop; embreex
    runs it on one thread). ``robust`` selects RTC_SCENE_FLAG_ROBUST."""

    name = "embree"

    def __init__(self, robust: bool = False):
        self.robust = robust

    @staticmethod
    def available() -> bool:
        return _importable("embreex.rtcore_scene")

    def build(self, scene):
        try:
            import embreex.rtcore as rtc
            import embreex.rtcore_scene as rtcs
            from embreex.mesh_construction import TriangleMesh
        except ImportError:
            raise GridcostError("Embree is not installed: pip install 'gridcost[embree]' (embreex)") from None
        t0 = time.perf_counter()
        self.device_ = rtc.EmbreeDevice()
        self.scene_ = rtcs.EmbreeScene(self.device_, robust=self.robust)
        self.mesh_ = TriangleMesh(self.scene_, scene.tris)
        # Embree builds lazily on the first query: force it with one ray
        self.scene_.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))
        self.build_seconds_ = time.perf_counter() - t0
        self.n_ = scene.n
        return self

    def _trace(self, o, d, tmin, tmax, anyhit, count):
        dists = None if np.isinf(tmax).all() else np.minimum(tmax, 1e37).astype(np.float32)
        if anyhit:
            occ = self.scene_.run(o, d, dists=dists, query="OCCLUDED")
            ids = np.where(np.asarray(occ) == 0, 0, -1).astype(np.int32)  # embreex: 0 = occluded, -1 = free
            return np.full(len(o), np.inf, np.float32), ids, None
        res = self.scene_.run(o, d, dists=dists, output=1)
        ids = res["primID"].astype(np.int32)
        t = np.where(ids >= 0, res["tfar"], np.inf).astype(np.float32)
        return t, ids, None

    def stats(self) -> dict:
        return {"structure": "embree", "build_s": self.build_seconds_, "robust": self.robust}


class TrimeshAccel(Accel):
    """trimesh.ray.ray_triangle.RayMeshIntersector (numpy, no spatial index beyond an rtree)."""

    name = "trimesh"

    @staticmethod
    def available() -> bool:
        """trimesh's ray tracer needs rtree."""
        return _importable("rtree")

    def build(self, scene):
        import trimesh
        from trimesh.ray.ray_triangle import RayMeshIntersector
        t0 = time.perf_counter()
        mesh = trimesh.Trimesh(vertices=scene.tris.reshape(-1, 3).astype(np.float64),
                               faces=np.arange(3 * scene.n).reshape(-1, 3), process=False)
        self.ray_ = RayMeshIntersector(mesh)
        self.mesh_ = mesh
        self.build_seconds_ = time.perf_counter() - t0
        return self

    def _trace(self, o, d, tmin, tmax, anyhit, count):
        ids = self.ray_.intersects_first(o.astype(np.float64), d.astype(np.float64)).astype(np.int32)
        return np.full(len(o), np.nan, np.float32), ids, None

    def stats(self) -> dict:
        return {"structure": "trimesh", "build_s": self.build_seconds_}


class VtkGridLocator(Accel):
    """VTK's ``vtkStaticCellLocator``: a uniform grid of ``divisions`` (nx, ny, nz) bins, each cell
    (triangle) binned by its bounding box, traced by ``IntersectWithLine`` one ray at a time (VTK has
    no batched ray query; a segment from the origin to ``reach`` x the scene diagonal along the ray).
    Its time per ray includes the Python call (about a microsecond), a constant per ray that a
    fitted Tsetup absorbs."""

    name = "vtk-grid"

    def __init__(self, divisions=(10, 10, 10), reach: float = 4.0):
        self.divisions = tuple(int(v) for v in divisions)
        if len(self.divisions) != 3 or min(self.divisions) < 1:
            raise GridcostError(f"VTK divisions must be three positive integers, got {divisions!r}")
        self.reach = float(reach)

    @staticmethod
    def available() -> bool:
        return _importable("vtkmodules.vtkCommonDataModel")

    def build(self, scene):
        try:
            from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray
            from vtkmodules.vtkCommonCore import vtkPoints
            from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData, vtkStaticCellLocator
        except ImportError:
            raise GridcostError("VTK is not installed: pip install 'gridcost[vtk]'") from None
        n = scene.n
        pts = vtkPoints()
        pts.SetData(numpy_to_vtk(scene.tris.reshape(-1, 3).astype(np.float64), deep=True))
        cells = vtkCellArray()
        cells.SetData(numpy_to_vtkIdTypeArray(np.arange(0, 3 * n + 1, 3, dtype=np.int64), deep=True),
                      numpy_to_vtkIdTypeArray(np.arange(3 * n, dtype=np.int64), deep=True))
        self.poly_ = vtkPolyData()
        self.poly_.SetPoints(pts)
        self.poly_.SetPolys(cells)
        t0 = time.perf_counter()
        loc = vtkStaticCellLocator()
        loc.SetDataSet(self.poly_)
        loc.AutomaticOff()
        loc.SetDivisions(*self.divisions)
        loc.BuildLocator()
        self.build_seconds_ = time.perf_counter() - t0
        self.locator_ = loc
        self.length_ = self.reach * max(float(np.linalg.norm(scene.bounds[1] - scene.bounds[0])), 1e-30)
        self.n_ = n
        return self

    def _trace(self, o, d, tmin, tmax, anyhit, count):
        from vtkmodules.vtkCommonCore import reference
        t_, sub, cid = reference(0.0), reference(0), reference(0)
        x, pc = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
        O = o.astype(np.float64) + tmin * d.astype(np.float64)
        P2 = o.astype(np.float64) + d.astype(np.float64) * np.minimum(tmax.astype(np.float64), self.length_)[:, None]
        span = np.linalg.norm(P2 - O, axis=1) / np.maximum(np.linalg.norm(d.astype(np.float64), axis=1), 1e-300)
        out_t = np.full(len(o), np.inf, np.float32)
        out_id = np.full(len(o), -1, np.int32)
        hit = self.locator_.IntersectWithLine
        for i in range(len(o)):
            if hit(O[i], P2[i], 0.0, t_, x, pc, sub, cid):
                out_id[i] = cid.get()
                out_t[i] = tmin + t_.get() * span[i]
        return out_t, out_id, None

    def stats(self) -> dict:
        return {"structure": "vtk-grid", "build_s": self.build_seconds_, "divisions": list(self.divisions),
                "cells": int(np.prod(self.divisions))}

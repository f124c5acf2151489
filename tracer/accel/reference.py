"""External reference tracers behind the same interface: Embree (``embreex``, optional extra
``gridcost[embree]``) and trimesh's pure-Python/numpy ``ray_triangle``. No counters."""
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

"""gridcost tracer: scenes, ray sets, acceleration structures (Numba), the float64 oracle, timing.

The one interface every structure implements (pbrt-v2 style)::

    from tracer import load_scene, build
    scene = load_scene("bunny-69k")
    accel = build(scene, "grid", cells=8 * scene.n)
    hits, counters = accel.intersect(origins, directions)   # t, tri_id (-1 = miss)
    occluded = accel.occluded(origins, directions, tmax)
    accel.stats()
"""
from tracer.errors import GridcostError
from tracer.scene import Scene, load_scene, scene_names
from tracer.accel import build, Hits, STRUCTURES

__all__ = ["GridcostError", "Scene", "load_scene", "scene_names", "build", "Hits", "STRUCTURES"]

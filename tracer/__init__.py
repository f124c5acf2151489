"""gridcost tracer: scenes, ray sets, acceleration structures (Numba), the float64 oracle, timing.

The one interface every structure implements (pbrt-v2 style)::

    from tracer import load_scene, build
    scene = load_scene("bunny-69k")
    accel = build(scene, "grid", cells=8 * scene.n)
    hits, counters = accel.intersect(origins, directions)   # t, tri_id (-1 = miss)
    occluded = accel.occluded(origins, directions, tmax)
    accel.stats()

Where things are (each module's docstring says more):

=========================  ==================================================================
scenes                     ``scene`` (every scene name -> its loader: :func:`load_scene`,
                           :func:`scene_names`), ``scenetype`` (:class:`Scene`), ``meshfile``
                           (reading mesh files, parsed-mesh cache), ``registry`` (named meshes:
                           lookup, download, stand-ins) + ``registry_data`` (their table),
                           ``procedural``, ``spd`` (generated scenes)
rays                       ``rays`` (random, camera, path, adversarial ray sets)
structures                 ``accel`` (the interface, :func:`build`), ``grid``, ``nested``,
                           ``packet`` + ``packet_kernels`` (coherent grid traversal),
                           ``kdtree`` + ``kdtree_build``, ``bvh``, ``sortedlists``,
                           ``reference`` (Embree)
shared kernels             ``geometry`` (ray/triangle, ray/box, triangle/box, the 3D-DDA:
                           set-up, cursor, step), ``_jit`` (the Numba decorator)
checking and measuring     ``oracle`` (float64 brute force), ``timing``, ``provenance``,
                           ``memory`` (build-size guard)
constants, errors          ``constants``, ``errors``
=========================  ==================================================================
"""
from tracer.errors import GridcostError
from tracer.scene import Scene, load_scene, scene_names
from tracer.accel import build, Hits, STRUCTURES

__all__ = ["GridcostError", "Scene", "load_scene", "scene_names", "build", "Hits", "STRUCTURES"]

"""gridcost tracer: scenes, ray sets, acceleration structures (Numba), the float64 oracle, timing.

The one interface every structure implements (pbrt style)::

    from tracer import load_scene, build, make_rays
    scene = load_scene("bunny-69k")
    accel = build(scene, "grid", cells=8 * scene.n)
    rays = make_rays(scene, "random", 10_000, seed=0)
    hits, counters = accel.intersect(rays.origins, rays.directions)   # t, tri_id (-1 = miss)
    occluded = accel.occluded(rays.origins, rays.directions, tmax=1.0)
    accel.stats()

Three rooms; imports point ``accel -> scenes (the Scene type), measure`` and never back.

``tracer/accel/`` -- structures and the kernels they share (hashed into the Numba cache and the
measurement key):

=====================  =======================================================================
``base``               the interface: :class:`Accel`, :func:`build`, :class:`Hits`,
                       :class:`Counters` and the counter schema
``_jit``               the one Numba decorator set-up, the ray block, ``store_ray``
``geometry``           ray/triangle, ray/box, triangle/box, the 3D-DDA (set-up, cursor, step)
``simd``               LLVM vector intrinsics (4-lane slab test)
``constants``          the build constants taken from papers and pbrt, each with its source
``oracle``             the float64 brute-force oracle
``grid``               uniform grid (exact/bbox assignment, mailbox, macrocells, layouts)
``nested``             nested (two- and more-level) grids
``kdtree``             SAH kd-tree traversal; ``kdtree_build`` (event SAH build),
                       ``kdtree_clip`` (split-clipping build)
``bvh``, ``bvh4``      binary SAH BVH, 4-wide BVH
``packet``             coherent grid traversal (Wald 2006); ``packet_kernels`` its helpers
``sortedlists``        Fournier & Poulin's hierarchy of sorted lists
``reference``          Embree and trimesh behind the same interface (no counters)
=====================  =======================================================================

``tracer/scenes/`` -- scenes and rays (never imports ``accel``):

=====================  =======================================================================
``scene``              every scene name -> its loader: :func:`load_scene`, :func:`scene_names`
``scenetype``          the :class:`Scene` type and its validation
``meshfile``           reading mesh files with trimesh, the parsed-mesh cache
``registry``           named meshes: lookup, download, stand-ins; ``registry_data`` their table
``procedural``         generated scenes (cylinders, particles, rooms, ...)
``spd``                Haines' Standard Procedural Databases
``derived``            scenes derived by name from another (subdivided, in a stadium, arrays)
``rays``               seeded ray sets: random, camera, path, adversarial (:func:`make_rays`)
=====================  =======================================================================

``tracer/measure/`` -- measuring:

=====================  =======================================================================
``timing``             the one timing module: warm-up, repeats, medians, paired rounds, clocks
``machine``            the machine probe (cache sizes, dependent-load latency)
``memory``             memory budgets and working-set estimates (the build guard)
``provenance``         what a measurement depends on: the kernel digest, the measurement key
=====================  =======================================================================

``tracer/errors`` holds :class:`GridcostError` (bad input: one line, exit 2).
"""
from tracer.errors import GridcostError
from tracer.scenes.scene import Scene, load_scene, scene_names
from tracer.scenes.rays import make_rays
from tracer.accel import build, Hits, STRUCTURES

__all__ = ["GridcostError", "Scene", "load_scene", "scene_names", "make_rays", "build", "Hits", "STRUCTURES"]

"""Peak memory of a structure's build, estimated before anything is allocated.

:func:`check_structure` is called by :func:`tracer.accel.base.build` for every structure, just
before ``inst.build(scene)``: the estimate of :func:`estimate` against :func:`memory_budget`, one
:class:`GridcostError` line when over. Structures need no edit; a registered (plug-in) structure may
declare ``estimate_bytes(scene) -> int`` (a method or classmethod of its :class:`Accel` subclass),
else it gets the conservative :data:`GENERIC_BYTES_PER_TRI`.

Each estimate is an inventory of the arrays the build holds at its peak:

* grids (``grid``, ``cgt``, each level of ``nested``): bytes per cell and per triangle reference,
  the references predicted from the geometry (:func:`expected_refs`: the mean number of cells of
  size h that a triangle overlaps in a grid laid at random over it is the volume of the triangle
  swept by an h-cube, sum(projected areas) / h^2 + sum(extents) / h + 1, exact in expectation for
  flat convex pieces);
* hierarchies (``bvh``, ``bvh4``, ``wbvh``, ``sortedlists``, ``kdtree``): node counts are bounded by the
  faces (a BVH leaf holds >= 1 triangle, the sorted lists' slots are N + nodes), so their peak is
  bytes per triangle; the kd-tree's sorted-edge work area (3 axes x 8N x 8 B) and its reference
  duplication (1-19 references per triangle on the meshes measured) are folded into one figure,
  and since no cheap figure predicts that duplication the edge build also stops itself when what
  it holds outgrows the budget.

The per-triangle figures are tracemalloc peaks of the builds (numpy and Numba allocations are both
traced) over bunny-948, bunny-69k, sphere-100k and particles-50k; tests/test_memory_guards.py keeps
every estimate within 1.5x of the measured peak.
"""
from __future__ import annotations

import math

import numpy as np

from tracer.errors import GridcostError
from tracer.measure.memory import fmt_bytes, memory_budget

#: bytes per cell (int32 start + occupancy bit) and per reference (int32 id + 9 float32 vertices in
#: cell order) of a grid build; macrocells add an int32 diff and two bool masks per cell
GRID_BYTES_PER_CELL = 4 + 1 / 8
GRID_BYTES_PER_REF_ID = 4
TRI_ROW_BYTES = 9 * 4
GRID_MACRO_BYTES_PER_CELL = 4 + 1 + 1
#: the packet grid then copies each triangle's row into one 64-byte row with its grid-space box
#: (the kernels' tracer.accel.packet_kernels.ROW float32 are read from here), while the scene's
#: 36-byte rows still exist
CGT_ROW_BYTES = 16 * 4
#: one nested level's peak per cell and per reference (the counts of tracer.accel.nested's own guard)
NESTED_BYTES_PER_CELL = 44
NESTED_BYTES_PER_REF = 82
#: the bytes a nested grid keeps per cell (int32 pair) and per leaf reference (id)
NESTED_KEPT_PER_CELL = 8
NESTED_KEPT_PER_REF = 4
#: tracemalloc peak per triangle of the hierarchies' builds (see the module docstring):
#: measured 279-288 (bvh), 367-420 (bvh4), 264-267 (sortedlists), 333-2797 (kdtree: particles-50k to
#: sphere-100k; 150 B per reference plus 157 B per triangle, with 1.2 to 18.6 references per triangle
#: and leaves stored as blocks of four), 269-710 (kdtree clip=True)
BVH_BYTES_PER_TRI = 285
BVH4_BYTES_PER_TRI = 395
SORTEDLISTS_BYTES_PER_TRI = 266
#: the wide BVH (binary SAH build collapsed, leaves of up to eight in blocks of four): 264-284 on
#: bunny-16k, dragon-48k, fandisk-x4, particles-20000 (338-351 with leaves of up to four)
WBVH_BYTES_PER_TRI = 280
KDTREE_BYTES_PER_TRI = 2100
#: the edge build's peak with the least duplication seen (particles-50k, 1.2 references per
#: triangle): the kd-tree checks what it holds as it builds (:func:`tracer.accel.kdtree_build.kd_build`),
#: so the model refuses it before building only when even this floor is over the budget
KDTREE_MIN_BYTES_PER_TRI = 333
KDTREE_CLIP_BYTES_PER_TRI = 550
#: a structure nothing is known of: the largest per-triangle figure above, doubled
GENERIC_BYTES_PER_TRI = 2 * KDTREE_BYTES_PER_TRI
#: fixed bytes of any build (small arrays, stacks): without it the grid, BVH, wide BVH and sorted-list
#: models are within 0-5 % of tracemalloc's peak on bunny-948 (tests/test_memory_guards.py); half
#: the former 64 KiB is kept as margin, since the packet grid's rows went from one per reference to
#: one per triangle and 64 KiB alone put its estimate over 1.5x that peak
BUILD_OVERHEAD = 32 << 10
#: triangles per block of the geometry pass (its float64 temporaries stay near 2 MB)
CHUNK = 1 << 13
#: triangles the nested model follows level by level (a regular sample of larger scenes)
NESTED_SAMPLE = 1 << 16
#: top grids up to this many cells get the per-cell reference field (8 bytes a cell while estimating)
NESTED_FIELD_CELLS = 1 << 26
#: triangles per block of the field's pass (the estimate must stay far below what it guards)
CELL_CHUNK = 1 << 11


def _geometry(tris: np.ndarray, lo: np.ndarray, cell: np.ndarray):
    """Per triangle, in cell units: the sum of its areas projected on the three axis planes, the sum
    of its extents along the axes, and its centroid (computed in blocks of :data:`CHUNK`)."""
    n = len(tris)
    area, ext, cen = np.empty(n), np.empty(n), np.empty((n, 3))
    for s in range(0, n, CHUNK):
        t = (tris[s:s + CHUNK].astype(np.float64) - lo) / cell
        e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
        area[s:s + CHUNK] = 0.5 * np.abs(np.cross(e1, e2)).sum(axis=1)
        ext[s:s + CHUNK] = (t.max(axis=1) - t.min(axis=1)).sum(axis=1)
        cen[s:s + CHUNK] = t.mean(axis=1)
    return area, ext, cen


def _bbox_cells(t: np.ndarray, res) -> tuple[np.ndarray, np.ndarray]:
    """First and last cell (per axis, inclusive, clamped to the grid) of the bounding box of each
    triangle of ``t`` (triangles in cell units)."""
    return np.clip(np.floor(t.min(axis=1)), 0, res - 1), np.clip(np.floor(t.max(axis=1)), 0, res - 1)


def expected_refs(scene, res, exact: bool = True) -> float:
    """Triangle references of a grid of ``res`` cells over the scene's bounds: with ``exact``
    (triangle/box overlap) the swept-cube volume of each triangle (module docstring), else the
    cells of its bounding box; counted in blocks of :data:`CHUNK` triangles."""
    lo = np.asarray(scene.bounds[0], np.float64)
    res = np.asarray(res, np.float64)
    cell = np.maximum(np.asarray(scene.bounds[1], np.float64) - lo, 1e-30) / res
    if exact:  # the scene's per-axis sums, scaled to cell units: no pass over the triangles per grid
        p, e = scene.axis_sums
        area = 0.5 * (p[0] / (cell[1] * cell[2]) + p[1] / (cell[0] * cell[2]) + p[2] / (cell[0] * cell[1]))
        return float(area + (e / cell).sum() + scene.n)
    total = 0.0
    for s in range(0, scene.n, CHUNK):
        a, b = _bbox_cells((scene.tris[s:s + CHUNK].astype(np.float64) - lo) / cell, res)
        total += float(np.prod(b - a + 1, axis=1).sum())
    return total


def grid_bytes(ncell: float, refs: float, layout: str = "copy", macro: int = 0) -> int:
    """Peak bytes of a one-level grid build, the estimate the build's own memory guard checks
    (tracer.accel.grid.fill_cells) and tests/test_provenance.py holds to tracemalloc's peak: cell
    array (ncell + 1 int32) and occupancy bits, reference ids, vertex rows in cell order ("copy",
    "blocks" and "auto", which builds the blocks; none for "index", whose cells read the scene's own
    rows) and with macrocells the block occupancy pass (an int32 diff, two bool arrays)."""
    rows = 0 if layout == "index" else refs
    b = (ncell + 1) * GRID_BYTES_PER_CELL + refs * GRID_BYTES_PER_REF_ID + rows * TRI_ROW_BYTES
    if macro:
        b += ncell * GRID_MACRO_BYTES_PER_CELL
    return int(b)


def _wald_res(scene, lam: float) -> np.ndarray:
    ext = np.maximum(np.asarray(scene.bounds[1], float) - np.asarray(scene.bounds[0], float), 1e-30)
    k = (lam * scene.n / float(np.prod(ext))) ** (1.0 / 3.0)
    return np.maximum(1, np.round(ext * k)).astype(np.int64)


def _grid(inst, scene) -> int:
    res = inst._resolution(scene)
    refs = expected_refs(scene, res, bool(inst.exact))
    return grid_bytes(float(np.prod(res)), refs, inst.layout, inst.macro)


def _cgt(inst, scene) -> int:
    res = np.asarray(inst.res, np.int64) if getattr(inst, "res", None) is not None else _wald_res(scene, inst.lam)
    refs = expected_refs(scene, res, bool(getattr(inst, "exact", True)))
    # the cells read one packet row per triangle (tracer.accel.packet_kernels.ROW), not copies per reference
    return grid_bytes(float(np.prod(res)), refs, "index", inst.macro) + int(scene.n * CGT_ROW_BYTES)


def _cell_counts(tris, lo, cell, res, pieces, cen) -> np.ndarray:
    """Per triangle, the expected references in the top-grid cell of its centroid ``cen`` (cell
    units): every triangle spreads its ``pieces`` (its expected cells) evenly over the cells of its
    bounding box, summed with a 3-D difference array (in blocks of :data:`CELL_CHUNK`, so the estimate
    itself stays small). Counting centroids instead stacks a long triangle's references in the cell
    of its middle: on a capped cylinder (triangles from cap to cap) that put every reference in one
    slab of cells and, through Eq 8's M2 = (4 N2)^1.5, estimated 4-5x the peak (19.6 GB for the
    19,996-triangle cylinder under Eq 17's rule, whose build peaks at 4.0 GB)."""
    res = np.asarray(res, np.int64)
    diff = np.zeros(tuple(res + 1))
    for s in range(0, len(tris), CELL_CHUNK):
        a, b = _bbox_cells((tris[s:s + CELL_CHUNK].astype(np.float64) - lo) / cell, res)
        a, b = a.astype(np.int64), b.astype(np.int64)
        w = pieces[s:s + CELL_CHUNK] / np.prod(b - a + 1, axis=1)
        for corner in range(8):
            idx = tuple(np.where((corner >> k) & 1, b[:, k] + 1, a[:, k]) for k in range(3))
            np.add.at(diff, idx, w if bin(corner).count("1") % 2 == 0 else -w)
    field = diff.cumsum(axis=0).cumsum(axis=1).cumsum(axis=2)
    out = np.empty(len(tris))
    for s in range(0, len(tris), CELL_CHUNK):
        c = np.clip(cen[s:s + CELL_CHUNK].astype(np.int64), 0, res - 1)
        out[s:s + CELL_CHUNK] = field[c[:, 0], c[:, 1], c[:, 2]]
    return out


def _nested(inst, scene) -> int:
    """Level by level (Ize's compact nesting: a sub-grid spans one parent cell): a triangle's cell
    holds about ``k`` references (every triangle's expected cells spread over its bounding box,
    :func:`_cell_counts`, read at the triangle's centroid); the sub-grid over that cell has
    ``_sub_cells(k)`` cells of side h / cells^(1/3); the triangle's references there are its swept-cube volume at that side,
    plus one per piece the level above cut it into. Below level 2 a cell's references spread over
    the sub-cells a surface crosses (1.5 cells^(2/3) of them). Over :data:`NESTED_SAMPLE` triangles, a
    regular sample of them stands for the whole (sums scaled)."""
    levels = int(inst.levels)
    n = scene.n
    m1 = inst._m1_cells(n, inst._check())
    lo = np.asarray(scene.bounds[0], np.float64)
    ext = np.maximum(np.asarray(scene.bounds[1], np.float64) - lo, 1e-30)
    res1 = np.maximum(1, np.round(ext / (float(np.prod(ext)) / max(m1, 1.0)) ** (1.0 / 3.0))).astype(np.int64)
    step = max(1, -(-n // NESTED_SAMPLE))
    area, sext, cen = _geometry(scene.tris[::step], lo, ext / res1)  # in top-grid cell units
    scale = n / max(len(area), 1)
    pieces = area + sext + 1.0
    cells_l, refs_l = float(np.prod(res1)), float(pieces.sum()) * scale
    # a cell holds at most one reference per triangle of the scene (a large triangle spreads its pieces
    # over many cells, it does not stack them in its centroid's)
    if cells_l <= NESTED_FIELD_CELLS:
        cnt = np.minimum(_cell_counts(scene.tris[::step], lo, ext / res1, res1, pieces, cen) * scale, n)
    else:  # a top grid this large is over any budget by its cells alone; spread the references evenly
        cnt = np.full(len(area), min(refs_l / cells_l, n))
    h = np.ones(len(area))
    alive = np.ones(len(area), bool)
    peak = kept = 0.0
    for level in range(1, levels + 1):
        peak = max(peak, kept + cells_l * NESTED_BYTES_PER_CELL + refs_l * NESTED_BYTES_PER_REF)
        kept += cells_l * NESTED_KEPT_PER_CELL + refs_l * NESTED_KEPT_PER_REF
        if level == levels:
            break
        alive &= cnt > inst.leaf_threshold
        if not alive.any():
            break
        sub = np.maximum(inst._sub_cells(cnt, level + 1) * float(inst.m2_scale) ** 3, 1.0)
        # each nested cell's sub-grid once: a triangle holds pieces/cnt of its cell
        cells_l = float((pieces * sub / np.maximum(cnt, 1e-30))[alive].sum()) * scale
        h = h / np.cbrt(sub)
        new = np.where(alive, area / h**2 + sext / h + pieces, 0.0)
        refs_l = float(new.sum()) * scale
        cnt = np.where(alive, np.minimum(cnt * (new / np.maximum(pieces, 1e-30))
                                         / np.minimum(sub, 1.5 * sub ** (2.0 / 3.0)), n), 0.0)
        pieces = new
    # the leaf rows gathered at the end, beside what the levels keep
    return int(max(peak, kept + refs_l * TRI_ROW_BYTES))


#: structure name -> estimate(inst, scene) of its build's peak bytes (beside BUILD_OVERHEAD)
_PER_TRI = {"bvh": BVH_BYTES_PER_TRI, "bvh4": BVH4_BYTES_PER_TRI, "wbvh": WBVH_BYTES_PER_TRI,
            "sortedlists": SORTEDLISTS_BYTES_PER_TRI}
ESTIMATES = {
    "grid": _grid,
    "cgt": _cgt,
    "nested": _nested,
    "kdtree": lambda inst, scene: scene.n * (KDTREE_CLIP_BYTES_PER_TRI if inst.clip else KDTREE_BYTES_PER_TRI),
    **{k: (lambda v: lambda inst, scene: scene.n * v)(v) for k, v in _PER_TRI.items()},
}


def estimate(name: str, inst, scene) -> tuple[int, str]:
    """(peak bytes, how it was estimated) of building ``inst`` (structure ``name``) over ``scene``."""
    if name in ESTIMATES:
        return int(ESTIMATES[name](inst, scene)) + BUILD_OVERHEAD, "model"
    declared = getattr(inst, "estimate_bytes", None)
    if callable(declared):
        return int(declared(scene)), "declared"
    return scene.n * GENERIC_BYTES_PER_TRI + BUILD_OVERHEAD, f"generic {GENERIC_BYTES_PER_TRI} B per triangle"


def refusal(name: str, n: int, est: int, budget: int, how: str = "model") -> str:
    """The one line of a refused build."""
    return (f"structure {name!r} over {n:,} faces would need about {fmt_bytes(est)} ({how} estimate), over the "
            f"memory budget of {fmt_bytes(budget)}; raise it with GRIDCOST_MEMORY_BUDGET (e.g. "
            f"GRIDCOST_MEMORY_BUDGET={max(1, math.ceil(est / 2**30))}G) or use a smaller scene")


#: structures that count their references before allocating and check that exact figure themselves
#: (:func:`tracer.accel.grid.fill_cells`): the model refuses them only beyond its own error (the
#: swept-cube count is within 10 % of the grid's), so the exact check decides near the budget
SELF_CHECKED_MARGIN = {"grid": 1.10}


def self_checked_margin(name: str, inst) -> float:
    """How far over the budget the model lets ``inst`` start its build, because the build checks
    its exact figure itself: :data:`SELF_CHECKED_MARGIN`, and for the kd-tree's edge build the
    ratio of its typical to its least per-triangle peak."""
    if name == "kdtree" and not getattr(inst, "clip", False):
        return KDTREE_BYTES_PER_TRI / KDTREE_MIN_BYTES_PER_TRI
    return SELF_CHECKED_MARGIN.get(name, 1.0)


def check_structure(name: str, inst, scene, budget: int | None = None) -> int:
    """Refuse (GridcostError) to build ``inst`` over ``scene`` when its estimate exceeds the budget;
    returns the estimate."""
    budget = memory_budget() if budget is None else budget
    est, how = estimate(name, inst, scene)
    if est > budget * self_checked_margin(name, inst):
        raise GridcostError(refusal(name, scene.n, est, budget, how))
    return est

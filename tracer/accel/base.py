"""The narrow interface every acceleration structure implements, and the ``build`` factory.

pbrt-v2 style: ``build(scene, name, **params)`` returns a built structure with

* ``intersect(origins, directions, tmin=0, tmax=None, counters=True) -> (Hits, Counters | None)``
* ``occluded(origins, directions, tmax) -> bool array``
* ``stats() -> dict`` (cells, refs, memory bytes, build seconds, ...)

Parameters go in ``__init__`` and fitted (built) attributes end with ``_`` (scikit-learn style).
Counting is a separately compiled variant of the same kernel source (``counters=False`` runs the
variant with no counter code in it), so the timed path is not slowed by counting.
"""
from __future__ import annotations

import functools
import importlib
import importlib.metadata
from typing import NamedTuple

import numba
import numpy as np

from tracer.errors import GridcostError
from tracer.measure.footprint import check_structure

#: per-ray counter columns, in the order of the int32 array the kernels fill (``_jit.store_ray``).
#: One meaning per column; a structure declares the columns it fills in ``counter_fields`` (name ->
#: what it counts there) and leaves the others at 0.
COUNTER_SCHEMA = {
    "setups": "traversal set-ups: 3D-DDA set-ups in grids, 1 per ray entering the root box in trees",
    "steps": "traversal steps: cells stepped in grids, leaves visited in trees, events in sorted lists",
    "tests": "ray/triangle tests",
    "nodes": "hierarchy nodes visited: tree nodes (leaves included), sub-grids entered, BVs opened",
    "skips": "work skipped: mailbox hits in grids, events of children already processed in sorted lists",
    "occupied": "visited grid cells that hold at least one triangle reference",
    "jumps": "macrocell jumps over empty blocks of cells",
}
COUNTER_NAMES = tuple(COUNTER_SCHEMA)

#: the entry-point group through which another package adds a structure: in its pyproject.toml,
#: ``[project.entry-points."gridcost.structures"]`` ``mine = "mypkg.mine:MyAccel"`` (an
#: :class:`Accel` subclass); verify, bench and advise then take ``mine`` with no edit to gridcost
ENTRY_POINT_GROUP = "gridcost.structures"

#: the built-in structures: name -> "module:Class"
STRUCTURES = {
    "grid": "tracer.accel.grid:UniformGrid",
    "nested": "tracer.accel.nested:NestedGrid",
    "kdtree": "tracer.accel.kdtree:KdTree",
    "bvh": "tracer.accel.bvh:BVH",
    "bvh4": "tracer.accel.bvh4:BVH4",
    "wbvh": "tracer.accel.wide_bvh:WideBVH",
    "cgt": "tracer.accel.packet:CoherentGrid",
    "sortedlists": "tracer.accel.sortedlists:SortedLists",
}


class Hits(NamedTuple):
    """Closest hits: ``t`` (float32, inf for a miss) and ``tri_id`` (int32, -1 for a miss)."""
    t: np.ndarray
    tri_id: np.ndarray


class Counters:
    """Per-ray work counters, an ``(m, len(COUNTER_NAMES))`` int32 array with columns
    :data:`COUNTER_NAMES`, read by name. ``fields`` names the columns the structure that filled them
    declares (its ``counter_fields``); the others are 0."""

    def __init__(self, data: np.ndarray, fields: dict | None = None):
        if data.ndim != 2 or data.shape[1] != len(COUNTER_NAMES):
            raise ValueError(f"counters must be (m, {len(COUNTER_NAMES)}), got {data.shape}")
        self.data = data
        self.fields = dict(fields) if fields is not None else dict(COUNTER_SCHEMA)

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in COUNTER_SCHEMA:
            raise KeyError(f"no counter {name!r}; counters are {', '.join(COUNTER_NAMES)}")
        return self.data[:, COUNTER_NAMES.index(name)]

    def mean(self) -> dict[str, float]:
        means = self.data.mean(axis=0) if len(self.data) else np.zeros(len(COUNTER_NAMES))
        return {k: float(v) for k, v in zip(COUNTER_NAMES, means)}

    def total(self) -> dict[str, int]:
        return {k: int(v) for k, v in zip(COUNTER_NAMES, self.data.sum(axis=0, dtype=np.int64))}


def as_rays(origins, directions) -> tuple[np.ndarray, np.ndarray]:
    """Validate and convert a batch of rays to C-contiguous float32 ``(m, 3)`` arrays."""
    o = np.ascontiguousarray(origins, dtype=np.float32)
    d = np.ascontiguousarray(directions, dtype=np.float32)
    if o.ndim != 2 or o.shape[1] != 3 or d.shape != o.shape:
        raise GridcostError(f"rays must be two (m, 3) arrays of equal shape, got {o.shape} and {d.shape}")
    if not (np.isfinite(o).all() and np.isfinite(d).all()):
        raise GridcostError("rays contain NaN or inf")
    return o, d


def tmax_array(tmax, m: int) -> np.ndarray:
    """Per-ray tmax: a new writable C-contiguous float32 array of m values (inf for None; a scalar or
    an (m,) array broadcast). Never a view of the caller's array: Numba types a read-only array
    apart, and ``np.ascontiguousarray(np.broadcast_to(...))`` returned read-only views, which
    compiled every kernel's any-hit variant twice (seen in ``wald-table3 --quick``: 13-35 s each)."""
    out = np.empty(m, dtype=np.float32)
    out[:] = np.inf if tmax is None else np.asarray(tmax, dtype=np.float32)
    return out


class Accel:
    """Base class: subclasses implement ``build(scene)`` and ``_trace(o, d, tmin, tmax, anyhit, count)``."""

    name = "accel"
    #: the counter columns this structure fills: name -> what it counts (see :data:`COUNTER_SCHEMA`)
    counter_fields: dict = {}

    def build(self, scene):  # pragma: no cover - abstract
        raise NotImplementedError

    def _trace(self, o, d, tmin, tmax, anyhit, count):  # pragma: no cover - abstract
        raise NotImplementedError

    def intersect(self, origins, directions, tmin: float = 0.0, tmax=None, counters: bool = True):
        o, d = as_rays(origins, directions)
        t, ids, cnt = self._trace(o, d, float(tmin), tmax_array(tmax, len(o)), False, counters)
        return Hits(t, ids), (Counters(cnt, self.counter_fields) if counters else None)

    def occluded(self, origins, directions, tmax, tmin: float = 0.0) -> np.ndarray:
        o, d = as_rays(origins, directions)
        _, ids, _ = self._trace(o, d, float(tmin), tmax_array(tmax, len(o)), True, False)
        return ids >= 0

    def stats(self) -> dict:  # pragma: no cover - abstract
        raise NotImplementedError

    @staticmethod
    def _outputs(m: int, count: bool):
        """Result buffers of a batch of m rays: t (float32), tri_id (int32), counters or None."""
        return (np.empty(m, np.float32), np.empty(m, np.int32),
                np.zeros((m, len(COUNTER_NAMES)), np.int32) if count else None)


class TreeTraceMixin:
    """``_trace`` shared by the hierarchies (kd-tree, BVH, BVH4, wide BVH): every kernel takes the
    rays, the root box and diagonal, the structure's flat arrays, the stack size, the outputs and the
    thread count, in that order. A subclass sets ``_kernel = staticmethod(<its Numba kernel>)`` and
    overrides :meth:`_tree_arrays` when its arrays differ from the binary BVH's, :meth:`_stack_size`
    when its stack holds more than one entry per level, and :meth:`_scene_ids` when it stores the
    triangles in another order."""

    def _stack_size(self) -> int:
        """Entries of the per-block traversal stack: one per level of the tree, and a margin."""
        return self.depth_ + 2

    def _tree_arrays(self) -> tuple:
        """The structure's arrays, as its kernel takes them after ``diag``."""
        return (self.nodes_.reshape(-1), self.nodes_f_.reshape(-1), self.tri_verts_, self.tri_ids_)

    def _scene_ids(self, out_id):
        """The kernel's triangle ids as the scene's (the same, unless overridden)."""
        return out_id

    def _trace(self, o, d, tmin, tmax, anyhit, count):
        out_t, out_id, cnt = self._outputs(len(o), count)
        if self.n_ == 0:
            out_t[:] = np.inf
            out_id[:] = -1
            return out_t, out_id, cnt
        self._kernel(o, d, tmin, tmax, anyhit, self.box_, self.diag_, *self._tree_arrays(), self._stack_size(),
                     out_t, out_id, cnt, numba.get_num_threads())
        return out_t, self._scene_ids(out_id), cnt


@functools.lru_cache(maxsize=None)
def _registered() -> tuple[tuple[str, str], ...]:
    """(name, "module:Class") of every structure installed packages declare in :data:`ENTRY_POINT_GROUP`."""
    return tuple((ep.name, ep.value) for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP))


def structures() -> dict[str, str]:
    """Every structure :func:`build` knows: name -> "module:Class", the built-in :data:`STRUCTURES`
    first, then those registered by entry points. A registered name that shadows a built-in one is
    an error (it would silently change what every target measures)."""
    out = dict(STRUCTURES)
    for name, value in _registered():
        if name in STRUCTURES:
            raise GridcostError(f"the entry point {name!r} = {value!r} in group {ENTRY_POINT_GROUP!r} shadows "
                                f"gridcost's built-in structure {name!r}; rename it")
        out[name] = value
    return out


def plugin_structures() -> tuple[str, ...]:
    """Names of the structures registered from outside gridcost (entry points), in registration order."""
    return tuple(name for name in structures() if name not in STRUCTURES)


def structure_class(name: str) -> type:
    """The :class:`Accel` subclass of structure ``name`` (a built-in or a registered one)."""
    known = structures()
    if name not in known:
        raise GridcostError(f"unknown structure {name!r}; known: {', '.join(known)}")
    modname, _, clsname = known[name].partition(":")
    try:
        cls = getattr(importlib.import_module(modname), clsname)
    except (ImportError, AttributeError) as exc:
        raise GridcostError(f"structure {name!r}: cannot load {known[name]!r} ({exc})") from None
    if not (isinstance(cls, type) and issubclass(cls, Accel)):
        raise GridcostError(f"structure {name!r}: {known[name]!r} is not a subclass of tracer.accel.base.Accel")
    return cls


def build(scene, name: str = "grid", **params) -> Accel:
    """Build structure ``name`` (one of :func:`structures`: built-in or registered) over ``scene`` with ``params``."""
    cls = structure_class(name)
    try:
        inst = cls(**params)
    except TypeError as exc:  # an unknown or missing parameter is the caller's input error
        raise GridcostError(f"structure {name!r}: bad parameters {params!r} ({exc})") from None
    check_structure(name, inst, scene)  # refuse over the memory budget before allocating anything big
    return inst.build(scene)

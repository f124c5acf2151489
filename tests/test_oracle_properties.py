"""Property-based oracle tests: every structure and variant against the float64 brute-force oracle
on generated triangle soups and adversarial ray sets (Hypothesis).

Soups (:func:`soups`): triangles on a small integer lattice (shared vertices and edges, coplanar and
axis-aligned quads, fans), free vertices, slivers, degenerate (collinear, repeated-vertex) and
duplicated triangles (same and reversed winding), mapped to a box of size 1e-4 .. 1e4 offset by up
to 1e5 per axis in float64 and rounded once to float32. Degenerate triangles are kept, as the mesh
loader keeps them (:func:`tracer.scenes.scenetype.validate` counts them and refuses only an
all-degenerate mesh; a soup the loader would refuse is not generated): the oracle and the structures
see the same scene, ids included.

Rays (:func:`cases`): exactly through vertices and points on edges (axis-aligned), towards them from
outside and inside, exactly in the coordinate planes of vertices (the kd-tree's split planes) and
along the cell planes of the grid under test, starting inside cells, on triangles, at vertices and
on the box boundary, in a triangle's plane, axis-parallel (directions with zero components) and
free, at direction lengths 1e-3 .. 1e3; first, k x k packets in the order the coherent grid
(``cgt``) groups rays: common origin through a lattice of image points (some rays with zero
direction components) or parallel rays from a lattice of origins. Every structure gets the same
rays, so the packets also reach the single-ray structures.

Assertions (:func:`conftest.assert_agrees_exactly`, the project's standard): no disagreement on
hit/miss or triangle id (another id only as a tie: the oracle saw another triangle at the same t,
e.g. a shared edge or a duplicate), and the t of a hit on the oracle's triangle is bit-identical
(every structure calls ``ray_triangle`` as the oracle does); the any-hit query (``occluded``, no
tmax) agrees with hit/miss. No tolerance is widened here.

Profiles (tests/_hypothesis_profiles.py): ``ci`` (fixed seed) for the unmarked tests, ``slow``
(many more and larger soups) for the ``@pytest.mark.slow`` copies. A shrunk failing case is kept
below as an explicit regression test.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from _hypothesis_profiles import profile
from conftest import assert_agrees_exactly
from hypothesis import assume, event, given, note
from hypothesis import strategies as st

from tracer.accel import Hits, build
from tracer.accel.grid import grid_params
from tracer.accel.oracle import oracle_intersect
from tracer.errors import GridcostError
from tracer.scenes.rays import bounding_sphere
from tracer.scenes.scene import Scene, validate

# ---------------------------------------------------------------- the structures and variants
#: family -> [(label, structure, params)]. ``RES`` in params is replaced by the case's grid
#: resolution (the grid the cell-plane rays are built on), ``K`` by its packet side.
RES, K = "<res>", "<k>"
FAMILIES = {
    "grid": [
        ("copy", "grid", dict(res=RES, layout="copy")),
        ("index", "grid", dict(res=RES, layout="index")),
        ("copy+mailbox", "grid", dict(res=RES, layout="copy", mailbox=True)),
        ("index+mailbox", "grid", dict(res=RES, layout="index", mailbox=True)),
        ("bbox-assignment", "grid", dict(res=RES, exact=False)),
        ("macro2", "grid", dict(res=RES, macro=2)),
        ("macro4+index+mailbox", "grid", dict(res=RES, macro=4, layout="index", mailbox=True)),
        ("8N-auto", "grid", dict()),
    ],
    "nested": [
        ("2-level", "nested", dict(levels=2)),
        ("3-level", "nested", dict(levels=3)),
        ("2-level-bbox-leaf0", "nested", dict(levels=2, exact=False, leaf_threshold=0)),
        ("3-level-skinny-eq16", "nested", dict(levels=3, m1_rule="ize_skinny", m2_rule="skinny",
                                               depth_rule="eq16")),
    ],
    "kdtree": [
        ("pbrt", "kdtree", dict()),
        ("pbrt-no-leaf-order", "kdtree", dict(leaf_order=False)),
        ("pbrt-max-prims4", "kdtree", dict(max_prims=4, empty_bonus=0.0)),
        ("clip", "kdtree", dict(clip=True)),
        ("clip-cheap-deep", "kdtree", dict(clip=True, isect_cost=4.0, max_depth=40)),
        ("clip-extra-depth", "kdtree", dict(clip=True, extra_depth=2)),
    ],
    "bvh": [
        ("distance", "bvh", dict(order="distance")),
        ("sign", "bvh", dict(order="sign")),
        ("leaf1-bins2", "bvh", dict(max_leaf=1, bins=2)),
    ],
    "bvh4": [
        ("default", "bvh4", dict()),
        ("leaf1", "bvh4", dict(max_leaf=1)),
    ],
    "wbvh": [
        ("width8", "wbvh", dict(width=8)),
        ("width4", "wbvh", dict(width=4)),
        ("width8-leaf1-bins2", "wbvh", dict(width=8, max_leaf=1, bins=2)),
        ("width8-leaf4", "wbvh", dict(width=8, max_leaf=4, trav_cost=1.0)),
    ],
    "cgt": [
        ("packet", "cgt", dict(res=RES, packet=K)),
        ("packet-no-mailbox-no-cull", "cgt", dict(res=RES, packet=K, mailbox=False, frustum_cull=False)),
        ("packet-no-macro", "cgt", dict(res=RES, packet=K, macro=0)),
        ("packet-macro2-bbox", "cgt", dict(res=RES, packet=K, macro=2, exact=False)),
        ("wald-lambda", "cgt", dict(packet=K)),
    ],
    "sortedlists": [
        ("hierarchy", "sortedlists", dict(hierarchy=True)),
        ("flat", "sortedlists", dict(hierarchy=False)),
        ("branching3-leaf1-nobig", "sortedlists", dict(branching=3, leaf_size=1, big=0)),
    ],
}

SCALES = (1e-4, 1e-2, 1.0, 1e2, 1e4)
OFFSETS = (0.0, 1.0, 10.0, 1e3, 1e5)
#: an offset at most this many times the scale: beyond it float32 collapses the soup to a point
MAX_OFFSET_OVER_SCALE = 1e5


# ---------------------------------------------------------------- triangle soups
def _lattice_point(L):
    c = st.integers(0, L)
    return st.tuples(c, c, c).map(lambda p: tuple(float(x) for x in p))


def _free_point(L):
    c = st.floats(0.0, float(L), allow_nan=False, allow_infinity=False)
    return st.tuples(c, c, c)


@st.composite
def _motif(draw, L, pool):
    """One motif of lattice-unit triangles (lists of three xyz tuples)."""
    P = np.asarray(pool, np.float64)
    pick = st.integers(0, len(P) - 1)
    kind = draw(st.sampled_from(["pool", "pool", "quad", "fan", "sliver", "degenerate", "big"]))
    if kind == "pool":  # three pool vertices: shared vertices and edges, collinear ones degenerate
        return [[P[draw(pick)], P[draw(pick)], P[draw(pick)]]]
    if kind == "quad":  # an axis-aligned lattice rectangle split along a diagonal: coplanar, shared edge
        a = draw(st.integers(0, 2))
        h = float(draw(st.integers(0, L)))
        u0, u1 = sorted(float(x) for x in draw(st.lists(st.integers(0, L), min_size=2, max_size=2)))
        v0, v1 = sorted(float(x) for x in draw(st.lists(st.integers(0, L), min_size=2, max_size=2)))

        def p(u, v):
            q = [0.0, 0.0, 0.0]
            q[a], q[(a + 1) % 3], q[(a + 2) % 3] = h, u, v
            return np.array(q)
        c00, c10, c11, c01 = p(u0, v0), p(u1, v0), p(u1, v1), p(u0, v1)
        if draw(st.booleans()):
            return [[c00, c10, c11], [c00, c11, c01]]
        return [[c00, c10, c01], [c10, c11, c01]]
    if kind == "fan":  # a centre and a ring of pool vertices: every edge to the centre shared
        ids = draw(st.lists(pick, min_size=3, max_size=6))
        c = P[draw(pick)]
        return [[c, P[i], P[j]] for i, j in zip(ids, ids[1:])]
    if kind == "sliver":  # a needle: the third vertex a hair off the middle of an edge
        a, b = P[draw(pick)], P[draw(pick)]
        eps = draw(st.sampled_from([1e-6, 1e-4, 1e-2])) * L
        side = np.zeros(3)
        side[draw(st.integers(0, 2))] = eps
        return [[a, b, (a + b) / 2 + side]]
    if kind == "degenerate":  # collinear (a point of the edge) or a repeated vertex: never hit
        a, b = P[draw(pick)], P[draw(pick)]
        w = draw(st.sampled_from([0.0, 0.5, 1.0, 2.0]))
        return [[a, b, a + w * (b - a)]]
    # big: a triangle across the whole lattice box
    corner = [np.array([0.0, 0, 0]), np.array([L, 0, 0.0]), np.array([0, L, 0.0]), np.array([0, 0, L * 1.0]),
              np.array([L, L, L * 1.0])]
    i, j, k = draw(st.permutations(range(5)))[:3]
    return [[corner[i], corner[j], corner[k]]]


@st.composite
def soups(draw, max_tris=40):
    """(float32 (N, 3, 3) triangles, scale, offset): a soup the mesh loader would accept."""
    L = draw(st.integers(1, 8))
    pool = draw(st.lists(st.one_of(_lattice_point(L), _lattice_point(L), _free_point(L)), min_size=3, max_size=16))
    tris = []
    for m in draw(st.lists(_motif(L, pool), min_size=1, max_size=max(1, max_tris // 2))):
        tris += m
    if draw(st.booleans()):  # duplicates: same winding or reversed (ties at the same t)
        for i in draw(st.lists(st.integers(0, len(tris) - 1), max_size=3)):
            tris.append(tris[i][::-1] if draw(st.booleans()) else list(tris[i]))
    tris = np.asarray(tris[:max_tris], np.float64).reshape(-1, 3, 3)
    # a permutation of the triangles, so ids are not in motif order
    tris = tris[np.asarray(draw(st.permutations(range(len(tris)))), np.int64)]
    scale = draw(st.sampled_from(SCALES))
    offset = np.array([draw(st.sampled_from([o for o in OFFSETS if o <= MAX_OFFSET_OVER_SCALE * scale]))
                       * draw(st.sampled_from([1.0, -1.0])) for _ in range(3)])
    world = (tris / L * scale + offset).astype(np.float32)
    try:
        validate(world, "soup")
    except GridcostError:  # all degenerate after rounding: the loader refuses such a mesh
        assume(False)
    return world, scale, offset


# ---------------------------------------------------------------- rays
_unit = st.floats(0.0, 1.0, allow_nan=False)
_signed = st.floats(-1.0, 1.0, allow_nan=False)


def _axis_vec(a, s=1.0):
    v = np.zeros(3)
    v[a] = s
    return v


@st.composite
def _direction(draw):
    """Axis-parallel (two zero components), in a coordinate plane (one zero) or free; length 1e-3..1e3."""
    kind = draw(st.sampled_from(["axis", "plane", "free"]))
    a = draw(st.integers(0, 2))
    if kind == "axis":
        d = _axis_vec(a, draw(st.sampled_from([1.0, -1.0])))
    else:
        d = np.array([draw(_signed), draw(_signed), draw(_signed)])
        if kind == "plane":
            d[a] = 0.0
    if not np.any(np.abs(d) > 1e-6):
        d = _axis_vec(a)
    # unit length times 1e-3..1e3 (components may still be tiny: nearly axis-parallel rays). Not
    # shorter: with |d| ~ 1e-45 the hit's t exceeds the float32 range of Hits.t, an output limit
    return d / np.linalg.norm(d) * draw(st.sampled_from([1.0, 1.0, 1e-3, 1e3]))


class _Geom:
    """What the ray strategies aim at: the scene's vertices, box, bounding sphere and grid planes."""

    def __init__(self, tris, res):
        self.V = tris.astype(np.float64)
        self.scene = Scene(tris, "soup")
        self.lo, self.hi = self.scene.bounds.astype(np.float64)
        self.ext = self.hi - self.lo
        self.c, self.r = bounding_sphere(self.scene)
        self.gp = grid_params(self.scene.bounds, res)
        self.res = np.asarray(res)


@st.composite
def _point(draw, g, kind=None):
    """A point: a vertex, on an edge, on a triangle, in the box, on the box boundary, on a cell
    line, outside (on a sphere around the scene)."""
    kind = kind or draw(st.sampled_from(["vertex", "edge", "face", "box", "boundary", "cell", "outside"]))
    k = draw(st.integers(0, len(g.V) - 1))
    if kind == "vertex":
        return g.V[k, draw(st.integers(0, 2))]
    if kind == "edge":
        e = draw(st.integers(0, 2))
        w = draw(st.one_of(st.sampled_from([0.0, 0.5, 1.0]), _unit))
        return g.V[k, e] * (1 - w) + g.V[k, (e + 1) % 3] * w
    if kind == "face":
        u, v = draw(_unit), draw(_unit)
        if u + v > 1:
            u, v = 1 - u, 1 - v
        return g.V[k, 0] + u * (g.V[k, 1] - g.V[k, 0]) + v * (g.V[k, 2] - g.V[k, 0])
    if kind == "box":
        return g.lo + np.array([draw(_unit), draw(_unit), draw(_unit)]) * g.ext
    if kind == "boundary":
        p = g.lo + np.array([draw(_unit), draw(_unit), draw(_unit)]) * g.ext
        a = draw(st.integers(0, 2))
        p[a] = g.hi[a] if draw(st.booleans()) else g.lo[a]
        return p
    if kind == "cell":  # on the grid's cell planes on every axis (a cell corner)
        ijk = np.array([draw(st.integers(0, int(n))) for n in g.res])
        return g.gp[0:3] + ijk * g.gp[3:6]
    u = np.array([draw(_signed), draw(_signed), draw(_signed)])
    if not np.any(u):
        u = _axis_vec(2)
    return g.c + g.r * draw(st.sampled_from([1.01, 1.5, 4.0])) * u / np.linalg.norm(u)


@st.composite
def _ray(draw, g):
    """One (origin, direction) pair, float64 (rounded to float32 with the rest)."""
    kind = draw(st.sampled_from(["exact-axis", "towards", "vertex-plane", "cell-plane", "from", "triangle-plane"]))
    if kind == "exact-axis":  # axis-aligned, exactly through a vertex or an edge point (or starting there)
        p = draw(_point(g, draw(st.sampled_from(["vertex", "edge", "face"]))))
        a = draw(st.integers(0, 2))
        s = draw(st.sampled_from([1.0, -1.0]))
        back = draw(st.sampled_from([0.0, 0.5, 2.0])) * max(g.ext[a], g.r)
        return p - s * back * _axis_vec(a), _axis_vec(a, s)
    if kind == "towards":  # from any point towards a vertex, an edge point, a triangle, a cell corner
        o = draw(_point(g))
        d = draw(_point(g)) - o
        if not np.any(np.asarray(d, np.float32)):
            d = draw(_direction())
        return o, d
    if kind == "vertex-plane":  # in the coordinate plane of a vertex (a kd-tree split plane)
        v = draw(_point(g, "vertex"))
        o = draw(_point(g))
        d = draw(_direction())
        a = draw(st.integers(0, 2))
        o[a] = v[a]
        d[a] = 0.0
        if not np.any(np.asarray(d, np.float32)):
            d = _axis_vec((a + 1) % 3)
        return o, d
    if kind == "cell-plane":  # along a line of cell planes, axis-aligned or tilted in one plane
        o = draw(_point(g, "cell"))
        a = draw(st.integers(0, 2))
        if draw(st.booleans()):  # from outside the box (or on its face) rather than from a cell corner
            o[a] = g.lo[a] - draw(st.sampled_from([0.0, 0.05, 1.0])) * g.ext[a]
        d = _axis_vec(a, draw(st.sampled_from([1.0, -1.0])))
        if draw(st.booleans()):
            b = draw(st.sampled_from([(a + 1) % 3, (a + 2) % 3]))
            d[b] = draw(_signed) * g.ext[b] / max(g.ext[a], 1e-30)
        return o, d
    if kind == "triangle-plane":  # in a triangle's plane (grazing: a miss by the parallel test)
        k = draw(st.integers(0, len(g.V) - 1))
        t = g.V[k]
        e = t[(draw(st.integers(1, 2)))] - t[0]
        if not np.any(np.asarray(e, np.float32)):
            e = draw(_direction())
        return t.mean(0) - 2 * e, e
    # from a point (on a triangle, at a vertex, inside a cell, on the boundary, outside) in any direction
    return draw(_point(g)), draw(_direction())


@st.composite
def _packet(draw, g, k):
    """k x k rays, in the order the coherent grid groups them: a common origin through a lattice of
    image points on an axis-aligned plane (the central ray's origin on the lattice's axis line, so
    rays of a row or column have zero direction components), or parallel rays from a lattice of
    origins. Returns (origins, directions) float64 (k^2, 3)."""
    a = draw(st.integers(0, 2))
    b, c = (a + 1) % 3, (a + 2) % 3
    h = max(float(g.ext.max()), 1e-30) * draw(st.sampled_from([1e-3, 0.02, 0.1, 0.4]))
    s0 = draw(st.sampled_from([0, -(k // 2), -(k - 1)]))
    i, j = np.meshgrid(np.arange(k) + s0, np.arange(k) + s0, indexing="ij")
    grid = (i.reshape(-1, 1) * _axis_vec(b) + j.reshape(-1, 1) * _axis_vec(c)) * h
    target = draw(_point(g, draw(st.sampled_from(["vertex", "edge", "box", "cell"]))))
    if draw(st.booleans()):  # common origin
        if draw(st.booleans()):
            o = target - _axis_vec(a, draw(st.sampled_from([1.0, -1.0]))) * draw(st.sampled_from([0.3, 1.0, 3.0])) * g.r
        else:
            o = draw(_point(g, draw(st.sampled_from(["outside", "box", "vertex"]))))
        d = target + grid - o
        d[~np.any(d.astype(np.float32), axis=1)] = _axis_vec(a)
        return np.broadcast_to(o, d.shape), d
    d = draw(_direction())
    return target + grid - 2 * g.r * d / np.linalg.norm(d), np.broadcast_to(d, grid.shape)


@dataclass
class Case:
    """A generated case: float32 triangles, the grid resolution, the packet side, float32 rays
    (the first ``packet_rays`` in k x k packets). The repr is a reproducer."""
    tris: np.ndarray
    res: tuple
    k: int
    origins: np.ndarray
    directions: np.ndarray
    packet_rays: int
    scale: float
    offset: tuple

    def __repr__(self):
        return (f"Case(tris=np.array({self.tris.tolist()!r}, np.float32), res={self.res}, k={self.k}, "
                f"origins=np.array({self.origins.tolist()!r}, np.float32), "
                f"directions=np.array({self.directions.tolist()!r}, np.float32), "
                f"packet_rays={self.packet_rays}, scale={self.scale!r}, offset={self.offset!r})")

    def _repr_pretty_(self, p, cycle):  # Hypothesis prints the falsifying case with this: exact values
        p.text(repr(self))


@st.composite
def cases(draw, max_tris=40, max_rays=40, max_packets=3):
    tris, scale, offset = draw(soups(max_tris))
    res = tuple(draw(st.integers(1, 6)) for _ in range(3))
    g = _Geom(tris, res)
    k = draw(st.sampled_from([2, 4]))
    O, D = [], []
    for _ in range(draw(st.integers(0, max_packets))):
        o, d = draw(_packet(g, k))
        O += list(o)
        D += list(d)
    npk = len(O)
    for _ in range(draw(st.integers(1, max_rays))):
        o, d = draw(_ray(g))
        O.append(o)
        D.append(d)
    O = np.asarray(O, np.float64).astype(np.float32)
    D = np.asarray(D, np.float64).astype(np.float32)
    zero = ~D.any(axis=1)  # a direction that rounded to zero
    D[zero] = (0.0, 0.0, 1.0)
    assume(np.isfinite(O).all() and np.isfinite(D).all())
    return Case(tris, res, k, O, D, npk, scale, tuple(float(x) for x in offset))


# ---------------------------------------------------------------- the property
def _params(params, case):
    return {key: (case.res if v == RES else case.k if v == K else v) for key, v in params.items()}


def _detail(case, hits, ref, bad):
    """The disagreeing rays and the triangles involved, for the failure message."""
    lines = []
    for i in bad[:5]:
        ids = sorted({int(x) for x in (hits.tri_id[i], ref.tri_id[i]) if x >= 0})
        lines.append(f"  ray {i}: o={case.origins[i].tolist()} d={case.directions[i].tolist()} "
                     f"oracle (t={ref.t[i]!r}, id={ref.tri_id[i]}) structure (t={hits.t[i]!r}, id={hits.tri_id[i]}) "
                     + " ".join(f"tri {j}={case.tris[j].tolist()}" for j in ids))
    return "\n".join(lines)


# ---------------------------------------------------------------- every input, every structure
# Real disagreements the property tests found are kept as regression cases (:data:`REGRESSIONS`, at
# the end of this file); none is left out of the property tests.


def check_family(family, case, variants=None):
    """Build every variant of ``family`` on the case's scene and compare with the oracle; raise one
    AssertionError listing every variant that disagrees."""
    tris = case.tris
    scene = Scene(tris, "soup", "hypothesis", validate(tris, "soup"))
    ref, ties = oracle_intersect(scene, case.origins, case.directions)
    note(f"oracle: {int((ref.tri_id >= 0).sum())} hits of {len(ref.t)} rays, {int((ties > 0).sum())} with ties")
    event(f"scale {case.scale:g}, max |offset| {max(abs(x) for x in case.offset):g}")
    if validate(tris, "soup")["degenerate"]:
        event("soup with degenerate triangles")
    if (ties > 0).any():
        event("rays with ties at the closest hit")
    failures = []
    for label, name, params in (variants or FAMILIES[family]):
        kw = _params(params, case)
        acc = build(scene, name, **kw)
        hits, _ = acc.intersect(case.origins, case.directions, counters=False)
        try:
            assert_agrees_exactly(hits, ref, ties, (name, label))
        except AssertionError as exc:
            hit_a, hit_b = hits.tri_id >= 0, ref.tri_id >= 0
            same = hit_a & (hits.tri_id == ref.tri_id)
            with np.errstate(over="ignore"):
                bad = np.flatnonzero(((hit_a != hit_b) | (hit_a & hit_b & ~same & (ties == 0))
                                             | (same & (hits.t != ref.t.astype(np.float32)))))
            failures.append(f"{name} {kw}: {exc}\n{_detail(case, hits, ref, bad)}")
            continue
        occ = acc.occluded(case.origins, case.directions, None)
        bad = np.flatnonzero(occ != (ref.tri_id >= 0))
        if len(bad):
            failures.append(f"{name} {kw}: occluded() disagrees with hit/miss on rays {bad[:10].tolist()}\n"
                            f"{_detail(case, hits, ref, bad)}")
    assert not failures, "\n".join(failures)


@pytest.mark.parametrize("family", list(FAMILIES))
@profile()
@given(case=cases())
def test_every_variant_agrees_with_the_oracle(family, case):
    check_family(family, case)


@pytest.mark.slow
@pytest.mark.parametrize("family", list(FAMILIES))
@profile("slow")
@given(case=cases(max_tris=200, max_rays=120, max_packets=6))
def test_every_variant_agrees_with_the_oracle_long(family, case):
    check_family(family, case)


# ---------------------------------------------------------------- the generators do what they claim
def test_generated_packets_take_the_packet_path():
    """The common-origin packets reach the coherent grid's packet loop, not only its single-ray
    fallback (the premise of covering ``cgt`` with them)."""
    tris = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[1, 0, 0], [1, 1, 0], [0, 1, 0]],
                     [[0, 0, 1], [1, 0, 1], [0, 1, 1]]], np.float32)
    g = _Geom(tris, (4, 4, 4))
    k = 4
    grid = np.array([(i * 0.1, j * 0.1, 0.0) for i in range(k) for j in range(k)])
    o = np.tile([0.2, 0.2, 3.0], (k * k, 1))
    d = (g.lo + [0.2, 0.2, 0.0] + grid) - o
    acc = build(g.scene, "cgt", res=(4, 4, 4), packet=k)
    pc = acc.packet_counters(o.astype(np.float32), d.astype(np.float32))
    assert pc["packet_rays"].sum() == k * k and pc["single"].sum() == 0, pc


def test_soups_cover_their_claims():
    """A fixed draw of soups holds shared vertices, degenerate and duplicate triangles, and every
    scale (a check on the generator, not on the structures)."""
    from hypothesis import find, settings
    FIND = settings(profile(), max_examples=2000)
    find(soups(), lambda s: (np.linalg.norm(np.cross(s[0][:, 1].astype(np.float64) - s[0][:, 0],
                                                     s[0][:, 2].astype(np.float64) - s[0][:, 0]), axis=1) == 0).any()
         and len(s[0]) > 3, settings=FIND)
    for scale in SCALES:
        find(soups(), lambda s, scale=scale: s[1] == scale and max(abs(x) for x in s[2]) > 0, settings=FIND)


# ---------------------------------------------------------------- regression cases (shrunk by Hypothesis)
#: the structures of the regression cases, with the parameters the shrunk cases used
REGRESSION_STRUCTURES = {
    "grid-res": ("grid", dict(res=(2, 2, 1))), "grid-auto": ("grid", {}), "nested": ("nested", dict(levels=2)),
    "cgt-res": ("cgt", dict(res=(2, 2, 1), packet=2)), "cgt-auto": ("cgt", dict(packet=2)),
    "kdtree": ("kdtree", {}), "kdtree-clip": ("kdtree", dict(clip=True)), "bvh": ("bvh", {}), "bvh4": ("bvh4", {}),
    "wbvh": ("wbvh", dict(width=8)), "sortedlists": ("sortedlists", {})}

#: case -> (triangles, origins, directions); every structure must agree with the oracle on each.
#:
#: FIXED (``tracer.scenes.scenetype.scene_bounds``, found here): the flat-axis pad and the margin
#: were added in float64 and the box rounded to nearest float32, so far from the origin they
#: vanished; the box now steps one float32 outward where rounding lost them.
#: * "flat-0.01-square-at-1e3" (shrunk) and "flat-unit-triangle-at-1e5": the box had zero
#:   thickness in z; grids with an explicit resolution missed the triangle, an automatic one
#:   divided by the zero thickness.
#: * "margin-shrunk-grid" (shrunk) and "margin-unit-at-1e5": the box top was the top vertex's z
#:   exactly, and a ray in that plane rising at d_z = 1e-30 left the grid's box at t = 0.
#: FIXED (``tracer.accel.oracle.compare``, found here): a hit beyond float32's range.
#: * "subnormal-direction-beyond-float32" (shrunk): a ray 1e-4 from a triangle moving towards it at
#:   d_x = -1.4e-45 hits it at t = 7.1e40 in float64; every structure returns float32 t = inf with
#:   the right id, and the comparison used the unrounded t. The oracle's t is now compared rounded
#:   to float32, as the structures return it.
#: FIXED (the hierarchies' boxes: ``tracer.accel.geometry.padded_bounds``, found here): a ray
#: starting in the plane of a node box face or split plane and leaving it with a direction
#: component in (0, ~1e-16] of the others meets a vertex or edge on that plane by
#: ``ray_triangle``'s float64 rounding (exactly it would leave at t = 0 and miss); the oracle counts
#: the hit, the grids (with a margin) and sorted lists found it, the kd-tree, BVH, BVH4 and wide BVH
#: put it outside the node (one ulp in x is ulp/d_x in t, far beyond T_EPS). Any scale, at the
#: origin too ("nearly-parallel-two-triangles": BVH and BVH4 missed for d_z from 3e-39 to 1e-16).
#: Every box the hierarchies cull by is now padded in space (BOX_PAD_REL of the triangle's
#: magnitude), which no widening in t could do.
#: * "nearly-parallel-shrunk-bvh" (shrunk): a degenerate triangle at the origin and a 1e-4 right
#:   triangle; the ray starts on its box face x = 1e-4 below vertex (1e-4, 0, 0) and rises along z
#:   with a subnormal x component: the oracle hits triangle 1 at t = 1.4142432e-4, BVH misses
#:   (BVH4 agrees there).
#: * "nearly-parallel-one-triangle": BVH4 misses (a one-triangle BVH is a leaf, and agrees).
#: * "nearly-parallel-shrunk-kdtree" (shrunk; scale 1e-4; the degenerate triangles are kept, as
#:   the loader keeps them) and "nearly-parallel-kdtree-unit" (the same by hand at unit size): a
#:   triangle in the plane x = 0 with its lowest vertex at y = 1 (resp. 5e-5), a degenerate
#:   triangle at the origin; the ray along +x in the plane y = 1 descends at d_y = -1e-30 (resp.
#:   -1.4e-45): the oracle hits the vertex at t = 2, the kd-tree (every build), BVH and BVH4 miss
#:   (kd-tree misses for |d_y| from 1e-45 to 1e-17; without the degenerate triangle it agrees).
#: * "axis-ray-beside-a-subnormal-vertex" (from a shrunk case of the long profile): the same in its
#:   exactly axis-parallel form. A sliver in the plane z = 0 with its lowest
#:   vertex at y = 1.1e-44; the ray along +z at x = y = 0 passes it by that subnormal, which
#:   ``ray_triangle``'s float64 rounding loses beside the 1e-4 edges: the oracle hits at
#:   t = 2.5e-5; the kd-tree (every build), BVH and BVH4 culled the triangle's box (the grids' margin
#:   and sorted lists found it).
_UNIT = np.array([[[0, 0, 0], [1, 0, 0], [0, 0, 1]], [[0, 0.5, 0], [1, 0.5, 0], [0, 0.5, 1]]], np.float32)
REGRESSIONS = {
    "flat-0.01-square-at-1e3": (
        np.array([[[0, 0, 1e3], [1e-2, 0, 1e3], [0, 1e-2, 1e3]], [[1e-2, 0, 1e3], [1e-2, 1e-2, 1e3], [0, 1e-2, 1e3]]],
                 np.float32), [[0.005, 0.005, 1001.0]], [[0.0, 0.0, -1.0]]),
    "flat-unit-triangle-at-1e5": (
        np.array([[[0, 0, 1e5], [1, 0, 1e5], [0, 1, 1e5]]], np.float32), [[0.2, 0.2, 100001.0]], [[0.0, 0.0, -1.0]]),
    "margin-shrunk-grid": (
        np.array([[[0, 0, 1], [1e-4, 0, 1], [0, 0, 1.0001]]], np.float32), [[0.0, -2.0, 1.0001]], [[0.0, 1.0, 1e-30]]),
    "margin-unit-at-1e5": (
        _UNIT + np.float32([0, 0, 1e5]), [[0.0, -2.0, 1e5 + 1]], [[0.0, 1.0, 1e-30]]),
    "nearly-parallel-two-triangles": (_UNIT, [[0.0, -2.0, 1.0]], [[0.0, 1.0, 1e-30]]),
    "nearly-parallel-shrunk-bvh": (
        np.array([[[0, 0, 0], [0, 0, 0], [0, 0, 0]], [[0, 0, 0], [1e-4, 0, 0], [0, 1e-4, 0]]], np.float32),
        [[9.999999747378752e-05, 0.0, -0.00014142431609798223]], [[1.807675018979014e-43, 0.0, 1.0]]),
    "nearly-parallel-shrunk-kdtree": (
        np.array([[[0, 5e-5, 0]] * 3] * 8 + [[[0, 1e-4, 0], [0, 5e-5, 5e-5], [0, 5e-5, 0]]] + [[[0, 0, 0]] * 3] * 2,
                 np.float32), [[-2.0, 4.999999873689376e-05, 0.0]], [[1.0, -1.401298464324817e-45, 0.0]]),
    "nearly-parallel-kdtree-unit": (
        np.array([[[0, 2, 0], [0, 1, 1], [0, 1, 0]], [[0, 0, 0]] * 3], np.float32), [[-2.0, 1.0, 0.0]],
        [[1.0, -1e-30, 0.0]]),
    "subnormal-direction-beyond-float32": (
        np.array([[[1e-4, 0, 0]] * 3] * 6 + [[[0, 0, 0], [0, 1e-4, 0], [0, 0, 1e-4]]], np.float32),
        [[9.999999747378752e-05, 0.0, 0.0]], [[-1.401298464324817e-45, 0.0, 0.0]]),
    "axis-ray-beside-a-subnormal-vertex": (
        np.array([[[0, 0, 0]] * 3, [[0, 1e-4, 0]] * 3, [[0, 1e-4, 0], [0, 1.1210387714598537e-44, 0], [1e-10, 5e-5, 0]]],
                 np.float32), [[0.0, 0.0, -2.5000601453939453e-05]], [[0.0, 0.0, 1.0]]),
    "nearly-parallel-one-triangle": (
        np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], np.float32), [[1.0, 0.0, -1.0]], [[1e-20, 0.0, 1.0]]),
}


@pytest.mark.parametrize("case,structure", [(c, lab) for c in REGRESSIONS for lab in REGRESSION_STRUCTURES])
def test_regression_cases(case, structure):
    """Every structure on every regression case."""
    tris, o, d = REGRESSIONS[case]
    name, params = REGRESSION_STRUCTURES[structure]
    scene = Scene(tris, case, "regression", validate(tris, case))
    o, d = np.asarray(o, np.float32), np.asarray(d, np.float32)
    ref, ties = oracle_intersect(scene, o, d)
    assert (ref.tri_id >= 0).all()  # the premise: the oracle hits
    hits, _ = build(scene, name, **params).intersect(o, d, counters=False)
    assert (hits.tri_id == ref.tri_id).all() or (ties > 0).all(), (hits.tri_id, ref.tri_id)
    assert assert_agrees_exactly(hits, ref, ties, (name, params))["hits"] == len(o)

"""Tests of the hierarchies (tracer.accel.kdtree: pbrt-v2 SAH kd-tree; tracer.accel.bvh: binned-SAH BVH):
closest hits identical to the float64 brute-force oracle on every ray kind, any-hit queries,
counters, the counting/non-counting variants, and small or empty cases."""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from conftest import assert_agrees_exactly, transformed_scene

from tracer import build
from tracer.accel.oracle import oracle_intersect
from tracer.scenes.rays import KINDS, make_rays
from tracer.scenes.scene import Scene, load_scene

STRUCTURES = ("kdtree", "bvh")
SCENES = ("bunny-948", "cornell", "cylinder-196", "particles-2000")
NRAYS = 5000


@lru_cache(maxsize=None)
def scene(name: str) -> Scene:
    return load_scene(name)


@lru_cache(maxsize=None)
def accel(structure: str, name: str):
    return build(scene(name), structure)


@lru_cache(maxsize=None)
def rays(name: str, kind: str):
    return make_rays(scene(name), kind, NRAYS, seed=7)


@lru_cache(maxsize=None)
def oracle(name: str, kind: str):
    r = rays(name, kind)
    return oracle_intersect(scene(name), r.origins, r.directions)


@pytest.mark.parametrize("name", SCENES)
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("structure", STRUCTURES)
def test_closest_hits_match_oracle(structure, name, kind):
    r = rays(name, kind)
    hits, cnt = accel(structure, name).intersect(r.origins, r.directions)
    ref, ties = oracle(name, kind)
    # both call ray_triangle as the oracle does: t bit-identical on the oracle's triangle
    res = assert_agrees_exactly(hits, ref, ties, (structure, name, kind))
    assert res["hits"] > 0
    # tri ids are the scene's original indices: the hit triangle really is at that t
    h = hits.tri_id >= 0
    assert np.array_equal(hits.tri_id >= 0, ref.tri_id >= 0)
    assert np.all(hits.tri_id[h] < scene(name).n)
    # counters: one setup per ray meeting the root box, some work done
    tot = cnt.total()
    assert set(np.unique(cnt["setups"])) <= {0, 1}
    assert tot["setups"] > 0 and tot["tests"] > 0 and tot["nodes"] > 0 and tot["steps"] > 0
    assert np.all(cnt["nodes"] >= cnt["steps"])
    assert np.all(cnt["setups"][h] == 1)


@pytest.mark.parametrize("name", SCENES)
@pytest.mark.parametrize("structure", STRUCTURES)
def test_counting_variant_returns_identical_hits(structure, name):
    for kind in ("random", "adversarial"):
        r = rays(name, kind)
        a = accel(structure, name)
        h1, c1 = a.intersect(r.origins, r.directions, counters=True)
        h0, c0 = a.intersect(r.origins, r.directions, counters=False)
        assert c0 is None and c1 is not None
        assert np.array_equal(h1.tri_id, h0.tri_id)
        assert np.array_equal(h1.t, h0.t, equal_nan=True)


@pytest.mark.parametrize("name", SCENES)
@pytest.mark.parametrize("structure", STRUCTURES)
def test_occluded_matches_oracle_within_tmax(structure, name):
    rng = np.random.default_rng(3)
    for kind in ("random", "path"):
        r = rays(name, kind)
        ref, _ = oracle(name, kind)
        hit = ref.tri_id >= 0
        ext = float(np.linalg.norm(scene(name).bounds[1] - scene(name).bounds[0]))
        tmax = np.where(hit, ref.t * rng.uniform(0.5, 1.5, len(hit)), ext * rng.uniform(0.0, 2.0, len(hit)))
        tmax = tmax.astype(np.float32)
        want = oracle_intersect(scene(name), r.origins, r.directions, tmax=tmax)[0].tri_id >= 0
        got = accel(structure, name).occluded(r.origins, r.directions, tmax)
        assert got.dtype == bool
        assert np.array_equal(got, want), np.flatnonzero(got != want)[:10]
        assert 0 < want.sum() < hit.sum()  # the tmax cut really cut some hits


@pytest.mark.parametrize("structure", STRUCTURES)
def test_tmin_and_tmax_respected(structure):
    sc = scene("bunny-948")
    diag = float(np.linalg.norm(sc.bounds[1] - sc.bounds[0]))
    r = rays("bunny-948", "random")
    tmin, tmax = 0.45 * diag, 0.6 * diag
    ref, ties = oracle_intersect(sc, r.origins, r.directions, tmin=tmin, tmax=tmax)
    hits, _ = accel(structure, "bunny-948").intersect(r.origins, r.directions, tmin=tmin, tmax=tmax)
    res = assert_agrees_exactly(hits, ref, ties, structure)
    assert res["hits"] > 0, res
    assert np.all((hits.t[hits.tri_id >= 0] > tmin) & (hits.t[hits.tri_id >= 0] < tmax))


def test_kdtree_tests_far_below_n():
    sc = scene("bunny-948")
    r = rays("bunny-948", "random")
    _, cnt = accel("kdtree", "bunny-948").intersect(r.origins, r.directions)
    per_ray = cnt.mean()
    assert 0 < per_ray["tests"] < 0.1 * sc.n
    assert per_ray["nodes"] > per_ray["steps"] > 0


def test_kdtree_follows_pbrt_parameters():
    a = build(scene("bunny-948"), "kdtree", leaf_order=False)
    s = a.stats()
    # pbrt-v2: maxDepth = round(8 + 1.3 * Log2Int(948)) = round(8 + 1.3 * 9) = 20
    assert s["max_depth"] == 20 and s["depth"] <= 20
    assert s["params"] == {"isect_cost": 80.0, "trav_cost": 1.0, "empty_bonus": 0.5, "max_prims": 1}
    # every triangle is referenced; with leaf_order=False the vertices are the scene's, in scene order
    assert set(np.unique(a.tri_ids_)) == set(range(scene("bunny-948").n))
    assert np.array_equal(a.tri_verts_, scene("bunny-948").tris.reshape(-1, 9))
    assert s["leaves"] == s["interior"] + 1 and s["nodes"] == s["leaves"] + s["interior"]
    assert s["stored_nodes"] == s["nodes"] - s["empty_leaves"]


def test_kdtree_leaf_blocks_hold_each_leaf_four_at_a_time():
    """Leaves of two or more triangles as SoA blocks of four (simd_tri layout): every leaf's
    triangles in order, -1 and degenerate padding, and the closest hits still the oracle's."""
    from tracer.accel.kdtree import LEAF
    sc = scene("bunny-948")
    a = build(sc, "kdtree", max_prims=4, max_depth=14)
    w = a.nodes_[:, 0]
    multi = np.flatnonzero(((w & 3) == LEAF) & ((w >> 2) > 1))
    assert len(multi) > 50  # the premise: many leaves of several triangles
    blocks = a.blocks_.reshape(-1, 9, 4)  # (block, coordinate, lane)
    ids = a.block_ids_
    seen = 0
    for node in multi:
        cnt, first = int(w[node] >> 2), int(a.nodes_[node, 1])
        lanes = ids[first:first + (cnt + 3) // 4].reshape(-1)
        assert (lanes[:cnt] >= 0).all() and (lanes[cnt:] == -1).all()
        v = blocks[first:first + (cnt + 3) // 4].transpose(0, 2, 1).reshape(-1, 9)
        assert np.array_equal(v[:cnt], a.tri_verts_[lanes[:cnt]])
        assert (v[cnt:] == 0).all()  # degenerate padding
        seen += cnt
    assert seen == int((w[multi] >> 2).sum()) and len(ids) == sum((int(c) + 3) // 4 for c in w[multi] >> 2)
    r = rays("bunny-948", "random")
    hits, cnt = a.intersect(r.origins, r.directions)
    ref, ties = oracle("bunny-948", "random")
    assert_agrees_exactly(hits, ref, ties, "kdtree max_prims=4")
    hits2, _ = a.intersect(r.origins, r.directions, counters=False)
    assert np.array_equal(hits.t, hits2.t) and np.array_equal(hits.tri_id, hits2.tri_id)
    assert cnt.mean()["tests"] > 2 * accel("kdtree", "bunny-948").intersect(r.origins, r.directions)[1].mean()["tests"]


@pytest.mark.parametrize("structure", STRUCTURES)
def test_stats(structure):
    s = accel(structure, "particles-2000").stats()
    for key in ("nodes", "leaves", "depth", "refs", "memory_bytes", "build_s"):
        assert key in s, key
    assert s["nodes"] > s["leaves"] > 0 and s["depth"] > 0
    assert s["refs"] >= scene("particles-2000").n
    assert s["memory_bytes"] > 0 and s["build_s"] >= 0


# ---------------------------------------------------------------- small and empty cases
def _check(sc, o, d, structure):
    hits, cnt = build(sc, structure).intersect(o, d)
    ref, ties = oracle_intersect(sc, o, d)
    assert_agrees_exactly(hits, ref, ties, (structure, sc.name))
    return hits, cnt, ref


@pytest.mark.parametrize("structure", STRUCTURES)
def test_single_triangle(structure):
    sc = Scene(np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], np.float32), "one")
    r = make_rays(sc, "random", 2000, seed=1)
    extra = [[0.25, 0.25, 1.0], [0.25, 0.25, -1.0], [2.0, 2.0, 1.0]]
    o = np.concatenate([r.origins, extra]).astype(np.float32)
    d = np.concatenate([r.directions, [[0, 0, -1], [0, 0, 1], [0, 0, -1]]]).astype(np.float32)
    hits, _, ref = _check(sc, o, d, structure)
    assert list(hits.tri_id[-3:]) == [0, 0, -1]
    assert hits.t[-3] == pytest.approx(1.0) and hits.t[-2] == pytest.approx(1.0)
    assert (ref.tri_id >= 0).sum() > 0
    a = build(sc, structure)
    assert a.stats()["refs"] == 1
    assert list(a.occluded(o[-3:], d[-3:], tmax=[2.0, 0.5, 2.0])) == [True, False, False]


@pytest.mark.parametrize("structure", STRUCTURES)
def test_rays_that_miss_everything(structure):
    sc = scene("bunny-948")
    a = accel(structure, "bunny-948")
    c = (sc.bounds[0] + sc.bounds[1]) / 2
    ext = float((sc.bounds[1] - sc.bounds[0]).max())
    rng = np.random.default_rng(5)
    d = rng.normal(size=(500, 3)).astype(np.float32)
    # outside the scene, pointing away from it
    o = (c + 3 * ext * d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    # and rays parallel to an axis passing beside the box
    o2 = np.tile(c, (6, 1)).astype(np.float32)
    o2[:, 0] = sc.bounds[1][0] + ext
    d2 = np.tile(np.array([0, 1, 0], np.float32), (6, 1))
    o, d = np.concatenate([o, o2]), np.concatenate([d, d2])
    hits, cnt = a.intersect(o, d)
    assert np.all(hits.tri_id == -1) and np.all(np.isinf(hits.t))
    assert cnt.total()["setups"] == 0 and cnt.total()["tests"] == 0
    assert not a.occluded(o, d, tmax=np.full(len(o), 1e30)).any()
    # a ray that stops before the scene misses too
    r = rays("bunny-948", "random")
    short = a.occluded(r.origins, r.directions, tmax=np.full(len(r.origins), 1e-6 * ext))
    assert not short.any()


@pytest.mark.parametrize("structure", STRUCTURES)
def test_degenerate_scenes(structure):
    rng = np.random.default_rng(2)
    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    cases = {
        # many copies of one triangle: no plane separates them
        "copies": np.repeat(tri[None], 40, axis=0),
        # a flat scene: all triangles in the plane z = 0
        "flat": np.concatenate([rng.random((60, 3, 2)), np.zeros((60, 3, 1))], axis=2).astype(np.float32),
        # zero-area triangles beside real ones
        "slivers": np.concatenate([np.repeat(np.zeros((1, 3, 3), np.float32), 5, axis=0),
                                   rng.random((30, 3, 3)).astype(np.float32)]),
    }
    for name, tris in cases.items():
        sc = Scene(tris, name)
        r = make_rays(sc, "random", 1000, seed=4)
        hits, _, ref = _check(sc, r.origins, r.directions, structure)
        assert (ref.tri_id >= 0).sum() > 0, name


def test_empty_scene():
    sc = Scene(np.zeros((0, 3, 3), np.float32), "empty", bounds=np.array([[0, 0, 0], [1, 1, 1]], np.float32))
    o = np.zeros((4, 3), np.float32)
    d = np.tile(np.array([0, 0, 1], np.float32), (4, 1))
    for structure in STRUCTURES:
        a = build(sc, structure)
        hits, cnt = a.intersect(o, d)
        assert np.all(hits.tri_id == -1) and cnt.total()["tests"] == 0
        assert not a.occluded(o, d, tmax=1.0).any()


def _kd_splits(a):
    """(axis, split) of every interior node of a built kd-tree (see tracer.accel.kdtree's layout)."""
    w = a.nodes_[:, 0]
    inner = (w & 3) != 3
    return (w[inner] & 3).astype(np.int64), a.nodes_f_[inner, 1]


@pytest.mark.parametrize("placement", [(1.0, 1e5), (1e-3, 1e3)])
@pytest.mark.parametrize("name", ["bunny-948", "dragon-11k"])
def test_kdtree_rays_lying_in_split_planes(name, placement):
    """Rays lying exactly in a split plane (origin on it, zero direction component along its axis)
    visit both children with the parent's whole t-range; the far child waits on the todo stack
    beneath entries pushed later that start at larger t, so the stack is not ordered by entry t and
    the traversal must not stop at the first popped entry beyond the closest hit (it did: a nearer
    hit in the far child was lost and a farther triangle returned). Such a ray meets the far
    child's triangles only where they touch the plane, so the rays are aimed at triangle edges
    lying in a split plane: common on a mesh far from the origin (float32 coordinates 1/128 apart
    at 1e5), where the bug showed; the other half of the rays have random directions in the plane."""
    sc = transformed_scene(scene(name), *placement)
    a = build(sc, "kdtree")
    axis, split = _kd_splits(a)
    tris = sc.tris.astype(np.float64)
    targets, taxis = [], []
    for k in range(3):  # midpoints of the edges lying in a split plane of axis k
        planes = np.unique(split[axis == k])
        for i, j in ((0, 1), (1, 2), (2, 0)):
            on = (tris[:, i, k] == tris[:, j, k]) & np.isin(tris[:, i, k].astype(np.float32), planes)
            targets.append((tris[on, i] + tris[on, j]) / 2)
            taxis.append(np.full(on.sum(), k))
    targets, taxis = np.concatenate(targets), np.concatenate(taxis)
    assert len(targets) > 100, len(targets)
    rng = np.random.default_rng(8)
    m = 4000
    lo, hi = sc.bounds[0].astype(np.float64), sc.bounds[1].astype(np.float64)
    pick = rng.integers(0, len(targets), m // 2)
    rnd = rng.integers(0, len(axis), m - m // 2)
    ax = np.concatenate([taxis[pick], axis[rnd]])
    p = np.concatenate([targets[pick], lo + rng.random((len(rnd), 3)) * (hi - lo)])
    rows = np.arange(m)
    p[rows[len(pick):], ax[len(pick):]] = split[rnd]
    d = rng.normal(size=(m, 3))
    d[rows, ax] = 0.0
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    # from outside the mesh's box through p, so the rays cross many nodes before the plane's edges
    o = p - 2.0 * (hi - lo).max() * d
    o[rows, ax] = p[rows, ax]
    o, d = o.astype(np.float32), d.astype(np.float32)
    assert np.all(np.isin(o[rows, ax], split)) and np.all(d[rows, ax] == 0)
    ref, ties = oracle_intersect(sc, o, d)
    hits, _ = a.intersect(o, d)
    res = assert_agrees_exactly(hits, ref, ties, (name, placement))
    assert res["hits"] > m // 4, res


def test_padded_bounds_contain_the_triangle_and_a_pad_in_space():
    """The BVHs' boxes (tracer.accel.geometry.padded_bounds): float32, outside the exact bounds by
    BOX_PAD_REL of the scene's largest magnitude or more, also where a bound is a subnormal, and by
    no more than one float32 step beyond it."""
    from tracer.accel.geometry import BOX_PAD_REL, box_pad, padded_bounds
    tris = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]],
                     [[0, 1e-4, 0], [0, 1.1210387714598537e-44, 0], [1e-10, 5e-5, 0]],  # a subnormal vertex
                     [[-2, -1, 0.5], [2, 1, 0.25], [1, -1, 0.5]],                  # exponent boundaries
                     [[0, 0, 0]] * 3], np.float32)
    box = np.array([-2.0, -1.0, 0.0, 2.0, 1.0, 0.5])
    assert box_pad(box) == 2.0 * 2.0 ** -21 == BOX_PAD_REL * 2
    lo, hi = padded_bounds(tris, box)
    assert lo.dtype == np.float32 and hi.dtype == np.float32 and lo.shape == (4, 3)
    exact_lo, exact_hi = tris.min(axis=1).astype(np.float64), tris.max(axis=1).astype(np.float64)
    pad = 2.0 ** -20
    assert (exact_lo - lo >= pad).all() and (hi - exact_hi >= pad).all()
    assert (exact_lo - lo <= pad + np.spacing(np.abs(lo))).all()
    assert (hi - exact_hi <= pad + np.spacing(np.abs(hi))).all()
    assert lo[1, 1] == np.float32(-pad) and hi[3, 2] == np.float32(pad)
    # far from the origin the pad is a float32 step or more of the coordinates there
    far = tris[:1] + np.float32(1e5)
    flo, fhi = padded_bounds(far, np.array([1e5, 1e5, 1e5, 1e5 + 1, 1e5 + 1, 1e5]))
    assert fhi[0, 0] - np.float64(1e5 + 1) >= (1e5 + 1) * 2.0 ** -21 and fhi[0, 0] - (1e5 + 1) < 0.06


def test_kdtree_visits_both_children_within_the_pad_of_a_split_plane():
    """A ray along +x in the plane y = 1 descending at d_y = -1e-30 meets a triangle whose lowest
    vertex is on y = 1 by ray_triangle's rounding (exactly it passes below it); the kd-tree's split
    there puts the triangle above and the ray below after t = 0, and the band of box_pad around
    the plane sends it to both children: the oracle's hit, t = 2, on every kd-tree build."""
    tris = np.array([[[0, 2, 0], [0, 1, 1], [0, 1, 0]], [[0, 0, 0]] * 3], np.float32)
    sc = Scene(tris, "kd-band")
    o, d = np.float32([[-2.0, 1.0, 0.0]]), np.float32([[1.0, -1e-30, 0.0]])
    ref, _ = oracle_intersect(sc, o, d)
    assert ref.tri_id[0] == 0 and ref.t[0] == 2.0
    for kw in ({}, {"clip": True}, {"max_prims": 0}):
        hits, _ = build(sc, "kdtree", **kw).intersect(o, d, counters=False)
        assert hits.tri_id[0] == 0 and hits.t[0] == 2.0, kw

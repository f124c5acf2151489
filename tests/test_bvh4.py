"""Tests of the 4-wide BVH (tracer.accel.bvh4, float32 slab tests of four children per node) and of the
binary BVH's sign-ordered traversal (``order="sign"``): closest hits identical to the float64
brute-force oracle on all four ray kinds, also on a mesh far from the origin and on rays lying in
the planes of the node boxes; any-hit queries; the collapse keeps every binary leaf once."""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from conftest import assert_agrees_exactly, transformed_scene

from tracer import build
from tracer.accel.oracle import oracle_intersect
from tracer.scenes.rays import KINDS, make_rays
from tracer.scenes.scene import Scene, load_scene

#: (structure, params) of the variants under test
VARIANTS = {"bvh4": ("bvh4", {}), "bvh-sign": ("bvh", {"order": "sign"}),
            # the SAH weight bench's bvh4-sah-fit fits (about 1 here): a shallower tree, bigger leaves
            "bvh4-trav1": ("bvh4", {"trav_cost": 1.0})}
NRAYS = 3000


@lru_cache(maxsize=None)
def scene(name: str) -> Scene:
    if name == "bunny-far":  # unit bunny 1e5 from the origin: float32 coordinates 1/128 apart
        return transformed_scene(load_scene("bunny-948"), 1.0, 1e5)
    return load_scene(name)


@lru_cache(maxsize=None)
def accel(variant: str, name: str):
    structure, params = VARIANTS[variant]
    return build(scene(name), structure, **params)


@pytest.mark.parametrize("name", ["bunny-948", "cornell", "bunny-far"])
@pytest.mark.parametrize("variant", list(VARIANTS))
def test_closest_hits_match_oracle_all_kinds(variant, name):
    a = accel(variant, name)
    for kind in KINDS:
        r = make_rays(scene(name), kind, NRAYS, seed=11)
        hits, cnt = a.intersect(r.origins, r.directions)
        ref, ties = oracle_intersect(scene(name), r.origins, r.directions)
        res = assert_agrees_exactly(hits, ref, ties, (variant, name, kind))
        assert res["hits"] > 0, (variant, name, kind)
        h0, c0 = a.intersect(r.origins, r.directions, counters=False)
        assert c0 is None and np.array_equal(h0.tri_id, hits.tri_id) and np.array_equal(h0.t, hits.t)
        tot = cnt.total()
        assert tot["tests"] > 0 and tot["steps"] > 0 and np.all(cnt["nodes"] >= cnt["steps"])
        assert np.all(cnt["setups"][hits.tri_id >= 0] == 1)


def _plane_rays(a, sc, m, seed):
    """Rays lying in planes of the 4-wide nodes' child boxes: origin on a box face's plane, zero
    direction component along that axis (the slab products there are 0 * inf = NaN), aimed through
    the box face from outside the mesh."""
    rng = np.random.default_rng(seed)
    rec = a.nodes_f_[:, :24].reshape(-1, 6, 4)  # (node, [lo x y z, hi x y z], child)
    valid = a.nodes_[:, 28:] >= 0
    node, child = np.nonzero(valid)
    pick = rng.integers(0, len(node), m)
    boxes = rec[node[pick], :, child[pick]].astype(np.float64)  # (m, 6)
    ax = rng.integers(0, 3, m)
    side = rng.integers(0, 2, m)
    rows = np.arange(m)
    lo, hi = boxes[:, :3], boxes[:, 3:]
    p = lo + rng.random((m, 3)) * (hi - lo)
    p[rows, ax] = boxes[rows, ax + 3 * side]
    d = rng.normal(size=(m, 3))
    d[rows, ax] = 0.0
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    ext = float((sc.bounds[1] - sc.bounds[0]).max())
    o = p - 2.0 * ext * d
    o[rows, ax] = p[rows, ax]
    o, d = o.astype(np.float32), d.astype(np.float32)
    assert np.all(d[rows, ax] == 0)
    return o, d


@pytest.mark.parametrize("name", ["bunny-948", "bunny-far"])
def test_bvh4_rays_lying_in_box_planes(name):
    sc = scene(name)
    a = accel("bvh4", name)
    o, d = _plane_rays(a, sc, 3000, seed=3)
    ref, ties = oracle_intersect(sc, o, d)
    for variant in VARIANTS:
        hits, _ = accel(variant, name).intersect(o, d)
        res = assert_agrees_exactly(hits, ref, ties, (variant, name))
        assert res["hits"] > 300, res


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_occluded_matches_oracle_within_tmax(variant):
    sc = scene("bunny-948")
    rng = np.random.default_rng(4)
    r = make_rays(sc, "random", NRAYS, seed=5)
    ref, _ = oracle_intersect(sc, r.origins, r.directions)
    hit = ref.tri_id >= 0
    ext = float(np.linalg.norm(sc.bounds[1] - sc.bounds[0]))
    tmax = np.where(hit, ref.t * rng.uniform(0.5, 1.5, len(hit)), ext * rng.uniform(0, 2, len(hit))).astype(np.float32)
    want = oracle_intersect(sc, r.origins, r.directions, tmax=tmax)[0].tri_id >= 0
    got = accel(variant, "bunny-948").occluded(r.origins, r.directions, tmax)
    assert np.array_equal(got, want), np.flatnonzero(got != want)[:10]
    assert 0 < want.sum() < hit.sum()


def test_bvh4_collapse_keeps_every_leaf_once():
    a = accel("bvh4", "bunny-948")
    b = build(scene("bunny-948"), "bvh")
    cnt, ref = a.nodes_[:, 28:], a.nodes_[:, 24:28]
    leaf = cnt > 0
    # every binary leaf (offset, count) once; every 4-wide node but the root referenced once
    bin_leaves = b.nodes_[b.nodes_[:, 7] > 0][:, 6:8]
    assert sorted(zip(ref[leaf], cnt[leaf])) == sorted(map(tuple, bin_leaves))
    assert sorted(ref[cnt == 0]) == list(range(1, len(a.nodes_)))
    nchild = (cnt >= 0).sum(axis=1)
    assert nchild.min() >= 2 and nchild.max() == 4
    s = a.stats()
    assert s["leaves"] == len(bin_leaves) and s["nodes"] == len(a.nodes_)
    assert s["depth"] < s["binary_depth"] and s["memory_bytes"] == a.nodes_.nbytes + a.tri_ids_.nbytes + a.tri_verts_.nbytes
    assert a.nodes_.shape[1] * 4 == 128  # 128-byte nodes
    # a child box holds the boxes of its own children (SoA: [lo x y z, hi x y z] x 4 children)
    rec = a.nodes_f_[:, :24].reshape(-1, 6, 4)
    for n in range(len(a.nodes_)):
        for k in np.flatnonzero(cnt[n] == 0):
            c = ref[n, k]
            kids = rec[c][:, cnt[c] >= 0]
            assert np.all(kids[:3] >= rec[n, :3, k, None]) and np.all(kids[3:] <= rec[n, 3:, k, None])


def test_bvh4_small_and_empty_scenes():
    one = Scene(np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], np.float32), "one")
    o = np.array([[0.25, 0.25, 1.0], [0.25, 0.25, -1.0], [2.0, 2.0, 1.0]], np.float32)
    d = np.array([[0, 0, -1], [0, 0, 1], [0, 0, -1]], np.float32)
    a = build(one, "bvh4")
    hits, _ = a.intersect(o, d)
    assert list(hits.tri_id) == [0, 0, -1] and hits.t[0] == 1.0 and hits.t[1] == 1.0
    assert list(a.occluded(o, d, tmax=[2.0, 0.5, 2.0])) == [True, False, False]
    empty = Scene(np.zeros((0, 3, 3), np.float32), "empty", bounds=np.array([[0, 0, 0], [1, 1, 1]], np.float32))
    e = build(empty, "bvh4")
    hits, cnt = e.intersect(o, d)
    assert np.all(hits.tri_id == -1) and cnt.total()["tests"] == 0

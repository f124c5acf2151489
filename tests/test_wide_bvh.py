"""Tests of the wide BVH (tracer.accel.wide_bvh: 8 or 4 children per node from the host's CPU features,
leaves of four triangles tested together): closest hits identical to the float64 oracle on every
ray kind at both widths, also far from the origin and on rays lying in the child boxes' planes;
counting and non-counting variants identical; any-hit queries; the layout (every triangle once in
the blocks, degenerate padding, order words that are permutations in near-to-far split order)."""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from conftest import assert_agrees_exactly, transformed_scene

from tracer import build
from tracer.accel.oracle import oracle_intersect
from tracer.accel.wide_bvh import NORD, host_width
from tracer.scenes.rays import KINDS, make_rays
from tracer.scenes.scene import Scene, load_scene

NRAYS = 3000
WIDTHS = (8, 4)


@lru_cache(maxsize=None)
def scene(name: str) -> Scene:
    if name == "bunny-far":  # unit bunny 1e5 from the origin: float32 coordinates 1/128 apart
        return transformed_scene(load_scene("bunny-948"), 1.0, 1e5)
    return load_scene(name)


BOXES = ("float", "quant")


@lru_cache(maxsize=None)
def accel(name: str, width: int, max_leaf: int = 4, boxes: str = "float"):
    return build(scene(name), "wbvh", width=width, max_leaf=max_leaf, boxes=boxes)


@pytest.mark.parametrize("boxes", BOXES)
@pytest.mark.parametrize("name", ["bunny-948", "cornell", "bunny-far"])
@pytest.mark.parametrize("width", WIDTHS)
def test_closest_hits_match_oracle_all_kinds(width, name, boxes):
    a = accel(name, width, boxes=boxes)
    for kind in KINDS:
        r = make_rays(scene(name), kind, NRAYS, seed=11)
        hits, cnt = a.intersect(r.origins, r.directions)
        ref, ties = oracle_intersect(scene(name), r.origins, r.directions)
        res = assert_agrees_exactly(hits, ref, ties, (width, name, kind))
        assert res["hits"] > 0, (width, name, kind)
        h0, c0 = a.intersect(r.origins, r.directions, counters=False)
        assert c0 is None and np.array_equal(h0.tri_id, hits.tri_id) and np.array_equal(h0.t.view(np.int32),
                                                                                         hits.t.view(np.int32))
        tot = cnt.total()
        assert tot["tests"] > 0 and tot["steps"] > 0 and np.all(cnt["nodes"] >= cnt["steps"])
        assert np.all(cnt["setups"][hits.tri_id >= 0] == 1)
        # a leaf holds 1..4 triangles: tests per leaf visited within that range
        assert np.all(cnt["tests"] <= 4 * cnt["steps"]) and np.all(cnt["tests"] >= cnt["steps"])


def test_widths_and_leaf_sizes_agree_with_each_other():
    """Width 8 and 4, leaves of 1, 4 and 8 triangles: the same hits (t bits and ids) on random rays."""
    sc = scene("bunny-948")
    r = make_rays(sc, "random", NRAYS, seed=2)
    got = [accel("bunny-948", w, leaf).intersect(r.origins, r.directions, counters=False)[0]
           for w in WIDTHS for leaf in (1, 4, 8)]
    ref, ties = oracle_intersect(sc, r.origins, r.directions)
    for h in got:
        assert_agrees_exactly(h, ref, ties, "widths")
        assert np.array_equal(h.t.view(np.int32), got[0].t.view(np.int32))


def _plane_rays(a, sc, m, seed):
    """Rays lying in planes of the wide nodes' child boxes: origin on a box face's plane, zero
    direction component along that axis (the slab products there are 0 * inf = NaN), aimed through
    the box face from outside the mesh."""
    w = a.width_
    rng = np.random.default_rng(seed)
    rec = a.nodes_.view(np.float32)[:, :6 * w].reshape(-1, 6, w)
    node, child = np.nonzero(np.isfinite(rec[:, 0, :]))
    pick = rng.integers(0, len(node), m)
    boxes = rec[node[pick], :, child[pick]].astype(np.float64)
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
    return o.astype(np.float32), d.astype(np.float32)


@pytest.mark.parametrize("name", ["bunny-948", "bunny-far"])
@pytest.mark.parametrize("width", WIDTHS)
def test_rays_lying_in_box_planes(width, name):
    sc = scene(name)
    a = accel(name, width)
    o, d = _plane_rays(a, sc, 3000, seed=3)
    ref, ties = oracle_intersect(sc, o, d)
    for boxes in BOXES:  # the float boxes' planes; the quantised ones lie at or outside them
        res = assert_agrees_exactly(accel(name, width, boxes=boxes).intersect(o, d)[0], ref, ties, (width, name, boxes))
        assert res["hits"] > 300, res


@pytest.mark.parametrize("width", WIDTHS)
def test_occluded_matches_oracle_within_tmax(width):
    sc = scene("bunny-948")
    rng = np.random.default_rng(4)
    r = make_rays(sc, "random", NRAYS, seed=5)
    ref, _ = oracle_intersect(sc, r.origins, r.directions)
    hit = ref.tri_id >= 0
    ext = float(np.linalg.norm(sc.bounds[1] - sc.bounds[0]))
    tmax = np.where(hit, ref.t * rng.uniform(0.5, 1.5, len(hit)), ext * rng.uniform(0, 2, len(hit))).astype(np.float32)
    want = oracle_intersect(sc, r.origins, r.directions, tmax=tmax)[0].tri_id >= 0
    for boxes in BOXES:
        got = accel("bunny-948", width, boxes=boxes).occluded(r.origins, r.directions, tmax)
        assert np.array_equal(got, want), (boxes, np.flatnonzero(got != want)[:10])
    assert 0 < want.sum() < hit.sum()


def _leaf_of(word):
    v = -1 - int(word)
    return v >> 4, v & 15


@pytest.mark.parametrize("width", WIDTHS)
def test_layout(width):
    sc = scene("bunny-948")
    a = accel("bunny-948", width)
    w, nodes = a.width_, a.nodes_
    assert w == width and nodes.shape[1] == 7 * w + NORD
    boxes = nodes.view(np.float32)[:, :6 * w].reshape(-1, 6, w)
    child = nodes[:, 6 * w:7 * w]
    valid = np.isfinite(boxes[:, 0, :])
    # every wide node but the root is some node's interior child once; every triangle sits in one leaf lane
    assert sorted(child[valid & (child >= 0)]) == list(range(1, len(nodes)))
    ids = []
    for word in child[valid & (child < 0)]:
        b, cnt = _leaf_of(word)
        assert 1 <= cnt <= 4
        ids += list(a.ids4_[b, :cnt])
        assert np.all(a.ids4_[b, cnt:] == -1)
        blk = a.tri4_[b].reshape(3, 3, 4)  # (vertex, axis, lane)
        for lane in range(4):
            if lane < cnt:  # the SoA lane holds the triangle's vertices
                np.testing.assert_array_equal(blk[:, :, lane], sc.tris[a.ids4_[b, lane]])
            else:  # padding: three equal vertices
                assert np.all(blk[:, :, lane] == blk[0, :, lane])
    assert sorted(ids) == list(range(sc.n))
    # a child box holds its own children's boxes
    for n in range(len(nodes)):
        for k in np.flatnonzero(valid[n] & (child[n] > 0)):
            c = child[n, k]
            kids = boxes[c][:, valid[c]]
            assert np.all(kids[:3] >= boxes[n, :3, k, None]) and np.all(kids[3:] <= boxes[n, 3:, k, None])
    # order words: a permutation of the W slots, valid slots first; octants o and 7 - o (all
    # direction signs flipped) give reversed orders of the valid slots
    for n in range(len(nodes)):
        nv = int(valid[n].sum())
        orders = [[(int(nodes[n, 7 * w + o]) >> (3 * p)) & 7 for p in range(w)] for o in range(NORD)]
        for o in range(NORD):
            assert sorted(orders[o]) == list(range(w)) and set(orders[o][:nv]) == set(np.flatnonzero(valid[n]))
            assert orders[o][:nv] == orders[7 - o][:nv][::-1]
    s = a.stats()
    assert s["width"] == w and s["nodes"] == len(nodes) and s["memory_bytes"] == nodes.nbytes + a.tri4_.nbytes + a.ids4_.nbytes
    assert s["depth"] < build(sc, "bvh").stats()["depth"]


def test_width_follows_the_cpu():
    """Width 8 exactly when the CPU has AVX2 (/proc/cpuinfo read independently of llvmlite)."""
    try:
        with open("/proc/cpuinfo") as f:
            avx2 = " avx2" in f.read()
    except OSError:
        pytest.skip("no /proc/cpuinfo")
    assert host_width() == (8 if avx2 else 4)
    assert build(scene("bunny-948"), "wbvh").width_ == host_width()


def test_small_and_empty_scenes():
    one = Scene(np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], np.float32), "one")
    o = np.array([[0.25, 0.25, 1.0], [0.25, 0.25, -1.0], [2.0, 2.0, 1.0]], np.float32)
    d = np.array([[0, 0, -1], [0, 0, 1], [0, 0, -1]], np.float32)
    for w, boxes in ((w, b) for w in WIDTHS for b in BOXES):
        a = build(one, "wbvh", width=w, boxes=boxes)
        hits, _ = a.intersect(o, d)
        assert list(hits.tri_id) == [0, 0, -1] and hits.t[0] == 1.0 and hits.t[1] == 1.0
        assert list(a.occluded(o, d, tmax=[2.0, 0.5, 2.0])) == [True, False, False]
    empty = Scene(np.zeros((0, 3, 3), np.float32), "empty", bounds=np.array([[0, 0, 0], [1, 1, 1]], np.float32))
    hits, cnt = build(empty, "wbvh").intersect(o, d)
    assert np.all(hits.tri_id == -1) and cnt.total()["tests"] == 0


@pytest.mark.parametrize("name", ["bunny-948", "bunny-far", "cornell"])
@pytest.mark.parametrize("width", WIDTHS)
def test_quantised_boxes_hold_the_float_boxes(width, name):
    """Each decoded child box (g + float32(q) s, float32 roundings as the kernel's) holds its float32
    box; empty slots decode inverted and point to an empty leaf; child words and orders are the
    float records'. On random rays the quantised layout visits at least the float layout's nodes,
    and gives the same t bits and ids."""
    from tracer.accel.wide_quant import QMAX, child_word, order_byte, qnode_words
    f, q = accel(name, width), accel(name, width, boxes="quant")
    w, nodes, qn = f.width_, f.nodes_, q.qnodes_
    assert qn.shape == (len(nodes), qnode_words(w, NORD)) and qn.shape[1] == (32 if w == 8 else 22)
    boxes = nodes.view(np.float32)[:, :6 * w].reshape(-1, 6, w)
    valid = np.isfinite(boxes[:, 0, :])
    g = qn.view(np.float32)[:, 0:3]
    st = qn.view(np.float32)[:, 3:6]
    planes = qn.view(np.uint8)[:, 24:24 + 6 * w].reshape(-1, 6, w)
    dec = (np.tile(g, 2)[:, :, None] + planes.astype(np.float32) * np.tile(st, 2)[:, :, None]).astype(np.float32)
    assert dec.dtype == np.float32
    assert np.all(dec[:, :3][np.broadcast_to(valid[:, None], (len(qn), 3, w))]
                  <= boxes[:, :3][np.broadcast_to(valid[:, None], (len(qn), 3, w))])
    assert np.all(dec[:, 3:][np.broadcast_to(valid[:, None], (len(qn), 3, w))]
                  >= boxes[:, 3:][np.broadcast_to(valid[:, None], (len(qn), 3, w))])
    assert np.all(planes[:, :3][~np.broadcast_to(valid[:, None], (len(qn), 3, w))] == QMAX)
    assert np.all(planes[:, 3:][~np.broadcast_to(valid[:, None], (len(qn), 3, w))] == 0)
    cw = child_word(w)
    assert np.array_equal(qn[:, cw:cw + w][valid], nodes[:, 6 * w:7 * w][valid])
    assert np.all(qn[:, cw:cw + w][~valid] == -1)
    ob = qn.view(np.uint8)[:, order_byte(w):order_byte(w) + 3 * NORD].reshape(-1, NORD, 3).astype(np.int64)
    assert np.array_equal(ob[:, :, 0] | ob[:, :, 1] << 8 | ob[:, :, 2] << 16, nodes[:, 7 * w:])
    # a plane is at most one step (and float32 round-off) outside its float box
    wide = np.where(valid[:, None], boxes[:, 3:] - boxes[:, :3], 0)
    ulp = np.spacing(np.maximum(np.abs(dec[:, :3]), np.abs(dec[:, 3:])))
    assert np.all(((dec[:, 3:] - dec[:, :3]) - wide <= 2.01 * st[:, :, None] + 4 * ulp)[
        np.broadcast_to(valid[:, None], (len(qn), 3, w))])
    r = make_rays(scene(name), "random", NRAYS, seed=8)
    hf, cf = f.intersect(r.origins, r.directions)
    hq, cq = q.intersect(r.origins, r.directions)
    assert np.array_equal(hf.tri_id, hq.tri_id) and np.array_equal(hf.t.view(np.int32), hq.t.view(np.int32))
    assert np.all(cq["nodes"] >= cf["nodes"]) and np.all(cq["tests"] >= cf["tests"])
    assert cq.total()["nodes"] <= 1.5 * cf.total()["nodes"]  # a byte a plane: few extra visits
    assert q.stats()["memory_bytes"] < f.stats()["memory_bytes"] and q.stats()["boxes"] == "quant"


def test_quantised_layout_rejects_unknown_boxes():
    from tracer.errors import GridcostError
    with pytest.raises(GridcostError, match="boxes"):
        build(scene("bunny-948"), "wbvh", boxes="half")

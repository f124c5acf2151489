"""The perfect-split kd-tree build on clipped triangles (tracer.accel.kdtree_clip) and the fitted SAH
constants (costmodel.kdcost): closest hits identical to the float64 oracle on every ray kind (also
far from the origin, where float32 rays lie in split planes), the clipping itself, and the fit on
known constants. Small scenes and few rays: the cost is mostly the one compilation of the build."""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from conftest import assert_agrees_exactly, transformed_scene

from costmodel.kdcost import BvhSahFit, KdCostFit, fit_bvh_trav_cost, fit_sah_constants, kd_time_per_ray
from tracer import build
from tracer.errors import GridcostError
from tracer.accel.oracle import oracle_intersect
from tracer.scenes.rays import KINDS, make_rays
from tracer.scenes.scene import Scene, load_scene

SCENES = ("bunny-948", "cornell", "particles-2000")
#: the clip build with pbrt's constants, and with a small isect:trav (as fitted) and a deeper budget
SETTINGS = ({"clip": True}, {"clip": True, "isect_cost": 4.0, "max_depth": 40},
            {"clip": True, "extra_depth": 2, "leaf_order": True})
NRAYS = 2000


@lru_cache(maxsize=None)
def scene(name: str) -> Scene:
    if name == "bunny-948-far":  # unit bunny 1e5 from the origin: float32 rays in split planes
        return transformed_scene(load_scene("bunny-948"), 1.0, 1e5)
    if name == "soup":  # random triangles with segments, points, duplicates and a planar patch
        t = np.random.default_rng(1).uniform(0, 1, (300, 3, 3)).astype(np.float32)
        t[:20, 2] = t[:20, 1]
        t[20:40] = t[40:60]
        t[60:80, :, 2] = 0.5
        t[80:90] = t[80:90, [0]]
        return Scene(t, "soup")
    return load_scene(name)


@lru_cache(maxsize=None)
def rays_and_oracle(name: str, kind: str):
    r = make_rays(scene(name), kind, NRAYS, seed=11)
    return r, oracle_intersect(scene(name), r.origins, r.directions)


@pytest.mark.parametrize("setting", range(len(SETTINGS)))
@pytest.mark.parametrize("name", SCENES + ("bunny-948-far", "soup"))
def test_clip_build_matches_oracle_on_every_kind(name, setting):
    kd = build(scene(name), "kdtree", **SETTINGS[setting])
    for kind in KINDS:
        r, (ref, ties) = rays_and_oracle(name, kind)
        hits, cnt = kd.intersect(r.origins, r.directions)
        res = assert_agrees_exactly(hits, ref, ties, (name, SETTINGS[setting], kind))
        assert res["hits"] > 0
        h0, _ = kd.intersect(r.origins, r.directions, counters=False)
        assert np.array_equal(h0.tri_id, hits.tri_id) and np.array_equal(h0.t, hits.t)
        assert np.all(cnt["nodes"] >= cnt["steps"])
        occ = kd.occluded(r.origins, r.directions, tmax=np.where(np.isfinite(ref.t), ref.t * 1.001, 1.0))
        assert np.all(occ[ref.tri_id >= 0])
    st = kd.stats()
    assert st["clip"] is True and st["depth"] <= st["max_depth"]
    # every triangle is referenced by some leaf
    assert set(np.unique(kd.tri_ids_).tolist()) | set(_inline_ids(kd)) >= set(range(scene(name).n))


def test_leaf_order_returns_scene_ids():
    """Triangles stored in leaf order: the same hits (scene ids) as the scene-order tree, pbrt build."""
    s = scene("bunny-948")
    r, (ref, ties) = rays_and_oracle("bunny-948", "random")
    a, b = build(s, "kdtree", leaf_order=False), build(s, "kdtree", leaf_order=True)
    ha, _ = a.intersect(r.origins, r.directions)
    hb, _ = b.intersect(r.origins, r.directions)
    assert np.array_equal(ha.tri_id, hb.tri_id) and np.array_equal(ha.t, hb.t)
    assert not np.array_equal(b.tri_verts_, a.tri_verts_)
    assert np.array_equal(np.sort(b.tri_order_[:-1]), np.arange(s.n)) and b.tri_order_[-1] == -1
    assert np.array_equal(b.tri_verts_, s.tris.reshape(-1, 9)[b.tri_order_[:-1]])


def _inline_ids(kd):
    w = kd.nodes_[:, 0]
    one = ((w & 3) == 3) & ((w >> 2) == 1)
    return kd.nodes_[one, 1].tolist()


def test_clipping_tightens_references_and_tree():
    """On a mesh of slanted triangles clipping removes references whose box overlaps a leaf but
    whose surface does not: fewer refs per triangle and a lower SAH cost than pbrt's build at the
    same depth budget."""
    s = scene("bunny-948")
    pbrt, clip = build(s, "kdtree"), build(s, "kdtree", clip=True)
    assert clip.stats()["refs_per_tri"] < pbrt.stats()["refs_per_tri"]
    assert clip.stats()["sah_cost"] < pbrt.stats()["sah_cost"]


def test_clip_bounds_of_a_triangle():
    from tracer.accel.kdtree_clip import _clip_bounds
    tv = np.array([[0, 0, 0, 1, 0, 0, 0, 1, 0]], np.float32)
    poly, out = np.empty((2, 10, 3)), np.empty(6)
    assert _clip_bounds(tv, 0, np.array([0.5, 0, -1, 1, 1, 1.0]), poly, out)
    assert np.allclose(out, [0.5, 0, 0, 1, 0.5, 0])
    # inside the triangle's bounding box, off its surface (x + y > 1)
    assert not _clip_bounds(tv, 0, np.array([0.6, 0.6, -1, 1, 1, 1.0]), poly, out)


def test_cost_fit_recovers_known_constants():
    rng = np.random.default_rng(0)
    X = np.column_stack([rng.uniform(10, 40, 30), rng.uniform(2, 8, 30), rng.uniform(0.5, 6, 30)])
    y = kd_time_per_ray(X[:, 0], X[:, 1], X[:, 2], 4.0, 3.0, 20.0, 15.0)
    fit = KdCostFit().fit(X, y)
    assert fit.ti_over_tt_ == pytest.approx(5.0, rel=1e-6)
    assert fit.c_leaf_ == pytest.approx(3.0, rel=1e-6) and fit.c_0_ == pytest.approx(15.0, rel=1e-6)
    assert fit.metrics_["r2"] == pytest.approx(1.0)
    pts = [{"nodes": a, "leaves": b, "tests": c, "s_per_ray": t * 1e-9} for (a, b, c), t in zip(X, y)]
    f2 = fit_sah_constants(pts)
    assert f2.ti_over_tt_ == pytest.approx(5.0, rel=1e-6)
    kd = build(scene("cornell"), "kdtree", constants=f2, clip=True)
    assert kd.stats()["params"]["isect_cost"] == pytest.approx(5.0) and kd.stats()["params"]["trav_cost"] == 1.0


def test_bvh_sah_fit_recovers_the_weight_per_kind():
    """Synthetic points with c_node / c_test = 2 (random) and 0.5 (camera): each kind's ratio comes
    back, and the weight is their geometric mean, 1."""
    rng = np.random.default_rng(1)
    pts = []
    for kind, cn, ct in (("random", 20.0, 10.0), ("camera", 6.0, 12.0)):
        for _ in range(12):
            nodes, tests = rng.uniform(10, 60), rng.uniform(1, 10)
            pts.append({"scene": "s", "kind": kind, "nodes": nodes, "leaves": 1.0, "tests": tests,
                        "s_per_ray": (cn * nodes + ct * tests) * 1e-9})
    fit = fit_bvh_trav_cost(pts)
    assert fit.ratios_["random"] == pytest.approx(2.0, rel=1e-6) and fit.ratios_["camera"] == pytest.approx(0.5, rel=1e-6)
    assert fit.trav_cost_ == pytest.approx(1.0, rel=1e-6) and fit.mape_["random"] == pytest.approx(0.0, abs=1e-6)
    assert fit.summary()["camera_c_test_ns"] == pytest.approx(12.0, rel=1e-6)


def test_bvh_sah_fit_refuses_a_free_test():
    """Times that do not grow with the tests (c_test fitted 0) never give a zero or infinite weight:
    with no kind fitted, strict raises a clear error and the default falls back to the tracer's
    build weight (pbrt-v2's 1/8) and says so; when another ray kind fits, the weight is that kind's,
    and the kind left out is named."""
    free = [{"scene": "s", "kind": "camera", "nodes": n, "leaves": 1.0, "tests": t, "s_per_ray": 5e-9 * n}
            for n, t in ((10, 3), (20, 1), (30, 4), (40, 2))]
    with pytest.raises(GridcostError, match="came out free for every ray kind"):
        BvhSahFit(strict=True).fit(free)
    with pytest.raises(GridcostError, match="came out free for every ray kind"):
        fit_bvh_trav_cost(free, strict=True)
    fb = BvhSahFit().fit(free)
    assert fb.fallback_ and fb.trav_cost_ == 0.125 and fb.summary()["fallback"] is True
    assert "NO ray kind fitted, so the weight is the tracer's default 0.125" in fb.note()
    assert BvhSahFit(default=0.5).fit(free).trav_cost_ == 0.5
    good = [{"scene": "s", "kind": "random", "nodes": n, "leaves": 1.0, "tests": t, "s_per_ray": (20 * n + 10 * t) * 1e-9}
            for n, t in ((10, 3), (20, 1), (30, 4), (40, 2))]
    fit = BvhSahFit().fit(good + free)
    assert fit.trav_cost_ == pytest.approx(2.0, rel=1e-6) and set(fit.ratios_) == {"random"}
    assert set(fit.free_) == {"camera"} and fit.free_["camera"][1] < 1e-6 * fit.free_["camera"][0]
    assert "camera-ray fit left out: a test came out free" in fit.note()
    assert fit.summary()["kinds_left_out"] == ["camera"] and BvhSahFit().fit(good).note() == ""
    assert not fit.fallback_ and "NO ray kind" not in fit.note()

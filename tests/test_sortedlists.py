"""Sorted event lists (tracer.accel.sortedlists, Fournier & Poulin 1993) against the float64 oracle, their
counters, and the SPD-style scene generators (tracer.scenes.spd)."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_agrees_exactly

from tracer.scenes import spd
from tracer.accel import COUNTER_NAMES, build
from tracer.errors import GridcostError
from tracer.accel.oracle import oracle_intersect
from tracer.scenes.rays import KINDS, make_rays
from tracer.accel.sortedlists import SortedLists

N_RAYS = 3000
#: small SPD scenes the oracle can afford (and that exercise the floor/field polygons)
SPD_SMALL = ("sphereflake-1", "tetra-4", "gears-1", "tree-3")
SCENES = ("bunny-948", "cornell", "cylinder-196", "particles-2000") + SPD_SMALL

_CACHE: dict = {}


def scene_for(load, name):
    key = ("scene", name)
    if key not in _CACHE:
        _CACHE[key] = spd.spd_scene(name) if spd.matches(name) else load(name)
    return _CACHE[key]


def rays_and_oracle(scene, kind):
    key = ("rays", scene.name, kind)
    if key not in _CACHE:
        rays = make_rays(scene, kind, N_RAYS, seed=11)
        _CACHE[key] = (rays, oracle_intersect(scene, rays.origins, rays.directions))
    return _CACHE[key]


def structures(scene):
    key = ("sl", scene.name)
    if key not in _CACHE:
        _CACHE[key] = (SortedLists(hierarchy=True).build(scene), SortedLists(hierarchy=False).build(scene))
    return _CACHE[key]


# ---------------------------------------------------------------- oracle agreement
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("name", SCENES)
def test_agrees_with_oracle(load, name, kind):
    scene = scene_for(load, name)
    rays, (ref, ties) = rays_and_oracle(scene, kind)
    per_variant = []
    for acc in structures(scene):
        hits, counters = acc.intersect(rays.origins, rays.directions)
        # ray_triangle called as the oracle calls it: t bit-identical on the oracle's triangle
        res = assert_agrees_exactly(hits, ref, ties, (name, kind, acc.hierarchy))
        if kind in ("camera", "random", "adversarial"):
            assert res["hits"] > 0
        # the separately compiled variant without counters gives bit-identical hits
        plain, none = acc.intersect(rays.origins, rays.directions, counters=False)
        assert none is None
        np.testing.assert_array_equal(plain.tri_id, hits.tri_id)
        np.testing.assert_array_equal(plain.t, hits.t)
        # any hit: occluded before just past the closest hit, never on a miss
        hit = ref.tri_id >= 0
        tmax = np.where(hit, ref.t * (1 + 1e-5) + 1e-12, np.inf).astype(np.float32)
        np.testing.assert_array_equal(acc.occluded(rays.origins, rays.directions, tmax), hit)
        # counters: one row per ray, a setup per ray, events treated, tests only on entered boxes
        assert counters.data.shape == (rays.n, len(COUNTER_NAMES))
        assert (counters["setups"] == 1).all()
        assert (counters["skips"] <= counters["steps"]).all()
        assert (counters["steps"][hit] > 0).all() and (counters["tests"][hit] >= 1).all()
        assert (counters["nodes"][hit] >= 1).all()
        assert counters.mean()["steps"] > 0
        per_variant.append(counters)
    # the hierarchy changes the events, never the triangle tests: both test exactly the triangles
    # whose (padded) boxes the ray enters before the closest hit (the paper's minimality claim)
    np.testing.assert_array_equal(per_variant[0]["tests"], per_variant[1]["tests"])


@pytest.mark.parametrize("name", ["bunny-948", "tetra-4"])
def test_tmin_tmax(load, name):
    scene = scene_for(load, name)
    rays, _ = rays_and_oracle(scene, "random")
    acc = structures(scene)[0]
    rng = np.random.default_rng(3)
    tmax = (rng.random(rays.n) * 2 * np.linalg.norm(scene.bounds[1] - scene.bounds[0])).astype(np.float32)
    for tmin in (0.0, 0.05):
        hits, _ = acc.intersect(rays.origins, rays.directions, tmin=tmin, tmax=tmax)
        ref, ties = oracle_intersect(scene, rays.origins, rays.directions, tmin=tmin, tmax=tmax)
        assert_agrees_exactly(hits, ref, ties, (name, tmin))


# ---------------------------------------------------------------- counters
def test_work_is_far_below_n_with_the_hierarchy(load):
    scene = load("particles-10000")
    rays = make_rays(scene, "random", 2000, seed=2)
    acc = SortedLists().build(scene)
    hits, counters = acc.intersect(rays.origins, rays.directions)
    m = counters.mean()
    assert 0 < m["tests"] < 5, m  # tests per ray << N = 10,000
    assert 0 < m["steps"] < 0.05 * scene.n, m
    assert m["nodes"] > 1
    # without the hierarchy every ray walks a good part of the 6 N events (the paper's Table 1)
    flat = SortedLists(hierarchy=False).build(scene)
    fh, fc = flat.intersect(rays.origins[:200], rays.directions[:200])
    assert fc.mean()["steps"] > 0.5 * scene.n
    np.testing.assert_array_equal(fc["tests"], counters["tests"][:200])
    np.testing.assert_array_equal(fh.tri_id >= 0, hits.tri_id[:200] >= 0)


def test_build_factory_params_and_stats(load):
    scene = load("bunny-948")
    acc = build(scene, "sortedlists", leaf_size=4, branching=(2, 3, 2))
    assert isinstance(acc, SortedLists)
    st = acc.stats()
    assert st["structure"] == "sortedlists" and st["nodes"] > 1 and st["leaves"] >= 1
    assert st["slots"] == scene.n + st["nodes"] - 1  # every triangle and every non-root BV once
    assert st["events"] == 6 * st["slots"]
    assert st["memory_bytes"] > 0 and st["depth"] >= 2
    assert sorted(acc.slot_tri_[acc.slot_tri_ >= 0].tolist()) == list(range(scene.n))
    flat = SortedLists(hierarchy=False).build(scene).stats()
    assert flat["nodes"] == 1 and flat["root_children"] == scene.n
    for bad in (dict(branching=0), dict(branching=1), dict(leaf_size=0), dict(branching=(2, 2, 99))):
        with pytest.raises(GridcostError):
            SortedLists(**bad).build(scene)


def test_events_sorted_per_node(load):
    acc = SortedLists().build(load("cornell"))
    cs = acc.child_start_
    for p in range(len(cs) - 1):
        a, m = cs[p], cs[p + 1] - cs[p]
        for k in range(3):
            v = acc.ev_val_[6 * a + 2 * m * k: 6 * a + 2 * m * (k + 1)]
            assert (np.diff(v) >= 0).all()
            codes = acc.ev_code_[6 * a + 2 * m * k: 6 * a + 2 * m * (k + 1)]
            assert sorted(codes.tolist()) == sorted([2 * s + h for s in range(a, a + m) for h in (0, 1)])


# ---------------------------------------------------------------- SPD scenes
@pytest.mark.parametrize("name,count,objects", [
    ("sphereflake-1", 2 + 48 * 10, 11), ("sphereflake-2", 2 + 48 * 91, 92), ("tetra-1", 4, 4),
    ("tetra-5", 1024, 1024), ("gears-1", 2 + 576, 147), ("gears-2", 2 + 576 * 8, 1169),
    ("tree-1", 2 + 40 * 3, 7), ("tree-6", 2 + 40 * 127, 255),
])
def test_spd_counts_and_determinism(name, count, objects):
    a = spd.spd_scene(name)
    b = spd.spd_scene(name)
    assert a.tris.dtype == np.float32 and a.tris.shape == (count, 3, 3)
    assert a.n == spd.spd_triangles(name) and spd.spd_objects(name) == objects
    np.testing.assert_array_equal(a.tris, b.tris)
    assert np.isfinite(a.tris).all()
    t = a.tris.astype(np.float64)
    area = np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
    assert (area > 0).all()  # no degenerate triangles (poles, seams)


def test_spd_sizes_and_shapes():
    for name in spd.names():
        assert spd.spd_triangles(name) <= 200_000, name
    assert max(spd.spd_triangles(n) for n in spd.names()) > 150_000
    c, r = spd.sphereflake_spheres(2)
    assert len(c) == 91 and r.max() == 0.5 and np.isclose(r.min(), 0.5 / 9)
    # the 9 children of the top sphere: 3 above, 6 round the equator, all touching the parent
    dirs = spd.flake_directions()
    assert (dirs[:, 2] > 0.5).sum() == 3 and (np.abs(dirs[:, 2]) < 0.05).sum() == 6
    np.testing.assert_allclose(np.linalg.norm(c[1:10], axis=1), 0.5 * 4 / 3)
    tet = spd.tetra(3).reshape(-1, 3)
    assert np.allclose(tet.min(0), -1) and np.allclose(tet.max(0), 1)
    o, d = spd.spd_camera_rays("tetra-5", 8, 6)
    assert o.shape == d.shape == (48, 3) and np.allclose(np.linalg.norm(d, axis=1), 1, atol=1e-6)
    for bad in ("tetra-0", "tetra-9", "sphereflake-5", "gears-8", "cube-2", "tree"):
        with pytest.raises(GridcostError):
            spd.spd_scene(bad)

"""Tests of tracer.accel.nested (two-level and d-level grids, Ize, Shirley & Parker 2007 Sec. 4):
oracle agreement for closest and any hit, counters, per-level counts, cell counts, memory guard."""
from __future__ import annotations

import functools

import numpy as np
import pytest
from conftest import assert_agrees_exactly

from tracer.accel import build
from tracer.errors import GridcostError
from tracer.accel.grid import UniformGrid, res_from_cells
from tracer.accel.nested import NestedGrid, res_many
from tracer.accel.oracle import oracle_intersect
from tracer.scenes.rays import KINDS, adversarial_rays, make_rays
from tracer.scenes.scene import load_scene

SCENES = ("bunny-948", "cornell", "cylinder-196", "particles-2000", "dragon-11k")
NRAYS = 5000


@functools.lru_cache(maxsize=None)
def scene(name):
    return load_scene(name)


@functools.lru_cache(maxsize=None)
def rays_and_oracle(name, kind):
    s = scene(name)
    r = make_rays(s, kind, NRAYS, seed=7)
    ref, ties = oracle_intersect(s, r.origins, r.directions)
    return r.origins, r.directions, ref, ties


@functools.lru_cache(maxsize=None)
def nested(name, levels, **kw):
    return NestedGrid(levels=levels, **kw).build(scene(name))


@pytest.mark.parametrize("levels", [2, 3])
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("name", SCENES)
def test_closest_hit_agrees_with_oracle(name, kind, levels):
    o, d, ref, ties = rays_and_oracle(name, kind)
    g = nested(name, levels)
    hits, cnt = g.intersect(o, d)
    # every level calls ray_triangle as the oracle does: t bit-identical on the oracle's triangle
    assert_agrees_exactly(hits, ref, ties, (name, kind, levels))
    hits2, none = g.intersect(o, d, counters=False)  # the variant compiled without counting code
    assert none is None
    np.testing.assert_array_equal(hits2.tri_id, hits.tri_id)
    np.testing.assert_array_equal(hits2.t, hits.t)


@pytest.mark.parametrize("name", ["bunny-948", "dragon-11k", "cylinder-196"])
def test_rays_along_top_and_sub_grid_planes(name):
    """Adversarial rays exactly along the planes of the top grid and of a typical sub-grid."""
    s = scene(name)
    g = nested(name, 2)
    sub = np.asarray(g.level_stats_[1]["res_max"]) * g.res1_ if len(g.level_stats_) > 1 else g.res1_
    for res in (g.res1_, sub):
        r = adversarial_rays(s, 2000, seed=3, res=res)
        hits, _ = g.intersect(r.origins, r.directions)
        assert_agrees_exactly(hits, *oracle_intersect(s, r.origins, r.directions), (name, res))


@pytest.mark.parametrize("levels", [2, 3])
@pytest.mark.parametrize("name", SCENES)
def test_occluded_agrees_with_oracle(name, levels):
    o, d, ref, _ = rays_and_oracle(name, "random")
    o2, d2, ref2, _ = rays_and_oracle(name, "path")
    o, d = np.concatenate([o, o2]), np.concatenate([d, d2])
    t_ref = np.concatenate([ref.t, ref2.t])
    hit = np.concatenate([ref.tri_id, ref2.tri_id]) >= 0
    rng = np.random.default_rng(1)
    factor = rng.choice([0.5, 1.5, np.inf], len(o))
    s = scene(name)
    far = 4.0 * float(np.linalg.norm(s.bounds[1] - s.bounds[0]))
    tmax = np.where(hit, t_ref * factor, np.where(factor > 1, far, 0.5 * far)).astype(np.float32)
    occ = nested(name, levels).occluded(o, d, tmax)
    np.testing.assert_array_equal(occ, hit & (factor > 1))


@pytest.mark.parametrize("name", ["bunny-948", "dragon-11k"])
def test_counters_and_levels(name):
    o, d, ref, _ = rays_and_oracle(name, "random")
    hit = ref.tri_id >= 0
    means = []
    for levels in (1, 2, 3):
        g = nested(name, levels)
        _, cnt = g.intersect(o, d)
        su = cnt["setups"]
        assert (su[hit] >= 1).all()
        # every sub-grid entered is one set-up beyond the top grid's
        np.testing.assert_array_equal(cnt["nodes"], np.maximum(su - 1, 0))
        assert (cnt["steps"][hit] >= su[hit]).all()
        assert (cnt["tests"][hit] >= 1).all()
        assert (cnt["skips"] == 0).all()
        lv = g.intersect_levels(o, d)
        for k in ("setups", "steps", "tests"):
            assert lv[k].shape == (len(o), levels)
            np.testing.assert_array_equal(lv[k].sum(axis=1), cnt[k])
            assert len(lv["mean"][k]) == levels
        np.testing.assert_array_equal(lv["hit"], hit)
        np.testing.assert_array_equal(lv["setups"][:, 0], (su > 0).astype(np.int32))
        means.append(su[hit].mean())
    assert means[0] == 1.0
    assert means[0] < means[1] < means[2]


def test_one_level_is_the_uniform_grid():
    s = scene("bunny-948")
    o, d, _, _ = rays_and_oracle("bunny-948", "random")
    g = NestedGrid(levels=1, m1=8 * s.n).build(s)
    u = UniformGrid(cells=8 * s.n).build(s)
    (h1, c1), (h2, c2) = g.intersect(o, d), u.intersect(o, d)
    np.testing.assert_array_equal(h1.tri_id, h2.tri_id)
    np.testing.assert_array_equal(h1.t, h2.t)
    for k in ("setups", "steps", "tests"):
        np.testing.assert_array_equal(c1[k], c2[k])
    assert g.stats()["cells"] == u.stats()["cells"]


def test_cell_counts_follow_ize_rule():
    """dragon-11k with M1 = (8N)^0.6, M2 = 8 N2: the top grid is ~1% of a one-level 8N grid, the
    total cell count is M1 + sum of 8 N2 over refined cells (Ize 2007 Table 4 scale, ~10-20 N)."""
    s = scene("dragon-11k")
    g = nested("dragon-11k", 2)
    st = g.stats()
    n = s.n
    assert st["M1"] == int(np.prod(res_from_cells(s.bounds, (8 * n) ** 0.6)))
    assert st["M1"] < 0.02 * 8 * n
    top, sub = st["per_level"]
    assert top["cells"] == st["M1"] and sub["grids"] == top["child_cells"]
    # sum of 8 N2 over refined cells, N2 = refs of the level-1 cells that got a sub-grid
    refined_refs = top["refs"] - top["leaf_refs"]
    assert 0.7 * 8 * refined_refs < sub["cells"] < 1.3 * 8 * refined_refs
    assert st["cells"] == top["cells"] + sub["cells"]
    assert st["cells"] < 20 * n
    assert st["memory_bytes"] > 0 and st["build_s"] >= 0 and st["levels"] == 2
    # the long-skinny rule (Eq 17: M1 = k N Ti/Ts = 4N with k = 1, Ti/Ts = 4) and an explicit M1
    assert NestedGrid(m1_rule="ize_skinny").build(s).stats()["M1_target"] == 4 * n
    assert NestedGrid(m1=1000).build(s).stats()["M1_target"] == 1000


def test_scales_and_depth_rules_change_resolutions():
    s = scene("bunny-948")
    base = nested("bunny-948", 2).stats()
    big = NestedGrid(m1_scale=2.0, m2_scale=1.5).build(s).stats()
    assert big["M1"] > 5 * base["M1"]
    assert big["per_level"][1]["res_mean"][0] > base["per_level"][1]["res_mean"][0]
    eq = NestedGrid(levels=3, depth_rule="eq16").build(s).stats()
    assert eq["M1_target"] == pytest.approx((8 * s.n) ** (3 / 7))
    lin = nested("bunny-948", 3).stats()
    assert eq["cells"] < lin["cells"]


def test_res_many_matches_res_from_cells():
    rng = np.random.default_rng(0)
    ext = rng.random((200, 3)) * 10 ** rng.uniform(-3, 1, (200, 1)) + 1e-6
    cells = rng.integers(1, 5000, 200)
    got = res_many(ext, cells)
    for k in range(200):
        np.testing.assert_array_equal(got[k], res_from_cells(np.array([np.zeros(3), ext[k]]), cells[k]))


def test_memory_budget_error(monkeypatch):
    monkeypatch.setenv("GRIDCOST_MEMORY_BUDGET", "2K")
    with pytest.raises(GridcostError, match=r"would need about [0-9.]+ (KiB|MiB)"):
        NestedGrid(levels=2).build(scene("dragon-11k"))


def test_factory_and_bad_parameters():
    s = scene("cornell")
    g = build(s, "nested", levels=3)
    assert isinstance(g, NestedGrid) and g.stats()["levels"] == 3
    for kw in (dict(levels=0), dict(levels=2.5), dict(m1_rule="nope"), dict(m1_rule="cells"),
               dict(m2_factor=-1), dict(m1_scale=0), dict(depth_rule="x")):
        with pytest.raises(GridcostError):
            NestedGrid(**kw).build(s)

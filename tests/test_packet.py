"""Coherent grid traversal (tracer.accel.packet) against the float64 oracle, its work counters, and the
packet cost model (costmodel.packet). Kept to two compiled kernel variants (counting / not, with
macrocells) so a cold run stays well under a minute."""
from __future__ import annotations

import numpy as np
import pytest

from costmodel.packet import COLUMNS, PacketCostFit, best_config
from tracer.accel import COUNTER_NAMES, build
from tracer.errors import GridcostError
from tracer.accel.grid import UniformGrid
from tracer.accel.oracle import compare, oracle_intersect
from tracer.accel.packet import PACKET_COUNTERS, CoherentGrid, slot_order
from tracer.accel.packet_kernels import BATCH, BOX
from tracer.scenes.rays import camera_rays, make_rays

PACKETS = (1, 2, 4, 8, 16, 32)  # 32: 1,024 rays, 128 groups of 8 (two bitmasks of 64)
VIEWS = ((0.55, 0.45, 0.7), (1.0, 0.0, 0.0), (-0.3, 0.2, -1.0))  # oblique, axis-aligned, from below
SIDE = 32

_ORACLE: dict = {}


def oracle(scene, o, d, key, tmax=None):
    if key not in _ORACLE:
        _ORACLE[key] = oracle_intersect(scene, o, d, tmax=tmax)
    return _ORACLE[key]


def ray_sets(scene, k):
    """(label, origins, directions) for camera rays tiled for k x k packets and incoherent rays."""
    for v in VIEWS:
        r = camera_rays(scene, SIDE, SIDE, tile=k, eye_dir=v)
        yield f"camera{v}-tile{k}", r.origins, r.directions
    for kind in ("random", "adversarial"):
        r = make_rays(scene, kind, 600, seed=3)
        yield kind, r.origins, r.directions


@pytest.mark.parametrize("k", PACKETS)
def test_cgt_agrees_with_oracle(small_scene, k):
    scene = small_scene
    cgt = CoherentGrid(packet=k).build(scene)
    for label, o, d in ray_sets(scene, k):
        ref, ties = oracle(scene, o, d, (scene.name, label))
        hits, cnt = cgt.intersect(o, d)
        res = compare(hits, ref, ties)
        assert res["disagreements"] == 0, (scene.name, k, label, res)
        # the non-counting variant (separately compiled) gives bit-identical hits
        plain, none = cgt.intersect(o, d, counters=False)
        assert none is None
        np.testing.assert_array_equal(plain.tri_id, hits.tri_id)
        np.testing.assert_array_equal(plain.t, hits.t)
        assert cnt.data.shape == (len(o), len(COUNTER_NAMES))


@pytest.mark.parametrize("variant", [dict(mailbox=False, frustum_cull=False), dict(exact=False, lam=1.0)])
def test_variants_agree_and_occlusion(bunny, variant):
    """Mailboxing/culling off, bounding-box insertion at another lambda; and any-hit queries."""
    cgt = CoherentGrid(packet=4, **variant).build(bunny)
    for label, o, d in ray_sets(bunny, 4):
        ref, ties = oracle(bunny, o, d, (bunny.name, label))
        assert compare(cgt.intersect(o, d, counters=False)[0], ref, ties)["disagreements"] == 0, label
        tmax = np.where(ref.tri_id >= 0, ref.t * 0.999, 1e30).astype(np.float32)
        ref_occ, _ = oracle(bunny, o, d, (bunny.name, label, "occ"), tmax=tmax)
        np.testing.assert_array_equal(cgt.occluded(o, d, tmax), ref_occ.tri_id >= 0)


@pytest.mark.parametrize("res", [(1, 1, 1), (2, 1, 1)])
def test_references_past_one_batch(bunny, res):
    """A grid of one or two cells holds more references per cell than one batch of
    :func:`tracer.accel.packet_kernels._gather` takes, so batches split inside a cell: every
    reference is still tested once per packet, so hits and mailbox counts stay right."""
    cgt = CoherentGrid(packet=8, res=res).build(bunny)
    assert np.diff(cgt.cell_start_).max() > BATCH
    r = camera_rays(bunny, SIDE, SIDE, tile=8)
    ref, ties = oracle(bunny, r.origins, r.directions, (bunny.name, "camera-tile8"))
    pc = cgt.packet_counters(r.origins, r.directions)
    assert compare(pc["hits"], ref, ties)["disagreements"] == 0
    live = pc["slices"] > 0
    assert live.any() and (pc["considered"][live] > BATCH).all()
    # with one reference per triangle and cell, a packet tests each triangle it meets at most once:
    # tests with mailboxing are at most (triangles) x (rays); without, the references' count
    assert (pc["tests_mb"] <= bunny.n * pc["packet_rays"]).all()
    assert (pc["tests_mb"] < pc["tests_plain"]).any() == (np.prod(res) > 1)


@pytest.mark.parametrize("k", (4, 8, 16))
def test_slot_order_groups_are_4x2_blocks(k):
    """Each group of 8 slots of a k x k packet is a 4 x 2 block of the tile (row-major pixels):
    a permutation, 4 adjacent columns and 2 adjacent rows per group."""
    o = slot_order(k)
    assert sorted(o.tolist()) == list(range(k * k))
    for g in range(k * k // 8):
        y, x = np.divmod(o[g * 8:(g + 1) * 8], k)
        assert (x.max() - x.min(), y.max() - y.min()) == (3, 1), (k, g, x, y)
    np.testing.assert_array_equal(slot_order(5), np.arange(25))  # no 4 x 2 blocks fit: row-major


def test_ray_order_within_packets_changes_no_hit(bunny):
    """Rays reach their slots through slot_order (and retired slots are refilled), so results are
    written back by ray id: shuffling the rays inside every packet moves each ray's hit with it."""
    r = camera_rays(bunny, SIDE, SIDE, tile=8)
    cgt = CoherentGrid(packet=8).build(bunny)
    base, _ = cgt.intersect(r.origins, r.directions, counters=False)
    rng = np.random.default_rng(5)
    perm = np.concatenate([b + rng.permutation(64) for b in range(0, r.n, 64)])
    hits, _ = cgt.intersect(r.origins[perm], r.directions[perm], counters=False)
    assert (base.tri_id >= 0).sum() > r.n // 8
    np.testing.assert_array_equal(hits.tri_id, base.tri_id[perm])
    np.testing.assert_array_equal(hits.t, base.t[perm])


@pytest.mark.parametrize("where", ((1.0, 0.0), (1.0, 1e5), (1e-3, 1e3)))
def test_ref_boxes_hold_every_vertex(far_scene, where):
    """Each triangle's row holds its vertices, then a float32 box (packet_kernels.ref_boxes)
    that holds the float64 grid-space coordinates (v - lo) * cells/extent of those vertices, the
    ones the packet's frame computes, also on meshes far from the origin, where float32 rounding is
    coarsest; and the box is tight: within a few float32 ulps of them."""
    scene = far_scene("bunny-948", *where)
    cgt = CoherentGrid(packet=8).build(scene)
    gp = cgt.gp_
    v = cgt.tri_verts_[:, :BOX].reshape(-1, 3, 3).astype(np.float64)
    g = (v - gp[:3]) * gp[6:9]
    lo, hi = g.min(axis=1), g.max(axis=1)
    box = cgt.tri_verts_[:, BOX:BOX + 6].astype(np.float64)
    np.testing.assert_array_equal(cgt.tri_verts_[:, :BOX], scene.tris.reshape(-1, 9))
    assert len(box) == scene.n < cgt.refs_ and np.prod(cgt.res_) > 1
    assert (box[:, 0::2] <= lo).all() and (box[:, 1::2] >= hi).all()
    ulp = np.spacing(np.abs(np.stack([lo, hi], axis=2)).astype(np.float32)).astype(np.float64)
    assert (lo - box[:, 0::2] <= 2 * ulp[..., 0]).all() and (box[:, 1::2] - hi <= 2 * ulp[..., 1]).all()


def test_build_factory_and_bad_parameters(bunny):
    acc = build(bunny, "cgt", packet=4, lam=2.0)
    assert isinstance(acc, CoherentGrid) and acc.stats()["structure"] == "cgt"
    for bad in (dict(packet=0), dict(packet=2.5), dict(lam=-1.0), dict(macro=-1)):
        with pytest.raises(GridcostError):
            CoherentGrid(**bad)


def test_counters(bunny):
    """Mailboxing and frustum culling cut ray-triangle tests; packets visit fewer cells per ray
    than single rays on the same grid; per-ray counters sum to the per-packet ones."""
    r = camera_rays(bunny, 64, 64, tile=4)
    cgt = CoherentGrid(packet=4, macro=6).build(bunny)
    pc = cgt.packet_counters(r.origins, r.directions)
    assert set(PACKET_COUNTERS) <= set(pc)
    plain, mb, fc = pc["tests_plain"].sum(), pc["tests_mb"].sum(), pc["tests_mb_fc"].sum()
    assert plain > 1.2 * mb > 0, (plain, mb)
    assert mb > 1.2 * fc > 0, (mb, fc)
    # both on: the group frusta then test a triangle on the groups of 8 rays it may meet only
    # (culling pauses while a packet is down to one vector of rays)
    assert pc["tests"].sum() < fc, (pc["tests"].sum(), fc)
    cnt = pc["counters"]
    assert cnt["tests"].sum() == pc["tests"].sum()
    assert cnt["steps"].sum() == pc["cells"].sum()
    assert cnt["nodes"].sum() == pc["slices"].sum()
    assert (pc["single"] == 0).all()  # coherent camera rays never fall back
    # switching a technique off makes the traversal test what the counters predicted
    off = CoherentGrid(packet=4, macro=6, frustum_cull=False).build(bunny).packet_counters(r.origins, r.directions)
    assert off["tests"].sum() == mb
    off = CoherentGrid(packet=4, macro=6, mailbox=False, frustum_cull=False).build(bunny)
    assert off.packet_counters(r.origins, r.directions)["tests"].sum() == plain
    # cells per ray: 8 x 8 packets < 4 x 4 packets < single rays (same grid, no macrocells there)
    single = UniformGrid(res=cgt.res_, exact=True).build(bunny)
    _, sc = single.intersect(r.origins, r.directions)
    r8 = camera_rays(bunny, 64, 64, tile=8)
    pc8 = CoherentGrid(packet=8, macro=6).build(bunny).packet_counters(r8.origins, r8.directions)
    cells1, cells4, cells8 = sc["steps"].mean(), pc["cells"].sum() / r.n, pc8["cells"].sum() / r.n
    assert cells8 < cells4 < cells1, (cells1, cells4, cells8)
    # 8 x 8 packets: a small triangle meets one or two 4 x 2 blocks of the tile, so the group frusta
    # leave well under the packet culling's tests (bunny-948: 19,680 against 53,584; 26,793 when the
    # groups were rows of 8)
    assert pc8["tests"].sum() < 0.45 * pc8["tests_mb_fc"].sum()


def test_random_rays_fall_back(bunny):
    r = make_rays(bunny, "random", 2048, seed=1)
    pc = CoherentGrid(packet=8).build(bunny).packet_counters(r.origins, r.directions)
    assert pc["single"].sum() > 0.5 * r.n  # incoherent packets are traced ray by ray


def test_packet_cost_fit_recovers_constants():
    rng = np.random.default_rng(0)
    true = np.array([400.0, 30.0, 6.0, 0.8])  # T_setup, T_slice, T_cell, T_test (ns)
    rows = []
    for k in (1, 2, 4, 8, 16, 32):
        for lam in (0.5, 1, 2, 5, 10, 20):
            packets = 1.0 / k**2
            slices = packets * 10 * lam ** (1 / 3)
            cells = slices * (1 + 0.3 * k) ** 2 * lam ** (2 / 3) / 3
            tests = 3 + 0.4 * k / lam ** (1 / 3)
            rows.append((packets, slices, cells, tests))
    X = np.array(rows)
    y = X @ true * (1 + 0.002 * rng.standard_normal(len(X)))
    fit = PacketCostFit().fit(X, y)
    np.testing.assert_allclose(fit.coef_, true, rtol=0.05)
    assert fit.metrics_["r2"] > 0.999
    for name, value in zip(("t_setup", "t_slice", "t_cell", "t_test"), true):
        lo, hi = fit.ci_[name]
        assert lo <= value * 1.05 and hi >= value * 0.95, (name, lo, hi)
    np.testing.assert_allclose(fit.predict(X), X @ fit.coef_)
    # the best configuration of a table of counted work is the argmin of the prediction
    import pandas as pd
    df = pd.DataFrame(X, columns=list(COLUMNS))
    df["packet"] = np.repeat([1, 2, 4, 8, 16, 32], 6)
    df["lam"] = np.tile([0.5, 1, 2, 5, 10, 20], 6)
    best, table = best_config(fit, df)
    i = int(np.argmin(X @ true))
    assert (best["packet"], best["lam"]) == (df.packet[i], df.lam[i])
    assert len(table) == len(df)


def test_packet_cost_fit_ray_term_and_shares():
    rng = np.random.default_rng(1)
    ks = np.repeat([1, 2, 4, 8, 16], 4)
    X = np.column_stack([1.0 / ks**2, 8.0 / ks, 20.0 / ks + rng.random(len(ks)), 2 + ks * rng.random(len(ks))])
    true = np.array([300.0, 20.0, 8.0, 1.5, 25.0])  # ... and 25 ns per ray
    y = np.column_stack([X, np.ones(len(X))]) @ true
    fit = PacketCostFit(ray_term=True, n_boot=50).fit(X, y)
    np.testing.assert_allclose(fit.coef_, true, rtol=1e-6)
    assert fit.t_ray_ == pytest.approx(25.0)
    shares = fit.shares(X)
    assert set(shares) == {"t_setup", "t_slice", "t_cell", "t_test", "t_ray"}
    assert sum(shares.values()) == pytest.approx(1.0)
    assert fit.packet_time(0, 0, 0) == pytest.approx(300.0)
    with pytest.raises(ValueError):
        PacketCostFit().fit(X[:, :3], y)

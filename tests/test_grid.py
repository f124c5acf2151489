"""Uniform grid (tracer.accel.grid) against the float64 oracle, its counters and resolution rules, the memory
guard, and the geometry kernels (tracer.accel.geometry) it is built on."""
from __future__ import annotations

import itertools

import numpy as np
import pytest
from conftest import assert_agrees_exactly

from tracer.accel import COUNTER_NAMES, Hits, build
from tracer.errors import GridcostError
from tracer.accel.geometry import ray_box, ray_triangle, tri_box_overlap
from tracer.accel.grid import UniformGrid, res_from_cells, res_pbrt, res_wald
from tracer.accel.oracle import compare, oracle_intersect
from tracer.scenes.rays import KINDS, make_rays
from tracer.scenes.scene import Scene

N_RAYS = 2000
VARIANTS = {"exact": dict(exact=True, mailbox=False), "exact-mailbox": dict(exact=True, mailbox=True),
            "bbox": dict(exact=False, mailbox=False), "bbox-mailbox": dict(exact=False, mailbox=True),
            "index": dict(layout="index"), "index-mailbox": dict(layout="index", mailbox=True),
            "copy": dict(layout="copy"), "blocks-mailbox": dict(layout="blocks", mailbox=True)}

_RAYS: dict = {}
_ORACLE: dict = {}


def rays_for(scene, kind, n=N_RAYS, seed=7):
    key = (scene.name, kind, n, seed)
    if key not in _RAYS:
        _RAYS[key] = make_rays(scene, kind, n, seed=seed)
    return _RAYS[key]


def oracle_for(scene, rays, tmax=None, tag=""):
    key = (scene.name, rays.kind, rays.n, rays.seed, tag)
    if key not in _ORACLE:
        _ORACLE[key] = oracle_intersect(scene, rays.origins, rays.directions, tmax=tmax)
    return _ORACLE[key]


# ---------------------------------------------------------------- oracle agreement
@pytest.mark.parametrize("variant", list(VARIANTS))
@pytest.mark.parametrize("kind", KINDS)
def test_grid_agrees_with_oracle(small_scene, kind, variant):
    scene = small_scene
    grid = UniformGrid(**VARIANTS[variant]).build(scene)
    rays = rays_for(scene, kind)
    hits, counters = grid.intersect(rays.origins, rays.directions)
    ref, ties = oracle_for(scene, rays)
    # the grid calls ray_triangle as the oracle does: t bit-identical on the oracle's triangle
    res = assert_agrees_exactly(hits, ref, ties, (scene.name, kind, variant))
    assert res["rays"] == rays.n
    if kind in ("camera", "random", "adversarial"):
        assert res["hits"] > 0
    # the non-counting variant (separately compiled) gives bit-identical hits
    plain, none = grid.intersect(rays.origins, rays.directions, counters=False)
    assert none is None
    np.testing.assert_array_equal(plain.tri_id, hits.tri_id)
    np.testing.assert_array_equal(plain.t, hits.t)
    # counters: one row per ray, setups only for rays meeting the box, skips only with mailboxing
    assert counters.data.shape == (rays.n, len(COUNTER_NAMES))
    assert set(np.unique(counters["setups"])) <= {0, 1}
    assert (counters["steps"][counters["setups"] == 0] == 0).all()
    assert (counters["steps"][counters["setups"] == 1] >= 1).all()
    assert (hits.tri_id[counters["setups"] == 0] == -1).all()
    if not grid.mailbox:
        assert (counters["skips"] == 0).all()


#: macrocell block sizes (``macro`` = K: blocks of K^3 cells) and the cell counts (per triangle)
#: they are tried at: the default grid, and a fine one where most blocks are empty
MACROS = (2, 4)
MACRO_FACTORS = (None, 16)


@pytest.mark.parametrize("factor", MACRO_FACTORS)
@pytest.mark.parametrize("macro", MACROS)
@pytest.mark.parametrize("kind", KINDS)
def test_macrocell_grid_agrees_with_oracle(small_scene, kind, macro, factor):
    """The macrocell layer (empty K^3 blocks jumped over, the DDA set up again at the block's exit)
    against the oracle on every ray kind, with and without mailboxing: the same hits, bit for bit,
    as the oracle and as the grid without macrocells, and real jumps taken."""
    scene = small_scene
    rays = rays_for(scene, kind)
    ref, ties = oracle_for(scene, rays)
    plain = UniformGrid(factor=factor).build(scene)
    base, _ = plain.intersect(rays.origins, rays.directions, counters=False)
    jumps = 0
    empty_blocks = 0
    for mailbox in (False, True):
        grid = build(scene, "grid", macro=macro, factor=factor, mailbox=mailbox)
        assert grid.macro == macro and grid.stats()["cells"] == plain.stats()["cells"]
        empty_blocks = int((grid.macro_ == 0).sum())
        hits, counters = grid.intersect(rays.origins, rays.directions)
        assert_agrees_exactly(hits, ref, ties, (scene.name, kind, macro, factor, mailbox))
        np.testing.assert_array_equal(hits.tri_id, base.tri_id)
        np.testing.assert_array_equal(hits.t, base.t)
        fast, none = grid.intersect(rays.origins, rays.directions, counters=False)
        assert none is None
        np.testing.assert_array_equal(fast.tri_id, hits.tri_id)
        np.testing.assert_array_equal(fast.t, hits.t)
        jumps += int(counters.total()["jumps"])
        assert counters.total()["nodes"] == 0  # no column holds another meaning
        # any hit: occluded just past the closest hit, never on a miss
        hit = ref.tri_id >= 0
        tmax = np.where(hit, ref.t * (1 + 1e-5) + 1e-12, np.inf).astype(np.float32)
        np.testing.assert_array_equal(grid.occluded(rays.origins, rays.directions, tmax), hit)
    if factor is not None and kind != "camera" and empty_blocks > 0.1 * len(grid.macro_):
        assert jumps > 0  # the fine grid has empty blocks, and rays jump over them


def test_hits_format(bunny):
    grid = UniformGrid().build(bunny)
    rays = rays_for(bunny, "random")
    hits, _ = grid.intersect(rays.origins, rays.directions)
    assert hits.t.dtype == np.float32 and hits.tri_id.dtype == np.int32
    miss = hits.tri_id < 0
    assert miss.any() and (~miss).any()
    assert np.isinf(hits.t[miss]).all() and (hits.tri_id[miss] == -1).all()
    assert (hits.t[~miss] > 0).all() and (hits.tri_id[~miss] < bunny.n).all()


def test_build_factory_and_stats(bunny):
    grid = build(bunny, "grid", cells=8 * bunny.n)
    st = grid.stats()
    assert st["cells"] == int(np.prod(st["res"]))
    assert st["refs"] >= bunny.n  # every triangle is in at least one cell
    assert st["memory_bytes"] > 0
    bbox = build(bunny, "grid", cells=8 * bunny.n, exact=False)
    assert bbox.stats()["refs"] >= st["refs"]  # exact assignment never adds references


@pytest.mark.parametrize("variant", ["exact", "bbox-mailbox"])
def test_grid_agrees_at_other_resolutions(bunny, variant):
    rays = rays_for(bunny, "adversarial")
    ref, ties = oracle_for(bunny, rays)
    for kw in (dict(factor=1), dict(factor=64), dict(rule="pbrt"), dict(rule="wald"), dict(res=(1, 1, 1)),
               dict(res=(7, 3, 11))):
        hits, _ = UniformGrid(**kw, **VARIANTS[variant]).build(bunny).intersect(rays.origins, rays.directions)
        assert_agrees_exactly(hits, ref, ties, kw)


def test_flat_single_triangle_scene():
    scene = Scene(np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], np.float32), "flat")
    grid = UniformGrid().build(scene)
    for kind in KINDS:
        rays = make_rays(scene, kind, 500, seed=1)
        hits, _ = grid.intersect(rays.origins, rays.directions)
        ref, ties = oracle_intersect(scene, rays.origins, rays.directions)
        assert compare(hits, ref, ties)["disagreements"] == 0, kind
    # straight down onto the triangle and beside it
    o = np.array([[0.25, 0.25, 1], [0.75, 0.75, 1], [0.5, 0.5, 1]], np.float32)
    d = np.array([[0, 0, -1]] * 3, np.float32)
    hits, _ = grid.intersect(o, d)
    assert hits.tri_id.tolist() == [0, -1, 0]
    np.testing.assert_allclose(hits.t[[0, 2]], 1.0)


# ---------------------------------------------------------------- ties


def _dup_scene(bunny, reverse: bool):
    """bunny-948 with its first 100 faces appended again (same vertices; reversed winding if asked)."""
    extra = bunny.tris[:100, ::-1] if reverse else bunny.tris[:100]
    return Scene(np.concatenate([bunny.tris, extra]), "bunny-dup-rev" if reverse else "bunny-dup")


def _rays_at_first_faces(scene, k=100, seed=3):
    rng = np.random.default_rng(seed)
    target = scene.tris[:k].astype(np.float64).mean(axis=1)
    lo, hi = scene.bounds.astype(np.float64)
    o = (lo + hi) / 2 + np.linalg.norm(hi - lo) * rng.normal(size=(k, 3))
    return o.astype(np.float32), (target - o).astype(np.float32)


def _check_duplicates(scene):
    grid = UniformGrid().build(scene)
    o, d = _rays_at_first_faces(scene)
    hits, _ = grid.intersect(o, d)
    ref, ties = oracle_intersect(scene, o, d)
    res = compare(hits, ref, ties)
    assert res["disagreements"] == 0, res
    dup_hit = (ref.tri_id >= 0) & (ref.tri_id < 100)
    assert dup_hit.sum() > 20
    assert (ties[dup_hit] >= 1).all(), ties[dup_hit]  # the oracle sees the copy at the same t
    return ref, ties, dup_hit


def test_duplicate_faces_ties_no_disagreement(bunny):
    scene = _dup_scene(bunny, reverse=False)
    ref, ties, dup_hit = _check_duplicates(scene)
    grid = UniformGrid(mailbox=True).build(scene)
    for kind in KINDS:
        rays = make_rays(scene, kind, 1000, seed=2)
        h, _ = grid.intersect(rays.origins, rays.directions)
        r, tt = oracle_intersect(scene, rays.origins, rays.directions)
        assert compare(h, r, tt)["disagreements"] == 0, kind
    # a structure that returns the other copy at the same t: a tie, counted apart, not a disagreement
    swapped = np.where(dup_hit, ref.tri_id + scene.n - 100, ref.tri_id).astype(np.int32)
    res = compare(Hits(ref.t.astype(np.float32), swapped), ref, ties)
    assert res["disagreements"] == 0
    assert res["ties"] == int(dup_hit.sum()) > 0
    # ... whereas another triangle where the oracle saw no tie is an id mismatch
    single = (ref.tri_id >= 100) & (ref.tri_id < scene.n - 100) & (ties == 0)
    wrong = np.where(single, (ref.tri_id + 1) % scene.n, ref.tri_id).astype(np.int32)
    res = compare(Hits(ref.t.astype(np.float32), wrong), ref, ties)
    assert res["id_mismatch"] == int(single.sum()) == res["disagreements"] > 0
    assert res["ties"] == 0


def test_duplicate_faces_reversed_winding_are_ties(bunny):
    _check_duplicates(_dup_scene(bunny, reverse=True))


def test_duplicate_faces_reversed_winding_no_disagreement(bunny):
    scene = _dup_scene(bunny, reverse=True)
    grid = UniformGrid().build(scene)
    o, d = _rays_at_first_faces(scene)
    hits, _ = grid.intersect(o, d)
    ref, ties = oracle_intersect(scene, o, d)
    assert compare(hits, ref, ties)["disagreements"] == 0


def _t_float64(o, d, tri):
    """Reference t in float64 (numpy solve of o + t d = a + u (b - a) + v (c - a))."""
    a, b, c = np.asarray(tri, np.float64)
    M = np.column_stack([-np.asarray(d, np.float64), b - a, c - a])
    return np.linalg.solve(M, np.asarray(o, np.float64) - a)[0]


def test_ray_triangle_float32_inputs_computed_in_float64():
    tri = np.array([[0.1, 0.2, 0.3], [1.7, 0.4, 0.9], [0.3, 1.9, 0.2]], np.float32)
    o = np.array([0.5, 0.6, 3.3], np.float32)
    d = (tri.astype(np.float64).mean(0) - o).astype(np.float32)
    t64 = ray_triangle(*map(float, o), *map(float, d), *map(float, tri.ravel()), 0.0, np.inf)
    ref = _t_float64(o, d, tri)
    assert t64 == pytest.approx(ref, rel=1e-12)  # float64 arguments: fine
    t32 = ray_triangle(*o, *d, *tri.ravel(), 0.0, np.inf)  # float32 arguments, as every kernel passes
    assert t32 == pytest.approx(ref, rel=1e-12)


def test_oracle_t_is_float64_accurate(bunny):
    rays = rays_for(bunny, "random")
    ref, _ = oracle_for(bunny, rays)
    hit = np.flatnonzero(ref.tri_id >= 0)[:200]
    expected = np.array([_t_float64(rays.origins[i], rays.directions[i], bunny.tris[ref.tri_id[i]]) for i in hit])
    np.testing.assert_allclose(ref.t[hit], expected, rtol=1e-10)


# ---------------------------------------------------------------- counters
def _mean_counters(scene, rays, **kw):
    grid = UniformGrid(**kw).build(scene)
    _, c = grid.intersect(rays.origins, rays.directions)
    return c.mean(), c


def test_steps_grow_with_resolution(bunny):
    rays = rays_for(bunny, "random", 5000, seed=0)
    m1, _ = _mean_counters(bunny, rays, cells=bunny.n)
    m8, _ = _mean_counters(bunny, rays, cells=8 * bunny.n)
    m64, _ = _mean_counters(bunny, rays, cells=64 * bunny.n)
    assert m64["steps"] > m8["steps"] > m1["steps"]
    assert m64["tests"] < m8["tests"] < m1["tests"]
    # steps per ray ~ m = M^(1/3): 64x the cells is 4x the cells per axis
    ratio = m64["steps"] / m1["steps"]
    assert 2.5 <= ratio <= 5.5, ratio
    assert m1["setups"] == m8["setups"] == m64["setups"] > 0


def test_mailbox_reduces_tests_and_records_skips(bunny, cylinder):
    for scene in (bunny, cylinder):
        rays = rays_for(scene, "random")
        for exact in (True, False):
            off, c_off = _mean_counters(scene, rays, exact=exact, mailbox=False)
            on, c_on = _mean_counters(scene, rays, exact=exact, mailbox=True)
            assert on["tests"] < off["tests"]
            assert on["skips"] > 0 and off["skips"] == 0
            # same walk; every reference met is either tested or skipped
            np.testing.assert_array_equal(c_on["steps"], c_off["steps"])
            np.testing.assert_array_equal(c_on["tests"] + c_on["skips"], c_off["tests"])


@pytest.mark.parametrize("variant", ["exact", "bbox-mailbox"])
def test_occluded_agrees_with_oracle_within_tmax(small_scene, variant):
    scene = small_scene
    grid = UniformGrid(**VARIANTS[variant]).build(scene)
    rays = rays_for(scene, "random")
    diam = float(np.linalg.norm(scene.bounds[1] - scene.bounds[0]))
    tmax = (np.random.default_rng(11).random(rays.n) * diam).astype(np.float32)
    ref, _ = oracle_for(scene, rays, tmax=tmax, tag="tmax")
    occ = grid.occluded(rays.origins, rays.directions, tmax)
    assert occ.dtype == bool and occ.shape == (rays.n,)
    np.testing.assert_array_equal(occ, ref.tri_id >= 0)
    assert occ.any() and (~occ).any()
    # closest hit with the same tmax agrees too
    hits, _ = grid.intersect(rays.origins, rays.directions, tmax=tmax)
    np.testing.assert_array_equal(hits.tri_id >= 0, occ)


# ---------------------------------------------------------------- resolution rules
BOUNDS = {
    "cube": [[0, 0, 0], [1, 1, 1]],
    "slab": [[-1, -2, 0], [3, 2, 1]],
    "long": [[0, 0, 0], [10, 3, 1]],
    "bunny": [[-0.0931, 0.0336, -0.0566], [0.0582, 0.1819, 0.0578]],
}


@pytest.mark.parametrize("bname", list(BOUNDS))
@pytest.mark.parametrize("cells", [1000, 8000, 75_000, 1_000_000])
def test_res_from_cells(bname, cells):
    b = np.asarray(BOUNDS[bname], float)
    res = res_from_cells(b, cells)
    assert res.shape == (3,) and res.dtype.kind == "i" and (res >= 1).all()
    assert abs(np.prod(res) - cells) <= 0.3 * cells, (res, np.prod(res))
    size = (b[1] - b[0]) / res
    assert size.max() / size.min() < 1.5, size  # near-cubical cells


def test_res_pbrt():
    b = np.asarray(BOUNDS["slab"], float)  # longest axis: x and y (4), z is 1
    for n in (10, 100, 948, 5000):
        res = res_pbrt(b, n)
        assert abs(res.max() - 3 * n ** (1 / 3)) <= 1, (n, res)
        assert res[0] == res[1] >= res[2]
        if n >= 100:
            size = (b[1] - b[0]) / res
            assert size.max() / size.min() < 1.4, (n, res)  # cubical voxels
    assert res_pbrt(b, 10 ** 6).tolist() == [64, 64, 64]  # 300 -> clamped at 64
    assert res_pbrt(b, 10 ** 6, clamp=False).max() == pytest.approx(300, abs=1)
    assert (res_pbrt(b, 10 ** 7) <= 64).all()
    assert (res_pbrt(np.asarray(BOUNDS["long"], float), 1) >= 1).all()


def test_res_pbrt_matches_pbrt_v2_rounding():
    # 3 * 948^(1/3) = 29.47 on x; 14.74 on y; 7.37 on z -> pbrt-v2: (29, 15, 7)
    assert res_pbrt([[0, 0, 0], [1, 0.5, 0.25]], 948).tolist() == [29, 15, 7]
    # 3 * 1000^(1/3) = 30 (29.999999999999996 in float64)
    assert res_pbrt([[0, 0, 0], [1, 1, 1]], 1000).tolist() == [30, 30, 30]


@pytest.mark.parametrize("bname", list(BOUNDS))
@pytest.mark.parametrize("n", [100, 948, 20_000])
def test_res_wald(bname, n):
    b = np.asarray(BOUNDS[bname], float)
    ext = b[1] - b[0]
    for lam in (5.0, 2.0):
        expected = np.maximum(1, np.round(ext * (lam * n / np.prod(ext)) ** (1 / 3)))
        np.testing.assert_array_equal(res_wald(b, n, lam), expected)
    # default lambda is Wald's 5: about 5 N cells
    assert abs(np.prod(res_wald(b, n)) / (5 * n) - 1) < 0.35


def test_grid_resolution_options(bunny):
    assert UniformGrid(res=(4, 5, 6)).build(bunny).res_.tolist() == [4, 5, 6]
    assert UniformGrid(rule="pbrt").build(bunny).res_.tolist() == res_pbrt(bunny.bounds, bunny.n).tolist()
    assert UniformGrid(rule="wald").build(bunny).res_.tolist() == res_wald(bunny.bounds, bunny.n).tolist()
    assert UniformGrid(factor=2).build(bunny).res_.tolist() == res_from_cells(bunny.bounds, 2 * bunny.n).tolist()
    assert UniformGrid().build(bunny).res_.tolist() == res_from_cells(bunny.bounds, 8 * bunny.n).tolist()
    for bad in (dict(cells=0), dict(cells=float("nan")), dict(res=(0, 4, 4)), dict(res=(4, 4))):
        with pytest.raises(GridcostError):
            UniformGrid(**bad).build(bunny)


# ---------------------------------------------------------------- memory guard
def test_memory_guard(bunny, monkeypatch):
    monkeypatch.setenv("GRIDCOST_MEMORY_BUDGET", "1M")
    with pytest.raises(GridcostError) as info:
        UniformGrid(cells=1e7).build(bunny)
    msg = str(info.value)
    assert "MiB" in msg or "GiB" in msg, msg
    assert "budget" in msg
    with pytest.raises(GridcostError, match="MiB|GiB"):
        build(bunny, "grid", res=(400, 250, 100))
    UniformGrid(cells=1000).build(bunny)  # small grids still fit
    monkeypatch.setenv("GRIDCOST_MEMORY_BUDGET", "lots")
    with pytest.raises(GridcostError, match="GRIDCOST_MEMORY_BUDGET"):
        UniformGrid(cells=1000).build(bunny)


# ---------------------------------------------------------------- geometry kernels
TRI = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0)  # a, b, c in the z = 0 plane


def rt(o, d, tri=TRI, tmin=0.0, tmax=np.inf):
    return ray_triangle(*map(float, o), *map(float, d), *tri, tmin, tmax)


def test_ray_triangle_hits_at_known_t():
    assert rt((0.25, 0.25, 2.0), (0, 0, -1)) == 2.0
    assert rt((0.25, 0.25, 2.0), (0, 0, -0.5)) == 4.0  # t in units of the direction
    assert rt((0.25, 0.25, -3.0), (0, 0, 1)) == 3.0  # back face: no culling
    # oblique ray through (0.2, 0.3, 0) from (1.2, 1.3, 1): direction (-1, -1, -1), t = 1
    assert rt((1.2, 1.3, 1.0), (-1, -1, -1)) == pytest.approx(1.0, rel=1e-12)
    # general triangle: hit point reproduces o + t d on the plane
    tri = (1.0, 2.0, 3.0, 4.0, 2.5, 3.5, 2.0, 5.0, 2.0)
    p = 0.5 * np.array(tri[0:3]) + 0.2 * np.array(tri[3:6]) + 0.3 * np.array(tri[6:9])
    o = p + np.array([0.3, -2.0, 4.0])
    t = rt(o, p - o, tri)
    assert t == pytest.approx(1.0, rel=1e-12)


def test_ray_triangle_misses():
    assert rt((1.0, 1.0, 2.0), (0, 0, -1)) == np.inf  # outside the hypotenuse
    assert rt((-0.1, 0.5, 2.0), (0, 0, -1)) == np.inf
    assert rt((0.5, -1e-9, 2.0), (0, 0, -1)) == np.inf
    assert rt((0.25, 0.25, 2.0), (0, 0, 1)) == np.inf  # pointing away: t < 0
    assert rt((0.25, 0.25, 2.0), (0, 0, -1), tmax=2.0) == np.inf  # t must be < tmax
    assert rt((0.25, 0.25, 2.0), (0, 0, -1), tmin=2.0) == np.inf  # and > tmin
    assert rt((0.25, 0.25, 2.0), (0, 0, -1), tmax=2.0000001) == 2.0


def test_ray_triangle_edges_and_vertices_inclusive():
    for x, y in [(0.5, 0.0), (0.0, 0.5), (0.5, 0.5), (0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (0.25, 0.75)]:
        assert rt((x, y, 1.0), (0, 0, -1)) == 1.0, (x, y)
        assert rt((x, y, -1.0), (0, 0, 1)) == 1.0, (x, y)


def test_ray_triangle_degenerate_never_hits():
    for tri in [(0, 0, 0, 1, 0, 0, 2, 0, 0),           # collinear
                (0, 0, 0, 0, 0, 0, 0, 1, 0),           # repeated vertex
                (0.5, 0.5, 0, 0.5, 0.5, 0, 0.5, 0.5, 0)]:  # a point
        tri = tuple(map(float, tri))
        for o, d in [((0.5, 0.5, 1), (0, 0, -1)), ((0.5, 0.0, 1), (0, 0, -1)), ((0.5, -1, 0), (0, 1, 0)),
                     ((-1, 0, 0), (1, 0, 0)), ((0.5, 0.5, 1), (0.1, 0.2, -1))]:
            assert rt(o, d, tri) == np.inf, (tri, o, d)


def test_ray_triangle_parallel_misses():
    assert rt((-1.0, 0.25, 0.0), (1, 0, 0)) == np.inf  # in the plane, through the interior
    assert rt((0.25, -1.0, 0.0), (0, 1, 0)) == np.inf
    assert rt((-1.0, 0.25, 0.5), (1, 0, 0)) == np.inf  # parallel above
    assert rt((-1.0, 0.25, 1e-9), (1, 0, 1e-12)) == np.inf  # grazing within PARALLEL_COS


TRI_BOX_CASES = {
    # name: (box centre, half sizes, triangle, expected)
    "inside": ((0, 0, 0), (1, 1, 1), ((-0.5, -0.5, 0), (0.5, -0.5, 0), (0, 0.5, 0)), True),
    "contains box": ((0, 0, 0), (1, 1, 1), ((-10, -10, 0), (10, -10, 0), (0, 10, 0)), True),
    "far away": ((0, 0, 0), (1, 1, 1), ((5, 5, 5), (6, 5, 5), (5, 6, 5)), False),
    "touches a face": ((0, 0, 0), (1, 1, 1), ((1, 0, 0), (3, 0, 0), (3, 1, 0)), True),
    "touches an edge": ((0, 0, 0), (1, 1, 1), ((1, 1, 0), (3, 1, 0), (1, 3, 0)), True),
    # one edge passes through the box, every vertex is outside
    "only an edge crosses": ((0, 0, 0), (1, 1, 1), ((-3, 0, 0), (3, 0, 0), (0, 0.1, 5)), True),
    # bbox overlaps and the plane cuts the box, but the hypotenuse x + y = 3.5 separates it from the
    # box (x + y <= 2): separating axis Z x edge (a cross-product axis)
    "edge axis separates": ((0, 0, 0), (1, 1, 1), ((0.5, 3, 0), (3, 0.5, 0), (3, 3, 0)), False),
    # bbox overlaps the box, the plane x + y + z = 4 misses it (x + y + z <= 3): plane axis
    "plane separates": ((0, 0, 0), (1, 1, 1), ((4, 0, 0), (0, 4, 0), (0, 0, 4)), False),
    # the same, tilted: plane x + y = 3 + 2 z cuts the box (at z = -1), the triangle has x + y >= 3
    "tilted edge axis separates": ((0, 0, 0), (1, 1, 1), ((-0.5, 3.5, 0), (3.5, -0.5, 0), (2.5, 2.5, 1)), False),
    "off-centre box": ((10, 20, 30), (0.5, 2, 1), ((9.8, 19, 30), (10.2, 19, 30), (10, 23, 30.5)), True),
}


def _aabb_overlaps(c, h, tri):
    t = np.asarray(tri, float)
    return bool(((t.min(0) <= np.add(c, h)) & (t.max(0) >= np.subtract(c, h))).all())


def _plane_cuts(c, h, tri):
    t = np.asarray(tri, float) - np.asarray(c, float)
    n = np.cross(t[1] - t[0], t[2] - t[0])
    return abs(n @ t[0]) <= np.abs(n) @ np.asarray(h, float)


@pytest.mark.parametrize("case", list(TRI_BOX_CASES))
def test_tri_box_overlap(case):
    c, h, tri, expected = TRI_BOX_CASES[case]
    args = [float(x) for x in (*c, *h, *itertools.chain(*tri))]
    assert tri_box_overlap(*args) is expected or bool(tri_box_overlap(*args)) == expected
    # vertex order does not matter
    for perm in itertools.permutations(range(3)):
        p = [tri[i] for i in perm]
        assert bool(tri_box_overlap(*map(float, (*c, *h, *itertools.chain(*p))))) == expected, perm
    if case in ("edge axis separates", "tilted edge axis separates"):
        # only a cross-product axis separates: the box-face and plane tests both pass
        assert _aabb_overlaps(c, h, tri) and _plane_cuts(c, h, tri)
    if case == "plane separates":
        assert _aabb_overlaps(c, h, tri) and not _plane_cuts(c, h, tri)


def test_tri_box_overlap_random_against_lp():
    """Random triangles and boxes against an exact feasibility LP (a point in both), skipping cases
    within 1e-6 of touching."""
    from scipy.optimize import linprog
    rng = np.random.default_rng(5)
    checked = 0
    for _ in range(300):
        c = rng.normal(size=3)
        h = rng.uniform(0.1, 1.0, 3)
        tri = c + rng.normal(scale=1.5, size=(3, 3))
        got = bool(tri_box_overlap(*map(float, (*c, *h, *tri.ravel()))))
        # variables (u, v): p = a + u (b - a) + v (c - a) within [c - h*s, c + h*s], u, v >= 0, u + v <= 1
        E = np.stack([tri[1] - tri[0], tri[2] - tri[0]], axis=1)

        def feasible(scale):
            A = np.vstack([E, -E, [[1, 1]]])
            b = np.concatenate([c + h * scale - tri[0], -(c - h * scale - tri[0]), [1]])
            r = linprog(np.zeros(2), A_ub=A, b_ub=b, bounds=[(0, None), (0, None)], method="highs")
            return r.status == 0

        if feasible(1 - 1e-6) == feasible(1 + 1e-6):
            assert got == feasible(1.0), (c, h, tri)
            checked += 1
    assert checked > 250


def test_ray_box():
    box = (0.0, 0.0, 0.0, 1.0, 1.0, 1.0)
    assert ray_box(0.5, 0.5, -1.0, 0.0, 0.0, 1.0, *box, 0.0, np.inf) == (1.0, 2.0)
    assert ray_box(-1.0, 0.5, 0.5, 2.0, 0.0, 0.0, *box, 0.0, np.inf) == (0.5, 1.0)
    # zero direction components: inside the slab -> unconstrained, outside -> miss
    t0, t1 = ray_box(1.5, 0.5, -1.0, 0.0, 0.0, 1.0, *box, 0.0, np.inf)
    assert t0 > t1
    t0, t1 = ray_box(0.5, -0.5, 0.5, 0.0, 0.0, -1.0, *box, 0.0, np.inf)
    assert t0 > t1
    t0, t1 = ray_box(0.5, 0.5, 0.5, 0.0, -0.0, 1.0, *box, 0.0, np.inf)  # -0.0 as well
    assert (t0, t1) == (0.0, 0.5)
    t0, t1 = ray_box(1.0, 0.0, -2.0, 0.0, 0.0, 1.0, *box, 0.0, np.inf)  # on the box's edge line
    assert (t0, t1) == (2.0, 3.0)
    t0, t1 = ray_box(0.5, 0.5, 0.5, 0.0, 0.0, 0.0, *box, 0.0, 7.0)  # all zero, inside
    assert (t0, t1) == (0.0, 7.0)
    t0, t1 = ray_box(2.0, 0.5, 0.5, 0.0, 0.0, 0.0, *box, 0.0, 7.0)  # all zero, outside
    assert t0 > t1
    # tmin / tmax clip the interval; behind the origin is a miss
    assert ray_box(0.5, 0.5, -1.0, 0.0, 0.0, 1.0, *box, 1.5, 1.75) == (1.5, 1.75)
    t0, t1 = ray_box(0.5, 0.5, 2.0, 0.0, 0.0, 1.0, *box, 0.0, np.inf)
    assert t0 > t1
    t0, t1 = ray_box(0.5, 0.5, -1.0, 0.0, 0.0, 1.0, *box, 0.0, 0.5)  # tmax before the box
    assert t0 > t1


def test_grid_axis_aligned_rays_on_cell_planes(bunny):
    """Axis-aligned rays whose two other coordinates lie exactly on cell planes (zero direction
    components in the DDA) agree with the oracle."""
    grid = UniformGrid(cells=8 * bunny.n).build(bunny)
    lo, hi = bunny.bounds.astype(np.float64)
    res = grid.res_
    rng = np.random.default_rng(9)
    O, D = [], []
    for axis in range(3):
        for _ in range(200):
            ijk = rng.integers(0, res + 1)
            o = lo + ijk * (hi - lo) / res
            o[axis] = lo[axis] - 0.1 if rng.random() < 0.5 else hi[axis] + 0.1
            d = np.zeros(3)
            d[axis] = 1.0 if o[axis] < lo[axis] else -1.0
            O.append(o)
            D.append(d)
    o, d = np.asarray(O, np.float32), np.asarray(D, np.float32)
    hits, _ = grid.intersect(o, d)
    ref, ties = oracle_intersect(bunny, o, d)
    res_ = compare(hits, ref, ties)
    assert res_["disagreements"] == 0, res_


# ---------------------------------------------------------------- vertex layout
def test_auto_layout_takes_blocks_and_index_saves_memory(monkeypatch):
    """"auto" takes the SoA blocks whatever fits in L2 (long skinny triangles read through their ids
    were slower than the blocks on every mesh timed); "index" stays on request: one row per triangle,
    the least memory where each triangle is referenced by tens of cells, and the same hits."""
    from tracer.accel.grid import choose_layout
    from tracer.measure.footprint import grid_bytes
    from tracer.scenes.scene import load_scene
    for l2 in ("1M", "2M"):
        monkeypatch.setenv("GRIDCOST_L2", l2)
        assert choose_layout("auto") == "blocks"
    assert choose_layout("copy") == "copy" and choose_layout("index") == "index"
    # the estimate counts the blocks' (and auto's) rows as the copy's: one per reference
    assert grid_bytes(1000, 5000, "auto") == grid_bytes(1000, 5000, "blocks") == grid_bytes(1000, 5000)
    assert grid_bytes(1000, 5000, "copy") - grid_bytes(1000, 5000, "index") == 5000 * 36
    cyl = load_scene("cylinder-3996")
    grid = UniformGrid(cells=132_651, layout="index").build(cyl)
    assert grid.stats()["layout"] == "index" and grid.tri_verts_.shape == (cyl.n, 9)
    assert UniformGrid(cells=132_651).build(cyl).stats()["layout"] == "blocks"
    copy = UniformGrid(cells=132_651, layout="copy").build(cyl)
    assert copy.tri_verts_.shape == (copy.refs_, 9) and copy.refs_ > 30 * cyl.n
    assert grid.stats()["memory_bytes"] < copy.stats()["memory_bytes"] / 4
    rays = make_rays(cyl, "random", 3000, seed=3)
    a, _ = grid.intersect(rays.origins, rays.directions)
    b, _ = copy.intersect(rays.origins, rays.directions)
    np.testing.assert_array_equal(a.tri_id, b.tri_id)
    np.testing.assert_array_equal(a.t, b.t)
    assert (a.tri_id >= 0).sum() > 1000


@pytest.mark.parametrize("kw", [{}, {"mailbox": True}, {"macro": 2, "factor": 16}])
def test_blocks_layout_same_hits_and_counts_as_copy(bunny, kw):
    """Four references per ray_tri4 call (blocks not aligned to cells, other cells' lanes masked):
    the same t, ids and counters as the scalar loop over the copy, also for any-hit queries."""
    rays = rays_for(bunny, "adversarial")
    copy, blocks = (UniformGrid(layout=lay, **kw).build(bunny) for lay in ("copy", "blocks"))
    assert blocks.stats()["vertex_bytes"] == 36 * (-(-blocks.refs_ // 4) * 4)  # the copy's bytes, padded to 4
    (a, ca), (b, cb) = copy.intersect(rays.origins, rays.directions), blocks.intersect(rays.origins, rays.directions)
    for x, y in ((a.tri_id, b.tri_id), (a.t, b.t), (ca.data, cb.data)):
        np.testing.assert_array_equal(x, y)
    assert (b.tri_id >= 0).sum() > rays.n // 4 and (cb["tests"] >= 4).sum() > 100  # several blocks per ray
    tmax = np.where(a.tri_id >= 0, a.t * (1 + 1e-5), np.inf).astype(np.float32)
    (_, ia, ka), (_, ib, kb) = (g._trace(rays.origins, rays.directions, 0.0, tmax, True, True) for g in (copy, blocks))
    np.testing.assert_array_equal(ia, ib)  # any hit: the first reference hit, as the scalar loop
    np.testing.assert_array_equal(ka, kb)  # counts up to that reference


def test_unknown_layout_is_refused():
    with pytest.raises(GridcostError, match="layout"):
        UniformGrid(layout="soa")


def test_cache_sizes_from_sysfs_or_environment(monkeypatch):
    from tracer.measure.memory import cache_bytes
    monkeypatch.delenv("GRIDCOST_L2", raising=False)
    l1, l2, l3 = cache_bytes(1), cache_bytes(2), cache_bytes(3)
    assert 0 < l1 < l2 <= l3  # a real hierarchy (sysfs) or the defaults (1 MiB, 32 MiB)
    monkeypatch.setenv("GRIDCOST_L2", "256K")
    assert cache_bytes(2) == 256 << 10
    monkeypatch.setenv("GRIDCOST_L2", "lots")
    with pytest.raises(GridcostError, match="GRIDCOST_L2"):
        cache_bytes(2)

"""Wald 2006: packet any-hit (shadow) queries against the float64 oracle, the room
camera from inside, and the new targets run with --quick (small scenes, small images)."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from experiments.wald.lib.views import ROOM_EYE, inside_view, light_position, shadow_rays, wald_camera
from tracer.accel.oracle import oracle_intersect
from tracer.accel.packet import CoherentGrid
from tracer.scenes.rays import camera_frame, make_rays
from tracer.scenes.scene import load_scene


@pytest.fixture(scope="module")
def bunny():
    return load_scene("bunny-948")


@pytest.mark.parametrize("k", (4, 8))
def test_packet_occlusion_matches_oracle(bunny, k):
    """Shadow packets (common origin at the light, tmax short of the hit) and random rays with a
    finite tmax: hit/miss of the any-hit packet kernel equals the oracle's closest hit within tmax."""
    cgt = CoherentGrid(packet=k).build(bunny)
    prim = wald_camera(bunny, 48, k)
    hits, _ = cgt.intersect(prim.origins, prim.directions, counters=False)
    so, sd, stmax = shadow_rays(prim, hits.t, light_position(bunny))
    rr = make_rays(bunny, "random", 500, seed=5)
    for o, d, tmax in ((so, sd, stmax), (rr.origins, rr.directions, np.full(500, 0.6, np.float32))):
        ref, _ = oracle_intersect(bunny, o, d, tmax=tmax)
        occ = cgt.occluded(o, d, tmax)
        np.testing.assert_array_equal(occ, ref.tri_id >= 0)
        assert 0 < occ.sum() < len(occ)  # both outcomes occur


def test_room_camera_is_inside(tmp_path):
    room = load_scene("room")
    sc, eye_dir = inside_view(room, ROOM_EYE, (1.0, 0.15, -0.12), 4.0)
    eye = camera_frame(sc, eye_dir)[0]
    np.testing.assert_allclose(eye, ROOM_EYE, atol=1e-9)
    lo, hi = room.bounds
    assert (eye > lo).all() and (eye < hi).all()


def run_target(tmp_path, *args):
    """Run a target in this process (kernels already compiled) into tmp_path; returns tmp_path."""
    from experiments.run import main
    assert main(list(args) + ["--quick", "--json", "--out", str(tmp_path)]) == 0
    return tmp_path


@pytest.mark.slow  # CI runs wald-table3 inside test_all_quick_into_a_fresh_folder; this checks its details
def test_table3_quick(tmp_path):
    """wald-table3 on a small scene and image: real values in its CSV."""
    out = run_target(tmp_path, "wald-table3", "--scenes", "bunny-948", "--side", "64", "--repeats", "3")
    df = pd.read_csv(out / "wald-table3" / "table3.csv")
    r = df.iloc[0]
    assert r.rays == 64 * 64 and r.N == 948
    assert r.ratio_p8 > 0.5 and r.single_mrays > 0 and r.p8_mrays > 0
    assert r.cells_single > 2 * r.cells_p8  # packets visit fewer cells per ray (3x at 64²)
    assert 0 < r.shadow_occluded < 1 and r.shadow_rays == round(r.hit_frac * r.rays)
    assert "(paper)" in (out / "wald-table3" / "summary.md").read_text()


def test_lowres_and_fig8_quick(tmp_path):
    """wald-lowres (bunny-948 at 64², 128²) and wald-fig8 (tiny scenes): real values in their CSVs."""
    out = run_target(tmp_path, "wald-lowres", "--sides", "32,64", "--repeats", "3")
    df = pd.read_csv(out / "wald-lowres" / "lowres.csv")
    assert list(df.side) == [32, 64] and (df.cgt_over_embree > 0).all() and (df.cgt_over_grid > 0).all()
    assert df.tests.iloc[0] > df.tests.iloc[1]  # a lower resolution: more triangle tests per ray
    out = run_target(tmp_path, "wald-fig8", "--side", "32", "--repeats", "3", "--largest", "bunny-3851")
    rb = pd.read_csv(out / "wald-fig8" / "rebuild.csv")
    assert list(rb.lam) == [1.0, 5.0] and (rb.build_s > 0).all() and (rb.trace_s > 0).all()
    assert rb.res.iloc[0] != rb.res.iloc[1]
    mr = pd.read_csv(out / "wald-fig8" / "model_resolution.csv")
    assert set(mr.scene) == {"bunny-948", "bunny-3851"} and (mr.trace_s > 0).all()


def test_lowres_goal_tally_counts_scenes_per_goal():
    """The Reading's goal line counts, per goal side, the scenes whose median ratio reaches it."""
    from experiments.wald.lowres import goal_tally
    df = pd.DataFrame({"scene": ["a", "b", "c", "a", "b", "c"], "side": [512, 512, 512, 1024, 1024, 1024],
                       "cgt_over_embree": [1.21, 1.19, 1.2, 1.7, 1.81, 1.8]})
    line = goal_tally(df)
    assert "512²: CGT / Embree >= 1.2 on 2 of 3 scenes (a, c)" in line
    assert "1024²: CGT / Embree >= 1.8 on 2 of 3 scenes (b, c)" in line
    assert goal_tally(df[df.side == 64]) == ""


def test_needs_of_single_rays_are_their_own_walks(bunny):
    """With one ray per 'packet' the needs kernel is the ray's own walk: its distinct cells are the
    grid's steps and the references they hold are the unmailboxed grid's tests, ray for ray; packets
    of 64 share cells, so their distinct cells and references fall below the sum of their rays'."""
    from experiments.wald.lib.needs import needs_row, packet_needs
    from tracer.accel.grid import UniformGrid
    rays = wald_camera(bunny, 48, 8)
    g = UniformGrid(res=(12, 11, 10)).build(bunny)
    hits, cnt = g.intersect(rays.origins, rays.directions)
    nx, ny, nz = g.res_
    per_ray = packet_needs(rays.origins, rays.directions, hits.t.astype(np.float64), 1, g.gp_, nx, ny, nz,
                           g.cell_start_, g.tri_ids_, bunny.n)
    np.testing.assert_array_equal(per_ray[:, 0], cnt["steps"])
    np.testing.assert_array_equal(per_ray[:, 1], cnt["steps"])  # a DDA walk never enters a cell twice
    np.testing.assert_array_equal(per_ray[:, 2], cnt["tests"])
    assert (per_ray[:, 3] <= per_ray[:, 2]).all() and per_ray[:, 3].sum() > 0
    own = needs_row(g, rays, hits.t, 64, bunny.n)
    assert own["own_cells"] == pytest.approx(cnt["steps"].mean())
    assert 0 < own["need_cells"] < 0.5 * own["own_cells"] and 0 < own["need_tris"] < own["need_refs"] < cnt["tests"].mean()

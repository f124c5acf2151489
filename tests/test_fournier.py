"""fournier-table1's additions: the teapot row (Newell's 28 patches and a floor, 29 objects), the
per-object flat-list counts, the Around Again stand-in with secondary rays, and the quick target."""
from __future__ import annotations

import argparse

import numpy as np
import pandas as pd

from experiments.fournier.lib import around, scenes
from experiments.fournier.table1 import PAPER_TABLE1, TEAPOT, measure_scene, object_ids
from tracer.accel.oracle import oracle_intersect
from tracer.accel.sortedlists import SortedLists, padded_boxes
from tracer.scenes.spd import spd_camera_rays, spd_scene

ARGS = argparse.Namespace(nogrid_max=5000, leaf_size=8, branching=2)


def test_teapot_scene_is_29_objects_and_every_eye_ray_hits():
    scene, obj, n_obj = scenes.teapot_scene()
    assert n_obj == 29 and int(obj.max()) + 1 == 29
    assert scene.n == 5560 + 2 and (obj == 28).sum() == 2  # 28 patches of 190-200 triangles, floor square
    assert sorted(set(np.bincount(obj[obj < 28]))) == [190, 200]
    o, d = scenes.teapot_rays(16)
    ref, _ = oracle_intersect(scene, o, d)
    assert (ref.tri_id >= 0).all()  # the paper's minimum for the teapot: 1.00
    assert (obj[ref.tri_id] < 28).mean() > 0.2  # and the teapot is in the picture


def test_flat_object_counts_reproduce_the_flat_lists_ray_for_ray():
    """Objects = triangles: the box computation gives exactly the counters of SortedLists(hierarchy=False)."""
    for name in ("tetra-3", "sphereflake-1"):
        s = spd_scene(name)
        o, d = spd_camera_rays(name, 16)
        hits, cnt = SortedLists(hierarchy=False).build(s).intersect(o, d)
        c = around.flat_object_counts(padded_boxes(s.tris), o, d, np.where(hits.tri_id >= 0, hits.t, np.inf))
        assert np.array_equal(c["tests"], cnt["tests"]), name
        assert np.array_equal(c["events"], cnt["steps"]), name
        assert (c["events_ahead"] <= c["events"]).all()


def test_teapot_row_measured_with_the_right_objects():
    rows = pd.DataFrame(measure_scene(TEAPOT, ARGS, 12, 1, 5000))
    assert set(rows.structure) == {"grid30", "grid30mb", "sl-hier", "sl-flat", "nogrid"}
    assert (rows.spd_objects == 29).all() and (rows.obj_count == 29).all() and (rows.N == 5562).all()
    assert rows.disagreements.sum() == 0 and (rows.reference == "oracle").all()
    assert (rows.hit_frac == 1.0).all()
    r = rows.iloc[0]
    # per object: at least the minimum, at most every object; events at most 6 per object
    assert 1.0 <= r.obj_tests_per_ray <= 29 and r.obj_events_per_ray <= 6 * 29
    by = rows.set_index("structure")
    assert by.loc["nogrid", "tests_per_ray"] == 5562
    assert by.loc["sl-flat", "tests_per_ray"] <= by.loc["grid30", "tests_per_ray"]
    assert "teapot" in [p[0] for p in PAPER_TABLE1]
    assert object_ids("sphereflake-1", 482).max() + 1 == 11 and object_ids("gears-1", 578) is None


def test_secondary_rays_agree_with_the_oracle():
    scene, kind = scenes.around_again_scene()
    assert scene.n == 28 * 1056 + 8 and (kind == 1).sum() == 8
    o, d = scenes.around_again_primary(12)
    ref, _ = oracle_intersect(scene, o, d)
    assert (ref.tri_id >= 0).mean() > 0.8 and (kind[ref.tri_id[ref.tri_id >= 0]] == 0).any()  # cans in view
    sec = scenes.secondary_rays(scene, o, d, ref.t, ref.tri_id)
    nh = int((ref.tri_id >= 0).sum())
    so, sd, tm = sec["shadow"]
    ro, rd, _ = sec["reflection"]
    assert len(so) == len(ro) == nh and np.allclose(np.linalg.norm(rd, axis=1), 1, atol=1e-5)
    from tracer.accel.grid import UniformGrid
    for acc in (UniformGrid(res=(30, 30, 30)).build(scene), SortedLists().build(scene)):
        occ_ref, _ = oracle_intersect(scene, so, sd, tmax=tm)
        assert np.array_equal(acc.occluded(so, sd, tm), occ_ref.tri_id >= 0)
        h, _ = acc.intersect(ro, rd)
        rr, _ = oracle_intersect(scene, ro, rd)
        assert np.array_equal(h.tri_id >= 0, rr.tri_id >= 0)
        both = rr.tri_id >= 0
        assert np.allclose(h.t[both], rr.t[both], rtol=1e-5)


def test_measure_around_counts():
    rows = pd.DataFrame(around.measure_around(12, 1, 8, 2))
    assert rows.disagreements.sum() == 0
    g = rows.set_index(["structure", "ray_kind"])
    for k in around.RAY_KINDS + ("all",):
        # the lists never test more than the grid (with or without mailboxing); mailboxing never adds tests
        assert g.loc[("sl-hier", k), "tests_per_ray"] <= g.loc[("grid30mb", k), "tests_per_ray"]
        assert g.loc[("grid30mb", k), "tests_per_ray"] <= g.loc[("grid30", k), "tests_per_ray"]
        assert g.loc[("grid30", k), "hit_frac"] == g.loc[("sl-hier", k), "hit_frac"]
    a = g.loc[("grid30", "all")]
    assert a.rays == sum(g.loc[("grid30", k), "rays"] for k in around.RAY_KINDS)
    assert g.loc[("sl-hier", "all"), "paired_ratio_to_grid30"] > 0
    text = "\n".join(around.around_summary(rows))
    assert "(618x)" in text and "(4.5x)" in text and "35 %" in text

"""The ize-levels, ize-skinny2 and extended fig5 targets in --quick mode on small scenes and few
rays, in-process into a temporary folder: the CSVs hold real values (theory cell counts equal to the
paper's formulas, non-negative swept penalties, positive paired speed-ups, one plane per scene x kind)."""
import json

import numpy as np
import pandas as pd
import pytest

from experiments.run import main

RAYS = "600"


@pytest.fixture(scope="module")
def out(tmp_path_factory, gridcost_cache):
    import numba
    threads = numba.get_num_threads()  # the targets time on one thread; the rest of the session keeps its own
    out = tmp_path_factory.mktemp("ize17")
    common = ["--quick", "--out", str(out), "--json", "--rays", RAYS]
    assert main(["ize-levels", *common, "--scenes", "bunny-948,particles-1000"]) == 0
    assert main(["ize-skinny2", *common]) == 0
    assert main(["fig5", *common, "--scenes", "bunny-948:compact,capped-cylinder-196:skinny"]) == 0
    numba.set_num_threads(threads)
    return out


def test_levels_theory_m1_is_the_d_level_rule(out):
    tab = pd.read_csv(out / "ize-levels" / "levels_summary.csv")
    assert list(tab.scene) == ["bunny-948", "particles-1000"]
    for _, r in tab.iterrows():
        assert r.theory_M1_L3 == round((8 * r.N) ** (3 / 7))      # Eq 16 with L = 3, k = 1, Ti/Ts = 4
        assert r.theory_M1_L2 == round((8 * r.N) ** (3 / 5))      # Eq 13 (Table 4)
        assert r.theory_M1_formula_L3 == pytest.approx((8 * r.N) ** (3 / 7), rel=1e-12)
    assert tab.loc[0, "theory_M1_L3"] == 46 and tab.loc[0, "theory_M1_L2"] == 213   # N = 948
    for L in (2, 3):
        for sfx in ("", "_camera"):
            assert (tab[f"L{L}_penalty_swept_pct{sfx}"] >= 0).all()
            assert np.isfinite(tab[f"L{L}_penalty_pct{sfx}"]).all()
            assert (tab[f"L{L}_speedup_vs_one_level{sfx}"] > 0).all()
            assert (tab[f"L{L}_theory_cells{sfx}"] > tab[f"theory_M1_L{L}"]).all()  # sub-grid cells counted
    assert np.allclose(tab.L3_over_L2, tab.L3_speedup_vs_one_level / tab.L2_speedup_vs_one_level)
    rows = pd.read_csv(out / "ize-levels" / "levels.csv")
    assert set(rows.levels) == {1, 2, 3} and set(rows.ray_kind) == {"random", "camera"}
    three = rows[rows.levels == 3]
    assert (three.param_depth_rule == "eq16").all() and (three.anchored_ns_per_ray > 0).all()
    assert {"commit", "host", "clock"} <= set(rows.columns)
    text = (out / "ize-levels" / "summary.md").read_text()
    assert "| bunny-948 (bunny) | 948 | 213, 46 |" in text and "(1%)" in text  # paper's Table 4 penalty beside ours
    assert "not helpful" in text


def test_skinny2_rules_and_paired_speedup(out):
    tab = pd.read_csv(out / "ize-skinny2" / "skinny2_summary.csv")
    r = tab.iloc[0]
    assert r.scene == "capped-cylinder-196" and r.N == 196
    assert r.skinny_M1_param == 4 * 196                       # Eq 17: M1 = k N Ti/Ts
    assert r.compact_M1_param == round((8 * 196) ** 0.6)      # Table 4's rule
    assert r.skinny_cells > r.compact_cells                   # Eq 18: the skinny rule's space is larger
    for sfx in ("", "_camera"):
        sp = r[f"skinny_speedup{sfx}"]
        assert sp > 0 and np.isfinite(sp)
        # the speed-up is the inverse ratio of the paired medians up to per-round pairing
        assert sp == pytest.approx(r[f"compact_ns{sfx}"] / r[f"skinny_ns{sfx}"], rel=0.5)
        lo, hi = (float(x) for x in r[f"skinny_speedup_range{sfx}"].split(".."))  # printed to 2 decimals
        assert lo - 0.005 <= sp <= hi + 0.005
    assert r.paper_speedup == 1.2
    assert "(1.2x)" in (out / "ize-skinny2" / "summary.md").read_text()


def test_fig5_one_plane_per_scene_and_kind(out):
    df = pd.read_csv(out / "fig5" / "fig5.csv")
    planes = df.groupby(["scene", "ray_kind"])
    assert set(planes.groups) == {(s, k) for s in ("bunny-948", "capped-cylinder-196") for k in ("random", "camera")}
    meta = json.loads((out / "fig5" / "meta.json").read_text())
    for (scene, _), g in planes:
        size = meta["planes"][scene]
        assert len(g) == len(size["c1"]) * len(size["c2"]) >= 4 and (g.pct_over_best >= 0).all()
        best = g.loc[g.pct_over_best.idxmin()]   # the interior flag says whether the fastest is inside
        inside = min(size["c1"]) < best.c1 < max(size["c1"]) and min(size["c2"]) < best.c2 < max(size["c2"])
        assert (g.interior == inside).all() and (g.widened == size["widened"]).all()
        assert (g.pct_over_best_sweep >= 0).all() and g.pct_over_best_sweep.min() == 0
        assert g.memory_pick.sum() == 1  # one memory-aware point per plane
        # a widened plane's ring was timed in its widening; the first 3 x 3 points in widening 0
        assert set(g.paired_in_widening) == set(range(size["widened"] + 1))
        assert (g.paired_in_widening == 0).sum() == 9
    assert set(df.model_kind) == {"compact", "skinny"}
    assert meta["kinds"] == ["random", "camera"]
    assert (out / "paper_figs" / "fig5.png").stat().st_size > 1000
    assert (out / "paper_figs" / "ize-levels.png").stat().st_size > 1000


def test_fig5_plane_widens_toward_an_edge_optimum():
    from experiments.ize.fig5 import interior, widen
    c1, c2 = [1.0, 1.5, 2.5], [1.0, 2.0, 3.0]
    assert widen(c1, c2, [(1.5, 2.0), (1.5, 2.0)]) is None          # interior in both kinds: as is
    g1, g2 = widen(c1, c2, [(2.5, 2.0), (1.5, 1.0)])                 # right edge in c1, bottom edge in c2
    assert g1 == [1.0, 1.5, 2.5, round(2.5 * 2.5 / 1.5, 4)] and g2 == [0.5, 1.0, 2.0, 3.0]
    assert interior(g1, g2, 2.5, 1.0) and not interior(c1, c2, 2.5, 1.0)


def test_fig5_ring_chained_through_the_narrower_planes_fastest():
    from experiments.ize.fig5 import chain_ring
    old = {(1, 1): 0.0, (1, 2): 10.0, (2, 1): 50.0}          # % over the narrower plane's fastest (1, 1)
    keys = [(1, 1), (1, 2), (2, 1), (3, 1), (3, 2)]
    # the new run: (1, 1) is 20 % over the ring's fastest (3, 1); (3, 2) 5 % over it
    pct = chain_ring(old, keys, [0, 3, 4], [20.0, 0.0, 5.0])
    assert pct == pytest.approx([20.0, 32.0, 80.0, 0.0, 5.0])
    # a ring slower than the old fastest leaves the old fastest at 0 and the old % as they were
    pct = chain_ring(old, keys, [0, 3, 4], [0.0, 7.0, 30.0])
    assert pct == pytest.approx([0.0, 10.0, 50.0, 7.0, 30.0])


def test_plane_pct_against_one_fixed_point_per_round():
    """Drift common to a round cancels; the fastest point is at 0; equal points stay near 0 (a
    per-round minimum over noisy points would lift all of them, by more the more points)."""
    from experiments.core.sweep import plane_pct
    rng = np.random.default_rng(3)
    t = np.array([1.0, 1.2, 2.0])[:, None] * (1 + 0.01 * rng.standard_normal((3, 41)))
    drift = 1 + 0.3 * rng.random(41)
    assert plane_pct(t * drift) == pytest.approx(plane_pct(t))
    pct = plane_pct(t)
    assert pct[0] == 0 and pct[1] == pytest.approx(20, abs=1.5) and pct[2] == pytest.approx(100, abs=3)
    equal = 1 + 0.05 * rng.random((6, 41))
    per_round_min = 100 * (np.median(equal / equal.min(axis=0), axis=1) - 1)  # the per-round minimum's bias:
    assert per_round_min.min() > 0.5                                              # even the best is lifted
    assert plane_pct(equal).min() == 0 and np.median(plane_pct(equal)) < np.median(per_round_min)

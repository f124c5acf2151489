"""advise across budgets: the lower envelope of the candidates' lines, crossovers with intervals."""
from __future__ import annotations

import pytest

from experiments.tools.lib.budgets import Advice, Candidate, check_budgets, crossover, describe, fastest_ranges


def _c(name, b, r, rel=0.1):
    return Candidate(name, {}, "test", b, r, (-rel, rel), (-rel, rel), 1 << 20)


def test_three_regimes_in_order():
    cands = [_c("grid", 1e-3, 100e-9), _c("cgt", 1e-2, 40e-9), _c("bvh4", 1.0, 20e-9)]
    ranges = fastest_ranges(cands, 1e3, 1e10)
    assert [r.candidate for r in ranges] == ["grid", "cgt", "bvh4"]
    # grid -> cgt where 1e-3 + R 100e-9 = 1e-2 + R 40e-9: R = 9e-3 / 60e-9 = 1.5e5
    assert ranges[0].r_to == pytest.approx(1.5e5)
    assert ranges[1].r_to == pytest.approx((1.0 - 1e-2) / 20e-9)
    assert ranges[0].cross_lo < ranges[0].r_to < ranges[0].cross_hi
    assert ranges[-1].r_to == 1e10 and ranges[-1].cross_lo is None
    text = describe(ranges, {c.label(): c.memory_bytes for c in cands})
    assert text.startswith("below 1.5e+05 rays: grid, 1.0 MiB; ") and "above 5e+07: bvh4" in text
    assert check_budgets(ranges) == pytest.approx(sorted([5e4, 4.5e5, 0.99e8 / 2 / 3, 0.99e8 / 2 * 3]))


def test_a_dominated_candidate_never_wins_and_ties_are_exact():
    cands = [_c("a", 1e-3, 10e-9), _c("b", 1e-2, 20e-9)]
    assert [r.candidate for r in fastest_ranges(cands)] == ["a"]
    r_star, lo, hi = crossover(_c("x", 0.0, 2e-9, 0.0), _c("y", 1.0, 1e-9, 0.0))
    assert r_star == lo == hi == pytest.approx(1e9)


def test_advice_picks_per_budget():
    adv = Advice("s", 10, "random", [_c("grid", 1e-3, 100e-9), _c("bvh4", 1.0, 20e-9)])
    assert adv.pick(1e4).structure == "grid" and adv.pick(1e9).structure == "bvh4"
    d = adv.to_dict()
    assert [r["candidate"] for r in d["ranges"]] == ["grid", "bvh4"] and len(d["candidates"]) == 2

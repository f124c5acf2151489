"""Tests of costmodel.derive (sympy derivations of Ize, Shirley & Parker 2007) and the `derive` CLI target."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from scipy.optimize import minimize, minimize_scalar

from costmodel import derive as d
from costmodel import derive_nested as dn

REPO = Path(__file__).resolve().parents[1]


def test_one_level_optimum_is_2N_Ti_over_Ts():
    r = d.ize_eq4_one_level_optimum()
    assert r.exponent == 1 and isinstance(r.exponent, sp.Rational)
    assert sp.simplify(r.optimum - 2 * d.N * d.Ti / d.Ts) == 0
    assert sp.simplify(d.ize_eq2_one_level_derivative() - (d.Ts - 2 * d.N * d.Ti / d.m**3)) == 0
    assert sp.simplify(d.ize_eq3_one_level_m() ** 3 - 2 * d.N * d.Ti / d.Ts) == 0
    assert r.time_exponent == sp.Rational(1, 3)
    assert r.match and r.formula_match
    assert all(r.checks.values()), r.checks  # includes Table 2's "theoretical M" = 8N column


def test_one_level_second_order_positive():
    r = d.ize_eq4_one_level_optimum()
    assert r.second_order_positive is True
    # d2T/dm2 = 6 N Ti / m^4 at m*, checked numerically too
    val = float(r.second_order.subs({d.N: 1000, d.Ti: 4, d.Ts: 1}))
    m_star = (2 * 1000 * 4 / 1) ** (1 / 3)
    assert val == pytest.approx(6 * 1000 * 4 / m_star**4, rel=1e-12) and val > 0


def test_long_skinny_exponent_three_halves():
    r = d.ize_eq8_long_skinny_optimum()
    assert r.exponent == sp.Rational(3, 2)
    assert sp.simplify(r.optimum - (d.N * d.Ti / d.Ts) ** sp.Rational(3, 2)) == 0
    assert r.time_exponent == sp.Rational(1, 2) and r.space_exponent == sp.Rational(3, 2)
    assert r.second_order_positive and r.match
    assert all(r.checks.values()), r.checks  # Eq 6's dT/dM label, Table 3's 8 N^1.5 column


def test_two_level_m1_three_fifths_and_eq12():
    r = d.ize_eq13_two_level_optimum()
    assert r.exponent == sp.Rational(3, 5)
    sol = d.ize_eq12_two_level_m1()
    assert d.same(sol[d.m1], (2 * d.k**2 * d.N * d.Ti / d.Ts) ** sp.Rational(1, 5))
    assert d.same(sol[d.m2], sol[d.m1] / d.k)
    assert r.formula_match and r.match
    assert r.time_exponent == sp.Rational(1, 5) and r.space_exponent == 1
    assert r.second_order_positive
    # both partials (Eq 10, 11) vanish at the solution
    for dT in d.ize_eq10_11_two_level_partials():
        assert sp.simplify(dT.subs(sol)) == 0


def test_two_level_m2_is_one_level_grid_of_subgrid_points():
    r = d.ize_eq13_two_level_m2()
    assert r.exponent == 1 and r.wrt == d.N2
    assert all(r.checks.values())
    assert d.exponent_of(r.optimum) == sp.Rational(3, 5)  # in N


@pytest.mark.parametrize("levels", [1, 2, 3, 4, 5])
def test_d_level_top_exponent(levels):
    r = dn.ize_eq16_d_level_top(levels)
    assert r.exponent == sp.Rational(3, 2 * levels + 1)
    assert r.time_exponent == sp.Rational(1, 2 * levels + 1)
    assert r.space_exponent == 1
    assert r.second_order_positive
    assert all(r.checks.values()), r.checks
    assert r.match


def test_d_level_general_and_three_level():
    g = dn.ize_d_level_general()
    assert sp.simplify(g.exponent - 3 / (2 * d.L + 1)) == 0
    assert all(g.checks.values()), g.checks
    t = dn.ize_eq15_three_level()
    assert t.exponent == sp.Rational(3, 7) and t.formula_match
    assert all(t.checks.values()), t.checks
    m2 = dn.ize_three_level_m2()
    assert m2.exponent == sp.Rational(1, 7) and m2.checks["m2_is_eq12_applied_to_subgrid"]


def test_scattered_two_level():
    r = dn.ize_scattered_two_level()
    assert r.space_exponent == sp.Rational(6, 5) and r.time_exponent == sp.Rational(2, 5)
    assert r.match and all(r.checks.values())


def test_two_level_long_skinny_eq17_matches_eq18_does_not():
    r17 = dn.ize_eq17_two_level_long_skinny()
    assert r17.exponent == 1 and r17.formula_match  # M1 = k N Ti / Ts
    assert r17.time_exponent == sp.Rational(1, 3)
    assert r17.second_order_positive
    assert all(r17.checks.values()), r17.checks
    m2 = dn.ize_eq17_two_level_long_skinny_m2()
    assert m2.exponent == sp.Rational(3, 2) and m2.checks["M2_is_eq8_of_N2_lines"]
    r18 = dn.ize_eq18_two_level_long_skinny_space()
    assert r18.exponent == sp.Rational(5, 3) and r18.paper == sp.Rational(1, 3)
    assert r18.match is False and "DISCREPANCY" in r18.note


def test_lambdified_one_level_time_matches_direct_evaluation():
    M = np.array([10.0, 1e3, 8e5, 3.3e7])
    N, Tsetup, Ts, Ti = 1e5, 12.5, 1.3, 5.2
    direct = Tsetup + np.cbrt(M) * Ts + N / np.cbrt(M) ** 2 * Ti
    np.testing.assert_allclose(d.one_level_time(M, N, Tsetup, Ts, Ti), direct, rtol=1e-13)
    direct_ls = Tsetup + np.cbrt(M) * Ts + N / np.cbrt(M) * Ti
    np.testing.assert_allclose(d.long_skinny_time(M, N, Tsetup, Ts, Ti), direct_ls, rtol=1e-13)


@pytest.mark.parametrize("N,Ts,Ti", [(948, 1.0, 4.0), (1e5, 1.3, 5.2), (1087716, 2.0, 3.0)])
def test_derived_optimum_minimises_one_level_time(N, Ts, Ti):
    Tsetup = 7.0
    res = minimize_scalar(lambda x: d.one_level_time(math.exp(x), N, Tsetup, Ts, Ti),
                          bracket=(0.0, 30.0), method="brent", tol=1e-12)
    M_num = math.exp(res.x)
    M_star = float(d.one_level_optimal_M(N, Ts, Ti))
    assert M_star == pytest.approx(2 * N * Ti / Ts, rel=1e-12)
    assert M_num == pytest.approx(M_star, rel=1e-6)


def test_derived_optimum_minimises_long_skinny_time():
    N, Tsetup, Ts, Ti = 3996, 7.0, 1.0, 4.0
    res = minimize_scalar(lambda x: d.long_skinny_time(math.exp(x), N, Tsetup, Ts, Ti),
                          bracket=(0.0, 30.0), method="brent", tol=1e-12)
    assert math.exp(res.x) == pytest.approx((N * Ti / Ts) ** 1.5, rel=1e-6)


@pytest.mark.parametrize("fn,result", [(d.two_level_time, d.ize_eq13_two_level_optimum),
                                       (dn.two_level_long_skinny_time, dn.ize_eq17_two_level_long_skinny)])
def test_derived_two_level_optimum_minimises_time(fn, result):
    N, k, Tsetup, Ts, Ti = 2.0e5, 1.7, 7.0, 1.0, 4.0
    res = minimize(lambda x: fn(math.exp(x[0]), math.exp(x[1]), N, k, Tsetup, Ts, Ti), x0=[5.0, 3.0],
                   method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-14, "maxiter": 20000})
    sol = result().solution
    vals = {d.N: N, d.k: k, d.Ts: Ts, d.Ti: Ti}
    M1_star, M2_star = float(sol[d.m1].subs(vals)) ** 3, float(sol[d.m2].subs(vals)) ** 3
    assert math.exp(res.x[0]) == pytest.approx(M1_star, rel=1e-4)
    assert math.exp(res.x[1]) == pytest.approx(M2_star, rel=1e-4)


def test_report_shape_and_values():
    rep = dn.report()
    models = rep["models"]
    expected = {"one_level": "1", "long_skinny": "3/2", "two_level_m1": "3/5", "two_level_m2": "1",
                "three_level_m1": "3/7", "scattered_two_level": "6/5", "two_level_long_skinny_m1": "1",
                "two_level_long_skinny_m2": "3/2", "two_level_long_skinny_space": "5/3",
                **{f"d_level_L{lv}": str(sp.Rational(3, 2 * lv + 1)) for lv in range(1, 6)}}
    for name, expo in expected.items():
        assert models[name]["exponent"] == expo, name
    mismatched = {n for n, e in models.items() if not e["match"]}
    assert mismatched == {"two_level_long_skinny_space"}
    assert models["two_level_long_skinny_m1"]["space_match"] is False
    json.dumps(rep)  # serialisable: plain str/bool/None/dict only


def test_cli_derive_json(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.run([sys.executable, "-m", "experiments.run", "derive", "--json", "--out", str(tmp_path)],
                          cwd=str(REPO), env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["models"]["two_level_m1"]["exponent"] == "3/5"
    assert set(out) == {"models"}
    assert json.loads((tmp_path / "derive" / "derive.json").read_text()) == out
    md = (tmp_path / "derive" / "summary.md").read_text()
    assert "two_level_long_skinny_space" in md and "MISMATCH" in md
    assert not [p for p in (tmp_path / "derive").iterdir() if p.name.startswith(".tmp-")]


def test_cli_derive_text(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.run([sys.executable, "-m", "experiments.run", "derive", "--out", str(tmp_path)],
                          cwd=str(REPO), env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "two_level_m1" in proc.stdout and "3/5" in proc.stdout and "MISMATCH" in proc.stdout


def test_numeric_copies_of_the_paper_rules_are_the_sympy_results():
    """tracer/ cannot import costmodel, so its constants are numbers; each is tied here to the
    derivation (Eq 4's 8N, Eq 13's (8N)^0.6) and to the paper's Ti/Ts."""
    import numpy as np

    from costmodel.derive import one_level_optimal_M, two_level_M1
    from costmodel.papers import ize2007
    from tracer.accel import constants as c
    from tracer.accel.nested import NestedGrid

    assert c.IZE_TI_OVER_TS == ize2007.TI_OVER_TS.value
    n = np.array([948.0, 69451.0, 1087716.0])
    assert np.allclose(c.IZE_M_FACTOR * n, one_level_optimal_M(n, 1.0, c.IZE_TI_OVER_TS), rtol=1e-12)
    assert np.allclose((c.IZE_M_FACTOR * n) ** c.IZE_M1_EXPONENT, two_level_M1(n), rtol=1e-12)
    # the nested grid's own top-level cell count for the "ize" rule is the derived one
    for count in (948, 69451):
        assert abs(NestedGrid(levels=2, m1_rule="ize")._m1_cells(count, "ize") / two_level_M1(count) - 1) < 1e-12

"""Sympy derivations of every grid cost model in Ize, Shirley & Parker 2007, "Grid Creation Strategies for
Efficient Ray Tracing" (``../shared/papers/ize-shirley-parker-2007-grid-creation-strategies.md`` beside the repository).

One function per paper equation, named for it.  Every optimum, exponent and check is computed by sympy at call
time; the only constants typed in are the paper's *stated* results (exponents, closed forms, Ti/Ts = 4 and the
"theoretical M" columns of Tables 2-3), kept for comparison.  Results are cached (``functools.lru_cache``).

Symbols: N primitives; m = M^(1/3) cells per axis (m_i, M_i at level i, i = 1 is the top); Tsetup, Ts (the paper's
T_step), Ti (T_intersection); k (k_i) the occupancy constant: a level-i grid has k_i m_i^2 occupied cells.

Level counting: L = number of grid levels (L = 1 is a plain grid, Eq 16's "L levels").  The abstract's "d levels of
nesting" is d = L - 1 (top level O(N^{3/(3+2d)})); the introduction's "d levels" is d = L (O(N^{3/(2d+1)})).
All three say the same thing: top-level M_1 = O(N^{3/(2L+1)}).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache, reduce
from operator import mul
from typing import Callable

import sympy as sp

from costmodel.papers import ize2007

R = sp.Rational
N, N2, Tsetup, Ts, Ti, k = sp.symbols("N N2 Tsetup Ts Ti k", positive=True)
m, M, m1, m2, m3, M1, M2 = sp.symbols("m M m1 m2 m3 M1 M2", positive=True)
k1, k2 = sp.symbols("k1 k2", positive=True)
L = sp.Symbol("L", positive=True, integer=True)

#: Sec 2.2: the paper's Ti/Ts (:data:`costmodel.papers.ize2007.TI_OVER_TS`);
#: tracer.accel.constants.IZE_TI_OVER_TS is tied to it by a test.
PAPER_TI_OVER_TS = sp.Integer(ize2007.TI_OVER_TS.value)
#: Table 2 "theoretical M" (= 8N) and Table 3 (= 8 N^1.5), N -> M as printed in the paper.
PAPER_TABLE2 = {r["N"]: r["theoretical_M"] for r in ize2007.TABLE2.records()}
PAPER_TABLE3 = {r["N"]: r["theoretical_M"] for r in ize2007.TABLE3.records()}


@dataclass(frozen=True)
class Result:
    """One derived model beside the paper's statement.  ``exponent`` is the exponent of ``wrt`` in ``optimum``."""

    name: str
    equation: str
    quantity: str                    # what `optimum`/`exponent` describe, e.g. "M1 (top-level cells)"
    cost: sp.Expr
    optimum: sp.Expr
    exponent: sp.Rational
    paper: sp.Rational | sp.Expr     # the paper's stated exponent (typed in)
    wrt: sp.Symbol = N
    paper_formula: sp.Expr | None = None
    solution: dict = field(default_factory=dict)      # variable -> optimal value
    derivatives: tuple = ()
    optimal_time: sp.Expr | None = None
    time_exponent: sp.Rational | None = None
    paper_time_exponent: sp.Rational | None = None
    space_exponent: sp.Rational | None = None
    paper_space_exponent: sp.Rational | None = None
    second_order: sp.Expr | None = None
    second_order_positive: bool | None = None
    checks: dict = field(default_factory=dict)         # name -> bool, extra comparisons with the paper
    note: str = ""
    time_fn: Callable | None = None                    # lambdified cost in cell counts (numpy)

    @property
    def formula_match(self) -> bool | None:
        return None if self.paper_formula is None else same(self.optimum, self.paper_formula)

    @property
    def match(self) -> bool:
        return bool(sp.simplify(self.exponent - self.paper) == 0) and self.formula_match is not False

    @staticmethod
    def _eq(a, b):
        return None if a is None or b is None else bool(sp.simplify(a - b) == 0)

    def as_dict(self) -> dict:
        s = lambda e: None if e is None else sp.sstr(e)  # noqa: E731
        return {
            "equation": self.equation, "quantity": self.quantity, "wrt": str(self.wrt),
            "cost": s(self.cost), "optimum": s(self.optimum), "paper_formula": s(self.paper_formula),
            "exponent": s(self.exponent), "paper": s(self.paper), "match": self.match,
            "formula_match": self.formula_match,
            "solution": {str(key): s(v) for key, v in self.solution.items()},
            "derivatives": [s(x) for x in self.derivatives],
            "optimal_time": s(self.optimal_time),
            "time_exponent": s(self.time_exponent), "paper_time_exponent": s(self.paper_time_exponent),
            "time_match": self._eq(self.time_exponent, self.paper_time_exponent),
            "space_exponent": s(self.space_exponent), "paper_space_exponent": s(self.paper_space_exponent),
            "space_match": self._eq(self.space_exponent, self.paper_space_exponent),
            "second_order": s(self.second_order), "second_order_positive": self.second_order_positive,
            "checks": {key: bool(v) for key, v in self.checks.items()}, "note": self.note,
        }


# ----------------------------------------------------------------------------------------------- helpers
def same(a, b) -> bool:
    """Exact symbolic equality of two expressions in positive symbols (difference, then ratio of logs)."""
    if sp.simplify(a - b) == 0:
        return True
    return bool(sp.simplify(sp.expand_log(sp.log(a) - sp.log(b), force=True)) == 0)


def exponent_of(expr, var=N) -> sp.Rational:
    """Growth order of ``expr`` in ``var``: the largest exponent of ``var`` over its additive terms (exact)."""
    best = None
    for term in sp.Add.make_args(sp.expand(expr)):
        e = sp.simplify(var * sp.diff(sp.expand_log(sp.log(term), force=True), var))
        if not e.is_Rational:
            raise ValueError(f"term {term} is not a power law in {var}")
        best = e if best is None else max(best, e)
    return sp.Rational(best)


def _prod(xs):
    return reduce(mul, xs, sp.Integer(1))


def _exponent_in_sub_count(quantity, n_sub):
    """Exponent of a per-subgrid quantity in the subgrid's own primitive count N2 = n_sub(N): invert n_sub."""
    (n_of_n2,) = sp.solve(sp.Eq(N2, n_sub), N)
    return exponent_of(sp.expand_power_base(quantity.subs(N, n_of_n2), force=True), N2)


def _hessian_check(T, xs, sol):
    """Second-order condition: leading principal minors of the Hessian at ``sol``; returns (minors, all > 0)."""
    H = sp.hessian(T, xs).subs(sol)
    minors = [sp.simplify(H[:i, :i].det()) for i in range(1, len(xs) + 1)]
    return minors, all(bool(mn.is_positive) for mn in minors)


@lru_cache(maxsize=None)
def _lam(args, expr):
    return sp.lambdify(args, expr, "numpy")


# ------------------------------------------------------------------------------ Sec 2: one-level grid
@lru_cache(maxsize=None)
def ize_eq1_one_level_cost() -> sp.Expr:
    """Eq 1:  T = T_setup + m T_step + (N / m^2) T_intersection.

    N infinitesimal points, m^3 cells, a random ray crosses m cells and tests N/m^3 points in each."""
    return Tsetup + m * Ts + N / m**2 * Ti


@lru_cache(maxsize=None)
def ize_eq2_one_level_derivative() -> sp.Expr:
    """Eq 2:  dT/dm = T_step - (2N / m^3) T_intersection."""
    return sp.diff(ize_eq1_one_level_cost(), m)


@lru_cache(maxsize=None)
def ize_eq3_one_level_m() -> sp.Expr:
    """Eq 3:  m = cbrt(N 2 T_intersection / T_step)   (the positive root of Eq 2)."""
    (sol,) = sp.solve(sp.Eq(ize_eq2_one_level_derivative(), 0), m)
    return sol


@lru_cache(maxsize=None)
def ize_eq4_one_level_optimum() -> Result:
    """Eq 4:  M = N 2 T_intersection / T_step   (cube of Eq 3); with Ti/Ts = 4, M = 8N (Table 2).

    Also the optimal time T* = Tsetup + (3/2) Ts m* = O(N^{1/3}) and d^2T/dm^2 = 6 N Ti / m^4 > 0."""
    T, dT, ms = ize_eq1_one_level_cost(), ize_eq2_one_level_derivative(), ize_eq3_one_level_m()
    Ms = sp.expand_power_base(ms**3, force=True)
    Tstar = sp.simplify(T.subs(m, ms))
    d2 = sp.simplify(sp.diff(T, m, 2).subs(m, ms))
    M8 = Ms.subs(Ti, PAPER_TI_OVER_TS * Ts)
    checks = {
        "eq2_as_printed": same(dT, Ts - 2 * N / m**3 * Ti),
        "eq3_as_printed": same(ms, sp.cbrt(N * 2 * Ti / Ts)),
        "M_is_8N_for_Ti_over_Ts_4": same(M8, 8 * N),
        "table2_theoretical_M": all(M8.subs(N, n) == v for n, v in PAPER_TABLE2.items()),
        "T_star_is_Tsetup_plus_1.5_Ts_m": same(Tstar, Tsetup + R(3, 2) * Ts * ms),
    }
    return Result(
        name="one_level", equation="Eq 1-4", quantity="M (cells)", cost=T, optimum=Ms,
        exponent=exponent_of(Ms), paper=sp.Integer(1), paper_formula=N * 2 * Ti / Ts,
        solution={m: ms, M: Ms}, derivatives=(dT,), optimal_time=Tstar,
        time_exponent=exponent_of(Tstar), paper_time_exponent=R(1, 3),
        space_exponent=exponent_of(Ms + N), paper_space_exponent=sp.Integer(1),  # cells + N references
        second_order=d2, second_order_positive=bool(d2.is_positive), checks=checks,
        note="N points, rays miss everything; space = M cells + N references.",
        time_fn=_lam((M, N, Tsetup, Ts, Ti), T.subs(m, sp.cbrt(M))),
    )


# ---------------------------------------------------------------- Sec 3: long-skinny one-level grid
@lru_cache(maxsize=None)
def ize_eq5_long_skinny_cost() -> sp.Expr:
    """Eq 5:  T = T_setup + m T_step + (N / m) T_intersection.

    Each primitive is a line spanning the model, so it lies in ~m cells: N m / m^3 lines per cell, m cells crossed."""
    return Tsetup + m * Ts + N / m * Ti


@lru_cache(maxsize=None)
def ize_eq6_long_skinny_derivative() -> sp.Expr:
    """Eq 6:  "dT/dM" = T_step - (N / m^2) T_intersection   (printed with dM; it is dT/dm, see the note)."""
    return sp.diff(ize_eq5_long_skinny_cost(), m)


@lru_cache(maxsize=None)
def ize_eq7_long_skinny_m() -> sp.Expr:
    """Eq 7:  m = sqrt(N T_intersection / T_step)."""
    (sol,) = sp.solve(sp.Eq(ize_eq6_long_skinny_derivative(), 0), m)
    return sol


@lru_cache(maxsize=None)
def ize_eq8_long_skinny_optimum() -> Result:
    """Eq 8:  M = (N T_intersection / T_step)^1.5; with Ti/Ts = 4, M = 8 N^1.5 (Table 3); memory O(N^1.5).

    Optimal time T* = Tsetup + 2 sqrt(N Ti Ts) = O(N^{1/2}); space = M cells + N m references = O(N^{3/2})."""
    T, dT, ms = ize_eq5_long_skinny_cost(), ize_eq6_long_skinny_derivative(), ize_eq7_long_skinny_m()
    Ms = sp.expand_power_base(ms**3, force=True)
    Tstar = sp.simplify(T.subs(m, ms))
    d2 = sp.simplify(sp.diff(T, m, 2).subs(m, ms))
    dT_dM = sp.diff(T.subs(m, sp.cbrt(M)), M)
    M8 = Ms.subs(Ti, PAPER_TI_OVER_TS * Ts)
    checks = {
        "eq6_is_dT_dm": same(dT, Ts - N / m**2 * Ti),
        "eq6_is_not_dT_dM": not same(sp.simplify(dT_dM.subs(M, m**3)), Ts - N / m**2 * Ti),
        "dT_dM_has_same_root": sp.simplify(dT_dM.subs(M, Ms)) == 0,
        "eq7_as_printed": same(ms, sp.sqrt(N * Ti / Ts)),
        "M_is_8N^1.5_for_Ti_over_Ts_4": same(M8, 8 * N**R(3, 2)),
        "table3_theoretical_M": all(abs(float(M8.subs(N, n)) - v) <= 1 for n, v in PAPER_TABLE3.items()),
    }
    return Result(
        name="long_skinny", equation="Eq 5-8", quantity="M (cells)", cost=T, optimum=Ms,
        exponent=exponent_of(Ms), paper=R(3, 2), paper_formula=(N * Ti / Ts) ** R(3, 2),
        solution={m: ms, M: Ms}, derivatives=(dT,), optimal_time=Tstar,
        time_exponent=exponent_of(Tstar), paper_time_exponent=R(1, 2),
        space_exponent=exponent_of(Ms + N * ms), paper_space_exponent=R(3, 2),
        second_order=d2, second_order_positive=bool(d2.is_positive), checks=checks,
        note="Eq 6 is printed as dT/dM but its right side is dT/dm (dT/dM = dT/dm / (3m^2)); "
             "both vanish at the same m, so Eq 7-8 stand.",
        time_fn=_lam((M, N, Tsetup, Ts, Ti), T.subs(m, sp.cbrt(M))),
    )


# ----------------------------------------------------------------------------- Sec 4.1: two-level grid
@lru_cache(maxsize=None)
def ize_eq9_two_level_cost() -> sp.Expr:
    """Eq 9:  T = T_setup + m1 T_step + k (T_setup + m2 T_step + N/(k m1^2 m2^2) T_intersection).

    k m1^2 occupied top cells each hold N/(k m1^2) points in an m2^3 subgrid; a ray enters k subgrids."""
    return Tsetup + m1 * Ts + k * (Tsetup + m2 * Ts + N / (k * m1**2 * m2**2) * Ti)


@lru_cache(maxsize=None)
def ize_eq10_11_two_level_partials() -> tuple:
    """Eq 10:  dT/dm1 = T_step - 2N/(m1^3 m2^2) T_intersection;
    Eq 11:  dT/dm2 = k T_step - 2N/(m1^2 m2^3) T_intersection."""
    T = ize_eq9_two_level_cost()
    return sp.diff(T, m1), sp.diff(T, m2)


@lru_cache(maxsize=None)
def ize_eq12_two_level_m1() -> dict:
    """Eq 12:  m1 = (N 2 k^2 T_intersection / T_step)^(1/5)   (both partials set to zero; also m2 = m1/k)."""
    (sol,) = sp.solve(list(ize_eq10_11_two_level_partials()), [m1, m2], dict=True)
    return sol


@lru_cache(maxsize=None)
def ize_eq13_two_level_optimum() -> Result:
    """Eq 13:  M1 = (N 2 k^2 T_intersection / T_step)^0.6; with k = 1, Ti/Ts = 4: M1 = (8N)^0.6 (Sec 4.2).

    T* = (1+k) Tsetup + (5/2) Ts m1 = O(N^{1/5}); total cells M1 + k m1^2 M2 = O(N)."""
    T, (d1, d2), sol = ize_eq9_two_level_cost(), ize_eq10_11_two_level_partials(), ize_eq12_two_level_m1()
    M1s = sp.expand_power_base(sol[m1] ** 3, force=True)
    Tstar = sp.simplify(T.subs(sol))
    space = (m1**3 + k * m1**2 * m2**3 + 2 * N).subs(sol)
    minors, pos = _hessian_check(T, (m1, m2), sol)
    c1 = sol[m1].subs({k: 1, Ti: PAPER_TI_OVER_TS * Ts}) / N ** R(1, 5)
    checks = {
        "eq10_as_printed": same(d1, Ts - 2 * N / (m1**3 * m2**2) * Ti),
        "eq11_as_printed": same(d2, k * Ts - 2 * N / (m1**2 * m2**3) * Ti),
        "eq12_as_printed": same(sol[m1], (N * 2 * k**2 * Ti / Ts) ** R(1, 5)),
        "m2_is_m1_over_k": same(sol[m2], sol[m1] / k),
        "M1_is_(8N)^0.6_for_k1_ratio4": same(M1s.subs({k: 1, Ti: 4 * Ts}), (8 * N) ** R(3, 5)),
        "fig5_m1_coefficient_1.5": round(float(c1), 1) == 1.5,
        "T_star_is_(1+k)Tsetup_plus_2.5_Ts_m1": same(Tstar, (1 + k) * Tsetup + R(5, 2) * Ts * sol[m1]),
    }
    return Result(
        name="two_level_m1", equation="Eq 9-13", quantity="M1 (top-level cells)", cost=T, optimum=M1s,
        exponent=exponent_of(M1s), paper=R(3, 5), paper_formula=(N * 2 * k**2 * Ti / Ts) ** R(3, 5),
        solution=dict(sol), derivatives=(d1, d2), optimal_time=Tstar,
        time_exponent=exponent_of(Tstar), paper_time_exponent=R(1, 5),
        space_exponent=exponent_of(space), paper_space_exponent=sp.Integer(1),
        second_order=minors[-1], second_order_positive=pos, checks=checks,
        note="Manifold-like model: k m1^2 occupied top cells. Hessian minors "
             f"{[sp.sstr(x) for x in minors]} > 0. Figure 5 point m1 = (8N)^(1/5): coefficient "
             f"{float(c1):.3f} (paper 1.5).",
        time_fn=_lam((M1, M2, N, k, Tsetup, Ts, Ti), T.subs({m1: sp.cbrt(M1), m2: sp.cbrt(M2)})),
    )


@lru_cache(maxsize=None)
def ize_eq13_two_level_m2() -> Result:
    """Text after Eq 13: "The formula for M2 ... ends up being the same answer as in Section 2 once you account for
    the fact that there are N/(k m1^2) points total in the subgrid", i.e. M2 = 2 N2 T_intersection / T_step."""
    sol = ize_eq12_two_level_m1()
    M2s = sp.expand_power_base(sol[m2] ** 3, force=True)
    n_sub = N / (k * sol[m1] ** 2)
    one_level = ize_eq4_one_level_optimum().optimum.subs(N, N2)
    ok = same(M2s, one_level.subs(N2, n_sub))
    c2 = sp.cbrt(one_level.subs(Ti, PAPER_TI_OVER_TS * Ts)) / sp.cbrt(N2)
    return Result(
        name="two_level_m2", equation="Eq 13 (text)", quantity="M2 (cells per subgrid)", wrt=N2,
        cost=ize_eq9_two_level_cost(), optimum=M2s, exponent=_exponent_in_sub_count(M2s, n_sub),
        paper=sp.Integer(1), solution={m2: sol[m2], N2: n_sub},
        checks={"M2_is_one_level_optimum_of_N2_points": ok, "fig5_m2_coefficient_2": same(c2, 2)},
        note=f"M2 = m2^3 = {sp.sstr(M2s)} = O(N^({exponent_of(M2s)})) in N; with N2 = N/(k m1^2) points per "
             "subgrid it is exactly the Eq 4 optimum 2 N2 Ti/Ts, linear in N2.",
    )


# ---------------------------------------------------------------------------------- numeric wrappers
_NTT = (N, Ts, Ti)  # the symbols, before the wrappers' parameters shadow their names

def one_level_time(M, N, Tsetup, Ts, Ti):  # noqa: N803 - paper symbols
    """Eq 1 as a numpy function of the cell count M (m = M^(1/3))."""
    return ize_eq4_one_level_optimum().time_fn(M, N, Tsetup, Ts, Ti)


def one_level_optimal_M(N, Ts, Ti):  # noqa: N802, N803
    """Eq 4 as a numpy function: M* = 2 N Ti / Ts."""
    return _lam(_NTT, ize_eq4_one_level_optimum().optimum)(N, Ts, Ti)


def long_skinny_time(M, N, Tsetup, Ts, Ti):  # noqa: N803
    """Eq 5 as a numpy function of the cell count M."""
    return ize_eq8_long_skinny_optimum().time_fn(M, N, Tsetup, Ts, Ti)


def two_level_time(M1, M2, N, k, Tsetup, Ts, Ti):  # noqa: N803
    """Eq 9 as a numpy function of the cell counts M1 (top) and M2 (per subgrid)."""
    return ize_eq13_two_level_optimum().time_fn(M1, M2, N, k, Tsetup, Ts, Ti)


_NKTT = (N, k, Ti, Ts)


def two_level_M1(N, k=1, ti_over_ts=None):  # noqa: N802, N803
    """Eq 13 as a numpy function: M1 = (2 k^2 N Ti/Ts)^0.6, the paper's Ti/Ts (4) unless given; with
    k = 1 this is the (8N)^0.6 rule of Sec 4.2 every target and tracer.accel.nested use."""
    r = float(PAPER_TI_OVER_TS) if ti_over_ts is None else ti_over_ts
    return _lam(_NKTT, ize_eq13_two_level_optimum().optimum)(N, k, r, 1.0)

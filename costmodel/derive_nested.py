"""Ize, Shirley & Parker 2007, Sec 4.3-4.4, derived with sympy: three and L-level grids (Eq 14-16,
the d-level top-grid rule M1 = O(N^(3/(2L+1))), scattered data), two-level grids of long skinny
triangles (Eq 17-18), and the report of every derived model (the ``derive`` target). The symbols,
the :class:`~costmodel.derive.Result` record and Eq 1-13 live in :mod:`costmodel.derive`."""
from __future__ import annotations

import copy
from functools import lru_cache

import sympy as sp

from costmodel.derive import (M1, M2, N2, PAPER_TI_OVER_TS, L, M, N, R, Result, Ti, Ts, Tsetup,  # noqa: F401
                              _exponent_in_sub_count, _hessian_check, _lam, _prod, exponent_of,
                              ize_eq1_one_level_cost, ize_eq4_one_level_optimum, ize_eq8_long_skinny_optimum,
                              ize_eq9_two_level_cost, ize_eq12_two_level_m1, ize_eq13_two_level_m2,
                              ize_eq13_two_level_optimum, k, k1, k2, m, m1, m2, m3, same)


# ------------------------------------------------------------------- Sec 4.3: three and L levels
def _level_symbols(levels: int):
    ms = (m1, m2, m3)[:levels] if levels <= 3 else sp.symbols(f"m1:{levels + 1}", positive=True)
    ks = (k1, k2)[:levels - 1] if levels <= 3 else sp.symbols(f"k1:{levels}", positive=True)
    return tuple(ms), tuple(ks)


@lru_cache(maxsize=None)
def ize_d_level_cost(levels: int) -> sp.Expr:
    """The L-level cost generalising Eq 1 (L = 1), Eq 9 (L = 2, k1 = k) and Eq 14 (L = 3):

        T = sum_j K_{j-1} (T_setup + m_j T_step) + N/(m_1^2 ... m_L^2) T_intersection,  K_j = k_1 ... k_j."""
    ms, ks = _level_symbols(levels)
    K = [_prod(ks[:j]) for j in range(levels)]
    return sum(K[j] * (Tsetup + ms[j] * Ts) for j in range(levels)) + N * Ti / _prod(x**2 for x in ms)


@lru_cache(maxsize=None)
def _stationary_logs(levels: int) -> dict:
    """Solve dT/dm_j = 0 (j = 1..L) exactly: each m_j dT/dm_j is (positive monomial) - (positive monomial), so
    taking logs gives a linear system in x_j = log m_j, solved by sympy.linsolve.  Returns {m_j: value}."""
    T = ize_d_level_cost(levels)
    ms, _ = _level_symbols(levels)
    xs = sp.symbols(f"x1:{levels + 1}", real=True)
    to_x = {sp.log(mj): xj for mj, xj in zip(ms, xs)}
    eqs = []
    for mj in ms:
        terms = sp.Add.make_args(sp.expand(mj * sp.diff(T, mj)))
        pos = sp.Add(*[t for t in terms if not t.could_extract_minus_sign()])
        neg = -sp.Add(*[t for t in terms if t.could_extract_minus_sign()])
        eqs.append(sp.expand_log(sp.log(pos) - sp.log(neg), force=True).subs(to_x))
    (xsol,) = sp.linsolve(eqs, xs)
    return {mj: sp.powsimp(sp.expand(sp.exp(x))) for mj, x in zip(ms, xsol)}


def ize_d_level_top_solution(levels: int) -> dict:
    """The exact optimum {m_j: value} of the L-level cost (see ``ize_eq16_d_level_top``)."""
    return _stationary_logs(levels)


@lru_cache(maxsize=None)
def ize_eq14_three_level_cost() -> sp.Expr:
    """Eq 14:  T = T_setup + m1 T_step + k1 (T_setup + m2 T_step)
                  + k1 k2 (T_setup + m3 T_step + N/(k1 k2 m1^2 m2^2 m3^2) T_intersection)."""
    return (Tsetup + m1 * Ts + k1 * (Tsetup + m2 * Ts)
            + k1 * k2 * (Tsetup + m3 * Ts + N / (k1 * k2 * m1**2 * m2**2 * m3**2) * Ti))


@lru_cache(maxsize=None)
def ize_eq16_d_level_top(levels: int) -> Result:
    """Eq 16:  for L levels in a grid, the optimal top-level subdivision is M = O(N^{3/(2L+1)})
    (abstract: O(N^{3/(3+2d)}) for d levels of nesting, d = L - 1; intro: time O(N^{1/(2d+1)}), d = L).

    Solves the full stationarity system of the L-level cost; the Hessian is f (4 J + 2 I) scaled by 1/(m_i m_j),
    f = N Ti / prod m_j^2, so it is positive definite everywhere and the stationary point is the global minimum."""
    T = ize_d_level_cost(levels)
    ms, ks = _level_symbols(levels)
    sol = _stationary_logs(levels)
    M1s = sp.expand_power_base(sol[m1] ** 3, force=True)
    Tstar = sp.simplify(T.subs(sol))
    cells = sum(_prod(ks[i] * ms[i] ** 2 for i in range(j)) * ms[j] ** 3 for j in range(levels))
    space = (cells + levels * N).subs(sol)
    stationary = all(sp.simplify(sp.diff(T, mj).subs(sol)) == 0 for mj in ms)
    f = N * Ti / _prod(x**2 for x in ms)
    C = sp.Matrix(levels, levels, lambda i, j: sp.simplify(sp.diff(T, ms[i], ms[j]) * ms[i] * ms[j] / f))
    minors = [C[:i, :i].det() for i in range(1, levels + 1)]
    K = [_prod(ks[:j]) for j in range(levels)]
    checks = {"solution_is_stationary": stationary,
              "hessian_factor_constant": all(c.is_Rational for c in C),
              "m_j_is_m1_over_K_{j-1}": all(same(sol[ms[j]], sol[m1] / K[j]) for j in range(levels))}
    paper = sp.Integer(3) / (2 * levels + 1)
    stated = {1: 2 * N * Ti / Ts, 2: (2 * k1**2 * N * Ti / Ts) ** R(3, 5),   # Eq 4, Eq 13 (k = k1), Eq 15
              3: (2 * N * k1**4 * k2**2 * Ti / Ts) ** R(3, 7)}.get(levels)
    return Result(
        name=f"d_level_L{levels}", equation="Eq 16", quantity=f"M1 (top-level cells), L = {levels}", cost=T,
        optimum=M1s, exponent=exponent_of(M1s), paper=paper, paper_formula=stated, solution=sol,
        optimal_time=Tstar,
        time_exponent=exponent_of(Tstar), paper_time_exponent=sp.Integer(1) / (2 * levels + 1),
        space_exponent=exponent_of(space), paper_space_exponent=sp.Integer(1),
        second_order=min(minors), second_order_positive=all(x > 0 for x in minors), checks=checks,
        note=f"L = {levels} grid levels = {levels - 1} levels of nesting; Hessian factor 4J+2I leading minors "
             f"{[int(x) for x in minors]}.",
    )


@lru_cache(maxsize=None)
def ize_eq15_three_level() -> Result:
    """Eq 15:  M1 = (2 N k1^4 k2^2 T_intersection / T_step)^(3/7); the text: m1 = O(N^{1/7}), m2 = O(5th-root(N)/m1^2)."""
    res = ize_eq16_d_level_top(3)
    T14 = ize_eq14_three_level_cost()
    checks = dict(res.checks)
    checks["eq14_is_L3_cost"] = sp.expand(T14 - res.cost) == 0
    checks["eq9_is_L2_cost"] = sp.expand(ize_d_level_cost(2).subs(k1, k) - ize_eq9_two_level_cost()) == 0
    checks["eq1_is_L1_cost"] = sp.expand(ize_d_level_cost(1).subs(m1, m) - ize_eq1_one_level_cost()) == 0
    checks["L2_matches_direct_eq12_solve"] = all(
        same(v.subs(k1, k), ize_eq12_two_level_m1()[key]) for key, v in _stationary_logs(2).items())
    return Result(
        name="three_level_m1", equation="Eq 14-15", quantity="M1 (top-level cells), 3 levels", cost=T14,
        optimum=res.optimum, exponent=res.exponent, paper=R(3, 7),
        paper_formula=(2 * N * k1**4 * k2**2 * Ti / Ts) ** R(3, 7), solution=res.solution,
        optimal_time=res.optimal_time, time_exponent=res.time_exponent, paper_time_exponent=R(1, 7),
        space_exponent=res.space_exponent, paper_space_exponent=sp.Integer(1),
        second_order=res.second_order, second_order_positive=res.second_order_positive, checks=checks,
        note="Eq 14 equals the general L = 3 cost; solved by the same exact log-linear stationarity solve.",
    )


@lru_cache(maxsize=None)
def ize_three_level_m2() -> Result:
    """Sec 4.3 text after Eq 14: "m2 = O(5th-root(N)/m1^2)" -- read as m2 = O((N/m1^2)^{1/5}), the two-level rule
    (Eq 12) applied to the N/(k1 m1^2) primitives of a top-level cell ("repeatedly applied ... in each subgrid")."""
    sol = _stationary_logs(3)
    n_sub = N / (k1 * sol[m1] ** 2)
    recursive = ize_eq12_two_level_m1()[m1].subs({N: n_sub, k: k2})
    literal = exponent_of(N ** R(1, 5) / sol[m1] ** 2)
    return Result(
        name="three_level_m2", equation="Sec 4.3 (after Eq 14)", quantity="m2 (level-2 cells per axis)",
        cost=ize_eq14_three_level_cost(), optimum=sol[m2], exponent=exponent_of(sol[m2]),
        paper=exponent_of((N / sol[m1] ** 2) ** R(1, 5)), solution={m2: sol[m2], N2: n_sub},
        checks={"m2_is_eq12_applied_to_subgrid": same(sol[m2], recursive)},
        note=f"Derived m2 = m1/k1 = O(N^(1/7)) equals Eq 12 applied to the subgrid exactly. The text as printed, "
             f"5th-root(N)/m1^2, would be O(N^({literal})) (shrinking); only the reading (N/m1^2)^(1/5) is consistent.",
    )


@lru_cache(maxsize=None)
def ize_d_level_general() -> Result:
    """Eq 16 for symbolic L: power-law ansatz m_j ~ N^{a_j}.  Equation j of the system balances N^{a_j} against
    N^{1 - 2S} (S = sum a_i), so a_j = 1 - 2S for every j, S = L (1 - 2S): a = 1/(2L+1), M1 ~ N^{3/(2L+1)}."""
    S, a = sp.symbols("S a", positive=True)
    # the per-equation balance a_j + 2 S = 1, read off the derived log-linear systems for L = 1..5
    balance_ok = all(
        sp.simplify(exponent_of(ize_d_level_top_solution(lv)[mj]) + 2 * sum(
            exponent_of(v) for v in ize_d_level_top_solution(lv).values()) - 1) == 0
        for lv in range(1, 6) for mj in _level_symbols(lv)[0])
    (Ssol,) = sp.solve(sp.Eq(S, L * (1 - 2 * S)), S)
    a_sol = sp.simplify(1 - 2 * Ssol)
    expo = sp.simplify(3 * a_sol)
    d = sp.Symbol("d", positive=True, integer=True)
    checks = {"balance_a_j_plus_2S_is_1_for_L1..5": balance_ok,
              "abstract_3/(3+2d)_with_d=L-1": sp.simplify(expo - (3 / (3 + 2 * d)).subs(d, L - 1)) == 0,
              "intro_3/(2d+1)_with_d=L": sp.simplify(expo - (3 / (2 * d + 1)).subs(d, L)) == 0,
              "L1..5_table": all(ize_eq16_d_level_top(lv).exponent == expo.subs(L, lv) for lv in range(1, 6))}
    return Result(
        name="d_level", equation="Eq 16", quantity="M1 (top-level cells), L levels", cost=sp.Symbol("T_L"),
        optimum=N ** expo, exponent=expo, paper=3 / (2 * L + 1), time_exponent=a_sol,
        paper_time_exponent=1 / (2 * L + 1), checks=checks,
        note="L counts grid levels (L=1 one grid). Abstract's d = nesting depth = L-1 gives 3/(3+2d); the "
             "introduction's d = L gives 3/(2d+1): the same rule.",
    )


# ------------------------------------------------------------------------- Sec 4.1 remark: scattered
@lru_cache(maxsize=None)
def ize_scattered_two_level() -> Result:
    """Sec 4.1 after Eq 13: "if you did the above build on scattered small points (k = m1), you would get
    O(N^{6/5}) memory use and O(N^{2/5}) time, both of which are not ideal."

    The build of Eq 12 (m1 = (2k^2 N Ti/Ts)^{1/5}, m2 = m1/k, with the builder's k a constant) applied to
    scattered data, whose true occupancy is every cell: k = m1 in the Eq 9 cost and in the cell count."""
    T, sol = ize_eq9_two_level_cost(), ize_eq12_two_level_m1()
    kb = sp.Symbol("k_build", positive=True)
    build = {m1: sol[m1].subs(k, kb), m2: sol[m2].subs(k, kb)}
    T_sc = T.subs(k, m1).subs(build)
    space = (m1**3 + m1**3 * m2**3 + 2 * N).subs(build)
    # re-optimising with k = m1 instead: at fixed q = m1 m2, dT/dm1 = Tsetup + Ts > 0, so m1 -> 1 (one level)
    q = sp.Symbol("q", positive=True)
    dT_fixed_q = sp.simplify(sp.diff(T.subs(k, m1).subs(m2, q / m1), m1))
    return Result(
        name="scattered_two_level", equation="Sec 4.1 (after Eq 13)", quantity="space (cells + refs)",
        cost=T.subs(k, m1), optimum=sp.simplify(space), exponent=exponent_of(space), paper=R(6, 5),
        optimal_time=sp.simplify(T_sc), time_exponent=exponent_of(T_sc), paper_time_exponent=R(2, 5),
        space_exponent=exponent_of(space), paper_space_exponent=R(6, 5),
        checks={"reoptimised_dT_dm1_at_fixed_m1m2_positive": bool(dT_fixed_q.is_positive)},
        note=f"Eq 12 build with k = m1 (all m1^3 cells occupied). Re-optimising instead: dT/dm1 at fixed m1*m2 = "
             f"{sp.sstr(dT_fixed_q)} > 0, so nesting cannot help scattered data (Sec 4).",
    )


# --------------------------------------------------------------- Sec 4.4: two-level, long-skinny
@lru_cache(maxsize=None)
def ize_eq17_two_level_long_skinny_cost() -> sp.Expr:
    """The cost behind Eq 17 (not printed in the paper; Eq 9 with the Eq 5 change applied at both levels):

        T = T_setup + m1 T_step + k (T_setup + m2 T_step + N/(k m1 m2) T_intersection).

    N lines on a surface, each crossing ~m1 top cells: N m1 pieces over k m1^2 occupied cells gives
    N2 = N/(k m1) lines per subgrid; inside, each spans the subgrid (Eq 5): N2/m2 tests per subgrid."""
    return Tsetup + m1 * Ts + k * (Tsetup + m2 * Ts + N / (k * m1 * m2) * Ti)


@lru_cache(maxsize=None)
def ize_eq17_two_level_long_skinny() -> Result:
    """Eq 17:  M1 = k N T_intersection / T_step,  "and M2, which is identical to M in Section 3"."""
    T = ize_eq17_two_level_long_skinny_cost()
    d1, d2 = sp.diff(T, m1), sp.diff(T, m2)
    (sol,) = sp.solve([d1, d2], [m1, m2], dict=True)
    M1s = sp.expand_power_base(sol[m1] ** 3, force=True)
    Tstar = sp.simplify(T.subs(sol))
    minors, pos = _hessian_check(T, (m1, m2), sol)
    c1 = sol[m1].subs({k: 1, Ti: PAPER_TI_OVER_TS * Ts}) / sp.cbrt(N)
    return Result(
        name="two_level_long_skinny_m1", equation="Eq 17", quantity="M1 (top-level cells)", cost=T, optimum=M1s,
        exponent=exponent_of(M1s), paper=sp.Integer(1), paper_formula=k * N * Ti / Ts, solution=dict(sol),
        derivatives=(d1, d2), optimal_time=Tstar, time_exponent=exponent_of(Tstar),
        paper_time_exponent=R(1, 3), space_exponent=ize_eq18_two_level_long_skinny_space().exponent,
        paper_space_exponent=R(1, 3), second_order=minors[-1], second_order_positive=pos,
        checks={"m2_is_m1_over_k": same(sol[m2], sol[m1] / k),
                "T_star_is_(1+k)Tsetup_plus_3_Ts_m1": same(Tstar, (1 + k) * Tsetup + 3 * Ts * sol[m1]),
                "fig5_m1_coefficient_1.6": round(float(c1), 1) == 1.6},
        note=f"Eq 17 agrees; time O(N^(1/3)) agrees with the introduction; Figure 5 m1 coefficient "
             f"4^(1/3) = {float(c1):.3f} (paper 1.6). Eq 18's space O(N^(1/3)) does not (see two_level_long_skinny_space).",
        time_fn=_lam((M1, M2, N, k, Tsetup, Ts, Ti), T.subs({m1: sp.cbrt(M1), m2: sp.cbrt(M2)})),
    )


@lru_cache(maxsize=None)
def ize_eq17_two_level_long_skinny_m2() -> Result:
    """Sec 4.4: "M2, which is identical to M in Section 3" -- M2 = (N2 T_intersection / T_step)^1.5 (Eq 8)."""
    T = ize_eq17_two_level_long_skinny_cost()
    (sol,) = sp.solve([sp.diff(T, m1), sp.diff(T, m2)], [m1, m2], dict=True)
    M2s = sp.expand_power_base(sol[m2] ** 3, force=True)
    n_sub = N / (k * sol[m1])
    eq8 = ize_eq8_long_skinny_optimum().optimum.subs(N, N2)
    c2 = sp.sqrt(eq8.subs(Ti, PAPER_TI_OVER_TS * Ts)) ** R(2, 3) / sp.sqrt(N2)
    return Result(
        name="two_level_long_skinny_m2", equation="Sec 4.4 (after Eq 17)", quantity="M2 (cells per subgrid)",
        wrt=N2, cost=T, optimum=M2s, exponent=_exponent_in_sub_count(M2s, n_sub), paper=R(3, 2),
        solution={m2: sol[m2], N2: n_sub},
        checks={"M2_is_eq8_of_N2_lines": same(M2s, eq8.subs(N2, n_sub)), "fig5_m2_coefficient_2": same(c2, 2)},
        note=f"Consistent with Eq 17: a subgrid holds N2 = N/(k m1) = O(N^(2/3)) line pieces, and "
             f"M2 = (N2 Ti/Ts)^1.5 exactly; in N, M2 = {sp.sstr(M2s)} = O(N^({exponent_of(M2s)})).",
    )


@lru_cache(maxsize=None)
def ize_eq18_two_level_long_skinny_space() -> Result:
    """Eq 18:  space = O(N^{1/3}).

    Derived: cells M1 + (k m1^2 subgrids)(m2^3) plus references N m1 (top) + N m1 m2 (subgrids)."""
    T = ize_eq17_two_level_long_skinny_cost()
    (sol,) = sp.solve([sp.diff(T, m1), sp.diff(T, m2)], [m1, m2], dict=True)
    cells = (m1**3 + k * m1**2 * m2**3).subs(sol)
    refs = (N * m1 + N * m1 * m2).subs(sol)
    space = sp.simplify(cells + refs)
    return Result(
        name="two_level_long_skinny_space", equation="Eq 18", quantity="space (cells + refs)", cost=T,
        optimum=space, exponent=exponent_of(space), paper=R(1, 3),
        time_exponent=exponent_of(T.subs(sol)), paper_time_exponent=R(1, 3),
        space_exponent=exponent_of(space), paper_space_exponent=R(1, 3),
        checks={"space_superlinear_as_abstract_says": exponent_of(space) > 1,
                "M1_alone_is_linear": exponent_of(sol[m1] ** 3) == 1},
        note=f"DISCREPANCY: Eq 17 and M2 = (N2 Ti/Ts)^1.5 are mutually consistent, but they imply cells "
             f"M1 + k m1^2 m2^3 = O(N^({exponent_of(cells)})) and references N m1 m2 = O(N^({exponent_of(refs)})): space "
             f"O(N^(5/3)), super-linear as the abstract says, not O(N^(1/3)). The time is O(N^(1/3)) (the "
             f"introduction's figure), as is m1: Eq 18 most likely mislabels the trace time (or m1) as space.",
    )


# ---------------------------------------------------------------------------------- numeric wrappers
def two_level_long_skinny_time(M1, M2, N, k, Tsetup, Ts, Ti):  # noqa: N803
    """The Eq 17 cost as a numpy function of M1 and M2."""
    return ize_eq17_two_level_long_skinny().time_fn(M1, M2, N, k, Tsetup, Ts, Ti)


# ------------------------------------------------------------------------------------------ report
def all_results() -> list[Result]:
    """Every derived model, in paper order."""
    return [ize_eq4_one_level_optimum(), ize_eq8_long_skinny_optimum(), ize_eq13_two_level_optimum(),
            ize_eq13_two_level_m2(), ize_scattered_two_level(), ize_eq15_three_level(), ize_three_level_m2(),
            *[ize_eq16_d_level_top(lv) for lv in range(1, 6)], ize_d_level_general(),
            ize_eq17_two_level_long_skinny(), ize_eq17_two_level_long_skinny_m2(),
            ize_eq18_two_level_long_skinny_space()]


@lru_cache(maxsize=None)
def _report() -> dict:
    return {"models": {r.name: r.as_dict() for r in all_results()}}


def report() -> dict:
    """``{"models": {name: {...}}}``: cost, optimum, exact exponent beside the paper's, match flags, notes."""
    return copy.deepcopy(_report())


# ---------------------------------------------------------------------------------- at the paper's constants
def paper_cells(result, n: int) -> float:
    """A derived cell count (``result.optimum`` of this module) at the paper's
    constants: every occupancy constant k, k_j = 1 (Sec 4.2: "setting it to 1 seemed to give the best
    results") and Ti/Ts = 4 (Sec 2), for a scene of ``n`` triangles."""
    return float(_paper_fn(result.name, result.optimum)(n))


@lru_cache(maxsize=None)
def _paper_fn(name: str, optimum):
    ks = {s: 1 for s in optimum.free_symbols if s.name.startswith("k")}
    return sp.lambdify(N, sp.simplify(optimum.subs({**ks, Ti: PAPER_TI_OVER_TS * Ts})), "math")


def d_level_m1(n: int, levels: int) -> float:
    """Top-level cells of an L-level grid, Ize 2007 Eq 16 (Eq 4 for L = 1, Eq 13 for L = 2, Eq 15 for L = 3):

        M1 = (2 N k1^(2(L-1)) ... Ti/Ts)^(3/(2L+1))  ->  (8N)^(3/(2L+1))  with every k_j = 1, Ti/Ts = 4,

    evaluated from the sympy optimum of :func:`ize_eq16_d_level_top`."""
    return paper_cells(ize_eq16_d_level_top(levels), n)

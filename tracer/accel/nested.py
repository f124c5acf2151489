"""Two-level and d-level nested grids (Ize, Shirley & Parker 2007, Sec. 4).

A top grid of M1 near-cubical cells over the scene bounds; every occupied cell holding more than
``leaf_threshold`` triangles gets a sub-grid spanning exactly that cell (Ize's "geometrically compact"
option) with M2 = m2_factor * N2 cells (N2 = the triangles assigned to the cell), recursively down
to ``levels`` levels. Triangle assignment at every level is the uniform grid's
:func:`tracer.accel.grid.grid_assign` (exact triangle/box overlap), run on the cell's triangles.

Layout (flat arrays shared by all levels, no Python objects per cell):

* ``grid_f_`` (G, 12) float64 — per grid: origin, cell size, inverse cell size, box max (the
  :func:`tracer.accel.grid.grid_params` vector); grid 0 is the top grid, grids are numbered level by level.
* ``grid_i_`` (G, 5) int64 — per grid: nx, ny, nz, offset of its first cell in ``cells_``, level.
* ``cells_`` (C, 2) int32 — per cell ``(a, b)``: ``a >= 0`` a leaf holding references ``[a, b)``
  (empty when a == b), ``a < 0`` a child grid with index ``-a - 1``.
* ``tri_ids_`` (refs,) int32 and ``tri_verts_`` (refs, 9) float32 — leaf references, the triangles
  copied into leaf order.

Traversal: one 3D-DDA loop (set-up by :func:`tracer.accel.geometry.dda_setup`) serves every level. A child
cell suspends the current DDA state on a small per-chunk stack and starts the same loop in the child
over the parent cell's [entry, exit] parameter interval (the ray clipped to the child's box, which
is exactly the cell); leaving the child pops the parent state and steps on. Early termination when the
closest hit lies before the current cell's exit (at every level), any-hit variant for shadow rays.
"""
from __future__ import annotations

import time

import numba
import numpy as np
from numba import prange

from tracer.accel._jit import BLOCK, jit, nblocks, pjit, ray_jit, store_ray
from tracer.accel import COUNTER_NAMES, Accel, as_rays, tmax_array
from tracer.accel.constants import IZE_M1_EXPONENT, IZE_M_FACTOR
from tracer.errors import GridcostError
from tracer.accel.geometry import INF, dda_cursor, dda_setup, dda_step, ray_box, ray_triangle
from tracer.accel.pages import traversal_concat, traversal_rows
from tracer.accel.grid import grid_assign, grid_params, res_from_cells, starts_shifted
from tracer.measure.memory import check_budget, working_set

NCOUNT = len(COUNTER_NAMES)
#: per-level counter columns of :meth:`NestedGrid.intersect_levels`
LEVEL_COUNTERS = ("setups", "steps", "tests")
MAX_LEVELS = 8
M1_RULES = ("ize", "ize_skinny", "cells")
DEPTH_RULES = ("linear", "eq16")


# ---------------------------------------------------------------- resolution rules
def res_many(ext: np.ndarray, cells: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """:func:`tracer.accel.grid.res_from_cells` for many boxes at once: ``ext`` (K, 3) box extents,
    ``cells`` (K,) cell counts; per-axis resolution multiplied by ``scale``. Same formula and
    rounding as ``res_from_cells`` (checked by the tests)."""
    ext = np.maximum(np.asarray(ext, np.float64), 1e-30)
    side = (np.prod(ext, axis=1) / np.maximum(np.asarray(cells, np.float64), 1.0)) ** (1.0 / 3.0)
    return np.maximum(1, np.round(ext / side[:, None] * scale)).astype(np.int64)


def eq16_exponent(levels_left: int) -> float:
    """Ize 2007 Eq. 16: with L levels left, the grid gets M = (8N)^(3 / (2L + 1)) cells."""
    return 3.0 / (2 * levels_left + 1)


# ---------------------------------------------------------------- memory guard
#: peak bytes one level of the build holds per cell (int64 counts/starts, their diff, the cell
#: entries, leaf lengths and ends, boolean masks) and per triangle reference (ids, the per-grid
#: vertex gathers of the assignment, the gathered leaf ids, the final vertex rows): measured with
#: tracemalloc over two- and three-level grids of 0.15-1.2 M cells (tests/test_memory.py)
NESTED_BYTES_PER_CELL = 44
NESTED_BYTES_PER_REF = 82


def nested_level_bytes(kept: int, cells: int, refs: int) -> int:
    """Estimated peak while building a level of ``cells`` cells and ``refs`` references, beside the
    ``kept`` bytes of the levels above."""
    return int(kept + cells * NESTED_BYTES_PER_CELL + refs * NESTED_BYTES_PER_REF)


# ---------------------------------------------------------------- build kernels
@pjit
def _assign_level(tris, gf, gres, off, lst_start, lst_ids, exact, cs, out_ids, fill):
    """Assign the triangles of every grid of one level (``grid_assign`` on each grid's triangle list).

    Count pass (``fill=False``): grid g's cell c count goes to cs[off[g] + c + 1] (disjoint between
    grids). Fill pass: cs[k + 1] holds global cell k's start (:func:`tracer.accel.grid.starts_shifted`) and
    advances to its end, so afterwards ``cs`` is the prefix sum; out_ids receives global triangle
    ids. Grid g writes only cs[off[g] + 1 .. off[g + 1]], so its range is read from those entries
    (cs[off[g]] belongs to the previous grid, which may still be filling it)."""
    for g in prange(gf.shape[0]):
        ids = lst_ids[lst_start[g]:lst_start[g + 1]]
        sub = tris[ids]
        o = off[g]
        n = off[g + 1] - o
        view = cs[o:o + n + 1]
        r0 = cs[o + 1]
        grid_assign(sub, gf[g], gres[g, 0], gres[g, 1], gres[g, 2], exact, view, out_ids, fill)
        if fill:
            for r in range(r0, cs[o + n]):
                out_ids[r] = ids[out_ids[r]]


def _gather_ranges(src: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Concatenate src[starts[k]:ends[k]] for all k (vectorised)."""
    lens = (ends - starts).astype(np.int64)
    total = int(lens.sum())
    if total == 0:
        return np.zeros(0, src.dtype)
    out_start = np.cumsum(lens) - lens
    idx = np.repeat(starts.astype(np.int64) - out_start, lens) + np.arange(total, dtype=np.int64)
    return src[idx]


# ---------------------------------------------------------------- traversal
@ray_jit
def nested_ray(ox, oy, oz, dx, dy, dz, tmin, tmax, anyhit, GF, GI, cells, tri_ids, tv,
               sti, stf, lvl, ray):
    """Trace one ray through a nested grid: closest hit (or any hit when ``anyhit``).

    ``sti``/``stf`` are the (levels, 7) int and (levels, 7) float stacks of suspended DDA states; ``lvl`` is the
    (m, levels, 3) per-level counter array or None (compiled out). Returns
    (t, tri_id, setups, steps, tests, nodes, occupied): ``occupied`` counts the visited leaf cells that
    hold at least one reference."""
    t0, t1 = ray_box(ox, oy, oz, dx, dy, dz, GF[0, 0], GF[0, 1], GF[0, 2], GF[0, 9], GF[0, 10],
                     GF[0, 11], tmin, tmax)
    if t0 > t1:
        return INF, -1, 0, 0, 0, 0, 0
    depth = 0
    ix, iy, iz, sx, sy, sz, tnx, tny, tnz, tdx, tdy, tdz = dda_setup(
        ox, oy, oz, dx, dy, dz, t0, GF[0, 0], GF[0, 1], GF[0, 2], GF[0, 3], GF[0, 4], GF[0, 5],
        GF[0, 6], GF[0, 7], GF[0, 8], GI[0, 0], GI[0, 1], GI[0, 2])
    # stepping form (see geometry.dda_cursor); c is offset into the flat cells_ of all grids
    c, lx, ly, lz, cdx, cdy, cdz = dda_cursor(ix, iy, iz, sx, sy, sz, GI[0, 0], GI[0, 1], GI[0, 2])
    c += GI[0, 3]
    tend = t1          # exit parameter of the current grid
    tenter = t0        # entry parameter of the current cell
    setups = 1
    steps = 0
    tests = 0
    nodes = 0
    occupied = 0
    if lvl is not None:
        lvl[ray, 0, 0] += 1
    best = np.float64(tmax)
    best_id = -1
    while True:
        cu = np.uintp(c)
        steps += 1
        if lvl is not None:
            lvl[ray, depth, 1] += 1
        a = cells[cu, np.uintp(0)]
        b = cells[cu, np.uintp(1)]
        if a < 0:
            # descend: suspend this DDA, run the same loop in the child over this cell's interval
            texit = min(tnx, tny, tnz, tend)
            sti[depth, 0] = c; sti[depth, 1] = lx; sti[depth, 2] = ly; sti[depth, 3] = lz
            sti[depth, 4] = cdx; sti[depth, 5] = cdy; sti[depth, 6] = cdz
            stf[depth, 0] = tnx; stf[depth, 1] = tny; stf[depth, 2] = tnz
            stf[depth, 3] = tdx; stf[depth, 4] = tdy; stf[depth, 5] = tdz; stf[depth, 6] = tend
            depth += 1
            g = -a - 1
            nx = GI[g, 0]; ny = GI[g, 1]; nz = GI[g, 2]
            ix, iy, iz, sx, sy, sz, tnx, tny, tnz, tdx, tdy, tdz = dda_setup(
                ox, oy, oz, dx, dy, dz, tenter, GF[g, 0], GF[g, 1], GF[g, 2], GF[g, 3], GF[g, 4],
                GF[g, 5], GF[g, 6], GF[g, 7], GF[g, 8], nx, ny, nz)
            c, lx, ly, lz, cdx, cdy, cdz = dda_cursor(ix, iy, iz, sx, sy, sz, nx, ny, nz)
            c += GI[g, 3]
            tend = texit
            setups += 1
            nodes += 1
            if lvl is not None:
                lvl[ray, depth, 0] += 1
            continue
        if b > a:
            occupied += 1
        for r in range(a, b):
            ru = np.uintp(r)
            tests += 1
            t = ray_triangle(ox, oy, oz, dx, dy, dz,
                             tv[ru, 0], tv[ru, 1], tv[ru, 2], tv[ru, 3], tv[ru, 4], tv[ru, 5],
                             tv[ru, 6], tv[ru, 7], tv[ru, 8], tmin, best)
            if t < best:
                best = t
                best_id = tri_ids[ru]
                if anyhit:
                    if lvl is not None:
                        lvl[ray, depth, 2] += r - a + 1
                    return best, best_id, setups, steps, tests, nodes, occupied
        if lvl is not None:
            lvl[ray, depth, 2] += b - a if b > a else 0
        # step to the next cell (tenter: its entry, where a child grid's DDA starts); a grid whose
        # step stops (a hit before the plane, past the parent cell's exit tend, or the grid's edge)
        # pops the parent and steps it on
        done = False
        while True:
            axis, c, lx, ly, lz, tnx, tny, tnz, tenter = dda_step(c, lx, ly, lz, cdx, cdy, cdz, tnx, tny, tnz,
                                                                  tdx, tdy, tdz, best, tend)
            if axis >= 0:
                break
            if depth == 0:
                done = True
                break
            depth -= 1
            c = sti[depth, 0]; lx = sti[depth, 1]; ly = sti[depth, 2]; lz = sti[depth, 3]
            cdx = sti[depth, 4]; cdy = sti[depth, 5]; cdz = sti[depth, 6]
            tnx = stf[depth, 0]; tny = stf[depth, 1]; tnz = stf[depth, 2]
            tdx = stf[depth, 3]; tdy = stf[depth, 4]; tdz = stf[depth, 5]; tend = stf[depth, 6]
        if done:
            break
    if best_id < 0:
        best = INF
    return best, best_id, setups, steps, tests, nodes, occupied


@pjit
def nested_trace(O, D, tmin, tmax, anyhit, GF, GI, cells, tri_ids, tv, levels,
                 out_t, out_id, counters, lvl, nt):
    """Batched nested-grid traversal, ``prange`` over the ``nt`` threads, each taking every nt-th block of BLOCK rays (:data:`tracer.accel._jit.BLOCK`), one DDA-state stack per
    thread. ``counters`` (m, len(COUNTER_NAMES)) and ``lvl`` (m, levels, 3) are arrays or None (compiled out)."""
    m = O.shape[0]
    for th in prange(nt):
        sti = np.empty((levels, 7), np.int64)
        stf = np.empty((levels, 7), np.float64)
        for b in range(th, nblocks(m), nt):
            for i in range(b * BLOCK, min(m, (b + 1) * BLOCK)):
                t, tid, su, st, te, no, oc = nested_ray(
                    np.float64(O[i, 0]), np.float64(O[i, 1]), np.float64(O[i, 2]),
                    np.float64(D[i, 0]), np.float64(D[i, 1]), np.float64(D[i, 2]), tmin, np.float64(tmax[i]),
                    anyhit, GF, GI, cells, tri_ids, tv, sti, stf, lvl, i)
                store_ray(out_t, out_id, counters, i, t, tid, su, st, te, no, 0, oc)


# ---------------------------------------------------------------- the structure
class NestedGrid(Accel):
    """Nested (two-level or d-level) grid of Ize, Shirley & Parker 2007 Sec. 4.

    Parameters: ``levels`` (1 = a plain uniform grid, 2, 3, ...); top-level cells ``m1`` with
    ``m1_rule`` "ize" (M1 = (8N)^0.6, Eq. 13 with k = 1), "ize_skinny" (M1 = 8N, Eq. 17 for long
    skinny triangles) or "cells" (use ``m1``; the default when ``m1`` is given); ``m2_factor``
    (M = m2_factor * N_l cells in a sub-grid of N_l triangles); ``m1_scale``/``m2_scale`` multiply
    the per-axis resolutions m1 = M1^(1/3) and m2 (Ize's Fig. 5 sweep); ``leaf_threshold`` (cells
    with at most this many triangles stay leaves); ``exact`` (triangle/box overlap assignment).
    ``m2_rule`` "skinny" gives sub-grids M2 = (N2 Ti/Ts)^1.5 (Sec 4.4, Ti/Ts = m2_factor / 2);
    ``depth_rule`` "linear" (default: every lower level uses m2_factor * N_l) or "eq16" (Ize Eq. 16
    applied recursively: with r levels left a grid of N_l triangles gets (m2_factor N_l)^(3/(2r+1))
    cells; the top grid too when ``m1_rule="ize"``; identical to "linear" for two levels).
    """

    name = "nested"
    counter_fields = {"setups": "3D-DDA set-ups (one per grid entered)", "steps": "cells stepped, all levels",
                      "tests": "ray/triangle tests", "nodes": "sub-grids entered",
                      "occupied": "stepped cells holding a reference or a sub-grid"}

    def __init__(self, levels=2, m1=None, m1_rule=None, m2_factor=IZE_M_FACTOR, m1_scale=1.0,
                 m2_scale=1.0, leaf_threshold=2, exact=True, depth_rule="linear", m2_rule="linear"):
        self.levels, self.m1, self.m1_rule, self.m2_factor = levels, m1, m1_rule, m2_factor
        self.m2_rule = m2_rule
        self.m1_scale, self.m2_scale, self.leaf_threshold = m1_scale, m2_scale, leaf_threshold
        self.exact, self.depth_rule = exact, depth_rule

    # -------------------------------------------------------- parameters
    def _check(self):
        if int(self.levels) != self.levels or not 1 <= self.levels <= MAX_LEVELS:
            raise GridcostError(f"nested grid levels must be an integer in 1..{MAX_LEVELS}, got {self.levels}")
        rule = self.m1_rule or ("cells" if self.m1 is not None else "ize")
        if rule not in M1_RULES:
            raise GridcostError(f"unknown m1_rule {rule!r}; known: {', '.join(M1_RULES)}")
        if rule == "cells" and self.m1 is None:
            raise GridcostError("m1_rule='cells' needs m1 (the top-level cell count)")
        if self.m2_rule not in ("linear", "skinny"):
            raise GridcostError(f"unknown m2_rule {self.m2_rule!r}; known: linear, skinny")
        if self.depth_rule not in DEPTH_RULES:
            raise GridcostError(f"unknown depth_rule {self.depth_rule!r}; known: {', '.join(DEPTH_RULES)}")
        for k in ("m2_factor", "m1_scale", "m2_scale"):
            v = getattr(self, k)
            if not (np.isfinite(v) and v > 0):
                raise GridcostError(f"nested grid {k} must be a positive number, got {v}")
        if self.leaf_threshold < 0:
            raise GridcostError(f"leaf_threshold must be >= 0, got {self.leaf_threshold}")
        return rule

    def _m1_cells(self, n: int, rule: str) -> float:
        if rule == "cells":
            m1 = float(self.m1)
        elif rule == "ize_skinny":
            m1 = IZE_M_FACTOR / 2 * n  # Eq 17: M1 = k N Ti/Ts with k = 1, Ti/Ts = 4 (Fig 5 point m1 = 1.6 N^(1/3))
        elif self.depth_rule == "eq16":
            m1 = (IZE_M_FACTOR * n) ** eq16_exponent(self.levels)
        else:
            m1 = (IZE_M_FACTOR * n) ** IZE_M1_EXPONENT
        if not np.isfinite(m1) or m1 < 1:
            raise GridcostError(f"top-level cell count must be a positive number, got {m1}")
        return m1 * float(self.m1_scale) ** 3

    def _sub_cells(self, n2: np.ndarray, level: int) -> np.ndarray:
        """Cell counts of sub-grids at ``level`` (2..levels) holding n2 triangles each."""
        m = self.m2_factor * n2.astype(np.float64)
        if self.m2_rule == "skinny":  # Sec 4.4: M2 = (N2 Ti/Ts)^1.5 with Ti/Ts = m2_factor / 2
            return (m / 2) ** 1.5
        if self.depth_rule == "eq16":
            m = m ** eq16_exponent(self.levels - level + 1)
        return m

    # -------------------------------------------------------- build
    def build(self, scene):
        rule = self._check()
        levels = int(self.levels)
        n = scene.n
        m1 = self._m1_cells(n, rule)
        res1 = res_from_cells(scene.bounds, m1)
        ncell1 = int(np.prod(res1))
        what = f"a {levels}-level nested grid of {scene.name}"
        check_budget(f"{what}: top grid {res1[0]}x{res1[1]}x{res1[2]} ({ncell1:,} cells)",
                     nested_level_bytes(0, ncell1, n))
        t_start = time.perf_counter()
        tris = scene.tris
        cur_gf = grid_params(scene.bounds, res1)[None, :]
        cur_res = res1[None, :].astype(np.int64)
        lst_start = np.array([0, n], np.int64)
        lst_ids = np.arange(n, dtype=np.int32)
        gf_parts, gi_parts, cell_parts, id_parts = [], [], [], []
        g_total = cell_total = refs_total = 0
        mem = 0  # bytes of the levels kept so far (cell entries, leaf ids)
        self.peak_estimate_ = 0
        self.level_stats_ = []
        for level in range(1, levels + 1):
            ng = len(cur_gf)
            ncell = np.prod(cur_res, axis=1)
            off = np.zeros(ng + 1, np.int64)
            np.cumsum(ncell, out=off[1:])
            total = int(off[-1])
            check_budget(f"{what}: level {level} with {ng:,} grids and {total:,} cells",
                         nested_level_bytes(mem, total, int(lst_ids.size)))
            cs = np.zeros(total + 1, np.int64)
            dummy = np.zeros(0, np.int32)
            _assign_level(tris, cur_gf, cur_res, off, lst_start, lst_ids, self.exact, cs, dummy, False)
            refs_l = int(cs.sum())
            starts_shifted(cs)  # the fill pass advances the starts to the ends: cs is then the prefix sum
            est = nested_level_bytes(mem, total, refs_l)
            self.peak_estimate_ = max(self.peak_estimate_, est)
            check_budget(f"{what}: level {level} with {total:,} cells and {refs_l:,} triangle references", est)
            if refs_total + refs_l >= 2**31:
                raise GridcostError(f"{refs_total + refs_l:,} triangle references exceed the int32 index range")
            ids_l = np.empty(refs_l, np.int32)
            _assign_level(tris, cur_gf, cur_res, off, lst_start, lst_ids, self.exact, cs, ids_l, True)
            cnt = np.diff(cs)
            # which cells get a child grid
            child = np.zeros(total, bool)
            if level < levels:
                child = cnt > self.leaf_threshold
            cidx = np.flatnonzero(child)
            if len(cidx):
                g = np.searchsorted(off, cidx, side="right") - 1
                c = cidx - off[g]
                nx, ny = cur_res[g, 0], cur_res[g, 1]
                ijk = np.stack([c % nx, (c // nx) % ny, c // (nx * ny)], axis=1).astype(np.float64)
                lo = cur_gf[g, 0:3] + ijk * cur_gf[g, 3:6]
                hi = cur_gf[g, 0:3] + (ijk + 1.0) * cur_gf[g, 3:6]
                cres = res_many(hi - lo, self._sub_cells(cnt[cidx], level + 1), self.m2_scale)
                keep = (cres > 1).any(axis=1)  # a one-cell sub-grid would only add a set-up
                child[cidx[~keep]] = False
                cidx, lo, hi, cres = cidx[keep], lo[keep], hi[keep], cres[keep]
            leaf = (cnt > 0) & ~child
            ent = np.zeros((total, 2), np.int32)
            lens = np.where(leaf, cnt, 0)
            lend = refs_total + np.cumsum(lens)
            ent[leaf, 0] = lend[leaf] - lens[leaf]
            ent[leaf, 1] = lend[leaf]
            ent[cidx, 0] = -(g_total + ng + np.arange(len(cidx))) - 1
            id_parts.append(_gather_ranges(ids_l, cs[:-1][leaf], cs[1:][leaf]))
            gi = np.zeros((ng, 5), np.int64)
            gi[:, 0:3] = cur_res
            gi[:, 3] = cell_total + off[:-1]
            gi[:, 4] = level
            gf_parts.append(cur_gf)
            gi_parts.append(gi)
            cell_parts.append(ent)
            self.level_stats_.append({
                "level": level, "grids": ng, "cells": total, "refs": refs_l,
                "leaf_refs": int(lens.sum()), "empty_cells": int((cnt == 0).sum()),
                "leaf_cells": int(leaf.sum()), "child_cells": int(len(cidx)),
                "res_min": cur_res.min(axis=0).tolist(), "res_max": cur_res.max(axis=0).tolist(),
                "res_mean": np.round(cur_res.mean(axis=0), 2).tolist(),
            })
            g_total += ng
            cell_total += total
            refs_total += int(lens.sum())
            mem += ent.nbytes + gi.nbytes + cur_gf.nbytes + id_parts[-1].nbytes
            if not len(cidx):
                break
            # the next level: one grid per child cell, spanning exactly that cell
            cell = (hi - lo) / cres
            cur_gf = np.ascontiguousarray(np.concatenate([lo, cell, 1.0 / cell, hi], axis=1))
            cur_res = np.ascontiguousarray(cres)
            clen = cnt[cidx]
            lst_start = np.zeros(len(cidx) + 1, np.int64)
            np.cumsum(clen, out=lst_start[1:])
            lst_ids = _gather_ranges(ids_l, cs[:-1][cidx], cs[1:][cidx])
            del cs, ids_l
        self.grid_f_ = traversal_concat(gf_parts, gf_parts[0].dtype)
        self.grid_i_ = traversal_concat(gi_parts, gi_parts[0].dtype)
        self.cells_ = traversal_concat(cell_parts, cell_parts[0].dtype)
        self.tri_ids_ = traversal_concat(id_parts, np.int32)
        self.tri_verts_ = traversal_rows(tris.reshape(-1, 9), self.tri_ids_)
        self.build_seconds_ = time.perf_counter() - t_start
        self.m1_cells_, self.res1_, self.n_, self.levels_ = m1, res1, n, levels
        self.scene_name_ = scene.name
        return self

    # -------------------------------------------------------- trace
    def _run(self, o, d, tmin, tmax, anyhit, count):
        m = len(o)
        out_t, out_id, cnt = self._outputs(m, count)
        lvl = np.zeros((m, self.levels_, len(LEVEL_COUNTERS)), np.int32) if count else None
        nested_trace(o, d, tmin, tmax, anyhit, self.grid_f_, self.grid_i_, self.cells_,
                     self.tri_ids_, self.tri_verts_, self.levels_, out_t, out_id, cnt, lvl, numba.get_num_threads())
        return out_t, out_id, cnt, lvl

    def _trace(self, o, d, tmin, tmax, anyhit, count):
        out_t, out_id, cnt, _ = self._run(o, d, tmin, tmax, anyhit, count)
        return out_t, out_id, cnt

    def intersect_levels(self, origins, directions, tmin: float = 0.0, tmax=None) -> dict:
        """Per-level work of closest-hit tracing: ``setups``, ``steps``, ``tests`` as (m, levels)
        int32 arrays (column l-1 = level l; ``setups`` at level >= 2 = sub-grids entered there),
        ``mean`` {"setups": [per level], ...} and ``hit`` (m,) bool."""
        o, d = as_rays(origins, directions)
        _, ids, _, lvl = self._run(o, d, float(tmin), tmax_array(tmax, len(o)), False, True)
        out = {k: np.ascontiguousarray(lvl[:, :, j]) for j, k in enumerate(LEVEL_COUNTERS)}
        out["mean"] = {k: [float(x) for x in (out[k].mean(axis=0) if len(o) else np.zeros(self.levels_))]
                       for k in LEVEL_COUNTERS}
        out["hit"] = ids >= 0
        return out

    def stats(self) -> dict:
        ncell = int(len(self.cells_))
        mem = sum(int(a.nbytes) for a in (self.grid_f_, self.grid_i_, self.cells_, self.tri_ids_,
                                          self.tri_verts_))
        return {
            "structure": "nested", "levels": self.levels_, "levels_built": len(self.level_stats_),
            "M1": int(np.prod(self.res1_)), "M1_target": float(self.m1_cells_),
            "res": [int(r) for r in self.res1_], "grids": int(len(self.grid_f_)),
            "cells": ncell, "cells_per_tri": ncell / max(self.n_, 1),
            "refs": int(len(self.tri_ids_)), "refs_per_tri": len(self.tri_ids_) / max(self.n_, 1),
            "per_level": self.level_stats_, "memory_bytes": mem,
            "working_set": working_set(self.grid_f_.nbytes + self.grid_i_.nbytes + self.cells_.nbytes,
                                       self.tri_ids_.nbytes, self.tri_verts_.nbytes), "build_s": self.build_seconds_,
            "exact": self.exact, "leaf_threshold": self.leaf_threshold,
            "m2_factor": self.m2_factor, "m1_scale": self.m1_scale, "m2_scale": self.m2_scale,
            "depth_rule": self.depth_rule,
        }

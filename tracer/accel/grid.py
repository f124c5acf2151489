"""Uniform grid: resolution rules, exact (or bounding-box) triangle assignment in CSR form,
3D-DDA traversal with early termination, optional mailboxing and per-ray counters.

Layout (flat arrays, no Python objects): ``cell_start_`` (M + 1, int32) and ``tri_ids_`` (refs,
int32) in CSR form, and the triangles' vertices: ``tri_verts_`` float32 rows of 9 copied into cell
order (one row per reference, read contiguously, "copy"), or for long skinny triangles one row per
triangle ("index"), or ``tri_blocks_``: the cell-order copy transposed into SoA blocks of four
references (:mod:`tracer.accel.simd_tri`, "blocks"), so a cell's list is tested four references at
a time with :func:`~tracer.accel.simd_tri.ray_tri4` (see :func:`choose_layout`).
"""
from __future__ import annotations

import math
import time

import numba
import numpy as np
from numba import prange

from tracer.accel._jit import BLOCK, jit, nblocks, pjit, ray_jit, store_ray
from tracer.accel import COUNTER_NAMES, Accel
from tracer.accel.constants import PBRT_GRID_MAX_VOXELS, PBRT_GRID_VOXELS_PER_CUBE_ROOT, WALD_LAMBDA
from tracer.errors import GridcostError
from tracer.accel.geometry import INF, dda_cursor, dda_setup, dda_step, ray_box, ray_triangle, tri_box_overlap
from tracer.accel.pages import traversal_empty, traversal_rows
from tracer.accel.simd import ctz, popc
from tracer.accel.simd_tri import TRI4_WORDS, ray_tri4
from tracer.measure.footprint import grid_bytes
from tracer.measure.memory import check_budget, working_set

#: direct-mapped mailbox entries per thread (power of two)
MAILBOX = 32
#: relative enlargement of cells in the overlap test, so rounding never drops a touching triangle
CELL_EPS = 1e-5
NCOUNT = len(COUNTER_NAMES)


# ---------------------------------------------------------------- resolution rules
def res_from_cells(bounds, cells: float) -> np.ndarray:
    """Ize 2007 Sec 2.2: a grid of about ``cells`` cells, each as close to a cube as the bounds allow."""
    ext = np.maximum(np.asarray(bounds[1], float) - np.asarray(bounds[0], float), 1e-30)
    side = (float(np.prod(ext)) / max(float(cells), 1.0)) ** (1.0 / 3.0)
    return np.maximum(1, np.round(ext / side)).astype(np.int64)


def res_pbrt(bounds, n_tris: int, clamp: bool = True) -> np.ndarray:
    """pbrt-v2 GridAccel: 3 N^(1/3) voxels along the longest axis (clamped at 64), cubical voxels."""
    ext = np.asarray(bounds[1], float) - np.asarray(bounds[0], float)
    per_unit = PBRT_GRID_VOXELS_PER_CUBE_ROOT * n_tris ** (1.0 / 3.0) / ext.max()
    res = np.maximum(1, np.floor(ext * per_unit + 0.5)).astype(np.int64)  # pbrt's Round2Int
    return np.minimum(res, PBRT_GRID_MAX_VOXELS) if clamp else res


def res_wald(bounds, n_tris: int, lam: float = WALD_LAMBDA) -> np.ndarray:
    """Wald et al. 2006 Sec 3: n_x = d_x (lambda N / V)^(1/3)."""
    ext = np.maximum(np.asarray(bounds[1], float) - np.asarray(bounds[0], float), 1e-30)
    k = (lam * n_tris / float(np.prod(ext))) ** (1.0 / 3.0)
    return np.maximum(1, np.round(ext * k)).astype(np.int64)


def choose_layout(layout: str) -> str:
    """Where a cell's triangle vertices are read from. "copy": duplicated into cell order (36 B per
    reference, read contiguously); "blocks": the same copy transposed into SoA blocks of four
    consecutive references (the same bytes, at most three rows of padding at the end), tested four
    at a time; "index": one row per triangle reached through the reference's id, the least memory
    where triangles are referenced by many cells. "auto" takes the blocks: on an Intel Xeon with
    2 MiB of L2, "index" took 1.28-2.01x the blocks' time per random ray (1.84-2.57x camera) on
    cylinder-3996, capped-cylinder-3996, beetle-alt and dragon-48k, even where the triangles fit in
    L2 and their copy did not; only on Ize's 8N^1.5 cylinders (140-250 references per triangle) did
    it gain, 8-16 % on random rays, while losing up to 10 % on camera rays."""
    return "blocks" if layout == "auto" else layout


def grid_params(bounds, res) -> np.ndarray:
    """The float64 parameter vector the kernels take: origin, cell size, inverse cell size, bounds max."""
    lo = np.asarray(bounds[0], np.float64)
    hi = np.asarray(bounds[1], np.float64)
    cell = (hi - lo) / np.asarray(res, np.float64)
    return np.concatenate([lo, cell, 1.0 / cell, hi])


# ---------------------------------------------------------------- build
@jit
def _cell_range(lo, hi, g0, ic, n):
    i0 = int(math.floor((lo - g0) * ic - CELL_EPS))
    i1 = int(math.floor((hi - g0) * ic + CELL_EPS))
    return max(i0, 0), min(i1, n - 1)


@jit
def grid_assign(tris, gp, nx, ny, nz, exact, cell_start, tri_ids, fill):
    """Assign triangles to cells: count pass (``fill=False``: counts into cell_start[c + 1]) or fill
    pass (``fill=True``: cell_start[c + 1] holds cell c's start, :func:`starts_shifted`, and is used
    as its write cursor, so after the pass cell_start[c + 1] is cell c's end: the prefix sum, with no
    cursor array). tri_ids are filled in triangle order per cell. Candidate cells come from the
    triangle's bounds; ``exact`` keeps only cells the triangle overlaps (separating-axis test against
    the cell enlarged by CELL_EPS). Returns the number of references (int64: the count pass may
    exceed the int32 range, which the caller refuses)."""
    hx = 0.5 * gp[3] * (1.0 + 2 * CELL_EPS)
    hy = 0.5 * gp[4] * (1.0 + 2 * CELL_EPS)
    hz = 0.5 * gp[5] * (1.0 + 2 * CELL_EPS)
    refs = np.int64(0)
    for t in range(tris.shape[0]):
        ax = np.float64(tris[t, 0, 0]); ay = np.float64(tris[t, 0, 1]); az = np.float64(tris[t, 0, 2])
        bx = np.float64(tris[t, 1, 0]); by = np.float64(tris[t, 1, 1]); bz = np.float64(tris[t, 1, 2])
        cx = np.float64(tris[t, 2, 0]); cy = np.float64(tris[t, 2, 1]); cz = np.float64(tris[t, 2, 2])
        x0, x1 = _cell_range(min(ax, bx, cx), max(ax, bx, cx), gp[0], gp[6], nx)
        y0, y1 = _cell_range(min(ay, by, cy), max(ay, by, cy), gp[1], gp[7], ny)
        z0, z1 = _cell_range(min(az, bz, cz), max(az, bz, cz), gp[2], gp[8], nz)
        single = x0 == x1 and y0 == y1 and z0 == z1
        for k in range(z0, z1 + 1):
            for j in range(y0, y1 + 1):
                for i in range(x0, x1 + 1):
                    if exact and not single:
                        if not tri_box_overlap(gp[0] + (i + 0.5) * gp[3], gp[1] + (j + 0.5) * gp[4],
                                               gp[2] + (k + 0.5) * gp[5], hx, hy, hz,
                                               ax, ay, az, bx, by, bz, cx, cy, cz):
                            continue
                    c = i + nx * (j + ny * k)
                    if fill:
                        tri_ids[cell_start[c + 1]] = t
                        cell_start[c + 1] += 1
                    else:
                        cell_start[c + 1] += 1
                    refs += 1
    return refs


@jit
def starts_shifted(cell_start):
    """Counts in cell_start[c + 1] -> cell c's start in cell_start[c + 1] (an exclusive prefix sum
    one place to the right), in place: the fill pass of :func:`grid_assign` advances it to the end."""
    s = 0
    for c in range(cell_start.shape[0] - 1):
        n = cell_start[c + 1]
        cell_start[c + 1] = s
        s += n


@jit
def occupancy_bits(cell_start, out):
    """Bit c of ``out`` (little-endian within each byte, as ``np.packbits(..., bitorder='little')``)
    set where cell c holds a triangle; ``out`` zeroed, (ncell + 7) // 8 bytes."""
    for c in range(cell_start.shape[0] - 1):
        if cell_start[c + 1] > cell_start[c]:
            out[c >> 3] |= np.uint8(1 << (c & 7))


# ---------------------------------------------------------------- traversal
@jit(inline="always")
def _block_exit(o, d, lo, bsize, b):
    """t where the ray leaves block ``b`` (of size ``bsize``) along one axis."""
    if d > 0.0:
        return (lo + (b + 1) * bsize - o) / d
    if d < 0.0:
        return (lo + b * bsize - o) / d
    return INF


@ray_jit
def grid_ray(ox, oy, oz, dx, dy, dz, tmin, tmax, anyhit, gp, nx, ny, nz,
             cell_start, tri_ids, tv, mb, chunk, macro, mshift, occ=None, tvi=None, tb=None, t4=None):
    """Trace one ray through a uniform grid: closest hit (or any hit when ``anyhit``).

    Returns (t, tri_id, setups, steps, tests, skips, jumps, occupied); ``occupied`` counts the
    visited cells that hold at least one reference (the steps that load a reference list). ``mb`` is the (chunks, MAILBOX) mailbox
    array or None (mailboxing compiled out). ``macro`` is the macrocell occupancy (blocks of
    2^mshift cells per axis, uint8, x fastest) or None: entering a cell of an empty block, the ray
    jumps to the block's exit and the DDA is set up again there. ``tb`` (flat float32 SoA blocks of
    four references, "blocks" layout, with ``t4`` a float64[4] scratch) or None: the vertices are
    read from ``tv`` (``tvi`` None: "copy", else "index")."""
    t0, t1 = ray_box(ox, oy, oz, dx, dy, dz, gp[0], gp[1], gp[2], gp[9], gp[10], gp[11], tmin, tmax)
    if t0 > t1:
        return INF, -1, 0, 0, 0, 0, 0, 0
    ix, iy, iz, sx, sy, sz, tnx, tny, tnz, tdx, tdy, tdz = dda_setup(
        ox, oy, oz, dx, dy, dz, t0, gp[0], gp[1], gp[2], gp[3], gp[4], gp[5],
        gp[6], gp[7], gp[8], nx, ny, nz)
    if mb is not None:
        for h in range(MAILBOX):
            mb[chunk, h] = -1
    # the cell index moves by a signed stride per axis; l* counts the cells left before the ray
    # leaves the grid on that axis (replaces two bounds checks and the index multiply per step)
    c, lx, ly, lz, cdx, cdy, cdz = dda_cursor(ix, iy, iz, sx, sy, sz, nx, ny, nz)
    # best starts at tmax: leaving a cell at t >= best (hit found, or beyond tmax) ends the ray
    best = np.float64(tmax)
    best_ref = -1
    steps = 0
    tests = 0
    skips = 0
    jumps = 0
    occupied = 0
    tjump = -INF
    bnx = ((nx - 1) >> mshift) + 1
    bny = ((ny - 1) >> mshift) + 1
    while True:
        if macro is not None:
            bx = ix >> mshift
            by = iy >> mshift
            bz = iz >> mshift
            if macro[bx + bnx * (by + bny * bz)] == 0:
                k = float(1 << mshift)
                te = min(_block_exit(ox, dx, gp[0], gp[3] * k, bx), _block_exit(oy, dy, gp[1], gp[4] * k, by),
                         _block_exit(oz, dz, gp[2], gp[5] * k, bz))
                if best <= te or te > t1:
                    break
                if te > tjump:  # a jump that makes no progress falls back to ordinary steps
                    tjump = te
                    jumps += 1
                    ix, iy, iz, sx, sy, sz, tnx, tny, tnz, tdx, tdy, tdz = dda_setup(
                        ox, oy, oz, dx, dy, dz, te, gp[0], gp[1], gp[2], gp[3], gp[4], gp[5],
                        gp[6], gp[7], gp[8], nx, ny, nz)
                    c, lx, ly, lz, cdx, cdy, cdz = dda_cursor(ix, iy, iz, sx, sy, sz, nx, ny, nz)
                    continue
        cu = np.uintp(c)
        steps += 1
        if occ is None:
            r0 = cell_start[cu]
            r1 = cell_start[cu + np.uintp(1)]
        else:
            r0 = 0
            r1 = 0
            if (occ[cu >> np.uintp(3)] >> (cu & np.uintp(7))) & 1:
                r0 = cell_start[cu]
                r1 = cell_start[cu + np.uintp(1)]
        if r1 > r0:
            occupied += 1
        if tb is not None:
            # the references r0..r1-1 lie in the blocks r0 >> 2 .. (r1 - 1) >> 2 (blocks are not
            # aligned to cells: no padding); each block is tested whole and the lanes outside the
            # cell are masked off. The hit lanes are taken in reference order with a strict <, so
            # the nearest hit and, on equal t, the first reference win, as in the scalar loop below.
            r = r0
            while r < r1:
                blk = r >> 2
                first = blk << 2
                valid = ((1 << min(r1 - first, 4)) - 1) & ~((1 << (r - first)) - 1)
                r = first + 4
                skipm = 0
                if mb is not None:
                    v = valid
                    while v != 0:
                        k = ctz(v)
                        v &= v - 1
                        tid = tri_ids[np.uintp(first + k)]
                        h = tid & (MAILBOX - 1)
                        if mb[chunk, h] == tid:
                            skipm |= 1 << k
                        else:
                            mb[chunk, h] = tid
                    valid &= ~skipm
                    skips += popc(skipm)
                    if valid == 0:
                        continue
                tests += popc(valid)
                hm = ray_tri4(tb, np.uintp(TRI4_WORDS) * np.uintp(blk), ox, oy, oz, dx, dy, dz, tmin, best, t4) & valid
                while hm != 0:
                    k = ctz(hm)
                    hm &= hm - 1
                    if t4[k] < best:
                        best = t4[k]
                        best_ref = first + k
                        if anyhit:  # the counts the scalar loop stops at: nothing after lane k
                            rest = -(1 << (k + 1))
                            return (best, tri_ids[np.uintp(best_ref)], 1, steps, tests - popc(valid & rest),
                                    skips - popc(skipm & rest), jumps, occupied)
            r1 = r0  # the scalar loop below has nothing left to do
        for r in range(r0, r1):
            ru = np.uintp(r)
            if mb is not None:
                tid = tri_ids[ru]
                h = tid & (MAILBOX - 1)
                if mb[chunk, h] == tid:
                    skips += 1
                    continue
                mb[chunk, h] = tid
            tests += 1
            if tvi is None:  # "copy" layout: vertices stored in cell order, row = reference
                row = ru
            else:  # "index" layout: one row per triangle, reached through the reference's id
                row = np.uintp(tvi[ru])
            t = ray_triangle(ox, oy, oz, dx, dy, dz,
                             tv[row, 0], tv[row, 1], tv[row, 2], tv[row, 3], tv[row, 4], tv[row, 5],
                             tv[row, 6], tv[row, 7], tv[row, 8], tmin, best)
            if t < best:
                best = t
                best_ref = r
                if anyhit:
                    return best, tri_ids[ru], 1, steps, tests, skips, jumps, occupied
        # leave the cell through its nearest plane (stops at a hit before it, or at the grid's end)
        axis, c, lx, ly, lz, tnx, tny, tnz, _ = dda_step(c, lx, ly, lz, cdx, cdy, cdz, tnx, tny, tnz,
                                                         tdx, tdy, tdz, best, INF)
        if axis < 0:
            break
        if macro is not None:  # the macrocell test needs the cell coordinates
            if axis == 0:
                ix += sx
            elif axis == 1:
                iy += sy
            else:
                iz += sz
    if best_ref < 0:
        return INF, -1, 1, steps, tests, skips, jumps, occupied
    return best, tri_ids[np.uintp(best_ref)], 1, steps, tests, skips, jumps, occupied


@pjit
def grid_trace(O, D, tmin, tmax, anyhit, gp, nx, ny, nz, cell_start, tri_ids, tv,
               out_t, out_id, counters, mb, macro, mshift, occ, tvi, nt, tb=None):
    """Batched grid traversal: ``prange`` over the ``nt`` threads, each taking every nt-th block of
    BLOCK rays (see :data:`tracer.accel._jit.BLOCK`). ``counters`` and ``mb`` (one mailbox row per thread)
    are arrays or None; None compiles a variant without that code (Numba prunes the branches)."""
    m = O.shape[0]
    for th in prange(nt):
        t4 = np.empty(4, np.float64)
        for b in range(th, nblocks(m), nt):
            for i in range(b * BLOCK, min(m, (b + 1) * BLOCK)):
                t, tid, su, st, te, sk, ju, oc = grid_ray(
                    np.float64(O[i, 0]), np.float64(O[i, 1]), np.float64(O[i, 2]),
                    np.float64(D[i, 0]), np.float64(D[i, 1]), np.float64(D[i, 2]), tmin, np.float64(tmax[i]),
                    anyhit, gp, nx, ny, nz, cell_start, tri_ids, tv, mb, th, macro, mshift, occ, tvi, tb, t4)
                store_ray(out_t, out_id, counters, i, t, tid, su, st, te, 0, sk, oc, ju)


def macro_occupancy(cell_start, res, k: int) -> np.ndarray:
    """uint8 occupancy of k x k x k blocks of cells (x fastest), 1 where any cell holds a triangle."""
    nx, ny, nz = (int(r) for r in res)
    occ = (np.diff(cell_start) > 0).reshape(nz, ny, nx)
    bx, by, bz = -(-nx // k), -(-ny // k), -(-nz // k)
    pad = np.zeros((bz * k, by * k, bx * k), bool)
    pad[:nz, :ny, :nx] = occ
    return np.ascontiguousarray(pad.reshape(bz, k, by, k, bx, k).any(axis=(1, 3, 5)).astype(np.uint8).ravel())


@jit
def soa_blocks(tv, tri_ids, out):
    """The cell-order copy of the triangles (row r = triangle ``tri_ids[r]``) as flat float32 SoA
    blocks of four references (block b holds references 4b..4b+3, word 12 v + 4 a + lane: vertex v,
    axis a), written into ``out`` (``ceil(refs / 4) * TRI4_WORDS`` words), the last block padded with
    zeros (a degenerate triangle; its lanes are masked anyway)."""
    refs = tri_ids.shape[0]
    out[max(refs - 1, 0) // 4 * TRI4_WORDS:] = 0.0
    for r in range(refs):
        t = tri_ids[r]
        base = (r >> 2) * TRI4_WORDS + (r & 3)
        for w in range(9):
            out[base + 4 * w] = tv[t, w]
    return out


def fill_cells(scene, res, gp, exact: bool, layout: str = "copy", macro: int = 0):
    """The grid build shared by the one-level grid and the packet grid: count references per cell
    into an int32 array, turn the counts into starts in place, fill the ids (the starts advance to
    the ends: no cursor array), copy vertex rows per ``layout`` ("auto" through :func:`choose_layout`)
    and set the occupancy bits. The memory guard checks :func:`grid_bytes` before allocating
    (before counting with one reference per triangle, after counting with the real count).
    Returns (cell_start, tri_ids, tri_verts, occupancy bits, layout); ``tri_verts`` is flat
    (:func:`soa_blocks`) for "blocks", (rows, 9) otherwise."""
    ncell = int(np.prod(res))
    what = f"a {res[0]}x{res[1]}x{res[2]} grid ({ncell:,} cells) of {scene.name}"
    if ncell >= 2**31:
        raise GridcostError(f"{what}: over the int32 cell index range")
    check_budget(what, grid_bytes(ncell, scene.n, "copy", macro))
    nx, ny, nz = (int(r) for r in res)
    # the arrays the kernels walk are made in place in traversal memory (tracer.accel.pages): no copy
    cell_start = traversal_empty(ncell + 1, np.int32)  # counts, then starts, then ends (grid_assign)
    cell_start[:] = 0
    refs = int(grid_assign(scene.tris, gp, nx, ny, nz, exact, cell_start, np.zeros(0, np.int32), False))
    if refs >= 2**31:
        raise GridcostError(f"{what}: {refs:,} triangle references exceed the int32 index range")
    layout = choose_layout(layout)
    check_budget(f"{what} with {refs:,} triangle references", grid_bytes(ncell, refs, layout, macro))
    starts_shifted(cell_start)
    tri_ids = traversal_empty(refs, np.int32)
    grid_assign(scene.tris, gp, nx, ny, nz, exact, cell_start, tri_ids, True)
    tv = scene.tris.reshape(-1, 9)
    if layout == "blocks":
        tri_verts = soa_blocks(tv, tri_ids, traversal_empty(((refs + 3) // 4) * TRI4_WORDS, np.float32))
    elif layout == "copy":
        tri_verts = traversal_rows(tv, tri_ids)
    else:  # "index": the scene's own rows
        tri_verts = np.ascontiguousarray(tv)
    occ = traversal_empty((ncell + 7) // 8, np.uint8)
    occ[:] = 0
    occupancy_bits(cell_start, occ)
    return cell_start, tri_ids, tri_verts, occ, layout


class UniformGrid(Accel):
    """One-level uniform grid (Ize 2007 Sec 2; pbrt-v2 GridAccel).

    Resolution: ``cells`` (total cell count M, near-cubical cells), or ``rule='pbrt'`` (3 N^(1/3)
    along the longest axis, ``clamp`` at 64), or ``rule='wald'`` (lambda), or an explicit ``res``.
    ``exact`` selects triangle/box overlap (default) vs bounding-box assignment; ``mailbox`` turns
    on per-ray mailboxing; ``macro`` = K > 0 adds an empty-space-skipping layer of K^3-cell blocks
    (K a power of two; counter "jumps").
    """

    name = "grid"
    counter_fields = {"setups": "1 per ray entering the grid", "steps": "cells stepped",
                      "tests": "ray/triangle tests", "skips": "tests skipped by the mailbox",
                      "occupied": "stepped cells holding a reference", "jumps": "macrocell jumps"}

    def __init__(self, cells=None, res=None, rule=None, lam=WALD_LAMBDA, clamp=True, exact=True,
                 mailbox=False, factor=None, macro=0, layout="auto"):
        if layout not in ("auto", "copy", "blocks", "index"):
            raise GridcostError(f"grid layout must be 'auto', 'copy', 'blocks' or 'index', got {layout!r}")
        self.layout = layout
        for what, v in (("cell count", cells), ("factor", factor)):  # e.g. bench's unresolved "fitted"
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating))):
                raise GridcostError(f"grid {what} must be a number, got {v!r}")
        self.cells, self.res, self.rule, self.lam = cells, res, rule, lam
        self.clamp, self.exact, self.mailbox, self.factor = clamp, exact, mailbox, factor
        if macro and (int(macro) & (int(macro) - 1)):
            raise GridcostError(f"macrocell size must be a power of two, got {macro}")
        self.macro = int(macro or 0)

    def _resolution(self, scene) -> np.ndarray:
        if self.res is not None:
            res = np.asarray(self.res, np.int64)
        elif self.rule == "pbrt":
            res = res_pbrt(scene.bounds, scene.n, self.clamp)
        elif self.rule == "wald":
            res = res_wald(scene.bounds, scene.n, self.lam)
        else:
            cells = self.cells if self.cells is not None else (self.factor or 8.0) * scene.n
            if not np.isfinite(cells) or cells < 1:
                raise GridcostError(f"grid cell count must be a positive number, got {cells}")
            res = res_from_cells(scene.bounds, cells)
        if res.shape != (3,) or (res < 1).any():
            raise GridcostError(f"grid resolution must be three positive integers, got {res}")
        return res

    def build(self, scene):
        res = self._resolution(scene)
        t_start = time.perf_counter()
        gp = grid_params(scene.bounds, res)
        cell_start, tri_ids, tri_verts, occ, layout = fill_cells(scene, res, gp, self.exact, self.layout, self.macro)
        refs = len(tri_ids)
        self.cell_start_, self.tri_ids_, self.occ_, self.layout_ = cell_start, tri_ids, occ, layout
        # "blocks": the vertices live in tri_blocks_ only (tri_verts_ empty, the scalar path unused)
        self.tri_blocks_ = tri_verts if layout == "blocks" else None
        self.tri_verts_ = np.zeros((0, 9), np.float32) if layout == "blocks" else tri_verts
        self.mshift_ = int(self.macro).bit_length() - 1 if self.macro else 0
        self.macro_ = macro_occupancy(self.cell_start_, res, self.macro) if self.macro else None
        self.build_seconds_ = time.perf_counter() - t_start
        self.res_, self.gp_, self.n_, self.refs_ = res, gp, scene.n, refs
        self.scene_name_ = scene.name
        return self

    def _trace(self, o, d, tmin, tmax, anyhit, count):
        m = len(o)
        out_t, out_id, cnt = self._outputs(m, count)
        mb = np.empty((numba.get_num_threads(), MAILBOX), np.int32) if self.mailbox else None
        nx, ny, nz = (int(r) for r in self.res_)
        grid_trace(o, d, tmin, tmax, anyhit, self.gp_, nx, ny, nz, self.cell_start_, self.tri_ids_,
                   self.tri_verts_, out_t, out_id, cnt, mb, self.macro_, self.mshift_, self.occ_,
                   self.tri_ids_ if self.layout_ == "index" else None, numba.get_num_threads(), self.tri_blocks_)
        return out_t, out_id, cnt

    def stats(self) -> dict:
        ncell = int(np.prod(self.res_))
        occ = np.diff(self.cell_start_)
        vb = self.tri_verts_.nbytes + (self.tri_blocks_.nbytes if self.tri_blocks_ is not None else 0)
        return {
            "structure": "grid", "res": [int(r) for r in self.res_], "cells": ncell,
            "refs": int(self.refs_), "refs_per_tri": self.refs_ / max(self.n_, 1),
            "empty_cells": int((occ == 0).sum()), "max_refs": int(occ.max(initial=0)),
            "working_set": working_set(self.cell_start_.nbytes + self.occ_.nbytes, self.tri_ids_.nbytes, vb),
            "memory_bytes": int(self.cell_start_.nbytes + self.tri_ids_.nbytes + vb + self.occ_.nbytes),
            # the vertices as stored: "blocks" holds the copy's 36 B per reference plus at most
            # three padding rows (vertex_bytes - 36 refs)
            "vertex_bytes": int(vb),
            "build_s": self.build_seconds_, "exact": self.exact, "mailbox": self.mailbox,
            "macro": self.macro, "layout": self.layout_,
        }

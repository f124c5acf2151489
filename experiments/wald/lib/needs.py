"""What a packet walks that none of its rays needs (what limits coherent grid traversal at
low resolution).

A ray *needs* the cells its own 3D-DDA walk visits up to its closest hit, and the triangles those
cells reference: a single-ray grid traversal touches exactly these. A packet of k x k rays walks the
cells its frustum's slices cover and tests the triangles they reference that survive mailboxing and
frustum culling. :func:`packet_needs` counts, per packet of consecutive rays (the tile order of
:func:`experiments.wald.lib.views.wald_camera`), the distinct cells and triangles the packet's rays need;
:func:`needs_row` sets them beside the CGT's own per-packet counters, per ray:

* ``need_refs`` against the packet's ``considered`` references: the share of the references a
  packet loads that lie in cells none of its rays needs (macrocells let the packet skip empty
  cells unseen, so references, not cells, are the comparable count);
* the single-ray grid's tests per ray (mailboxed: each triangle once per ray) against the packet's
  ray-triangle tests per ray: the share of a packet's tests that its rays' own walks would not
  make (a packet tests each triangle it keeps on all its active rays).
"""
from __future__ import annotations

import numpy as np

from tracer.accel._jit import jit
from tracer.accel.geometry import INF, dda_cursor, dda_setup, dda_step, ray_box


@jit
def packet_needs(O, D, T, per, gp, nx, ny, nz, cell_start, tri_ids, ntri):
    """Per packet of ``per`` consecutive rays: (cell visits, distinct cells, references in the distinct
    cells, distinct triangles) of the rays' own walks through the grid (``gp``, n*, ``cell_start``, ``tri_ids`` of
    :class:`tracer.accel.grid.UniformGrid`), each walk ending at the ray's closest hit ``T`` (inf: a miss)."""
    m = O.shape[0]
    npk = (m + per - 1) // per
    out = np.zeros((npk, 4), np.int64)
    cell_mark = np.full(nx * ny * nz, -1, np.int64)
    tri_mark = np.full(ntri, -1, np.int64)
    for p in range(npk):
        for i in range(p * per, min(m, (p + 1) * per)):
            ox, oy, oz, dx, dy, dz = O[i, 0], O[i, 1], O[i, 2], D[i, 0], D[i, 1], D[i, 2]
            t0, t1 = ray_box(ox, oy, oz, dx, dy, dz, gp[0], gp[1], gp[2], gp[9], gp[10], gp[11], 0.0, INF)
            if t0 > t1:
                continue
            ix, iy, iz, sx, sy, sz, tnx, tny, tnz, tdx, tdy, tdz = dda_setup(
                ox, oy, oz, dx, dy, dz, t0, gp[0], gp[1], gp[2], gp[3], gp[4], gp[5],
                gp[6], gp[7], gp[8], nx, ny, nz)
            c, lx, ly, lz, cdx, cdy, cdz = dda_cursor(ix, iy, iz, sx, sy, sz, nx, ny, nz)
            best = T[i]
            while True:
                out[p, 0] += 1
                if cell_mark[c] != p:
                    cell_mark[c] = p
                    out[p, 1] += 1
                    out[p, 2] += cell_start[c + 1] - cell_start[c]
                    for r in range(cell_start[c], cell_start[c + 1]):
                        tid = tri_ids[r]
                        if tri_mark[tid] != p:
                            tri_mark[tid] = p
                            out[p, 3] += 1
                axis, c, lx, ly, lz, tnx, tny, tnz, _ = dda_step(c, lx, ly, lz, cdx, cdy, cdz, tnx, tny, tnz,
                                                                 tdx, tdy, tdz, best, INF)
                if axis < 0:
                    break
    return out


def needs_row(grid, rays, hits_t, packet_rays: int, n_tris: int) -> dict:
    """Per camera ray: the cells the packets' rays visit on their own walks (``own_cells``, with
    repeats), and per packet the distinct cells (``need_cells``), the references they hold
    (``need_refs``) and the distinct triangles (``need_tris``)."""
    nx, ny, nz = (int(r) for r in grid.res_)
    pk = packet_needs(rays.origins, rays.directions, np.asarray(hits_t, np.float64), int(packet_rays), grid.gp_, nx, ny, nz,
                      grid.cell_start_, grid.tri_ids_, int(n_tris))
    n = rays.n
    return {k: pk[:, j].sum() / n for j, k in enumerate(("own_cells", "need_cells", "need_refs", "need_tris"))}

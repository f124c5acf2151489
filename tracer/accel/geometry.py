"""Geometry kernels written once and used by every structure and by the oracle.

* :func:`ray_triangle` — Moeller-Trumbore in float64 on float32 vertices. Structures and the oracle
  call the same function, so a structure that tests the right triangle gets bit-identical t.
* :func:`ray_box` — slab test returning the parametric overlap [t0, t1] (robust to zero directions).
* :func:`tri_box_overlap` — Akenine-Moeller separating-axis triangle/box test (float64).
* :func:`dda_setup`, :func:`dda_cursor`, :func:`dda_step` — Amanatides & Woo 3D-DDA: set-up at
  parameter t, its stepping form, and one step to the next cell; the one copy used by the uniform
  grid, every level of the nested grids and the packet tracer's single-ray fallback.
"""
from __future__ import annotations

import math

import numpy as np

from tracer.accel._jit import jit

INF = np.inf


#: rays within this cosine of a triangle's plane are grazing and count as misses: their t is
#: numerically meaningless (every structure and the oracle agree on this, it is one function)
PARALLEL_COS = 1e-7
_PAR2 = PARALLEL_COS * PARALLEL_COS


@jit(inline="always")
def ray_triangle(ox, oy, oz, dx, dy, dz, ax, ay, az, bx, by, bz, cx, cy, cz, tmin, tmax):
    """Ray/triangle test (Moeller-Trumbore by Cramer's rule in the geometric-normal form Embree uses).
    Returns t in (tmin, tmax) or inf for a miss.

    Solves o + t d = a + u (b - a) + v (c - a). All arithmetic is float64: inputs are widened with
    ``np.float64`` (in Numba ``float(x)`` keeps a float32 a float32); the widening is exact; no back-face culling; edges inclusive (u, v >= 0, u + v <= 1, compared as u det, v det against det); degenerate triangles
    and rays within PARALLEL_COS of the triangle's plane never hit.
    """
    e1x = np.float64(bx) - np.float64(ax)
    e1y = np.float64(by) - np.float64(ay)
    e1z = np.float64(bz) - np.float64(az)
    e2x = np.float64(cx) - np.float64(ax)
    e2y = np.float64(cy) - np.float64(ay)
    e2z = np.float64(cz) - np.float64(az)
    nx = e1y * e2z - e1z * e2y
    ny = e1z * e2x - e1x * e2z
    nz = e1x * e2y - e1y * e2x
    det = dx * nx + dy * ny + dz * nz
    if det * det <= _PAR2 * (nx * nx + ny * ny + nz * nz) * (dx * dx + dy * dy + dz * dz):
        return INF
    sx = np.float64(ax) - ox
    sy = np.float64(ay) - oy
    sz = np.float64(az) - oz
    rx = dy * sz - dz * sy
    ry = dz * sx - dx * sz
    rz = dx * sy - dy * sx
    # barycentrics scaled by det: test signs against det before paying for the division
    un = -(e2x * rx + e2y * ry + e2z * rz)
    vn = e1x * rx + e1y * ry + e1z * rz
    if det > 0.0:
        if un < 0.0 or vn < 0.0 or un + vn > det:
            return INF
    elif un > 0.0 or vn > 0.0 or un + vn < det:
        return INF
    t = (sx * nx + sy * ny + sz * nz) / det
    if t > tmin and t < tmax:
        return t
    return INF


#: relative widening of node t-ranges (of the ray's t scale) in the hierarchies' traversal
#: comparisons; covers the rounding of plane distances and of ray_triangle's edge test
T_EPS = 2e-6


#: the hierarchies' pad in space, relative to the scene's largest coordinate magnitude
#: (:func:`box_pad`). ray_triangle's float64 rounding reports hits a little outside the exact
#: triangle (a ray passing a vertex or edge by a subnormal, or leaving the triangle's plane at a
#: direction component of 1e-30); such a point lies outside the exact bounds, and for a nearly
#: axis-parallel ray one float32 step in space is far more than any widening in t (``T_EPS``).
#: 2^-21 is 2-4 float32 steps of the magnitude, ~2^31 times the float64 rounding near the scene,
#: and on real meshes (extent >> 1e-6 of the coordinates) it moves no box by a visible amount.
BOX_PAD_REL = 2.0 ** -21


@jit(inline="always")
def box_pad(box):
    """The pad in space of a scene with root box ``box`` (6 float64: lo, hi): BOX_PAD_REL of its
    largest coordinate magnitude. The BVHs' node boxes are built padded by it
    (:func:`padded_bounds`); the kd-tree visits both children of a split plane while a ray is
    within it of the plane."""
    m = 0.0
    for k in range(6):
        m = max(m, abs(box[k]))
    return BOX_PAD_REL * m


def padded_bounds(tris, box):
    """Each triangle's bounds (lo, hi: (N, 3) float32) widened by :func:`box_pad` of the root box
    ``box`` and rounded outward: the boxes the BVHs build from, so a hit ray_triangle reports by
    rounding just outside a triangle is never culled by its box."""
    v = tris.astype(np.float64)
    pad = box_pad(np.asarray(box, np.float64))
    lo, hi = v.min(axis=1) - pad, v.max(axis=1) + pad
    flo, fhi = lo.astype(np.float32), hi.astype(np.float32)
    flo = np.where(flo.astype(np.float64) > lo, np.nextafter(flo, np.float32(-np.inf)), flo)
    fhi = np.where(fhi.astype(np.float64) < hi, np.nextafter(fhi, np.float32(np.inf)), fhi)
    return flo, fhi


@jit(inline="always")
def load_ray(O, D, i):
    """Ray ``i`` exactly as the grid and the oracle pass it to :func:`ray_triangle` (widened with
    np.float64, as Numba's float() keeps a float32 a float32) and its inverse direction (1 / 0 is
    inf under the kernels' numpy error model): (ox, oy, oz, dx, dy, dz, ix, iy, iz)."""
    ox = np.float64(O[i, 0])
    oy = np.float64(O[i, 1])
    oz = np.float64(O[i, 2])
    dx = np.float64(D[i, 0])
    dy = np.float64(D[i, 1])
    dz = np.float64(D[i, 2])
    return ox, oy, oz, dx, dy, dz, 1.0 / dx, 1.0 / dy, 1.0 / dz


@jit(inline="always")
def t_tolerance(t0, t1, diag, ix, iy, iz):
    """The hierarchies' ``tol``: T_EPS of the ray's t scale, |t| at the root box [t0, t1] plus the
    t-length of the scene (diag / max|d_k| >= diag / |d|, conservatively)."""
    return T_EPS * (max(abs(t0), abs(t1)) + diag * min(abs(ix), abs(iy), abs(iz)))


@jit(inline="always")
def _slab(o, d, lo, hi):
    """One axis of the slab test; a zero direction gives (-inf, inf) inside the slab, empty outside."""
    if d == 0.0:
        if o < lo or o > hi:
            return INF, -INF
        return -INF, INF
    inv = 1.0 / d
    a = (lo - o) * inv
    b = (hi - o) * inv
    if a > b:
        return b, a
    return a, b


@jit(inline="always")
def ray_box(ox, oy, oz, dx, dy, dz, x0, y0, z0, x1, y1, z1, tmin, tmax):
    """Kay-Kajiya slab test. Returns (t0, t1); the ray misses the box when t0 > t1."""
    a, b = _slab(ox, dx, x0, x1)
    t0 = max(tmin, a)
    t1 = min(tmax, b)
    a, b = _slab(oy, dy, y0, y1)
    t0 = max(t0, a)
    t1 = min(t1, b)
    a, b = _slab(oz, dz, z0, z1)
    t0 = max(t0, a)
    t1 = min(t1, b)
    return t0, t1


@jit(inline="always")
def _axis_test(a, b, fa, fb, v0a, v0b, v2a, v2b, rad_a, rad_b):
    p0 = a * v0a - b * v0b
    p2 = a * v2a - b * v2b
    mn = min(p0, p2)
    mx = max(p0, p2)
    rad = fa * rad_a + fb * rad_b
    return mn > rad or mx < -rad


@jit
def tri_box_overlap(cx, cy, cz, hx, hy, hz, ax, ay, az, bx, by, bz, qx, qy, qz):
    """Akenine-Moeller (2001) triangle/box overlap by the separating axis theorem, float64.

    Box given by centre (cx, cy, cz) and half sizes (hx, hy, hz); returns True when they overlap
    (touching counts as overlapping).
    """
    v0x = ax - cx; v0y = ay - cy; v0z = az - cz
    v1x = bx - cx; v1y = by - cy; v1z = bz - cz
    v2x = qx - cx; v2y = qy - cy; v2z = qz - cz
    # 1) the three box face normals (AABB of the triangle vs the box)
    if min(v0x, v1x, v2x) > hx or max(v0x, v1x, v2x) < -hx:
        return False
    if min(v0y, v1y, v2y) > hy or max(v0y, v1y, v2y) < -hy:
        return False
    if min(v0z, v1z, v2z) > hz or max(v0z, v1z, v2z) < -hz:
        return False
    e0x = v1x - v0x; e0y = v1y - v0y; e0z = v1z - v0z
    e1x = v2x - v1x; e1y = v2y - v1y; e1z = v2z - v1z
    e2x = v0x - v2x; e2y = v0y - v2y; e2z = v0z - v2z
    # 2) the nine edge cross products
    for k in range(3):
        if k == 0:
            ex = e0x; ey = e0y; ez = e0z
            # vertices not on this edge's line: use v0 and v2
            pax = v0x; pay = v0y; paz = v0z; pbx = v2x; pby = v2y; pbz = v2z
        elif k == 1:
            ex = e1x; ey = e1y; ez = e1z
            pax = v0x; pay = v0y; paz = v0z; pbx = v1x; pby = v1y; pbz = v1z
        else:
            ex = e2x; ey = e2y; ez = e2z
            pax = v0x; pay = v0y; paz = v0z; pbx = v1x; pby = v1y; pbz = v1z
        fex = abs(ex); fey = abs(ey); fez = abs(ez)
        # axis X x e = (0, -ez, ey)
        if _axis_test(ez, ey, fez, fey, pay, paz, pby, pbz, hy, hz):
            return False
        # axis Y x e = (ez, 0, -ex)
        if _axis_test(-ez, -ex, fez, fex, pax, paz, pbx, pbz, hx, hz):
            return False
        # axis Z x e = (-ey, ex, 0)
        if _axis_test(ey, ex, fey, fex, pax, pay, pbx, pby, hx, hy):
            return False
    # 3) the triangle's plane
    nx = e0y * e1z - e0z * e1y
    ny = e0z * e1x - e0x * e1z
    nz = e0x * e1y - e0y * e1x
    d = -(nx * v0x + ny * v0y + nz * v0z)
    r = hx * abs(nx) + hy * abs(ny) + hz * abs(nz)
    return abs(d) <= r


@jit(inline="always")
def _dda_axis(o, d, t, lo, cell, inv_cell, n):
    """One axis of the DDA set-up: cell index at parameter t, step, t of the next plane, t per cell."""
    p = o + d * t
    i = int(math.floor((p - lo) * inv_cell))
    if i < 0:
        i = 0
    elif i > n - 1:
        i = n - 1
    if d == 0.0:
        return i, 0, INF, INF
    inv = 1.0 / d  # the same expression as in _slab: inlined together, LLVM computes it once
    if d > 0.0:
        return i, 1, (lo + (i + 1) * cell - o) * inv, cell * inv
    return i, -1, (lo + i * cell - o) * inv, -cell * inv


@jit(inline="always")
def dda_setup(ox, oy, oz, dx, dy, dz, t, x0, y0, z0, cx, cy, cz, icx, icy, icz, nx, ny, nz):
    """Amanatides & Woo (1987) 3D-DDA set-up for a grid with origin (x0, y0, z0), cell sizes c*
    (inverses ic*) and resolution n*, for the ray point at parameter t (inside or on the grid box).

    Returns (ix, iy, iz, sx, sy, sz, tnx, tny, tnz, tdx, tdy, tdz): cell, steps (+1/-1/0),
    t of the next cell plane on each axis, and t per cell on each axis.
    """
    ix, sx, tnx, tdx = _dda_axis(ox, dx, t, x0, cx, icx, nx)
    iy, sy, tny, tdy = _dda_axis(oy, dy, t, y0, cy, icy, ny)
    iz, sz, tnz, tdz = _dda_axis(oz, dz, t, z0, cz, icz, nz)
    return ix, iy, iz, sx, sy, sz, tnx, tny, tnz, tdx, tdy, tdz


@jit(inline="always")
def dda_cursor(ix, iy, iz, sx, sy, sz, nx, ny, nz):
    """The stepping form of a DDA state: flat cell index c = ix + nx (iy + ny iz), the cells left
    before the ray leaves the grid on each axis (l*), and the signed index stride per axis (cd*).
    A step on axis x is then ``lx -= 1; c += cdx`` (leaving when lx == 0): no bounds checks and no
    index multiply per step."""
    nxy = nx * ny
    c = ix + nx * iy + nxy * iz
    lx = nx - 1 - ix if sx > 0 else ix
    ly = ny - 1 - iy if sy > 0 else iy
    lz = nz - 1 - iz if sz > 0 else iz
    return c, lx, ly, lz, sx, sy * nx, sz * nxy


@jit(inline="always")
def dda_step(c, lx, ly, lz, cdx, cdy, cdz, tnx, tny, tnz, tdx, tdy, tdz, best, tend):
    """One step of the DDA in the stepping form of :func:`dda_cursor`: leave the current cell through
    its nearest plane (the axis with the smallest next-crossing t*: x when tnx < tny and tnx < tnz,
    else y when tny < tnz, else z), i.e. ``l -= 1; c += cd; tn += td`` on that axis.

    The ray stops instead (nothing is updated) when the closest hit so far lies before that plane
    (``best <= t``: no later cell can hold a closer hit), when the plane lies past ``tend`` (the end
    of the interval traced, e.g. a nested grid's parent-cell exit; INF for a whole grid), or when
    that axis has no cell left (the ray leaves the grid).

    Returns (axis, c, lx, ly, lz, tnx, tny, tnz, t): ``axis`` 0/1/2 for the step taken (callers that
    track cell coordinates add the step to that axis) or -1 to stop, and ``t`` the crossing's
    parameter (the entry of the new cell)."""
    if tnx < tny:
        axis = 0 if tnx < tnz else 2
    else:
        axis = 1 if tny < tnz else 2
    if axis == 0:
        if best <= tnx or tnx > tend or lx == 0:
            return -1, c, lx, ly, lz, tnx, tny, tnz, tnx
        return 0, c + cdx, lx - 1, ly, lz, tnx + tdx, tny, tnz, tnx
    if axis == 1:
        if best <= tny or tny > tend or ly == 0:
            return -1, c, lx, ly, lz, tnx, tny, tnz, tny
        return 1, c + cdy, lx, ly - 1, lz, tnx, tny + tdy, tnz, tny
    if best <= tnz or tnz > tend or lz == 0:
        return -1, c, lx, ly, lz, tnx, tny, tnz, tnz
    return 2, c + cdz, lx, ly, lz - 1, tnx, tny, tnz + tdz, tnz

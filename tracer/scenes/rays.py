"""Deterministic (seeded) ray sets as ``(m, 3)`` float32 origin and direction arrays.

* ``random`` — each ray through two points uniform on the scene's bounding sphere (Hapala 2011;
  Ize 2007's "all rays hit the root box from outside, all equally likely").
* ``camera`` — pinhole primary rays framing the scene (its ``view`` when set, e.g. the teapot of
  ``teapot-in-stadium``; else its bounding sphere), W x H.
* ``path`` — camera rays plus k cosine-weighted diffuse bounces from their hit points.
* ``adversarial`` — axis-aligned, exactly along cell planes, through vertices and edges, starting
  inside cells and on the boundary, parallel to faces, nearly axis-parallel in a vertex's plane.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from tracer.errors import GridcostError

KINDS = ("random", "camera", "path", "adversarial")


class Rays(NamedTuple):
    origins: np.ndarray
    directions: np.ndarray
    kind: str
    seed: int

    @property
    def n(self) -> int:
        return len(self.origins)


def _pack(o, d, kind, seed) -> Rays:
    d = np.asarray(d, np.float64)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    return Rays(np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32), kind, seed)


def bounding_sphere(scene) -> tuple[np.ndarray, float]:
    lo, hi = scene.bounds.astype(np.float64)
    return (lo + hi) / 2, float(np.linalg.norm(hi - lo) / 2)


def view_sphere(scene) -> tuple[np.ndarray, float]:
    """The sphere cameras frame: the scene's ``view`` (region of interest) when set, else its
    bounding sphere."""
    view = getattr(scene, "view", None)
    if view is None:
        return bounding_sphere(scene)
    return np.asarray(view[0], np.float64), float(view[1])


def _sphere_points(rng, n) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def random_rays(scene, n: int, seed: int = 0) -> Rays:
    """Rays through two independent uniform points on the bounding sphere (origin: the first).
    Always the whole scene's sphere, never its ``view``: in ``teapot-in-stadium`` almost every random
    ray sees only the stadium walls (the teapot is 1/200 of the stadium's size)."""
    rng = np.random.default_rng(seed)
    c, r = bounding_sphere(scene)
    a = c + r * _sphere_points(rng, n)
    b = c + r * _sphere_points(rng, n)
    same = np.linalg.norm(b - a, axis=1) < 1e-9 * r
    b[same] = c  # vanishingly rare: a == b
    return _pack(a, b - a, "random", seed)


def camera_frame(scene, eye_dir=(0.55, 0.45, 0.7), fov_deg: float = 45.0):
    """(eye, forward, right, up, tan(fov / 2)) of a pinhole camera looking along ``-eye_dir`` whose
    square frame just contains the sphere :func:`view_sphere` (the scene's ``view`` when set, else the
    bounding sphere). With a view inside the scene the eye may be inside the scene: in
    ``teapot-in-stadium`` it stands in the stadium, close to the teapot, which fills the frame."""
    c, r = view_sphere(scene)
    fwd = -np.asarray(eye_dir, float)
    fwd /= np.linalg.norm(fwd)
    dist = r / np.sin(np.radians(fov_deg) / 2)
    eye = c - fwd * dist
    up0 = np.array([0.0, 0.0, 1.0]) if abs(fwd[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    right = np.cross(fwd, up0)
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    return eye, fwd, right, up, np.tan(np.radians(fov_deg) / 2)


def tile_order(width: int, height: int, tile: int) -> np.ndarray:
    """Permutation of a row-major W x H image into tile x tile blocks (row-major inside each tile,
    tiles row-major; partial tiles at the right/bottom edges keep their pixels together)."""
    y, x = np.mgrid[0:height, 0:width]
    key = ((y // tile) * ((width + tile - 1) // tile) + x // tile) * (tile * tile) + (y % tile) * tile + x % tile
    return np.argsort(key.ravel(), kind="stable")


def camera_rays(scene, width: int, height: int | None = None, seed: int = 0, jitter: bool = False,
                eye_dir=(0.55, 0.45, 0.7), tile: int = 8) -> Rays:
    """Pinhole primary rays of a W x H image from a camera framing the scene's view (default: the
    bounding sphere; see :func:`camera_frame`), ordered in
    ``tile`` x ``tile`` pixel blocks (so consecutive rays are coherent packets; ``tile=1`` gives
    plain row-major order)."""
    height = height or width
    eye, fwd, right, up, tanh = camera_frame(scene, eye_dir)
    rng = np.random.default_rng(seed)
    jy, jx = np.mgrid[0:height, 0:width].astype(np.float64)
    off = rng.random((2, height, width)) if jitter else np.full((2, height, width), 0.5)
    sx = (2 * (jx + off[0]) / width - 1) * tanh * width / height
    sy = (1 - 2 * (jy + off[1]) / height) * tanh
    d = fwd + sx[..., None] * right + sy[..., None] * up
    d = d.reshape(-1, 3)
    if tile > 1:
        d = d[tile_order(width, height, tile)]
    return _pack(np.broadcast_to(eye, d.shape), d, "camera", seed)


def _normals(scene, ids) -> np.ndarray:
    t = scene.tris[ids].astype(np.float64)
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(ln > 0, ln, 1)


def path_rays(scene, n: int, bounces: int = 2, seed: int = 0, accel=None) -> Rays:
    """Camera rays (about n / (bounces + 1) of them, jittered; framing the scene's view when set)
    and, for each hit, ``bounces`` cosine-weighted diffuse continuations; origins are offset along the
    normal by 1e-4 of the whole scene's bounding-sphere radius. Hit points come from ``accel``
    (default: a grid built here)."""
    if accel is None:
        from tracer.accel.grid import UniformGrid
        accel = UniformGrid(factor=4.0).build(scene)
    rng = np.random.default_rng(seed)
    side = max(1, int(np.sqrt(n / (bounces + 1))))
    cam = camera_rays(scene, side, side, seed=seed, jitter=True)
    _, r = bounding_sphere(scene)
    O, D = [cam.origins], [cam.directions]
    o, d = cam.origins, cam.directions
    for _ in range(bounces):
        hits, _ = accel.intersect(o, d, counters=False)
        h = hits.tri_id >= 0
        if not h.any():
            break
        p = o[h].astype(np.float64) + hits.t[h, None].astype(np.float64) * d[h]
        nrm = _normals(scene, hits.tri_id[h])
        nrm *= np.where((nrm * d[h]).sum(1) > 0, -1.0, 1.0)[:, None]  # face the incoming ray
        u1, u2 = rng.random((2, len(p)))
        rad, phi = np.sqrt(u1), 2 * np.pi * u2
        a = np.where(np.abs(nrm[:, :1]) > 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
        tx = np.cross(nrm, a)
        tx /= np.linalg.norm(tx, axis=1, keepdims=True)
        ty = np.cross(nrm, tx)
        dn = (rad * np.cos(phi))[:, None] * tx + (rad * np.sin(phi))[:, None] * ty \
            + np.sqrt(np.maximum(0, 1 - u1))[:, None] * nrm
        o = (p + 1e-4 * r * nrm).astype(np.float32)
        d = (dn / np.linalg.norm(dn, axis=1, keepdims=True)).astype(np.float32)
        O.append(o)
        D.append(d)
    o, d = np.concatenate(O), np.concatenate(D)
    if len(o) > n:
        keep = np.sort(rng.choice(len(o), n, replace=False))
        o, d = o[keep], d[keep]
    return _pack(o, d, "path", seed)


def adversarial_rays(scene, n: int, seed: int = 0, res=None) -> Rays:
    """Rays built to break traversal: axis-aligned (from outside and from inside), exactly along the
    cell planes of a grid of resolution ``res`` (default: the 8N cube-cell grid), through vertices,
    through points on edges, starting inside cells and on the box boundary, parallel to faces, and
    nearly axis-parallel past a vertex."""
    from tracer.accel.grid import res_from_cells
    rng = np.random.default_rng(seed)
    lo, hi = scene.bounds.astype(np.float64)
    ext = hi - lo
    c, r = bounding_sphere(scene)
    res = np.asarray(res if res is not None else res_from_cells(scene.bounds, 8 * scene.n))
    k = max(1, n // 9)
    V = scene.tris.astype(np.float64)
    O, D = [], []
    # 1. axis-aligned rays from outside the box, +/- each axis
    axis = rng.integers(0, 3, k)
    sign = rng.choice([-1.0, 1.0], k)
    o = lo + rng.random((k, 3)) * ext
    o[np.arange(k), axis] = np.where(sign > 0, lo[axis] - 0.1 * ext[axis] - 1e-3, hi[axis] + 0.1 * ext[axis] + 1e-3)
    d = np.zeros((k, 3))
    d[np.arange(k), axis] = sign
    O.append(o); D.append(d)
    # 2. along cell planes: two coordinates exactly on cell boundaries, axis-aligned or diagonal in-plane
    ijk = rng.integers(0, res + 1, (k, 3))
    o = lo + ijk * (ext / res)
    axis = rng.integers(0, 3, k)
    o[np.arange(k), axis] = lo[axis] - 0.05 * ext[axis]
    d = np.zeros((k, 3))
    d[np.arange(k), axis] = 1.0
    diag = rng.random(k) < 0.5  # tilt within the plane of one of the other axes
    other = (axis + 1) % 3
    d[np.arange(k)[diag], other[diag]] = rng.choice([-1.0, 1.0], diag.sum()) * ext[other[diag]] / ext[axis[diag]]
    O.append(o); D.append(d)
    # 3. through vertices, from random points on the bounding sphere
    tri = rng.integers(0, scene.n, k)
    target = V[tri, rng.integers(0, 3, k)]
    o = c + r * _sphere_points(rng, k) * 1.01
    O.append(o); D.append(target - o)
    # 4. through points on edges (shared edges: the watertightness trap)
    tri = rng.integers(0, scene.n, k)
    e = rng.integers(0, 3, k)
    w = rng.random((k, 1))
    target = V[tri, e] * (1 - w) + V[tri, (e + 1) % 3] * w
    o = c + r * _sphere_points(rng, k) * 1.01
    O.append(o); D.append(target - o)
    # 5. starting inside cells (random origin inside the box, random direction)
    o = lo + rng.random((k, 3)) * ext
    O.append(o); D.append(_sphere_points(rng, k))
    # 6. starting on the box boundary (on a face, any direction; half of them axis-aligned inward)
    o = lo + rng.random((k, 3)) * ext
    axis = rng.integers(0, 3, k)
    side = rng.integers(0, 2, k)
    o[np.arange(k), axis] = np.where(side == 1, hi[axis], lo[axis])
    d = _sphere_points(rng, k)
    ax_in = rng.random(k) < 0.5
    d[ax_in] = 0
    d[np.arange(k)[ax_in], axis[ax_in]] = np.where(side[ax_in] == 1, -1.0, 1.0)
    O.append(o); D.append(d)
    # 7. parallel to faces: in a triangle's plane, through its centroid
    tri = rng.integers(0, scene.n, k)
    t = V[tri]
    cen = t.mean(1)
    e1 = t[:, 1] - t[:, 0]
    ok = np.linalg.norm(e1, axis=1) > 0
    d = np.where(ok[:, None], e1, _sphere_points(rng, k))
    O.append(cen - d * 2.0); D.append(d)
    # 8. nearly axis-parallel in a vertex's coordinate plane: along axis b from outside the box,
    # leaving the plane o_a = v_a at a direction component of 1e-45..1e-8 (a subnormal in float32
    # at the low end). Exactly the ray passes the vertex, by rounding ray_triangle may hit it: the
    # trap of the hierarchies' boxes and split planes (tracer.accel.geometry.box_pad)
    tri = rng.integers(0, scene.n, k)
    v = V[tri, rng.integers(0, 3, k)]
    b = rng.integers(0, 3, k)
    a = (b + rng.integers(1, 3, k)) % 3
    sign = rng.choice([-1.0, 1.0], k)
    o = v.copy()
    o[np.arange(k), b] = np.where(sign > 0, lo[b] - 0.1 * ext[b] - 1e-3, hi[b] + 0.1 * ext[b] + 1e-3)
    d = np.zeros((k, 3))
    d[np.arange(k), b] = sign
    d[np.arange(k), a] = rng.choice([-1.0, 1.0], k) * 10.0 ** rng.uniform(-45, -8, k)
    O.append(o); D.append(d)
    # 9. axis-aligned rays starting inside cells (origin inside, +/- axis)
    rest = n - 8 * k
    o = lo + rng.random((rest, 3)) * ext
    d = np.zeros((rest, 3))
    d[np.arange(rest), rng.integers(0, 3, rest)] = rng.choice([-1.0, 1.0], rest)
    O.append(o); D.append(d)
    o, d = np.concatenate(O), np.concatenate(D)
    zero = np.linalg.norm(d, axis=1) == 0
    d[zero] = [0.0, 0.0, 1.0]
    return _pack(o, d, "adversarial", seed)


def make_rays(scene, kind: str, n: int, seed: int = 0, accel=None) -> Rays:
    """One entry point for every ray kind."""
    if n < 1:
        raise GridcostError(f"number of rays must be >= 1, got {n}")
    if kind == "random":
        return random_rays(scene, n, seed)
    if kind == "camera":
        side = max(1, int(round(np.sqrt(n))))
        return camera_rays(scene, side, max(1, n // side), seed)
    if kind == "path":
        return path_rays(scene, n, seed=seed, accel=accel)
    if kind == "adversarial":
        return adversarial_rays(scene, n, seed)
    raise GridcostError(f"unknown ray kind {kind!r}; known: {', '.join(KINDS)}")

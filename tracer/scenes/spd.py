"""SPD-style scenes: Eric Haines' Standard Procedural Databases (IEEE CG&A 1987) made of triangles.

Deterministic re-implementations of four SPD generators, following the published programs'
geometry (object placement, proportions, ground polygons, viewpoints) but with every object
tessellated into triangles, so the structures of :mod:`tracer` can trace them:

===================  ==========================================================================
``sphereflake-SF``   ``balls``: a sphere of radius 1/2 blooming 9 spheres of 1/3 the radius (6
                     round the "equator", 3 on top), recursively SF levels deep (10, 91, 820,
                     7381 spheres for SF = 1..4), on a 24 x 24 floor square. Each sphere is a UV
                     sphere of ``4 k^2 - 4 k`` triangles (k = 4: 48 for SF <= 3; k = 3: 24 at SF 4).
``tetra-SF``         ``tetra``: the Sierpinski tetrahedral pyramid, 4^SF triangles (SF = 1..8).
``gears-SF``         ``gears``: SF^3 gears of 36 teeth in SF layers above a 4 x 4 ground square;
                     each concave 144-vertex gear face is a fan of 144 triangles from the gear's
                     centre and each of the 144 side rectangles 2 triangles (576 per gear).
``tree-SF``          ``tree``: Aono & Kunii's binary tree, 2^(SF+1) - 1 branches, each a cone
                     (8 sides, 16 triangles) with a sphere (24 triangles) at its tip, on a
                     100 x 100 field square (SF = 1..11).
===================  ==========================================================================

Every SPD polygon (floor, field, ground) is a square of 2 triangles. ``spd_objects(name)`` gives
the object count of the original database (spheres, cones and polygons, as Fournier & Poulin 1993
count them) beside the triangle count ``spd_triangles(name)``; ``spd_view(name)`` the SPD
viewpoint (eye, look-at, up, field of view) and ``spd_camera_rays`` primary rays from it. The
scenes load by name like every other (``tracer.scenes.scene.load_scene("sphereflake-2")``) and are listed by
``tracer.scenes.scene.scene_names()``.
"""
from __future__ import annotations

import re

import numpy as np

from tracer.errors import GridcostError
from tracer.scenes.scenetype import Scene

#: name -> valid size factors (largest sizes stay under 200k triangles)
SIZES = {
    "sphereflake": (0, 1, 2, 3, 4),
    "tetra": (1, 2, 3, 4, 5, 6, 7, 8),
    "gears": (1, 2, 3, 4, 5, 6, 7),
    "tree": (1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11),
}
PATTERN = re.compile(r"^(sphereflake|tetra|gears|tree)-(\d+)$")

#: SPD viewpoints: eye, look-at, up, vertical field of view (degrees)
VIEWS = {
    "sphereflake": ((2.1, 1.3, 1.7), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 45.0),
    "tetra": ((1.022846, -3.177154, -2.174512), (-0.004103, -0.004103, 0.216539),
              (-0.816497, -0.816497, 0.816497), 45.0),
    "gears": ((-1.1, -2.1, 2.6), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 45.0),
    "tree": ((4.5, 0.4, 2.0), (0.0, 0.0, 1.5), (0.0, 0.0, 1.0), 45.0),
}


# ---------------------------------------------------------------- primitives
def _square(half: float, z: float) -> np.ndarray:
    """The SPD ground polygon: an axis-aligned square of side 2 half at height z, 2 triangles."""
    p = np.array([[half, half, z], [-half, half, z], [-half, -half, z], [half, -half, z]])
    return np.stack([p[[0, 1, 2]], p[[0, 2, 3]]]).astype(np.float32)


def uv_sphere_template(k: int) -> np.ndarray:
    """Unit UV sphere with k latitude bands and 2k longitudes: 4k^2 - 4k triangles (one per quad
    at the poles, two elsewhere); seam and pole vertices are shared exactly."""
    if k < 2:
        raise GridcostError(f"a UV sphere needs at least 2 latitude bands, got {k}")
    th = np.pi * np.arange(k + 1) / k
    j = np.arange(2 * k + 1) % (2 * k)  # the seam reuses longitude 0 exactly
    ph = np.pi * j / k
    st, ct = np.sin(th), np.cos(th)
    st[0] = st[-1] = 0.0
    P = np.stack([st[:, None] * np.cos(ph)[None], st[:, None] * np.sin(ph)[None],
                  np.broadcast_to(ct[:, None], (k + 1, 2 * k + 1))], axis=-1)
    a, b, c, d = P[:-1, :-1], P[1:, :-1], P[1:, 1:], P[:-1, 1:]
    top = np.stack([a[0], b[0], c[0]], axis=-2)
    bottom = np.stack([a[-1], b[-1], d[-1]], axis=-2)
    mid1 = np.stack([a[1:-1], b[1:-1], c[1:-1]], axis=-2).reshape(-1, 3, 3)
    mid2 = np.stack([a[1:-1], c[1:-1], d[1:-1]], axis=-2).reshape(-1, 3, 3)
    return np.concatenate([top, mid1, mid2, bottom])


def _spheres(centers, radii, k: int) -> np.ndarray:
    t = uv_sphere_template(k)
    c = np.asarray(centers, np.float64).reshape(-1, 1, 1, 3)
    r = np.asarray(radii, np.float64).reshape(-1, 1, 1, 1)
    return (t[None] * r + c).reshape(-1, 3, 3)


def _rotation_from_z(d: np.ndarray) -> np.ndarray:
    """(m, 3, 3) rotations taking +Z to the unit vectors d (m, 3) (Rodrigues about z x d)."""
    d = np.asarray(d, np.float64).reshape(-1, 3)
    R = np.tile(np.eye(3), (len(d), 1, 1))
    cz = np.clip(d[:, 2], -1.0, 1.0)
    axis = np.stack([-d[:, 1], d[:, 0], np.zeros(len(d))], axis=1)
    s = np.linalg.norm(axis, axis=1)
    gen = s > 1e-12
    k = axis[gen] / s[gen, None]
    K = np.zeros((gen.sum(), 3, 3))
    K[:, 0, 1], K[:, 0, 2] = -k[:, 2], k[:, 1]
    K[:, 1, 0], K[:, 1, 2] = k[:, 2], -k[:, 0]
    K[:, 2, 0], K[:, 2, 1] = -k[:, 1], k[:, 0]
    sa, ca = s[gen, None, None], cz[gen, None, None]
    R[gen] = np.eye(3) + sa * K + (1 - ca) * (K @ K)
    flip = ~gen & (cz < 0)
    R[flip] = np.diag([-1.0, 1.0, -1.0])  # half turn about Y
    return R


def _axis_rotation(axis, angle) -> np.ndarray:
    k = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * (K @ K)


# ---------------------------------------------------------------- sphereflake (SPD balls)
def flake_directions() -> np.ndarray:
    """The 9 unit child directions of a sphere pointing up +Z: three edge directions of a cube
    tilted so one points up (about (1, -1, 0) by asin(2/sqrt 6)), repeated at 0/120/240 degrees
    about Z: 3 on top, 6 round the equator."""
    h = 1.0 / np.sqrt(2.0)
    trio = np.array([[h, h, 0.0], [h, 0.0, -h], [0.0, h, -h]]) @ _axis_rotation((1, -1, 0), np.arcsin(2 / np.sqrt(6))).T
    out = [trio @ _axis_rotation((0, 0, 1), 2 * np.pi * s / 3).T for s in range(3)]
    return np.concatenate(out)


def sphereflake_spheres(level: int) -> tuple[np.ndarray, np.ndarray]:
    """Centres (m, 3) and radii (m,) of the SPD sphereflake of size factor ``level``."""
    objset = flake_directions()
    centers = [np.zeros((1, 3))]
    radii = [np.array([0.5])]
    c, r, d = centers[0], radii[0], np.array([[0.0, 0.0, 1.0]])
    for _ in range(level):
        R = _rotation_from_z(d)
        cd = np.einsum("mij,kj->mki", R, objset).reshape(-1, 3)  # child directions
        cd /= np.linalg.norm(cd, axis=1, keepdims=True)
        rr = np.repeat(r, 9)
        c = np.repeat(c, 9, axis=0) + cd * (rr * 4.0 / 3.0)[:, None]
        r = rr / 3.0
        d = cd
        centers.append(c)
        radii.append(r)
    return np.concatenate(centers), np.concatenate(radii)


def sphereflake(level: int, tess: int | None = None) -> np.ndarray:
    """SPD ``balls`` (sphereflake) of size factor ``level``: sum_{i<=level} 9^i UV spheres of
    4 tess^2 - 4 tess triangles (tess 4, or 3 at level 4 to stay under 200k) and the floor."""
    k = tess or (4 if level <= 3 else 3)
    c, r = sphereflake_spheres(level)
    return np.concatenate([_square(12.0, -0.5), _spheres(c, r, k).astype(np.float32)])


# ---------------------------------------------------------------- tetra (SPD tetra)
_TETRA_CORNERS = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1) if x * y * z == 1], float)
#: face vertex orders of the SPD tetra (faces 1 and 3 reversed so all face outwards alike)
_TETRA_FACES = np.array([[0, 1, 2], [3, 2, 1], [2, 3, 0], [1, 0, 3]])


def tetra(level: int) -> np.ndarray:
    """SPD ``tetra``: the Sierpinski pyramid of size factor ``level``, 4^level triangles (4 faces
    of each of 4^(level-1) tetrahedra inscribed in a cube of half-size 1 / 2^(level-1))."""
    if level < 1:
        raise GridcostError(f"tetra size factor must be >= 1, got {level}")
    c = np.zeros((1, 3))
    w = 1.0
    for _ in range(level - 1):
        c = (c[:, None, :] + _TETRA_CORNERS[None] * (w / 2.0)).reshape(-1, 3)
        w /= 2.0
    verts = c[:, None, :] + _TETRA_CORNERS[None] * w  # (m, 4, 3)
    return verts[:, _TETRA_FACES].reshape(-1, 3, 3).astype(np.float32)


# ---------------------------------------------------------------- gears (SPD gears)
GEAR_TEETH = 36
GEAR_OUTER, GEAR_INNER, GEAR_DEPTH = 0.995, 0.9, 0.1


def gear_outline(center, offset_angle, outer, inner) -> np.ndarray:
    """The 4 x TEETH outline points of one gear face (z = center z): per tooth two tip points at
    +-0.19 of the tooth angle and two root points at 0.3 and 0.7 of it."""
    ta = 2 * np.pi / GEAR_TEETH
    base = offset_angle + ta * np.arange(GEAR_TEETH)
    ang = (base[:, None] + ta * np.array([-0.19, 0.19, 0.3, 0.7])[None]).ravel()
    rad = np.tile([outer, outer, inner, inner], GEAR_TEETH)
    cx, cy, cz = center
    return np.stack([cx + rad * np.cos(ang), cy + rad * np.sin(ang), np.full(ang.shape, cz)], axis=1)


def gear(center, offset_angle, outer, inner, thickness) -> np.ndarray:
    """One gear: top and bottom faces (fans from the centre), side rectangles (2 triangles each)."""
    top = gear_outline(center, offset_angle, outer, inner)
    bot = top - [0.0, 0.0, thickness]
    nxt = np.roll(np.arange(len(top)), -1)
    ctop = np.broadcast_to(np.asarray(center, float), top.shape)
    cbot = ctop - [0.0, 0.0, thickness]
    faces = [np.stack([ctop, top, top[nxt]], axis=1), np.stack([cbot, bot[nxt], bot], axis=1),
             np.stack([top, bot, bot[nxt]], axis=1), np.stack([top, bot[nxt], top[nxt]], axis=1)]
    return np.concatenate(faces)


def gears(level: int) -> np.ndarray:
    """SPD ``gears`` of size factor ``level``: level^3 gears in a level x level x level lattice
    (meshing neighbours turned half a tooth) above the 4 x 4 ground square; 576 level^3 + 2 triangles."""
    if level < 1:
        raise GridcostError(f"gears size factor must be >= 1, got {level}")
    sf = float(level)
    ediff = 1.0 - GEAR_INNER
    outer = 1.0 / (sf - (sf - 1) * ediff / 2.0)
    step_xy = outer * (2.0 - ediff)
    thick = min(GEAR_DEPTH, 1.0 / (2.0 * sf))
    out = [_square(2.0, 0.0)]
    for iz in range(level):
        for iy in range(level):
            for ix in range(level):
                c = (-1.0 + outer + ix * step_xy, -1.0 + outer + iy * step_xy, 1.0 - iz / sf)
                ang = np.pi * ((ix + iy + iz) % 2) / GEAR_TEETH
                out.append(gear(c, ang, GEAR_OUTER * outer, GEAR_INNER * outer, thick).astype(np.float32))
    return np.concatenate(out)


# ---------------------------------------------------------------- tree (SPD tree)
TREE_ANGLES = (40.0, 25.0)
TREE_CONTRACTION = (0.65, 0.70)
TREE_DIVERGENCE = (90.0, 140.0 + 90.0)
TREE_DIAMETER = 0.67
TREE_WIDTH = 0.15
CONE_SIDES = 8
JOINT_TESS = 3


def _rot(axis: int, deg: float) -> np.ndarray:
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    m = np.eye(4)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m


def tree_branches(level: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Base points, apex points, base radii and apex radii of the 2^(level+1) - 1 branches."""
    grow = []
    for i in range(2):
        st = np.diag([TREE_CONTRACTION[i]] * 3 + [1.0])
        st[2, 3] = 1.0  # scaled branch starts at the parent's tip
        grow.append(st @ _rot(2, TREE_DIVERGENCE[i]) @ _rot(0, TREE_ANGLES[i]))
    mats = np.eye(4)[None]
    scales = np.array([1.0])
    bases, apexes, rb, ra = [], [], [], []
    for depth in range(level + 1):
        bases.append(mats[:, :3, 3].copy())
        apexes.append(mats[:, :3, 2] + mats[:, :3, 3])
        rb.append(scales * TREE_WIDTH)
        ra.append(scales * TREE_WIDTH * TREE_DIAMETER)
        if depth < level:
            mats = np.concatenate([mats @ g for g in grow])
            scales = np.concatenate([scales * TREE_DIAMETER] * 2)
    return np.concatenate(bases), np.concatenate(apexes), np.concatenate(rb), np.concatenate(ra)


def _cones(base, apex, rb, ra, sides: int) -> np.ndarray:
    axis = apex - base
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    R = _rotation_from_z(axis)
    ang = 2 * np.pi * (np.arange(sides + 1) % sides) / sides
    ring = np.stack([np.cos(ang), np.sin(ang), np.zeros(sides + 1)], axis=1)  # (s+1, 3)
    ring = np.einsum("mij,kj->mki", R, ring)
    lo = base[:, None] + ring * rb[:, None, None]
    hi = apex[:, None] + ring * ra[:, None, None]
    t1 = np.stack([lo[:, :-1], lo[:, 1:], hi[:, 1:]], axis=2)
    t2 = np.stack([lo[:, :-1], hi[:, 1:], hi[:, :-1]], axis=2)
    return np.concatenate([t1, t2], axis=1).reshape(-1, 3, 3)


def tree(level: int) -> np.ndarray:
    """SPD ``tree`` of size factor ``level``: 2^(level+1) - 1 branches (cone + tip sphere, 40
    triangles) on the 100 x 100 field square."""
    if level < 0:
        raise GridcostError(f"tree size factor must be >= 0, got {level}")
    b, a, rb, ra = tree_branches(level)
    return np.concatenate([_square(50.0, 0.0), _cones(b, a, rb, ra, CONE_SIDES).astype(np.float32),
                           _spheres(a, ra, JOINT_TESS).astype(np.float32)])


# ---------------------------------------------------------------- registry
GENERATORS = {"sphereflake": sphereflake, "tetra": tetra, "gears": gears, "tree": tree}


def parse(name: str) -> tuple[str, int]:
    m = PATTERN.match(str(name))
    if not m:
        raise GridcostError(f"unknown SPD scene {name!r}; known: " + ", ".join(f"{k}-{{{v[0]}..{v[-1]}}}" for k, v in SIZES.items()))
    kind, level = m.group(1), int(m.group(2))
    if level not in SIZES[kind]:
        raise GridcostError(f"SPD scene {name!r}: size factor must be one of {SIZES[kind]}")
    return kind, level


def matches(name: str) -> bool:
    return bool(PATTERN.match(str(name)))


def names() -> list[str]:
    return [f"{k}-{s}" for k, sizes in SIZES.items() for s in sizes]


def spd_triangles(name: str) -> int:
    """Triangle count of an SPD scene, from the generators' formulas."""
    kind, sf = parse(name)
    if kind == "sphereflake":
        k = 4 if sf <= 3 else 3
        return 2 + (4 * k * k - 4 * k) * sum(9**i for i in range(sf + 1))
    if kind == "tetra":
        return 4**sf
    if kind == "gears":
        return 2 + 16 * GEAR_TEETH * sf**3
    return 2 + (2 * CONE_SIDES + 4 * JOINT_TESS**2 - 4 * JOINT_TESS) * (2 ** (sf + 1) - 1)


def spd_objects(name: str) -> int:
    """Object count of the original (untessellated) SPD database: spheres, cones, polygons."""
    kind, sf = parse(name)
    if kind == "sphereflake":
        return 1 + sum(9**i for i in range(sf + 1))
    if kind == "tetra":
        return 4**sf
    if kind == "gears":
        return 1 + (2 + 4 * GEAR_TEETH) * sf**3
    return 1 + 2 * (2 ** (sf + 1) - 1)


def spd_scene(name: str):
    """The named SPD scene (e.g. ``"sphereflake-2"``, ``"tetra-5"``) as a :class:`~tracer.scenes.scenetype.Scene`
    (what :func:`tracer.scenes.scene.load_scene` returns for SPD names)."""
    kind, sf = parse(name)
    return Scene(GENERATORS[kind](sf), name, "spd")


def spd_view(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The SPD viewpoint of a scene (kind or full name): eye, look-at, up, vertical fov (deg)."""
    kind = parse(name)[0] if "-" in str(name) else str(name)
    if kind not in VIEWS:
        raise GridcostError(f"no SPD view for {name!r}")
    e, a, u, fov = VIEWS[kind]
    return np.array(e, float), np.array(a, float), np.array(u, float), float(fov)


def pinhole_rays(eye, at, up, fov: float, width: int, height: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole rays through pixel centres (row-major) from ``eye`` toward ``at`` with ``up`` and a
    vertical field of view ``fov`` (degrees), as float32 (m, 3) origins and unit directions."""
    height = height or width
    eye, at = np.asarray(eye, float), np.asarray(at, float)
    fwd = (at - eye) / np.linalg.norm(at - eye)
    right = np.cross(fwd, np.asarray(up, float))
    right /= np.linalg.norm(right)
    upv = np.cross(right, fwd)
    tanh = np.tan(np.radians(fov) / 2)
    jy, jx = np.mgrid[0:height, 0:width].astype(np.float64)
    sx = (2 * (jx + 0.5) / width - 1) * tanh * width / height
    sy = (1 - 2 * (jy + 0.5) / height) * tanh
    d = (fwd + sx[..., None] * right + sy[..., None] * upv).reshape(-1, 3)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(eye, d.shape)
    return np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32)


def spd_camera_rays(name: str, width: int, height: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole primary rays through pixel centres from the SPD viewpoint (row-major), as float32
    (m, 3) origins and unit directions."""
    eye, at, up, fov = spd_view(name)
    return pinhole_rays(eye, at, up, fov, width, height)

"""Procedural scenes built in code (deterministic): the papers' synthetic test cases.

==========================  ================================================================
``cylinder-N``              open cylinder of N long skinny triangles, one ring of quads
``capped-cylinder-N``       Ize 2007's cylinder (Table 3, Fig 5, Fig 6): N/4 segments, each a side
                            quad spanning the whole height (2 triangles) and one triangle in each
                            end cap's fan, all long and skinny (N = 196, 3996, 19996)
``particles-N``             N small triangles scattered uniformly in a unit cube ("exploding
                            particles", Ize 2007 Sec 4.3: scattered data)
``teapot-in-stadium``       the teapot mesh inside a box 200x its size (the classic grid failure);
                            its ``view`` is a close-up of the teapot, so cameras (camera and path
                            rays) stand in the stadium looking at the teapot, which fills the
                            frame, while random rays (whole bounding sphere) mostly see only the
                            stadium
``room``                    ~270K-triangle room of tables and chairs made of subdivided boxes on a
                            floor (no walls, so outside rays reach them), standing in for Ize's
                            conference room (282,664 triangles)
``sphere-N``                UV sphere of about N triangles
``knot-N``                  a (3, 2) torus-knot tube of about N triangles
``boxes-N``                 N random axis-aligned boxes (12 triangles each)
``surfpoints-N``            N tiny triangles scattered on a sphere: "points on a surface", the
                            manifold-like data of Ize Sec 4 with rays that (almost) never hit
==========================  ================================================================

The generators import only the scene type (:mod:`tracer.scenes.scenetype`): ``teapot-in-stadium`` gets its
teapot from the caller (:func:`make`'s ``mesh``; :func:`tracer.scenes.scene.load_scene` passes its loader
of named meshes), so this module never imports the scene registry back.
"""
from __future__ import annotations

import re
from typing import Callable

import numpy as np

from tracer.errors import GridcostError
from tracer.scenes.scenetype import Scene

#: the named mesh teapot-in-stadium is built around (from :func:`make`'s ``mesh`` loader)
TEAPOT = "teapot"

PATTERNS = {
    "cylinder": re.compile(r"^cylinder-(\d+)$"),
    "capped_cylinder": re.compile(r"^capped-cylinder-(\d+)$"),
    "particles": re.compile(r"^particles-(\d+)(k?)$"),
    "sphere": re.compile(r"^sphere-(\d+)(k?)$"),
    "knot": re.compile(r"^knot-(\d+)(k?)$"),
    "boxes": re.compile(r"^boxes-(\d+)$"),
    "surfpoints": re.compile(r"^surfpoints-(\d+)(k?)$"),
}
FIXED = ("teapot-in-stadium", "room", "conference-room")
EXAMPLES = ["cylinder-196", "cylinder-3996", "cylinder-19996", "capped-cylinder-3996", "particles-100k", "teapot-in-stadium",
            "room", "conference-room", "sphere-20k", "knot-50k", "boxes-2000"]


def names() -> list[str]:
    return list(EXAMPLES)


def matches(spec: str) -> bool:
    return spec in FIXED or any(p.match(spec) for p in PATTERNS.values())


def _count(m) -> int:
    n = int(m.group(1)) * (1000 if (m.lastindex or 0) >= 2 and m.group(2) else 1)
    if n < 1:
        raise GridcostError(f"procedural scene size must be >= 1, got {n}")
    return n


def make(spec: str, mesh: Callable[[str], Scene | None] | None = None) -> Scene:
    """The procedural scene ``spec``. ``teapot-in-stadium`` needs ``mesh``: ``mesh(name)`` returns a
    named mesh's :class:`Scene`, or None when the name is unknown (then a sphere stands in for the
    teapot); :func:`tracer.scenes.scene.load_scene` passes its own."""
    if spec == "teapot-in-stadium":
        if mesh is None:
            raise GridcostError("teapot-in-stadium needs a loader of named meshes (tracer.scenes.scene.load_scene passes one)")
        tris, n_pot, view = _teapot_in_stadium(mesh)
        return Scene(tris, spec, "procedural", report={"teapot_triangles": n_pot}, view=view)
    if spec == "room":
        return Scene(room(), spec, "procedural")
    if spec == "conference-room":
        tris, view = conference_room()
        return Scene(tris, spec, "procedural", view=view)
    for kind, pat in PATTERNS.items():
        m = pat.match(spec)
        if m:
            n = _count(m)
            return Scene(globals()[kind](n), spec, "procedural")
    raise GridcostError(f"unknown procedural scene {spec!r}")


def _grid_mesh(P: np.ndarray) -> np.ndarray:
    """Triangles of a (u, v, 3) point grid: two per quad."""
    a, b, c, d = P[:-1, :-1], P[1:, :-1], P[1:, 1:], P[:-1, 1:]
    t1 = np.stack([a, b, c], axis=-2).reshape(-1, 3, 3)
    t2 = np.stack([a, c, d], axis=-2).reshape(-1, 3, 3)
    return np.concatenate([t1, t2]).astype(np.float32)


def surfpoints(n: int, seed: int = 3) -> np.ndarray:
    """n tiny triangles (edge 1e-3 of the mean spacing) at uniform points of the unit sphere."""
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 1, 3))
    v /= np.linalg.norm(v, axis=2, keepdims=True)
    size = 1e-3 * np.sqrt(4 * np.pi / n)
    return (v + size * (rng.random((n, 3, 3)) - 0.5)).astype(np.float32)


def cylinder(n: int) -> np.ndarray:
    """Open cylinder (radius 1, height 2) of exactly n (rounded to even) long skinny triangles."""
    k = max(2, n // 2)
    ang = np.linspace(0, 2 * np.pi, k + 1)
    ang[-1] = 0.0  # close the seam exactly
    ring = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    P = np.stack([np.concatenate([ring, np.full((k + 1, 1), z)], axis=1) for z in (-1.0, 1.0)], axis=1)
    return _grid_mesh(P)


def capped_cylinder(n: int) -> np.ndarray:
    """Closed cylinder (radius 1, height 2) as Ize 2007 built it: k = N // 4 segments, each a side
    quad spanning the whole height (2 triangles) and a fan triangle (centre, rim, rim) in each cap,
    so N = 4k triangles (196 = 4 x 49)."""
    k = max(3, n // 4)
    side = cylinder(2 * k)
    ang = np.linspace(0, 2 * np.pi, k + 1)
    ang[-1] = 0.0
    ring = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    caps = []
    for z in (-1.0, 1.0):
        rim = np.concatenate([ring, np.full((k + 1, 1), z)], axis=1)
        centre = np.broadcast_to([0.0, 0.0, z], (k, 3))
        caps.append(np.stack([centre, rim[:-1], rim[1:]], axis=1))
    return np.concatenate([side, *caps]).astype(np.float32)


def particles(n: int, seed: int = 1) -> np.ndarray:
    """n small random triangles (edge ~ 0.5 n^(-1/3)) with centres uniform in the unit cube."""
    rng = np.random.default_rng(seed)
    centres = rng.random((n, 1, 3))
    size = 0.5 * n ** (-1.0 / 3.0)
    return (centres + size * (rng.random((n, 3, 3)) - 0.5)).astype(np.float32)


def sphere(n: int, center=(0.0, 0.0, 0.0), radius: float = 1.0) -> np.ndarray:
    """UV sphere of about n triangles."""
    k = max(3, int(round(np.sqrt(n / 4))))
    th = np.linspace(0, np.pi, k + 1)
    ph = np.linspace(0, 2 * np.pi, 2 * k + 1)
    ph[-1] = 0.0
    T, F = np.meshgrid(th, ph, indexing="ij")
    P = np.stack([np.sin(T) * np.cos(F), np.sin(T) * np.sin(F), np.cos(T)], axis=-1)
    tris = _grid_mesh(P * radius + np.asarray(center))
    t = tris.astype(np.float64)
    keep = np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1) > 0
    return tris[keep]


def knot(n: int, p: int = 3, q: int = 2) -> np.ndarray:
    """Tube of radius 0.25 around a (p, q) torus knot, about n triangles."""
    around = max(6, int(round(np.sqrt(n / 16))))
    along = max(12, n // (2 * around))
    s = np.linspace(0, 2 * np.pi, along + 1)
    r = np.cos(q * s) + 2
    C = np.stack([r * np.cos(p * s), r * np.sin(p * s), -np.sin(q * s)], axis=1)
    Tn = np.gradient(C, axis=0)
    Tn /= np.linalg.norm(Tn, axis=1, keepdims=True)
    N1 = np.cross(Tn, [0.0, 0.0, 1.0])
    N1 /= np.linalg.norm(N1, axis=1, keepdims=True)
    N2 = np.cross(Tn, N1)
    a = np.linspace(0, 2 * np.pi, around + 1)
    P = C[:, None] + 0.25 * (np.cos(a)[None, :, None] * N1[:, None] + np.sin(a)[None, :, None] * N2[:, None])
    P[-1] = P[0]
    P[:, -1] = P[:, 0]
    return _grid_mesh(P)


def box(lo, hi, sub: int = 1) -> np.ndarray:
    """An axis-aligned box, each face split into sub x sub quads (12 sub^2 triangles)."""
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    u = np.linspace(0, 1, sub + 1)
    U, V = np.meshgrid(u, u, indexing="ij")
    faces = []
    for axis in range(3):
        a1, a2 = (axis + 1) % 3, (axis + 2) % 3
        for side in (0, 1):
            P = np.empty(U.shape + (3,))
            P[..., axis] = hi[axis] if side else lo[axis]
            P[..., a1] = lo[a1] + U * (hi[a1] - lo[a1])
            P[..., a2] = lo[a2] + V * (hi[a2] - lo[a2])
            faces.append(_grid_mesh(P))
    return np.concatenate(faces)


def boxes(n: int, seed: int = 2) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lo = rng.random((n, 3)) * 10
    size = 0.05 + rng.random((n, 3)) * 0.5
    return np.concatenate([box(a, a + s) for a, s in zip(lo, size)])


def teapot_in_stadium(mesh: Callable[[str], Scene | None]) -> np.ndarray:
    """The teapot model (``mesh("teapot")``; a sphere if that is None) inside a stadium: a
    subdivided box 200x the teapot's size (floor, walls, roof). The teapot's triangles come first."""
    return _teapot_in_stadium(mesh)[0]


def _teapot_in_stadium(mesh):
    """(triangles, number of teapot triangles (the first ones), view): :func:`in_stadium` around
    ``mesh("teapot")``, or around a sphere when that is None."""
    pot = mesh(TEAPOT)
    return in_stadium(pot.tris if pot is not None else sphere(6000))


def in_stadium(pot: np.ndarray) -> tuple[np.ndarray, int, tuple]:
    """(triangles, number of object triangles (the first ones), view ``(centre, radius)``) of the
    object ``pot`` (m, 3, 3) inside a stadium: a subdivided box 200x the object's size.

    The view is a close-up of the object: centred on its box, radius half the box's smallest extent
    (the pot's height), so the pot fills the camera's frame (spout and handle may be cut off). Its
    full bounding sphere (half the box diagonal) would leave the pot about 15 % of the pixels from the
    default camera direction, the rest of the image being stadium floor and walls; this view gives
    about 85 % (a sphere stand-in: pi / 4)."""
    lo = pot.reshape(-1, 3).min(0)
    hi = pot.reshape(-1, 3).max(0)
    size = float((hi - lo).max())
    c = (lo + hi) / 2
    stadium = box(c - 100 * size, c + 100 * size, sub=4)
    lo64, hi64 = lo.astype(np.float64), hi.astype(np.float64)
    view = ((lo64 + hi64) / 2, float((hi64 - lo64).min() / 2))
    return np.concatenate([pot, stadium]).astype(np.float32), len(pot), view


#: the conference room's hall (m): width, depth, height; and the view its cameras frame from inside
ROOM_W, ROOM_D, ROOM_H = 30.0, 20.0, 3.0


def _furniture():
    """Boxes (lo, hi) of 6 x 8 tables with four chairs each (legs, seats, backs)."""
    parts = []
    for i in range(6):
        for j in range(8):
            x0, y0 = 2.0 + i * 4.5, 1.5 + j * 2.3
            parts.append(((x0, y0, 0.75), (x0 + 3.0, y0 + 1.2, 0.8)))  # table top
            for lx in (x0 + 0.1, x0 + 2.8):
                for ly in (y0 + 0.1, y0 + 1.0):
                    parts.append(((lx, ly, 0.0), (lx + 0.1, ly + 0.1, 0.75)))  # table legs
            for cx in (x0 + 0.4, x0 + 1.9):
                for side in (-1, 1):
                    cy = y0 - 0.6 if side < 0 else y0 + 1.35
                    parts.append(((cx, cy, 0.45), (cx + 0.5, cy + 0.45, 0.5)))  # seat
                    by = cy if side < 0 else cy + 0.4
                    parts.append(((cx, by, 0.5), (cx + 0.5, by + 0.05, 1.0)))  # back
                    for lx in (cx, cx + 0.45):
                        for ly in (cy, cy + 0.4):
                            parts.append(((lx, ly, 0.0), (lx + 0.05, ly + 0.05, 0.45)))  # chair legs
    return parts


def conference_room(target: int = 280_000):
    """(triangles, view): the conference room's character for Ize Tables 2/4 and Wald Tables 1/3/4 —
    a closed hall (floor, ceiling and four walls, thin boxes) with the tables and chairs of
    :func:`room` inside, about ``target`` triangles, small detail in a large box. The ``view``
    (centre, radius) puts the camera inside the hall under the ceiling, looking down across the
    tables (:func:`tracer.scenes.rays.camera_frame`: eye = centre + 2.6 radius along the view
    direction, here about 2.9 m above the floor)."""
    W, D, H, t = ROOM_W, ROOM_D, ROOM_H, 0.1
    parts = _furniture()
    sub = max(1, int(round(np.sqrt(target / (12.0 * (len(parts) + 6 * 16))))))
    shell = [((0, 0, -t), (W, D, 0)), ((0, 0, H), (W, D, H + t)),                # floor, ceiling
             ((-t, 0, 0), (0, D, H)), ((W, 0, 0), (W + t, D, H)),                # walls x
             ((0, -t, 0), (W, 0, H)), ((0, D, 0), (W, D + t, H))]                # walls y
    tris = [box(lo, hi, sub=4 * sub) for lo, hi in shell] + [box(lo, hi, sub=sub) for lo, hi in parts]
    view = (np.array([W / 2, D / 2, 1.0]), 1.0)
    return np.concatenate(tris).astype(np.float32), view


def room(target: int = 280_000) -> np.ndarray:
    """Tables and chairs on a floor slab, no walls or ceiling, about ``target`` triangles: what
    stood in for the conference room before :func:`conference_room` (viewed from outside, it has
    none of the room's character: no large box around small detail)."""
    parts = _furniture()
    W, D = ROOM_W, ROOM_D
    sub = max(1, int(round(np.sqrt(target / (12.0 * (len(parts) + 1))))))
    # a floor slab but no walls or ceiling: rays from outside (random rays) must reach the furniture
    tris = [box((0, 0, -0.1), (W, D, 0.0), sub=4 * sub)]
    tris += [box(lo, hi, sub=sub) for lo, hi in parts]
    return np.concatenate(tris).astype(np.float32)

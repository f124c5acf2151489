"""Scenes and rays of ``fournier-table1`` that are not SPD scenes: the stand-ins for the paper's
Newell teapot (Table 1's last row) and for its *Around Again* scene (Sec. "Results", Fig. 11), and
the secondary rays (shadow and mirror reflection) traced from primary hits.

* ``teapot`` (Table 1): Newell's teapot is 28 bicubic patches; with a floor polygon that is the
  paper's 29 objects (and its minimum of 1.00: every eye ray hits something). Our teapot mesh
  (``load_scene("teapot")``, 6,320 triangles) is the 32-patch Utah teapot tessellated 10 x 10 per
  patch, its triangles stored patch by patch (:data:`TEAPOT_PATCH_TRIS`); we keep the 28 patches of
  Newell's set (dropping Blinn's 4 bottom patches, which no eye ray above the floor can see), turn
  it z-up, and add a floor square (2 triangles) large enough that every eye ray hits: 29 objects,
  5,562 triangles; ``object_of[t]`` names each triangle's patch (0..27) or the floor (28).
* ``around-again``: 28 drink cans (cylinders of 48 x 10 side quads and 48-triangle caps: large
  meshes of small polygons), some stacked, some lying, beside long polygons (the ground and three
  walls of a room, 2 triangles each): 29,576 triangles (the paper's scene: 25,426 triangles,
  4,610 quadrilaterals and 636 larger polygons); the eye stands in the room.
"""
from __future__ import annotations

import numpy as np

from tracer.scenes.scenetype import Scene
from tracer.scenes.spd import pinhole_rays as spd_pinhole_rays

#: triangles per patch of the Utah teapot mesh, in its stored order: rim 4, body 8, handle 4,
#: spout 4, lid 8 (the 4 knob patches lose their 10 degenerate pole triangles), bottom 4 (likewise)
TEAPOT_PATCH_TRIS = (200,) * 20 + (190,) * 4 + (200,) * 4 + (190,) * 4
NEWELL_PATCHES = 28
#: eye, look-at, vertical field of view (deg) of the teapot view (z up)
TEAPOT_VIEW = ((3.6, -4.7, 5.6), (0.2, 0.0, 1.2), 45.0)
#: Around Again stand-in: room half-size, wall height, eye, look-at, fov, point light
ROOM = {"half": 8.0, "height": 5.0, "eye": (4.0, 3.0, 2.8), "at": (-2.2, -2.6, 0.7), "fov": 50.0,
        "light": (3.0, 2.0, 4.6)}
CAN = {"radius": 0.33, "height": 1.22, "sides": 48, "rings": 10}


def pinhole_rays(eye, at, fov, width, height=None, up=(0.0, 0.0, 1.0)):
    """Row-major pinhole rays through pixel centres (float32 origins, unit directions), z up."""
    return spd_pinhole_rays(eye, at, up, fov, width, height)


def _quad(p0, p1, p2, p3) -> np.ndarray:
    return np.array([[p0, p1, p2], [p0, p2, p3]], np.float64)


# ---------------------------------------------------------------- Newell's teapot
def teapot_patches():
    """(triangles of Newell's 28 patches, z up, (n, 3, 3) float64; patch id per triangle)."""
    from tracer.scenes.scene import load_scene
    pot = load_scene("teapot").tris.astype(np.float64)
    assert len(pot) == sum(TEAPOT_PATCH_TRIS), "the teapot mesh is not the 32-patch tessellation"
    ids = np.repeat(np.arange(len(TEAPOT_PATCH_TRIS)), TEAPOT_PATCH_TRIS)
    keep = ids < NEWELL_PATCHES
    pot, ids = pot[keep], ids[keep]
    pot = pot[..., [0, 2, 1]] * np.array([1.0, -1.0, 1.0])  # y up -> z up (x, y, z) -> (x, -z, y)
    pot[..., 2] -= pot[..., 2].min()  # standing on z = 0
    return pot, ids


def teapot_scene(res_for_floor: int = 64):
    """(Scene ``teapot``: Newell's 28 patches on a floor square, object id per triangle, 29).
    The floor is the smallest square about the teapot that every eye ray of :data:`TEAPOT_VIEW`
    hits (its size does not depend on the image size)."""
    pot, ids = teapot_patches()
    o, d = pinhole_rays(*TEAPOT_VIEW, res_for_floor)
    t = -o[:, 2].astype(np.float64) / d[:, 2]
    hit = o + t[:, None] * d
    half = float(np.ceil(1.05 * np.abs(hit[:, :2]).max()))
    floor = _quad((half, half, 0), (-half, half, 0), (-half, -half, 0), (half, -half, 0))
    tris = np.concatenate([pot, floor])
    obj = np.concatenate([ids, np.full(2, NEWELL_PATCHES)])
    return Scene(tris, "teapot-newell", "fournier stand-in"), obj, NEWELL_PATCHES + 1


def teapot_rays(width: int):
    return pinhole_rays(*TEAPOT_VIEW, width)


# ---------------------------------------------------------------- Around Again stand-in
def can(center, axis="z", radius=CAN["radius"], height=CAN["height"], sides=CAN["sides"], rings=CAN["rings"]):
    """A closed cylinder (side quads split in two, caps as fans) standing on ``center`` (bottom
    centre) along ``axis`` ("z" upright, "x"/"y" lying)."""
    a = np.linspace(0, 2 * np.pi, sides + 1)
    ca, sa = np.cos(a) * radius, np.sin(a) * radius
    z = np.linspace(0, height, rings + 1)
    tris = []
    for r in range(rings):
        for s in range(sides):
            p = [(ca[s], sa[s], z[r]), (ca[s + 1], sa[s + 1], z[r]), (ca[s + 1], sa[s + 1], z[r + 1]), (ca[s], sa[s], z[r + 1])]
            tris.append(_quad(*p))
    side = np.concatenate(tris)
    caps = []
    for zc, flip in ((0.0, True), (height, False)):
        for s in range(sides):
            t = [(0, 0, zc), (ca[s], sa[s], zc), (ca[s + 1], sa[s + 1], zc)]
            caps.append([t[0], t[2], t[1]] if flip else t)
    v = np.concatenate([side, np.asarray(caps, float)])
    if axis == "x":
        v = v[..., [2, 0, 1]] + np.array([0, 0, radius])
    elif axis == "y":
        v = v[..., [0, 2, 1]] + np.array([0, 0, radius])
    return v + np.asarray(center, float)


def around_again_scene():
    """(Scene ``around-again``, object kind per triangle: 0 can, 1 long polygon)."""
    h, H = ROOM["half"], ROOM["height"]
    r, ch = CAN["radius"], CAN["height"]
    cans = []
    # a pyramid of 14 cans in the corner: 3 x 3, 2 x 2, 1 stacked
    for lvl, k in enumerate((3, 2, 1)):
        for i in range(k):
            for j in range(k):
                off = (3 - k) * r
                cans.append(can((-5.0 + off + 2 * r * i, -5.0 + off + 2 * r * j, lvl * ch)))
    # 10 cans standing about the floor, 4 lying on it
    rng = np.random.default_rng(1993)
    spots = [(-2.0, -4.5), (-1.2, -3.1), (0.4, -4.0), (1.5, -2.2), (-3.9, -1.5), (-2.7, 0.3), (-0.6, -0.9),
             (1.0, 0.5), (2.6, -3.6), (-4.6, 1.4)]
    for x, y in spots:
        cans.append(can((x + rng.uniform(-0.1, 0.1), y + rng.uniform(-0.1, 0.1), 0.0)))
    for (x, y), ax in zip([(-1.5, 1.8), (0.8, -5.8), (2.8, -0.8), (-6.0, 2.8)], "xyxy"):
        cans.append(can((x, y, 0.0), axis=ax))
    walls = np.concatenate([
        _quad((h, h, 0), (-h, h, 0), (-h, -h, 0), (h, -h, 0)),                    # ground
        _quad((-h, -h, 0), (-h, h, 0), (-h, h, H), (-h, -h, H)),                   # wall x = -h
        _quad((-h, -h, 0), (-h, -h, H), (h, -h, H), (h, -h, 0)),                   # wall y = -h
        _quad((h, -h, 0), (h, -h, H), (h, h, H), (h, h, 0)),                       # wall x = +h (behind the eye)
    ])
    tris = np.concatenate(cans + [walls])
    kind = np.concatenate([np.zeros(sum(len(c) for c in cans), np.int8), np.ones(len(walls), np.int8)])
    return Scene(tris, "around-again", "fournier stand-in"), kind


def around_again_primary(width: int):
    return pinhole_rays(ROOM["eye"], ROOM["at"], ROOM["fov"], width)


def normals(tris, ids) -> np.ndarray:
    t = tris[ids].astype(np.float64)
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(ln > 0, ln, 1)


def secondary_rays(scene, o, d, t, tri_id, light=ROOM["light"]):
    """From the primary hits (t, tri_id of rays o, d): shadow rays toward the point light ``light``
    (any hit before it occludes; returned with their tmax) and mirror reflection rays. Origins are
    offset along the normal, toward the side the ray came from, by 1e-4 of the scene's size.
    Returns {"shadow": (o, d, tmax), "reflection": (o, d, None)} (float32)."""
    h = tri_id >= 0
    lo, hi = scene.bounds.astype(np.float64)
    eps = 1e-4 * float(np.linalg.norm(hi - lo))
    dd = d[h].astype(np.float64)
    p = o[h].astype(np.float64) + t[h, None].astype(np.float64) * dd
    n = normals(scene.tris, tri_id[h])
    n *= np.where((n * dd).sum(1) > 0, -1.0, 1.0)[:, None]  # face the incoming ray
    p = p + eps * n
    to_l = np.asarray(light, float) - p
    dist = np.linalg.norm(to_l, axis=1)
    refl = dd - 2 * (dd * n).sum(1)[:, None] * n
    refl /= np.linalg.norm(refl, axis=1, keepdims=True)
    f32 = lambda a: np.ascontiguousarray(a, np.float32)  # noqa: E731
    return {"shadow": (f32(p), f32(to_l / dist[:, None]), f32(dist * (1 - 1e-6))),
            "reflection": (f32(p), f32(refl), None)}

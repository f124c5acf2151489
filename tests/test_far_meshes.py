"""Every structure against the float64 oracle on meshes far from the origin or far from unit size.

A unit mesh 1e5 from the origin has float32 coordinates 1/128 apart, so float32 rays (adversarial
ones above all) often lie exactly in the planes of vertices, kd-tree splits, box faces and cells:
the kd-tree once lost nearer hits there (a ray in a split plane pushed the far child beneath
entries that start later, and the traversal stopped at the first entry beyond the closest hit).
Meshes scaled by 1e-4 and 1e4 catch absolute epsilons; 1e-3 at 1e3 is both small and far.

Every structure here calls :func:`tracer.accel.geometry.ray_triangle` exactly as the oracle does, so a
hit on the oracle's triangle has a bit-identical t (:func:`conftest.assert_agrees_exactly`).
"""
from __future__ import annotations

import numpy as np
import pytest

from tracer.accel import STRUCTURES, build
from tracer.accel.geometry import PARALLEL_COS
from tracer.accel.oracle import oracle_intersect
from tracer.scenes.rays import make_rays
from tracer.scenes.scene import Scene

#: name -> (scale, shift) applied to the mesh normalised to unit size
PLACEMENTS = {"far-1e5": (1.0, 1e5), "tiny-1e-4": (1e-4, 0.0), "huge-1e4": (1e4, 0.0),
              "small-far-1e-3-at-1e3": (1e-3, 1e3)}
MESHES = ("bunny-948", "dragon-11k")
KINDS = ("random", "adversarial")
NRAYS = 3000


_CACHE: dict = {}


def _rays_and_oracle(scene, kind):
    key = ("rays", scene.name, kind)
    if key not in _CACHE:
        r = make_rays(scene, kind, NRAYS, seed=5)
        _CACHE[key] = r, oracle_intersect(scene, r.origins, r.directions)
    return _CACHE[key]


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("placement", list(PLACEMENTS))
@pytest.mark.parametrize("mesh", MESHES)
@pytest.mark.parametrize("structure", list(STRUCTURES))
def test_far_and_scaled_meshes_match_oracle_exactly(structure, mesh, placement, kind, far_scene, agrees_exactly):
    scene = far_scene(mesh, *PLACEMENTS[placement])
    rays, (ref, ties) = _rays_and_oracle(scene, kind)
    hits, _ = build(scene, structure).intersect(rays.origins, rays.directions, counters=False)
    res = agrees_exactly(hits, ref, ties, (structure, scene.name, kind))
    assert res["hits"] > NRAYS // 10  # the rays really meet the mesh


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("placement", list(PLACEMENTS))
def test_far_and_scaled_meshes_quantised_wide_bvh(placement, kind, far_scene, agrees_exactly):
    """The wide BVH's byte-quantised boxes (node origin and step per axis) at every placement: far
    from the origin a step is below float32's spacing, and the outward rounding must still hold."""
    scene = far_scene("bunny-948", *PLACEMENTS[placement])
    rays, (ref, ties) = _rays_and_oracle(scene, kind)
    hits, _ = build(scene, "wbvh", boxes="quant").intersect(rays.origins, rays.directions, counters=False)
    res = agrees_exactly(hits, ref, ties, ("wbvh-quant", scene.name, kind))
    assert res["hits"] > NRAYS // 10


@pytest.mark.parametrize("placement", ["far-1e5", "small-far-1e-3-at-1e3"])
def test_far_mesh_rays_lie_in_vertex_planes(placement, far_scene):
    """The premise of the far-mesh cases: many adversarial rays lie exactly in a coordinate plane
    of some vertex (a zero direction component, the origin's coordinate a vertex's)."""
    scene = far_scene("bunny-948", *PLACEMENTS[placement])
    rays, _ = _rays_and_oracle(scene, "adversarial")
    v = scene.tris.reshape(-1, 3)
    in_plane = np.zeros(rays.n, bool)
    for k in range(3):
        in_plane |= (rays.directions[:, k] == 0) & np.isin(rays.origins[:, k], v[:, k])
    assert in_plane.sum() > rays.n // 20, in_plane.sum()


def _grazing_rays(n=4000, seed=0):
    """Rays from just above the plane z = 0 that descend at about PARALLEL_COS to it: the grazing
    test ``det^2 <= PARALLEL_COS^2 |n|^2 |d|^2`` decides them, a few ulps either side. Returns
    (origins, directions, flips): flips marks the rays it decides the other way when |d|^2 is
    summed in float32 (as a kernel passing the ray to ray_triangle as float32 would)."""
    rng = np.random.default_rng(seed)
    dx = rng.uniform(0.5, 1.0, n).astype(np.float32)
    dy = rng.uniform(-0.5, 0.5, n).astype(np.float32)
    p2 = PARALLEL_COS ** 2
    dz = -np.sqrt(p2 * (dx.astype(np.float64) ** 2 + dy.astype(np.float64) ** 2) / (1 - p2))
    dz = dz.astype(np.float32)
    for _ in range(3):  # spread a few ulps either side of the threshold
        step = rng.integers(-1, 2, n).astype(np.float32)
        dz = np.nextafter(dz, dz + step * np.abs(dz)).astype(np.float32)
    d = np.stack([dx, dy, dz], axis=1)
    o = np.tile(np.array([0.0, 0.0, 1e-7], np.float32), (n, 1))  # the plane is met near t = 1
    nn = 144.0 ** 2  # |n|^2 of the triangle below (n = (0, 0, 144))
    det = d[:, 2].astype(np.float64) * 144.0
    d64 = d.astype(np.float64)
    dd64 = d64[:, 0] * d64[:, 0] + d64[:, 1] * d64[:, 1] + d64[:, 2] * d64[:, 2]
    dd32 = (d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]).astype(np.float64)
    flips = (det * det <= p2 * nn * dd64) != (det * det <= p2 * nn * dd32)
    return o, d, flips


@pytest.mark.parametrize("structure", list(STRUCTURES))
def test_grazing_rays_decided_as_the_oracle_decides(structure, agrees_exactly):
    """Every structure passes the ray to ray_triangle widened to float64, as the oracle does, so the
    grazing test sums |d|^2 in float64 everywhere: a kernel passing float32 components (Numba's
    ``float()`` keeps a float32 a float32) sums it in float32 and decides some rays differently."""
    tri = np.array([[[-4.0, -4.0, 0.0], [8.0, -4.0, 0.0], [-4.0, 8.0, 0.0]]], np.float32)
    scene = Scene(tri, "grazing")
    o, d, flips = _grazing_rays()
    ref, ties = oracle_intersect(scene, o, d)
    hit = ref.tri_id >= 0
    assert flips.sum() >= 20 and (flips & hit).sum() >= 10 and (flips & ~hit).sum() >= 10, \
        (flips.sum(), (flips & hit).sum())
    hits, _ = build(scene, structure).intersect(o, d, counters=False)
    agrees_exactly(hits, ref, ties, structure)

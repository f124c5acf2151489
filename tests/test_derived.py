"""Scenes derived by name (tracer.scenes.derived): subdivided, in a stadium, arrays of copies."""
from __future__ import annotations

import numpy as np
import pytest

from tracer.scenes import derived
from tracer.errors import GridcostError
from tracer.scenes.scene import load_scene


def _area(t):
    t = np.asarray(t, np.float64)
    return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum()


def test_subdivide_keeps_the_surface(load):
    base = load("suzanne").tris
    fine = derived.subdivide(base, 2)
    assert fine.shape == (16 * len(base), 3, 3) and fine.dtype == np.float32
    assert np.isclose(_area(fine), _area(base), rtol=1e-5)
    np.testing.assert_allclose(fine.reshape(-1, 3).min(0), base.reshape(-1, 3).min(0), atol=1e-6)


def test_named_derived_scenes(load):
    s = load_scene("suzanne-x4")
    assert s.n == 4 * load("suzanne").n and s.name == "suzanne-x4" and s.report["base"] == "suzanne"
    st = load_scene("teapot-x4-in-stadium")
    pot = load("teapot").n
    stadium = load("teapot-in-stadium").n - pot
    assert st.n == 4 * pot + stadium and stadium > 0 and st.view is not None
    assert load_scene("teapot-in-stadium").n == pot + stadium  # procedural's own, not derived
    assert not derived.matches("teapot-in-stadium") and derived.matches("cylinder-196-in-stadium")


def test_array_copies_are_rigid_and_apart(load):
    base = load("suzanne").tris
    k, gap = 10, 0.5
    a = derived.array(base, k, gap)
    assert a.shape == (k * len(base), 3, 3)
    assert np.isclose(_area(a), k * _area(base), rtol=1e-4)  # rotations keep every copy's area
    copies = a.reshape(k, len(base), 3, 3).astype(np.float64)
    centres = np.array([(c.reshape(-1, 3).min(0) + c.reshape(-1, 3).max(0)) / 2 for c in copies])
    radius = max(np.linalg.norm(c.reshape(-1, 3) - m, axis=1).max() for c, m in zip(copies, centres))
    d = np.linalg.norm(centres[:, None] - centres[None], axis=2) + np.eye(k) * 1e9
    assert d.min() > 2 * radius  # bounding spheres never overlap
    # a larger gap spreads the same copies further
    b = derived.array(base, k, 2.0)
    assert np.ptp(b.reshape(-1, 3), axis=0).max() > 1.5 * np.ptp(a.reshape(-1, 3), axis=0).max()
    np.testing.assert_array_equal(derived.array(base, k, gap), a)  # seeded: the same every time


def test_array_by_name_and_bad_names(load):
    s = load_scene("array-8-100-suzanne")
    assert s.n == 8 * load("suzanne").n and s.report == {"base": "suzanne", "copies": 8, "gap": 1.0}
    with pytest.raises(GridcostError, match="k >= 1"):
        load_scene("array-0-100-suzanne")
    with pytest.raises(GridcostError, match="unknown scene"):
        load_scene("array-4-10-no-such-mesh")


@pytest.mark.parametrize("name, lo, ext", [("suzanne-far1e5", 1e5, 1.0), ("suzanne-size1e-4", 0.0, 1e-4),
                                           ("suzanne-size25e3", 0.0, 2.5e4)])
def test_placed_scenes_far_and_at_extreme_scales(load, name, lo, ext):
    s = load_scene(name)
    base = load("suzanne")
    v = s.tris.reshape(-1, 3).astype(np.float64)
    assert s.n == base.n and s.name == name and s.report["base"] == "suzanne"
    np.testing.assert_allclose(v.min(0), lo, rtol=1e-6, atol=ext * 1e-6)
    assert np.isclose((v.max(0) - v.min(0)).max(), ext, rtol=1e-3)
    # the same shape: the base mesh normalised the same way, to float32 rounding at that place
    b = base.tris.reshape(-1, 3).astype(np.float64)
    unit = (b - b.min(0)) / (b.max(0) - b.min(0)).max()
    np.testing.assert_allclose((v - lo) / ext, unit, atol=1e-7 * max(1.0, lo / ext) * 4)


def test_placed_scenes_bad_names(load):
    with pytest.raises(GridcostError, match="positive"):
        load_scene("suzanne-size0")
    with pytest.raises(GridcostError, match="float32"):
        load_scene("suzanne-far1e39")
    with pytest.raises(GridcostError, match="unknown scene"):
        load_scene("no-such-mesh-far1e5")

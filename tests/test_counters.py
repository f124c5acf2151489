"""Typed counters: every structure declares the columns it fills, by name, and leaves the rest at 0;
no column holds another meaning (the grid's macrocell jumps are ``jumps``, not ``nodes``)."""
from __future__ import annotations

import numpy as np
import pytest

from tracer import build, load_scene, make_rays
from tracer.accel import COUNTER_NAMES, Counters
from tracer.accel.base import COUNTER_SCHEMA

CASES = [("grid", {"cells": 2000, "macro": 2}), ("grid", {"cells": 2000, "mailbox": True}),
         ("nested", {"levels": 2}), ("kdtree", {}), ("bvh", {}), ("bvh4", {}), ("wbvh", {"width": 8}), ("wbvh", {"width": 4}),
         ("cgt", {"packet": 4}),
         ("sortedlists", {})]


@pytest.fixture(scope="module")
def scene_rays():
    scene = load_scene("bunny-948")
    return scene, make_rays(scene, "random", 3000, seed=4), make_rays(scene, "camera", 4096, seed=4)


@pytest.mark.parametrize("name,params", CASES, ids=[f"{n}-{'-'.join(p)}" for n, p in CASES])
def test_structure_fills_only_its_declared_counters(scene_rays, name, params):
    scene, *raysets = scene_rays
    acc = build(scene, name, **params)
    assert acc.counter_fields and set(acc.counter_fields) <= set(COUNTER_SCHEMA)
    assert {"setups", "tests"} <= set(acc.counter_fields)
    filled = set()
    for rays in raysets:
        _, cnt = acc.intersect(rays.origins, rays.directions)
        assert cnt.fields == acc.counter_fields
        for col in COUNTER_NAMES:
            if col not in acc.counter_fields:
                assert not cnt[col].any(), (name, col)
            elif cnt[col].any():
                filled.add(col)
    assert {"setups", "tests"} <= filled


def test_grid_macrocell_jumps_are_their_own_column(scene_rays):
    scene, rays, _ = scene_rays
    _, plain = build(scene, "grid", cells=60_000).intersect(rays.origins, rays.directions)
    _, macro = build(scene, "grid", cells=60_000, macro=4).intersect(rays.origins, rays.directions)
    assert plain.total()["jumps"] == 0 and macro.total()["jumps"] > 0
    assert plain.total()["nodes"] == macro.total()["nodes"] == 0
    assert macro.total()["steps"] < plain.total()["steps"]  # and jumping saves steps


def test_counters_by_name():
    c = Counters(np.arange(2 * len(COUNTER_NAMES), dtype=np.int32).reshape(2, -1), {"tests": "t"})
    assert c["tests"].tolist() == [2, 2 + len(COUNTER_NAMES)]
    assert list(c.mean()) == list(COUNTER_NAMES) and c.fields == {"tests": "t"}
    with pytest.raises(KeyError, match="no counter 'cells'"):
        c["cells"]
    with pytest.raises(ValueError, match="counters must be"):
        Counters(np.zeros((2, 6), np.int32))

"""Traversal arrays (tracer.accel.pages): same values and layout as the array given, cache-line
aligned, huge-page aligned from one huge page up, writable (Numba types a read-only array apart)."""
from __future__ import annotations

import numpy as np
import pytest

from tracer import build, load_scene
from tracer.accel.pages import ALIGN, HUGE_PAGE, thp_mode, traversal_array, traversal_concat, traversal_rows


@pytest.mark.parametrize("shape,dtype", [((0, 9), np.float32), ((7,), np.uint8), ((1000, 9), np.float32),
                                         ((HUGE_PAGE // 4 + 3,), np.int32), ((70_000, 64), np.int32)])
def test_copy_keeps_values_layout_and_alignment(shape, dtype):
    rng = np.random.default_rng(5)
    a = (rng.random(shape) * 1e6).astype(dtype)
    b = traversal_array(a)
    assert b.shape == a.shape and b.dtype == a.dtype and np.array_equal(a, b)
    assert b.flags.c_contiguous and b.flags.writeable and not np.shares_memory(a, b)
    step = HUGE_PAGE if a.nbytes >= HUGE_PAGE and thp_mode() in ("always", "madvise") else ALIGN
    assert a.size == 0 or b.ctypes.data % step == 0  # (an empty slice keeps no offset)
    b[...] = 0  # a copy: the original is untouched
    assert a.size == 0 or a.any()


def test_non_contiguous_input_is_copied_in_order():
    a = np.arange(60, dtype=np.int32).reshape(6, 10)[:, ::2]
    assert np.array_equal(traversal_array(a), a)


def test_gathers_and_concatenations_equal_numpy_s():
    rng = np.random.default_rng(7)
    tv = rng.random((500, 9)).astype(np.float32)
    rows = rng.integers(0, 500, 1200)
    assert np.array_equal(traversal_rows(tv, rows), tv[rows])
    parts = [rng.integers(0, 1 << 30, (k, 2)) for k in (3, 0, 700_000)]
    out = traversal_concat(parts, np.int32)
    assert out.dtype == np.int32 and np.array_equal(out, np.concatenate(parts).astype(np.int32))
    assert out.ctypes.data % ALIGN == 0


def test_thp_mode_is_a_policy_word():
    assert thp_mode() in ("always", "madvise", "never", "unavailable")


#: each structure's arrays its kernel walks
TRAVERSED = {"grid": ("cell_start_", "tri_ids_", "occ_", "vertices"),
             "cgt": ("cell_start_", "tri_ids_", "tri_verts_", "occupied_"),
             "kdtree": ("nodes_", "tri_verts_", "blocks_", "block_ids_"), "bvh": ("nodes_", "tri_verts_"),
             "bvh4": ("nodes_",), "wbvh": ("nodes_", "tri4_", "ids4_"),
             "nested": ("grid_f_", "grid_i_", "cells_", "tri_ids_", "tri_verts_")}


def _root(a):
    while isinstance(a.base, np.ndarray):
        a = a.base
    return a


@pytest.mark.parametrize("name", sorted(TRAVERSED))
def test_structures_trace_from_traversal_arrays(name):
    acc = build(load_scene("bunny-948"), name)
    for attr in TRAVERSED[name]:
        if attr == "vertices":  # the grid's vertices: rows, or SoA blocks of four
            attr = "tri_blocks_" if acc.layout_ == "blocks" else "tri_verts_"
        v = getattr(acc, attr)
        assert _root(v) is not v and _root(v).dtype == np.uint8, f"{name}.{attr} is not a traversal array"
        assert v.ctypes.data % ALIGN == 0, f"{name}.{attr}"

"""Mesh files the loader once accepted or reported badly (tracer.scenes.meshfile.load_mesh): meshes that
the cast to float32 destroys (far from the origin for their size), vertices beyond float32 range (a
numpy warning before the error line), and truncated PLY / binary STL files (silently short, or
"empty"). Each is refused with a GridcostError naming the cause, which the CLI turns into one line.

No CLI runs here: ``experiments.run verify`` writes (and guards) the repository's results/, which a
long run may be using; the one-line contract for GridcostError is the CLI tests' business.
"""
from __future__ import annotations

import struct
import warnings

import numpy as np
import pytest
import trimesh

from tracer.errors import GridcostError
from tracer.scenes.meshfile import load_mesh


def _sphere(offset: float, subdivisions: int = 3) -> np.ndarray:
    """(1280, 3, 3) triangles of a unit icosphere translated by ``offset`` on every axis."""
    s = trimesh.creation.icosphere(subdivisions)
    return (s.vertices + offset)[s.faces]


def _tiny(offset: float, k: int) -> np.ndarray:
    """``k`` triangles 1e-4 across at ``offset``: nonzero area in float64, zero once cast to float32
    there (float32 steps by 1/128 at 1e5)."""
    base = np.array([[0, 0, 0], [1e-4, 0, 0], [0, 1e-4, 0]]) + offset
    return np.repeat(base[None], k, axis=0) + np.arange(k)[:, None, None] * 1e-3


def _load(path):
    """load_mesh with numpy warnings as errors: a RuntimeWarning would come before the error line."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return load_mesh(path, use_cache=False)


# ---------------------------------------------------------------- A: float32 collapse
def test_far_unit_sphere_destroyed_by_float32_is_refused(write_mesh):
    tris = _sphere(1e7)
    assert not (np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1) == 0).any()
    path = write_mesh("far.obj", tris)
    with pytest.raises(GridcostError) as exc:
        _load(path)
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(f"{path}: 1,232 of 1,280 triangles collapse to zero area in float32")
    assert "float32 precision: coordinates up to 1e+07 with a mesh extent of 2" in msg
    assert "re-centre the mesh near the origin" in msg


def test_unit_sphere_1e5_from_origin_loads_silently(write_mesh, capsys):
    scene = _load(write_mesh("near.obj", _sphere(1e5)))
    assert scene.n == 1280
    assert scene.report["degenerate"] == 0 and scene.report["collapsed_f32"] == 0
    assert capsys.readouterr().err == ""
    assert np.allclose(scene.tris, _sphere(1e5), atol=1e5 * 2.0 ** -23)


def test_one_percent_collapsed_loads_and_says_why(write_mesh, capsys):
    # 2 of 200 (1 %): kept and reported; the warning line names float32 as the cause
    scene = _load(write_mesh("two.obj", np.concatenate([_sphere(1e5, 2)[:198], _tiny(1e5, 2)])))
    assert scene.n == 200 and scene.report["degenerate"] == 2 and scene.report["collapsed_f32"] == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "2 of 200 triangles are degenerate" in err[0]
    assert "2 of them only in float32, the mesh is far from the origin for its size" in err[0]


def test_over_one_percent_collapsed_is_refused(write_mesh):
    path = write_mesh("three.obj", np.concatenate([_sphere(1e5, 2)[:197], _tiny(1e5, 3)]))
    with pytest.raises(GridcostError, match=r"3 of 200 triangles collapse to zero area in float32"):
        _load(path)


def test_degenerate_in_float64_keeps_old_behaviour(write_mesh, capsys):
    # 2 of 3 zero-area in the file itself: kept, counted, and not blamed on float32
    tris = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 0, 0], [1, 1, 1], [2, 2, 2]],
                     [[5, 5, 5], [5, 5, 5], [6, 6, 6]]], float)
    scene = _load(write_mesh("flat.obj", tris))
    assert scene.n == 3 and scene.report["degenerate"] == 2 and scene.report["collapsed_f32"] == 0
    err = capsys.readouterr().err
    assert "2 of 3 triangles are degenerate (zero area)" in err and "float32" not in err


# ---------------------------------------------------------------- F: beyond float32 range
def test_vertex_beyond_float32_range_is_one_error_no_numpy_warning(write_mesh):
    tris = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 0, 0], [1e39, 0, 0], [0, 1, 0]]], float)
    path = write_mesh("huge.obj", tris)
    with pytest.raises(GridcostError) as exc:  # a RuntimeWarning (as error) would fail this
        _load(path)
    assert str(exc.value) == f"{path}: 1 triangles have vertices beyond float32 range (first: triangle 1)"


# ---------------------------------------------------------------- G: truncated PLY / STL
_PLY_HEADER = ("ply\nformat {fmt} 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\nproperty float z\n"
               "element face {nf}\nproperty list uchar int vertex_indices\nend_header\n")
_VERTS = "0 0 0\n1 0 0\n0 1 0\n0 0 1\n"


def test_truncated_ascii_ply_faces_refused(write_mesh):
    path = write_mesh("short.ply", _PLY_HEADER.format(fmt="ascii", nv=4, nf=10) + _VERTS + "3 0 1 2\n3 0 1 3\n")
    with pytest.raises(GridcostError) as exc:
        _load(path)
    assert str(exc.value) == f"{path}: truncated PLY: header declares 10 faces, file holds 2"


def test_truncated_ascii_ply_vertices_refused(write_mesh):
    path = write_mesh("shortv.ply", _PLY_HEADER.format(fmt="ascii", nv=9, nf=0) + _VERTS)
    with pytest.raises(GridcostError, match=r"truncated PLY: header declares 9 vertices, file holds 4$"):
        _load(path)


def test_complete_ascii_ply_and_quads_still_load(write_mesh):
    whole = _PLY_HEADER.format(fmt="ascii", nv=4, nf=2) + _VERTS + "3 0 1 2\n4 0 1 3 2\n"  # a quad: 3 triangles
    scene = _load(write_mesh("whole.ply", whole))
    assert scene.n == 3 and scene.report["faces_loaded"] == 3


def test_truncated_binary_ply_refused(write_mesh):
    body = struct.pack("<12f", 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1) + struct.pack("<B3i", 3, 0, 1, 2)
    path = write_mesh("short_bin.ply", _PLY_HEADER.format(fmt="binary_little_endian", nv=4, nf=10).encode() + body)
    with pytest.raises(GridcostError, match=r"short_bin\.ply: "):
        _load(path)


def _binary_stl(declared: int, held: int) -> bytes:
    tri = struct.pack("<12fH", 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0)
    return b"binary stl".ljust(80, b" ") + struct.pack("<I", declared) + tri * held


def test_truncated_binary_stl_refused(write_mesh):
    path = write_mesh("short.stl", _binary_stl(1000, 10))
    with pytest.raises(GridcostError) as exc:
        _load(path)
    assert str(exc.value) == f"{path}: truncated STL: header declares 1,000 triangles, file holds 10"


def test_complete_binary_and_ascii_stl_still_load(write_mesh):
    assert _load(write_mesh("whole.stl", _binary_stl(10, 10))).n == 10
    ascii_stl = ("solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\n"
                 "endfacet\nendsolid t\n")
    assert _load(write_mesh("ascii.stl", ascii_stl)).n == 1

"""Shared fixtures: a per-session mesh cache, the small test scenes, mesh-file writers and a CLI runner.

The parsed-mesh cache ($GRIDCOST_CACHE) points at a session temporary directory, set before any
scene is loaded, so tests never read or write the user's meshes and points in ``~/.cache/gridcost``
and subprocesses (the CLI tests) inherit the same directory. Compiled kernels are the exception:
every test process, xdist worker and CLI subprocess shares the one Numba cache the tests' own
imports use ($GRIDCOST_NUMBA_CACHE, exported here; its folders are named by the tracer's source
digest, so a kernel is never reused across a source change). Without it each worker's subprocesses
followed $GRIDCOST_CACHE into their own folder and compiled every kernel again (CI: 216 s for
``all --quick``).
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

if not os.environ.get("GRIDCOST_NUMBA_CACHE"):
    from tracer.measure.provenance import numba_cache_dir
    os.environ["GRIDCOST_NUMBA_CACHE"] = str(numba_cache_dir().parent)

#: the small scenes the structure tests run on (each loads/builds in well under a second)
SMALL_SCENES = ("bunny-948", "cornell", "cylinder-196", "particles-2000")

#: small mesh files for the bad-input tests: name -> (content or None for a directory, words the
#: error message must contain one of, besides the path)
BAD_MESHES = {
    "missing": ("missing.obj", None, ("no such file",)),
    "unknown-format": ("points.xyz", "1 2 3\n4 5 6\n", ("unknown mesh format", ".xyz")),
    "directory": ("folder.obj", "<dir>", ("directory",)),
    "zero-bytes": ("zero.obj", "", ("empty", "0 triangles", "0 faces", "no triangle")),
    "no-faces": ("nofaces.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n",
                 ("empty", "0 triangles", "0 faces", "no triangle")),
    "nan-vertex": ("nan.obj", "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", ("NaN",)),
    "inf-vertex": ("inf.obj", "v 0 0 0\nv inf 0 0\nv 0 1 0\nf 1 2 3\n", ("inf",)),
    "zero-bytes-ply": ("zero.ply", "", ("cannot parse", "empty", "0 triangles")),
}


@pytest.fixture(scope="session", autouse=True)
def gridcost_cache(tmp_path_factory):
    """$GRIDCOST_CACHE -> a session temporary directory (restored afterwards)."""
    path = tmp_path_factory.mktemp("gridcost-cache")
    old = os.environ.get("GRIDCOST_CACHE")
    os.environ["GRIDCOST_CACHE"] = str(path)
    yield path
    if old is None:
        os.environ.pop("GRIDCOST_CACHE", None)
    else:
        os.environ["GRIDCOST_CACHE"] = old


@pytest.fixture
def one_numba_thread():
    """Run the test with one Numba thread, so timings use this thread's CPU time, which the other
    xdist worker's load does not inflate. With two threads and wall time a ~1 ms kernel beside a
    busy worker measured as slow as a 50x larger one (a one-cell grid read 0.2 % over an 8N grid)."""
    import numba

    from tracer.measure.timing import set_threads
    threads = numba.get_num_threads()
    set_threads(1)
    yield
    set_threads(threads)


_SCENES: dict = {}


@pytest.fixture(scope="session")
def load(gridcost_cache):
    """``load(name)``: a named scene, loaded once per session (after the cache is redirected)."""
    from tracer.scenes.scene import load_scene

    def _load(name: str):
        if name not in _SCENES:
            _SCENES[name] = load_scene(name)
        return _SCENES[name]

    return _load


@pytest.fixture(scope="session")
def bunny(load):
    return load("bunny-948")


@pytest.fixture(scope="session")
def cornell(load):
    return load("cornell")


@pytest.fixture(scope="session")
def cylinder(load):
    return load("cylinder-196")


@pytest.fixture(scope="session")
def particles(load):
    return load("particles-2000")


@pytest.fixture(scope="session", params=SMALL_SCENES)
def small_scene(request, load):
    """Each of the small scenes in turn."""
    return load(request.param)


def write_file(directory: Path, name: str, content) -> Path:
    """Write ``content`` (str, bytes, or ``"<dir>"`` for a directory, None for nothing) to directory/name."""
    path = Path(directory) / name
    if content is None:
        return path
    if content == "<dir>":
        path.mkdir(parents=True, exist_ok=True)
    elif isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    return path


def obj_text(tris) -> str:
    """An OBJ file holding the triangles ``tris`` (m, 3, 3), three fresh vertices per face."""
    lines = []
    for k, tri in enumerate(tris):
        lines += [f"v {x!r} {y!r} {z!r}" for x, y, z in (map(float, v) for v in tri)]
        lines.append(f"f {3 * k + 1} {3 * k + 2} {3 * k + 3}")
    return "\n".join(lines) + "\n"


@pytest.fixture
def write_mesh(tmp_path):
    """``write_mesh(name, content)`` -> Path of a small mesh file in this test's tmp dir; content may
    be text, bytes, ``"<dir>"`` or an (m, 3, 3) triangle array (written as OBJ)."""

    def _write(name: str, content) -> Path:
        if content is not None and not isinstance(content, (str, bytes)):
            content = obj_text(content)
        return write_file(tmp_path, name, content)

    return _write


@pytest.fixture(scope="session")
def bad_meshes(tmp_path_factory):
    """case -> (path, causes): the bad mesh files of :data:`BAD_MESHES`, written once per session."""
    d = tmp_path_factory.mktemp("bad-meshes")
    return {case: (write_file(d, fname, content), causes) for case, (fname, content, causes) in BAD_MESHES.items()}


@pytest.fixture(scope="session")
def run_cli(gridcost_cache):
    """``run_cli(*args, env=None, code=None)``: ``python -m experiments.run *args`` in the repository
    (or ``python -c code`` when ``code`` is given); returns the CompletedProcess."""

    def _run(*args, env=None, code=None, timeout=120):
        full_env = dict(os.environ)
        full_env.update(env or {})
        cmd = [sys.executable, "-c", code, *args] if code else [sys.executable, "-m", "experiments.run", *args]
        return subprocess.run(cmd, cwd=str(REPO), capture_output=True, text=True, env=full_env, timeout=timeout)

    return _run


def assert_cli_error(proc, path) -> str:
    """The CLI's bad-input contract: exit 2, one stderr line 'error: ...' naming ``path``, no traceback."""
    assert proc.returncode == 2, (proc.returncode, proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stderr, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("error:"), lines[0]
    if path is not None:
        assert str(path) in lines[0], lines[0]
    return lines[0]


@pytest.fixture(scope="session")
def cli_error():
    """:func:`assert_cli_error` as a fixture."""
    return assert_cli_error


# ---------------------------------------------------------------- exact oracle agreement, far meshes
def assert_agrees_exactly(hits, ref, ties, what=None) -> dict:
    """The oracle contract for a structure that calls :func:`tracer.accel.geometry.ray_triangle` as the
    oracle does (ray widened to float64 with ``np.float64``, float32 vertices, float64 tmin/tmax):
    no disagreement by :func:`tracer.accel.oracle.compare` (hit/miss, id, t), and where the structure
    returns the oracle's triangle its t is *bit-identical*: the structure's float32 t is the
    oracle's float64 t rounded, with no tolerance — the same function on the same inputs.

    A different triangle is accepted only as a tie (``compare``: the oracle saw another triangle at
    its t — duplicate faces, shared edges and vertices). There the t comes from other vertices, so
    it may differ in its last bits: the oracle counts a tie within 1e-9 relative of its t, which
    after rounding to float32 is at most one float32 ulp — the tolerance of that case, and only of
    that case. Returns ``compare``'s counts."""
    import numpy as np

    from tracer.accel.oracle import compare

    res = compare(hits, ref, ties)
    assert res["disagreements"] == 0, (what, res)
    hit = hits.tri_id >= 0
    assert np.all(np.isinf(hits.t[~hit])), (what, "a miss has a finite t")
    ref32 = ref.t.astype(np.float32)
    same = hit & (hits.tri_id == ref.tri_id)
    bad = np.flatnonzero(same & (hits.t != ref32))
    assert len(bad) == 0, (what, f"{len(bad)} hits on the oracle's triangle with another t", bad[:10].tolist(),
                           hits.t[bad[:5]].tolist(), ref.t[bad[:5]].tolist())
    tie = hit & ~same
    far = np.abs(hits.t[tie].astype(np.float64) - ref32[tie]) > np.spacing(np.abs(ref32[tie])).astype(np.float64)
    assert not far.any(), (what, "a tie more than one float32 ulp from the oracle's t",
                           np.flatnonzero(tie)[far][:10].tolist())
    return res


@pytest.fixture(scope="session")
def agrees_exactly():
    """:func:`assert_agrees_exactly` as a fixture."""
    return assert_agrees_exactly


def transformed_scene(scene, scale: float = 1.0, shift: float = 0.0):
    """``scene`` through :func:`tracer.scenes.derived.placed`: normalised to unit size, scaled by
    ``scale`` and moved by ``shift`` on every axis: e.g. (1, 1e5) is a unit mesh 1e5 from the origin,
    where float32 coordinates are 1/128 apart and float32 rays often lie exactly in the planes of the
    mesh's vertices."""
    from tracer.scenes.derived import placed
    from tracer.scenes.scene import Scene

    return Scene(placed(scene.tris, scale, shift), f"{scene.name}@x{scale:g}+{shift:g}")


_FAR: dict = {}


@pytest.fixture(scope="session")
def far_scene(load):
    """``far_scene(name, scale, shift)``: :func:`transformed_scene` of a named scene, once per session."""

    def _far(name: str, scale: float = 1.0, shift: float = 0.0):
        key = (name, float(scale), float(shift))
        if key not in _FAR:
            _FAR[key] = transformed_scene(load(name), scale, shift)
        return _FAR[key]

    return _far

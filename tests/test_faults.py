"""Faults and bad settings: one line on stderr, exit 2, and the output as it was before the run."""
from __future__ import annotations

import errno

import pytest

from experiments.run import main


@pytest.mark.parametrize("args, words", [
    (["derive", "--threads", "0"], "--threads must be between 1 and"),
    (["derive", "--threads", "999"], "--threads must be between 1 and"),
    (["table2", "--rays", "-5"], "--rays must be between 1 and"),
    (["table2", "--repeats", "0"], "--repeats must be between 1 and"),
    (["wald-fig6", "--side", "100000"], "--side must be between 1 and"),
    (["derive", "--models", "/nonexistent/models"], "--models must be a folder of meshes"),
])
def test_settings_out_of_range_are_refused(args, words, capsys, tmp_path):
    assert main(args + ["--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0], err
    assert not (tmp_path / "out").exists()  # refused before anything ran


def test_full_disk_exits_2_and_leaves_the_output_as_it_was(tmp_path, monkeypatch, capsys):
    """A full disk while a target writes: exit 2 naming the file and the bytes, and the target's
    folder and figures exactly as before the run (the run's new files gone)."""
    out = tmp_path / "out"
    (out / "derive").mkdir(parents=True)
    (out / "derive" / "summary.md").write_text("the committed summary\n")
    (out / "derive" / "old.csv").write_text("a\n1\n")

    from tracer import storage
    real = storage.atomic_write

    def full(path, data, **kw):
        if str(path).endswith("summary.md"):
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, data, **kw)

    monkeypatch.setattr("experiments.ize.derive.atomic_write", full)
    assert main(["derive", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no space left" in err[0] and "summary.md" in err[0], err
    assert sorted(p.name for p in (out / "derive").iterdir()) == ["old.csv", "summary.md"]
    assert (out / "derive" / "summary.md").read_text() == "the committed summary\n"
    assert not list(out.glob(".derive.before"))


def test_full_disk_in_atomic_write_names_file_and_bytes(tmp_path, monkeypatch):
    from tracer import storage

    def no_space(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(storage.os, "replace", no_space)
    with pytest.raises(OSError, match="12 bytes needed") as e:
        storage.atomic_write(tmp_path / "x.txt", "hello world!")
    assert e.value.filename == str(tmp_path / "x.txt") and not list(tmp_path.iterdir())
    assert storage.atomic_write(tmp_path / "y.txt", "cache", strict=False) == tmp_path / "y.txt"  # caches shrug


def test_a_mesh_of_only_degenerate_triangles_is_refused(tmp_path, capsys):
    mesh = tmp_path / "line.obj"
    mesh.write_text("v 0 0 0\nv 1 1 1\nv 2 2 2\nv 3 3 3\nf 1 2 3\nf 2 3 4\n")
    assert main(["verify", "--mesh", str(mesh), "--rays", "10"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "all 2 triangles are degenerate" in err[0], err


def test_degenerate_triangles_beside_real_ones_are_counted_and_kept(tmp_path):
    from tracer.scenes.meshfile import load_mesh
    mesh = tmp_path / "mixed.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 2 2\nf 1 2 3\nf 1 4 4\n")
    scene = load_mesh(mesh, use_cache=False)
    assert scene.n == 2 and scene.report["degenerate"] == 1


def test_a_truncated_numba_cache_entry_is_dropped_and_rebuilt(tmp_path):
    """A kill or a full disk can leave a cache file cut short: the next run recompiles that kernel,
    says so in one line and gives the same answer."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    (tmp_path / "kern.py").write_text("from tracer.accel._jit import jit\n\n\n@jit\ndef twice(x):\n    return 2 * x\n")
    env = dict(os.environ, GRIDCOST_NUMBA_CACHE=str(tmp_path / "nb"),
               PYTHONPATH=os.pathsep.join([str(tmp_path), str(Path(__file__).resolve().parents[1])]))
    run = lambda: subprocess.run([sys.executable, "-c", "import kern; print(kern.twice(21))"], env=env,  # noqa: E731
                                 capture_output=True, text=True, timeout=300)
    first = run()
    assert first.returncode == 0 and first.stdout.strip() == "42", first.stderr
    files = [p for p in (tmp_path / "nb").rglob("*") if p.suffix in (".nbi", ".nbc")]
    assert files
    for p in files:
        p.write_bytes(p.read_bytes()[: max(1, p.stat().st_size // 3)])
    second = run()
    assert second.returncode == 0 and second.stdout.strip() == "42", second.stderr
    lines = [l for l in second.stderr.splitlines() if "dropped an unreadable compiled-kernel cache entry" in l]
    assert len(lines) == 1, second.stderr
    third = run()  # rebuilt: read back silently
    assert third.returncode == 0 and "dropped" not in third.stderr


@pytest.mark.parametrize("cut", ["truncated", "wrong keys"])
def test_own_cache_files_cut_short_are_dropped_and_rebuilt(cut, tmp_path, monkeypatch, capsys):
    """gridcost's own caches (a parsed mesh, an oracle answer): an entry cut short or holding other
    arrays is dropped with one line naming it, rebuilt, and gives the same answer as before."""
    import numpy as np

    from tracer.accel.oracle import oracle_cached
    from tracer.scenes.meshfile import load_mesh
    from tracer.scenes.rays import make_rays
    monkeypatch.setenv("GRIDCOST_CACHE", str(tmp_path / "cache"))
    mesh = tmp_path / "two.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\n")
    scene = load_mesh(mesh)
    rays = make_rays(scene, "random", 64, seed=1)
    hits, ties = oracle_cached(scene, rays.origins, rays.directions)
    entries = sorted((tmp_path / "cache").rglob("*.npz"))
    assert len(entries) == 2  # the parse and the oracle answer
    for p in entries:
        if cut == "truncated":
            p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])
        else:
            np.savez(p, other=np.zeros(3))
    capsys.readouterr()
    again = load_mesh(mesh)
    hits2, ties2 = oracle_cached(again, rays.origins, rays.directions)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all("dropped and rebuilt" in line for line in err), err
    assert {p.name for p in entries} == {next(p.name for p in entries if p.name in line) for line in err}
    np.testing.assert_array_equal(again.tris, scene.tris)
    np.testing.assert_array_equal(hits2.t, hits.t)
    np.testing.assert_array_equal(hits2.tri_id, hits.tri_id)
    np.testing.assert_array_equal(ties2, ties)
    load_mesh(mesh)
    oracle_cached(again, rays.origins, rays.directions)
    assert capsys.readouterr().err == ""  # rebuilt: read back silently


@pytest.mark.parametrize("content, why", [('{"key": {}, "provenance": {}, "val', "unreadable"),
                                          ('{"garbage": 1}', "not a gridcost point"),
                                          ('{"key": {}, "provenance": {}, "value": {"x": "1"}, "sha": "0"}',
                                           "does not match the checksum")])
def test_a_bad_stored_point_is_named_set_aside_and_measured_again(content, why, tmp_path, capsys):
    from experiments.core.store import PointStore
    store = PointStore(tmp_path)
    params = {"scene": "s", "cells": 8}
    store.put(params, {"x": 1})
    path = store.dir / f"{store.key(params)}.json"
    path.write_text(content)
    fresh = PointStore(tmp_path)
    row, cached = fresh.measure(params, lambda: {"x": 2})
    assert (row, cached) == ({"x": 2}, False)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0] and why in err[0], err
    kept = list((store.dir / "set-aside").iterdir())
    assert len(kept) == 1 and kept[0].read_text() == content
    assert PointStore(tmp_path).get(params) == {"x": 2}  # the re-measured point is stored


def test_a_quick_run_does_not_write_over_the_full_results(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "results" / "derive").mkdir(parents=True)
    (tmp_path / "results" / "derive" / "summary.md").write_text("full run\n")
    assert main(["derive", "--quick"]) == 0
    assert "writes to results/quick" in capsys.readouterr().err
    assert (tmp_path / "results" / "derive" / "summary.md").read_text() == "full run\n"
    assert (tmp_path / "results" / "quick" / "derive" / "summary.md").exists()


def test_a_point_stored_before_checksums_is_stale_not_altered(tmp_path, capsys):
    """A point with no checksum (an older gridcost's) is measured again quietly, as a stale one."""
    import json
    from experiments.core.store import PointStore
    store = PointStore(tmp_path)
    params = {"scene": "s", "cells": 8}
    store.put(params, {"x": 1})
    path = store.dir / f"{store.key(params)}.json"
    rec = json.loads(path.read_text())
    del rec["sha"]
    path.write_text(json.dumps(rec))
    assert PointStore(tmp_path).measure(params, lambda: {"x": 2}) == ({"x": 2}, False)
    assert capsys.readouterr().err == "" and not (store.dir / "set-aside").exists()
    rec = json.loads(path.read_text())
    assert rec["value"] == {"x": 2} and "sha" in rec

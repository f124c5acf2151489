"""Every number traceable: the Numba cache sees cross-file edits, stored points carry and check
their measurement key, clocks are checked, memory estimates match the build, failures are loud."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from experiments.core.context import RunContext
from experiments.core.store import PointStore, read_csv
from tracer import build, load_scene
from tracer.errors import GridcostError

REPO = Path(__file__).resolve().parents[1]


# ---------------------------------------------------------------- Numba cache keyed by the kernel sources
_PROBE = """
import sys
import numpy as np
from tracer.accel.geometry import ray_triangle
from tracer.accel._jit import jit, CACHE_DIR

@jit
def caller():
    return ray_triangle(0.0, 0.0, -1.0, 0.0, 0.0, 1.0, -1.0, -1.0, 0.0, 1.0, -1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1e30)

print(caller(), CACHE_DIR)
"""


def test_cross_file_edit_reaches_cached_kernel(tmp_path):
    """A kernel in one file inlines ray_triangle from tracer/accel/geometry.py. After an edit to
    geometry.py only, a fresh process must run the edited code, not the cached machine code."""
    pkg = tmp_path / "repo"
    shutil.copytree(REPO / "tracer", pkg / "tracer", ignore=shutil.ignore_patterns("__pycache__", "data"))
    (pkg / "probe.py").write_text(_PROBE)
    env = dict(os.environ, GRIDCOST_NUMBA_CACHE=str(tmp_path / "numba"), PYTHONPATH=str(pkg))

    def run():
        p = subprocess.run([sys.executable, "probe.py"], cwd=pkg, env=env, capture_output=True, text=True,
                           timeout=300)
        assert p.returncode == 0, p.stderr
        t, cache = p.stdout.split()
        return float(t), cache

    t1, cache1 = run()
    assert t1 == pytest.approx(1.0)
    t1b, cache1b = run()  # second run: served from the cache
    assert (t1b, cache1b) == (t1, cache1)
    assert any(Path(cache1).rglob("*.nbi")), "the kernel was not cached"
    geo = pkg / "tracer" / "accel" / "geometry.py"
    src = geo.read_text()
    # an edit in geometry.py only: the triangle test now returns t + 1
    edited = src.replace("def ray_triangle(", "def _ray_triangle_orig(", 1)
    edited += ("\n\n@jit(inline=\"always\")\ndef ray_triangle(ox, oy, oz, dx, dy, dz, ax, ay, az, bx, by, bz, cx, cy, cz, "
               "tmin, tmax):\n    return _ray_triangle_orig(ox, oy, oz, dx, dy, dz, ax, ay, az, bx, by, bz, cx, cy, cz, "
               "tmin, tmax) + 1.0\n")
    geo.write_text(edited)
    t2, cache2 = run()
    assert cache2 != cache1
    assert t2 == pytest.approx(2.0), "a cached kernel kept running the old geometry.py"


_KEYS = """
from tracer.measure.provenance import measurement_key, numba_cache_dir
print(numba_cache_dir().name, measurement_key(("experiments/core/sweep.py",), 1, "thread CPU time")["code"])
"""


def test_registry_edit_keeps_cache_and_points_kernel_edit_drops_both(tmp_path):
    """The Numba cache folder and the measurement key hash the kernel sources only: an edit to the
    registry's table, to a scene loader or to a kernel's docstring keeps both; an edit to the code
    of ``ray_triangle`` changes both."""
    pkg = tmp_path / "repo"
    shutil.copytree(REPO / "tracer", pkg / "tracer", ignore=shutil.ignore_patterns("__pycache__", "data"))
    shutil.copytree(REPO / "experiments" / "core", pkg / "experiments" / "core",
                    ignore=shutil.ignore_patterns("__pycache__"))
    (pkg / "keys.py").write_text(_KEYS)
    env = dict(os.environ, PYTHONPATH=str(pkg), GRIDCOST_NUMBA_CACHE=str(tmp_path / "numba"))

    def keys():
        p = subprocess.run([sys.executable, "keys.py"], cwd=pkg, env=env, capture_output=True, text=True,
                           timeout=120)
        assert p.returncode == 0, p.stderr
        return tuple(p.stdout.split())

    base = keys()
    assert len(base) == 2 and all(len(k) == 16 for k in base)
    reg = pkg / "tracer" / "scenes" / "registry_data.py"
    reg.write_text(reg.read_text() + "\nEXTRA_MESH_NOTE = 'a new registry entry'\n")
    scene = pkg / "tracer" / "scenes" / "scene.py"
    scene.write_text(scene.read_text() + "\n\ndef _new_loader():\n    return None\n")
    geo = pkg / "tracer" / "accel" / "geometry.py"
    src = geo.read_text()
    j = src.index('"""', src.index("def ray_triangle(")) + 3
    geo.write_text(src[:j] + "A reworded docstring. " + src[j:])  # docstring only
    assert keys() == base
    code_edit = geo.read_text()
    i = code_edit.index("def ray_triangle(")
    k = code_edit.index('"""', code_edit.index('"""', i) + 3) + 3
    geo.write_text(code_edit[:k] + "\n    tmax = tmax * 1.0" + code_edit[k:])  # code: one more operation
    edited = keys()
    assert edited[0] != base[0] and edited[1] != base[1]


# ---------------------------------------------------------------- stored points and their key
def test_point_with_another_key_is_remeasured(tmp_path, monkeypatch):
    store = PointStore(tmp_path)
    calls = []

    def fn():
        calls.append(1)
        return {"v": len(calls)}

    assert store.measure({"p": 1}, fn) == ({"v": 1}, False)
    assert PointStore(tmp_path).measure({"p": 1}, fn) == ({"v": 1}, True)  # same key: reused
    rec = json.loads(next((tmp_path / "points").glob("*.json")).read_text())
    assert rec["key"]["code"] and rec["key"]["threads"] >= 1 and rec["key"]["clock"] and rec["key"]["cpu"]
    assert rec["provenance"]["commit"] and rec["provenance"]["host"]
    # another thread count (or code, clock, CPU): the stored point is stale and measured again
    from tracer.measure import provenance
    real = provenance.measurement_key
    monkeypatch.setattr(provenance, "measurement_key", lambda code, threads, clock:
                        dict(real(code, threads, clock), threads=99))
    assert PointStore(tmp_path).measure({"p": 1}, fn) == ({"v": 2}, False)
    # --reuse-stale uses a stale point and marks it
    monkeypatch.setattr(provenance, "measurement_key", lambda code, threads, clock:
                        dict(real(code, threads, clock), threads=98))
    stale = PointStore(tmp_path, reuse_stale=True)
    assert stale.get({"p": 1}) == {"v": 2}
    assert stale.provenance({"p": 1})["stale"] is True
    assert len(calls) == 2


def test_code_in_key_invalidates(tmp_path):
    """The key covers the experiment code that shapes a point, beside tracer/."""
    a = PointStore(tmp_path, code=("experiments/core/sweep.py",))
    b = PointStore(tmp_path, code=("experiments/core/sweep.py", "experiments/ize/lib/memprobe.py"))
    assert a.measurement_key["code"] != b.measurement_key["code"]
    a.put({"p": 2}, {"v": 1})
    assert b.get({"p": 2}) is None


def test_legacy_point_without_key_is_remeasured(tmp_path):
    (tmp_path / "points").mkdir()
    (tmp_path / "points" / f"{PointStore.key({'p': 3})}.json").write_text(json.dumps({"v": "old"}))
    assert PointStore(tmp_path).get({"p": 3}) is None


def test_rows_carry_commit_host_clock(tmp_path):
    import pandas as pd
    ctx = RunContext(out=tmp_path)
    ctx.start_target()
    ctx.store().put({"p": 4}, {"v": 1})
    ctx.write_csv(tmp_path / "x.csv", pd.DataFrame([{"a": 1}]))
    df = read_csv(tmp_path / "x.csv")
    now = ctx.ledger.now()
    assert df.commit[0] == now["commit"] and df.host[0] == now["host"] and df.clock[0] == now["clock"]


@pytest.mark.parametrize("commit", ["7704900", "1234e56", "0a1b2c3"])
def test_results_csv_keeps_commits_text(tmp_path, commit):
    """An abbreviated hash of digits (or digits and one 'e') is text, not a number: pandas alone reads
    "7704900" as an int and "1234e56" as 1.234e+59."""
    import pandas as pd
    pd.DataFrame([{"a": 1, "commit": commit, "host": "0042", "clock": "thread CPU time",
                   "source_commit": commit}]).to_csv(tmp_path / "x.csv", index=False)
    df = read_csv(tmp_path / "x.csv")
    assert df.commit[0] == commit and df.source_commit[0] == commit and df.host[0] == "0042" and df.a[0] == 1


# ---------------------------------------------------------------- clocks
def test_clock_check_sees_kernel_work():
    from tracer.measure.timing import thread_clock_check
    chk = thread_clock_check()
    assert chk["ok"], chk
    # the calling thread did the process's work (a busy machine may preempt it: wall time is no test)
    assert chk["thread"] > 0.5 * chk["process"] > 0 and chk["wall"] > 0


def test_untrustworthy_thread_clock_falls_back_to_wall(monkeypatch, capsys):
    import numba

    from tracer.measure import timing
    timing.thread_clock_check.cache_clear()
    monkeypatch.setattr(timing.time, "thread_time", lambda: 1.0)  # a clock that sees no work
    n = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        assert timing.default_clock() is time.perf_counter
        assert timing.clock_name() == "wall time"
    finally:
        numba.set_num_threads(n)
        monkeypatch.undo()
        timing.thread_clock_check.cache_clear()
    assert "wall time instead" in capsys.readouterr().err


# ---------------------------------------------------------------- memory guard matches the build
def _peak(fn):
    tracemalloc.start()
    try:
        out = fn()
        return out, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize("params", [{"cells": 2e6}, {"cells": 2e6, "macro": 4}, {"cells": 2e6, "layout": "index"}])
def test_grid_memory_estimate_matches_peak(params):
    from tracer.measure.footprint import grid_bytes
    scene = load_scene("dragon-11k")
    build(scene, "grid", cells=1000)  # compile outside the measurement
    g, peak = _peak(lambda: build(scene, "grid", **params))
    st = g.stats()
    est = grid_bytes(st["cells"], st["refs"], g.layout_, g.macro)
    assert peak / 1.5 <= est <= peak * 1.5, (est, peak)


@pytest.mark.parametrize("params", [{"levels": 2}, {"levels": 3}, {"levels": 2, "m2_factor": 64}])
def test_nested_memory_estimate_matches_peak(params):
    scene = load_scene("dragon-11k")
    build(scene, "nested", levels=2, m1=10)
    g, peak = _peak(lambda: build(scene, "nested", **params))
    assert peak / 1.5 <= g.peak_estimate_ <= peak * 1.5, (g.peak_estimate_, peak)


def test_grid_near_the_budget(monkeypatch):
    """Just over the estimate builds; just under refuses with the estimate in the message."""
    from tracer.measure.footprint import grid_bytes
    scene = load_scene("bunny-948")
    g = build(scene, "grid", cells=1e6)
    st = g.stats()
    est = grid_bytes(st["cells"], st["refs"], g.layout_)
    monkeypatch.setenv("GRIDCOST_MEMORY_BUDGET", str(int(est * 1.01)))
    build(scene, "grid", cells=1e6)
    monkeypatch.setenv("GRIDCOST_MEMORY_BUDGET", str(int(est * 0.99)))
    with pytest.raises(GridcostError, match=r"would need about [0-9.]+ MiB"):
        build(scene, "grid", cells=1e6)


# ---------------------------------------------------------------- loud failures
def test_internal_error_is_one_line_exit_1(monkeypatch, capsys):
    from experiments import run
    from experiments.ize import derive as ize_derive

    def boom(ctx, args):
        raise RuntimeError("kaboom\nsecond line")
    monkeypatch.setattr(ize_derive, "main", boom)
    assert run.main(["derive", "--out", "/tmp/gridcost-test-derive"]) == 1
    err = capsys.readouterr().err
    assert err.strip() == "internal error in derive: RuntimeError: kaboom (--debug shows the traceback)"
    assert run.main(["derive", "--out", "/tmp/gridcost-test-derive", "--debug"]) == 1
    assert "Traceback" in capsys.readouterr().err


def test_all_goes_on_lists_failures_and_exits_nonzero(monkeypatch, capsys, tmp_path):
    from experiments import run
    ran = []
    monkeypatch.setattr(run, "ALL_ORDER", ["derive", "fig2"])

    def fake(name, ctx, args):
        ran.append(name)
        if name == "derive":
            raise GridcostError("bad input")
        return 0
    monkeypatch.setattr(run, "_run_target", fake)
    assert run.main(["all", "--out", str(tmp_path)]) == 2
    assert ran == ["derive", "fig2"]
    assert "1 of 2 targets failed: derive (exit 2)" in capsys.readouterr().err


def test_all_refuses_dirty_tree_into_results(monkeypatch, capsys):
    from experiments import run
    from experiments.core import store
    monkeypatch.setattr(store, "git_commit", lambda: "abc1234-dirty")
    assert run.main(["all"]) == 2
    assert "uncommitted changes" in capsys.readouterr().err


def test_bench_threads_ratio_is_labelled_per_thread(tmp_path):
    from experiments.tools.bench import run_bench
    from tracer.accel.reference import EmbreeAccel
    if not EmbreeAccel.available():
        pytest.skip("embreex not installed (optional extra)")
    scene = load_scene("bunny-948")
    out = run_bench(scene, ["grid", "embree"], 2000, 1, 2, log=lambda *a: None)
    (key,) = [k for k in out["ratios"] if k.startswith("grid/")]
    assert "per thread" in key and out["embree_ratio_basis"].startswith("per thread")
    s = out["structures"]
    assert out["ratios"][key]["random"] == pytest.approx(s["grid"]["random_mrays"] / 2 / s["embree"]["random_mrays"])
    assert "paired" in out and "grid/embree" not in out["paired"]  # paired ratios only at one thread
    assert np.isfinite(out["ratios"][key]["camera"])


def test_results_index_names_who_measured_each_folder(tmp_path):
    """results/README.md's last column: each folder's commit, CPU and date from its meta.json (or
    from every JSON naming a commit, where a target writes one per run)."""
    from experiments.core.store import write_index
    out, figs = tmp_path / "results", tmp_path / "paper_figs"
    figs.mkdir()
    for name, commit, cpu in (("table2", "d986c17", "AMD EPYC"), ("bench", "7d0395f", "Intel(R) Xeon(R) Processor")):
        (out / name).mkdir(parents=True)
        (out / name / "meta.json").write_text(json.dumps({"git_commit": commit, "host": {"cpu": cpu},
                                                          "finished": "2026-12-02T10:00:00+0000"}))
    (out / "derive").mkdir()  # no meta.json
    (out / "verify").mkdir()  # one JSON per run, no meta.json
    for name, commit in (("grid", "acd51cd"), ("bvh", "cb824b8")):
        (out / "verify" / f"{name}.json").write_text(json.dumps({"git_commit": commit, "host": {"cpu": "Intel"},
                                                                 "finished": f"2026-12-0{1 + len(name)}T00:00"}))
    rows = {ln.split("|")[1].strip(): ln for ln in write_index(out, figs).read_text().splitlines() if ln.startswith("| ")}
    assert rows["table2"].rstrip().endswith("| `d986c17`, AMD EPYC, 2026-12-02 |")
    assert rows["bench"].rstrip().endswith("| `7d0395f`, Intel(R) Xeon(R) Processor, 2026-12-02 |")
    assert rows["derive"].rstrip().endswith("| – |")
    assert rows["verify"].rstrip().endswith("| `acd51cd`, `cb824b8`, Intel, 2026-12-05 |")


def test_timing_noise_is_measured_without_counting_as_a_timing():
    """The noise meter's reading: finite, non-negative CVs of both kernels, on the run's clock; it
    must not move tracer.measure.timing's count of timings (which tells a file measured now from one drawn
    from stored points)."""
    from experiments.core.noise import timing_noise, worst_cv
    from tracer.measure.timing import timing_calls
    before = timing_calls()
    tn = timing_noise(samples=4, min_sample=0.002)
    assert timing_calls() == before
    assert tn["clock"] in ("thread CPU time", "wall time") and tn["samples"] == 4
    for k in ("compute_cv", "compute_spread", "memory_cv", "memory_spread"):
        assert np.isfinite(tn[k]) and tn[k] >= 0, (k, tn)
    assert worst_cv({"timing_noise": {"start": None, "end": tn}}) == max(tn["compute_cv"], tn["memory_cv"])
    assert worst_cv({}) is None
    with pytest.raises(ValueError, match="at least 2 samples"):
        timing_noise(samples=1)

"""A Dask worker killed in the middle of a sweep: the sweep finishes on the other worker (the point
it was measuring is sent again), or, when a point cannot be measured anywhere, fails with one line
naming it; every finished point is stored once and a rerun measures only what is missing."""
from __future__ import annotations

import re

import json
import os
import signal
import threading
import time
from types import SimpleNamespace

import pytest

distributed = pytest.importorskip("distributed")

from experiments.core.executor import DaskExecutor  # noqa: E402
from experiments.core.store import PointStore  # noqa: E402
from experiments.core.sweep import sweep  # noqa: E402
from tracer.errors import GridcostError  # noqa: E402
from tracer.scenes.rays import make_rays  # noqa: E402
from tracer.scenes.scene import load_scene  # noqa: E402

PARAMS = [{"cells": c} for c in (500, 1000, 2000, 4000, 8000, 16000)]


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1, dashboard_address=None,
                                  host="127.0.0.1") as c:
        yield c


def _files(tmp_path) -> list:
    return sorted(p for p in (tmp_path / "points").rglob("*.json") if "set-aside" not in p.parts)


def _kill_a_busy_worker(client, stop: threading.Event) -> list[int]:
    """Wait until a worker is measuring a point, then SIGKILL that worker's process (by its pid)."""
    killed = []
    while not stop.is_set() and not killed:
        busy = [w for w, keys in client.processing().items() if keys]
        if busy:
            pid = client.run(os.getpid, workers=busy[:1])[busy[0]]
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)
        time.sleep(0.05)
    return killed


def _sweep(executor, tmp_path, scene, rays):
    """The sweep as `run.main` runs it with --dask: the client on the wall clock its workers time with
    (whatever Numba thread count an earlier test of this process left)."""
    from tracer.settings import current, use
    store = PointStore(tmp_path, ctx=SimpleNamespace(quick=True, executor=executor))
    with use(current().replace(clock="wall")):
        return store, sweep(scene, "grid", PARAMS, rays, store, repeats=1)


def test_a_killed_worker_does_not_lose_the_sweep(cluster, tmp_path):
    scene = load_scene("bunny-948")
    rays = {"random": make_rays(scene, "random", 2000, seed=0)}
    ex = DaskExecutor(cluster.scheduler_address)
    try:
        stop = threading.Event()
        killed: list = []
        t = threading.Thread(target=lambda: killed.extend(_kill_a_busy_worker(ex.client, stop)))
        t.start()
        try:
            _, rows = _sweep(ex, tmp_path, scene, rays)
        finally:
            stop.set()
            t.join()
        assert killed, "no worker was killed while the sweep ran"
        assert sorted(r["param_cells"] for r in rows) == [p["cells"] for p in PARAMS]
        points = [f for f in _files(tmp_path) if "rows" in json.loads(f.read_text())["value"]]
        assert len(points) == len(PARAMS)  # each point stored once, whole
        for f in points:
            assert len(json.loads(f.read_text())["value"]["rows"]) == 1
        # a rerun measures nothing: every point is found in the store
        before = {f: f.stat().st_mtime_ns for f in points}
        ex2 = SimpleNamespace(map=lambda specs, scenes=None: pytest.fail(f"re-measured {list(specs)}"))
        _, again = _sweep(ex2, tmp_path, scene, rays)
        assert len(again) == len(PARAMS)
        assert {f: f.stat().st_mtime_ns for f in points} == before
    finally:
        ex.client.close()


def test_a_point_lost_on_every_try_is_named_and_remeasured_alone(cluster, tmp_path, monkeypatch):
    scene = load_scene("bunny-948")
    rays = {"random": make_rays(scene, "random", 2000, seed=0)}
    ex = DaskExecutor(cluster.scheduler_address, retries=1)
    victim = PARAMS[2]["cells"]
    real_submit = ex.client.submit

    def submit(fn, spec, **kw):  # the victim point's task kills the worker that runs it, every time
        if spec["params"] == {"cells": victim}:
            return real_submit(_die, spec, **kw)
        return real_submit(fn, spec, **kw)

    monkeypatch.setattr(ex.client, "submit", submit)
    try:
        ex.client.run_on_scheduler(_set_allowed_failures, 0)  # a worker's death fails its task at once
        with pytest.raises(GridcostError) as exc:
            _sweep(ex, tmp_path, scene, rays)
        msg = str(exc.value)
        assert "\n" not in msg
        # the poisoned point is named; a point that shared a dying worker with it may be lost beside it
        lost = sorted(float(c) for c in re.findall(r"\{'cells': ([0-9.]+)\}", msg))
        assert msg.startswith(f"{len(lost)} point(s) lost with their Dask worker after 2 tries: ")
        assert float(victim) in lost and f"{{'cells': {victim}}} (KilledWorker)" in msg
        assert sorted(_stored_cells(tmp_path)) == sorted(p["cells"] for p in PARAMS if float(p["cells"]) not in lost)
    finally:
        ex.client.run_on_scheduler(_set_allowed_failures, 3)
        ex.client.close()
    # the rerun sends only the missing point, and then every point is stored once
    ex3 = DaskExecutor(cluster.scheduler_address)
    sent = []
    try:
        counting = SimpleNamespace(map=lambda specs, scenes=None: (sent.extend(specs), ex3.map(specs, scenes))[1])
        _, rows = _sweep(counting, tmp_path, scene, rays)
    finally:
        ex3.client.close()
    assert sorted(float(s["params"]["cells"]) for s in sent) == lost
    assert sorted(r["param_cells"] for r in rows) == [p["cells"] for p in PARAMS]
    assert sorted(_stored_cells(tmp_path)) == [p["cells"] for p in PARAMS]


def _stored_cells(tmp_path) -> list:
    out = []
    for f in _files(tmp_path):
        value = json.loads(f.read_text())["value"]
        if "rows" in value:
            out.extend(r["param_cells"] for r in value["rows"])
    return out


def _set_allowed_failures(n, dask_scheduler=None):
    dask_scheduler.allowed_failures = n


def _die(spec):
    os.kill(os.getpid(), signal.SIGKILL)

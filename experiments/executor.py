"""One executor interface for sweep points: local (default, in this process, one point at a time so
timings never overlap) or Dask (``--dask ADDRESS``: points go to the workers of an existing
dask.distributed cluster; every row records the worker that timed it).

A point is a plain, picklable spec: scene name, structure, parameters, ray sets as (kind, n, seed),
repeats. Workers rebuild the scene and the rays from it (both deterministic).
"""
from __future__ import annotations

from typing import Iterable, Iterator

_SCENES: dict = {}


def remember_scene(scene) -> None:
    """Let local execution reuse an already loaded scene object."""
    _SCENES[scene.name] = scene


def run_point(spec: dict) -> tuple[dict, list[dict]]:
    """Measure one sweep point from its spec (runs on a worker or locally). Returns (spec, rows);
    every row carries the worker's measurement key (``key``: code digest, threads, clock, CPU,
    versions) so the client can refuse a point made by other code."""
    from experiments.sweep import measure
    from tracer.timing import MIN_SAMPLE_SECONDS
    from tracer.rays import make_rays
    from tracer.scene import load_scene
    scene = _SCENES.get(spec["scene"]) or load_scene(spec["scene"])
    _SCENES[scene.name] = scene
    rays = {kind: make_rays(scene, kind, n, seed=seed) for kind, (n, seed) in spec["rays"].items()}
    if spec.get("threads"):
        from tracer.timing import set_threads
        set_threads(spec["threads"])
    from tracer.provenance import measurement_key
    rows = measure(scene, spec["structure"], spec["params"], rays, spec["repeats"],
                   spec.get("min_sample", MIN_SAMPLE_SECONDS))
    key = measurement_key(tuple(spec.get("code", ())))
    return spec, [dict(r, key=key) for r in rows]


class LocalExecutor:
    name = "local"

    def map(self, specs: Iterable[dict]) -> Iterator[tuple[dict, list[dict]]]:
        for spec in specs:
            yield run_point(spec)


class DaskExecutor:
    """Send points to a dask.distributed cluster at ``address`` (or an in-process LocalCluster for
    ``address='local'``). Results are yielded as they complete."""

    name = "dask"

    def __init__(self, address: str):
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError:
            from tracer.errors import GridcostError
            raise GridcostError("Dask is not installed: pip install 'gridcost[dask]'") from None
        if address == "local":
            self.cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None)
            self.client = Client(self.cluster)
        else:
            self.cluster = None
            self.client = Client(address)

    def map(self, specs: Iterable[dict]) -> Iterator[tuple[dict, list[dict]]]:
        from dask.distributed import as_completed
        futures = [self.client.submit(run_point, s, pure=False) for s in specs]
        for fut in as_completed(futures):
            yield fut.result()

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


_CURRENT = None


def get_executor():
    global _CURRENT
    if _CURRENT is None:
        _CURRENT = LocalExecutor()
    return _CURRENT


def set_executor(address: str | None):
    """``None`` → local; otherwise a Dask scheduler address (``tcp://host:8786``) or ``local``."""
    global _CURRENT
    if _CURRENT is not None and hasattr(_CURRENT, "close"):
        _CURRENT.close()
    _CURRENT = DaskExecutor(address) if address else LocalExecutor()
    return _CURRENT

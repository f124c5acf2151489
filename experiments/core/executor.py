"""One executor interface for measurement tasks: local (default, in this process, one task at a time
so timings never overlap) or Dask (``--dask ADDRESS``: tasks go to the workers of an existing
dask.distributed cluster; every row records the worker that timed it).

A task is a plain, picklable spec: scene name (looked up through the mesh registry on the worker,
``models`` telling it where), structure, parameters, ray sets as (kind, n, seed), repeats, thread
count and the measurement code. Workers rebuild the scene and the rays from it (both
deterministic) and return their measurement key with the rows, so the client can refuse a point
made by other code.
"""
from __future__ import annotations

import os
from typing import Iterable, Iterator


def run_point(spec: dict, scene=None, ref=None) -> tuple[dict, list[dict]]:
    """Measure one sweep point from its spec (on a worker, or locally with the client's ``scene``
    and reference structure). Returns (spec, rows); every row carries the worker's measurement key."""
    from experiments.core.point import measure
    from tracer.provenance import measurement_key
    from tracer.rays import make_rays
    from tracer.scene import load_scene
    from tracer.timing import MIN_SAMPLE_SECONDS, set_threads
    if spec.get("models"):
        os.environ["GRIDCOST_MODELS"] = spec["models"]
    if spec.get("threads"):
        set_threads(spec["threads"])
    scene = scene if scene is not None else load_scene(spec["scene"])
    rays = {kind: make_rays(scene, kind, n, seed=seed) for kind, (n, seed) in spec["rays"].items()}
    rows = measure(scene, spec["structure"], spec["params"], rays, spec["repeats"],
                   spec.get("min_sample", MIN_SAMPLE_SECONDS), ref=ref)
    key = measurement_key(tuple(spec.get("code", ())))
    return spec, [dict(r, key=key) for r in rows]


class LocalExecutor:
    """Tasks run here, one at a time; the reference structure of the current scene is kept."""
    name = "local"

    def __init__(self, ctx=None):
        self.ctx = ctx
        self._ref: dict = {}

    def _reference(self, scene):
        from experiments.core.point import reference
        key = (scene.name, scene.n)
        if key not in self._ref:
            self._ref.clear()  # one scene at a time: large references are not kept around
            self._ref[key] = reference(scene)
        return self._ref[key]

    def map(self, specs: Iterable[dict], scenes: dict | None = None) -> Iterator[tuple[dict, list[dict]]]:
        for spec in specs:
            scene = (scenes or {}).get(spec["scene"])
            yield run_point(spec, scene, self._reference(scene) if scene is not None else None)


class DaskExecutor:
    """Send tasks to a dask.distributed cluster at ``address`` (or a LocalCluster of worker
    processes for ``address='local'``). Results are yielded as they complete."""

    name = "dask"

    def __init__(self, address: str, ctx=None):
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError:
            from tracer.errors import GridcostError
            raise GridcostError("Dask is not installed: pip install 'gridcost[dask]'") from None
        self.ctx = ctx
        if address == "local":
            self.cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
            self.client = Client(self.cluster)
        else:
            self.cluster = None
            self.client = Client(address)

    def map(self, specs: Iterable[dict], scenes: dict | None = None) -> Iterator[tuple[dict, list[dict]]]:
        from dask.distributed import as_completed
        models = os.environ.get("GRIDCOST_MODELS")
        futures = [self.client.submit(run_point, dict(s, models=models) if models else s, pure=False) for s in specs]
        for fut in as_completed(futures):
            spec, rows = fut.result()
            spec.pop("models", None)
            yield spec, rows

    def submit(self, fn, *args):
        """Run ``fn(*args)`` as one task (e.g. a paired comparison, both sides in one process)."""
        return self.client.submit(fn, *args, pure=False).result()

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()

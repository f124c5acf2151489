"""One executor interface for measurement tasks: local (default, in this process, one task at a time
so timings never overlap) or Dask (``--dask ADDRESS``: tasks go to the workers of an existing
dask.distributed cluster; every row records the worker that timed it).

A task is a plain, picklable spec: scene name (looked up through the mesh registry on the worker),
structure, parameters, ray sets as (kind, n, seed), repeats, thread count, the measurement code and
the client's :class:`tracer.settings.Settings` (``settings``: where meshes are, the clock), under
which the worker runs it. Workers rebuild the scene and the rays from it (both
deterministic) and return their measurement key with the rows, so the client can refuse a point
made by other code.
"""
from __future__ import annotations

import contextlib
from typing import Iterable, Iterator

from tracer.settings import Settings, current, use


def _settings_of(d: dict | None):
    """The block runs with the client's settings ``d`` (a worker), or with this process' own (local)."""
    return use(Settings.on_worker(d)) if d else contextlib.nullcontext()


def run_point(spec: dict, scene=None, ref=None) -> tuple[dict, list[dict]]:
    """Measure one sweep point from its spec (on a worker, or locally with the client's ``scene``
    and reference structure). Returns (spec, rows); every row carries the worker's measurement key."""
    from experiments.core.point import measure
    from tracer.measure.timing import measurement_key
    from tracer.scenes.rays import make_rays
    from tracer.scenes.scene import load_scene
    from tracer.measure.timing import MIN_SAMPLE_SECONDS, set_threads
    with _settings_of(spec.get("settings")):
        if spec.get("threads"):
            set_threads(spec["threads"])
        scene = scene if scene is not None else load_scene(spec["scene"])
        rays = {kind: make_rays(scene, kind, n, seed=seed) for kind, (n, seed) in spec["rays"].items()}
        rows = measure(scene, spec["structure"], spec["params"], rays, spec["repeats"],
                       spec.get("min_sample", MIN_SAMPLE_SECONDS), ref=ref)
        key = measurement_key(tuple(spec.get("code", ())))
    return spec, [dict(r, key=key) for r in rows]


# ---------------------------------------------------------------- any measurement as one task
class SceneRef(tuple):
    """A named scene sent to a worker by name (the worker loads it through the mesh registry)."""


class RaysRef(tuple):
    """A ray set sent by (scene name, kind, n, seed): the worker regenerates it (deterministic)."""


def _to_refs(args):
    """Scenes known by name and ray sets made by ``make_rays`` travel as references, not arrays."""
    from tracer.scenes.rays import Rays
    from tracer.scenes.scene import Scene
    out = []
    scene = next((a for a in args if isinstance(a, Scene)), None)
    for a in args:
        if isinstance(a, Scene) and _reloadable(a):
            out.append(SceneRef((a.name, a.n)))
        elif isinstance(a, Rays) and scene is not None and a.kind in ("random", "camera", "path", "adversarial"):
            out.append(RaysRef((scene.name, scene.n, a.kind, a.n, a.seed)))
        else:
            out.append(a)
    return tuple(out)


def _reloadable(scene) -> bool:
    """A scene a worker can load by its name (a registry mesh, procedural or SPD scene)."""
    from tracer.scenes import procedural, spd
    from tracer.scenes.scene import manifest
    return scene.name in manifest() or procedural.matches(scene.name) or spd.matches(scene.name)


def _from_refs(args):
    from tracer.scenes.rays import make_rays
    from tracer.scenes.scene import load_scene
    scenes = {}

    def scene_of(name, n):
        if name not in scenes:
            scenes[name] = load_scene(name)
            if scenes[name].n != n:
                from tracer.errors import GridcostError
                raise GridcostError(f"worker loaded {name} with {scenes[name].n:,} triangles, the client {n:,}")
        return scenes[name]
    out = []
    for a in args:
        if isinstance(a, SceneRef):
            out.append(scene_of(*a))
        elif isinstance(a, RaysRef):
            name, n, kind, m, seed = a
            r = make_rays(scene_of(name, n), kind, m, seed=seed)
            if r.n != m:
                from tracer.errors import GridcostError
                raise GridcostError(f"worker made {r.n} {kind} rays for {name}, the client {m}")
            out.append(r)
        else:
            out.append(a)
    return tuple(out)


def remote_task(fn, args, threads, settings: dict, code):
    """Run ``fn(*args)`` on a worker with the client's thread count and settings; returns (result,
    the worker's measurement key, its host)."""
    from tracer.measure.provenance import host
    from tracer.measure.timing import measurement_key
    from tracer.measure.timing import set_threads
    with _settings_of(settings):
        if threads:
            set_threads(threads)
        result = fn(*_from_refs(args))
        return result, measurement_key(tuple(code)), host()


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

    def run_task(self, fn, args: tuple, threads: int, code: tuple):
        """(fn(*args), None, this host): a local task needs no key check."""
        from tracer.measure.provenance import host
        return fn(*args), None, host()


#: times a point is sent again after the worker measuring it was lost (beside the scheduler's own
#: ``distributed.scheduler.allowed-failures``, which reschedules a task whose worker died)
LOST_RETRIES = 2


def _lost_worker_errors() -> tuple[type, ...]:
    """What a future raises when its worker, not its task, failed."""
    from distributed import KilledWorker
    from distributed.comm.core import CommClosedError
    return (KilledWorker, CommClosedError)


class DaskExecutor:
    """Send tasks to a dask.distributed cluster at ``address`` (or a LocalCluster of worker
    processes for ``address='local'``). Results are yielded as they complete.

    A Dask worker runs tasks on a thread of its own pool, where a one-thread Numba ``prange`` kernel
    may run on another thread than the task's (the thread-clock check sees ~0 %); a run with Dask
    therefore times everything, client and workers, with wall time: ``run.main`` resolves its
    settings with ``clock="wall"``, and the tasks carry the client's settings with that clock."""

    name = "dask"

    def __init__(self, address: str, ctx=None, tls=None, insecure: bool = False, retries: int = LOST_RETRIES):
        """``tls``: a certificate folder (:mod:`experiments.core.tls`): mutual TLS with the scheduler
        (required for a scheduler beyond loopback unless ``insecure``); with ``address='local'`` the
        local cluster uses it too. ``retries``: times a point lost with its worker is sent again."""
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError:
            from tracer.errors import GridcostError
            raise GridcostError("Dask is not installed: pip install 'gridcost[dask]'") from None
        from experiments.core import tls as tls_mod
        self.ctx = ctx
        self.retries = int(retries)
        sec = tls_mod.security(tls) if tls is not None else None
        if address == "local":
            kw = {"security": sec, "protocol": "tls://"} if sec is not None else {}
            self.cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                        host="127.0.0.1", **kw)
            self.client = Client(self.cluster, security=sec) if sec is not None else Client(self.cluster)
        else:
            tls_mod.check_address(address, tls, insecure)
            self.cluster = None
            self.client = Client(address, security=sec, timeout=30) if sec is not None else Client(address, timeout=30)

    def map(self, specs: Iterable[dict], scenes: dict | None = None) -> Iterator[tuple[dict, list[dict]]]:
        """Points as they complete (the sweep stores each at once, so an interrupted sweep keeps
        them). A point whose worker was lost (the process killed, the connection closed, or Dask's
        KilledWorker after the scheduler's own allowed failures) is sent again, up to ``retries``
        times; points still lost after that are named in one GridcostError once every other point
        has been yielded, and a rerun measures only them."""
        from dask.distributed import as_completed
        settings = self._settings()
        pending = {}

        def send(s, tries):
            fut = self.client.submit(run_point, dict(s, settings=settings), pure=False)
            pending[fut] = (s, tries)
            return fut

        done = as_completed([send(s, 0) for s in specs])
        lost = []
        for fut in done:
            s, tries = pending.pop(fut)
            try:
                spec, rows = fut.result()
            except _lost_worker_errors() as exc:
                if tries < self.retries:
                    done.add(send(s, tries + 1))
                else:
                    lost.append(f"{s['scene']} {s['structure']} {s['params']} ({type(exc).__name__})")
                continue
            finally:
                fut.release()
            spec.pop("settings", None)
            yield spec, rows
        if lost:
            from tracer.errors import GridcostError
            raise GridcostError(f"{len(lost)} point(s) lost with their Dask worker after {self.retries + 1} tries: "
                                f"{'; '.join(lost)}; the other points are stored, run again to measure these")

    @staticmethod
    def _settings() -> dict:
        """The client's settings for its tasks, with the wall clock a Dask run times with."""
        return current().replace(clock="wall").for_worker()

    def run_task(self, fn, args: tuple, threads: int, code: tuple):
        """``fn(*args)`` as one task on one worker (e.g. a paired comparison: both sides in one
        process on one machine); scenes and ray sets travel by name. Returns (result, the worker's
        measurement key, its host)."""
        return self.client.submit(remote_task, fn, _to_refs(args), threads, self._settings(), tuple(code),
                                  pure=False).result()

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()

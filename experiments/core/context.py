"""The run context: everything a target needs from the run that calls it, in one object.

``run.main`` builds one :class:`RunContext` from the command line and passes it to the target's
``main(ctx, args)``; a test or a notebook builds its own (``RunContext(out=tmp_path, quick=True)``).
Nothing else holds run state: no module-level flags to set in the right order.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from experiments.core.figures import figure_dir, finish_figure
from experiments.core.store import PROVENANCE_COLUMNS, Ledger, PointStore, atomic_write, git_commit, versions, write_json
from tracer.settings import Settings


@dataclass
class RunContext:
    """Output directory, quick mode, threads, executor, the point store's settings, the figure
    directory, the provenance ledger, the per-run caches of one run, and its :class:`Settings`
    (the environment's, unless the caller resolved others: ``run.main`` runs the target inside
    ``tracer.settings.use(ctx.settings)``; a Dask task carries them to its worker)."""
    out: Path = Path("results")
    quick: bool = False
    threads: int | None = None
    force: bool = False
    reuse_stale: bool = False
    executor: object = None
    fig_dir: Path | None = None
    ledger: Ledger = field(default_factory=Ledger)
    #: the sweep's reference structure of the current scene (one scene at a time)
    ref_cache: dict = field(default_factory=dict)
    #: scenes already loaded in this process (local execution reuses them)
    scenes: dict = field(default_factory=dict)
    #: this host's timing noise when the current target started (:mod:`experiments.core.noise`)
    noise_start: dict | None = None
    settings: Settings = field(default_factory=Settings.from_env)

    def __post_init__(self):
        self.out = Path(self.out)
        if self.fig_dir is None:
            self.fig_dir = figure_dir(self.out)
        if self.executor is None:
            from experiments.core.executor import LocalExecutor
            self.executor = LocalExecutor(self)

    @classmethod
    def from_args(cls, args, settings: Settings) -> "RunContext":
        """The context of a command line (``run.main`` only) with its resolved ``settings``."""
        executor = None
        ctx = cls(out=Path(args.out), quick=bool(getattr(args, "quick", False)), threads=args.threads,
                  force=bool(getattr(args, "force", False)), reuse_stale=bool(getattr(args, "reuse_stale", False)),
                  settings=settings)
        if getattr(args, "dask", None):
            from experiments.core.executor import DaskExecutor
            executor = DaskExecutor(args.dask, ctx, tls=getattr(args, "tls", None),
                                    insecure=bool(getattr(args, "insecure", False)))
            ctx.executor = executor
        return ctx

    # ------------------------------------------------------------ per target
    def start_target(self) -> None:
        """A fresh ledger and a reading of the host's timing noise before each target."""
        self.ledger.reset()
        self.noise_start = self._noise()

    def _noise(self) -> dict:
        from experiments.core.noise import timing_noise
        return timing_noise(5, 0.005) if self.quick else timing_noise()

    def store(self, code: tuple = (), out=None) -> PointStore:
        """The point store of this run (``out``/points), keyed by ``code`` beside tracer/."""
        return PointStore(out or self.out, force=self.force, code=code, reuse_stale=self.reuse_stale,
                          ledger=self.ledger, ctx=self)

    def run_task(self, store: PointStore, fn, *args):
        """Measure ``fn(*args)`` through the run's executor (here, or as one Dask task on one worker)
        and return (result, provenance of the measurement: host and clock). A worker that measured
        with another measurement key than ``store``'s (other code, threads, clock, CPU) is refused."""
        from tracer.errors import GridcostError
        mine = store.measurement_key
        result, theirs, host = self.executor.run_task(fn, args, mine["threads"], store.code)
        prov = {"host": host, "clock": mine["clock"]}
        if theirs is not None:  # measured on a worker: the ledger hears of it here (the local clock did not)
            if theirs != mine:
                raise GridcostError(f"worker {host} measured with another measurement key ({theirs}) than this run "
                                    f"({mine}): same code, threads, clock and CPU needed")
            self.ledger.add(dict(self.ledger.now(), **prov))
        return result, prov

    # ------------------------------------------------------------ writers
    def write_csv(self, path, df: pd.DataFrame) -> Path:
        """Write ``df`` atomically; rows without provenance columns (``commit``, ``host``,
        ``clock``) get the values behind this target's numbers (the ledger); rows of a scene that is
        a stand-in for a mesh not found are marked (``stand_in``)."""
        missing = [c for c in PROVENANCE_COLUMNS if c not in df.columns]
        if missing:
            df = df.copy()
            vals = self.ledger.column_values()
            for c in missing:
                df[c] = vals[c]
        from tracer.settings import run_log
        used = run_log().stand_ins
        if "scene" in df.columns and "stand_in" not in df.columns:
            df = df.copy()
            df["stand_in"] = df.scene.map(lambda s: used.get(s, "")).fillna("")
        return atomic_write(path, df.to_csv(index=False))

    def write_meta(self, out_dir, target: str, started: float, **extra) -> Path:
        """meta.json: the commit that drew the file, versions, host, wall time, ``measured_by``: the
        distinct commits, hosts and clocks behind its numbers, and ``timing_noise``: the host's
        timing noise when the target started and now (:mod:`experiments.core.noise`)."""
        from tracer.measure.timing import host_info
        src = self.ledger.sources()
        meta = {"target": target, "git_commit": git_commit(), "versions": versions(), "host": host_info(),
                "wall_seconds": round(time.time() - started, 2),
                "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                "measured_by": {"commits": sorted({str(o["commit"]) for o in src}),
                                "hosts": sorted({str(o["host"]) for o in src}),
                                "clocks": sorted({str(o["clock"]) for o in src}), "sources": src,
                                "points_measured_now": self.ledger.measured, "points_reused": self.ledger.reused,
                                "stale_points_reused": self.ledger.stale},
                "executor": getattr(self.executor, "name", "local"),
                "timing_noise": {"start": self.noise_start, "end": self._noise()}, **extra}
        return write_json(Path(out_dir) / "meta.json", meta)

    def finish_figure(self, fig, name: str) -> list[Path]:
        """Lay out, save (PNG + PDF into this run's figure directory) and close ``fig``."""
        return finish_figure(fig, name, self.fig_dir)

    def mark_hosts(self, summary_path) -> None:
        """A summary built from points measured on several hosts says so."""
        hosts = sorted({str(o["host"]) for o in self.ledger.sources()})
        path = Path(summary_path)
        if len(hosts) > 1 and path.exists() and "## Hosts" not in path.read_text():
            atomic_write(path, path.read_text().rstrip("\n") + "\n\n## Hosts\n\nThe numbers above were measured on "
                         f"{len(hosts)} hosts ({', '.join(hosts)}); every curve's reference time is per host, so "
                         "curves never mix machines, but absolute times of different hosts are not comparable "
                         "(the `host` column of each CSV row says which measured it).\n")

    def mark_noise(self, out_dir) -> None:
        """Append to a target's summary.md the host's timing noise its meta.json recorded
        (:mod:`experiments.core.noise`), so a reader weighs its small differences against it."""
        import json
        path, meta_path = Path(out_dir) / "summary.md", Path(out_dir) / "meta.json"
        if not (path.exists() and meta_path.exists()) or "## Timing noise" in path.read_text():
            return
        tn = json.loads(meta_path.read_text()).get("timing_noise") or {}
        parts = [(w, tn[w]) for w in ("start", "end") if isinstance(tn.get(w), dict)]
        if not parts:
            return
        read = "; ".join(f"{w}: dependent loads {100 * v['memory_cv']:.1f} %, arithmetic {100 * v['compute_cv']:.1f} %"
                         for w, v in parts)
        atomic_write(path, path.read_text().rstrip("\n") + "\n\n## Timing noise\n\nCoefficient of variation of two "
                     f"fixed kernels timed back to back on this host ({parts[0][1]['samples']} samples each, "
                     f"`experiments/core/noise.py`) — {read}. About 1 % is a quiet host. Ray tracing waits on "
                     "loads: one sample of two equal points differs by about 1.4 times the loads' CV from noise "
                     "alone, and the medians of n samples by that over the square root of n (paired rounds "
                     "cancel slow drifts, not this).\n")

    def mark_stand_ins(self, summary_path) -> None:
        """Append to a target's summary.md which of its scenes are stand-ins for meshes not found."""
        from tracer.settings import run_log
        stand_ins = run_log().stand_ins
        path = Path(summary_path)
        if not stand_ins or not path.exists():
            return
        text = path.read_text()
        used = {k: v for k, v in stand_ins.items() if k in text}
        if not used or "## Stand-ins" in text:
            return
        atomic_write(path, text.rstrip("\n") + "\n\n## Stand-ins\n\n**These rows are not the real meshes:**\n\n"
                     + "".join(f"- `{k}`: {v}\n" for k, v in sorted(used.items())))

    def close(self) -> None:
        if hasattr(self.executor, "close"):
            self.executor.close()

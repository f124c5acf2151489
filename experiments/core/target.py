"""The preamble and epilogue the experiment targets share.

A target's ``run(ctx, args, log)`` starts with :func:`begin` (start the clock, set the threads, pick
the scene list: ``--scenes``, else the quick or the full default) and ends with
:meth:`TargetRun.finish` (its CSVs, ``summary.md``, the figure, ``meta.json``, then the summary on
``log``, in that order). ``main(ctx, args)`` is :func:`run_quiet` around ``run``. Nothing here goes
into a point's key or a measurement key: the targets build those as before.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from experiments.core.common import progress, scene_list
from experiments.core.store import atomic_write


@dataclass
class TargetRun:
    """One run of one target: its context, arguments, name (the folder under ``--out`` and the
    ``target`` of meta.json), thread count, scenes and start time."""
    ctx: object
    args: object
    name: str
    threads: int
    names: list
    started: float
    log: Callable = print

    @property
    def quick(self) -> bool:
        return self.args.quick

    @property
    def out_dir(self) -> Path:
        return Path(self.args.out) / self.name

    def pick(self, given, quick, full):
        """``given`` (a command-line value) when set, else the quick or the full default."""
        return given or (quick if self.quick else full)

    def ray_budget(self, quick_rays: int, full_rays: int) -> tuple[int, int]:
        """(rays per kind, sweep rounds per point): ``--rays`` or the quick or full default, and
        ``--repeats`` or 3 (quick) / 5 rounds."""
        return self.pick(self.args.rays, quick_rays, full_rays), self.pick(self.args.repeats, 3, 5)

    def scenes(self, desc: str | None = None):
        """(name, loaded scene) of every scene of the run, in order; with ``desc``, behind a progress
        bar (silent under ``--json``)."""
        from tracer.scenes.scene import load_scene
        names = self.names if desc is None else progress(self.names, desc, quiet=getattr(self.args, "json", False))
        for name in names:
            yield name, load_scene(name)

    def finish(self, md: str, csvs: dict, figure: Callable | None = None, **meta) -> None:
        """Write ``csvs`` (file name -> frame, in order) and ``summary.md`` into the target's folder,
        draw ``figure()``, write meta.json (``threads``, then ``meta``; ``scenes`` and ``quick`` last
        unless ``meta`` places them) and print ``md`` on ``log``."""
        for fname, df in csvs.items():
            self.ctx.write_csv(self.out_dir / fname, df)
        atomic_write(self.out_dir / "summary.md", md)
        if figure is not None:
            figure()
        meta = {"threads": self.threads, **meta}
        meta.setdefault("scenes", self.names)
        meta.setdefault("quick", self.quick)
        self.ctx.write_meta(self.out_dir, self.name, self.started, **meta)
        self.log(md)


def begin(ctx, args, name: str, scenes: tuple, threads=None, log: Callable = print) -> TargetRun:
    """Start target ``name``: the clock, :func:`tracer.measure.timing.set_threads` (``threads``; None: the
    library's default), the scenes (``scenes`` = (quick list, full list), ``--scenes`` first)."""
    from tracer.measure.timing import set_threads
    started = time.time()
    n = set_threads(threads)
    return TargetRun(ctx=ctx, args=args, name=name, threads=n, names=scene_list(args, *scenes), started=started,
                     log=log)


def kind_rays(scene, kinds, n: int, seed: int) -> dict:
    """``n`` rays of every kind in ``kinds`` (:func:`tracer.scenes.rays.make_rays`), kind -> rays."""
    from tracer.scenes.rays import make_rays
    return {k: make_rays(scene, k, n, seed=seed) for k in kinds}


def run_quiet(run: Callable, ctx, args) -> int:
    """A target's ``main``: ``run`` with the summary printed, or not under ``--json``."""
    run(ctx, args, log=(lambda *a: None) if args.json else print)
    return 0


def ensure_input(ctx, args, target: str, path: Path, log: Callable = print, **overrides) -> None:
    """Run ``target`` first when the output ``path`` a derived target reads is missing.

    The target is named, not imported: the runner's table (:data:`experiments.run.TARGETS`) resolves
    it, so no target module imports another. ``overrides`` replace arguments of this run (a derived
    target's own flags) with the input target's defaults."""
    if path.exists():
        return
    import argparse
    import importlib
    log(f"{path} missing: running {target} first")
    module = importlib.import_module(importlib.import_module("experiments.run").TARGETS[target][0])
    a = argparse.Namespace(**{**vars(args), "target": target, **overrides})
    if hasattr(module, "run"):
        module.run(ctx, a, log=log)
    else:
        module.main(ctx, a)

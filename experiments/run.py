"""The gridcost CLI: ``python -m experiments.run <target> [options]``.

One table of targets (``TARGETS``) maps a name to the module that implements it.
Every target module exposes ``add_arguments(parser)`` and ``main(ctx, args) -> int`` (``ctx``: the
run's :class:`experiments.core.context.RunContext`).
Bad input anywhere raises :class:`tracer.errors.GridcostError`; it is printed as one
line on stderr and the process exits with status 2. Any other exception is an internal
error: one line naming the target, exit status 1 (``--debug`` shows the traceback). Ctrl-C and
SIGTERM stop a run with one line (exit 130 / 143), its outputs put back as they were.
``all`` goes on after a failed target (targets are resumable), lists what failed and
exits non-zero.
"""
from __future__ import annotations

import argparse
import errno
import importlib
import os
import signal
import sys
import threading

# name -> (module, one-line help). Order is the dependency order used by `all`.
TARGETS: dict[str, tuple[str, str]] = {
    "verify": ("experiments.tools.verify", "trace with a structure and the float64 oracle; count disagreements"),
    "bench": ("experiments.tools.bench", "build time and Mrays/s of every structure beside Embree and trimesh"),
    "derive": ("experiments.ize.derive", "sympy derivations of every Ize 2007 cost model vs the paper"),
    "table2": ("experiments.ize.table2", "Ize Table 2: one-level grid, theoretical M vs best swept M"),
    "fit": ("experiments.ize.fit", "sweep one scene, fit Tsetup/Ts/Ti with CIs, choose the model, predict M"),
    "vtk-timings": ("experiments.tools.vtk_timings", "time VTK's uniform grid (vtkStaticCellLocator) to validate fit --timings on it"),
    "table4": ("experiments.ize.table4", "Ize Table 4: two-level grids, M1 = (8N)^0.6, M2 = 8N2 vs swept M1"),
    "ize-levels": ("experiments.ize.levels", "Ize Sec 4.3: three-level grids (Eq 16) vs two levels and the best one-level grid"),
    "ize-skinny2": ("experiments.ize.skinny2", "Ize Sec 4.4: two-level long-skinny rule (Eq 17) vs the compact rule on cylinders"),
    "fig2": ("experiments.ize.fig2", "Ize Fig 2: runtime against M with the fitted Eq 1 / Eq 5 curves"),
    "fig5": ("experiments.ize.fig5", "Ize Fig 5: two-level (m1, m2) factor plane, %% over best, theory point"),
    "wald-table1": ("experiments.wald.table1", "Wald 2006 Table 1: triangle tests with/without mailboxing and frustum culling"),
    "wald-table3": ("experiments.wald.table3", "Wald 2006 Table 3: single-ray grid vs 8x8/4x4 packets (fps, paired), macrocells, shadow packets"),
    "wald-table4": ("experiments.wald.table4", "Wald 2006 Table 4: cells visited and tests, single ray vs 4x4 vs 8x8"),
    "wald-fig8": ("experiments.wald.fig8", "Wald 2006 Fig 8: rebuild vs trace per frame on the largest mesh, trace time against model resolution"),
    "wald-lowres": ("experiments.wald.lowres", "packets at low resolution: CGT vs Embree vs single-ray grid against image side (paired), work per ray"),
    "wald-fig6": ("experiments.wald.fig6", "Wald 2006 Fig 6: render time against the grid resolution factor lambda"),
    "wald-fig7": ("experiments.wald.fig7", "Wald 2006 Fig 7: time against packet size for several model resolutions"),
    "fournier-table1": ("experiments.fournier.table1", "Fournier & Poulin 1993 Table 1: sorted lists vs a 30^3 grid"),
    "table1h": ("experiments.hapala.table1", "Hapala 2011 Table 1: grid vs kd-tree build/trace times and R_C per scene"),
    "fig1h": ("experiments.hapala.figs", "Hapala 2011 Fig 1: R_C estimate error against calibration scenes, random rays"),
    "fig2h": ("experiments.hapala.figs", "Hapala 2011 Fig 2: R_C estimate error against calibration scenes, path rays"),
    "selector": ("experiments.hapala.selector", "grid or kd-tree for a scene and a ray budget: the decision and its estimate"),
    "havran": ("experiments.hapala.havran", "Havran scene statistics from the grid (sparseness, maxRefs, moments)"),
    "exponents": ("experiments.ize.exponents", "fitted exponents M_best ∝ N^alpha per scene family, with CIs"),
    "predict": ("experiments.ize.predict", "cross-scene runtime prediction with the counter cost model (leave one out)"),
    "stability": ("experiments.ize.stability", "where each rule fails: penalty of 8N, 2N·Ti/Ts, 8N^1.5, pbrt, Wald's lambda against N and scene family"),
    "table3": ("experiments.ize.table3", "Ize Table 3: long skinny triangles (cylinders), M = 8N^1.5 vs swept"),
    "advise": ("experiments.tools.advise", "which structure to build for your mesh and ray budget: predicted build + trace times, pick, --check"),
    "advise-check": ("experiments.tools.advise_check", "advise on four meshes outside its calibration: pick vs measured best, predicted vs measured totals"),
    "certs": ("experiments.tools.certs", "a private CA and a node certificate for a TLS Dask sweep (--tls DIR)"),
    "scorecard": ("experiments.tools.scorecard", "every paper claim beside ours with a verdict (reproduced, explained, contradicted, not measurable), from the paper data and results/"),
    "models": ("experiments.tools.models", "every named scene: faces, where it was found or how to get it, licence"),
}

#: targets that `all` runs, in order
ALL_ORDER = ["derive", "table2", "table3", "table4", "ize-levels", "ize-skinny2", "fig2", "fig5", "exponents", "stability",
             "table1h", "fig1h", "fig2h", "predict", "selector", "havran", "wald-table1", "wald-table3", "wald-table4",
             "wald-fig6", "wald-fig7", "wald-fig8", "wald-lowres",
             "fournier-table1", "advise-check", "scorecard"]


#: target -> the targets whose outputs it reads; `all --jobs` starts it only after they have finished
#: (the scorecard reads every result, so it runs last)
READS = {"fig2": ("table2", "table3"), "fig1h": ("table1h",), "fig2h": ("table1h",), "selector": ("table1h",),
         "havran": ("table1h",), "stability": ("exponents",), "predict": ("table2", "table3", "exponents", "fig1h"),
         "scorecard": tuple(t for t in ALL_ORDER if t != "scorecard")}
#: targets `all --jobs` runs with no neighbour (:mod:`experiments.core.lanes`). advise-check: its
#: results are absolute times measured minutes apart (a probe against the truth), which a target
#: running beside it shifts. wald-lowres: its goals are the packets' throughput over Embree's, timed
#: in interleaved rounds, but the packet loop waits on memory and a neighbour's traffic slowed it more
#: than Embree (same commit, 2-core EPYC host, CGT/Embree beside another target and alone: bunny-69k
#: 1.17 and 1.24 at 512^2, 1.55 and 1.91 at 1024^2; fandisk-x16 0.83 and 1.01, 1.51 and 1.76). Not
#: wald-table3: its 8x8/single-ray ratios came out the same beside and alone (2.14-5.13, 2.04-4.80).
ALONE = frozenset({"advise-check", "wald-lowres"})


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--models", default=None,
                   help="models directory searched first (default: $GRIDCOST_MODELS; then ../shared/models, the "
                        "meshes shipped in tracer/data, the user cache, a download; `models` lists them)")
    p.add_argument("--threads", type=int, default=None, help="Numba threads (default: all cores)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    p.add_argument("--out", default=None, help="results directory (default: results; a --quick or otherwise "
                                                 "reduced run: results/quick, so the committed results stay)")
    p.add_argument("--quick", action="store_true", help="fewer rays and sweep points (CI, first contact)")
    p.add_argument("--force", action="store_true", help="redo sweep points already stored")
    p.add_argument("--reuse-stale", action="store_true",
                   help="use stored points measured under another measurement key (other code, threads, clock "
                        "or CPU); their rows are marked stale")
    p.add_argument("--allow-dirty", action="store_true",
                   help="let `all` write into the default results/ from a tree with uncommitted changes (recorded)")
    p.add_argument("--debug", action="store_true", help="show the traceback of an internal error")
    p.add_argument("--dask", default=None, metavar="ADDRESS",
                   help="send sweep points to a Dask scheduler (tls://host:8786 with --tls; tcp:// on loopback; "
                        "'local' for a LocalCluster of 2 worker processes)")
    p.add_argument("--tls", default=None, metavar="DIR",
                   help="certificate folder for mutual TLS with the Dask scheduler (made by `gridcost certs`)")
    p.add_argument("--insecure", action="store_true",
                   help="allow a plain tcp:// scheduler beyond loopback: anyone who reaches its port can run code "
                        "on every worker")


class _Parser(argparse.ArgumentParser):
    """argparse with the CLI's rule for bad input: one line on stderr, exit status 2 (the stock
    parser prints its usage block first)."""

    def error(self, message):
        self.exit(2, f"error: {self.prog}: {message} (--help lists the options)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="gridcost", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="target", required=True, metavar="target")
    for name, (modname, helptext) in list(TARGETS.items()) + [("all", ("", "every target in dependency order"))]:
        p = sub.add_parser(name, help=helptext, description=helptext)
        _common(p)
        if modname:
            importlib.import_module(modname).add_arguments(p)
        else:
            p.add_argument("--jobs", type=int, default=1,
                           help="targets run side by side, each in its own process on one core (default 1; at most "
                                "this host's CPUs): a point two targets need is measured once")
    return parser


#: every numeric option's range: dest -> (lowest, highest); None is unbounded. --threads is checked
#: against this host's CPUs (:func:`_check_settings`).
RANGES = {"seed": (0, None), "repeats": (1, 1000), "rays": (1, 1e10), "side": (1, 16384), "packet": (1, 64),
          "grid_factor": (1e-6, 1e6), "trimesh_rays": (0, 1e8), "splits": (1, 1e6), "sample_rays": (1, 1e8),
          "res": (1, 4096), "reps": (1, 1000), "nogrid_max": (0, None), "leaf_size": (1, 1024), "lam": (1e-6, 1e6),
          "flat_max": (0, None), "eps": (0, 10), "branching": (2, 64), "around_res": (1, 4096)}


def _check_settings(args) -> str | None:
    """The first setting out of its range, as one line (None when all are fine)."""
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    for dest in ("threads", "jobs"):
        v = getattr(args, dest, None)
        if v is not None and not 1 <= v <= cpus:
            return f"--{dest} must be between 1 and {cpus} (this host's CPUs), got {v}"
    if getattr(args, "jobs", 1) > 1 and (getattr(args, "dask", None) or (args.threads or 1) > 1):
        return "--jobs runs targets side by side on one core each: not with --dask or --threads above 1"
    for dest, (lo, hi) in RANGES.items():
        v = getattr(args, dest, None)
        if v is None:
            continue
        if v != v or (lo is not None and v < lo) or (hi is not None and v > hi):
            span = f"at least {lo:g}" if hi is None else f"between {lo:g} and {hi:g}"
            return f"--{dest.replace('_', '-')} must be {span}, got {v:g}"
    if getattr(args, "models", None) and not os.path.isdir(args.models):  # else every scene falls through to stand-ins
        return f"--models must be a folder of meshes, got {args.models!r}"
    return None


def _default_out(args) -> str:
    """``results``, or ``results/quick`` for a reduced run of a paper target (``--quick``, or its
    scenes, rays or repeats cut): a reduced sweep never overwrites the committed full results. Says
    where it goes."""
    reduced = getattr(args, "quick", False) or (
        args.target in set(ALL_ORDER) | {"all"} and any(getattr(args, k, None) for k in ("scenes", "rays", "repeats")))
    if not reduced:
        return "results"
    print("gridcost: a reduced run writes to results/quick (the committed results/ stay as they are; "
          "--out results overwrites them)", file=sys.stderr)
    return os.path.join("results", "quick")


def _refuse_dirty(ctx, args) -> None:
    """``all`` into the default results/ must come from a clean commit (or say it did not)."""
    from experiments.core.store import REPO, git_commit
    from tracer.errors import GridcostError
    if ctx.out.resolve() != (REPO / "results").resolve():
        return
    commit = git_commit()
    if commit.endswith("-dirty") and not args.allow_dirty:
        raise GridcostError(f"the tree has uncommitted changes ({commit}): commit them before `all` writes the "
                            f"committed results/, or pass --allow-dirty (recorded in every meta.json)")


def _run_target(name: str, ctx, args) -> int:
    """One target with a fresh ledger; its summary marks stand-ins; the results index is rewritten."""
    from experiments.core.store import OutputGuard, write_index
    ctx.start_target()
    with OutputGuard(ctx.out / name, ctx.fig_dir, name) as guard:  # a failed run leaves the folder as it was
        module = importlib.import_module(TARGETS[name][0])
        rc = module.main(ctx, args)
        # a whole-folder target's files that this run did not write are an earlier run's; the per-scene
        # targets (KEEPS_EARLIER_FILES) add to their folder, one scene or variant a run
        if rc == 0 and not getattr(module, "KEEPS_EARLIER_FILES", False):
            guard.drop_stale()
    ctx.mark_stand_ins(ctx.out / name / "summary.md")
    ctx.mark_hosts(ctx.out / name / "summary.md")
    ctx.mark_noise(ctx.out / name)
    if name != "verify" and ctx.out.is_dir():
        write_index(ctx.out, ctx.fig_dir)
    return rc


def _sub_argv(name: str, args) -> list[str]:
    """The command line of one target of `all` (`all`'s flags passed on)."""
    flags = [f for f in ("quick", "force", "reuse_stale", "allow_dirty", "debug") if getattr(args, f, False)]
    return ([name, "--out", args.out] + [f"--{f.replace('_', '-')}" for f in flags]
            + (["--threads", str(args.threads)] if args.threads else [])
            + (["--models", args.models] if args.models else []))


def _sub_args(name: str, args) -> argparse.Namespace:
    return build_parser().parse_args(_sub_argv(name, args))


#: errors of an output path that cannot be written (read-only disk, no permission, a file in the way)
_UNWRITABLE = (errno.EROFS, errno.EACCES, errno.EPERM, errno.ENOTDIR, errno.EISDIR, errno.EEXIST)


class Interrupted(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C's KeyboardInterrupt so that every open output guard puts its
    folder back (:class:`experiments.core.store.OutputGuard`)."""


def _on_term(signum, frame):
    raise Interrupted()


def _failure(name: str, exc: BaseException, debug: bool) -> int:
    """One line on stderr for a failed target; 2 for bad input, 1 for an internal error."""
    from tracer.errors import GridcostError
    if debug:
        import traceback
        traceback.print_exception(exc)
    if isinstance(exc, GridcostError):
        print(f"error: {name}: {exc}", file=sys.stderr)
        return 2
    if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT):
        where = f" writing {exc.filename}" if exc.filename else ""
        print(f"error: {name}: no space left on the device{where} ({exc.strerror}); free space or pass --out "
              f"on another disk", file=sys.stderr)
        return 2
    if isinstance(exc, OSError) and exc.errno in _UNWRITABLE and exc.filename:
        print(f"error: {name}: {exc.strerror}: {exc.filename} (is --out a folder you can write?)", file=sys.stderr)
        return 2
    first = str(exc).splitlines()[0] if str(exc) else ""
    print(f"internal error in {name}: {type(exc).__name__}: {first} (--debug shows the traceback)", file=sys.stderr)
    return 1


def main(argv: list[str] | None = None) -> int:
    """Parse the command line, build the one :class:`RunContext`, run the target (or all).
    Ctrl-C or SIGTERM: one line, the outputs as before the run (exit 130 or 143)."""
    from tracer.errors import GridcostError
    try:
        parser = build_parser()  # imports the targets, which read GRIDCOST_* settings
    except GridcostError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    args = parser.parse_args(argv)
    old = signal.signal(signal.SIGTERM, _on_term) if threading.current_thread() is threading.main_thread() else None
    try:
        return _main(args)
    except KeyboardInterrupt as exc:
        term = isinstance(exc, Interrupted)
        print(f"gridcost {args.target}: {'terminated' if term else 'interrupted'}; its outputs are as before the "
              f"run, and running it again resumes from the points stored so far", file=sys.stderr)
        return 143 if term else 130
    finally:
        if old is not None:
            signal.signal(signal.SIGTERM, old)


def _main(args) -> int:
    bad = _check_settings(args)
    if bad:
        print(f"error: {args.target}: {bad}", file=sys.stderr)
        return 2
    if args.out is None:
        args.out = _default_out(args)
    try:
        from tracer import settings as settings_mod
        settings = settings_mod.Settings.from_env()  # the one read of the environment
        if args.models:
            settings = settings.replace(models=args.models)
        if getattr(args, "dask", None):  # see DaskExecutor: a Dask run times client and workers with wall time
            settings = settings.replace(clock="wall")
        with settings_mod.use(settings):
            return _run(args, settings)
    except Exception as exc:
        return _failure(args.target, exc, args.debug)


def _run(args, settings) -> int:
    """The target (or all) of ``args`` inside the run's settings."""
    ctx = None
    try:
        if args.threads:
            from tracer.measure.timing import set_threads
            set_threads(args.threads)
        from experiments.core.context import RunContext
        ctx = RunContext.from_args(args, settings)
        if args.target != "all":
            return _run_target(args.target, ctx, args)
        _refuse_dirty(ctx, args)
        if args.jobs > 1:
            return _run_lanes(ctx, args)
        failed = {}
        from experiments.core.common import expected_seconds, overall_progress
        bar = overall_progress(expected_seconds(args.out, ALL_ORDER, args.quick), quiet=getattr(args, "json", False))
        for i, name in enumerate(ALL_ORDER):
            bar.start(name)
            try:
                rc = _run_target(name, ctx, _sub_args(name, args))
                if rc:
                    failed[name] = rc
            except Exception as exc:
                failed[name] = _failure(name, exc, args.debug)
            bar.advance(name, ALL_ORDER[i + 1] if i + 1 < len(ALL_ORDER) else None)
        bar.close()
        return _all_status(failed)
    except Exception as exc:
        return _failure(args.target, exc, args.debug)
    finally:
        if ctx is not None:
            ctx.close()


def _run_lanes(ctx, args) -> int:
    """`all --jobs N`: the targets in N lane processes, side by side (:mod:`experiments.core.lanes`)."""
    from experiments.core.common import expected_seconds
    from experiments.core.lanes import run_lanes
    from experiments.core.store import write_index
    status = run_lanes(ALL_ORDER, READS, lambda t: _sub_argv(t, args), args.jobs,
                       expected_seconds(args.out, ALL_ORDER, args.quick), alone=ALONE)
    if ctx.out.is_dir():  # the children each rewrote it; once more with every folder in place
        write_index(ctx.out, ctx.fig_dir)
    return _all_status({k: v for k, v in status.items() if v})


def _all_status(failed: dict) -> int:
    """`all`'s exit status: 0, or the worst of the failed targets' after one line naming them."""
    if not failed:
        return 0
    print(f"all: {len(failed)} of {len(ALL_ORDER)} targets failed: "
          + ", ".join(f"{k} (exit {v})" for k, v in failed.items()), file=sys.stderr)
    return max(failed.values())


def cli() -> None:
    """The ``gridcost`` console command (same as ``python -m experiments.run``)."""
    sys.exit(main())


if __name__ == "__main__":
    cli()

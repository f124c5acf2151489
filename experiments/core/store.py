"""Atomic, resumable result storage: files written atomically, the point store keyed by the
measurement key, and the ledger of who measured the numbers a target writes.

* Every file is written to a temporary file in the same directory and renamed into place, so a
  killed run never leaves a half-written file.
* :class:`PointStore` keeps one small JSON file per sweep point (``results/<target>/points/``);
  rerunning a target skips points already stored (``--force`` redoes them).
"""
from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import socket
import subprocess
import sys
import time
from importlib import metadata
from pathlib import Path

from tracer.storage import atomic_write  # noqa: F401 (the one atomic write, re-exported for targets)


REPO = Path(__file__).resolve().parents[2]


def write_json(path, obj) -> Path:
    return atomic_write(path, json.dumps(obj, indent=2, default=_jsonable) + "\n")


def _jsonable(x):
    try:
        return float(x)
    except (TypeError, ValueError):
        return str(x)


def git_commit() -> str:
    """Short commit of the working tree, with ``-dirty`` when tracked code (anything but the outputs
    results/ and paper_figs/) differs from it."""
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True,
                             text=True, timeout=10)
        # outputs (results/, paper_figs/) do not make the code dirty: a run writes them as it goes
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", ".",
                                ":(exclude)results", ":(exclude)paper_figs"], cwd=REPO,
                               capture_output=True, text=True, timeout=10).stdout.strip()
        return out.stdout.strip() + ("-dirty" if dirty else "") if out.returncode == 0 else "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def versions() -> dict:
    out = {}
    for pkg in ("numpy", "numba", "llvmlite", "scipy", "sympy", "pandas", "trimesh", "matplotlib", "embreex"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = None
    return out


# ---------------------------------------------------------------- provenance of the numbers a target writes
#: the provenance columns every CSV row carries
PROVENANCE_COLUMNS = ("commit", "host", "clock")
#: columns that name a commit or host: always text (an abbreviated hash may be all digits, or read
#: as a number in scientific notation: "1234e56")
TEXT_COLUMNS = PROVENANCE_COLUMNS + ("source_commit", "worker")


def read_csv(path):
    """A results CSV, its provenance columns (:data:`TEXT_COLUMNS`) read as text."""
    import pandas as pd
    return pd.read_csv(path, dtype={c: str for c in TEXT_COLUMNS})


class Ledger:
    """Who measured the numbers a target writes: the provenance of every stored point it served or
    stored, and whether it timed anything itself in this run. The run context
    (:class:`experiments.core.context.RunContext`) holds one, resets it before each target and reads
    it when it writes a CSV or meta.json."""

    def __init__(self):
        self.reset()

    def reset(self) -> None:
        from tracer.measure.timing import timing_calls
        self.served: dict[tuple, int] = {}
        self.stale = 0
        self.reused = 0
        self.measured = 0
        self._timing_calls0 = timing_calls()
        self._now: dict | None = None

    def now(self) -> dict:
        """Provenance of a measurement made now (commit read once per target run)."""
        if self._now is None:
            from tracer.measure.provenance import host
            from tracer.measure.timing import clock_name
            self._now = {"commit": git_commit(), "host": host(), "clock": clock_name()}
        return dict(self._now)

    def add(self, prov: dict, stale: bool = False) -> None:
        k = tuple(prov.get(c) for c in PROVENANCE_COLUMNS)
        self.served[k] = self.served.get(k, 0) + 1
        self.stale += bool(stale)

    def timed_now(self) -> bool:
        from tracer.measure.timing import timing_calls
        return timing_calls() > self._timing_calls0

    def sources(self) -> list[dict]:
        """Distinct (commit, host, clock) behind this target's numbers, with point counts."""
        out = [dict(zip(PROVENANCE_COLUMNS, k), points=n) for k, n in self.served.items()]
        if self.timed_now():
            now = self.now()
            if not any(all(o[c] == now[c] for c in PROVENANCE_COLUMNS) for o in out):
                out.append(dict(now, points=0))
        return out

    def column_values(self) -> dict:
        """The value of each provenance column for a row that does not carry its own: the distinct
        values behind the file joined by ';' (one value when one commit measured everything)."""
        src = self.sources()
        if not src:  # counts or derived numbers computed now, no timing (inputs: see meta.json)
            return dict(self.now(), clock="none (no timing in this file)")
        return {c: ";".join(sorted({str(o[c]) for o in src})) for c in PROVENANCE_COLUMNS}


class PointStore:
    """One JSON file per measured point, named by the point's parameters and holding the
    measurement key (:func:`tracer.measure.timing.measurement_key`: code digest, threads, clock, CPU,
    library versions) and the provenance (commit, host, clock, time) of the measurement.

    A stored point whose key differs from the current one (other code, threads, clock, CPU) is
    measured again; with ``reuse_stale`` it is used and its rows are marked ``stale``. ``code`` names
    the experiment/cost-model files (repository-relative) that shape the point, beside ``tracer/``
    which is always in the key."""

    DEFAULT_CODE = ("experiments/core/point.py", "experiments/core/sweep.py", "experiments/core/executor.py")

    def __init__(self, directory, force: bool = False, code: tuple = (), reuse_stale: bool = False,
                 ledger: "Ledger | None" = None, ctx=None):
        self.dir = Path(directory) / "points"
        self.force = force
        self.reuse_stale = reuse_stale
        self.ledger = ledger if ledger is not None else Ledger()
        #: the run context this store belongs to (sweeps read its quick flag, executor, reference cache)
        self.ctx = ctx
        self.code = tuple(sorted(set(self.DEFAULT_CODE) | set(code)))
        self._fresh: set[str] = set()  # points measured by this run (visible even with --force)

    @property
    def measurement_key(self) -> dict:
        from tracer.measure.timing import measurement_key
        return measurement_key(self.code)

    @staticmethod
    def key(params: dict) -> str:
        return hashlib.sha1(json.dumps(params, sort_keys=True, default=str).encode()).hexdigest()[:16]

    def _read(self, params: dict):
        p = self.dir / f"{self.key(params)}.json"
        if not p.exists():
            return None
        try:
            rec = json.loads(p.read_text())
        except (OSError, ValueError) as exc:
            return self._set_aside(p, f"unreadable ({type(exc).__name__})")
        if not (isinstance(rec, dict) and {"value", "key", "provenance"} <= set(rec)):
            return self._set_aside(p, "not a gridcost point (no value, key and provenance)")
        if "sha" not in rec:  # stored before points had a checksum: stale, as from other code
            rec["key"] = None
        elif rec["sha"] != _value_sha(rec["value"]):  # changed since it was stored
            return self._set_aside(p, "altered (its value does not match the checksum it was stored with)")
        return rec

    def _set_aside(self, path: Path, why: str) -> None:
        """Move a bad point file to ``points/set-aside/`` (kept for a look, never deleted), say so in
        one line, and let the point be measured again."""
        aside = self.dir / "set-aside"
        aside.mkdir(parents=True, exist_ok=True)
        dest = aside / f"{path.stem}.{time.strftime('%Y%m%dT%H%M%S')}{path.suffix}"
        os.replace(path, dest)
        print(f"gridcost: stored point {path} is {why}: moved to {dest}, measuring it again", file=sys.stderr)
        return None

    def record(self, params: dict, ignore_force: bool = False):
        """The stored record ``{value, key, provenance, stale}`` for ``params``, or None when it
        must be measured (missing, ``--force``, or stale without ``reuse_stale``)."""
        k = self.key(params)
        if self.force and not ignore_force and k not in self._fresh:
            return None
        rec = self._read(params)
        if rec is None:
            return None
        stale = rec.get("key") != self.measurement_key
        if stale and not self.reuse_stale and k not in self._fresh:
            return None
        rec["stale"] = bool(stale)
        return rec

    def get(self, params: dict, ignore_force: bool = False):
        rec = self.record(params, ignore_force)
        if rec is None:
            return None
        if self.key(params) not in self._fresh:  # a point stored in this run is in the ledger already
            self.ledger.reused += 1
            self.ledger.add(rec.get("provenance") or {}, stale=rec["stale"])
        return rec["value"]

    def provenance(self, params: dict) -> dict:
        """Provenance columns of a stored point (``stale`` added): ``commit``, ``host``, ``clock``."""
        rec = self.record(params, ignore_force=True) or {}
        prov = rec.get("provenance") or {}
        return {**{c: prov.get(c) for c in PROVENANCE_COLUMNS}, "stale": bool(rec.get("stale"))}

    @contextlib.contextmanager
    def claim(self, params: dict):
        """Hold the point ``params`` while it is looked up, measured and stored: targets that `all
        --jobs` runs side by side share the store, and one that needs a point another is measuring
        waits for it and then reads it, so a shared point is measured once (an advisory ``flock`` on
        ``points/locks/<key>.lock``; the kernel drops it if the holder dies)."""
        locks = self.dir / "locks"
        locks.mkdir(parents=True, exist_ok=True)
        with open(locks / f"{self.key(params)}.lock", "a") as f:
            fcntl.flock(f, fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(f, fcntl.LOCK_UN)

    def put(self, params: dict, value, provenance: dict | None = None) -> dict:
        """Store ``value`` measured now (or by ``provenance``, e.g. a Dask worker's host)."""
        k = self.key(params)
        prov = {**self.ledger.now(), **(provenance or {}), "measured": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
        write_json(self.dir / f"{k}.json", {"key": self.measurement_key, "provenance": prov, "value": value,
                                            "sha": _value_sha(value)})
        self._fresh.add(k)
        self.ledger.measured += 1
        self.ledger.add(prov)
        return value

    def measure(self, params: dict, fn, *args) -> tuple[dict, bool]:
        """Stored row for ``params``, or ``fn(*args)`` measured now and stored: through the run's
        executor when the store belongs to a run (one task: here, or on one Dask worker; ``fn`` must
        then be a module-level function). Returns (row, was_cached)."""
        with self.claim(params):
            row = self.get(params)
            if row is not None:
                return row, True
            if self.ctx is None:
                return self.put(params, fn(*args)), False
            value, prov = self.ctx.run_task(self, fn, *args)
            return self.put(params, value, provenance=prov), False


def _measured_by(folder: Path) -> str:
    """"commit(s), CPU(s), date[, timing CV]" of a target's folder: from its meta.json, or, for targets
    that write one JSON per run instead (bench, verify), from every JSON of the folder naming a commit;
    – when none does."""
    from experiments.core.noise import worst_cv
    paths = [folder / "meta.json"] if (folder / "meta.json").is_file() else sorted(folder.glob("*.json"))
    metas = [m for m in (json.loads(p.read_text()) for p in paths) if isinstance(m, dict) and m.get("git_commit")]
    if not metas:
        return "–"
    commits = sorted({f"`{m['git_commit']}`" for m in metas})
    cpus = sorted({str((m.get("host") or {}).get("cpu") or "?") for m in metas})
    when = max(str(m.get("finished") or "")[:10] for m in metas)
    cvs = [c for c in map(worst_cv, metas) if c is not None]
    noise = f"timing CV {100 * max(cvs):.1f} %" if cvs else ""
    return ", ".join(v for v in (*commits, *cpus, when, noise) if v)


def write_index(out_dir, fig_dir) -> Path:
    """<out>/README.md: a link to every target's summary, data and figure present on disk."""
    out_dir, figs = Path(out_dir), Path(fig_dir)
    lines = ["# Results", "", "Output of the last run of each target (`python -m experiments.run <target>`). "
             "Each folder holds tidy CSV (one row per measurement), `summary.md` (ours beside the paper) and "
             "`meta.json` (commit, versions, CPU, threads, seeds, wall time); the last column names the commit "
             "and CPU that measured it (folders of one results/ may come from different runs and hosts) and, "
             "where recorded, the host's timing noise during the run (the larger coefficient of variation of "
             "two fixed kernels timed back to back at its start and end: `experiments/core/noise.py`).", "",
             "| target | summary | data | figure | measured by |", "|---|---|---|---|---|"]
    for d in sorted(p for p in out_dir.iterdir() if p.is_dir() and p.name != "points"):
        summ = d / "summary.md"
        csvs = sorted(d.glob("*.csv")) + sorted(d.glob("*.json"))
        fig = sorted(f for f in figs.glob(f"{d.name}*.p[nd][gf]") if f.stem == d.name or f.stem.startswith(d.name + "_"))
        lines.append(f"| {d.name} | {f'[summary.md]({d.name}/summary.md)' if summ.exists() else '–'} | "
                     + (", ".join(f"[{c.name}]({d.name}/{c.name})" for c in csvs) or "–") + " | "
                     + (", ".join(f"[{f.name}]({os.path.relpath(f, out_dir)})" for f in fig) or "–") + " | "
                     + _measured_by(d) + " |")
    return atomic_write(out_dir / "README.md", "\n".join(lines) + "\n")


def _alive(pid, host) -> bool:
    """Is process ``pid`` of this host running (a snapshot's maker still at work)?"""
    if not isinstance(pid, int) or host != socket.gethostname() or pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    return True


def _value_sha(value) -> str:
    """The checksum a point is stored with: a value that no longer matches it was changed after the
    measurement (by hand, or by other code) and is measured again rather than reused."""
    as_read = json.loads(json.dumps(value, default=_jsonable))  # as a reader sees it (str keys, floats)
    return hashlib.sha1(json.dumps(as_read, sort_keys=True).encode()).hexdigest()


class OutputGuard:
    """A target's outputs as they were before its run, put back if the run fails.

    On entry every file of ``folder`` and every ``fig_dir/<name>.*`` is hard-linked into a hidden
    folder beside it (no bytes copied, so it works on a full disk; atomic writes give the new files
    new inodes, so the links keep the old contents). On an exception the run's files are removed and
    the old ones put back; on success the links are dropped. :meth:`drop_stale` removes, after a
    successful run, the files the run did not rewrite (still the snapshot's inode): an earlier run's
    outputs (an optional flag's, a renamed file's) are not kept beside this run's as if it made them.
    A run killed outright (SIGKILL, power loss) leaves the snapshot with its ``complete`` marker
    (what it held); the next run on the folder puts it back first."""

    def __init__(self, folder: Path, fig_dir: Path | None = None, name: str = ""):
        self.folder, self.fig_dir, self.name = Path(folder), fig_dir, name or Path(folder).name
        self.keep = self.folder.parent / f".{self.folder.name}.before"

    def _figs(self) -> list:
        return sorted(self.fig_dir.glob(f"{self.name}.*")) if self.fig_dir is not None and self.fig_dir.is_dir() else []

    def __enter__(self):
        import shutil
        try:  # a run killed while guarded (SIGKILL, power loss) left its snapshot: put it back first
            before = json.loads((self.keep / "complete").read_text())
        except (OSError, ValueError):  # none, or a snapshot cut short (the folder was not touched yet)
            before = None
        if before is not None and _alive(before.get("pid"), before.get("host")):
            from tracer.errors import GridcostError
            raise GridcostError(f"{self.folder} is being written by another gridcost run (pid {before['pid']}); "
                                f"wait for it, or remove {self.keep} if no such run is going")
        if before is not None:
            self._put_back(before["folder"], before["figs"])
            print(f"gridcost: {self.folder} put back as it was before an interrupted run", file=sys.stderr)
        shutil.rmtree(self.keep, ignore_errors=True)
        self.made_parent = not self.keep.parent.exists()  # removed again if the run leaves it empty
        self.had_folder = self.folder.is_dir()
        self.old_figs = {}
        try:
            if self.had_folder:
                shutil.copytree(self.folder, self.keep / "folder", copy_function=os.link)
            for f in self._figs():
                (self.keep / "figs").mkdir(parents=True, exist_ok=True)
                os.link(f, self.keep / "figs" / f.name)
                self.old_figs[f.name] = f
            self.keep.mkdir(parents=True, exist_ok=True)  # the snapshot is whole: a later run may put it back
            write_json(self.keep / "complete", {"folder": self.had_folder, "figs": sorted(self.old_figs),
                                                "pid": os.getpid(), "host": socket.gethostname()})
        except OSError:  # no snapshot (a filesystem without hard links): the run goes ahead unguarded
            shutil.rmtree(self.keep, ignore_errors=True)
            self.had_folder, self.old_figs, self.keep = None, {}, None
        return self

    def _put_back(self, had_folder: bool, old_figs: list) -> None:
        """The folder and the ``<name>.*`` figures as before the run (``old_figs``: the figures'
        names); the run's own are removed. What is no longer in the snapshot was put back already
        (a put-back cut short is finished by the next run)."""
        import shutil
        if not (had_folder and not (self.keep / "folder").is_dir()):  # else: moved back already
            shutil.rmtree(self.folder, ignore_errors=True)
            if had_folder:
                os.replace(self.keep / "folder", self.folder)
        for f in self._figs():
            if f.name not in old_figs:
                f.unlink()
        for nm in old_figs:
            if (self.keep / "figs" / nm).exists():
                os.replace(self.keep / "figs" / nm, self.fig_dir / nm)

    def drop_stale(self) -> list[Path]:
        """Remove the folder's files and the ``<name>.*`` figures this run did not rewrite (every
        output is written atomically, so a rewritten file is a new inode); returns them."""
        if self.keep is None or not self.had_folder and not self.old_figs:
            return []
        pairs = [(f, self.folder / f.relative_to(self.keep / "folder"))
                 for f in (self.keep / "folder").rglob("*") if f.is_file()] if self.had_folder else []
        pairs += [(self.keep / "figs" / nm, f) for nm, f in self.old_figs.items()]
        gone = [p for old, p in pairs if p.is_file() and os.path.samefile(old, p)]
        for p in gone:
            p.unlink()
        return gone

    def __exit__(self, exc_type, exc, tb):
        import shutil
        if self.keep is None:
            return False
        if exc_type is not None and self.had_folder is not None:
            self._put_back(self.had_folder, list(self.old_figs))
        (self.keep / "complete").unlink(missing_ok=True)  # first: a kill from here on keeps this run's outputs
        shutil.rmtree(self.keep, ignore_errors=True)
        if self.made_parent and self.keep.parent.is_dir() and not any(self.keep.parent.iterdir()):  # no empty --out
            self.keep.parent.rmdir()
        return False

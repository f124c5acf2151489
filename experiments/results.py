"""Atomic, resumable result storage and the writers every target shares.

* Every file is written to a temporary file in the same directory and renamed into place, so a
  killed run never leaves a half-written file.
* :class:`PointStore` keeps one small JSON file per sweep point (``results/<target>/points/``);
  rerunning a target skips points already stored (``--force`` redoes them).
"""
from __future__ import annotations

import hashlib
import json
import os
import subprocess
import tempfile
import time
from importlib import metadata
from pathlib import Path

import pandas as pd

REPO = Path(__file__).resolve().parents[1]


def atomic_write(path, data: str | bytes) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data.encode() if isinstance(data, str) else data)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def write_json(path, obj) -> Path:
    return atomic_write(path, json.dumps(obj, indent=2, default=_jsonable) + "\n")


def write_csv(path, df: pd.DataFrame) -> Path:
    return atomic_write(path, df.to_csv(index=False))


def _jsonable(x):
    try:
        return float(x)
    except (TypeError, ValueError):
        return str(x)


#: where figures go: the repo's paper_figs/ for the default results directory, else <out>/paper_figs
#: (so a run with ``--out /tmp/x`` never overwrites the committed figures); set by :func:`set_output`
FIG_DIR: Path | None = None


def set_output(out) -> Path:
    """Point :func:`save_figure` at the figures directory that belongs to results directory ``out``."""
    global FIG_DIR
    out = Path(out).resolve()
    FIG_DIR = REPO / "paper_figs" if out == (REPO / "results").resolve() else out / "paper_figs"
    return FIG_DIR


def save_figure(fig, name: str, out_dir=None) -> list[Path]:
    """Save ``fig`` as <figures dir>/<name>.png and .pdf (atomically); see :func:`set_output`."""
    import io
    out_dir = Path(out_dir) if out_dir else (FIG_DIR or REPO / "paper_figs")
    paths = []
    for ext in ("png", "pdf"):
        buf = io.BytesIO()
        fig.savefig(buf, format=ext, dpi=150, bbox_inches="tight")
        paths.append(atomic_write(out_dir / f"{name}.{ext}", buf.getvalue()))
    return paths


def finish_figure(fig, name: str) -> list[Path]:
    """Lay out ``fig``, save it (:func:`save_figure`) and close it."""
    import matplotlib.pyplot as plt
    fig.tight_layout()
    paths = save_figure(fig, name)
    plt.close(fig)
    return paths


def git_commit() -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True,
                             text=True, timeout=10)
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=REPO,
                               capture_output=True, text=True, timeout=10).stdout.strip()
        return out.stdout.strip() + ("-dirty" if dirty else "") if out.returncode == 0 else "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def versions() -> dict:
    out = {}
    for pkg in ("numpy", "numba", "scipy", "sympy", "pandas", "trimesh", "matplotlib", "embreex"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = None
    return out


def write_meta(out_dir, target: str, started: float, **extra) -> Path:
    from tracer.timing import host_info
    meta = {"target": target, "git_commit": git_commit(), "versions": versions(), "host": host_info(),
            "wall_seconds": round(time.time() - started, 2),
            "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"), **extra}
    return write_json(Path(out_dir) / "meta.json", meta)


class PointStore:
    """One JSON file per measured point, keyed by the point's parameters."""

    def __init__(self, directory, force: bool = False):
        self.dir = Path(directory) / "points"
        self.force = force
        self._fresh: set[str] = set()  # points measured by this run (visible even with --force)

    @staticmethod
    def key(params: dict) -> str:
        return hashlib.sha1(json.dumps(params, sort_keys=True, default=str).encode()).hexdigest()[:16]

    def get(self, params: dict, ignore_force: bool = False):
        key = self.key(params)
        if self.force and not ignore_force and key not in self._fresh:
            return None
        p = self.dir / f"{key}.json"
        if p.exists():
            try:
                return json.loads(p.read_text())
            except (OSError, ValueError):
                return None
        return None

    def put(self, params: dict, row: dict) -> dict:
        key = self.key(params)
        write_json(self.dir / f"{key}.json", row)
        self._fresh.add(key)
        return row

    def measure(self, params: dict, fn) -> tuple[dict, bool]:
        """Stored row for ``params``, or ``fn()`` measured now and stored. Returns (row, was_cached)."""
        row = self.get(params)
        if row is not None:
            return row, True
        return self.put(params, fn()), False


def write_index(out_dir="results") -> Path:
    """results/README.md: a link to every target's summary, data and figure present on disk."""
    out_dir = Path(out_dir)
    figs = REPO / "paper_figs"
    lines = ["# Results", "", "Output of the last run of each target (`python -m experiments.run <target>`). "
             "Each folder holds tidy CSV (one row per measurement), `summary.md` (ours beside the paper) and "
             "`meta.json` (commit, versions, CPU, threads, seeds, wall time).", "",
             "| target | summary | data | figure |", "|---|---|---|---|"]
    for d in sorted(p for p in out_dir.iterdir() if p.is_dir() and p.name != "points"):
        summ = d / "summary.md"
        csvs = sorted(d.glob("*.csv")) + sorted(d.glob("*.json"))
        fig = sorted(f for f in figs.glob(f"{d.name}*.p[nd][gf]") if f.stem == d.name or f.stem.startswith(d.name + "_"))
        lines.append(f"| {d.name} | {f'[summary.md]({d.name}/summary.md)' if summ.exists() else '–'} | "
                     + (", ".join(f"[{c.name}]({d.name}/{c.name})" for c in csvs[:6]) or "–") + " | "
                     + (", ".join(f"[{f.name}](../paper_figs/{f.name})" for f in fig) or "–") + " |")
    return atomic_write(out_dir / "README.md", "\n".join(lines) + "\n")

"""gridcost's Python API for the two questions users come with, as the CLI answers them:

* :func:`advise`: which structure to build for a mesh, at one ray budget or at every budget: an
  :class:`~experiments.tools.lib.budgets.Advice` (every candidate's predicted build seconds and
  seconds per ray with intervals; ``pick(R)``, ``ranked(R)``, ``ranges()``);
* :func:`fit`: the cost model's constants fitted to *your own* uniform grid's timings: a
  :class:`GridFit` (Tsetup, Ts, Ti with 95 % bootstrap intervals, how well they explain your
  times, your predicted best resolution).

Both run inside a :class:`~experiments.core.context.RunContext` of their own (results under ``out``,
default ``results/quick`` for quick runs), exactly as ``gridcost advise`` and ``gridcost fit
--timings`` do, and raise :class:`tracer.errors.GridcostError` on bad input.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from tracer.settings import Settings, use


def _context(out, quick: bool):
    from experiments.core.context import RunContext
    return RunContext(out=Path(out or ("results/quick" if quick else "results")), quick=quick, threads=1)


def _scene(mesh):
    from tracer.scenes.scene import Scene, load_scene
    return mesh if isinstance(mesh, Scene) else load_scene(str(mesh))


def advise(mesh, kind: str = "random", *, image: int | None = None, seed: int = 0, out=None, quick: bool = False):
    """Every candidate structure's predicted build and per-ray time for ``mesh`` (a path, a named scene
    or a :class:`tracer.Scene`) and ray ``kind`` ("random", "camera" or "path"; ``image`` sets the
    camera's side). The host's calibration is measured once and stored under ``out``.

    Returns an :class:`~experiments.tools.lib.budgets.Advice`: ``.pick(1e6)`` is the candidate predicted
    fastest for a million rays, ``.ranges()`` the budget ranges where each candidate is fastest."""
    from experiments.tools.lib.advising import advice_for
    from tracer.measure.timing import set_threads
    settings = Settings.from_env()
    with use(settings):
        ctx = _context(out, quick)
        set_threads(1)
        return advice_for(ctx, _scene(mesh), kind, seed, image)


@dataclass(frozen=True)
class GridFit:
    """The cost model fitted to a user's grid: seconds per unit of counted work (``constants``:
    tsetup per cell set-up, ts per step, ti per triangle test) with 95 % intervals (``ci``), R² and
    the leave-one-resolution-out errors (%) of the fitted rows, and the predicted best resolution
    (``best``: nx, ny, nz, cells, predicted_s_per_ray) with the cells range whose bootstrap share of
    "best" is at least 5 % (``cells_range``)."""
    scene: str
    N: int
    constants: dict
    ci: dict
    r2: float
    loo_error_pct: tuple
    best: dict
    cells_range: tuple | None


def fit(timings, mesh, kind: str = "random", *, rays_file=None, grid_params: dict | None = None,
        seed: int = 0) -> GridFit:
    """Fit Tsetup, Ts and Ti to ``timings`` (a CSV path, or a DataFrame with columns cells or nx, ny,
    nz; rays; seconds: your grid's trace times at a few resolutions) on ``mesh``: gridcost counts the
    work of the same grids on rays of ``kind`` (or the very rays you timed, ``rays_file``)."""
    from experiments.core.usergrid import counting_rays, fit_timings, read_timings
    settings = Settings.from_env()
    with use(settings):
        scene = _scene(mesh)
        res = fit_timings(read_timings(timings), scene, counting_rays(scene, kind, seed, rays_file), grid_params)
    f, rec = res["fit"], res["recommendation"]
    return GridFit(scene.name, scene.n, dict(f.coef_), dict(f.ci_), float(f.metrics_["r2"]),
                   tuple(float(v) for v in f.loo_), dict(rec["best"]),
                   tuple(rec["cells_range"]) if rec["cells_range"] else None)

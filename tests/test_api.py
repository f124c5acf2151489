"""experiments.api: advise and fit as Python calls returning dataclasses, and the README's example."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

REPO = Path(__file__).resolve().parents[1]


def test_fit_recovers_the_constants_of_a_grid_made_from_counted_work():
    """Timings made from gridcost's own counted work at known costs: fit returns those costs."""
    from experiments.api import GridFit, fit
    from experiments.core.usergrid import count_work, counting_rays
    from tracer import load_scene
    scene = load_scene("bunny-948")
    rows = [(4, 4, 4), (8, 8, 8), (12, 12, 12), (20, 20, 20), (32, 32, 32), (48, 48, 48)]
    work = count_work(scene, rows, counting_rays(scene, "random", 0))
    per_ray = 3e-9 * work.setups + 1.5e-9 * work.steps + 6e-9 * work.tests
    timings = pd.DataFrame({"nx": work.nx, "ny": work.ny, "nz": work.nz, "rays": 100_000, "seconds": 1e5 * per_ray})
    got = fit(timings, scene)
    assert isinstance(got, GridFit) and got.scene == "bunny-948" and got.N == scene.n
    assert got.constants["tsetup"] == pytest.approx(3e-9, rel=1e-6)
    assert got.constants["ts"] == pytest.approx(1.5e-9, rel=1e-6)
    assert got.constants["ti"] == pytest.approx(6e-9, rel=1e-6)
    assert got.r2 == pytest.approx(1.0) and np.allclose(got.loo_error_pct, 0.0, atol=1e-6)
    assert got.best["cells"] == got.best["nx"] * got.best["ny"] * got.best["nz"] > 0


def test_fit_refuses_too_few_rows():
    from experiments.api import fit
    from tracer.errors import GridcostError
    bad = pd.DataFrame({"cells": [100, 200], "rays": 10, "seconds": [1.0, 1.0]})
    with pytest.raises(GridcostError, match="need at least 4 resolutions"):
        fit(bad, "bunny-948")


def test_readme_api_example_runs(tmp_path):
    """The README's Python API block, run as a user would (its results go under the working folder)."""
    text = (REPO / "README.md").read_text()
    section = text.split("### Python API: advise and fit", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = proc.stdout.splitlines()
    assert re.search(r"s predicted$", lines[0]) and any(".." in ln and "rays" in ln for ln in lines[1:])
    assert lines[-1].startswith("your best grid:") and (tmp_path / "results" / "quick").is_dir()

"""The CLI (``python -m experiments.run``): verify and bench targets, JSON output, exit codes."""
from __future__ import annotations

import json

import numpy as np

import pytest

from costmodel.derive import one_level_optimal_M
from tracer.accel.grid import res_from_cells
from tracer.accel.reference import EmbreeAccel
from tracer.scenes.scene import load_scene


def _json(proc) -> dict:
    assert proc.returncode == 0, (proc.returncode, proc.stderr)
    assert "Traceback" not in proc.stderr, proc.stderr
    lines = [line for line in proc.stdout.splitlines() if line.strip()]
    assert len(lines) == 1, proc.stdout  # --json: exactly one JSON object on stdout
    return json.loads(lines[0])


def test_verify_json(run_cli):
    out = _json(run_cli("verify", "--scene", "bunny-948", "--rays", "2000", "--json"))
    assert out["faces"] == 948 and out["scene"] == "bunny-948" and out["structure"] == "grid"
    assert out["disagreements"] == 0
    assert set(out["kinds"]) == {"random", "camera", "path", "adversarial"}
    assert out["rays"] == sum(k["rays"] for k in out["kinds"].values())
    assert 4 * 2000 * 0.3 < out["rays"] <= 4 * 2000
    assert out["kinds"]["random"]["rays"] == 2000 and out["kinds"]["adversarial"]["rays"] == 2000
    assert all(k["disagreements"] == 0 for k in out["kinds"].values())
    assert out["hits"] > 0 and out["stats"]["cells"] > 0


def test_verify_adversarial(run_cli):
    out = _json(run_cli("verify", "--scene", "bunny-948", "--rays", "2000", "--kind", "adversarial",
                        "--param", "mailbox=true", "--param", "exact=false", "--json"))
    assert list(out["kinds"]) == ["adversarial"]
    assert out["rays"] == 2000 and out["disagreements"] == 0
    assert out["params"] == {"mailbox": True, "exact": False}
    assert out["stats"]["mailbox"] is True and out["stats"]["exact"] is False


def test_verify_text_output(run_cli):
    proc = run_cli("verify", "--scene", "cylinder-196", "--rays", "500", "--kind", "random")
    assert proc.returncode == 0, proc.stderr
    assert "cylinder-196" in proc.stdout and "0 disagreements" in proc.stdout


def test_verify_suite_checks_every_variant(tmp_path):
    """``verify --suite``: every bench variant but the measured one, on the scenes given (one far from the
    origin here), a JSON and a summary each, and an index naming them all with their totals."""
    from experiments.run import main
    from experiments.tools.lib.variants import VARIANTS
    from experiments.tools.verify import NOT_IN_SUITE
    assert main(["verify", "--suite", "--scene", "cornell,bunny-948-far1e5", "--rays", "300",
                 "--out", str(tmp_path)]) == 0
    d = tmp_path / "verify"
    names = [n for n in VARIANTS if n not in NOT_IN_SUITE]
    assert "wbvh" in names and "kdtree-fast" in names and "bvh4-sah-fit" not in names
    index = (d / "summary.md").read_text()
    for name in names:
        out = json.loads((d / f"{name}.json").read_text())
        assert out["variant"] == name and (out["structure"], out["params"]) == VARIANTS[name]
        assert [o["scene"] for o in out["scenes"]] == ["cornell", "bunny-948-far1e5"]
        assert out["disagreements"] == 0 and out["rays"] > 4 * 300
        assert (d / f"summary-{name}.md").exists() and f"[{name}](summary-{name}.md)" in index
    assert "Not run: bvh4-sah-fit" in index


def test_verify_suite_json_is_one_object(run_cli, tmp_path):
    out = _json(run_cli("verify", "--suite", "--scene", "cornell", "--rays", "100", "--kind", "random", "--json",
                        "--out", str(tmp_path)))
    assert out["scenes"] == ["cornell"] and out["disagreements"] == 0 and "wbvh" in out["variants"]
    assert all(v["rays"] == 100 for v in out["variants"].values())


def test_bench_json(run_cli, tmp_path):
    out_dir = tmp_path / "results"
    out = _json(run_cli("bench", "--scene", "bunny-948", "--rays", "5000", "--repeats", "1",
                        "--structures", "grid,grid-fit,bvh4,bvh4-sah-fit,embree", "--threads", "1", "--sah-scenes", "bunny-948",
                        "--json", "--out", str(out_dir)))
    assert out["scene"] == "bunny-948" and out["faces"] == 948 and out["rays"] == 5000
    grid = out["structures"]["grid"]
    for key in ("build_s", "random_mrays", "camera_mrays"):
        assert grid[key] > 0, key
    assert grid["random_per_ray"]["steps"] > 0
    written = list((out_dir / "bench").glob("bunny-948-*.json"))
    assert len(written) == 1
    assert json.loads(written[0].read_text())["structures"].keys() == out["structures"].keys()
    assert out["git_commit"] and out["host"]["cpu"]
    summary = (out_dir / "bench" / "summary.md").read_text()
    assert "## bench: bunny-948" in summary and f"Measured by commit {out['git_commit']}" in summary
    # the BVH4 built with the SAH weight fitted in this run, on the calibration mesh asked for
    fit = out["bvh_sah_fit"]
    assert fit["scenes"] == ["bunny-948"] and fit["trav_cost"] > 0
    # the geometric mean of the kinds whose fit separated a node from a test (a noisy host can leave
    # a kind out, or every kind: then the tracer's default weight, said in fit["fallback"])
    fitted = [k for k in ("random", "camera") if f"{k}_ratio" in fit]
    assert sorted(fitted + fit["kinds_left_out"]) == ["camera", "random"]
    expected = 0.125 if fit["fallback"] else np.exp(np.mean(np.log([fit[f"{k}_ratio"] for k in fitted])))
    assert fit["fallback"] == (not fitted) and fit["trav_cost"] == pytest.approx(expected)
    assert out["structures"]["bvh4-sah-fit"]["params"] == {"trav_cost": fit["trav_cost"]}
    assert f"C_trav/C_isect = {fit['trav_cost']:.3f}" in summary
    # the grid at Ize's Eq 4 with T_i/T_s fitted in this run on the same calibration mesh
    gfit = out["grid_density_fit"]
    assert gfit["scenes"] == ["bunny-948"] and 0.125 <= gfit["factor"] <= 64.0
    assert gfit["fallback"] or gfit["factor"] == pytest.approx(
        min(max(float(one_level_optimal_M(1.0, 1.0, gfit["ti_over_ts"])), 0.125), 64.0))
    assert out["structures"]["grid-fit"]["params"] == {"factor": gfit["factor"]}
    bunny = load_scene("bunny-948")  # the grid bench built has the fitted factor's cells
    assert out["structures"]["grid-fit"]["stats"]["cells"] == int(np.prod(res_from_cells(bunny.bounds, gfit["factor"] * bunny.n)))
    assert f"grid-fit: the grid with M = 2N T_i/T_s cells (Ize 2007 Eq 4), {gfit['factor']:.2f}N" in summary
    if not EmbreeAccel.available():
        assert "embree" in out["unavailable"]
        pytest.skip("embreex is not installed: Embree assertions skipped")
    emb = out["structures"]["embree"]
    for key in ("build_s", "random_mrays", "camera_mrays"):
        assert emb[key] > 0, key
    (key,) = [k for k in out["ratios"] if k.startswith("grid/embree")]
    assert set(out["ratios"][key]) >= {"random", "camera", "build"}
    # Embree traces on one thread: more of ours are compared per thread, and the name says so
    assert ("per thread" in key) == (out["threads"] > 1)
    # the headline structures that ran are paired with Embree in the same rounds
    assert set(out["paired"]) == {"grid/embree", "grid-fit/embree", "bvh4/embree", "bvh4-sah-fit/embree"}
    for v in out["paired"].values():
        assert set(v) == {"random", "camera"} and all(0 < k["min"] <= k["ratio"] <= k["max"] for k in v.values())
    assert "| bvh4/embree | " in summary


# ---------------------------------------------------------------- bad input: exit 2, one line
@pytest.mark.parametrize("case", ["missing", "nan-vertex"])
def test_bad_mesh_exit_2(case, bad_meshes, run_cli, cli_error):
    path, causes = bad_meshes[case]
    line = cli_error(run_cli("verify", "--mesh", str(path), "--rays", "10"), path)
    assert any(c.lower() in line.lower() for c in causes), line


@pytest.mark.parametrize("case", ["missing", "unknown-format", "directory", "zero-bytes", "no-faces", "nan-vertex",
                                  "inf-vertex", "zero-bytes-ply"])
def test_bad_mesh_exit_2_in_process(case, bad_meshes, capsys):
    from experiments.run import main
    path, causes = bad_meshes[case]
    assert main(["verify", "--mesh", str(path), "--rays", "10"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and str(path) in lines[0], lines
    assert any(c.lower() in lines[0].lower() for c in causes), lines[0]


def test_bench_bad_mesh_exit_2(bad_meshes, run_cli, cli_error, tmp_path):
    path, causes = bad_meshes["nan-vertex"]
    out = tmp_path / "out"
    line = cli_error(run_cli("bench", "--mesh", str(path), "--rays", "10", "--repeats", "1", "--structures", "grid",
                             "--out", str(out)), path)
    assert any(c.lower() in line.lower() for c in causes), line
    assert not out.exists() or not any(out.rglob("*")), "bad input must leave nothing written"


BAD_ARGS = [
    (["verify", "--scene", "no-such-scene", "--rays", "10"], "unknown scene 'no-such-scene'"),
    (["verify", "--scene", "bunny-948", "--rays", "0"], "rays"),
    (["verify", "--scene", "bunny-948", "--rays", "10", "--structure", "octree"], "unknown structure 'octree'"),
    (["verify", "--scene", "bunny-948", "--rays", "10", "--param", "cells"], "key=value"),
    (["verify", "--scene", "bunny-948", "--rays", "10", "--param", "cells=0"], "cell"),
    (["verify", "--rays", "10"], "needs --scene or --mesh"),
]


def test_bad_arguments_exit_2_subprocess(run_cli, cli_error):
    args, words = BAD_ARGS[0]
    assert words in cli_error(run_cli(*args), None)


@pytest.mark.parametrize("args, words", BAD_ARGS)
def test_bad_arguments_exit_2(args, words, capsys):
    """In-process (``experiments.run.main``): return 2, one 'error:' line on stderr, nothing on stdout."""
    from experiments.run import main
    assert main(args) == 2
    cap = capsys.readouterr()
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:"), cap.err
    assert words in lines[0], lines[0]
    assert cap.out == ""


def test_memory_budget_exit_2(run_cli, cli_error):
    proc = run_cli("verify", "--scene", "bunny-948", "--rays", "10", "--param", "cells=10000000",
                   env={"GRIDCOST_MEMORY_BUDGET": "1M"})
    line = cli_error(proc, None)
    assert "MiB" in line or "GiB" in line, line


def test_advise_json_predicts_and_checks(run_cli, tmp_path):
    """advise on a mesh outside its calibration: a pick among the candidates, predicted totals with
    intervals around them, and --check's measured totals for the best three."""
    p = run_cli("advise", "--quick", "--scene", "dragon-11k", "--rays", "1e6", "--check", "--json",
                "--out", str(tmp_path), timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    out = _json(p)
    names = [c["structure"] for c in out["candidates"]]
    assert out["pick"] == names[0] and set(names) >= {"grid", "nested", "kdtree", "bvh"}
    assert out["rays"] == 1e6
    for c in out["candidates"]:
        assert 0 < c["predicted_lo"] <= c["predicted_s"] <= c["predicted_hi"]
    checked = [c for c in out["candidates"] if "measured_s" in c]
    assert len(checked) == 3 and all(c["measured_s"] > 0 for c in checked)
    assert (tmp_path / "advise" / "summary.md").exists()
    # the BVH4's SAH weight (3 meshes x 5 builds x 2 ray kinds) and the grid's density (3 meshes x 3
    # densities x 2 ray kinds): their points stored with their provenance, and a second call fits
    # them from those instead of measuring again
    fits = sorted((r for r in (json.loads(f.read_text()) for f in (tmp_path / "points").glob("*.json"))
                   if isinstance(r["value"], list) and r["value"] and r["value"][0].get("nodes") is not None),
                  key=lambda r: len(r["value"]))
    assert [len(r["value"]) for r in fits] == [18, 30] and all(r["provenance"]["commit"] for r in fits)
    for r in fits:
        assert {p_["scene"] for p_ in r["value"]} == {"bunny-16k", "dragon-11k", "teapot"}
    assert sorted({p_["params"]["factor"] for p_ in fits[0]["value"]}) == [0.5, 2.0, 8.0]
    # the grid candidate is probed at the density those points give (Ize Eq 4, or 8N when no kind fitted)
    from costmodel.griddensity import GridDensityFit
    dens = GridDensityFit(default=8.0).fit(fits[0]["value"])
    assert out["candidates"][names.index("grid")]["params"] == {"factor": dens.factor_}
    assert (f"T_i/T_s {dens.ti_over_ts_:.2f} fitted on this host" if not dens.fallback_ else "paper's") \
        in out["candidates"][names.index("grid")]["how"]
    again = run_cli("advise", "--quick", "--scene", "dragon-11k", "--rays", "1e6", "--out", str(tmp_path), timeout=600)
    assert again.returncode == 0, again.stderr[-2000:]
    log = again.stdout + again.stderr
    assert f"C_trav/C_isect {out['candidates'][names.index('bvh4')]['params']['trav_cost']:.2f}, fitted on" in log
    assert log.count("(stored points of this host)") == 2 and f"the grid's cells {dens.factor_:.2f}N" in log


def test_trimesh_reference_rays_fit_the_memory_budget(monkeypatch):
    """trimesh's tracer holds ~16 B per (ray, face): its rays are cut to the budget (dragon-871k at
    2,000 rays was OOM-killed at 24 GB)."""
    from experiments.tools import bench
    monkeypatch.setenv("GRIDCOST_MEMORY_BUDGET", "12G")
    assert bench.trimesh_ray_count(2000, 69_451) == 2000
    assert bench.trimesh_ray_count(2000, 871_414) == 12 * 2**30 // (16 * 871_414) == 924
    monkeypatch.setenv("GRIDCOST_MEMORY_BUDGET", "1G")
    assert bench.trimesh_ray_count(2000, 871_414) < bench.TRIMESH_MIN_RAYS


def test_a_whole_folder_target_drops_an_earlier_runs_files(tmp_path):
    """derive rewrites its folder: a file an earlier run left (say by an optional flag) is removed after
    a successful run, its own outputs stay; a per-scene target (verify) keeps earlier scenes' files."""
    from experiments.run import main
    from tracer.storage import atomic_write
    out = tmp_path / "results"
    stale = atomic_write(out / "derive" / "from-an-earlier-run.csv", "x\n")
    fig = atomic_write(out / "paper_figs" / "derive.png", b"old")  # a figure derive does not draw
    assert main(["derive", "--out", str(out)]) == 0
    assert not stale.exists() and (out / "derive" / "summary.md").is_file()
    assert (out / "derive" / "derive.json").is_file()
    assert not fig.exists()
    kept = atomic_write(out / "verify" / "other-scene.json", "{}\n")
    assert main(["verify", "--scene", "cornell,bunny-948", "--rays", "50", "--kind", "random", "--out", str(out)]) == 0
    assert kept.exists() and (out / "verify" / "grid.json").is_file()

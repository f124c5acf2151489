"""A structure from outside gridcost, registered by an entry point (``gridcost.structures``), goes
through ``verify`` and ``bench`` with no edit to gridcost; a bad registration is one clear error."""
from __future__ import annotations

import json
import os
import textwrap

import pytest

# the whole outside package: one module, one Accel subclass (brute force over the float64 oracle)
PLUGIN = textwrap.dedent('''
    """A structure that is not gridcost's: every ray against every triangle."""
    import numpy as np

    from tracer.accel.base import COUNTER_NAMES, Accel
    from tracer.accel.oracle import oracle_intersect


    class BruteForce(Accel):
        name = "brute"
        counter_fields = {"tests": "ray/triangle tests: every triangle, for every ray"}

        def __init__(self, note: str = ""):
            self.note = note

        def build(self, scene):
            self.scene_ = scene
            return self

        def _trace(self, o, d, tmin, tmax, anyhit, count):
            hits, _ = oracle_intersect(self.scene_, o, d, tmin, tmax)
            cnt = None
            if count:
                cnt = np.zeros((len(o), len(COUNTER_NAMES)), np.int32)
                cnt[:, COUNTER_NAMES.index("tests")] = self.scene_.n
            return hits.t.astype(np.float32), hits.tri_id.astype(np.int32), cnt

        def stats(self):
            return {"triangles": self.scene_.n, "memory_bytes": 0}
''')


def _install(root, entry: str, module: str = PLUGIN) -> dict:
    """A package installed the way pip leaves one: the module and its dist-info with entry_points.txt."""
    (root / "gridcost_brute_plugin.py").write_text(module)
    dist = root / "gridcost_brute_plugin-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: gridcost-brute-plugin\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(f"[gridcost.structures]\n{entry}\n")
    return {"PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)}


@pytest.fixture
def plugin_env(tmp_path):
    return _install(tmp_path, "brute = gridcost_brute_plugin:BruteForce")


def test_registered_structure_is_listed(run_cli, plugin_env):
    proc = run_cli(code="from tracer.accel import structures, plugin_structures, build, STRUCTURES;"
                        "from tracer import load_scene;"
                        "s = structures(); assert list(s)[:len(STRUCTURES)] == list(STRUCTURES);"
                        "assert plugin_structures() == ('brute',), plugin_structures();"
                        "a = build(load_scene('bunny-948'), 'brute', note='x'); assert a.note == 'x';"
                        "print(s['brute'])", env=plugin_env)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "gridcost_brute_plugin:BruteForce"


def test_registered_structure_through_verify(run_cli, plugin_env):
    proc = run_cli("verify", "--scene", "bunny-948", "--structure", "brute", "--rays", "300", "--json", env=plugin_env)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["structure"] == "brute" and out["faces"] == 948
    assert out["disagreements"] == 0 and out["hits"] > 0
    assert set(out["kinds"]) == {"random", "camera", "path", "adversarial"}
    assert out["stats"]["triangles"] == 948


def test_registered_structure_through_bench(run_cli, plugin_env, tmp_path):
    out_dir = tmp_path / "results"
    proc = run_cli("bench", "--scene", "bunny-948", "--rays", "400", "--repeats", "1", "--threads", "1",
                   "--structures", "grid,brute", "--json", "--out", str(out_dir), env=plugin_env)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    brute, grid = out["structures"]["brute"], out["structures"]["grid"]
    assert brute["random_mrays"] > 0 and brute["camera_mrays"] > 0
    # its counters come through by name: every ray tests every triangle
    assert brute["random_per_ray"]["tests"] == 948 and brute["random_per_ray"]["steps"] == 0
    assert grid["random_per_ray"]["tests"] < 948  # the grid, beside it, does less work
    # bench's default list takes it too, with no --structures
    proc = run_cli(code="from experiments.tools.bench import default_names, VARIANTS; n = default_names();"
                        "assert n[:len(VARIANTS)] == list(VARIANTS); print(n[len(VARIANTS):])", env=plugin_env)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "['brute', 'embree', 'trimesh']"


def test_registered_structure_changes_the_measurement_key(run_cli, plugin_env, tmp_path):
    code = "from tracer.measure.provenance import measurement_key as k; print(k((), 1, 'wall')['code'])"
    plain, plugged = run_cli(code=code), run_cli(code=code, env=plugin_env)
    assert plain.returncode == 0 and plugged.returncode == 0, (plain.stderr, plugged.stderr)
    assert plain.stdout.strip() != plugged.stdout.strip()  # a point measured with it is keyed by its source
    (tmp_path / "v2").mkdir()
    edited = _install(tmp_path / "v2", "brute = gridcost_brute_plugin:BruteForce", PLUGIN + "\nEDITED = 1\n")
    again = run_cli(code=code, env=edited)
    assert again.returncode == 0 and again.stdout.strip() not in (plain.stdout.strip(), plugged.stdout.strip())


@pytest.mark.parametrize("entry, message", [
    ("grid = gridcost_brute_plugin:BruteForce", "shadows gridcost's built-in structure 'grid'"),
    ("nope = gridcost_brute_plugin:Missing", "cannot load"),
    ("notaccel = json:dumps", "is not a subclass of tracer.accel.base.Accel"),
])
def test_bad_registration_is_one_clear_error(run_cli, cli_error, tmp_path, entry, message):
    env = _install(tmp_path, entry)
    name = entry.split(" = ")[0]
    proc = run_cli("verify", "--scene", "bunny-948", "--structure", name, "--rays", "50", env=env)
    line = cli_error(proc, name)
    assert message in line

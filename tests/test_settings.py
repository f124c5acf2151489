"""One Settings: the environment is read in one place, runs carry their settings, no module state."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

from tracer.errors import GridcostError
from tracer.settings import RunLog, Settings, current, parse_bytes, run_log, use

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("tracer", "costmodel", "experiments")


def test_from_env_reads_every_variable():
    s = Settings.from_env({"GRIDCOST_CACHE": "/c", "GRIDCOST_MODELS": "/m", "GRIDCOST_SHARED_MODELS": "",
                           "GRIDCOST_OFFLINE": "yes", "GRIDCOST_NO_STAND_INS": "1", "GRIDCOST_MEMORY_BUDGET": "2G",
                           "GRIDCOST_L2": "1.5M", "GRIDCOST_CLOCK": "wall", "GRIDCOST_PIN": "1",
                           "GRIDCOST_NUMBA_CACHE": "/n", "GRIDCOST_MACHINE_DIR": "/p"})
    assert (s.cache, s.models, s.numba_cache, s.machine_dir) == ("/c", "/m", "/n", "/p")
    assert s.shared_models_dir == "" and s.offline and not s.stand_ins and s.pin and s.clock == "wall"
    assert s.memory_budget == 2 << 30 and s.cache_sizes == (None, 3 << 19, None)
    empty = Settings.from_env({})
    assert empty.shared_models_dir is None and empty.stand_ins and not empty.offline and empty.memory_budget is None


@pytest.mark.parametrize("env", [{"GRIDCOST_MEMORY_BUDGET": "lots"}, {"GRIDCOST_L3": "1Q"}, {"GRIDCOST_CLOCK": "cpu"}])
def test_bad_values_are_one_clear_error(env):
    with pytest.raises(GridcostError, match=next(iter(env))):
        Settings.from_env(env)


def test_parse_bytes():
    assert [parse_bytes(t) for t in ("4096", "1K", "2MiB", "1.5G", "3gb")] == [4096, 1024, 2 << 20, 3 << 29, 3 << 30]


def test_use_scopes_settings_and_log(monkeypatch):
    from tracer.measure.memory import memory_budget
    monkeypatch.setenv("GRIDCOST_MEMORY_BUDGET", "1G")
    outer = run_log()
    with use(Settings.from_env().replace(memory_budget=5 << 20)):
        assert memory_budget() == 5 << 20 and run_log() is not outer
        run_log().stand_ins["x"] = "note"
    assert memory_budget() == 1 << 30 and "x" not in run_log().stand_ins
    monkeypatch.setenv("GRIDCOST_MEMORY_BUDGET", "2G")  # outside any run: the environment now
    assert current().memory_budget == 2 << 30


def test_worker_takes_the_clients_lookup_and_clock_not_its_caches(monkeypatch):
    client = Settings.from_env({"GRIDCOST_MODELS": "/client/models", "GRIDCOST_CACHE": "/client/cache",
                                "GRIDCOST_MEMORY_BUDGET": "1G"}).replace(clock="wall")
    monkeypatch.setenv("GRIDCOST_CACHE", "/worker/cache")
    monkeypatch.delenv("GRIDCOST_MEMORY_BUDGET", raising=False)
    w = Settings.on_worker(client.for_worker())
    assert (w.models, w.clock, w.cache, w.memory_budget) == ("/client/models", "wall", "/worker/cache", None)


def test_a_run_log_counts_timings():
    from tracer.measure.timing import time_call, timing_calls
    with use(None, RunLog()):
        assert timing_calls() == 0
        time_call(lambda: None, repeats=1, warmup=0, min_sample=0.0)
        assert timing_calls() == 1


def _modules():
    for pkg in PACKAGES:
        yield from sorted((ROOT / pkg).rglob("*.py"))


def test_the_environment_is_read_only_in_settings():
    readers = []
    for path in _modules():
        text = path.read_text()
        for i, line in enumerate(text.splitlines(), 1):
            if ("os.environ" in line or "getenv(" in line) and "GRIDCOST" in line:
                readers.append(f"{path.relative_to(ROOT)}:{i}")
            if "os.environ[" in line and "=" in line.split("os.environ[", 1)[1]:
                readers.append(f"{path.relative_to(ROOT)}:{i} (writes the environment)")
    assert readers == []


def test_no_mutable_module_state():
    """No module binds a name to a dict, list or set it then changes (constants are tuples, frozensets,
    mappings that are never assigned into; memoization is functools.lru_cache)."""
    found = []
    for path in _modules():
        tree = ast.parse(path.read_text())
        mutable = {}
        for node in tree.body:
            targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(node, ast.AnnAssign) else []
            value = getattr(node, "value", None)
            is_mut = isinstance(value, (ast.Dict, ast.List, ast.Set)) or (
                isinstance(value, ast.Call) and isinstance(value.func, ast.Name) and value.func.id in ("dict", "list", "set"))
            for t in targets:
                if isinstance(t, ast.Name) and is_mut:
                    mutable[t.id] = node.lineno
        for node in ast.walk(tree):  # a module-level container changed from inside a function
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                for sub in ast.walk(node):
                    tgt = None
                    if isinstance(sub, (ast.Assign, ast.AugAssign)):
                        for t in (sub.targets if isinstance(sub, ast.Assign) else [sub.target]):
                            if isinstance(t, ast.Subscript) and isinstance(t.value, ast.Name):
                                tgt = t.value.id
                    elif isinstance(sub, ast.Call) and isinstance(sub.func, ast.Attribute) and \
                            sub.func.attr in ("append", "add", "update", "pop", "clear", "setdefault", "extend") and \
                            isinstance(sub.func.value, ast.Name):
                        tgt = sub.func.value.id
                    local = {a.arg for a in node.args.args + node.args.kwonlyargs} | {
                        n.id for n in ast.walk(node) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Store)}
                    if tgt in mutable and tgt not in local:
                        found.append(f"{path.relative_to(ROOT)}:{mutable[tgt]} {tgt}")
    assert sorted(set(found)) == []


def test_costmodel_never_builds_or_times():
    """costmodel/ receives measured numbers: it imports nothing that builds a structure, makes rays,
    loads a scene or reads a clock (experiments.core.probes does)."""
    banned = ("tracer.measure.timing", "tracer.accel.base", "tracer.scenes.rays", "tracer.scenes.scene", "time")
    found = []
    for path in sorted((ROOT / "costmodel").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            if isinstance(node, ast.ImportFrom) and node.module == "tracer.accel":
                names += [f"tracer.accel.{a.name}" for a in node.names if a.name == "build"]
            found += [f"{path.relative_to(ROOT)}: {n}" for n in names
                      if n in banned or n == "tracer.accel.build"]
    assert found == []

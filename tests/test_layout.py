"""The repository's layout rules: every module imports on its own, dependencies point one way, no
import cycle inside tracer/, and no source file grows past MAX_LINES.

Dependencies (every ``import`` statement, at top level and inside functions, read with ``ast``):

* ``tracer`` imports neither ``costmodel`` nor ``experiments``; ``costmodel`` does not import
  ``experiments``;
* ``experiments/core`` (the shared machinery) reaches none of the paper packages
  (``experiments/{ize,hapala,wald,fournier,tools}``), and ``experiments/core/point.py`` (one
  measurement) reaches neither ``core/sweep.py`` nor ``core/executor.py``;
* the modules of ``tracer/`` form no cycle.

"Reaches" follows imports transitively, so a path through a third module counts too; a failure
names the chain of imports (file:line) that breaks the rule.
"""
from __future__ import annotations

import ast
import json
import subprocess
import sys
from functools import lru_cache
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("tracer", "costmodel", "experiments")
PAPERS = tuple(f"experiments.{p}" for p in ("ize", "hapala", "wald", "fournier", "tools"))
#: no .py file of PACKAGES may have more lines than this
MAX_LINES = 650

#: (importers, modules they must not reach, why): a module name prefix matches itself and its submodules
RULES = [
    ("tracer", ("costmodel", "experiments"), "the tracer is the bottom layer"),
    ("costmodel", ("experiments",), "cost models do not depend on the experiments"),
    ("experiments.core", PAPERS, "the shared machinery is below the paper packages"),
    ("experiments.core.point", ("experiments.core.sweep", "experiments.core.executor"),
     "one measurement knows nothing of sweeps or executors"),
]


def _under(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


@lru_cache(maxsize=None)
def modules() -> dict[str, Path]:
    """Module name -> file for every .py file of PACKAGES (a package is its ``__init__.py``)."""
    out = {}
    for pkg in PACKAGES:
        for path in sorted((REPO / pkg).rglob("*.py")):
            parts = list(path.relative_to(REPO).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join(parts)] = path
    return out


def _targets(node, name: str, path: Path) -> list[str]:
    """The project modules one import statement loads. ``from pkg import x`` loads ``pkg.x`` when
    that is a module, else ``pkg`` itself."""
    mods = modules()
    if isinstance(node, ast.Import):
        return [a.name for a in node.names if a.name in mods]
    base = node.module or ""
    if node.level:
        pkg = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
        pkg = pkg[:len(pkg) - (node.level - 1)]
        base = ".".join(pkg + ([node.module] if node.module else []))
    out = []
    for a in node.names:
        sub = f"{base}.{a.name}"
        if sub in mods:
            out.append(sub)
        elif base in mods and base not in out:
            out.append(base)
    return out


@lru_cache(maxsize=None)
def import_graph() -> dict[str, dict[str, str]]:
    """Module -> {imported project module: "file:line" of the (first) statement importing it}, for
    every import statement of the module (top level and inside functions or classes)."""
    graph = {}
    for name, path in modules().items():
        edges: dict[str, str] = {}
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                for target in _targets(node, name, path):
                    if target != name:
                        edges.setdefault(target, f"{path.relative_to(REPO)}:{node.lineno}")
        graph[name] = edges
    return graph


def _chain(start: str, forbidden) -> list[str] | None:
    """The shortest chain of imports from ``start`` to a module under one of ``forbidden`` (as
    "file:line -> module" steps), or None."""
    graph = import_graph()
    prev = {start: None}
    queue = [start]
    while queue:
        cur = queue.pop(0)
        for nxt, where in graph[cur].items():
            if nxt in prev:
                continue
            prev[nxt] = (cur, where)
            if any(_under(nxt, f) for f in forbidden):
                steps = []
                node = nxt
                while prev[node] is not None:
                    parent, at = prev[node]
                    steps.append(f"{at} imports {node}")
                    node = parent
                return steps[::-1]
            queue.append(nxt)
    return None


def _cycles(names) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan) of the graph restricted to
    ``names``: each is a set of modules that import each other, directly or through each other."""
    graph = {n: [m for m in import_graph()[n] if m in names] for n in names}
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


# ---------------------------------------------------------------- (a) every module imports
def test_every_module_imports_in_a_fresh_interpreter():
    """Each module of tracer/, costmodel/, experiments/ imports without error in a fresh interpreter
    (one subprocess, modules in sorted order; failures are listed with their error)."""
    code = ("import importlib, json, sys, traceback\n"
            "bad = {}\n"
            "for name in sys.argv[1:]:\n"
            "    try:\n"
            "        importlib.import_module(name)\n"
            "    except BaseException:\n"
            "        bad[name] = traceback.format_exc(limit=3).strip().splitlines()[-1]\n"
            "print(json.dumps(bad))\n")
    proc = subprocess.run([sys.executable, "-c", code, *sorted(modules())], capture_output=True, text=True,
                          cwd=str(REPO), check=False, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    bad = json.loads(proc.stdout.strip().splitlines()[-1])
    assert not bad, "modules that fail to import:\n" + "\n".join(f"  {k}: {v}" for k, v in bad.items())


# ---------------------------------------------------------------- (b) dependencies point one way
def test_the_import_reader_sees_function_level_imports():
    """The checks below read imports inside functions too (the graph has a known one)."""
    assert "tracer.scenes.procedural" in import_graph()["tracer.scenes.registry"]
    assert any(_under(m, "tracer") for m in import_graph()["experiments.tools.verify"])


@pytest.mark.parametrize("importers, forbidden, why", RULES, ids=[r[0] for r in RULES])
def test_dependencies_point_one_way(importers, forbidden, why):
    broken = {}
    for name in modules():
        if _under(name, importers):
            chain = _chain(name, forbidden)
            if chain:
                broken[name] = chain
    assert not broken, (f"{importers} must not import {', '.join(forbidden)} ({why}):\n"
                        + "\n".join(f"  {name}: " + " -> ".join(chain) for name, chain in broken.items()))


def test_no_import_cycle_in_tracer():
    """No two modules of tracer/ import each other, directly or through other tracer modules
    (function-level imports count: they are cycles that only hide until run time)."""
    names = {n for n in modules() if _under(n, "tracer")}
    cycles = _cycles(names)
    lines = []
    for comp in cycles:
        lines.append("  cycle among " + ", ".join(comp) + ":")
        for a in comp:
            for b, where in import_graph()[a].items():
                if b in comp:
                    lines.append(f"    {where} {a} imports {b}")
    assert not cycles, "import cycles in tracer/:\n" + "\n".join(lines)


# ---------------------------------------------------------------- (c) file sizes
def test_no_source_file_over_max_lines():
    """Modules stay small enough to read: no .py file of tracer/, costmodel/, experiments/ over
    MAX_LINES lines (split by concern, re-exporting public names from the old module)."""
    sizes = {str(p.relative_to(REPO)): len(p.read_text().splitlines()) for p in modules().values()}
    over = {k: v for k, v in sorted(sizes.items()) if v > MAX_LINES}
    assert not over, f"files over {MAX_LINES} lines:\n" + "\n".join(f"  {k}: {v}" for k, v in over.items())

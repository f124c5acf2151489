"""The documentation site: it builds in strict mode (no warning: a broken link, an anchor, an API
page mkdocstrings cannot render, a target without its section), every Python example of every page
runs, and every target of the CLI is documented."""
from __future__ import annotations

import importlib.util
import logging
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from experiments.run import TARGETS

REPO = Path(__file__).resolve().parent.parent
DOCS = REPO / "docs"
#: every page of the site (mkdocs.yml nav), as its source under docs/ without ".md"
PAGES = ("index", "quickstart", "models", "targets", "structures", "distributed",
         "reference/tracer", "reference/costmodel", "reference/experiments")
#: a ```python fence of a page: the examples that must run
PYTHON_BLOCK = re.compile(r"^```python\n(.*?)^```\s*$", re.S | re.M)


def python_blocks(page: str) -> list[str]:
    return PYTHON_BLOCK.findall((DOCS / f"{page}.md").read_text())


def _load(name: str):
    """A module of docs/ (the build's hook and griffe extension), loaded from its file."""
    spec = importlib.util.spec_from_file_location(f"docs_{name}", DOCS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _examples_file(page: str, code: str) -> Path:
    """The page's examples as a script at a path that is the same in every run, rewritten (atomically)
    only when they change: Numba caches a kernel an example defines (structures.md) by its file's
    path and modification time, so a fresh path per run would add a cache folder per run and compile
    the kernel every time."""
    folder = Path(tempfile.gettempdir()) / f"gridcost-docs-examples-{os.getuid()}"
    folder.mkdir(exist_ok=True)
    script = folder / f"{page.replace('/', '_')}_examples.py"
    if not script.is_file() or script.read_text() != code:
        part = folder / f".{script.name}.{os.getpid()}"
        part.write_text(code)
        os.replace(part, script)
    return script


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    out = tmp_path_factory.mktemp("site")
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(out)], cwd=REPO,
                          capture_output=True, text=True, timeout=600, env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    return proc, out


def test_site_builds_in_strict_mode(site):
    proc, out = site
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "WARNING" not in proc.stderr, proc.stderr[-3000:]
    built = sorted(p.parent.relative_to(out).as_posix() for p in out.rglob("index.html"))
    assert built == sorted("." if p == "index" else p for p in PAGES)
    assert len(built) == 9
    assert (out / "404.html").is_file() and (out / "search" / "search_index.json").is_file()
    # the docs' own Python (hook, griffe extension) is not published
    assert not list(out.rglob("*.py"))


def test_api_reference_renders_the_public_modules(site):
    _, out = site
    pages = {p: (out / p / "index.html").read_text() for p in PAGES if p.startswith("reference/")}
    for ident in ("tracer.accel.base.Accel", "tracer.accel.base.build", "tracer.accel.base.Counters",
                  "tracer.scenes.rays.make_rays", "tracer.scenes.scene.load_scene"):
        assert f'id="{ident}"' in pages["reference/tracer"], ident
    for ident in ("costmodel.derive.ize_eq1_one_level_cost", "costmodel.derive.ize_eq13_two_level_optimum",
                  "costmodel.derive_nested.ize_eq18_two_level_long_skinny_space", "costmodel.fit.GridCostFit",
                  "costmodel.select.exact_rc", "costmodel.select.Selector", "costmodel.packet.PacketCostFit"):
        assert f'id="{ident}"' in pages["reference/costmodel"], ident
    for ident in ("experiments.run.TARGETS", "experiments.tools.lib.budgets.Advice", "experiments.core.tls.make_certs"):
        assert f'id="{ident}"' in pages["reference/experiments"], ident
    # the docstrings' reST reached the page as Markdown: no role left verbatim, tables made lists
    for html in pages.values():
        assert ":class:" not in html and ":func:" not in html and "=======" not in html
    assert "<li><code>base</code>: the interface" in pages["reference/tracer"]


def test_math_is_left_for_mathjax(site):
    _, out = site
    html = (out / "models" / "index.html").read_text()
    assert html.count('class="arithmatex"') >= 20
    assert r"M = \frac{2N\,T_\text{int}}{T_\text{step}}" in html


@pytest.mark.parametrize("page", ["quickstart", "models", "structures", "distributed"])
def test_python_examples_run(page, tmp_path):
    """Each page's Python blocks, in order, in one fresh interpreter (blocks build on each other)."""
    blocks = python_blocks(page)
    assert blocks, f"{page}.md: expected Python examples"
    script = _examples_file(page, "\n\n".join(blocks))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])),
           "MPLBACKEND": "Agg"}
    proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=300,
                          env=env)
    assert proc.returncode == 0, f"{page}.md examples failed:\n{proc.stderr[-3000:]}"
    assert proc.stdout.strip(), f"{page}.md examples printed nothing"


def test_every_page_without_examples_has_none_to_run():
    """Pages are either reference/overview pages with no Python examples or run above: none is skipped."""
    with_blocks = {p for p in PAGES if python_blocks(p)}
    assert with_blocks == {"quickstart", "models", "structures", "distributed"}


def test_every_target_has_its_section():
    text = (DOCS / "targets.md").read_text()
    sections = re.findall(r"^###\s+`([a-z0-9-]+)`", text, re.M)
    assert len(sections) == len(set(sections)), "a target documented twice"
    assert set(sections) == set(TARGETS) | {"all"}


def test_targets_page_lists_every_target(site):
    _, out = site
    html = (out / "targets" / "index.html").read_text()
    for name, (module, _) in TARGETS.items():
        assert f'id="{name}"' in html, name                       # its section
        assert f'<a href="#{name}"><code>{name}</code></a>' in html, name  # its row of the generated table
        assert f"<code>{module}</code>" in html, module


def test_hook_fails_the_build_on_an_undocumented_target(caplog):
    hooks = _load("hooks")
    page = type("Page", (), {"file": type("File", (), {"src_uri": "targets.md"})()})()
    text = (DOCS / "targets.md").read_text()
    with caplog.at_level(logging.WARNING):
        full = hooks.on_page_markdown(text, page)
    assert not caplog.records
    assert full.count("| [`") == len(TARGETS) + 1 and hooks.MARKER not in full
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        hooks.on_page_markdown(text.replace("### `havran`", "### havran statistics"), page)
    assert [r.getMessage() for r in caplog.records] == [
        "targets.md: target 'havran' (experiments/run.py TARGETS) has no section '### `havran`'"]


def test_counter_schema_is_generated_from_the_source():
    from tracer.accel.base import COUNTER_SCHEMA
    table = _load("hooks").counter_table(REPO / "tracer" / "accel" / "base.py").splitlines()
    assert len(table) == 2 + len(COUNTER_SCHEMA)
    assert table[2].startswith("| 0 | `setups` |") and table[4].startswith("| 2 | `tests` | ray/triangle tests")


def test_rest_docstrings_become_markdown():
    convert = _load("griffe_rst").rst_to_markdown
    src = ("Uses :func:`tracer.accel.geometry.ray_triangle`, :class:`~costmodel.derive.Result` and\n"
           "`Dask's TLS docs <https://distributed.dask.org/en/stable/tls.html>`_. For example::\n\n"
           "    build(scene)\n\n"
           "=====  ==========\n"
           "``a``  first row\n"
           "       continued\n"
           "``b``  second\n"
           "=====  ==========\n\n"
           "after\n")
    assert convert(src).splitlines() == [
        "Uses `tracer.accel.geometry.ray_triangle`, `Result` and",
        "[Dask's TLS docs](https://distributed.dask.org/en/stable/tls.html). For example:", "",
        "    build(scene)", "", "",
        "- ``a``: first row continued", "- ``b``: second", "", "", "after"]

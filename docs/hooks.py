"""mkdocs hook: the tables that restate the code are generated from it, so the pages cannot fall
behind. On targets.md the table of targets comes from ``experiments.run.TARGETS`` (the CLI's own
table); a target with no section of its own on the page, or a section for a target the CLI no longer
has, is a warning, which ``mkdocs build --strict`` turns into a failed build. On structures.md the
counter schema comes from ``tracer.accel.base.COUNTER_SCHEMA`` (read from the source: the hook
imports no Numba). Loaded by mkdocs.yml (``hooks``), never by gridcost."""
from __future__ import annotations

import ast
import logging
import re
import sys
from pathlib import Path

log = logging.getLogger("mkdocs.hooks.targets")

#: where the generated table goes on targets.md
MARKER = "<!-- targets-table -->"
#: where the counter schema goes on structures.md
COUNTERS_MARKER = "<!-- counter-schema -->"
#: a target's own section: a level-3 heading holding its name in backticks
SECTION = re.compile(r"^###\s+`([a-z0-9-]+)`", re.M)


def _targets() -> tuple[dict, list]:
    root = str(Path(__file__).resolve().parent.parent)
    if root not in sys.path:  # mkdocs may run from an environment where gridcost is not installed
        sys.path.insert(0, root)
    from experiments.run import ALL_ORDER, TARGETS
    return TARGETS, ALL_ORDER


def _cell(text: str) -> str:
    return text.replace("%%", "%").replace("|", "\\|")


def target_table(targets: dict, all_order: list) -> str:
    """Markdown: every target, its module, its one-line help and whether ``all`` runs it."""
    rows = ["| target | module | what it does (`gridcost <target> --help`) | in `all` |", "|---|---|---|---|"]
    for name, (module, helptext) in targets.items():
        rows.append(f"| [`{name}`](#{name}) | `{module}` | {_cell(helptext)} | {'yes' if name in all_order else ''} |")
    rows.append("| [`all`](#all) | | every paper target in dependency order | |")
    return "\n".join(rows)


def counter_table(base: Path) -> str:
    """Markdown: the counter columns of ``COUNTER_SCHEMA`` in ``base`` (tracer/accel/base.py), in order."""
    for node in ast.parse(base.read_text()).body:
        target = getattr(node, "target", None) or (node.targets[0] if isinstance(node, ast.Assign) else None)
        if isinstance(target, ast.Name) and target.id == "COUNTER_SCHEMA":
            schema = ast.literal_eval(node.value)
            return "\n".join(["| column | counter | what it counts |", "|---|---|---|"]
                             + [f"| {i} | `{k}` | {_cell(v)} |" for i, k in enumerate(schema) for v in [schema[k]]])
    raise RuntimeError(f"no COUNTER_SCHEMA in {base}")


def on_page_markdown(markdown: str, page, **kwargs) -> str:
    if page.file.src_uri == "structures.md":
        if COUNTERS_MARKER not in markdown:
            log.warning("structures.md: the marker %s for the counter schema is missing", COUNTERS_MARKER)
            return markdown
        base = Path(__file__).resolve().parent.parent / "tracer" / "accel" / "base.py"
        return markdown.replace(COUNTERS_MARKER, counter_table(base))
    if page.file.src_uri != "targets.md":
        return markdown
    targets, all_order = _targets()
    documented = set(SECTION.findall(markdown))
    for name in targets:
        if name not in documented:
            log.warning("targets.md: target %r (experiments/run.py TARGETS) has no section '### `%s`'", name, name)
    for name in sorted(documented - set(targets) - {"all"}):
        log.warning("targets.md: a section documents %r, which is not in experiments.run.TARGETS", name)
    if MARKER not in markdown:
        log.warning("targets.md: the marker %s for the generated table is missing", MARKER)
        return markdown
    return markdown.replace(MARKER, target_table(targets, all_order))

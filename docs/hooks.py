"""mkdocs hook: the table of targets on targets.md comes from ``experiments.run.TARGETS`` (the CLI's
own table), so the page cannot fall behind the CLI. A target with no section of its own on the page,
or a section for a target the CLI no longer has, is a warning, which ``mkdocs build --strict`` turns
into a failed build. Loaded by mkdocs.yml (``hooks``), never by gridcost."""
from __future__ import annotations

import logging
import re
import sys
from pathlib import Path

log = logging.getLogger("mkdocs.hooks.targets")

#: where the generated table goes on targets.md
MARKER = "<!-- targets-table -->"
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


def on_page_markdown(markdown: str, page, **kwargs) -> str:
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

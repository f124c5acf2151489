"""A griffe extension for the API reference: gridcost's docstrings are written in a light reST
(``code``, :class:`X`, ``::`` before a literal block, simple ``====`` tables, `text <url>`_ links),
which Markdown would print verbatim or, for the tables, run into one paragraph. This turns those
few constructs into their Markdown equivalents before mkdocstrings renders a docstring; the text
itself is left alone. Loaded by mkdocs.yml (mkdocstrings ``extensions``), never by gridcost."""
from __future__ import annotations

import re

import griffe

#: :role:`target`, :role:`~a.b.target` (shown as ``target``), :role:`text <target>` (shown as ``text``)
ROLE = re.compile(r":(?:py:)?(?:class|func|meth|data|mod|attr|obj|exc|const):`(~?)([^`<]+?)(?:\s*<([^>]+)>)?`")
#: `text <https://...>`_
LINK = re.compile(r"`([^`<]+?)\s*<(https?://[^>]+)>`_")
#: a border line of a simple table: two or more runs of '=' separated by spaces
BORDER = re.compile(r"^(\s*)=+(\s+=+)+\s*$")


def _role(m: re.Match) -> str:
    tilde, text, target = m.groups()
    if target:
        return f"`{text.strip()}`"
    return f"`{text.rsplit('.', 1)[-1]}`" if tilde else f"`{text}`"


def _columns(border: str) -> list[tuple[int, int]]:
    """(start, end) of each column, read off a border line."""
    return [(m.start(), m.end()) for m in re.finditer(r"=+", border)]


def _split(line: str, cols) -> list[str]:
    """A row's cells; the last column runs to the end of the line."""
    cells = []
    for i, (start, end) in enumerate(cols):
        stop = cols[i + 1][0] if i + 1 < len(cols) else len(line)
        cells.append(line[start:stop].strip())
    return cells


def _table(lines: list[str], cols) -> list[str]:
    """A simple table's rows (between its borders) as Markdown: a header-less two-column table is a
    list ("- first: second"), anything else a pipe table. A row whose first cell is empty continues
    the row above it."""
    borders = [i for i, ln in enumerate(lines) if BORDER.match(ln)]
    header = None
    if len(borders) >= 3:  # top border, header, middle border, body, bottom border
        header = _split(" ".join(lines[borders[0] + 1:borders[1]]), cols)
        body = lines[borders[1] + 1:borders[-1]]
    else:
        body = lines[borders[0] + 1:borders[-1]]
    rows: list[list[str]] = []
    for ln in body:
        if not ln.strip():
            continue
        cells = _split(ln, cols)
        if rows and not cells[0]:
            rows[-1] = [a + (" " + b if b else "") for a, b in zip(rows[-1], cells)]
        else:
            rows.append(cells)
    if header is None and len(cols) == 2:
        return [f"- {a}: {b}" for a, b in rows]
    header = header or [""] * len(cols)
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(cols)]
    return out + ["| " + " | ".join(r) + " |" for r in rows]


def rst_to_markdown(text: str) -> str:
    """The reST constructs gridcost's docstrings use, as Markdown."""
    text = LINK.sub(r"[\1](\2)", ROLE.sub(_role, text))
    lines, out, i = text.splitlines(), [], 0
    while i < len(lines):
        line = lines[i]
        if BORDER.match(line):
            cols = _columns(line)
            ends = [j for j in range(i + 1, len(lines)) if BORDER.match(lines[j])]
            # the table ends at the last border before a blank line that follows a border
            last = None
            for j in ends:
                last = j
                if j + 1 >= len(lines) or not lines[j + 1].strip():
                    break
            if last is not None:
                out += [""] + _table(lines[i:last + 1], cols) + [""]
                i = last + 1
                continue
        if line.rstrip().endswith("::") and not line.strip() == "::":
            line = line.rstrip()[:-1]  # "Example::" -> "Example:", the indented block follows
        out.append(line)
        i += 1
    return "\n".join(out)


class ReSTToMarkdown(griffe.Extension):
    """Rewrites every docstring once its object is loaded."""

    def on_instance(self, *, obj: griffe.Object, **kwargs) -> None:
        if obj.docstring is not None:
            obj.docstring.value = rst_to_markdown(obj.docstring.value)

"""The two shapes a paper's number takes here: one printed value (:class:`Cited`) and one printed
table (:class:`CitedTable`), each with the verbatim text it stands in and where it stands.

Every number an output prints as a paper's comes from one of these; a number we recompute from a
paper's values is a :class:`Derived` that names what it was computed from. ``tests/test_papers.py``
finds every quote in the paper's text (``../shared/papers/*.md``, whitespace-normalised) and the
printed value inside its quote, so a typo in a value or a quote fails a test.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path


@dataclass(frozen=True)
class Cited:
    """A number as the paper prints it.

    ``value`` in ``unit``; ``where`` names the table, figure or section; ``quote`` is the shortest
    verbatim stretch of the paper's text that holds it; ``printed`` is how the value is written in
    the quote when that is not its plain form (``"2.4 \\\\times"``, ``"80%"``)."""
    value: float
    unit: str
    where: str
    quote: str
    printed: str = ""

    def __float__(self) -> float:
        return float(self.value)

    @property
    def text(self) -> str:
        """The value as the quote writes it."""
        return self.printed or plain(self.value)

    def cite(self) -> str:
        """``value unit (where)``, the form a summary prints."""
        txt = self.printed if self.printed and "\\" not in self.printed else plain(self.value)
        return f"{txt}{'' if self.unit in ('', '×', '%') else ' '}{self.unit} ({self.where})"


@dataclass(frozen=True)
class Derived:
    """A number recomputed from a paper's printed values (never printed as the paper's own)."""
    value: float
    how: str
    sources: tuple = ()

    def __float__(self) -> float:
        return float(self.value)


@dataclass(frozen=True)
class CitedTable:
    """A table as the paper prints it: ``columns`` (with ``units``), one tuple per row in ``rows``
    and, for each row, the verbatim line it stands in (``lines``); ``caption`` is the verbatim
    caption. Rows may carry a key column of ours first (``key``: our stand-in scene), which is not
    the paper's and is not checked against its text."""
    where: str
    caption: str
    columns: tuple
    units: tuple
    rows: tuple
    lines: tuple
    key: str = ""
    checked: tuple = field(default=())  # columns whose values must appear in their row's line

    def __post_init__(self):
        width = len(self.columns) + (1 if self.key else 0)
        if len(self.units) != len(self.columns):
            raise ValueError(f"{self.where}: {len(self.units)} units for {len(self.columns)} columns")
        if any(len(r) != width for r in self.rows) or len(self.lines) != len(self.rows):
            raise ValueError(f"{self.where}: rows, lines and columns do not line up")

    def records(self) -> list[dict]:
        """One dict per row, keyed by column name (and ``key`` first when the table has one)."""
        names = ((self.key,) if self.key else ()) + tuple(self.columns)
        return [dict(zip(names, r)) for r in self.rows]

    def by_key(self) -> dict:
        """Our stand-in scene -> the row's dict (tables with a ``key`` only)."""
        if not self.key:
            raise ValueError(f"{self.where} has no key column")
        return {r[self.key]: r for r in self.records()}

    def cell(self, row: int, column: str) -> Cited:
        """One printed cell as a :class:`Cited` (its row's line as the quote)."""
        rec = self.records()[row]
        return Cited(rec[column], self.units[self.columns.index(column)], self.where, self.lines[row])

    def frame(self):
        import pandas as pd
        return pd.DataFrame(self.records())


def plain(v) -> str:
    """A value as a paper writes it plainly: integers without a decimal point, others as given."""
    if isinstance(v, float) and v.is_integer():
        return str(int(v))
    return str(v)


def normalise(text: str) -> str:
    """Whitespace runs to one space, so a quote matches across the text's line and tab breaks."""
    return re.sub(r"\s+", " ", text).strip()


def papers_dir() -> Path | None:
    """../shared/papers beside the repository (absent in a user's clone: tests then skip)."""
    p = Path(__file__).resolve().parents[3] / "shared" / "papers"
    return p if p.is_dir() else None

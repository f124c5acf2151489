"""Every number printed as a paper's is in the paper: each quote is found in the paper's text and
each printed value inside its quote (skips in a clone without ../shared/papers)."""
from __future__ import annotations

import pytest

from costmodel.papers import MODULES, Cited, CitedTable, citations, module
from costmodel.papers.cite import normalise, papers_dir

PAPERS = papers_dir()
needs_text = pytest.mark.skipif(PAPERS is None, reason="../shared/papers is not beside the repository")


def _numbers(line: str) -> set:
    """Every number written in a table line (thousands separators and % signs dropped)."""
    out = set()
    for tok in line.split():
        try:
            out.add(float(tok.replace(",", "").rstrip("%")))
        except ValueError:
            pass
    return out


def _text(name: str) -> str:
    return normalise((PAPERS / f"{module(name).PAPER}.md").read_text())


@needs_text
@pytest.mark.parametrize("name", MODULES)
def test_every_quote_is_in_the_paper_and_holds_its_value(name):
    text = _text(name)
    cites = citations(name)
    assert len(cites) >= 5
    for c in cites:
        if isinstance(c, Cited):
            q = normalise(c.quote)
            assert q in text, (c.where, c.quote)
            assert c.text in q, (c.where, c.text, c.quote)
        else:
            assert normalise(c.caption) in text, c.caption
            for row, line in zip(c.records(), c.lines):
                line = normalise(line)
                assert line in text, (c.where, line)
                numbers = _numbers(line)
                for col in c.checked:
                    assert float(row[col]) in numbers, (c.where, col, row[col], line)


def test_a_wrong_value_or_quote_is_caught():
    """The check itself can fail: a value that is not in its quote, a row that does not fit."""
    c = Cited(2.5, "×", "Sec 4.2", "a $2.4 \\times$ speedup for the conference room")
    assert c.text not in normalise(c.quote)
    with pytest.raises(ValueError, match="do not line up"):
        CitedTable("T", "cap", ("a", "b"), ("", ""), ((1, 2, 3),), ("1 2",))


def test_tables_read_by_our_scene():
    from costmodel.papers import ize2007
    row = ize2007.TABLE2.by_key()["conference-room"]
    assert (row["model"], row["N"], row["theoretical_M"]) == ("conference", 282664, 2261312)
    assert ize2007.TABLE2.cell(4, "penalty_pct").value == 5
    assert ize2007.TWO_LEVEL_GAIN["conference-room"].cite() == "2.4× (Sec 4.2)"

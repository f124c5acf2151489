"""The scorecard: verdict rules, and every paper artefact covered from the committed results."""
from __future__ import annotations

import shutil
from pathlib import Path

import pandas as pd
import pytest

from costmodel.papers.cite import Cited
from experiments.tools.scorecard import COLUMNS, judge, precision

REPO = Path(__file__).resolve().parents[1]
C = Cited(2.4, "×", "Sec 4.2", "a $2.4 \\times$ speedup for the conference room")


def test_precision_is_half_the_last_printed_digit():
    assert precision(C) == pytest.approx(0.05)
    assert precision(Cited(618, "×", "", "")) == 0.5
    assert precision(Cited(7 / 9, "", "", "", "7/9")) == 0.0


@pytest.mark.parametrize("ours, lo, hi, cf, verdict", [
    (2.42, None, None, None, "reproduced"),          # within ±0.05
    (1.9, 1.5, 2.6, None, "reproduced"),             # inside our interval
    (0.9, None, None, 2.38, "explained"),            # the work counterfactual lands
    (0.9, None, None, 1.1, "contradicted"),          # it does not
    (None, None, None, None, "not measurable here"),
])
def test_verdicts(ours, lo, hi, cf, verdict):
    v, why = judge(C, ours, lo, hi, cf=cf, cf_how="work ratio")
    assert v == verdict, why
    if verdict == "contradicted":
        assert "13 % of the gap" in why  # (1.1 - 0.9) / (2.4 - 0.9)


def test_scorecard_covers_every_table_and_figure_from_committed_results(tmp_path):
    from experiments.run import main
    out = tmp_path / "results"
    shutil.copytree(REPO / "results", out, ignore=shutil.ignore_patterns("points"))
    shutil.rmtree(out / "wald-fig8")  # a missing input is a row that says so
    assert main(["scorecard", "--out", str(out), "--json"]) == 0
    df = pd.read_csv(out / "scorecard" / "scorecard.csv")
    assert list(df.columns[:len(COLUMNS)]) == COLUMNS
    have = set(zip(df.paper, df.artefact))
    for want in [("Ize 2007", "Table 2"), ("Ize 2007", "Table 3"), ("Ize 2007", "Table 4"), ("Ize 2007", "Sec 4.2"),
                 ("Ize 2007", "Sec 4.4"), ("Ize 2007", "Sec 5"), ("Hapala 2011", "Table 1"),
                 ("Hapala 2011", "Sec 4, Fig 1"), ("Hapala 2011", "Sec 4, Fig 2"), ("Wald 2006", "Table 1"),
                 ("Wald 2006", "Table 3"), ("Wald 2006", "Table 4"), ("Wald 2006", "Fig 6"), ("Wald 2006", "Fig 7"),
                 ("Wald 2006", "Fig 8"), ("Fournier 1993", "Table 1")]:
        assert want in have, want
    assert (df[df.paper == "Ize 2007"].artefact.str.startswith("Eq")).sum() >= 10  # every numbered equation
    assert set(df.verdict) <= {"reproduced", "explained", "contradicted", "not measurable here"}
    fig8 = df[df.artefact == "Fig 8"].iloc[0]
    assert fig8.verdict == "not measurable here" and "gridcost wald-fig8" in fig8.explanation
    room = df[(df.artefact == "Sec 4.2") & df.claim.str.contains("conference-room")].iloc[0]
    assert room.paper_value == 2.4 and "conference room" in room.quote

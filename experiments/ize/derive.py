"""``python -m experiments.run derive [--json]``: the sympy derivations of every Ize, Shirley & Parker 2007 grid
cost model beside the paper's stated results (see ``costmodel.derive``).

Text mode prints a table (derived exponent of N, the paper's, match/MISMATCH) then each model's cost, optimum and
notes; ``--json`` prints exactly one JSON object ``{"models": {...}}``.  Both write ``<out>/derive/derive.json``
and ``<out>/derive/summary.md`` atomically.
"""
from __future__ import annotations

import json
import os
import time

from experiments.core.store import atomic_write


def add_arguments(parser) -> None:  # noqa: ARG001 - the common options are all this target needs
    """No target-specific options."""


def _flag(ok) -> str:
    return "" if ok is None else ("match" if ok else "MISMATCH")


def _pair(entry: dict, what: str) -> str:
    ours, paper = entry.get(f"{what}_exponent"), entry.get(f"paper_{what}_exponent")
    if ours is None:
        return ""
    return f"{ours} / {paper}" + ("" if entry.get(f"{what}_match") in (None, True) else " MISMATCH")


def _rows(models: dict) -> list[tuple]:
    rows = []
    for name, e in models.items():
        failed = [c for c, ok in e["checks"].items() if not ok]
        if e["formula_match"] is False:
            failed.insert(0, "formula")
        rows.append((name, e["equation"], f"{e['quantity']} vs {e['wrt']}", e["exponent"], e["paper"],
                     _flag(e["match"]), _pair(e, "time"), _pair(e, "space"),
                     "all" if not failed else "FAILED: " + ", ".join(failed)))
    return rows


HEADER = ("model", "paper eq", "quantity", "derived exp", "paper exp", "", "time exp (ours/paper)",
          "space exp (ours/paper)", "checks")


def render_text(report: dict) -> str:
    rows = [HEADER] + _rows(report["models"])
    widths = [max(len(str(r[i])) for r in rows) for i in range(len(HEADER))]
    line = lambda r: "  ".join(str(c).ljust(w) for c, w in zip(r, widths)).rstrip()  # noqa: E731
    out = ["Ize, Shirley & Parker 2007 cost models: sympy derivation vs the paper", "",
           line(rows[0]), line(["-" * w for w in widths])] + [line(r) for r in rows[1:]] + [""]
    for name, e in report["models"].items():
        out.append(f"[{name}] {e['equation']}: {_flag(e['match'])}")
        out.append(f"  cost     T = {e['cost']}")
        out.append(f"  optimum  {e['quantity']} = {e['optimum']}")
        if e["paper_formula"] is not None:
            out.append(f"  paper    {e['paper_formula']}  ({_flag(e['formula_match'])})")
        if e["optimal_time"] is not None:
            out.append(f"  T*       = {e['optimal_time']}")
        if e["note"]:
            out.append(f"  note     {e['note']}")
    n_bad = sum(not e["match"] for e in report["models"].values())
    out += ["", f"{len(report['models']) - n_bad} of {len(report['models'])} models match the paper; "
                f"{n_bad} MISMATCH."]
    return "\n".join(out) + "\n"


def render_markdown(report: dict) -> str:
    esc = lambda s: str(s).replace("|", "\\|")  # noqa: E731
    out = ["# derive: Ize, Shirley & Parker 2007 cost models (sympy) vs the paper", "",
           "Exponents are exact; `quantity vs N2` means per subgrid, in the subgrid's own primitive count.", "",
           "| " + " | ".join(h or "match" for h in HEADER) + " |", "|" + "---|" * len(HEADER)]
    out += ["| " + " | ".join(esc(c) for c in r) + " |" for r in _rows(report["models"])]
    out += ["", "## Models", ""]
    for name, e in report["models"].items():
        out.append(f"- **{name}** ({e['equation']}, {_flag(e['match'])}): cost `T = {e['cost']}`; "
                   f"optimum `{e['optimum']}`" + (f"; paper `{e['paper_formula']}`" if e["paper_formula"] else "")
                   + (f". {e['note']}" if e["note"] else ""))
    return "\n".join(out) + "\n"


def main(ctx, args) -> int:
    from costmodel.derive_nested import report as derive_report

    started = time.time()
    rep = derive_report()
    outdir = os.path.join(getattr(args, "out", None) or "results", "derive")
    atomic_write(os.path.join(outdir, "derive.json"), json.dumps(rep, indent=2) + "\n")
    atomic_write(os.path.join(outdir, "summary.md"), render_markdown(rep))
    ctx.write_meta(outdir, "derive", started, models=len(rep["models"]))
    if getattr(args, "json", False):
        print(json.dumps(rep))
    else:
        print(render_text(rep), end="")
    return 0

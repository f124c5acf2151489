"""Figure helpers every target shares: save PNG + PDF atomically, lay out and close, log axes that
survive degenerate data."""
from __future__ import annotations

import io
from pathlib import Path

from experiments.core.store import REPO, atomic_write


def figure_dir(out) -> Path:
    """The figures directory that belongs to results directory ``out``: the repository's
    ``paper_figs/`` for the default ``results/``, else ``<out>/paper_figs`` (a run with ``--out
    /tmp/x`` never overwrites the committed figures)."""
    out = Path(out).resolve()
    return REPO / "paper_figs" if out == (REPO / "results").resolve() else out / "paper_figs"


def save_figure(fig, name: str, out_dir) -> list[Path]:
    """Save ``fig`` as <out_dir>/<name>.png and .pdf (atomically)."""
    paths = []
    for ext in ("png", "pdf"):
        buf = io.BytesIO()
        fig.savefig(buf, format=ext, dpi=150, bbox_inches="tight")
        paths.append(atomic_write(Path(out_dir) / f"{name}.{ext}", buf.getvalue()))
    return paths


def finish_figure(fig, name: str, out_dir) -> list[Path]:
    """Lay out ``fig``, save it (:func:`save_figure`) and close it."""
    import matplotlib.pyplot as plt
    fig.tight_layout()
    paths = save_figure(fig, name, out_dir)
    plt.close(fig)
    return paths


def log_scale(ax, axis: str, values) -> bool:
    """Put ``axis`` ("x" or "y") of ``ax`` on a log scale when ``values`` hold a positive finite
    number; otherwise leave it linear and say on the panel that there is nothing to draw on a log
    scale (a --quick run can produce such data; matplotlib would raise). Returns True when log."""
    import numpy as np
    v = np.asarray(values, dtype=float).ravel()
    if (np.isfinite(v) & (v > 0)).any():
        (ax.set_xscale if axis == "x" else ax.set_yscale)("log")
        return True
    ax.text(0.5, 0.5, "no positive values to draw on a log scale", transform=ax.transAxes, ha="center",
            va="center", fontsize=8, color="gray")
    return False

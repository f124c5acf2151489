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
        from matplotlib.ticker import LogLocator
        (ax.set_xscale if axis == "x" else ax.set_yscale)("log")
        # minor ticks at 2 and 5 only: a panel spanning many decades otherwise lays out 8 per decade
        (ax.xaxis if axis == "x" else ax.yaxis).set_minor_locator(LogLocator(base=10.0, subs=(2.0, 5.0)))
        return True
    ax.text(0.5, 0.5, "no positive values to draw on a log scale", transform=ax.transAxes, ha="center",
            va="center", fontsize=8, color="gray")
    return False


def subplots(*args, **kw):
    """``matplotlib.pyplot.subplots(*args, **kw)`` on the non-interactive Agg backend: (fig, axes)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt.subplots(*args, **kw)


def finish_log_panels(ctx, fig, axes, titles, xlabel: str, ylabel: str, name: str, label_size=None) -> list[Path]:
    """Label the row of panels ``axes[0]`` (one per title) on a log x axis: title (size 8), x label
    and small ticks on each, the y label on the first, the legend on the last (``label_size``: the
    labels' font size, None for matplotlib's); then save ``fig`` as ``name`` (``ctx.finish_figure``)."""
    kw = {} if label_size is None else {"fontsize": label_size}
    for ax, title in zip(axes[0], titles):
        ax.set_xscale("log")
        ax.set_title(title, fontsize=8)
        ax.set_xlabel(xlabel, **kw)
        ax.tick_params(labelsize=7)
    axes[0][0].set_ylabel(ylabel, **kw)
    axes[0][-1].legend(fontsize=6)
    return ctx.finish_figure(fig, name)


def row_legend(axes, **kw) -> None:
    """One legend for a row of panels: every distinct label of ``axes`` once, on the last panel,
    outside its right edge (``kw`` overrides the placement)."""
    handles, labels = [], []
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    axes[-1].legend(handles, labels, **{"fontsize": 6, "loc": "upper left", "bbox_to_anchor": (1.02, 1.0), **kw})

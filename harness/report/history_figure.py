"""The performance-history figure: benchmark values against commit date."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from harness.kit.figure_style import (
    label_text,
    loglog_axes,
    new_figure,
    styled,
)
from harness.kit.figure_svg import Figure, to_svg

__all__ = ['perf_history_figure']


@styled
def perf_history_figure(history: pd.DataFrame, max_panels: int = 12,
                        max_lines: int = 8) -> Figure | None:
    """Benchmark value against commit date: one panel per benchmark (up to `max_panels`), one
    line per parameter set (up to `max_lines`)."""
    if history is None or history.empty:
        return None
    h = history.copy()
    h["date"] = pd.to_datetime(h["date"], errors="coerce", utc=True)
    h = h[np.isfinite(pd.to_numeric(h["value"], errors="coerce"))]
    if h.empty:
        return None
    benches = list(dict.fromkeys(h["benchmark"].astype(str)))[:max_panels]
    ncols = min(3, len(benches))
    nrows = int(math.ceil(len(benches) / ncols))
    fig, axes = new_figure(nrows, ncols, size=(3.4 * ncols + 0.6, 2.5 * nrows + 0.4))
    for ax in axes.flat[len(benches):]:
        ax.set_visible(False)
    for ax, bench in zip(axes.flat, benches, strict=False):
        g = h[h["benchmark"].astype(str) == bench]
        unit = str(g["unit"].dropna().iloc[0]) if g["unit"].notna().any() else ""
        for params, s in list(g.groupby(g["params"].astype(str), sort=False))[:max_lines]:
            s = s.sort_values("date")
            ax.plot(s["date"], pd.to_numeric(s["value"]), marker="o", ms=3, lw=1.0,
                    label=label_text(params) if params not in ("", "()", "None") else None)
        if unit in ("seconds", "s", "bytes"):
            loglog_axes(ax, x=False)
        ax.set_title(label_text(bench), fontsize=8)
        ax.set_ylabel(unit, fontsize=7)
        ax.tick_params(labelsize=6, axis="both")
        for lbl in ax.get_xticklabels():
            lbl.set_rotation(30)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=5.5, frameon=False)
    return to_svg(fig, "perf-history", "benchmark values against commit date",
                  h.reset_index(drop=True))

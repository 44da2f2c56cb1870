"""Reversibility figure: return error over the rounding bound against the number of steps."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pandas as pd

from harness.kit import figure_style as fs
from harness.kit.figure_svg import Figure, to_svg

__all__ = ['reversibility_figure']


@fs.styled
def reversibility_figure(table: pd.DataFrame, palette: fs.Palette,
                         symmetric: Mapping[str, bool]) -> Figure | None:
    """Return error over the rounding bound against the number of steps N, all problems in one
    figure, one panel per family: for each method the worst case against its claim over the
    problems (the largest ratio for a method claimed symmetric, solid, which must stay at or
    below 1; the smallest for one not claimed, dashed, which must stay above). The per-problem
    values are in the figure's CSV and the section's table."""
    need = {"stepper", "steps", "return_error_ulps", "rounding_bound_ulps"}
    if table.empty or not need <= set(table.columns):
        return None
    t = table.assign(ratio=table["return_error_ulps"].astype(float)
                     / table["rounding_bound_ulps"].astype(float))
    groups = fs.panels(list(dict.fromkeys(t["stepper"])), palette.families)
    fig, axes = fs.small_multiples(len(groups), sharex=True, sharey=True)
    for ax, (title, members) in zip(axes, groups, strict=True):
        for stepper in members:
            sym = symmetric.get(stepper, False)
            g = t[t["stepper"] == stepper].groupby("steps")["ratio"]
            worst = (g.max() if sym else g.min()).sort_index()
            y = worst.to_numpy(float)
            y = np.where(np.isfinite(y), np.clip(y, 1e-3, fs.LOG_CEILING), np.nan)
            ax.plot(worst.index.to_numpy(float), y, "-" if sym else "--", marker=palette.marker(stepper),
                    color=palette.colour(stepper), ms=3, lw=0.9,
                    label=f"{fs.label_text(stepper)}{' (symmetric)' if sym else ''}")
        ax.axhline(1.0, color="k", ls=":", lw=1.0, label="rounding bound")
        fs.loglog_axes(ax)
        ax.set_title(title)
        fs.small_ticks(ax)
        fs.panel_legend(ax, loc="upper left")
    fig.supxlabel("steps N forward, then N back", fontsize=8)
    fig.supylabel("return error / rounding bound (0 at 10⁻³)", fontsize=8)
    fig.suptitle("Time reversibility, every problem", fontsize=8)
    cols = [c for c in ("stepper", "problem", "steps", "h", "return_error", "return_error_ulps",
                        "rounding_bound_ulps", "verdict") if c in table]
    return to_svg(fig, "reversibility", "return error over the rounding bound against N",
                  table[cols].reset_index(drop=True))

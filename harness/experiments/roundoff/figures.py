"""Roundoff figure: position error against step size at a fixed step count, with the
truncation error alone."""

from __future__ import annotations

import pandas as pd

from harness.kit import figure_style as fs
from harness.kit.figure_svg import Figure, to_svg

__all__ = ['roundoff_figure']


@fs.styled
def roundoff_figure(rows: pd.DataFrame, palette: fs.Palette) -> Figure | None:
    """Position error against h at a fixed step count, one panel per problem, with the
    truncation error extrapolated from the largest step.

    Parameters
    ----------
    rows : DataFrame, the roundoff rows (one per stepper, problem and h).
    palette : Palette

    Returns
    -------
    Figure or None: None for no rows.
    """
    if "series" in rows:
        rows = rows[rows["series"].fillna("sweep") == "sweep"]
    if rows.empty:
        return None
    problems = list(dict.fromkeys(rows["problem"]))
    fig, axes = fs.new_figure(1, len(problems), size=(3.9 * len(problems) + 1.6, 3.8))
    for ax, problem in zip(axes[0], problems, strict=True):
        g = rows[rows["problem"] == problem]
        for stepper, s in g.groupby("stepper", sort=False):
            s = s.sort_values("h")
            ax.plot(s["h"], fs.clip_log(s["error"]), "-",
                    marker=palette.marker(stepper), ms=4, color=palette.colour(stepper),
                    label=fs.label_text(stepper))
        first = g.sort_values("h").groupby("stepper").tail(1)
        if len(first):
            s = g[g["stepper"] == first["stepper"].iloc[0]].sort_values("h")
            ax.plot(s["h"], fs.clip_log(s["truncation_estimate"]), ":",
                    color="k", lw=0.9, label="truncation alone (∝ h^(p+1) at fixed N)")
        fs.loglog_axes(ax)
        ax.set_xlabel("step size h")
        ax.set_title(f"{fs.label_text(problem)}, N = {int(g['n_steps'].iloc[0])} steps")
    axes[0][0].set_ylabel("relative position error")
    fs.legend_outside(axes[0][-1], layout=False)
    cols = [c for c in ("stepper", "problem", "n_steps", "h", "error", "truncation_estimate") if c in rows]
    return to_svg(fig, "roundoff", "position error against step size at a fixed step count",
                  rows[cols].reset_index(drop=True))

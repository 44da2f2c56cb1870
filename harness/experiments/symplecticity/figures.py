"""Symplecticity figure: the deviation from symplecticity per stepper and problem."""

from __future__ import annotations

import numpy as np
import pandas as pd

from harness.kit import figure_style as fs
from harness.kit.figure_svg import Figure, to_svg

__all__ = ['symplecticity_figure']


@fs.styled
def symplecticity_figure(summary: pd.DataFrame, palette: fs.Palette) -> Figure | None:
    """Deviation from symplecticity per stepper (x, grouped by family) and problem (one point
    each), log scale, with the finite-difference threshold the verdict uses; claimed-symplectic
    steppers filled, the others hollow."""
    if summary.empty or "deviation" not in summary:
        return None
    s = summary.assign(_d=summary["deviation"].astype(float))
    names = sorted(dict.fromkeys(s["stepper"]), key=lambda n: (palette.family(n), n))
    fig, axes = fs.new_figure(size=(max(5.0, 0.2 * len(names) + 1.6), 3.4))
    ax = axes[0][0]
    for i, name in enumerate(names):
        g = s[s["stepper"] == name]
        claimed = bool(g["claimed_symplectic"].iloc[0]) if "claimed_symplectic" in g else False
        c = palette.colour(name)
        ax.plot(np.full(len(g), i), fs.clip_log(g["_d"]), linestyle="none", marker=palette.marker(name),
                ms=4, color=c, markerfacecolor=c if claimed else "none")
    if "threshold" in s:
        thr = s["threshold"].astype(float)
        thr = thr[np.isfinite(thr) & (thr > 0)]
        if len(thr):
            ax.axhline(float(thr.max()), color="k", ls=":", lw=1.0)
            ax.text(len(names) - 0.5, float(thr.max()), " threshold", fontsize=6.5, va="bottom",
                    ha="right")
    fs.loglog_axes(ax, x=False)
    ax.set_xticks(range(len(names)), [fs.label_text(n) for n in names], rotation=60, ha="right", fontsize=6.5)
    ax.set_xlim(-0.6, len(names) - 0.4)
    ax.set_ylabel(f"‖JᵀΩJ − Ω‖ / ‖J‖² (0 at {fs.LOG_FLOOR:g})", fontsize=7.5)
    ax.set_title("Symplecticity: filled = claimed symplectic, hollow = not claimed", fontsize=8)
    ax.tick_params(axis="y", labelsize=6.5)
    cols = [c for c in ("stepper", "problem", "h", "deviation", "threshold", "claimed_symplectic",
                        "verdict") if c in summary]
    return to_svg(fig, "symplecticity", "deviation from symplecticity per stepper",
                  summary[cols].reset_index(drop=True))

"""Work figures: error against evaluations per problem (the best method of each family bold)."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import pandas as pd
from matplotlib.lines import Line2D

from harness.kit.figure_style import (
    LEGEND_CHAR_W,
    LOG_CEILING,
    Palette,
    label_text,
    loglog_axes,
    small_multiples,
    small_ticks,
    styled,
)
from harness.kit.figure_svg import Figure, to_svg

__all__ = ['WORK_TARGET_ERROR', 'best_per_family', 'work_precision_figure']

# -- work-precision -----------------------------------------------------------------------------------
# The precision the "best of each family" is judged at: every method of the catalogue reaches it
# on the work-precision problems, so the cheapest one to get there is well defined.
WORK_TARGET_ERROR = 1e-6
# Markers on a bold line: enough to tell the family (a marker shape each), not one per point
# of a sweep of dozens (every point is in the CSV).
MARKERS_PER_LINE = 8


def best_per_family(rows: pd.DataFrame, families: Mapping[str, str], cost: str = "rhs_evals"
                    ) -> dict[str, str]:
    """family -> its method that reaches WORK_TARGET_ERROR for the least `cost` on these rows
    (one problem); a family where none reaches it: the method with the lowest error.

    Parameters
    ----------
    rows : DataFrame, one problem's work-precision rows.
    families : mapping of str to str, stepper -> family.
    cost : str, optional, the cost column (default 'rhs_evals').

    Returns
    -------
    dict of str to str: empty when `rows` is empty or lacks `cost`.
    """
    best: dict[str, tuple[int, float, str]] = {}
    if rows.empty or cost not in rows:
        return {}
    err = rows["error"].astype(float)
    x = rows[cost].astype(float)
    ok = np.isfinite(err) & (err > 0) & np.isfinite(x) & (x > 0)
    for stepper, g in rows[ok].groupby("stepper", sort=False):
        e, c = g["error"].astype(float), g[cost].astype(float)
        hit = c[e <= WORK_TARGET_ERROR]
        score = (0, float(hit.min()), stepper) if len(hit) else (1, float(e.min()), stepper)
        fam = families.get(stepper, "")
        if fam not in best or score < best[fam]:
            best[fam] = score
    return {f: s[2] for f, s in best.items()}


@styled
def work_precision_figure(problem: str, rows: pd.DataFrame, palette: Palette,
                          adaptive: Mapping[str, bool]) -> Figure | None:
    """Error against evaluations on one problem, one line per method; the best method of each
    family (`best_per_family`) drawn bold and named in the legend, the others thin and faint.
    Adaptive peers dashed with hollow markers. Wall times are not drawn: on a shared machine
    they rank nothing the evaluations do not (the section's table gives each method's wall
    time to reach the target, the CSV every point's); a run without evaluation counts draws
    wall time instead.

    Parameters
    ----------
    problem : str, the problem's name.
    rows : DataFrame, its work-precision rows.
    palette : Palette, colours and families.
    adaptive : mapping of str to bool, which steppers are adaptive (dashed).

    Returns
    -------
    Figure or None: None when nothing finite can be drawn.
    """
    err = rows["error"].astype(float) if "error" in rows else pd.Series(dtype=float)
    frame = rows[np.isfinite(err) & (err > 0) & (err <= LOG_CEILING)]
    if frame.empty:
        return None
    costs = [c for c in ("rhs_evals", "wall_s") if c in frame][:1]
    if not costs:
        return None
    best = best_per_family(frame, palette.families)
    bold = set(best.values())
    units = {}
    if "evals_unit" in frame:
        units = {k: str(v.iloc[0]) for k, v in frame.groupby("stepper", sort=False)["evals_unit"]}
    longest = max([len(label_text(s)) + len(f) + 8 for f, s in best.items()] + [22])
    fig, axes = small_multiples(len(costs), ncols=2, panel=(3.3, 2.7), sharey=True,
                           right=longest * LEGEND_CHAR_W * 0.85 + 0.5)
    for ax, cost in zip(axes, costs, strict=True):
        for stepper, s in frame.groupby("stepper", sort=False):
            x = s[cost].astype(float)
            s = s.assign(_x=x)[np.isfinite(x) & (x > 0)].sort_values("_x")
            if s.empty:
                continue
            peer = adaptive.get(stepper, False)
            strong = stepper in bold
            c = palette.colour(stepper)
            ax.plot(s["_x"], s["error"].astype(float), "--" if peer else "-",
                    marker=palette.marker(stepper) if strong else None, ms=3.2,
                    lw=1.6 if strong else 0.6, markevery=max(1, math.ceil(len(s) / MARKERS_PER_LINE)),
                    alpha=1.0 if strong else 0.3, color=c,
                    markerfacecolor="none" if peer else c, zorder=3 if strong else 2)
        loglog_axes(ax)
        ax.set_xlabel("right-hand-side or force evaluations" if cost == "rhs_evals" else "wall time (s)",
                      fontsize=7.5)
        small_ticks(ax)
    axes[0].set_ylabel("error at the final time", fontsize=7.5)
    handles = [Line2D([], [], color=palette.colour(s), marker=palette.marker(s), ms=3, lw=1.6,
                      ls="--" if adaptive.get(s) else "-",
                      label=f"{label_text(s)} (best {fam or 'method'})"
                      + (f" [{units[s]}s]" if units.get(s, "f-or-force") != "f-or-force" else ""))
               for fam, s in best.items()]
    handles.append(Line2D([], [], color="0.6", lw=0.6, alpha=0.5, label="other methods (faint)"))
    axes[-1].legend(handles=handles, loc="upper left", bbox_to_anchor=(1.03, 1.0), borderaxespad=0.0,
                    frameon=False, fontsize=6.5)
    fig.suptitle(f"Work–precision on {label_text(problem)}", fontsize=8.5)
    cols = [c for c in ("stepper", "h", "tol", "error", "rhs_evals", "wall_s") if c in frame]
    data = frame[cols].reset_index(drop=True).assign(
        best_of_family=lambda d: d["stepper"].isin(bold).astype(int))
    return to_svg(fig, f"work-{problem}", f"error against work on {problem}", data)



"""Energy figures: the error of an invariant (energy, angular momentum) against time, one panel
per drift class."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from harness import tolerances as tol
from harness.kit import figure_style as fs
from harness.kit.figure_svg import Figure, to_svg

__all__ = ['energy_figure', 'angular_momentum_figure']


# -- energy -------------------------------------------------------------------------------------------
@fs.styled
def energy_figure(problem: str, rows: pd.DataFrame, palette: fs.Palette,
                  symplectic: Mapping[str, bool], quantity: str = "energy",
                  classes: Mapping[str, str] | None = None) -> Figure | None:
    """Relative error of an invariant against t (log-log), one panel per drift class (the class
    the experiment measured, `classes`: stepper -> class), at most MAX_LINES_PER_PANEL lines
    each; symplectic steppers solid, others dashed; lines thinned to the envelope of log-spaced
    bins."""
    g = rows[rows["quantity"] == quantity]
    if g.empty:
        return None
    classes = dict(classes or {})
    steppers = list(dict.fromkeys(g["stepper"]))
    order = {c: i for i, c in enumerate(("bounded", "sqrt", "linear", "unstable"))}
    steppers.sort(key=lambda s: order.get(classes.get(s, ""), len(order)))
    groups = fs.panels(steppers, {s: (f"drift class: {classes[s]}" if classes.get(s) else
                                   "not measurable: no drift class" if s in classes
                                   else "not classified") for s in steppers}, pack=False)
    fig, axes = fs.small_multiples(len(groups), sharex=True, sharey=True)
    what = "energy" if quantity == "energy" else "angular momentum"
    data = []
    for ax, (title, members) in zip(axes, groups, strict=True):
        for stepper in members:
            s = g[g["stepper"] == stepper]
            t = s["t"].astype(float).to_numpy()
            t0 = float(np.nanmin(t))
            x, y = fs.thin_line(t - t0, s["error"].astype(float).to_numpy())
            data.append(pd.DataFrame({"stepper": stepper, "t": x, "error": y}))
            sym = symplectic.get(stepper, False)
            # solid: symplectic, dashed: not (said in the caption and the section's intro)
            ax.plot(x, fs.clip_log(y), "-" if sym else "--", color=palette.colour(stepper), lw=0.9,
                    label=fs.label_text(stepper))
        if quantity != "energy":
            _rounding_bound(ax, g)
        fs.loglog_axes(ax)
        ax.set_title(title)
        fs.small_ticks(ax)
        fs.panel_legend(ax, loc="best")
    fig.supxlabel("t", fontsize=8)
    fig.supylabel(f"relative {what} error (0 at {fs.LOG_FLOOR:g})", fontsize=8)
    fig.suptitle(f"{what.capitalize()} error on {fs.label_text(problem)}", fontsize=8.5)
    return to_svg(fig, f"{quantity}-{problem}", f"relative {what} error against time on {problem}",
                  pd.concat(data, ignore_index=True) if data else None)


def _rounding_bound(ax: Any, g: pd.DataFrame) -> None:
    """The bound n * eps (n steps) against t for the fixed-step runs (one step size per problem
    in this experiment); adaptive runs take other steps and are not bounded by it."""
    fixed = g[~np.isfinite(g["tol"].astype(float))] if "tol" in g else g
    if fixed.empty:
        return
    first = fixed[fixed["stepper"] == fixed["stepper"].iloc[0]].sort_values("step")
    n = first["step"].astype(float).to_numpy()
    tt = first["t"].astype(float).to_numpy() - float(first["t"].astype(float).min())
    pos = n > 0
    tt, n = fs.thin_line(tt[pos], n[pos])
    ax.plot(tt, tol.ANGULAR_MOMENTUM_ROUNDING_ULPS * n * tol.EPS, ":", color="k", lw=1.0,
            label=f"rounding bound ({tol.ANGULAR_MOMENTUM_ROUNDING_ULPS:g} ulp per step)")


def angular_momentum_figure(problem: str, rows: pd.DataFrame, palette: fs.Palette,
                            symplectic: Mapping[str, bool],
                            classes: Mapping[str, str] | None = None) -> Figure | None:
    return energy_figure(problem, rows, palette, symplectic, quantity="angular_momentum",
                         classes=classes)



"""Convergence figures: error against step size per problem (small multiples per family), with
the range the order fit used."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from matplotlib.lines import Line2D

from harness import tolerances as tol
from harness.kit.figure_style import (
    LOG_CEILING,
    Palette,
    label_text,
    loglog_axes,
    panel_legend,
    panels,
    small_multiples,
    small_ticks,
    styled,
)
from harness.kit.figure_svg import Figure, to_svg
from harness.order_fit import fit_order

__all__ = ['SAME_CURVE_DIGITS', 'same_curves', 'convergence_figure']

# -- convergence ----------------------------------------------------------------------------------
# Digits at which two methods' error curves count as the same curve (drawn once): far more than
# a log-log figure resolves.
SAME_CURVE_DIGITS = 6


def same_curves(rows: pd.DataFrame) -> dict[str, list[str]]:
    """Methods whose (h, error, used-by-the-fit) points agree to SAME_CURVE_DIGITS digits — the
    same coefficients run by another implementation — are drawn as one curve: first method ->
    the others, in the order given (a method drawn by another maps to nothing, is not a key).

    Parameters
    ----------
    rows : DataFrame, one problem's global-error rows of every method.

    Returns
    -------
    dict of str to list of str
    """
    keys: dict[tuple, str] = {}
    out: dict[str, list[str]] = {}
    if rows.empty:
        return out
    # every point's rounded (log10 h, error, in the fit), computed once for the whole table
    h = np.round(np.log10(rows["h"].astype(float).abs().to_numpy() + 1e-300), SAME_CURVE_DIGITS)
    e = [float(f"{x:.{SAME_CURVE_DIGITS}g}") for x in rows["error"].astype(float)]
    fit = rows["in_fit"].fillna(False).astype(bool).to_numpy()
    points = list(zip(h.tolist(), e, fit.tolist(), strict=True))
    for stepper, where in rows.groupby("stepper", sort=False).indices.items():
        key = tuple(sorted(points[i] for i in where))
        if key in keys:
            out[keys[key]].append(stepper)
        else:
            keys[key] = stepper
            out[stepper] = []
    return out


@styled
def convergence_figure(problem: str, rows: pd.DataFrame, palette: Palette,
                       reference_error: float | None) -> Figure | None:
    """Global error against h (log-log) on one problem, one panel per family (at most
    MAX_LINES_PER_PANEL methods each): points used by the order fit marked, excluded points on
    the thin line only (the CSV says why each was excluded), the fitted slope drawn over exactly
    the range it used, the reference's certified error as the floor every panel shares.

    Parameters
    ----------
    problem : str, the problem's name (the figure's slug and title).
    rows : DataFrame, that problem's convergence rows (global ones of finite h are drawn).
    palette : Palette, the methods' colours and markers.
    reference_error : float or None, the reference's certified error (None: no floor drawn).

    Returns
    -------
    Figure or None: None when no global row has a finite h.
    """
    g = rows[(rows["kind"] == "global") & np.isfinite(rows["h"].astype(float))]
    if g.empty:
        return None
    twins = same_curves(g)
    shown = [s for s in dict.fromkeys(g["stepper"]) if s in twins]
    groups = panels(shown, palette.families)
    fig, axes = small_multiples(len(groups), sharey=True)
    floor = reference_error if reference_error is not None and np.isfinite(reference_error) \
        and reference_error > 0 else None
    data = []
    for ax, (title, members) in zip(axes, groups, strict=True):
        handles = []
        for stepper in members:
            s = g[g["stepper"] == stepper].sort_values("h")
            c = palette.colour(stepper)
            err = s["error"].astype(float).to_numpy()
            h = s["h"].astype(float).to_numpy()
            ok = np.isfinite(err) & (err > 0) & (err <= LOG_CEILING)
            used = s["in_fit"].fillna(False).astype(bool).to_numpy() & ok
            ax.plot(h[ok], err[ok], "-", color=c, lw=0.8, alpha=0.7)
            ends = np.flatnonzero(used)[[0, -1]] if used.any() else np.array([], dtype=int)
            ax.plot(h[ends], err[ends], linestyle="none", marker=palette.marker(stepper), color=c,
                    ms=3.2)  # the ends of the fitted range (every point's role is in the CSV)
            slope = math.nan
            if used.sum() >= tol.MIN_FIT_POINTS:
                f = fit_order(h[used], err[used])
                slope = float(f["order"])
                hh = np.array([h[used].min(), h[used].max()])
                ax.plot(hh, np.exp(f["intercept"]) * hh ** f["order"], "--", color=c, lw=1.8)
            fit_text = f"slope {slope:.2f}" if np.isfinite(slope) else "no fit"
            same = f" and {len(twins[stepper])} identical" if twins[stepper] else ""
            label = f"{label_text(stepper)}{same} ({fit_text})"
            handles.append(Line2D([], [], color=c, marker=palette.marker(stepper), ms=3, lw=0.8,
                                  label=label))
            excluded = s["excluded"].fillna("").astype(str).to_numpy() if "excluded" in s else \
                np.array([""] * len(s))
            for name in (stepper, *twins[stepper]):
                data.append(pd.DataFrame({"stepper": name, "h": h, "error": err,
                                          "in_fit": used.astype(int), "excluded": excluded}))
        if floor is not None:
            ax.axhline(floor, color="k", lw=0.9, ls=":")
        loglog_axes(ax)
        ax.set_title(title)
        small_ticks(ax)
        panel_legend(ax, handles, loc="lower right")
    if floor is not None:
        lo, hi = axes[0].get_ylim()
        axes[0].set_ylim(min(lo, floor / 3.0), hi)  # the floor line stays in view
    ncols = min(3, len(axes))  # small_multiples' default width
    for k, ax in enumerate(axes):
        if k % ncols:  # one shared error axis: labelled in the first column only
            ax.tick_params(labelleft=False)
    fig.supxlabel("step size h", fontsize=8)
    fig.supylabel("global error at the final time", fontsize=8)
    fig.suptitle(f"Convergence on {label_text(problem)}", fontsize=8.5)
    frame = pd.concat(data, ignore_index=True) if data else None
    return to_svg(fig, f"convergence-{problem}", f"error against step size on {problem}", frame)



"""Multistep-orbits figures: energy error against h omega with the resonances found and
predicted, and the spiralling drift rate against h omega, measured beside predicted."""

from __future__ import annotations

import numpy as np
import pandas as pd

from harness import tolerances as tol
from harness.kit import figure_style as fs
from harness.kit.figure_svg import Figure, to_svg

__all__ = ["scan_figure", "drift_figure"]


@fs.styled
def scan_figure(problem: str, rows: pd.DataFrame, summary: pd.DataFrame,
                palette: fs.Palette) -> Figure | None:
    """Largest relative energy error against h omega, one line per stepper; resonances found
    circled, predicted ones as ticks along the top in the stepper's colour.

    Parameters
    ----------
    problem : str, the problem's name.
    rows : DataFrame, its rows.
    summary : DataFrame, its summary records (the resonances found).
    palette : Palette

    Returns
    -------
    Figure or None: None for no rows.
    """
    if rows.empty:
        return None
    fig, axes = fs.new_figure(1, 1, size=(7.2, 3.8))
    ax = axes[0][0]
    found = dict(zip(summary["stepper"], summary["resonances"].fillna(""), strict=True))
    for stepper, s in rows.groupby("stepper", sort=False):
        s = s.sort_values("h_omega")
        colour = palette.colour(stepper)
        err = np.where(s["finite"].astype(bool), s["max_error"].astype(float), np.nan)
        ax.plot(s["h_omega"], fs.clip_log(err), "-", marker=palette.marker(stepper), ms=3,
                color=colour, lw=0.9, label=fs.label_text(stepper))
        hits = [float(x) for x in str(found.get(stepper, "")).split(",") if x.strip()]
        if hits:
            pick = s[s["h_omega"].round(4).isin(np.round(hits, 4))]
            ax.plot(pick["h_omega"], fs.clip_log(pick["max_error"].astype(float)), "o", ms=9,
                    mfc="none", color=colour)
        for hw in s.loc[s["source"] == "prediction", "h_omega"]:
            ax.axvline(float(hw), ymin=0.93, ymax=1.0, color=colour, lw=1.6)
    fs.loglog_axes(ax)
    ax.set_xlabel("h ω (ω = 2π / period)")
    ax.set_ylabel("largest relative energy error")
    ax.set_title(f"Energy error against step size on {fs.label_text(problem)}: "
                 "circled = resonance found, ticks = predicted")
    fs.legend_outside(ax, layout=False)
    cols = ["stepper", "h_omega", "source", "max_error", "max_L_error", "drift_rate", "finite"]
    return to_svg(fig, f"multistep-scan-{problem}", f"energy error against h omega on {problem}",
                  rows[cols].reset_index(drop=True))


@fs.styled
def drift_figure(problem: str, rows: pd.DataFrame, palette: fs.Palette) -> Figure | None:
    """|drift rate| of the relative energy against h omega: measured (markers, filled when the
    sign is the predicted one) and predicted (lines) where the orbit is circular, at the step
    sizes whose energy error stayed below SPIRAL_MAX_ERROR.

    Parameters
    ----------
    problem : str, the problem's name.
    rows : DataFrame, its rows of steppers with a non-zero predicted rate.
    palette : Palette

    Returns
    -------
    Figure or None: None when no row has a predicted rate.
    """
    pred = rows["predicted_rate"].astype(float)
    near = rows["max_error"].astype(float) < tol.SPIRAL_MAX_ERROR  # where the drift law is read
    g = rows[np.isfinite(pred) & (pred != 0) & rows["finite"].astype(bool) & near]
    if g.empty:
        return None
    fig, axes = fs.new_figure(1, 1, size=(7.2, 3.6))
    ax = axes[0][0]
    for stepper, s in g.groupby("stepper", sort=False):
        s = s.sort_values("h_omega")
        colour = palette.colour(stepper)
        ax.plot(s["h_omega"], fs.clip_log(np.abs(s["predicted_rate"].astype(float))), "-",
                color=colour, lw=0.9, label=f"{fs.label_text(stepper)} predicted")
        same = np.sign(s["drift_rate"].astype(float)) == np.sign(s["predicted_rate"].astype(float))
        ax.plot(s["h_omega"][same], fs.clip_log(np.abs(s["drift_rate"][same].astype(float))), "o",
                ms=4, color=colour, label=f"{fs.label_text(stepper)} measured")
        ax.plot(s["h_omega"][~same], fs.clip_log(np.abs(s["drift_rate"][~same].astype(float))), "o",
                ms=4, mfc="none", color=colour)
    fs.loglog_axes(ax)
    ax.set_xlabel("h ω")
    ax.set_ylabel("|d(ΔE/|E|)/dt|")
    ax.set_title(f"Spiralling on {fs.label_text(problem)}: energy drift rate, measured and "
                 "predicted (hollow: opposite sign)")
    fs.legend_outside(ax, layout=False)
    cols = ["stepper", "h_omega", "drift_rate", "predicted_rate", "max_error"]
    return to_svg(fig, f"multistep-drift-{problem}", f"energy drift rate against h omega on {problem}",
                  g[cols].reset_index(drop=True))

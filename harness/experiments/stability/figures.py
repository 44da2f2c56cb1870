"""Stability figures: region boundaries overlaid per family and the h omega limits of the
Newtonian steppers."""

from __future__ import annotations

import numpy as np
import pandas as pd
from matplotlib.lines import Line2D

from harness.kit import figure_style as fs
from harness.kit.figure_svg import Figure, to_svg

__all__ = ['stability_overlay_figure', 'hw_limits_figure']

# -- stability ------------------------------------------------------------------------------------
def _grid(rows: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    g = rows[rows["kind"] == "grid"]
    if g.empty:
        return None
    re_vals = np.unique(g["z_re"].astype(float))
    im_vals = np.unique(g["z_im"].astype(float))
    if re_vals.size * im_vals.size != len(g):
        return None
    pivot = g.pivot_table(index="z_im", columns="z_re", values="abs_r_probe", aggfunc="first")
    return pivot.columns.to_numpy(float), pivot.index.to_numpy(float), pivot.to_numpy(float)


@fs.styled
def stability_overlay_figure(rows: pd.DataFrame, palette: fs.Palette) -> Figure | None:
    """Boundaries |R(z)| = 1 of the first-order methods, overlaid one panel per family; the
    stable side is shaded lightly for each method.

    Parameters
    ----------
    rows : DataFrame, the stability grid rows of the first-order steppers.
    palette : Palette

    Returns
    -------
    Figure or None: None when no stepper has a grid.
    """
    names = [s for s, g in rows.groupby("stepper", sort=False) if _grid(g) is not None]
    if not names:
        return None
    groups = fs.panels(names, palette.families)
    fig, axes = fs.small_multiples(len(groups), panel=(3.1, 2.8), sharex=True, sharey=True)
    data = []
    for ax, (title, members) in zip(axes, groups, strict=True):
        handles = []
        for stepper in members:
            x, y, z = _grid(rows[rows["stepper"] == stepper])
            z = np.where(np.isfinite(z), z, 1e300)
            c = palette.colour(stepper)
            if np.nanmin(z) > 1 or np.nanmax(z) <= 1:
                where = "stable on the whole grid" if np.nanmax(z) <= 1 else "unstable on the grid"
                handles.append(Line2D([], [], color=c, lw=0, marker="s",
                                      label=f"{fs.label_text(stepper)} ({where})"))
                continue
            ax.contourf(x, y, z, levels=[-1.0, 1.0], colors=[c], alpha=0.08)
            cs = ax.contour(x, y, z, levels=[1.0], colors=[c], linewidths=1.1)
            for seg in cs.allsegs[0]:
                data.append(pd.DataFrame({"stepper": stepper, "re": seg[:, 0], "im": seg[:, 1]}))
            handles.append(Line2D([], [], color=c, lw=1.1, label=fs.label_text(stepper)))
        ax.axhline(0, color="0.5", lw=0.5)
        ax.axvline(0, color="0.5", lw=0.5)
        ax.set_aspect("equal")
        ax.set_title(title)
        fs.small_ticks(ax)
        fs.panel_legend(ax, handles, loc="upper left")
    fig.supxlabel("Re(hλ)", fontsize=8)
    fig.supylabel("Im(hλ)", fontsize=8)
    fig.suptitle("Stability boundaries |R(hλ)| = 1 (probe)", fontsize=8.5)
    return to_svg(fig, "stability-overlay", "stability region boundaries per family",
                  pd.concat(data, ignore_index=True) if data else None)


@fs.styled
def hw_limits_figure(summary: pd.DataFrame, palette: fs.Palette) -> Figure | None:
    """Bar chart of the h omega stability limits of the Newtonian steppers (unbounded: hatched
    bar to the search limit).

    Parameters
    ----------
    summary : DataFrame, the stability summary (only form 'newtonian' rows are drawn).
    palette : Palette

    Returns
    -------
    Figure or None: None without Newtonian steppers.
    """
    s = summary[summary["form"] == "newtonian"]
    if s.empty:
        return None
    fig, axes = fs.new_figure(size=(6.4, 0.22 * len(s) + 1.0))
    ax = axes[0][0]
    names = [str(n) for n in s["stepper"]]
    values = s["hw_limit"].astype(float).to_numpy()
    finite = values[np.isfinite(values)]
    cap = max(4.0, float(finite.max()) * 1.15) if finite.size else 4.0
    for i, (name, v) in enumerate(zip(names, values, strict=True)):
        if np.isfinite(v):
            ax.barh(i, v, color=palette.colour(name))
            ax.text(v, i, f" {v:.4g}", va="center", fontsize=6.5)
        else:
            ax.barh(i, cap, color="none", edgecolor=palette.colour(name), hatch="//")
            ax.text(cap, i, " unbounded", va="center", fontsize=6.5)
    ax.set_yticks(range(len(names)), [fs.label_text(n) for n in names])
    ax.tick_params(labelsize=6.5)
    ax.invert_yaxis()
    ax.set_xlabel("largest stable hω (harmonic oscillator x'' = -ω²x)")
    ax.set_title("hω stability limits of the Newtonian steppers (probe)")
    ax.set_xlim(0, cap * 1.25)
    return to_svg(fig, "stability-hw", "bar chart of h omega stability limits",
                  pd.DataFrame({"stepper": names, "hw_limit": values}))



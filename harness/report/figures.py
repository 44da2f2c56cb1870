"""Figures of the report: matplotlib (Agg) drawn to inline SVG text.

Each public function takes tidy rows/summary tables of one experiment and returns a `Figure`
(its SVG text, caption-free; the section supplies the caption). The SVG is deterministic (ids
salted by the figure's slug, no date), uses no external resource, and is checked by
`check_svg` before it is embedded: names from plugins end up in legends as SVG text, which
matplotlib escapes; `check_svg` rejects any script, event attribute, foreign object or
reference outside the figure, so embedding the SVG as markup is safe.

Names are drawn as plain text (`text.parse_math` off), so a stepper called `$x$` is not read as
mathematics and a name with a stray backslash cannot break the drawing.
"""

from __future__ import annotations

import io
import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from harness import tolerances as tol

__all__ = [
    "Figure",
    "Palette",
    "check_svg",
    "to_svg",
    "convergence_figure",
    "stability_overlay_figure",
    "stability_multiples_figure",
    "hw_limits_figure",
    "reversibility_figure",
    "energy_figure",
    "angular_momentum_figure",
    "work_precision_figure",
    "roundoff_figure",
    "perf_history_figure",
    "UnsafeFigureError",
]

# Excluded convergence points: marker and legend text per reason.
EXCLUSION_STYLE = {
    "pre-asymptotic": ("o", "pre-asymptotic (excluded from the fit)"),
    "roundoff": ("v", "at the roundoff floor (excluded)"),
    "reference": ("s", "within 100x of the reference error (excluded)"),
}
# Lines of long runs are thinned to about this many points per line (log-spaced in steps).
MAX_POINTS_PER_LINE = 300
# Errors of exactly zero cannot sit on a log axis: they are drawn at this value (said in the
# axis label); errors above LOG_CEILING (a blow-up, meaningless as a number) are drawn there, so
# one exploding method cannot squash every other line into a corner.
LOG_FLOOR = 1e-18
LOG_CEILING = 1e20


def _clip_log(y: Any) -> np.ndarray:
    """Values for a log axis: non-finite -> NaN (a gap), the rest clipped to [floor, ceiling]."""
    a = np.asarray(y, dtype=float)
    return np.where(np.isfinite(a), np.clip(a, LOG_FLOOR, LOG_CEILING), np.nan)

_RC = {
    "svg.fonttype": "none",
    "font.family": "DejaVu Sans",
    "font.size": 9.0,
    "axes.titlesize": 10.0,
    "legend.fontsize": 7.5,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "text.parse_math": False,
    "figure.dpi": 72,
    "path.simplify": True,
}

_SVG_NS = "{http://www.w3.org/2000/svg}"
_XLINK = "{http://www.w3.org/1999/xlink}href"
_ALLOWED_TAGS = {"svg", "g", "path", "defs", "clipPath", "use", "text", "tspan", "rect", "style",
                 "metadata", "title", "desc", "circle", "ellipse", "line", "polyline", "polygon",
                 "image", "pattern", "linearGradient", "radialGradient", "stop", "mask"}
_RDF_TAGS = {"RDF", "Work", "type", "date", "format", "creator", "Agent", "title"}


class UnsafeFigureError(ValueError):
    """A figure's SVG holds something that must not be embedded in the report."""


@dataclass(frozen=True)
class Figure:
    """One figure: its slug (unique in the report), inline SVG text and a short alt text."""

    slug: str
    svg: str
    alt: str


class Palette:
    """One colour, marker and line style per stepper, the same in every figure."""

    _MARKERS = ("o", "s", "^", "D", "v", "P", "X", "<", ">", "h", "*", "p")

    def __init__(self, steppers: Sequence[str]):
        from matplotlib import colormaps

        colours = list(colormaps["tab20"].colors) + list(colormaps["tab20b"].colors)
        # tab20 pairs a strong and a light shade; take the strong ones first
        ordered = colours[0:20:2] + colours[1:20:2] + colours[20:]
        self._style = {}
        for i, name in enumerate(dict.fromkeys(steppers)):
            self._style[name] = (ordered[i % len(ordered)], self._MARKERS[i % len(self._MARKERS)])

    def colour(self, stepper: str) -> Any:
        return self._style.get(stepper, ((0.3, 0.3, 0.3), "o"))[0]

    def marker(self, stepper: str) -> str:
        return self._style.get(stepper, ((0.3, 0.3, 0.3), "o"))[1]


# -- SVG output -----------------------------------------------------------------------------------
def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def check_svg(svg: str) -> str:
    """Return `svg` when it is a plain drawing: well-formed, only drawing elements, no script,
    no event attribute, no link outside the figure. Raise `UnsafeFigureError` otherwise."""
    try:
        root = ET.fromstring(svg)
    except ET.ParseError as exc:
        raise UnsafeFigureError(f"figure SVG is not well-formed XML: {exc}") from None
    if _local(root.tag) != "svg":
        raise UnsafeFigureError(f"figure SVG root is <{_local(root.tag)}>, expected <svg>")
    for el in root.iter():
        tag = _local(el.tag)
        if tag not in _ALLOWED_TAGS and tag not in _RDF_TAGS:
            raise UnsafeFigureError(f"figure SVG holds a <{tag}> element")
        for name, value in el.attrib.items():
            attr = _local(name).lower()
            if attr.startswith("on"):
                raise UnsafeFigureError(f"figure SVG holds an event attribute {attr!r}")
            if attr == "href" and not value.startswith("#"):
                if not (tag == "image" and value.startswith("data:image/png;base64,")):
                    raise UnsafeFigureError(f"figure SVG links outside itself: {value[:60]!r}")
            if "url(" in value and not re.fullmatch(r"[^()]*(url\(#[\w.-]+\)[^()]*)*", value):
                raise UnsafeFigureError(f"figure SVG refers to an outside resource: {value[:60]!r}")
    if re.search(r"<\s*script|javascript:|<\s*foreignObject|@import", svg, re.IGNORECASE):
        raise UnsafeFigureError("figure SVG holds script or imported content")
    return svg


def to_svg(fig: Any, slug: str, alt: str) -> Figure:
    """Render a matplotlib figure (made without pyplot, so no global state) to checked,
    deterministic inline SVG."""
    buf = io.StringIO()
    tight = not getattr(fig, "_harness_layout", False)
    with _rc(slug):
        fig.savefig(buf, format="svg", bbox_inches="tight" if tight else None,
                    metadata={"Date": None})
    text = buf.getvalue()
    start = text.find("<svg")
    if start < 0:
        raise UnsafeFigureError("matplotlib wrote no <svg> element")
    text = text[start:]
    check_svg(text)
    # sizes in CSS pixels (the stylesheet scales figures down to the page width; the viewBox
    # keeps the aspect ratio)
    head_end = text.find(">")
    head = re.sub(r'width="([\d.]+)pt" height="([\d.]+)pt"',
                  lambda m: f'width="{float(m.group(1)) * 4 / 3:.0f}" '
                            f'height="{float(m.group(2)) * 4 / 3:.0f}"',
                  text[:head_end], count=1)
    text = head + text[head_end:]
    text = text.replace("<svg", f'<svg role="img" class="figure" data-slug="{_attr(slug)}"', 1)
    return Figure(slug=slug, svg=text, alt=alt)


def _attr(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]", "-", text)


def _rc(slug: str):
    import matplotlib as mpl

    return mpl.rc_context({**_RC, "svg.hashsalt": f"harness-report-{slug}"})


def _styled(fn):
    """Run a figure function with the report's matplotlib settings (text objects read them
    when they are created, so the whole drawing happens inside)."""
    import functools

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        import matplotlib

        with matplotlib.rc_context(_RC):
            return fn(*args, **kwargs)

    return wrapper


def _new(nrows: int = 1, ncols: int = 1, *, size: tuple[float, float] = (7.2, 4.2), **kw: Any):
    from matplotlib.figure import Figure as MplFigure

    fig = MplFigure(figsize=size)
    axes = fig.subplots(nrows, ncols, squeeze=False, **kw)
    return fig, axes


_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def _power_of_ten(value: float, _pos: Any = None) -> str:
    """Tick label of a log axis as plain Unicode text (10⁻³), since mathtext is off."""
    if not np.isfinite(value) or value <= 0:
        return ""
    exponent = math.log10(value)
    if abs(exponent - round(exponent)) > 1e-9:
        return ""
    k = int(round(exponent))
    if k == 0:
        return "1"
    if k == 1:
        return "10"
    return "10" + str(k).translate(_SUPERSCRIPT)


def _loglog(ax: Any, x: bool = True, y: bool = True) -> None:
    """Log scales with plain-text power-of-ten tick labels."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter, NullLocator

    for on, axis, scale, lim in ((x, ax.xaxis, ax.set_xscale, ax.get_xlim),
                                 (y, ax.yaxis, ax.set_yscale, ax.get_ylim)):
        if not on:
            continue
        scale("log")
        axis.set_major_locator(LogLocator(base=10.0, numticks=12))
        axis.set_major_formatter(FuncFormatter(_power_of_ten))
        lo, hi = lim()
        if lo > 0 and hi > 0 and abs(math.log10(hi) - math.log10(lo)) < 1.5:
            # less than two powers of ten in view: label the minor ticks too
            axis.set_minor_formatter(FuncFormatter(lambda v, _p: f"{v:.2g}"))
        else:
            # minor ticks cost a third of the drawing time and carry no label here
            axis.set_minor_locator(NullLocator())
            axis.set_minor_formatter(NullFormatter())


def _label(text: Any) -> str:
    """A name as it appears in a legend: plain text, bounded length."""
    s = str(text)
    return s if len(s) <= 40 else s[:37] + "..."


def _finite_positive(values: Iterable[float]) -> np.ndarray:
    a = np.asarray(list(values), dtype=float)
    return a[np.isfinite(a) & (a > 0)]


# Layout of a one-panel figure with its legend on the right, in inches. Computing it here
# instead of asking matplotlib for a tight bounding box saves a layout pass per figure (a third
# of the report's drawing time).
_AX_W, _AX_H = 5.0, 3.3
_LEFT, _BOTTOM, _TOP, _GAP = 0.95, 0.6, 0.4, 0.2
_LEGEND_CHAR_W, _LEGEND_HANDLE_W, _LEGEND_ROW_H = 0.052, 0.6, 0.16


def _legend_outside(ax: Any, handles: list | None = None, *, layout: bool = True,
                    **kw: Any) -> None:
    """Put the legend right of the axes; with `layout`, size a one-panel figure around both
    (`to_svg` then keeps this layout instead of computing a tight bounding box)."""
    if handles is None:
        handles, _ = ax.get_legend_handles_labels()
    labels = [h.get_label() for h in handles]
    fig = ax.figure
    if handles:
        ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.0 if layout else 1.02, 1.0),
                  borderaxespad=0.0, frameon=False, **kw)
    if not layout:
        return
    ncol = int(kw.get("ncol", 1))
    rows = math.ceil(len(labels) / ncol) if labels else 0
    legend_w = (max((len(t) for t in labels), default=0) * _LEGEND_CHAR_W + _LEGEND_HANDLE_W) * ncol
    legend_h = rows * _LEGEND_ROW_H + 0.1
    width = _LEFT + _AX_W + (_GAP + legend_w if labels else 0.3)
    height = max(_BOTTOM + _AX_H + _TOP, _TOP + legend_h + 0.2)
    fig.set_size_inches(width, height)
    bottom = height - _TOP - _AX_H
    ax.set_position([_LEFT / width, bottom / height, _AX_W / width, _AX_H / height])
    fig._harness_layout = True  # to_svg: no tight bounding box needed


def _thin(x: np.ndarray, y: np.ndarray, n: int = MAX_POINTS_PER_LINE) -> tuple[np.ndarray, np.ndarray]:
    """Keep about `n` points log-spaced in x (x > 0), keeping the largest y in each bin so an
    envelope keeps its peaks."""
    order = np.argsort(x)
    x, y = x[order], y[order]
    pos = x > 0
    if pos.sum() <= n:
        return x[pos], y[pos]
    x, y = x[pos], y[pos]
    edges = np.geomspace(x[0], x[-1] * (1 + 1e-12), n + 1)
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, n - 1)
    keep = []
    for b in np.unique(idx):
        members = np.flatnonzero(idx == b)
        yy = np.where(np.isfinite(y[members]), y[members], np.inf)
        keep.append(members[int(np.argmax(yy))])
    keep = np.array(sorted(keep))
    return x[keep], y[keep]


# -- convergence ----------------------------------------------------------------------------------
@_styled
def convergence_figure(problem: str, rows: pd.DataFrame, palette: Palette,
                       reference_error: float | None) -> Figure | None:
    """Global error against h (log-log) for every fixed-step stepper on one problem: points used
    by the fit filled, excluded points hollow (marker by reason), the fitted slope drawn over the
    points it used, and the reference's certified error as a floor line."""
    from matplotlib.lines import Line2D

    from harness.experiments.convergence import fit_order

    g = rows[(rows["kind"] == "global") & np.isfinite(rows["h"].astype(float))]
    if g.empty:
        return None
    fig, axes = _new(size=(7.4, 4.6))
    ax = axes[0][0]
    handles = []
    reasons_seen: set[str] = set()
    for stepper, s in g.groupby("stepper", sort=False):
        s = s.sort_values("h")
        c = palette.colour(stepper)
        err = s["error"].astype(float).to_numpy()
        h = s["h"].astype(float).to_numpy()
        ok = np.isfinite(err) & (err > 0) & (err <= LOG_CEILING)
        ax.plot(h[ok], err[ok], "-", color=c, lw=0.8, alpha=0.5)
        used = s["in_fit"].astype(bool).to_numpy() & ok
        ax.plot(h[used], err[used], linestyle="none", marker=palette.marker(stepper), color=c, ms=4.5)
        excluded = s["excluded"].fillna("").astype(str).to_numpy()
        for reason, (marker, _) in EXCLUSION_STYLE.items():
            sel = (excluded == reason) & ok
            if sel.any():
                reasons_seen.add(reason)
                ax.plot(h[sel], err[sel], linestyle="none", marker=marker, ms=5,
                        markerfacecolor="none", markeredgecolor=c, markeredgewidth=0.9)
        if used.sum() >= tol.MIN_FIT_POINTS:
            f = fit_order(h[used], err[used])
            hh = np.array([h[used].min(), h[used].max()])
            ax.plot(hh, np.exp(f["intercept"]) * hh ** f["order"], "--", color=c, lw=1.6)
            label = f"{_label(stepper)} (slope {f['order']:.2f})"
        else:
            label = f"{_label(stepper)} (no fit)"
        handles.append(Line2D([], [], color=c, marker=palette.marker(stepper), lw=0.8, label=label))
    if reference_error is not None and np.isfinite(reference_error) and reference_error > 0:
        ax.axhline(reference_error, color="k", lw=1.0, ls=":")
        handles.append(Line2D([], [], color="k", ls=":", label="reference certified error"))
    for reason in EXCLUSION_STYLE:
        if reason in reasons_seen:
            marker, text = EXCLUSION_STYLE[reason]
            handles.append(Line2D([], [], color="0.3", marker=marker, markerfacecolor="none",
                                  linestyle="none", label=text))
    handles.append(Line2D([], [], color="0.3", ls="--", lw=1.6, label="fitted slope over the points used"))
    _loglog(ax)
    if reference_error is not None and np.isfinite(reference_error) and reference_error > 0:
        lo, hi = ax.get_ylim()
        ax.set_ylim(min(lo, reference_error / 3.0), hi)  # the floor line stays in view
    ax.set_xlabel("step size h")
    ax.set_ylabel("global error (max norm over the ensemble)")
    ax.set_title(f"Convergence on {_label(problem)}")
    _legend_outside(ax, handles, ncol=1)
    return to_svg(fig, f"convergence-{problem}", f"error against step size on {problem}")


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


@_styled
def stability_overlay_figure(rows: pd.DataFrame, palette: Palette) -> Figure | None:
    """Boundaries |R(z)| = 1 of every first-order method in one complex plane."""
    from matplotlib.lines import Line2D

    fig, axes = _new(size=(7.4, 5.0))
    ax = axes[0][0]
    handles = []
    for stepper, g in rows.groupby("stepper", sort=False):
        grid = _grid(g)
        if grid is None:
            continue
        x, y, z = grid
        z = np.where(np.isfinite(z), z, 1e300)
        if np.nanmin(z) > 1 or np.nanmax(z) <= 1:
            # no boundary on this grid (stable or unstable everywhere): say so in the legend
            where = "stable on the whole grid" if np.nanmax(z) <= 1 else "unstable on the whole grid"
            handles.append(Line2D([], [], color=palette.colour(stepper), lw=0,
                                  label=f"{_label(stepper)} ({where})"))
            continue
        ax.contour(x, y, z, levels=[1.0], colors=[palette.colour(stepper)], linewidths=1.2)
        handles.append(Line2D([], [], color=palette.colour(stepper), lw=1.2, label=_label(stepper)))
    if not handles:
        return None
    ax.axhline(0, color="0.5", lw=0.6)
    ax.axvline(0, color="0.5", lw=0.6)
    ax.set_aspect("equal")
    ax.set_xlabel("Re(hλ)")
    ax.set_ylabel("Im(hλ)")
    ax.set_title("Stability boundaries |R(hλ)| = 1 (probe)")
    _legend_outside(ax, handles, layout=False)
    return to_svg(fig, "stability-overlay", "stability region boundaries of the first-order methods")


@_styled
def stability_multiples_figure(rows: pd.DataFrame, palette: Palette) -> Figure | None:
    """One small panel per first-order method: the stable set |R| <= 1 shaded."""
    names = [s for s, g in rows.groupby("stepper", sort=False) if _grid(g) is not None]
    if not names:
        return None
    ncols = min(5, len(names))
    nrows = int(math.ceil(len(names) / ncols))
    fig, axes = _new(nrows, ncols, size=(1.75 * ncols + 0.4, 1.7 * nrows + 0.3),
                     sharex=True, sharey=True)
    for ax in axes.flat[len(names):]:
        ax.set_visible(False)
    for ax, stepper in zip(axes.flat, names, strict=False):
        x, y, z = _grid(rows[rows["stepper"] == stepper])
        z = np.where(np.isfinite(z), z, 1e300)
        ax.contourf(x, y, z, levels=[-1.0, 1.0], colors=[palette.colour(stepper)], alpha=0.45)
        if np.nanmin(z) <= 1 < np.nanmax(z):
            ax.contour(x, y, z, levels=[1.0], colors=[palette.colour(stepper)], linewidths=0.9)
        ax.axhline(0, color="0.5", lw=0.5)
        ax.axvline(0, color="0.5", lw=0.5)
        ax.set_title(_label(stepper), fontsize=8)
        ax.tick_params(labelsize=6.5)
        ax.set_aspect("equal")
        ax.label_outer()
    fig.supxlabel("Re(hλ)", fontsize=8)
    fig.supylabel("Im(hλ)", fontsize=8)
    return to_svg(fig, "stability-multiples", "stable set of each first-order method")


@_styled
def hw_limits_figure(summary: pd.DataFrame, palette: Palette) -> Figure | None:
    """Bar chart of the h omega stability limits of the Newtonian steppers (unbounded: hatched
    bar to the search limit)."""
    s = summary[summary["form"] == "newtonian"]
    if s.empty:
        return None
    fig, axes = _new(size=(7.4, 0.32 * len(s) + 1.2))
    ax = axes[0][0]
    names = [str(n) for n in s["stepper"]]
    values = s["hw_limit"].astype(float).to_numpy()
    finite = values[np.isfinite(values)]
    cap = max(4.0, float(finite.max()) * 1.15) if finite.size else 4.0
    for i, (name, v) in enumerate(zip(names, values, strict=True)):
        if np.isfinite(v):
            ax.barh(i, v, color=palette.colour(name))
            ax.text(v, i, f" {v:.4g}", va="center", fontsize=7)
        else:
            ax.barh(i, cap, color="none", edgecolor=palette.colour(name), hatch="//")
            ax.text(cap, i, " unbounded", va="center", fontsize=7)
    ax.set_yticks(range(len(names)), [_label(n) for n in names])
    ax.invert_yaxis()
    ax.set_xlabel("largest stable hω (harmonic oscillator x'' = -ω²x)")
    ax.set_title("hω stability limits of the Newtonian steppers (probe)")
    ax.set_xlim(0, cap * 1.25)
    return to_svg(fig, "stability-hw", "bar chart of h omega stability limits")


# -- reversibility ----------------------------------------------------------------------------------
@_styled
def reversibility_figure(problem: str, table: pd.DataFrame, palette: Palette,
                         symmetric: Mapping[str, bool]) -> Figure | None:
    """Return error in ulps against the number of steps N, per stepper (claimed symmetric: solid
    lines; not claimed: dashed)."""
    if table.empty:
        return None
    fig, axes = _new(size=(7.4, 4.4))
    ax = axes[0][0]
    for stepper, g in table.groupby("stepper", sort=False):
        g = g.sort_values("steps")
        x = g["steps"].astype(float).to_numpy()
        y = g["return_error_ulps"].astype(float).to_numpy()
        y = np.where(np.isfinite(y), np.clip(y, 1e-1, LOG_CEILING), np.nan)
        ls = "-" if symmetric.get(stepper, False) else "--"
        ax.plot(x, y, ls, marker=palette.marker(stepper), color=palette.colour(stepper), ms=4,
                lw=1.0, label=f"{_label(stepper)}{' (symmetric)' if symmetric.get(stepper) else ''}")
    n = np.geomspace(max(1.0, float(table["steps"].min())), float(table["steps"].max()), 20)
    ax.plot(n, n, ":", color="k", lw=0.9, label="N ulps (rounding alone)")
    _loglog(ax)
    ax.set_xlabel("steps N forward, then N back")
    ax.set_ylabel("return error (ulps of the state; 0 drawn at 0.1)")
    ax.set_title(f"Time reversibility on {_label(problem)}")
    _legend_outside(ax)
    return to_svg(fig, f"reversibility-{problem}", f"return error against N on {problem}")


# -- energy -------------------------------------------------------------------------------------------
@_styled
def energy_figure(problem: str, rows: pd.DataFrame, palette: Palette,
                  symplectic: Mapping[str, bool], quantity: str = "energy") -> Figure | None:
    """Relative error of an invariant against t (log-log): symplectic steppers solid, others
    dashed; the lines are thinned to the envelope of log-spaced bins."""
    g = rows[rows["quantity"] == quantity]
    if g.empty:
        return None
    fig, axes = _new(size=(7.4, 4.4))
    ax = axes[0][0]
    for stepper, s in g.groupby("stepper", sort=False):
        t = s["t"].astype(float).to_numpy()
        t0 = float(np.nanmin(t))
        x, y = _thin(t - t0, s["error"].astype(float).to_numpy())
        y = _clip_log(y)
        ls = "-" if symplectic.get(stepper, False) else "--"
        ax.plot(x, y, ls, color=palette.colour(stepper), lw=1.0,
                label=f"{_label(stepper)}{' (symplectic)' if symplectic.get(stepper) else ''}")
    what = "energy" if quantity == "energy" else "angular momentum"
    if quantity != "energy":
        # the bound n * eps (n steps) against t, drawn for the fixed-step runs (one step size h
        # per problem in this experiment); adaptive runs take other steps and are not bounded
        fixed = g[~np.isfinite(g["tol"].astype(float))] if "tol" in g else g
        if len(fixed):
            first = fixed[fixed["stepper"] == fixed["stepper"].iloc[0]].sort_values("step")
            n = first["step"].astype(float).to_numpy()
            tt = first["t"].astype(float).to_numpy() - float(first["t"].astype(float).min())
            pos = n > 0
            ax.plot(tt[pos], tol.ANGULAR_MOMENTUM_ROUNDING_ULPS * n[pos] * tol.EPS, ":", color="k",
                    lw=1.0, label=f"rounding bound of the fixed-step runs "
                          f"({tol.ANGULAR_MOMENTUM_ROUNDING_ULPS:g} ulp per step)")
    _loglog(ax)
    ax.set_xlabel("t")
    ax.set_ylabel(f"relative {what} error (0 drawn at {LOG_FLOOR:g}; clipped at {LOG_CEILING:g})")
    ax.set_title(f"{what.capitalize()} error on {_label(problem)}")
    _legend_outside(ax)
    return to_svg(fig, f"{quantity}-{problem}", f"relative {what} error against time on {problem}")


def angular_momentum_figure(problem: str, rows: pd.DataFrame, palette: Palette,
                            symplectic: Mapping[str, bool]) -> Figure | None:
    return energy_figure(problem, rows, palette, symplectic, quantity="angular_momentum")


# -- work-precision -----------------------------------------------------------------------------------
@_styled
def work_precision_figure(problem: str, rows: pd.DataFrame, palette: Palette,
                          adaptive: Mapping[str, bool], cost: str) -> Figure | None:
    """Error against cost (`cost` = 'evals' or 'wall_s'), one line per stepper; adaptive peers
    (heyoka, scipy) drawn dashed with hollow markers. Evaluations are the experiment's
    `rhs_evals` (right-hand-side plus force calls; a stepper whose `evals_unit` differs, e.g.
    heyoka's Taylor steps, says so in the legend)."""
    col_err = "error"
    if cost == "evals":
        x_all = (rows["rhs_evals"].astype(float) if "rhs_evals" in rows
                 else pd.Series(np.nan, index=rows.index))
        xlabel = "right-hand-side or force evaluations"
    else:
        x_all = rows["wall_s"].astype(float)
        xlabel = "wall time (s)"
    frame = rows.assign(_x=x_all.to_numpy(float))
    err = frame[col_err].astype(float)
    frame = frame[np.isfinite(frame["_x"]) & (frame["_x"] > 0) & np.isfinite(err) & (err > 0)
                  & (err <= LOG_CEILING)]
    if frame.empty:
        return None
    units = {}
    if "evals_unit" in frame:
        units = {k: str(v.iloc[0]) for k, v in frame.groupby("stepper", sort=False)["evals_unit"]}
    fig, axes = _new(size=(7.4, 4.4))
    ax = axes[0][0]
    for stepper, s in frame.groupby("stepper", sort=False):
        s = s.sort_values("_x")
        peer = adaptive.get(stepper, False)
        ax.plot(s["_x"], s[col_err].astype(float), "--" if peer else "-",
                marker=palette.marker(stepper), ms=3.5, lw=1.0, color=palette.colour(stepper),
                markerfacecolor="none" if peer else palette.colour(stepper),
                label=_label(stepper) + (" (adaptive)" if peer else "")
                + (f" [{units[stepper]}s]" if cost == "evals" and units.get(stepper, "f-or-force")
                   != "f-or-force" else ""))
    _loglog(ax)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("error at the final time")
    ax.set_title(f"Work-precision on {_label(problem)}: error vs "
                 f"{'evaluations' if cost == 'evals' else 'wall time'}")
    _legend_outside(ax)
    return to_svg(fig, f"work-{cost}-{problem}", f"error against {xlabel} on {problem}")


# -- roundoff -------------------------------------------------------------------------------------
@_styled
def roundoff_figure(rows: pd.DataFrame, palette: Palette) -> Figure | None:
    """Position error against h at a fixed step count, one panel per problem, with the
    truncation error extrapolated from the largest step."""
    if rows.empty:
        return None
    problems = list(dict.fromkeys(rows["problem"]))
    fig, axes = _new(1, len(problems), size=(3.9 * len(problems) + 1.6, 3.8))
    for ax, problem in zip(axes[0], problems, strict=True):
        g = rows[rows["problem"] == problem]
        for stepper, s in g.groupby("stepper", sort=False):
            s = s.sort_values("h")
            ax.plot(s["h"], _clip_log(s["error"]), "-",
                    marker=palette.marker(stepper), ms=4, color=palette.colour(stepper),
                    label=_label(stepper))
        first = g.sort_values("h").groupby("stepper").tail(1)
        if len(first):
            s = g[g["stepper"] == first["stepper"].iloc[0]].sort_values("h")
            ax.plot(s["h"], _clip_log(s["truncation_estimate"]), ":",
                    color="k", lw=0.9, label="truncation alone (∝ h³ at fixed N)")
        _loglog(ax)
        ax.set_xlabel("step size h")
        ax.set_title(f"{_label(problem)}, N = {int(g['n_steps'].iloc[0])} steps")
    axes[0][0].set_ylabel("relative position error")
    _legend_outside(axes[0][-1], layout=False)
    return to_svg(fig, "roundoff", "position error against step size at a fixed step count")


# -- performance history --------------------------------------------------------------------------
@_styled
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
    fig, axes = _new(nrows, ncols, size=(3.4 * ncols + 0.6, 2.5 * nrows + 0.4))
    for ax in axes.flat[len(benches):]:
        ax.set_visible(False)
    for ax, bench in zip(axes.flat, benches, strict=False):
        g = h[h["benchmark"].astype(str) == bench]
        unit = str(g["unit"].dropna().iloc[0]) if g["unit"].notna().any() else ""
        for params, s in list(g.groupby(g["params"].astype(str), sort=False))[:max_lines]:
            s = s.sort_values("date")
            ax.plot(s["date"], pd.to_numeric(s["value"]), marker="o", ms=3, lw=1.0,
                    label=_label(params) if params not in ("", "()", "None") else None)
        if unit in ("seconds", "s", "bytes"):
            _loglog(ax, x=False)
        ax.set_title(_label(bench), fontsize=8)
        ax.set_ylabel(unit, fontsize=7)
        ax.tick_params(labelsize=6, axis="both")
        for lbl in ax.get_xticklabels():
            lbl.set_rotation(30)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=5.5, frameon=False)
    return to_svg(fig, "perf-history", "benchmark values against commit date")


def finite_or_none(x: Any) -> float | None:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None

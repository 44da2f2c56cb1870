"""The report figures' shared drawing style: matplotlib settings, the one colour and marker of
each method (`Palette`), small-multiple panels, log axes with plain-text ticks, legends, line
thinning. Every figure module draws with these, so a method looks the same in every figure.

Names are drawn as plain text (`text.parse_math` off), so a stepper called `$x$` is not read as
mathematics and a name with a stray backslash cannot break the drawing.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import matplotlib
import numpy as np
from matplotlib.figure import Figure as MplFigure
from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter, NullLocator

from harness.kit.figure_cache import cached_call

__all__ = ["Palette", "panels", "MAX_LINES_PER_PANEL", "MAX_POINTS_PER_LINE", "EXCLUSION_STYLE",
           "LOG_FLOOR", "LOG_CEILING", "finite_or_none"]

# Excluded convergence points: marker and legend text per reason.
EXCLUSION_STYLE = {
    "pre-asymptotic": ("o", "pre-asymptotic (excluded from the fit)"),
    "roundoff": ("v", "at the roundoff floor (excluded)"),
    "reference": ("s", "within 100x of the reference error (excluded)"),
    "coefficients": ("D", "at the coefficients' own floor (excluded)"),
}
# Lines of long runs are thinned to about this many points per line (log-spaced in steps): on a
# panel a few hundred pixels wide, more points add bytes, not detail.
MAX_POINTS_PER_LINE = 16
# Small multiples: at most this many methods share one panel, so every line can be told apart.
MAX_LINES_PER_PANEL = 8
# Errors of exactly zero cannot sit on a log axis: they are drawn at this value (said in the
# axis label); errors above LOG_CEILING (a blow-up, meaningless as a number) are drawn there, so
# one exploding method cannot squash every other line into a corner.
LOG_FLOOR = 1e-18
LOG_CEILING = 1e20


def clip_log(y: Any) -> np.ndarray:
    """Values for a log axis: non-finite -> NaN (a gap), the rest clipped to [floor, ceiling].

    Parameters
    ----------
    y : array_like, the values (any shape; read as float).

    Returns
    -------
    ndarray of float: same shape as `y`.
    """
    a = np.asarray(y, dtype=float)
    return np.where(np.isfinite(a), np.clip(a, LOG_FLOOR, LOG_CEILING), np.nan)

RC_PARAMS = {
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
    # a fixed title position: matplotlib otherwise measures every axis's tick labels to lift
    # titles above them (a sixth of the drawing time; the report's panels have none on top)
    "axes.titley": 1.0,
}


# Twenty colours that stay distinct on white and for the common colour-vision deficiencies
# (the strong halves of matplotlib's tab20 and tab20b, darkest first).
_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
            "#7f7f7f", "#bcbd22", "#17becf", "#393b79", "#637939", "#8c6d31", "#843c39",
            "#7b4173", "#3182bd", "#e6550d", "#31a354", "#756bb1", "#636363")
_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "<", ">", "h", "*", "p")


class Palette:
    """The one colour and marker of each method, the same in every figure of a report.

    Methods are ordered by family (then as given) and take the colours in turn, so the members
    of one family, which share a panel, always differ in colour; the marker is the family's."""

    def __init__(self, steppers: Sequence[str], families: Mapping[str, str] | None = None):
        fam = dict(families or {})
        names = list(dict.fromkeys(str(s) for s in steppers))
        family_order = list(dict.fromkeys(fam.get(n, "") for n in names))
        ordered = sorted(names, key=lambda n: (family_order.index(fam.get(n, "")), names.index(n)))
        self._style = {
            n: (_COLOURS[i % len(_COLOURS)], _MARKERS[family_order.index(fam.get(n, "")) % len(_MARKERS)])
            for i, n in enumerate(ordered)}
        self.families = {n: fam.get(n, "") for n in names}

    def colour(self, stepper: str) -> str:
        """The line colour of a method.

        Parameters
        ----------
        stepper : str, the method; one the palette was not built with is drawn
            grey.

        Returns
        -------
        str: '#rrggbb'.
        """
        return self._style.get(stepper, ("#4d4d4d", "o"))[0]

    def marker(self, stepper: str) -> str:
        """The marker of a method.

        Parameters
        ----------
        stepper : str, a method's name (unknown: 'o').

        Returns
        -------
        str: a matplotlib marker code.
        """
        return self._style.get(stepper, ("#4d4d4d", "o"))[1]

    def family(self, stepper: str) -> str:
        """The family a method was grouped under.

        Parameters
        ----------
        stepper : str, any name; unknown names have none.

        Returns
        -------
        str: the family's name; empty when unknown.
        """
        return self.families.get(stepper, "")


def panels(steppers: Iterable[str], group: Mapping[str, str] | Any,
           max_lines: int = MAX_LINES_PER_PANEL, pack: bool = True) -> list[tuple[str, list[str]]]:
    """Split methods into panels of at most `max_lines`: one per group (family, drift class...),
    a large group cut into numbered parts, small groups sharing a panel while they fit (its
    title names them all). `group` maps a method to its group's name.

    Parameters
    ----------
    steppers : iterable of str, the methods (duplicates dropped, order kept).
    group : mapping of str to str, or callable, a method's group name (empty reads 'other').
    max_lines : int, optional, the most methods in one panel (default MAX_LINES_PER_PANEL).
    pack : bool, optional, let small groups share a panel (default True).

    Returns
    -------
    list of (title, methods): one entry per panel.
    """
    by: dict[str, list[str]] = {}
    for s in dict.fromkeys(steppers):
        by.setdefault(str(group.get(s, "") if hasattr(group, "get") else group(s)) or "other",
                      []).append(s)
    out: list[tuple[list[str], list[str]]] = []
    for name, members in by.items():
        chunks = [members[i:i + max_lines] for i in range(0, len(members), max_lines)]
        if len(chunks) > 1:
            out += [([f"{name} ({k + 1}/{len(chunks)})"], c) for k, c in enumerate(chunks)]
            continue
        home = next((p for p in out if pack and "/" not in p[0][0]
                     and len(p[1]) + len(members) <= max_lines), None)
        if home is None:
            out.append(([name], list(members)))
        else:
            home[0].append(name)
            home[1].extend(members)
    return [(", ".join(names), members) for names, members in out]


def styled(fn):
    """Run a figure function with the report's matplotlib settings (text objects read them
    when they are created, so the whole drawing happens inside); a call drawn before with the
    same arguments and drawing code comes from the figure cache (`figure_cache`).

    Parameters
    ----------
    fn : callable, a function that draws and returns a matplotlib figure.

    Returns
    -------
    callable: `fn` wrapped; same arguments, the figure possibly from the cache.
    """
    def draw(*args, **kwargs):
        with matplotlib.rc_context(RC_PARAMS):
            return fn(*args, **kwargs)

    draw.__module__, draw.__qualname__ = fn.__module__, fn.__qualname__

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        return cached_call(draw, args, kwargs)

    return wrapper


def new_figure(nrows: int = 1, ncols: int = 1, *, size: tuple[float, float] = (7.2, 4.2), **kw: Any):
    """A matplotlib figure (not tied to pyplot) with a grid of axes and no backgrounds.

    Parameters
    ----------
    nrows, ncols : int, optional, the grid's shape (default 1 x 1).
    size : (float, float), optional, width and height in inches.
    **kw : passed to `Figure.subplots` (sharex, sharey, ...).

    Returns
    -------
    (Figure, ndarray of Axes): the figure and its axes, always 2-D.
    """
    fig = MplFigure(figsize=size)
    axes = fig.subplots(nrows, ncols, squeeze=False, **kw)
    # the page is white: white backgrounds behind the figure and each panel draw nothing
    fig.patch.set_visible(False)
    for ax in axes.flat:
        ax.patch.set_visible(False)
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


# Labelled powers of ten on a log axis, at most: a panel two inches high holds about this many
# readable labels (a wider range labels every second or fourth power).
LOG_TICKS = 8


def loglog_axes(ax: Any, x: bool = True, y: bool = True) -> None:
    """Log scales with plain-text power-of-ten tick labels.

    Parameters
    ----------
    ax : matplotlib Axes.
    x, y : bool, optional, which axes become logarithmic (default both).
    """
    for on, axis, scale, lim in ((x, ax.xaxis, ax.set_xscale, ax.get_xlim),
                                 (y, ax.yaxis, ax.set_yscale, ax.get_ylim)):
        if not on:
            continue
        scale("log")
        axis.set_major_locator(LogLocator(base=10.0, numticks=LOG_TICKS))
        axis.set_major_formatter(FuncFormatter(_power_of_ten))
        lo, hi = lim()
        if lo > 0 and hi > 0 and abs(math.log10(hi) - math.log10(lo)) < 1.5:
            # less than two powers of ten in view: label 2 and 5 times each power of ten too (every
            # minor tick labelled crowds a small panel's axis into unreadable text)
            axis.set_minor_locator(LogLocator(base=10.0, subs=(2.0, 5.0)))
            axis.set_minor_formatter(FuncFormatter(lambda v, _p: f"{v:.2g}"))
        else:
            # minor ticks cost a third of the drawing time and carry no label here
            axis.set_minor_locator(NullLocator())
            axis.set_minor_formatter(NullFormatter())


def label_text(text: Any) -> str:
    """A name as it appears in a legend: plain text, bounded length.

    Parameters
    ----------
    text : Any, the name (any object, shown as its `str`).

    Returns
    -------
    str: at most 40 characters ('...' marks a cut).
    """
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
LEGEND_CHAR_W, _LEGEND_HANDLE_W, _LEGEND_ROW_H = 0.052, 0.6, 0.16


def legend_outside(ax: Any, handles: list | None = None, *, layout: bool = True,
                    **kw: Any) -> None:
    """Put the legend right of the axes; with `layout`, size a one-panel figure around both
    (`to_svg` then keeps this layout instead of computing a tight bounding box).

    Parameters
    ----------
    ax : matplotlib Axes.
    handles : list of artists, optional, the legend entries (default the axes' labelled lines).
    layout : bool, optional, resize the figure around axes and legend (default True).
    **kw : passed to `Axes.legend` (`ncol` also widens the layout).
    """
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
    legend_w = (max((len(t) for t in labels), default=0) * LEGEND_CHAR_W + _LEGEND_HANDLE_W) * ncol
    legend_h = rows * _LEGEND_ROW_H + 0.1
    width = _LEFT + _AX_W + (_GAP + legend_w if labels else 0.3)
    height = max(_BOTTOM + _AX_H + _TOP, _TOP + legend_h + 0.2)
    fig.set_size_inches(width, height)
    bottom = height - _TOP - _AX_H
    ax.set_position([_LEFT / width, bottom / height, _AX_W / width, _AX_H / height])
    fig.harness_layout = True  # to_svg: no tight bounding box needed


def thin_line(x: np.ndarray, y: np.ndarray, n: int = MAX_POINTS_PER_LINE) -> tuple[np.ndarray, np.ndarray]:
    """Keep about `n` points log-spaced in x (x > 0), keeping the largest y in each bin so an
    envelope keeps its peaks.

    Parameters
    ----------
    x, y : ndarray, the line's points (any order; points with x <= 0 dropped).
    n : int, optional, the number of bins (default MAX_POINTS_PER_LINE).

    Returns
    -------
    (ndarray, ndarray): the kept x and y, sorted by x.
    """
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


# -- small multiples ------------------------------------------------------------------------------
_PANEL_W, _PANEL_H = 2.9, 2.25


def small_multiples(n: int, *, ncols: int = 3, panel: tuple[float, float] = (_PANEL_W, _PANEL_H),
               sharex: bool = False, sharey: bool = False, right: float = 0.0) -> tuple[Any, list[Any]]:
    """A grid of `n` panels (unused cells hidden), `ncols` wide at most, laid out by fixed
    margins in inches (`right`: extra room for a legend), so `to_svg` needs no tight-bbox pass.

    Parameters
    ----------
    n : int, the number of panels.
    ncols : int, optional, the most panels in a row (default 3).
    panel : (float, float), optional, one panel's width and height in inches.
    sharex, sharey : bool, optional, share axes between panels.
    right : float, optional, extra width in inches at the right.

    Returns
    -------
    (Figure, list of Axes): the figure and its `n` visible panels.
    """
    ncols = max(1, min(ncols, n))
    nrows = int(math.ceil(n / ncols))
    left, bottom, top, wgap, hgap = 0.75, 0.5, 0.5, 0.35 if sharey else 0.6, 0.45
    width = left + ncols * panel[0] + (ncols - 1) * wgap + 0.15 + right
    height = bottom + nrows * panel[1] + (nrows - 1) * hgap + top
    fig, axes = new_figure(nrows, ncols, size=(width, height), sharex=sharex, sharey=sharey)
    fig.subplots_adjust(left=left / width, right=(width - 0.15 - right) / width,
                        bottom=bottom / height, top=(height - top) / height,
                        wspace=wgap / panel[0], hspace=hgap / panel[1])
    fig.harness_layout = True  # to_svg: this layout, no tight bounding box
    flat = list(axes.flat)
    for ax in flat[n:]:
        ax.set_visible(False)
    return fig, flat[:n]


def panel_legend(ax: Any, handles: list | None = None, **kw: Any) -> None:
    """A small legend inside a panel (no legend when there are no handles).

    Parameters
    ----------
    ax : matplotlib Axes.
    handles : list of artists, optional, the entries (default the axes' labelled lines).
    **kw : passed to `Axes.legend` (`loc` defaults to 'best').
    """
    if handles is None:
        handles, _ = ax.get_legend_handles_labels()
    if handles:
        ax.legend(handles=handles, fontsize=6.2, loc=kw.pop("loc", "best"), frameon=True, fancybox=False,
                  framealpha=0.85, edgecolor="none", handlelength=1.6, borderpad=0.3,
                  labelspacing=0.25, **kw)


def small_ticks(ax: Any) -> None:
    """Small labels; no tick marks and no vertical grid lines (the horizontal grid carries the
    reading; each mark is a few dozen bytes of SVG, times hundreds of panels).

    Parameters
    ----------
    ax : matplotlib Axes.
    """
    ax.tick_params(labelsize=6.5, length=0, pad=2)
    ax.grid(False, axis="x")
    ax.title.set_fontsize(8)


def finite_or_none(x: Any) -> float | None:
    """`x` as a float, or None when it is not a finite number.

    Parameters
    ----------
    x : Any, a value.

    Returns
    -------
    float or None: None for NaN, infinities and values `float` cannot read.
    """
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


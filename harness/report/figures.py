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

import hashlib
import io
import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from harness import tolerances as tol

__all__ = [
    "Figure",
    "Palette",
    "check_svg",
    "to_svg",
    "panels",
    "MAX_LINES_PER_PANEL",
    "convergence_figure",
    "stability_overlay_figure",
    "hw_limits_figure",
    "reversibility_figure",
    "energy_figure",
    "angular_momentum_figure",
    "work_precision_figure",
    "best_per_family",
    "same_curves",
    "roundoff_figure",
    "symplecticity_figure",
    "perf_history_figure",
    "UnsafeFigureError",
]

# Excluded convergence points: marker and legend text per reason.
EXCLUSION_STYLE = {
    "pre-asymptotic": ("o", "pre-asymptotic (excluded from the fit)"),
    "roundoff": ("v", "at the roundoff floor (excluded)"),
    "reference": ("s", "within 100x of the reference error (excluded)"),
}
# Lines of long runs are thinned to about this many points per line (log-spaced in steps): on a
# panel a few hundred pixels wide, more points add bytes, not detail.
MAX_POINTS_PER_LINE = 32
# Small multiples: at most this many methods share one panel, so every line can be told apart.
MAX_LINES_PER_PANEL = 8
# Coordinates in the SVG are rounded to this many decimals of a point (1/10 pt is far below
# what a screen shows; the full-precision numbers are in each figure's CSV).
SVG_DECIMALS = 1
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
    """One figure: its slug (unique in the report), inline SVG text, a short alt text, and the
    tidy table of what it draws (offered for download beside it)."""

    slug: str
    svg: str
    alt: str
    data: pd.DataFrame | None = field(default=None, compare=False, repr=False)


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
        return self._style.get(stepper, ("#4d4d4d", "o"))[0]

    def marker(self, stepper: str) -> str:
        return self._style.get(stepper, ("#4d4d4d", "o"))[1]

    def family(self, stepper: str) -> str:
        return self.families.get(stepper, "")


def panels(steppers: Iterable[str], group: Mapping[str, str] | Any,
           max_lines: int = MAX_LINES_PER_PANEL, pack: bool = True) -> list[tuple[str, list[str]]]:
    """Split methods into panels of at most `max_lines`: one per group (family, drift class...),
    a large group cut into numbered parts, small groups sharing a panel while they fit (its
    title names them all). `group` maps a method to its group's name."""
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


def to_svg(fig: Any, slug: str, alt: str, data: pd.DataFrame | None = None) -> Figure:
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
    text = _shrink(text[start:], "f" + hashlib.sha1(slug.encode()).hexdigest()[:5])
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
    return Figure(slug=slug, svg=text, alt=alt, data=data)


_NUMBER = re.compile(r"-?\d+\.\d+")
_NS = "http://www.w3.org/2000/svg"
_XLINK_NS = "http://www.w3.org/1999/xlink"


def _round_numbers(text: str) -> str:
    def one(m: re.Match) -> str:
        s = f"{float(m.group(0)):.{SVG_DECIMALS}f}".rstrip("0").rstrip(".")
        return "0" if s in ("-0", "") else s

    return _NUMBER.sub(one, text)


def _compact_path(d: str) -> str:
    d = _round_numbers(" ".join(d.split()))
    return re.sub(r"\s*([MLCQZHVAmlcqzhva])\s*", r"\1", d)


def _shrink(svg: str, salt: str) -> str:
    """Fewer bytes, same drawing: no metadata, coordinates rounded to SVG_DECIMALS, compact
    paths, attribute-less groups unwrapped, identity rotations dropped, each repeated style
    turned into a class (names salted by the figure, since a page's inline SVGs share one
    style scope), and only the ids something refers to kept (matplotlib's group ids would
    repeat across the figures of one page)."""
    ET.register_namespace("", _NS)
    ET.register_namespace("xlink", _XLINK_NS)
    root = ET.fromstring(svg)
    used = set(re.findall(r'(?:href="#|url\(#)([\w.-]+)', svg))

    for el in root.iter():
        if "id" in el.attrib and el.attrib["id"] not in used:
            del el.attrib["id"]
        if el.text is not None and not el.text.strip():
            el.text = None
        if el.tail is not None and not el.tail.strip():
            el.tail = None

    def unwrap(parent: ET.Element) -> None:
        out = []
        for child in list(parent):
            unwrap(child)
            if _local(child.tag) == "metadata":
                continue
            if _local(child.tag) == "g" and not child.attrib:
                out.extend(list(child))
            else:
                out.append(child)
        parent[:] = out

    unwrap(root)
    _merge_marker_defs(root)
    _merge_siblings(root)
    styles: dict[str, int] = {}
    for el in root.iter():
        for name in ("d", "x", "y", "points"):
            if name in el.attrib:
                value = el.attrib[name]
                el.set(name, _compact_path(value) if name == "d" else _round_numbers(value))
        tr = el.attrib.get("transform", "")
        if re.fullmatch(r"rotate\(-?0(?:\s[^)]*)?\)", tr):
            del el.attrib["transform"]
        st = el.attrib.get("style")
        if st is not None:
            st = re.sub(r"\s*([:;])\s*", r"\1", st).strip().rstrip(";")
            el.set("style", st)
            styles[st] = styles.get(st, 0) + 1
    classes = {st: f"{salt}{i}" for i, st in enumerate(s for s, n in styles.items() if n > 1)}
    if classes:
        for el in root.iter():
            st = el.attrib.get("style")
            if st in classes:
                del el.attrib["style"]
                el.set("class", classes[st])
        css = "".join(f".{c}{{{st}}}" for st, c in classes.items())
        defs = root.find(f"{{{_NS}}}defs")
        if defs is None:
            defs = ET.Element(f"{{{_NS}}}defs")
            root.insert(0, defs)
        style = defs.find(f"{{{_NS}}}style")
        if style is None:
            style = ET.SubElement(defs, f"{{{_NS}}}style")
        style.text = (style.text or "") + css
    text = ET.tostring(root, encoding="unicode").replace(" />", "/>")
    # shorter ids (every marker use repeats one): salted, since ids are page-wide
    ids = sorted(set(re.findall(r'\sid="([\w.-]+)"', text)), key=len, reverse=True)
    for i, old in enumerate(ids):
        text = text.replace(f'id="{old}"', f'id="{salt}i{i}"').replace(f'"#{old}"', f'"#{salt}i{i}"') \
            .replace(f"url(#{old})", f"url(#{salt}i{i})")
    return text


def _merge_siblings(root: ET.Element) -> None:
    """Paths with the same attributes but their data, separated only by text (grid lines
    between tick labels, the segments of one style), become one path."""
    for parent in root.iter():
        kids = list(parent)
        out: list[ET.Element] = []
        last: dict[tuple, ET.Element] = {}
        for child in kids:
            tag = _local(child.tag)
            if tag == "path" and "id" not in child.attrib and "d" in child.attrib:
                key = tuple(sorted((k, v) for k, v in child.attrib.items() if k != "d"))
                prev = last.get(key)
                if prev is not None:
                    prev.set("d", prev.attrib["d"] + child.attrib["d"])
                    continue
                last = {key: child}
            elif tag != "text":
                last = {}
            out.append(child)
        if len(out) != len(kids):
            parent[:] = out


def _merge_marker_defs(root: ET.Element) -> None:
    """matplotlib defines one marker path per (shape, stroke style); keep one definition per
    shape and move its style onto each use (a used element inherits from its <use>)."""
    href = f"{{{_XLINK_NS}}}href"
    defs = {}
    for el in root.iter(f"{{{_NS}}}path"):
        if "id" in el.attrib and "d" in el.attrib:
            defs[el.attrib["id"]] = el
    canonical: dict[str, ET.Element] = {}
    style_of: dict[str, str] = {}
    target: dict[str, str] = {}
    for i, el in defs.items():
        key = el.attrib["d"]
        style_of[i] = el.attrib.get("style", "")
        first = canonical.setdefault(key, el)
        target[i] = first.attrib["id"]
    for use in root.iter(f"{{{_NS}}}use"):
        ref = use.attrib.get(href, "")[1:]
        if ref in target:
            # the definition's own style won over the use's: it goes last
            merged = ";".join(s for s in (use.attrib.get("style", ""), style_of[ref]) if s)
            if merged:
                use.set("style", merged)
            use.set(href, "#" + target[ref])
    keep = {id(e) for e in canonical.values()}
    for parent in root.iter():
        for child in list(parent):
            if child.attrib.get("id") in defs and id(child) not in keep:
                parent.remove(child)
    for el in canonical.values():
        el.attrib.pop("style", None)


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


# -- small multiples ------------------------------------------------------------------------------
_PANEL_W, _PANEL_H = 2.9, 2.25


def _multiples(n: int, *, ncols: int = 3, panel: tuple[float, float] = (_PANEL_W, _PANEL_H),
               sharex: bool = False, sharey: bool = False, right: float = 0.0) -> tuple[Any, list[Any]]:
    """A grid of `n` panels (unused cells hidden), `ncols` wide at most, laid out by fixed
    margins in inches (`right`: extra room for a legend), so `to_svg` needs no tight-bbox pass."""
    ncols = max(1, min(ncols, n))
    nrows = int(math.ceil(n / ncols))
    left, bottom, top, wgap, hgap = 0.75, 0.5, 0.5, 0.35 if sharey else 0.6, 0.45
    width = left + ncols * panel[0] + (ncols - 1) * wgap + 0.15 + right
    height = bottom + nrows * panel[1] + (nrows - 1) * hgap + top
    fig, axes = _new(nrows, ncols, size=(width, height), sharex=sharex, sharey=sharey)
    fig.subplots_adjust(left=left / width, right=(width - 0.15 - right) / width,
                        bottom=bottom / height, top=(height - top) / height,
                        wspace=wgap / panel[0], hspace=hgap / panel[1])
    fig._harness_layout = True  # to_svg: this layout, no tight bounding box
    flat = list(axes.flat)
    for ax in flat[n:]:
        ax.set_visible(False)
    return fig, flat[:n]


def _panel_legend(ax: Any, handles: list | None = None, **kw: Any) -> None:
    if handles is None:
        handles, _ = ax.get_legend_handles_labels()
    if handles:
        ax.legend(handles=handles, fontsize=6.2, loc=kw.pop("loc", "best"), frameon=True,
                  framealpha=0.85, edgecolor="none", handlelength=1.6, borderpad=0.3,
                  labelspacing=0.25, **kw)


def _small_ticks(ax: Any) -> None:
    """Small labels; no tick marks and no vertical grid lines (the horizontal grid carries the
    reading; each mark is a few dozen bytes of SVG, times hundreds of panels)."""
    ax.tick_params(labelsize=6.5, length=0, pad=2)
    ax.grid(False, axis="x")
    ax.title.set_fontsize(8)


# -- convergence ----------------------------------------------------------------------------------
# Digits at which two methods' error curves count as the same curve (drawn once): far more than
# a log-log figure resolves.
SAME_CURVE_DIGITS = 6


def same_curves(rows: pd.DataFrame) -> dict[str, list[str]]:
    """Methods whose (h, error, used-by-the-fit) points agree to SAME_CURVE_DIGITS digits — the
    same coefficients run by another implementation — are drawn as one curve: first method ->
    the others, in the order given (a method drawn by another maps to nothing, is not a key)."""
    keys: dict[tuple, str] = {}
    out: dict[str, list[str]] = {}
    for stepper, s in rows.groupby("stepper", sort=False):
        s = s.sort_values("h")
        key = tuple(zip(np.round(np.log10(s["h"].astype(float).abs() + 1e-300), SAME_CURVE_DIGITS),
                        [float(f"{e:.{SAME_CURVE_DIGITS}g}") for e in s["error"].astype(float)],
                        s["in_fit"].fillna(False).astype(bool), strict=True))
        if key in keys:
            out[keys[key]].append(stepper)
        else:
            keys[key] = stepper
            out[stepper] = []
    return out


@_styled
def convergence_figure(problem: str, rows: pd.DataFrame, palette: Palette,
                       reference_error: float | None) -> Figure | None:
    """Global error against h (log-log) on one problem, one panel per family (at most
    MAX_LINES_PER_PANEL methods each): points used by the order fit marked, excluded points on
    the thin line only (the CSV says why each was excluded), the fitted slope drawn over exactly
    the range it used, the reference's certified error as the floor every panel shares."""
    from matplotlib.lines import Line2D

    from harness.experiments.convergence import fit_order

    g = rows[(rows["kind"] == "global") & np.isfinite(rows["h"].astype(float))]
    if g.empty:
        return None
    twins = same_curves(g)
    shown = [s for s in dict.fromkeys(g["stepper"]) if s in twins]
    groups = panels(shown, palette.families)
    fig, axes = _multiples(len(groups), sharey=True)
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
            ax.plot(h[used], err[used], linestyle="none", marker=palette.marker(stepper), color=c,
                    ms=3.2)
            slope = math.nan
            if used.sum() >= tol.MIN_FIT_POINTS:
                f = fit_order(h[used], err[used])
                slope = float(f["order"])
                hh = np.array([h[used].min(), h[used].max()])
                ax.plot(hh, np.exp(f["intercept"]) * hh ** f["order"], "--", color=c, lw=1.8)
            fit_text = f"slope {slope:.2f}" if np.isfinite(slope) else "no fit"
            same = f" and {len(twins[stepper])} identical" if twins[stepper] else ""
            label = f"{_label(stepper)}{same} ({fit_text})"
            handles.append(Line2D([], [], color=c, marker=palette.marker(stepper), ms=3, lw=0.8,
                                  label=label))
            excluded = s["excluded"].fillna("").astype(str).to_numpy() if "excluded" in s else \
                np.array([""] * len(s))
            for name in (stepper, *twins[stepper]):
                data.append(pd.DataFrame({"stepper": name, "h": h, "error": err,
                                          "in_fit": used.astype(int), "excluded": excluded}))
        if floor is not None:
            ax.axhline(floor, color="k", lw=0.9, ls=":")
        _loglog(ax)
        ax.set_title(title)
        _small_ticks(ax)
        _panel_legend(ax, handles, loc="lower right")
    if floor is not None:
        lo, hi = axes[0].get_ylim()
        axes[0].set_ylim(min(lo, floor / 3.0), hi)  # the floor line stays in view
    fig.supxlabel("step size h", fontsize=8)
    fig.supylabel("global error at the final time", fontsize=8)
    fig.suptitle(f"Convergence on {_label(problem)}", fontsize=8.5)
    frame = pd.concat(data, ignore_index=True) if data else None
    return to_svg(fig, f"convergence-{problem}", f"error against step size on {problem}", frame)


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
    """Boundaries |R(z)| = 1 of the first-order methods, overlaid one panel per family; the
    stable side is shaded lightly for each method."""
    from matplotlib.lines import Line2D

    names = [s for s, g in rows.groupby("stepper", sort=False) if _grid(g) is not None]
    if not names:
        return None
    groups = panels(names, palette.families)
    fig, axes = _multiples(len(groups), panel=(3.1, 2.8), sharex=True, sharey=True)
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
                                      label=f"{_label(stepper)} ({where})"))
                continue
            ax.contourf(x, y, z, levels=[-1.0, 1.0], colors=[c], alpha=0.08)
            cs = ax.contour(x, y, z, levels=[1.0], colors=[c], linewidths=1.1)
            for seg in cs.allsegs[0]:
                data.append(pd.DataFrame({"stepper": stepper, "re": seg[:, 0], "im": seg[:, 1]}))
            handles.append(Line2D([], [], color=c, lw=1.1, label=_label(stepper)))
        ax.axhline(0, color="0.5", lw=0.5)
        ax.axvline(0, color="0.5", lw=0.5)
        ax.set_aspect("equal")
        ax.set_title(title)
        _small_ticks(ax)
        _panel_legend(ax, handles, loc="upper left")
    fig.supxlabel("Re(hλ)", fontsize=8)
    fig.supylabel("Im(hλ)", fontsize=8)
    fig.suptitle("Stability boundaries |R(hλ)| = 1 (probe)", fontsize=8.5)
    return to_svg(fig, "stability-overlay", "stability region boundaries per family",
                  pd.concat(data, ignore_index=True) if data else None)


@_styled
def hw_limits_figure(summary: pd.DataFrame, palette: Palette) -> Figure | None:
    """Bar chart of the h omega stability limits of the Newtonian steppers (unbounded: hatched
    bar to the search limit)."""
    s = summary[summary["form"] == "newtonian"]
    if s.empty:
        return None
    fig, axes = _new(size=(6.4, 0.22 * len(s) + 1.0))
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
    ax.set_yticks(range(len(names)), [_label(n) for n in names])
    ax.tick_params(labelsize=6.5)
    ax.invert_yaxis()
    ax.set_xlabel("largest stable hω (harmonic oscillator x'' = -ω²x)")
    ax.set_title("hω stability limits of the Newtonian steppers (probe)")
    ax.set_xlim(0, cap * 1.25)
    return to_svg(fig, "stability-hw", "bar chart of h omega stability limits",
                  pd.DataFrame({"stepper": names, "hw_limit": values}))


# -- reversibility ----------------------------------------------------------------------------------
@_styled
def reversibility_figure(problem: str, table: pd.DataFrame, palette: Palette,
                         symmetric: Mapping[str, bool]) -> Figure | None:
    """Return error in ulps against the number of steps N, one panel per family (claimed
    symmetric: solid lines; not claimed: dashed), with the rounding bound the verdict uses."""
    if table.empty:
        return None
    groups = panels(list(dict.fromkeys(table["stepper"])), palette.families)
    fig, axes = _multiples(len(groups), sharex=True, sharey=True)
    for ax, (title, members) in zip(axes, groups, strict=True):
        sub = table[table["stepper"].isin(members)]
        for stepper in members:
            g = sub[sub["stepper"] == stepper].sort_values("steps")
            x = g["steps"].astype(float).to_numpy()
            y = g["return_error_ulps"].astype(float).to_numpy()
            y = np.where(np.isfinite(y), np.clip(y, 1e-1, LOG_CEILING), np.nan)
            sym = symmetric.get(stepper, False)
            ax.plot(x, y, "-" if sym else "--", marker=palette.marker(stepper),
                    color=palette.colour(stepper), ms=3, lw=0.9,
                    label=f"{_label(stepper)}{' (symmetric)' if sym else ''}")
        if "rounding_bound_ulps" in sub:
            bound = sub.groupby("steps")["rounding_bound_ulps"].max().sort_index()
            bound = bound[np.isfinite(bound.astype(float))]
            if len(bound):
                ax.plot(bound.index.astype(float), bound.astype(float), ":", color="k", lw=1.0,
                        label="rounding bound")
        _loglog(ax)
        ax.set_title(title)
        _small_ticks(ax)
        _panel_legend(ax, loc="upper left")
    fig.supxlabel("steps N forward, then N back", fontsize=8)
    fig.supylabel("return error (ulps; 0 drawn at 0.1)", fontsize=8)
    fig.suptitle(f"Time reversibility on {_label(problem)}", fontsize=8)
    cols = [c for c in ("stepper", "problem", "steps", "h", "return_error", "return_error_ulps",
                        "rounding_bound_ulps", "verdict") if c in table]
    return to_svg(fig, f"reversibility-{problem}", f"return error against N on {problem}",
                  table[cols].reset_index(drop=True))


# -- energy -------------------------------------------------------------------------------------------
@_styled
def energy_figure(problem: str, rows: pd.DataFrame, palette: Palette,
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
    groups = panels(steppers, {s: f"drift class: {classes.get(s) or 'not classified'}"
                               for s in steppers}, pack=False)
    fig, axes = _multiples(len(groups), sharex=True, sharey=True)
    what = "energy" if quantity == "energy" else "angular momentum"
    data = []
    for ax, (title, members) in zip(axes, groups, strict=True):
        for stepper in members:
            s = g[g["stepper"] == stepper]
            t = s["t"].astype(float).to_numpy()
            t0 = float(np.nanmin(t))
            x, y = _thin(t - t0, s["error"].astype(float).to_numpy())
            data.append(pd.DataFrame({"stepper": stepper, "t": x, "error": y}))
            sym = symplectic.get(stepper, False)
            ax.plot(x, _clip_log(y), "-" if sym else "--", color=palette.colour(stepper), lw=0.9,
                    label=f"{_label(stepper)}{' (symplectic)' if sym else ''}")
        if quantity != "energy":
            _rounding_bound(ax, g)
        _loglog(ax)
        ax.set_title(title)
        _small_ticks(ax)
        _panel_legend(ax, loc="best")
    fig.supxlabel("t", fontsize=8)
    fig.supylabel(f"relative {what} error (0 at {LOG_FLOOR:g})", fontsize=8)
    fig.suptitle(f"{what.capitalize()} error on {_label(problem)}", fontsize=8.5)
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
    tt, n = _thin(tt[pos], n[pos])
    ax.plot(tt, tol.ANGULAR_MOMENTUM_ROUNDING_ULPS * n * tol.EPS, ":", color="k", lw=1.0,
            label=f"rounding bound ({tol.ANGULAR_MOMENTUM_ROUNDING_ULPS:g} ulp per step)")


def angular_momentum_figure(problem: str, rows: pd.DataFrame, palette: Palette,
                            symplectic: Mapping[str, bool],
                            classes: Mapping[str, str] | None = None) -> Figure | None:
    return energy_figure(problem, rows, palette, symplectic, quantity="angular_momentum",
                         classes=classes)


# -- work-precision -----------------------------------------------------------------------------------
# The precision the "best of each family" is judged at: every method of the catalogue reaches it
# on the work-precision problems, so the cheapest one to get there is well defined.
WORK_TARGET_ERROR = 1e-6


def best_per_family(rows: pd.DataFrame, families: Mapping[str, str], cost: str = "rhs_evals"
                    ) -> dict[str, str]:
    """family -> its method that reaches WORK_TARGET_ERROR for the least `cost` on these rows
    (one problem); a family where none reaches it: the method with the lowest error."""
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


@_styled
def work_precision_figure(problem: str, rows: pd.DataFrame, palette: Palette,
                          adaptive: Mapping[str, bool]) -> Figure | None:
    """Error against evaluations (left) and wall time (right) on one problem, one line per
    method; the best method of each family (`best_per_family`) drawn bold and named in the
    legend, the others thin and faint. Adaptive peers dashed with hollow markers."""
    from matplotlib.lines import Line2D

    err = rows["error"].astype(float) if "error" in rows else pd.Series(dtype=float)
    frame = rows[np.isfinite(err) & (err > 0) & (err <= LOG_CEILING)]
    if frame.empty:
        return None
    costs = [c for c in ("rhs_evals", "wall_s") if c in frame]
    if not costs:
        return None
    best = best_per_family(frame, palette.families)
    bold = set(best.values())
    units = {}
    if "evals_unit" in frame:
        units = {k: str(v.iloc[0]) for k, v in frame.groupby("stepper", sort=False)["evals_unit"]}
    longest = max([len(_label(s)) + len(f) + 8 for f, s in best.items()] + [22])
    fig, axes = _multiples(len(costs), ncols=2, panel=(3.3, 2.7), sharey=True,
                           right=longest * _LEGEND_CHAR_W * 0.85 + 0.5)
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
                    marker=palette.marker(stepper) if strong else None, ms=3.2, lw=1.6 if strong else 0.6,
                    alpha=1.0 if strong else 0.3, color=c,
                    markerfacecolor="none" if peer else c, zorder=3 if strong else 2)
        _loglog(ax)
        ax.set_xlabel("right-hand-side or force evaluations" if cost == "rhs_evals" else "wall time (s)",
                      fontsize=7.5)
        _small_ticks(ax)
    axes[0].set_ylabel("error at the final time", fontsize=7.5)
    handles = [Line2D([], [], color=palette.colour(s), marker=palette.marker(s), ms=3, lw=1.6,
                      ls="--" if adaptive.get(s) else "-",
                      label=f"{_label(s)} (best {fam or 'method'})"
                      + (f" [{units[s]}s]" if units.get(s, "f-or-force") != "f-or-force" else ""))
               for fam, s in best.items()]
    handles.append(Line2D([], [], color="0.6", lw=0.6, alpha=0.5, label="other methods (faint)"))
    axes[-1].legend(handles=handles, loc="upper left", bbox_to_anchor=(1.03, 1.0), borderaxespad=0.0,
                    frameon=False, fontsize=6.5)
    fig.suptitle(f"Work–precision on {_label(problem)}", fontsize=8.5)
    cols = [c for c in ("stepper", "h", "tol", "error", "rhs_evals", "wall_s") if c in frame]
    data = frame[cols].reset_index(drop=True).assign(
        best_of_family=lambda d: d["stepper"].isin(bold).astype(int))
    return to_svg(fig, f"work-{problem}", f"error against work on {problem}", data)


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
    cols = [c for c in ("stepper", "problem", "n_steps", "h", "error", "truncation_estimate") if c in rows]
    return to_svg(fig, "roundoff", "position error against step size at a fixed step count",
                  rows[cols].reset_index(drop=True))


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
    return to_svg(fig, "perf-history", "benchmark values against commit date",
                  h.reset_index(drop=True))


def finite_or_none(x: Any) -> float | None:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


# -- symplecticity --------------------------------------------------------------------------------
@_styled
def symplecticity_figure(summary: pd.DataFrame, palette: Palette) -> Figure | None:
    """Deviation from symplecticity per stepper (x, grouped by family) and problem (one point
    each), log scale, with the finite-difference threshold the verdict uses; claimed-symplectic
    steppers filled, the others hollow."""
    if summary.empty or "deviation" not in summary:
        return None
    s = summary.assign(_d=summary["deviation"].astype(float))
    names = sorted(dict.fromkeys(s["stepper"]), key=lambda n: (palette.family(n), n))
    fig, axes = _new(size=(max(5.0, 0.2 * len(names) + 1.6), 3.4))
    ax = axes[0][0]
    for i, name in enumerate(names):
        g = s[s["stepper"] == name]
        claimed = bool(g["claimed_symplectic"].iloc[0]) if "claimed_symplectic" in g else False
        c = palette.colour(name)
        ax.plot(np.full(len(g), i), _clip_log(g["_d"]), linestyle="none", marker=palette.marker(name),
                ms=4, color=c, markerfacecolor=c if claimed else "none")
    if "threshold" in s:
        thr = s["threshold"].astype(float)
        thr = thr[np.isfinite(thr) & (thr > 0)]
        if len(thr):
            ax.axhline(float(thr.max()), color="k", ls=":", lw=1.0)
            ax.text(len(names) - 0.5, float(thr.max()), " threshold", fontsize=6.5, va="bottom",
                    ha="right")
    _loglog(ax, x=False)
    ax.set_xticks(range(len(names)), [_label(n) for n in names], rotation=60, ha="right", fontsize=6.5)
    ax.set_xlim(-0.6, len(names) - 0.4)
    ax.set_ylabel(f"‖JᵀΩJ − Ω‖ / ‖J‖² (0 at {LOG_FLOOR:g})", fontsize=7.5)
    ax.set_title("Symplecticity: filled = claimed symplectic, hollow = not claimed", fontsize=8)
    ax.tick_params(axis="y", labelsize=6.5)
    cols = [c for c in ("stepper", "problem", "h", "deviation", "threshold", "claimed_symplectic",
                        "verdict") if c in summary]
    return to_svg(fig, "symplecticity", "deviation from symplecticity per stepper",
                  summary[cols].reset_index(drop=True))

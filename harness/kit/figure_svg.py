"""Figures as inline SVG text: a matplotlib figure rendered to deterministic, checked, compact SVG.

The SVG is deterministic (ids salted by the figure's slug, no date), uses no external resource,
and is checked by `check_svg` before it is embedded: names from plugins end up in legends as SVG
text, which matplotlib escapes; `check_svg` rejects any script, event attribute, foreign object
or reference outside the figure, so embedding the SVG as markup is safe.
"""

from __future__ import annotations

import hashlib
import io
import re
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import matplotlib as mpl
import pandas as pd

from harness.kit.figure_cache import keep_figures_of
from harness.kit.figure_style import RC_PARAMS
from harness.kit.svg_paths import SVG_DECIMALS, compact_path, dedupe_style, round_numbers

__all__ = ["Figure", "UnsafeFigureError", "check_svg", "to_svg", "SVG_DECIMALS", "page_css", "short_classes",
           "short_ids"]


_SVG_NS = "{http://www.w3.org/2000/svg}"
_XLINK = "{http://www.w3.org/1999/xlink}href"
_ALLOWED_TAGS = {"svg", "g", "path", "defs", "clipPath", "use", "text", "tspan", "rect", "style",
                 "metadata", "title", "desc", "circle", "ellipse", "line", "polyline", "polygon",
                 "image", "pattern", "linearGradient", "radialGradient", "stop", "mask"}
_RDF_TAGS = {"RDF", "Work", "type", "date", "format", "creator", "Agent", "title"}


class UnsafeFigureError(ValueError):
    """A figure's SVG holds something that must not be embedded in the report."""


@keep_figures_of
@dataclass(frozen=True)
class Figure:
    """One figure: its slug (unique in the report), inline SVG text, a short alt text, the
    tidy table of what it draws (offered for download beside it), and the style rules its
    classes need (`css`; the page holds every figure's rules once, see `page_css`)."""

    slug: str
    svg: str
    alt: str
    data: pd.DataFrame | None = field(default=None, compare=False, repr=False)
    css: str = field(default="", compare=False, repr=False)

    def standalone(self) -> str:
        """The SVG with its style rules inside (for use outside the report page).

        Returns
        -------
        str: an SVG document with an `xmlns` and a <style> element (when the figure has rules).
        """
        svg = self.svg if "xmlns=" in self.svg.split(">", 1)[0] else \
            self.svg.replace("<svg", '<svg xmlns="http://www.w3.org/2000/svg"', 1)
        if not self.css:
            return svg
        head_end = svg.find(">") + 1
        return f"{svg[:head_end]}<style>{self.css}</style>{svg[head_end:]}"


def page_css(figures: Iterable[Figure]) -> str:
    """The style rules of `figures`, each once: classes are named by a hash of their rule, so
    the same line style in two figures is one rule of the page.

    Parameters
    ----------
    figures : iterable of Figure, the page's figures.

    Returns
    -------
    str: the rules, in first-seen order; `UnsafeFigureError` when they hold a '<'.
    """
    rules: dict[str, None] = {}
    for fig in figures:
        for rule in re.findall(r"[^{}]+\{[^{}]*\}", fig.css):
            rules.setdefault(rule, None)
    css = "".join(rules)
    if "<" in css:  # matplotlib's style text never holds markup; refuse if it ever does
        raise UnsafeFigureError("figure style rules hold a '<'")
    return css



_CLASS = re.compile(r'(?<=class=")k[0-9a-f]{7}(?=")|(?<=^\.)k[0-9a-f]{7}(?=\{)|(?<=\}\.)k[0-9a-f]{7}(?=\{)')
# lower case only: class names are case-insensitive in a page without a doctype (quirks mode)
_DIGITS = "0123456789abcdefghijklmnopqrstuvwxyz"


def _short_name(i: int) -> str:
    out = ""
    while True:
        i, r = divmod(i, len(_DIGITS))
        out = _DIGITS[r] + out
        if i == 0:
            return "z" + out
        i -= 1


def short_classes(svgs: Sequence[str], css: str) -> tuple[list[str], str]:
    """The page's figures and their style rules with each hashed class name (`k` + 7 hex
    digits, thousands of uses) replaced by a short one, the most used shortest: `z` and one to
    three letters or digits (no class of the page's own stylesheet starts with `z`).

    Parameters
    ----------
    svgs : sequence of str, the figures' SVG text.
    css : str, the page's figure rules (`page_css`).

    Returns
    -------
    (list of str, str): the SVG texts and the rules, renamed alike.
    """
    counts: dict[str, int] = {}
    for text in svgs:
        for m in _CLASS.finditer(text):
            counts[m.group(0)] = counts.get(m.group(0), 0) + 1
    for m in _CLASS.finditer(css):
        counts.setdefault(m.group(0), 0)
    names = {c: _short_name(i) for i, c in enumerate(sorted(counts, key=lambda c: (-counts[c], c)))}

    def sub(text: str) -> str:
        return _CLASS.sub(lambda m: names[m.group(0)], text)

    return [sub(t) for t in svgs], sub(css)


_FIGURE_ID = re.compile(r'(id="|href="#|url\(#)(f[0-9a-f]{5}i\d+)(?=[")])')


def short_ids(html: str) -> str:
    """The page with every figure's ids (salted per figure so they are unique on the page:
    `f` + 5 hex digits + `i` + a number, repeated by every marker and clip reference) replaced
    by short page-wide ones (`y` + letters or digits), none taken by another id of the page.

    Parameters
    ----------
    html : str, the whole page.

    Returns
    -------
    str: the page, ids and their references renamed.
    """
    found = list(dict.fromkeys(m.group(2) for m in _FIGURE_ID.finditer(html) if m.group(1) == 'id="'))
    taken = set(re.findall(r'\bid="([^"]+)"', html)) - set(found)
    names: dict[str, str] = {}
    i = 0
    for old in found:
        while (name := "y" + _short_name(i)[1:]) in taken:
            i += 1
        names[old] = name
        i += 1
    return _FIGURE_ID.sub(lambda m: m.group(1) + names.get(m.group(2), m.group(2)), html)


# -- SVG output -----------------------------------------------------------------------------------
def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def check_svg(svg: str) -> str:
    """Return `svg` when it is a plain drawing: well-formed, only drawing elements, no script,
    no event attribute, no link outside the figure. Raise `UnsafeFigureError` otherwise.

    Parameters
    ----------
    svg : str, one figure's SVG text.

    Returns
    -------
    str: `svg` unchanged.
    """
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
    deterministic inline SVG.

    Parameters
    ----------
    fig : matplotlib Figure; laid out by fixed margins when it has `harness_layout` set, else
        cropped to a tight bounding box.
    slug : str, the figure's name, unique in the report (salts its ids and class names).
    alt : str, the text read in place of the picture.
    data : DataFrame, optional, the tidy table of what it draws (offered as a download).

    Returns
    -------
    Figure: checked by `check_svg`; `UnsafeFigureError` when matplotlib wrote no drawing.
    """
    buf = io.StringIO()
    tight = not getattr(fig, "harness_layout", False)
    with _rc(slug):
        fig.savefig(buf, format="svg", bbox_inches="tight" if tight else None,
                    metadata={"Date": None})
    text = buf.getvalue()
    start = text.find("<svg")
    if start < 0:
        raise UnsafeFigureError("matplotlib wrote no <svg> element")
    text, css = _shrink(text[start:], "f" + hashlib.sha1(slug.encode()).hexdigest()[:5])
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
    # inline in HTML, an <svg> needs neither its namespace nor a version (`standalone` output
    # puts the namespace back)
    text = text.replace(f' xmlns="{_NS}"', "", 1).replace(' version="1.1"', "", 1)
    return Figure(slug=slug, svg=text, alt=alt, data=data, css=css)


_NS = "http://www.w3.org/2000/svg"
_XLINK_NS = "http://www.w3.org/1999/xlink"


def _shrink(svg: str, salt: str) -> tuple[str, str]:
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
    _group_runs(root, "clip-path", _clip_hoistable)
    styles: dict[str, int] = {}
    for el in root.iter():
        whole = _local(el.tag) in ("text", "use")  # labels and markers: to whole points, as lines
        for name in ("d", "x", "y", "points"):
            if name in el.attrib:
                value = el.attrib[name]
                if name == "d":
                    # a two-point data line (a fitted slope, a floor) too; not a marker's
                    # shape (defined once, with an id), whose tenths of a point matter
                    el.set(name, compact_path(value, 3 if "id" in el.attrib else 2))
                elif whole and name in ("x", "y") and re.fullmatch(r"-?[\d.]+", value.strip()):
                    el.set(name, str(round(float(value))))
                else:
                    el.set(name, round_numbers(value))
        tr = el.attrib.get("transform", "")
        if re.fullmatch(r"rotate\(-?0(?:\s[^)]*)?\)", tr):
            del el.attrib["transform"]
        st = el.attrib.get("style")
        if st is not None:
            st = dedupe_style(re.sub(r"\s*([:;])\s*", r"\1", st).strip().rstrip(";"))
            el.set("style", st)
            styles[st] = styles.get(st, 0) + 1
    # every style becomes a class named by its rule's hash: the page holds each rule once
    classes = {st: "k" + hashlib.sha1(st.encode()).hexdigest()[:7] for st in styles}
    for el in root.iter():
        st = el.attrib.get("style")
        if st in classes:
            del el.attrib["style"]
            el.set("class", classes[st])
    inherited = {c for st, c in classes.items() if _only_inherited(st)}
    _group_runs(root, "class", lambda el: _local(el.tag) == "text" and el.attrib.get("class") in inherited,
                min_run=3)
    for g in root.iter(f"{{{_NS}}}g"):  # a run of markers of one style: the class once, on the group
        kids = list(g)
        first = kids[0].attrib.get("class") if kids else None
        if first and "class" not in g.attrib and all(
                _local(k.tag) == "use" and k.attrib.get("class") == first for k in kids):
            g.set("class", first)
            for k in kids:
                del k.attrib["class"]
    css = "".join(f".{c}{{{st}}}" for st, c in classes.items())
    for parent in root.iter():  # matplotlib's own <style> (one global rule) joins the page's
        for child in list(parent):
            if _local(child.tag) == "style":
                css = re.sub(r"\s*([:;{}])\s*", r"\1", child.text or "") + css
                parent.remove(child)
    for parent in root.iter():
        for child in list(parent):
            if _local(child.tag) == "defs" and not len(child):
                parent.remove(child)
    text = ET.tostring(root, encoding="unicode").replace(" />", "/>")
    # SVG 2's plain `href` (every current browser): each marker's <use> is a few bytes shorter
    text = text.replace(' xlink:href="#', ' href="#')
    if "xlink:" not in text.split(">", 1)[1]:
        text = text.replace(f' xmlns:xlink="{_XLINK_NS}"', "", 1)
    # shorter ids (every marker use repeats one): salted, since ids are page-wide
    ids = sorted(dict.fromkeys(re.findall(r'\sid="([\w.-]+)"', text)), key=len, reverse=True)
    for i, old in enumerate(ids):
        text = text.replace(f'id="{old}"', f'id="{salt}i{i}"').replace(f'"#{old}"', f'"#{salt}i{i}"') \
            .replace(f"url(#{old})", f"url(#{salt}i{i})")
    return text, css


# Properties a child takes from its group when it does not set them (and that the one global
# rule matplotlib writes, for stroke joins and caps, does not set on every element).
_INHERITED = {"fill", "fill-opacity", "font", "font-family", "font-size", "font-style", "font-weight",
              "text-anchor"}


def _only_inherited(style: str) -> bool:
    return all(d.partition(":")[0] in _INHERITED for d in style.split(";") if d)


def _clip_hoistable(el: ET.Element) -> bool:
    # a clip path is drawn in the user space of the element it is set on: a group's equals its
    # children's only where the child has no transform of its own
    return "clip-path" in el.attrib and "transform" not in el.attrib


def _group_runs(root: ET.Element, attr: str, eligible: Any, min_run: int = 2) -> None:
    """Runs of at least `min_run` consecutive siblings that are `eligible` and share one value
    of `attr` become a `<g attr=value>` around them, the attribute written once (the drawing
    order is unchanged)."""
    for parent in list(root.iter()):
        kids = list(parent)
        if len(kids) < min_run:
            continue
        out: list[ET.Element] = []
        k = 0
        while k < len(kids):
            el = kids[k]
            value = el.attrib.get(attr) if eligible(el) else None
            j = k + 1
            while value is not None and j < len(kids) and eligible(kids[j]) \
                    and kids[j].attrib.get(attr) == value:
                j += 1
            if value is not None and j - k >= min_run:
                g = ET.Element(f"{{{_NS}}}g", {attr: value})
                for child in kids[k:j]:
                    del child.attrib[attr]
                    g.append(child)
                out.append(g)
            else:
                out.extend(kids[k:j])
            k = j
        if len(out) != len(kids):
            parent[:] = out


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
    return mpl.rc_context({**RC_PARAMS, "svg.hashsalt": f"harness-report-{slug}"})



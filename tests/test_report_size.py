"""The report's bytes: what makes the full report fit its budget draws the same thing in fewer
bytes (relative paths, shared figure styles, gzipped data links), and the size breakdown adds up.

The full report's own size (every experiment over the whole registry, 1.5 MB budget) is measured
by `python -m harness.report.sizes reports/latest/index.html` on `make report`'s output, not
here: it takes minutes of measuring.
"""

from __future__ import annotations

import base64
import gzip
import io
import math
import re

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure as MplFigure

from harness.kit import csv_download
from harness.kit.figure_style import styled
from harness.kit.figure_svg import check_svg, page_css, to_svg
from harness.kit.svg_paths import relative_path
from harness.report.sizes import report_sizes, section_totals


def _absolute_points(d: str) -> list[tuple[float, float]]:
    """The points of a path of moves, lines, horizontal/vertical lines and closes (absolute or
    relative, implicit repeats) in absolute numbers (a close adds nothing)."""
    points, x, y, sx, sy = [], 0.0, 0.0, 0.0, 0.0
    for letter, nums in re.findall(r"([MLHVZmlhvz])([^MLHVZmlhvz]*)", d):
        values = [float(v) for v in re.findall(r"-?(?:\d+\.?\d*|\.\d+)", nums)]
        if letter in "Zz":
            x, y = sx, sy
            continue
        step = 1 if letter in "HVhv" else 2
        for k in range(0, len(values), step):
            c = letter if k == 0 else {"M": "L", "m": "l"}.get(letter, letter)
            rel = c.islower()
            if c in "Hh":
                x = x + values[k] if rel else values[k]
            elif c in "Vv":
                y = y + values[k] if rel else values[k]
            else:
                dx, dy = values[k], values[k + 1]
                x, y = (x + dx, y + dy) if rel else (dx, dy)
            if c in "Mm":
                sx, sy = x, y
            points.append((round(x, 6), round(y, 6)))
    assert points
    return points


@pytest.mark.parametrize("d", [
    "M10 20L11.5 19.5L12 22M30 30L31 31",
    "M0.1 0.9L0.2 0.8L-3.4 5L-3.4 5.1L100 0",
    "M5 5L5 5L5 5",
    "M10 10L20 10L20 30L10 10",
])
def test_relative_paths_draw_the_same_points(d):
    for scale in (1, 10):  # whole points, tenths
        short = relative_path(d, scale)
        exact = [(round(x * scale) / scale, round(y * scale) / scale) for x, y in _absolute_points(d)]
        drawn = _absolute_points(short)
        # zero-length steps are dropped; every point drawn is the exact one, rounded
        assert [p for k, p in enumerate(exact) if k == 0 or p != exact[k - 1]] == drawn
        assert len(short) <= len(d)


def test_closed_shapes_keep_tenths_and_return_to_their_start():
    d = "M54 230.4L291.6 230.4L291.6 36L54 36zM10 10L20 10L20 20z"
    short = relative_path(d, 1)
    assert short == "M54 230.4h237.6v-194.4h-237.6zm-44-220.4h10v10z"
    assert _absolute_points(short) == _absolute_points(d)


def _distance_to_polyline(p, line) -> float:
    best = math.inf
    for (ax, ay), (bx, by) in zip(line, line[1:], strict=False):
        dx, dy = bx - ax, by - ay
        t = 0.0 if dx == dy == 0 else max(0.0, min(1.0, ((p[0] - ax) * dx + (p[1] - ay) * dy)
                                                    / (dx * dx + dy * dy)))
        best = min(best, math.hypot(p[0] - ax - t * dx, p[1] - ay - t * dy))
    return best


def test_thinned_lines_stay_within_the_tolerance_of_every_point():
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.uniform(0.5, 3, 200))
    y = 100 + np.cumsum(rng.normal(0, 0.3, 200))
    d = "M" + "L".join(f"{a:.2f} {b:.2f}" for a, b in zip(x, y, strict=True))
    thin = relative_path(d, 1, tolerance=0.4)
    drawn = _absolute_points(thin)
    assert len(drawn) < 150
    assert drawn[0] == (round(x[0]), round(y[0])) and drawn[-1] == (round(x[-1]), round(y[-1]))
    # every original point: within the tolerance plus the rounding to whole points
    assert max(_distance_to_polyline(p, drawn) for p in zip(x, y, strict=True)) <= 0.4 + 0.71


def test_other_paths_are_left_as_they_are():
    for d in ("M0 0L1 1C2 2 3 3 4 4", "M0 0L1 1z", "M1 1", "M0 0L1 1"):
        assert relative_path(d) == d


@styled
def _figure(colour: str, slug: str):
    fig = MplFigure(figsize=(3, 2))
    ax = fig.subplots()
    x = np.geomspace(1e-3, 1, 30)
    ax.loglog(x, x ** 2, "o-", color=colour)
    ax.loglog(x, x ** 3, "--", color="#1f77b4")
    return to_svg(fig, slug, "test", pd.DataFrame({"h": x, "error": x ** 2}))


def test_figures_share_their_style_rules_on_the_page():
    a, b = _figure("#d62728", "a"), _figure("#2ca02c", "b")
    for fig in (a, b):
        assert "<style" not in fig.svg and "style=" not in fig.svg
        check_svg(fig.svg)
        check_svg(fig.standalone())
        classes = set(re.findall(r'class="(k[0-9a-f]{7})"', fig.svg))
        assert classes and all(f".{c}{{" in fig.css for c in classes)
    css = page_css([a, b])
    shared = set(re.findall(r"\.(k[0-9a-f]{7})\{", a.css)) & set(re.findall(r"\.(k[0-9a-f]{7})\{", b.css))
    assert shared  # the axes, the grid and the common line style
    for c in shared:
        assert css.count(f".{c}{{") == 1
    assert len(css) < len(a.css) + len(b.css)


def test_data_links_are_gzipped_csv_of_the_figures_table():
    frame = pd.DataFrame({"stepper": ["a", "b", "c"] * 200, "h": np.geomspace(1e-4, 1, 600),
                          "error": np.linspace(1, 2, 600)})
    dl = csv_download(frame, "convergence-x.csv")
    assert dl.filename == "convergence-x.csv.gz" and dl.rows == 600
    head, payload = dl.uri.split(",", 1)
    assert head == "data:application/gzip;base64"
    back = pd.read_csv(io.BytesIO(gzip.decompress(base64.b64decode(payload))))
    assert list(back.columns) == ["stepper", "h", "error"] and len(back) == 600
    assert np.allclose(back["h"], frame["h"], rtol=1e-3)
    assert dl.size < len(frame.to_csv(index=False)) / 2


def test_the_size_breakdown_adds_up_to_the_file():
    svg = _figure("#d62728", "c").svg
    html = ('<html><head><style>x{}</style></head><body>'
            '<section id="one"><h2>1</h2><figure>' + svg + '<figcaption>c <a class="data" '
            'download="c.csv.gz" href="data:application/gzip;base64,AAAA">c</a></figcaption></figure>'
            '<div class="table-wrap"><table id="t1"><tr><td>1</td></tr></table>\n</div></section>'
            '<section id="two"><p>text</p></section></body></html>')
    sizes = report_sizes(html)
    assert sizes["bytes"].sum() == len(html.encode("utf-8"))
    totals = section_totals(sizes)
    assert list(totals.index) == ["one", "two", "(page)"]
    assert totals.loc["one", "figure"] > 0 and totals.loc["one", "csv"] > 0 and totals.loc["one", "table"] > 0
    assert totals.loc["two", ["figure", "csv", "table"]].sum() == 0

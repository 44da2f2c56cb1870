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
import re

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure as MplFigure

from harness.report.figure_style import styled
from harness.report.figure_svg import _relative_path, check_svg, page_css, to_svg
from harness.report.sections import csv_download
from harness.report.sizes import report_sizes, section_totals


def _absolute_points(d: str) -> list[tuple[float, float]]:
    """The points of an M/L path (absolute or relative, implicit repeats) in absolute numbers."""
    points, x, y, cmd = [], 0.0, 0.0, ""
    for letter, nums in re.findall(r"([MLml])([^MLml]*)", d):
        values = [float(v) for v in re.findall(r"-?(?:\d+\.?\d*|\.\d+)", nums)]
        for k in range(0, len(values), 2):
            c = letter if k == 0 else ("l" if letter in "ml" else "L")
            dx, dy = values[k], values[k + 1]
            x, y = (x + dx, y + dy) if c.islower() else (dx, dy)
            points.append((round(x, 6), round(y, 6)))
            cmd = c
    assert cmd
    return points


@pytest.mark.parametrize("d", [
    "M10 20L11.5 19.5L12 22M30 30L31 31",
    "M0.1 0.9L0.2 0.8L-3.4 5L-3.4 5.1L100 0",
    "M5 5L5 5L5 5",
])
def test_relative_paths_draw_the_same_points(d):
    for scale in (1, 10):  # whole points, tenths
        short = _relative_path(d, scale)
        exact = [(round(x * scale) / scale, round(y * scale) / scale) for x, y in _absolute_points(d)]
        drawn = _absolute_points(short)
        # zero-length steps are dropped; every point drawn is the exact one, rounded
        assert [p for k, p in enumerate(exact) if k == 0 or p != exact[k - 1]] == drawn
        assert len(short) <= len(d)


def test_other_paths_are_left_as_they_are():
    for d in ("M0 0L1 1C2 2 3 3 4 4", "M0 0L1 1z", "M1 1", "M0 0L1 1"):
        assert _relative_path(d) == d


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

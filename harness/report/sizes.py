"""Where a report's bytes go: per section, per figure (drawing and its CSV link) and per table.

`report_sizes(html)` reads a written report (the template's markup, no HTML parser needed) and
returns one row per item; `python -m harness.report.sizes reports/latest/index.html` prints the
sections' totals and the largest items. The issue's budget for the whole report is
`SIZE_BUDGET_BYTES`.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pandas as pd

__all__ = ["SIZE_BUDGET_BYTES", "report_sizes", "section_totals", "main"]

# The full report (every experiment over the whole registry) stays a file a reader downloads
# and opens without waiting: 1.5 MB (issue 13).
SIZE_BUDGET_BYTES = 1_500_000

_SECTION = re.compile(r'<section id="([^"]+)".*?</section>', re.DOTALL)
_FIGURE = re.compile(r"<figure>.*?</figure>", re.DOTALL)
_SLUG = re.compile(r'data-slug="([^"]+)"')
_CSV = re.compile(r'<a class="data"[^>]*href="data:[^"]*"[^>]*>')
_TABLE = re.compile(r'<div class="table-wrap">.*?</table>\s*</div>(?:\s*<ol class="notes">.*?</ol>)?',
                    re.DOTALL)
_TABLE_ID = re.compile(r'<table[^>]*\bid="([^"]+)"')


def report_sizes(html: str) -> pd.DataFrame:
    """One row per item of each section: kind ('figure', 'csv', 'table', 'other' for the
    section's remaining text), name (figure slug or table id), bytes (UTF-8).

    Parameters
    ----------
    html : str, a written report page.

    Returns
    -------
    DataFrame: columns section, kind, name, bytes.
    """
    rows = []

    def size(text: str) -> int:
        return len(text.encode("utf-8"))

    for m in _SECTION.finditer(html):
        section, text = m.group(1), m.group(0)
        rest = size(text)
        for fig in _FIGURE.finditer(text):
            slug = _SLUG.search(fig.group(0))
            name = slug.group(1) if slug else "figure"
            csv = sum(size(c) for c in _CSV.findall(fig.group(0)))
            rows.append((section, "figure", name, size(fig.group(0)) - csv))
            if csv:
                rows.append((section, "csv", name, csv))
            rest -= size(fig.group(0))
        for k, table in enumerate(_TABLE.finditer(text)):
            tid = _TABLE_ID.search(table.group(0))
            rows.append((section, "table", tid.group(1) if tid else f"table {k + 1}", size(table.group(0))))
            rest -= size(table.group(0))
        rows.append((section, "other", "", rest))
    inside = sum(size(m.group(0)) for m in _SECTION.finditer(html))
    rows.append(("(page)", "other", "head, style, navigation, footer", size(html) - inside))
    return pd.DataFrame(rows, columns=["section", "kind", "name", "bytes"])


def section_totals(sizes: pd.DataFrame) -> pd.DataFrame:
    """Bytes per section and kind (columns figure, csv, table, other, total), in page order.

    Parameters
    ----------
    sizes : DataFrame, as `report_sizes` returns it.

    Returns
    -------
    DataFrame: indexed by section.
    """
    order = list(dict.fromkeys(sizes["section"]))
    t = sizes.pivot_table(index="section", columns="kind", values="bytes", aggfunc="sum", fill_value=0)
    for k in ("figure", "csv", "table", "other"):
        if k not in t:
            t[k] = 0
    t = t[["figure", "csv", "table", "other"]].reindex(order)
    return t.assign(total=t.sum(axis=1))


def main(argv: list[str] | None = None) -> int:
    """`python -m harness.report.sizes REPORT.html`: print the page's size against its budget,
    the bytes per section and the 15 largest items.

    Parameters
    ----------
    argv : list of str, optional, the arguments (default `sys.argv[1:]`); exactly one path.

    Returns
    -------
    int: 0, or 2 for a wrong argument count.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) != 1:
        print("usage: python -m harness.report.sizes REPORT.html", file=sys.stderr)
        return 2
    html = Path(args[0]).read_text(encoding="utf-8")
    sizes = report_sizes(html)
    total = len(html.encode("utf-8"))
    print(f"{args[0]}: {total / 1e6:.3f} MB (budget {SIZE_BUDGET_BYTES / 1e6:.1f} MB)")
    print(section_totals(sizes).to_string())
    print("\nlargest items:")
    print(sizes[sizes["kind"] != "other"].nlargest(15, "bytes").to_string(index=False))
    sys.stdout.flush()
    return 0


if __name__ == "__main__":  # pragma: no cover
    try:
        sys.exit(main())
    except BrokenPipeError:  # the reader (`| head`) has what it wanted
        sys.stderr.close()
        sys.exit(141)

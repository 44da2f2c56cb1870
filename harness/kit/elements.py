"""The report's document model and formatting: text cells, rows, tables (as data), gzipped CSV
data links, blocks and sections, and the number/verdict formatting every section uses. The
template renders these; nothing here knows about experiments."""

from __future__ import annotations

import base64
import gzip
import hashlib
import math
import re
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from harness.kit.figure_svg import Figure

FAIL, PASS, NONE = "fail", "pass", "none"
MARK = {FAIL: "✗ FAIL", PASS: "✓ pass", NONE: "– not measured"}
# Columns whose text is a reason: written once per table as a numbered note.
NOTE_COLUMNS = ("message", "reason", "prediction_note")
# Columns of folded tables whose value is written once per run of equal rows (the rows of one
# problem follow each other); a row a link points to shows it in full.
DITTO_COLUMNS = ("problem", "h", "steps", "states")
# Columns never shown in a generic table (bookkeeping, not measurement).
HIDDEN_COLUMNS = ("wall_s", "ensemble_size", "params", "key")


# -- the data the template renders ----------------------------------------------------------------
@dataclass
class TextCell:
    """A table cell: plain text, or `parts` ((text, href) pairs; href "" for plain text) when
    several numbers in one cell each link to their own row; `swatch` a method's colour."""

    text: str
    cls: str = ""
    title: str = ""
    href: str = ""
    parts: list[tuple[str, str]] = field(default_factory=list)
    swatch: str = ""


@dataclass
class Row:
    cells: list[TextCell]
    cls: str = ""
    stepper: str = ""
    id: str = ""


@dataclass
class Table:
    caption: str
    columns: list[str]
    rows: list[Row]
    cls: str = ""
    id: str = ""
    notes: list[tuple[int, str]] = field(default_factory=list)
    # folded tables are rendered inside <details> with the caption as summary
    folded: bool = False
    # columns (indices) whose cell is left blank where it repeats the row above (folded tables)
    ditto: list[int] = field(default_factory=list)


@dataclass
class Download:
    """A tidy table embedded as a gzip-compressed CSV `data:` link."""

    filename: str
    uri: str
    rows: int
    size: int


@dataclass
class Block:
    """One piece of a section: kind 'figure' (figure, caption, CSV link), 'table', 'note' (a
    paragraph), 'heading', 'pre', 'details' (summary + pre text), 'list' (items: (text, href)),
    'downloads'."""

    kind: str
    text: str = ""
    figure: Figure | None = None
    table: Table | None = None
    summary: str = ""
    cls: str = ""
    items: list[tuple[str, str]] = field(default_factory=list)
    download: Download | None = None
    downloads: list[Download] = field(default_factory=list)


@dataclass
class Section:
    id: str
    number: int
    title: str
    intro: str = ""
    blocks: list[Block] = field(default_factory=list)

    def note(self, text: str, cls: str = "") -> None:
        """Append a paragraph of text.

        Parameters
        ----------
        text, cls : str, the paragraph (HTML-escaped when written) and an optional CSS class.
        """
        self.blocks.append(Block("note", text=text, cls=cls))

    def heading(self, text: str) -> None:
        """Append a sub-heading.

        Parameters
        ----------
        text : str, the heading's words.
        """
        self.blocks.append(Block("heading", text=text))

    def figure(self, fig: Figure | None, caption: str) -> None:
        """Append a figure with its caption and a CSV download of its data.

        Parameters
        ----------
        fig : Figure or None, the figure (None appends nothing: a figure with nothing to draw).
        caption : str, the text under the figure.
        """
        if fig is not None:
            dl = csv_download(fig.data, f"{fig.slug}.csv") if fig.data is not None else None
            self.blocks.append(Block("figure", figure=fig, text=caption, download=dl))

    def table(self, table: Table) -> None:
        """Append a table.

        Parameters
        ----------
        table : Table, the rows, headers and caption (built by `df_table` or by hand).
        """
        self.blocks.append(Block("table", table=table))

    def details(self, summary: str, text: str) -> None:
        """Append a folded block, closed until the reader opens it.

        Parameters
        ----------
        summary, text : str, the line shown while folded, and the content shown when opened.
        """
        self.blocks.append(Block("details", summary=summary, text=text))


class SectionTimer:
    """Seconds spent building each section (reported in the provenance section)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}

    def run(self, name: str, fn: Callable[[], Any]) -> Any:
        """Call `fn` and add its wall time to `seconds[name]` (also when it raises).

        Parameters
        ----------
        name : str, the key the time accumulates under.
        fn : callable with no arguments, the work.

        Returns
        -------
        Any: what `fn` returns.
        """
        started = time.perf_counter()
        try:
            return fn()
        finally:
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - started


# -- formatting -----------------------------------------------------------------------------------
def fmt(x: Any, digits: int = 3) -> str:
    """A number for a table: `digits` significant digits, 'inf' spelled out, '—' for missing.

    Parameters
    ----------
    x : Any, a number, bool, string or missing value.
    digits : int, optional, significant digits (default 3).

    Returns
    -------
    str: the cell text ('yes'/'no' for a bool, 'unbounded' for +inf).
    """
    if x is None:
        return "—"
    if isinstance(x, bool | np.bool_):
        return "yes" if x else "no"
    if isinstance(x, str):
        return x or "—"
    try:
        v = float(x)
    except (TypeError, ValueError):
        return str(x)
    if math.isnan(v):
        return "—"
    if math.isinf(v):
        return "unbounded" if v > 0 else "-inf"
    if v != 0 and (abs(v) < 1e-3 or abs(v) >= 1e5):
        # 4.63e-4, 1.31e5: the exponent without its padding zero and plus sign (thousands of
        # table cells)
        mantissa, exponent = f"{v:.{max(digits - 1, 0)}e}".split("e")
        if "." in mantissa:  # trailing zeros go, as in the plain numbers' `g` format
            mantissa = mantissa.rstrip("0").rstrip(".")
        return mantissa + _EXPONENT.sub(r"e\1\2", "e" + exponent)
    return _EXPONENT.sub(r"e\1\2", f"{v:.{digits}g}")  # `g` writes 1e+04 for 10000 at 3 digits


_EXPONENT = re.compile(r"e\+?(-?)0*(\d)")


def is_missing(v: Any) -> bool:
    """Whether `v` is None, NaN or a pandas missing value.

    Parameters
    ----------
    v : Any, a cell value (a list or an array reads as not missing).

    Returns
    -------
    bool: True when missing; False also for values pandas cannot test.
    """
    if v is None:
        return True
    try:
        return bool(pd.isna(v))
    except (TypeError, ValueError):
        return False


def yes_no(x: Any) -> str:
    """A truth value as a cell's text.

    Parameters
    ----------
    x : Any, a truth value or a missing value.

    Returns
    -------
    str: 'yes', 'no', or '—' when missing.
    """
    return "—" if is_missing(x) else ("yes" if bool(x) else "no")


def text_cell(x: Any, digits: int = 3, cls: str = "", href: str = "") -> TextCell:
    """A table cell holding `x` formatted by `fmt`.

    Parameters
    ----------
    x : Any, the value; a number gets the CSS class 'num' unless `cls` is given.
    digits : int, optional, significant digits of a number (default 3).
    cls, href : str, optional, the cell's CSS class and link target.

    Returns
    -------
    TextCell: the formatted cell.
    """
    numeric = isinstance(x, int | float | np.number) and not isinstance(x, bool | np.bool_)
    return TextCell(fmt(x, digits), cls=cls or ("num" if numeric else ""), href=href)


# Status cells of folded per-cell tables (thousands of rows): one short class each.
# (a pass or a failure needs none: the table's `st` class colours its first column, the row's
# `failing` class says which)
FOLDED_STATUS_CLASS = {FAIL: "", PASS: "", NONE: "sn"}


# ... and their marks: a failure spelled out, a pass or nothing measured as its sign alone (the
# colour and the column say the rest).
FOLDED_MARK = {FAIL: MARK[FAIL], PASS: "✓", NONE: "–"}


def status_cell(passed: Any, folded: bool = False) -> TextCell:
    """A pass/fail/missing mark as a table cell.

    Parameters
    ----------
    passed : Any, a truth value; missing gives the neutral mark.
    folded : bool, optional, use the compact marks of a folded table (default False).

    Returns
    -------
    TextCell: the mark with its status CSS class.
    """
    status = NONE if is_missing(passed) else (PASS if bool(passed) else FAIL)
    if folded:
        return TextCell(FOLDED_MARK[status], cls=FOLDED_STATUS_CLASS[status])
    return TextCell(MARK[status], cls=f"status {status}")


def anchor(*parts: Any) -> str:
    """A stable, safe HTML id for a table row: a short hash of the exact key (names from
    plugins may hold any character).

    Parameters
    ----------
    *parts : Any, the key (experiment, stepper, problem, ...), each turned into text.

    Returns
    -------
    str: 'r-' followed by 10 hex digits of the key's SHA-1.
    """
    key = "\x1f".join(str(p) for p in parts)
    # a short hash only: every link repeats it (hundreds in the scoreboard)
    return f"r-{hashlib.sha1(key.encode()).hexdigest()[:10]}"


def first_sentence(text: Any, limit: int = 220) -> str:
    """The first sentence of a reason, at most `limit` characters.

    Parameters
    ----------
    text : Any, the reason (None reads as empty); whitespace runs become one space.
    limit : int, optional, the longest result in characters (default 220; cut with '…').

    Returns
    -------
    str: the text up to its first '. ', trailing punctuation dropped.
    """
    s = " ".join(str(text or "").split())
    m = re.search(r"(?<=\.)\s", s)
    if m:
        s = s[:m.start()]
    s = s.rstrip(";,: ")
    return s if len(s) <= limit else s[:limit - 1] + "…"


# Significant digits of the numbers in a figure's CSV: what the figure shows and more (the full
# precision is in the run's saved tables, results/<run id>/).
CSV_DIGITS = 4
# ... and of wall times (seconds), which vary by more than that from run to run.
WALL_DIGITS = 2


def csv_download(df: pd.DataFrame | None, filename: str) -> Download | None:
    """`df` as an embedded, gzip-compressed CSV link (`<name>.csv.gz`, numbers with CSV_DIGITS
    significant digits): a figure's tidy table costs the page a third of its CSV text or less,
    and every CSV reader opens it (`pandas.read_csv` reads .gz directly). The archive carries
    no date, so a report's bytes depend on its data only.

    Parameters
    ----------
    df : DataFrame or None, the table; wall-time columns are rounded to WALL_DIGITS digits.
    filename : str, the offered file name (unsafe characters replaced, '.gz' appended).

    Returns
    -------
    Download or None: the data-URI link; None when `df` is None or has no columns.
    """
    if df is None or not len(df.columns):
        return None
    timed = [c for c in df.columns if str(c) == "wall_s" or str(c).endswith("_wall_s")]
    if timed:  # a wall time on a shared machine is good to a few per cent: two digits
        df = df.assign(**{c: pd.to_numeric(df[c], errors="coerce").map(
            lambda v: float(f"{v:.{WALL_DIGITS}g}") if np.isfinite(v) else v) for c in timed})
    text = df.to_csv(index=False, float_format=f"%.{CSV_DIGITS}g", lineterminator="\n")
    packed = gzip.compress(text.encode("utf-8"), compresslevel=9, mtime=0)
    uri = "data:application/gzip;base64," + base64.b64encode(packed).decode("ascii")
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "-", filename)[:120]
    return Download(stem if stem.endswith(".gz") else stem + ".gz", uri, len(df), len(uri))


def df_table(df: pd.DataFrame, columns: Sequence[tuple[str, str]], caption: str, *,
             experiment: str = "", key: Sequence[str] = ("stepper", "problem"),
             status: str | None = "passed", digits: int = 3, sort_failing: bool = True,
             folded: bool = True, cls: str = "", id: str = "",
             links: Mapping[str, str] | None = None) -> Table:
    """A Table from `df`: `columns` are (column name, header) pairs; a leading status column from
    the `status` column (failing rows first when `sort_failing`); each row's id is
    `anchor(experiment, *key values)`; a reason column (NOTE_COLUMNS) holds a reference to a
    numbered note below the table, each distinct reason written once. `links` maps a shown
    column to a column of `df` holding the href its cell links to.

    Parameters
    ----------
    df : DataFrame, one row per table row.
    columns : sequence of (column, header), the columns shown, in order.
    caption : str, the table's caption.
    experiment : str, optional, the experiment name, first part of each row anchor and of the id.
    key : sequence of str, optional, the columns naming a row (default stepper, problem).
    status : str or None, optional, the pass/fail column (None: no status column).
    digits : int, optional, significant digits of numbers (default 3).
    sort_failing, folded : bool, optional, failing rows first; reasons as numbered notes (both
        default True).
    cls, id : str, optional, the table's CSS class and HTML id (default: hash of experiment, caption).
    links : mapping of str to str, optional, shown column -> column of `df` with its href.

    Returns
    -------
    Table: the rows, headers, notes and caption.
    """
    links = dict(links or {})
    if sort_failing and status and status in df and len(df):
        k = df[status].map(lambda v: 0 if (not is_missing(v) and not bool(v)) else 1)
        df = df.assign(_k=k).sort_values("_k", kind="stable").drop(columns="_k")
    headers = ([""] if status else []) + [f"{h} (note)" if folded and c in NOTE_COLUMNS else h
                                          for c, h in columns]
    # short: every note reference repeats it
    table_id = id or (f"t-{hashlib.sha1(f'{experiment}{caption}'.encode()).hexdigest()[:6]}"
                      if experiment else "")
    notes: dict[str, int] = {}
    rows = []
    for rec in df.to_dict("records"):
        cells = []
        rcls = ""
        if status:
            v = rec.get(status)
            cells.append(status_cell(v, folded))
            if not is_missing(v) and not bool(v):
                rcls = "failing"
        for col, _ in columns:
            v = rec.get(col)
            if col in NOTE_COLUMNS:
                text = "" if is_missing(v) else " ".join(str(v).split())
                if text:
                    n = notes.setdefault(text, len(notes) + 1)
                    cells.append(TextCell(f"note {n}" if not folded else str(n), cls="" if folded else "nr",
                                          href=f"#{table_id}-n{n}" if table_id else ""))
                else:
                    cells.append(TextCell(""))
            else:
                c = text_cell(v, digits, href=str(rec.get(links[col]) or "") if col in links else "")
                if folded and c.cls == "num":  # folded tables align numbers by their own CSS
                    c.cls = ""
                if folded and c.text == "—" and not c.href and col not in DITTO_COLUMNS:
                    c.text = ""  # nothing measured: an empty cell (a blank ditto cell repeats)
                cells.append(c)
        rid = anchor(experiment, *(rec.get(c, "") for c in key)) if experiment else ""
        rows.append(Row(cells, cls=rcls, id=rid))
    ditto = []
    if folded:
        for k, (col, _) in enumerate(columns):
            if col in DITTO_COLUMNS:
                ditto.append(k + (1 if status else 0))
        if ditto:
            named = [headers[k] for k in ditto]
            shown = ", ".join(named[:-1]) + (" or " if len(named) > 1 else "") + named[-1]
            caption = (f"{caption} (a blank {shown} cell: as in the row above; a blank elsewhere: "
                       "nothing measured)")
    if folded and status:
        cls = f"{cls} st".strip()
    return Table(caption, headers, rows, cls=cls, id=table_id,
                 notes=[(n, t) for t, n in notes.items()], folded=folded, ditto=ditto)


def drop_unlinked_row_ids(sections: Sequence[Section]) -> int:
    """Clear the id of every folded table's row that no link of the page points to (a row id
    costs ~20 bytes, over thousands of rows; the rows that the scoreboard, the verdict list or
    the changed-since section link to keep theirs), and blank the cells that repeat the row
    above (`Table.ditto`). Returns how many ids were cleared.

    Parameters
    ----------
    sections : sequence of Section, the whole page (links are looked for in every section).

    Returns
    -------
    int: the number of row ids cleared.
    """
    linked: set[str] = set()
    for sec in sections:
        for b in sec.blocks:
            linked.update(h[1:] for _, h in b.items if h.startswith("#"))
            if b.table is not None:
                for r in b.table.rows:
                    for c in r.cells:
                        if c.href.startswith("#"):
                            linked.add(c.href[1:])
                        linked.update(h[1:] for _, h in c.parts if h.startswith("#"))
    cleared = 0
    for sec in sections:
        for b in sec.blocks:
            if b.table is not None and b.table.folded:
                for r in b.table.rows:
                    if r.id and r.id not in linked:
                        r.id = ""
                        cleared += 1
                _blank_repeats(b.table)
    return cleared


def _blank_repeats(table: Table) -> None:
    """Blank the `ditto` cells that repeat the row above (not in a row a link points to)."""
    for k in table.ditto:
        previous = None
        for r in table.rows:
            if k >= len(r.cells):
                continue
            c = r.cells[k]
            text = c.text
            if text == previous and not r.id and not c.href and not c.parts:
                r.cells[k] = TextCell("", cls=c.cls)
            previous = text

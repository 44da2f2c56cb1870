"""The report's sections, built from a saved run: tables as data, figures as checked SVG.

`build_sections(view, ...)` returns the sections the template renders in order:
- Verdicts: how many claims were checked and which failed (one sentence each), then the
  scoreboard, each of whose numbers links to the table row it comes from;
- What changed since the last run (`harness.report.compare`), when an earlier run is given;
- one section per experiment of the registry (`harness.experiments.EXPERIMENTS`), in its order,
  each built by the builder registered for it with `register_section` (built-ins in
  `harness.report.experiment_sections`) or, for an experiment nobody registered a builder for,
  by the generic table section;
- Ground truth, Claims from the course material, Provenance, Performance history.

Every text here is plain text; the template escapes it. Only figure SVG is embedded as markup,
after `figures.check_svg` has passed it. Per-cell tables are folded in `<details>`; a reason
shared by many rows is written once as a numbered note below its table and referred to.
"""

from __future__ import annotations

import base64
import gzip
import hashlib
import json
import math
import re
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from harness.report import figures as F

__all__ = ["Section", "Table", "Row", "TextCell", "Block", "Download", "RunView", "SectionSpec",
           "Measure", "ScoreColumn", "SECTION_BUILDERS", "register_section", "section_spec",
           "build_sections", "section_titles", "anchor", "df_table", "csv_download", "fmt",
           "SectionTimer"]

FAIL, PASS, NONE = "fail", "pass", "none"
MARK = {FAIL: "✗ FAIL", PASS: "✓ pass", NONE: "– not measured"}
# Columns whose text is a reason: written once per table as a numbered note.
NOTE_COLUMNS = ("message", "reason")
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
    figure: F.Figure | None = None
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
        self.blocks.append(Block("note", text=text, cls=cls))

    def heading(self, text: str) -> None:
        self.blocks.append(Block("heading", text=text))

    def figure(self, fig: F.Figure | None, caption: str) -> None:
        if fig is not None:
            dl = csv_download(fig.data, f"{fig.slug}.csv") if fig.data is not None else None
            self.blocks.append(Block("figure", figure=fig, text=caption, download=dl))

    def table(self, table: Table) -> None:
        self.blocks.append(Block("table", table=table))

    def details(self, summary: str, text: str) -> None:
        self.blocks.append(Block("details", summary=summary, text=text))


class SectionTimer:
    """Seconds spent building each section (reported in the provenance section)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}

    def run(self, name: str, fn: Callable[[], Any]) -> Any:
        started = time.perf_counter()
        try:
            return fn()
        finally:
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - started


# -- formatting -----------------------------------------------------------------------------------
def fmt(x: Any, digits: int = 3) -> str:
    """A number for a table: `digits` significant digits, 'inf' spelled out, '—' for missing."""
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
        return f"{v:.{max(digits - 1, 0)}e}"
    return f"{v:.{digits}g}"


def is_missing(v: Any) -> bool:
    if v is None:
        return True
    try:
        return bool(pd.isna(v))
    except (TypeError, ValueError):
        return False


def yes_no(x: Any) -> str:
    return "—" if is_missing(x) else ("yes" if bool(x) else "no")


def text_cell(x: Any, digits: int = 3, cls: str = "", href: str = "") -> TextCell:
    numeric = isinstance(x, int | float | np.number) and not isinstance(x, bool | np.bool_)
    return TextCell(fmt(x, digits), cls=cls or ("num" if numeric else ""), href=href)


def _status_cell(passed: Any) -> TextCell:
    if is_missing(passed):
        return TextCell(MARK[NONE], cls="status none")
    if bool(passed):
        return TextCell(MARK[PASS], cls="status pass")
    return TextCell(MARK[FAIL], cls="status fail")


def anchor(*parts: Any) -> str:
    """A stable, safe HTML id for a table row: readable slug plus a short hash of the exact
    key (names from plugins may hold any character)."""
    key = "\x1f".join(str(p) for p in parts)
    slug = re.sub(r"[^a-z0-9]+", "-", key.lower()).strip("-")[:16]  # every link repeats it
    return f"r-{slug}-{hashlib.sha1(key.encode()).hexdigest()[:6]}"


def first_sentence(text: Any, limit: int = 220) -> str:
    """The first sentence of a reason, at most `limit` characters."""
    s = " ".join(str(text or "").split())
    m = re.search(r"(?<=\.)\s", s)
    if m:
        s = s[:m.start()]
    s = s.rstrip(";,: ")
    return s if len(s) <= limit else s[:limit - 1] + "…"


# Significant digits of the numbers in a figure's CSV: what the figure shows and more (the full
# precision is in the run's saved tables, results/<run id>/).
CSV_DIGITS = 4


def csv_download(df: pd.DataFrame | None, filename: str) -> Download | None:
    """`df` as an embedded, gzip-compressed CSV link (`<name>.csv.gz`, numbers with CSV_DIGITS
    significant digits): a figure's tidy table costs the page a third of its CSV text or less,
    and every CSV reader opens it (`pandas.read_csv` reads .gz directly). The archive carries
    no date, so a report's bytes depend on its data only."""
    if df is None or not len(df.columns):
        return None
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
    column to a column of `df` holding the href its cell links to."""
    links = dict(links or {})
    if sort_failing and status and status in df and len(df):
        k = df[status].map(lambda v: 0 if (not is_missing(v) and not bool(v)) else 1)
        df = df.assign(_k=k).sort_values("_k", kind="stable").drop(columns="_k")
    headers = ([""] if status else []) + [h for _, h in columns]
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
            cells.append(_status_cell(v))
            if not is_missing(v) and not bool(v):
                rcls = "failing"
        for col, _ in columns:
            v = rec.get(col)
            if col in NOTE_COLUMNS:
                text = "" if is_missing(v) else " ".join(str(v).split())
                if text:
                    n = notes.setdefault(text, len(notes) + 1)
                    cells.append(TextCell(f"note {n}", cls="noteref",
                                          href=f"#{table_id}-n{n}" if table_id else ""))
                else:
                    cells.append(TextCell(""))
            else:
                c = text_cell(v, digits, href=str(rec.get(links[col]) or "") if col in links else "")
                if folded and c.cls == "num":  # folded tables align numbers by their own CSS
                    c.cls = ""
                cells.append(c)
        rid = anchor(experiment, *(rec.get(c, "") for c in key)) if experiment else ""
        rows.append(Row(cells, cls=rcls, id=rid))
    return Table(caption, headers, rows, cls=cls, id=table_id,
                 notes=[(n, t) for t, n in notes.items()], folded=folded)


# -- inputs -----------------------------------------------------------------------------------------
@dataclass
class RunView:
    """What the sections read: per-experiment rows and summaries, failures, the stepper infos."""

    rows: dict[str, pd.DataFrame]
    summaries: dict[str, pd.DataFrame]
    meta: dict
    steppers: list[str]
    problems: list[str]
    infos: dict[str, Any]
    origins: dict[str, str]
    quick: bool
    palette: F.Palette
    run_id: str = ""

    def gate(self) -> pd.DataFrame:
        """The CI gate's judgement of every convergence cell (computed once per report)."""
        cached = self.__dict__.get("_gate")
        if cached is None:
            from harness.gate import gate_table

            conv = self.summary("convergence")
            cached = gate_table(conv) if len(conv) and "stepper" in conv else pd.DataFrame(
                columns=["stepper", "problem", "passed", "reason", "verdict", "expected"])
            self.__dict__["_gate"] = cached
        return cached

    def has(self, name: str) -> bool:
        return name in self.summaries and name in self.meta.get("experiments", {})

    def summary(self, name: str) -> pd.DataFrame:
        return self.summaries.get(name, pd.DataFrame())

    def rowtable(self, name: str) -> pd.DataFrame:
        return self.rows.get(name, pd.DataFrame())

    def failures(self, name: str | None = None) -> list[dict]:
        exps = self.meta.get("experiments", {})
        names = [name] if name else list(exps)
        out = []
        for n in names:
            out.extend(exps.get(n, {}).get("failures", []))
        return out

    def skips(self, name: str) -> list[dict]:
        return self.meta.get("experiments", {}).get(name, {}).get("skips", [])

    def flag(self, attr: str) -> dict[str, bool]:
        """stepper -> a boolean of its info (symmetric, symplectic, adaptive...)."""
        return {n: bool(getattr(i, attr, False)) for n, i in self.infos.items()}


# -- the section registry ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Measure:
    """A measured figure of an experiment's summary that the changed-since comparison follows:
    its column, how to name it, and its confidence interval (two columns), or else the relative
    change (`rtol`) or the factor (`factor`) beyond which it counts as moved."""

    column: str
    label: str
    ci: tuple[str, str] | None = None
    rtol: float | None = None
    factor: float | None = None


@dataclass(frozen=True)
class ScoreColumn:
    """A scoreboard column an experiment contributes: its header, and per stepper the cell as
    (text, anchor) parts (each number linked to the row it comes from, "" for plain text) and
    whether anything was measured."""

    header: str
    value: Callable[[RunView, str], tuple[list[tuple[str, str]], bool]]


@dataclass(frozen=True)
class SectionSpec:
    """How an experiment's section is built: `build(view, section)` adds the figures and tables;
    `intro` is two sentences (what is measured, how to read it); `key` the summary columns that
    identify one judged row; `measures` the figures the changed-since comparison follows;
    `verdicts(view)` overrides the judged rows (default: the summary's `passed` column);
    `score` the scoreboard columns this experiment fills."""

    experiment: str
    title: str
    intro: str
    build: Callable[[RunView, Section], None]
    key: tuple[str, ...] = ("stepper", "problem")
    measures: tuple[Measure, ...] = ()
    verdicts: Callable[[RunView], pd.DataFrame] | None = None
    score: tuple[ScoreColumn, ...] = ()


SECTION_BUILDERS: dict[str, SectionSpec] = {}


def register_section(experiment: str, *, title: str, intro: str,
                     key: Sequence[str] = ("stepper", "problem"), measures: Sequence[Measure] = (),
                     verdicts: Callable[[RunView], pd.DataFrame] | None = None,
                     score: Sequence[ScoreColumn] = ()) -> Callable:
    """Decorator: register `build(view, section)` as the section of `experiment`."""

    def deco(build: Callable[[RunView, Section], None]) -> Callable[[RunView, Section], None]:
        SECTION_BUILDERS[experiment] = SectionSpec(experiment, title, intro, build, tuple(key),
                                                   tuple(measures), verdicts, tuple(score))
        return build

    return deco


def section_spec(experiment: str) -> SectionSpec:
    """The registered spec of `experiment`, or the generic table section built from the
    experiment's own description."""
    from harness.report import experiment_sections  # noqa: F401  (registers the built-ins)

    spec = SECTION_BUILDERS.get(experiment)
    if spec is not None:
        return spec
    description = ""
    try:
        from harness.experiments import get_experiment

        description = get_experiment(experiment).description
    except Exception:
        pass
    intro = (f"{description.rstrip('.') or 'The ' + experiment + ' experiment'}. One row per cell "
             "of the experiment; the first column is its verdict against the stepper's claim.")
    return SectionSpec(experiment, experiment.replace("-", " ").capitalize(), intro, generic_section)


def generic_section(view: RunView, sec: Section) -> None:
    """The fallback: the experiment's summary as one folded table, every column."""
    name = sec.id
    summ = view.summary(name)
    spec = SECTION_BUILDERS.get(name)
    key = spec.key if spec else _generic_key(summ)
    cols = [(c, c.replace("_", " ")) for c in summ.columns if c not in ("passed", *HIDDEN_COLUMNS)]
    sec.table(df_table(summ, cols, f"{name}: one row per cell", experiment=name, key=key,
                       status="passed" if "passed" in summ else None))


def _generic_key(summ: pd.DataFrame) -> tuple[str, ...]:
    key = [c for c in ("stepper", "problem") if c in summ]
    for extra in ("steps", "kind", "quantity", "h", "tol"):
        if key and len(summ) and summ.duplicated(key).any() and extra in summ:
            key.append(extra)
    return tuple(key)


def experiment_key(name: str, summ: pd.DataFrame) -> tuple[str, ...]:
    spec = SECTION_BUILDERS.get(name)
    return spec.key if spec is not None else _generic_key(summ)


def missing(sec: Section, view: RunView, name: str) -> bool:
    """Add a note and return True when experiment `name` has no results in this run."""
    if not view.has(name):
        sec.note(f"The {name} experiment is not part of this run, so this section has no "
                 "measurements.", cls="warning")
        return True
    fails = view.failures(name)
    if view.summary(name).empty:
        why = f" All {len(fails)} of its cells failed (see Provenance)." if fails else ""
        sec.note(f"The {name} experiment produced no results for this selection.{why}", cls="warning")
        return True
    if fails:
        sec.note(f"{len(fails)} cell(s) of the {name} experiment failed and are missing here; "
                 "they are listed with their messages under Provenance.", cls="warning")
    return False


def skip_note(sec: Section, view: RunView, name: str) -> None:
    skips = view.skips(name)
    if skips:
        reasons: dict[str, int] = {}
        for s in skips:
            reasons[s.get("reason", "")] = reasons.get(s.get("reason", ""), 0) + 1
        sec.details(f"{len(skips)} pairs not applicable to the {name} experiment, and why",
                    "\n".join(f"{n} × {r}" for r, n in sorted(reasons.items(), key=lambda kv: -kv[1])))


# -- the sections in order ---------------------------------------------------------------------------
FIXED_BEFORE = (("verdicts", "Verdicts"), ("changes", "What changed since the last run"))
FIXED_AFTER = (("ground-truth", "Ground truth"), ("claims", "Claims from the course material, checked"),
               ("gate-population", "How much to trust the gate"),
               ("provenance", "Provenance"), ("performance-history", "Performance history"))


def section_titles(experiments: Iterable[str]) -> list[tuple[str, str]]:
    """(id, title) of every section, in order, for a run of `experiments`."""
    return ([*FIXED_BEFORE] + [(e, section_spec(e).title) for e in experiments] + [*FIXED_AFTER])


def build_sections(view: RunView, *, run_id: str, results_path: str, build_s: Mapping[str, float],
                   previous: Any = None, progress: Callable[[str], None] | None = None
                   ) -> tuple[list[Section], dict[str, str], dict[str, Any]]:
    """Every section in order, each stepper's scoreboard status, and the headline counts
    (claims checked, failed, failing list) the page's first screen shows."""
    from harness.report import fixed_sections as X
    from harness.report.verdicts import collect_verdicts

    timer = SectionTimer()
    say = progress or (lambda _msg: None)
    experiments = _in_registry_order(list(view.meta.get("experiments", {})))
    titles = section_titles(experiments)
    number = {k: i + 1 for i, (k, _) in enumerate(titles)}
    say("verdicts")
    verdicts = timer.run("verdicts", lambda: collect_verdicts(view))
    head, statuses = timer.run("scoreboard", lambda: X.verdicts_section(view, verdicts, experiments))
    head.number = number["verdicts"]
    out: list[Section] = [head]
    say("changes")
    names = dict(titles)
    changes = timer.run("changes", lambda: _guarded(
        lambda v: X.changes_section(v, verdicts, previous), view, "changes", number, names))
    out.append(changes)
    since = next((b for b in changes.blocks if b.kind == "headline"), None)
    if since is not None:  # the first screen says what changed, too
        head.blocks.insert(1, Block("list", items=[(since.text, "#changes")], cls="since"))
    for name in experiments:
        say(name)
        out.append(timer.run(name, lambda name=name: _guarded(
            lambda v: _experiment_section(v, name, number[name]), view, name, number, names)))
    trust = lambda v: X.gate_trust(v, Path(results_path).parent)  # noqa: E731
    for key, fn in (("ground-truth", X.ground_truth), ("claims", X.claims), ("gate-population", trust)):
        say(key)
        out.append(timer.run(key, lambda fn=fn, key=key: _guarded(fn, view, key, number, names)))
    say("performance history")
    perf = timer.run("performance-history", X.performance_history)
    prov = X.provenance(view, run_id=run_id, results_path=results_path, timer=timer, build_s=build_s)
    for sec in (prov, perf):
        sec.number = number[sec.id]
    out += [prov, perf]
    for sec in out:
        sec.number = number.get(sec.id, sec.number)
    failing = verdicts[~verdicts["passed"].astype(bool)] if len(verdicts) else verdicts
    headline = {"checked": int(len(verdicts)), "failed": int(len(failing)),
                "experiments": int(verdicts["experiment"].nunique()) if len(verdicts) else 0,
                "verdicts": verdicts}
    return out, statuses, headline


def _in_registry_order(names: list[str]) -> list[str]:
    """The run's experiments in the registry's order (the order they finished in the run is
    not the reader's), any the registry does not know at the end."""
    from harness.experiments import EXPERIMENTS

    order = {n: i for i, n in enumerate(EXPERIMENTS)}
    return sorted(names, key=lambda n: (order.get(n, len(order)), names.index(n)))


def _experiment_section(view: RunView, name: str, number: int) -> Section:
    spec = section_spec(name)
    sec = Section(name, number, spec.title, intro=spec.intro)
    if missing(sec, view, name):
        return sec
    spec.build(view, sec)
    skip_note(sec, view, name)
    return sec


def _guarded(fn: Callable[[RunView], Section], view: RunView, name: str,
             number: Mapping[str, int], titles: Mapping[str, str] | None = None) -> Section:
    """A section whose building fails still appears, with the error, so the report is written."""
    try:
        sec = fn(view)
        sec.number = number.get(name, sec.number)
        return sec
    except Exception as exc:
        import traceback

        title = (titles or {}).get(name, name)
        sec = Section(name, number.get(name, 0), title)
        sec.note(f"This section could not be built: {type(exc).__name__}: {exc}", cls="warning")
        sec.details("traceback", traceback.format_exc(limit=-6))
        return sec


def json_text(obj: Any) -> str:
    return json.dumps(obj, indent=2, sort_keys=True, default=str)

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

import contextlib
import json
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from harness.report import figures as F
from harness.report.elements import (  # noqa: F401  (re-exported: the sections' vocabulary)
    CSV_DIGITS,
    FAIL,
    HIDDEN_COLUMNS,
    MARK,
    NONE,
    NOTE_COLUMNS,
    PASS,
    Block,
    Download,
    Row,
    Section,
    SectionTimer,
    Table,
    TextCell,
    anchor,
    csv_download,
    df_table,
    drop_unlinked_row_ids,
    first_sentence,
    fmt,
    is_missing,
    status_cell,
    text_cell,
    yes_no,
)

__all__ = ["Section", "Table", "Row", "TextCell", "Block", "Download", "RunView", "SectionSpec",
           "Measure", "ScoreColumn", "SECTION_BUILDERS", "register_section", "section_spec",
           "build_sections", "section_titles", "anchor", "df_table", "csv_download", "fmt",
           "SectionTimer"]


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
    `score` the scoreboard columns this experiment fills; `row_key` the columns that identify a
    row of the section's table when it folds several judged rows into one (links to a judged
    row go to the row holding it; default: `key`)."""

    experiment: str
    title: str
    intro: str
    build: Callable[[RunView, Section], None]
    key: tuple[str, ...] = ("stepper", "problem")
    measures: tuple[Measure, ...] = ()
    verdicts: Callable[[RunView], pd.DataFrame] | None = None
    score: tuple[ScoreColumn, ...] = ()
    row_key: tuple[str, ...] | None = None

    @property
    def anchor_key(self) -> tuple[str, ...]:
        return self.row_key or self.key


SECTION_BUILDERS: dict[str, SectionSpec] = {}


def register_section(experiment: str, *, title: str, intro: str,
                     key: Sequence[str] = ("stepper", "problem"), measures: Sequence[Measure] = (),
                     verdicts: Callable[[RunView], pd.DataFrame] | None = None,
                     score: Sequence[ScoreColumn] = (),
                     row_key: Sequence[str] | None = None) -> Callable:
    """Decorator: register `build(view, section)` as the section of `experiment`."""

    def deco(build: Callable[[RunView, Section], None]) -> Callable[[RunView, Section], None]:
        SECTION_BUILDERS[experiment] = SectionSpec(experiment, title, intro, build, tuple(key),
                                                   tuple(measures), verdicts, tuple(score),
                                                   tuple(row_key) if row_key else None)
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
FIXED_AFTER = (("ground-truth", "Ground truth"), ("test-sets", "Published test sets"),
               ("claims", "Claims from the course material, checked"),
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
    # the experiment sections (their figures: most of a cold report's section time) start in
    # forked processes now, while this one judges the verdicts
    pending = _start_experiment_sections(view, experiments, number, dict(titles))
    try:
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
            out.append(_finish_experiment_section(pending, view, name, number, names, timer))
        trust = lambda v: X.gate_trust(v, Path(results_path).parent)  # noqa: E731
        from harness.report.test_sets import test_sets_section

        for key, fn in (("ground-truth", X.ground_truth), ("test-sets", test_sets_section),
                        ("claims", X.claims), ("gate-population", trust)):
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
        drop_unlinked_row_ids(out)
        failing = verdicts[~verdicts["passed"].astype(bool)] if len(verdicts) else verdicts
        judged = verdicts[verdicts["judged"].astype(bool)] if len(verdicts) else verdicts
        headline = {"checked": int(len(judged)), "failed": int(len(failing)),
                    "informational": int(len(verdicts) - len(judged)),
                    "experiments": int(verdicts["experiment"].nunique()) if len(verdicts) else 0,
                    "verdicts": verdicts}
        return out, statuses, headline
    finally:
        _close(pending)


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


# -- experiment sections in forked processes ---------------------------------------------------------
# A cold report spent 39 s building sections, 28 s of them drawing the energy and convergence
# figures, one after another. The experiment sections depend only on the run's view, so they are
# built in forked worker processes (the view reaches them through the fork, not pickled), the
# largest tables first; each Section comes back pickled. Without `fork` (not POSIX), on one core,
# or when a worker fails, a section is built here as before.
_FORKED_VIEW: list[RunView] = []


def _section_in_worker(name: str, number: Mapping[str, int], titles: Mapping[str, str]
                       ) -> tuple[Section, float]:
    import time

    started = time.perf_counter()
    sec = _built_section(_FORKED_VIEW[0], name, number, titles)
    return sec, time.perf_counter() - started


def _built_section(view: RunView, name: str, number: Mapping[str, int],
                   titles: Mapping[str, str]) -> Section:
    return _guarded(lambda v: _experiment_section(v, name, number[name]), view, name, number, titles)


@dataclass
class _Pending:
    pool: Any
    futures: dict[str, Any]


def _start_experiment_sections(view: RunView, experiments: Sequence[str], number: Mapping[str, int],
                               titles: Mapping[str, str]) -> _Pending | None:
    import multiprocessing
    import os
    from concurrent.futures import ProcessPoolExecutor

    workers = min(os.cpu_count() or 1, len(experiments))
    if workers < 2 or "fork" not in multiprocessing.get_all_start_methods():
        return None
    size = {name: len(view.rows.get(name, ())) for name in experiments}
    _FORKED_VIEW[:] = [view]
    import signal

    from harness.runner.executors import workers_born_deaf

    try:  # forked with the signals ignored until `_quiet_signals` (the parent's handlers raise)
        with workers_born_deaf((signal.SIGINT, signal.SIGTERM)):
            pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("fork"),
                                       initializer=_quiet_signals)
            futures = {name: pool.submit(_section_in_worker, name, dict(number), dict(titles))
                       for name in sorted(experiments, key=lambda n: -size[n])}
    except (OSError, RuntimeError):  # no process could be started: build them here
        _FORKED_VIEW.clear()
        return None
    return _Pending(pool, futures)


def _quiet_signals() -> None:
    """In a forked section worker: Ctrl-C and SIGTERM (sent to the whole process group) end it
    at once and silently; the parent, which got them too, reports the interruption once."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _finish_experiment_section(pending: _Pending | None, view: RunView, name: str,
                               number: Mapping[str, int], titles: Mapping[str, str],
                               timer: SectionTimer) -> Section:
    future = pending.futures.get(name) if pending is not None else None
    if future is not None:
        try:
            sec, seconds = future.result()
        except Exception:  # a worker died or its section could not come back: build it here
            pass
        else:
            timer.seconds[name] = seconds
            return sec
    return timer.run(name, lambda: _built_section(view, name, number, titles))


def _close(pending: _Pending | None) -> None:
    import sys

    from harness.errors import Terminated

    if pending is not None:  # interrupted: the workers got the signal too; do not wait for them
        interrupted = isinstance(sys.exc_info()[1], KeyboardInterrupt | SystemExit | Terminated)
        if interrupted:  # one forked while the signals were ignored may have missed it
            for proc in list((getattr(pending.pool, "_processes", None) or {}).values()):
                with contextlib.suppress(Exception):
                    proc.terminate()
        pending.pool.shutdown(wait=not interrupted, cancel_futures=True)
    _FORKED_VIEW.clear()


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

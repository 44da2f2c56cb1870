"""The report's sections in order, built from a saved run: the assembler.

`build_sections(view, ...)` returns the sections the template renders in order:
- Verdicts: how many claims were checked and which failed (one sentence each), then the
  scoreboard, each of whose numbers links to the table row it comes from;
- What changed since the last run (`harness.report.compare`), when an earlier run is given;
- one section per experiment of the registry (`harness.experiments.EXPERIMENTS`), in its order,
  each the one its experiment names (`Experiment.section`, a `harness.kit.SectionSpec`) or, for
  an experiment that names none, the generic table section (`harness.kit.section`);
- Ground truth, Published test sets, Claims from the course material, How much to trust the
  gate, Provenance, Performance history (`harness.report.fixed_sections`).

Every text here is plain text; the template escapes it. Only figure SVG is embedded as markup,
after `harness.kit.figure_svg.check_svg` has passed it.
"""

from __future__ import annotations

import contextlib
import json
import multiprocessing
import os
import signal
import sys
import time
import traceback
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from harness.errors import Terminated
from harness.experiments import EXPERIMENTS
from harness.kit.elements import Block, Section, SectionTimer, drop_unlinked_row_ids
from harness.kit.section import missing, skip_note
from harness.kit.view import RunView
from harness.report import fixed_sections as X
from harness.report.specs import section_spec
from harness.report.test_sets import test_sets_section
from harness.report.verdicts import collect_verdicts
from harness.runner.executors import workers_born_deaf

__all__ = ["build_sections", "section_titles", "section_spec"]


# -- the sections in order ---------------------------------------------------------------------------
FIXED_BEFORE = (("verdicts", "Verdicts"), ("changes", "What changed since the last run"))
FIXED_AFTER = (("ground-truth", "Ground truth"), ("test-sets", "Published test sets"),
               ("claims", "Claims from the course material, checked"),
               ("gate-population", "How much to trust the gate"),
               ("provenance", "Provenance"), ("performance-history", "Performance history"))


def section_titles(experiments: Iterable[str]) -> list[tuple[str, str]]:
    """(id, title) of every section, in order, for a run of `experiments`.

    Parameters
    ----------
    experiments : iterable of str, the run's experiments, in report order.

    Returns
    -------
    list of (str, str): the fixed sections before and after the experiments' own.
    """
    return ([*FIXED_BEFORE] + [(e, section_spec(e).title) for e in experiments] + [*FIXED_AFTER])


def build_sections(view: RunView, *, run_id: str, results_path: str, build_s: Mapping[str, float],
                   previous: Any = None, progress: Callable[[str], None] | None = None
                   ) -> tuple[list[Section], dict[str, str], dict[str, Any]]:
    """Every section in order, each stepper's scoreboard status, and the headline counts
    (claims checked, failed, failing list) the page's first screen shows.

    Parameters
    ----------
    view : RunView, the run.
    run_id : str, its id.
    results_path : str, its directory, as shown in Provenance.
    build_s : mapping of str to float, seconds of the build phases so far.
    previous : Previous, optional, the earlier run for "what changed" (None: the first run).
    progress : callable, optional, receives a line per section built.

    Returns
    -------
    (list of Section, dict of str to str, dict): the sections, the scoreboard statuses, the
        headline counts.
    """
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
    workers = min(os.cpu_count() or 1, len(experiments))
    if workers < 2 or "fork" not in multiprocessing.get_all_start_methods():
        return None
    size = {name: len(view.rows.get(name, ())) for name in experiments}
    _FORKED_VIEW[:] = [view]

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
        title = (titles or {}).get(name, name)
        sec = Section(name, number.get(name, 0), title)
        sec.note(f"This section could not be built: {type(exc).__name__}: {exc}", cls="warning")
        sec.details("traceback", traceback.format_exc(limit=-6))
        return sec


def json_text(obj: Any) -> str:
    """`obj` as indented JSON with sorted keys (values JSON cannot hold written as text).

    Parameters
    ----------
    obj : Any, the value (dates, paths and the like via `str`).

    Returns
    -------
    str
    """
    return json.dumps(obj, indent=2, sort_keys=True, default=str)

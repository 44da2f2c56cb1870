"""Orchestration of a run: list an experiment's cells, reuse the cached ones, run the others on
the chosen executor, and assemble the `RunResult` (see the package docstring for the guarantees)."""

from __future__ import annotations

import json
import os
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from harness.errors import (
    HarnessError,
    InputError,
    NoApplicableCellsError,
)
from harness.experiments.base import Cell, Experiment, Skip, failed_record
from harness.keys import cell_key, code_version, experiment_fingerprint
from harness.progress import Progress
from harness.registry import load_plugin
from harness.runner.checks import (
    check_jobs,
    check_names,
    check_plugins,
    check_scheduler,
    progress_display,
    resolve_config,
    resolve_experiment,
)
from harness.runner.executors import (
    Task,
    dask_client,
    run_dask,
    run_loky,
    run_serial,
)
from harness.runner.limits import (
    check_timeout,
)
from harness.runner.memory import (
    guard_memory,
)
from harness.runner.packs import read_pack, summarize_packed, write_pack
from harness.runner.result import (
    CELL_COLUMNS,
    FAILURE_COLUMNS,
    ID_COLUMNS,
    SKIP_COLUMNS,
    RunResult,
)
from harness.runner.validation import SCALARS, CellOutputError
from harness.runner.workers import (
    one_line,
    plugin_spec,
    shipped_objects,
    short_traceback,
)
from harness.store import (
    CellCache,
    encode_cell,
)

FAILURE_KINDS = ("error", "invalid", "timeout", "crash", "lookup", "version", "summarize")


class ExperimentError(HarnessError):
    """An experiment could not list its cells (the message names the experiment)."""



# -- the runner -------------------------------------------------------------------------------------
def _skip_records(skips: Iterable[Skip]) -> list[dict]:
    return [{"experiment": s.experiment, "stepper": s.stepper, "problem": s.problem,
             "reason": s.reason} for s in skips]


def no_cells_error(experiments: Sequence[str], skips: Sequence[Skip] | pd.DataFrame,
                   steppers: Sequence[str], problems: Sequence[str]) -> NoApplicableCellsError:
    """The error for a run over zero applicable cells: one line saying why each requested pair
    does not apply (the experiments' skip reasons); every record is kept in `.skips`.

    Parameters
    ----------
    experiments : sequence of str, the experiments run.
    skips : sequence of Skip or DataFrame, their skip records.
    steppers, problems : sequence of str, the requested names.

    Returns
    -------
    NoApplicableCellsError
    """
    records = (skips.to_dict("records") if isinstance(skips, pd.DataFrame)
               else _skip_records(skips))
    what = ", ".join(map(repr, experiments))
    head = (f"no cell of {what} applies to the requested stepper(s) "
            f"{_few(steppers)} x problem(s) {_few(problems)}")
    if not records:
        return NoApplicableCellsError(head + " (the experiment lists no pairs for them)", records)
    reasons = [f"{r['stepper'] or '-'} x {r['problem'] or '-'}: {r['reason']}" for r in records[:4]]
    more = f"; and {len(records) - 4} more pairs" if len(records) > 4 else ""
    return NoApplicableCellsError(f"{head}: " + "; ".join(reasons) + more, records)


def _few(names: Sequence[str], n: int = 4) -> str:
    shown = ", ".join(names[:n]) if names else "(none)"
    return shown + (f" (+{len(names) - n} more)" if len(names) > n else "")


def _params_json(cell: Cell) -> str:
    return json.dumps({str(k): v for k, v in cell.params}, sort_keys=True, default=repr)


def _with_ids(rows: pd.DataFrame, cell: Cell) -> pd.DataFrame:
    rows = rows.reset_index(drop=True)
    front = {"experiment": cell.experiment, "cell": cell.label, "stepper": cell.stepper,
             "problem": cell.problem}
    for k, v in cell.params:
        if isinstance(k, str) and k and isinstance(v, SCALARS):
            front.setdefault(k, v.item() if isinstance(v, np.generic) else v)
    add = {k: v for k, v in front.items() if k not in rows.columns}
    if not add:
        return rows
    ids = pd.DataFrame({k: [v] * len(rows) for k, v in add.items()})
    return pd.concat([ids, rows], axis=1)


def _roundtrip(key: str, rows: pd.DataFrame, info: Mapping[str, Any]) -> tuple[pd.DataFrame, bytes]:
    """Rows as they come back from the cell file (so fresh and cached cells are identical), and
    the file's bytes for the cache (`harness.store.encode_cell`)."""
    try:
        return encode_cell(key, rows, info)
    except InputError as exc:
        raise CellOutputError(f"rows {exc}") from None


@dataclass(frozen=True)
class RunOptions:
    """How to run cells, as one object: what `run_experiments` hands to each `run_experiment`
    (and what a caller may pass as `options=` instead of the keywords of the same names)."""

    quick: bool = False
    jobs: int | None = None
    scheduler: str | Any | None = None
    fresh: bool = False
    cache: bool = True
    cache_dir: str | os.PathLike | None = None
    plugins: tuple[str | os.PathLike, ...] = ()
    cell_timeout: float | None = None


def run_experiment(
    experiment: str | Experiment,
    steppers: Sequence[str] | None = None,
    problems: Sequence[str] | None = None,
    *,
    config: Mapping[str, Any] | None = None,
    options: RunOptions | None = None,
    quick: bool = False,
    jobs: int | None = None,
    scheduler: str | Any | None = None,
    fresh: bool = False,
    cache: bool = True,
    cache_dir: str | os.PathLike | None = None,
    plugins: Sequence[str | os.PathLike] = (),
    cell_timeout: float | None = None,
    progress: Progress | bool | str | None = None,
    allow_empty: bool = False,
    _client: Any = None,
    _counted: bool = False,
    _listed: tuple[list, list] | None = None,
    _versions: dict[tuple[str, str], Any] | None = None,
) -> RunResult:
    """Run one experiment over `steppers` x `problems` (None: the whole registry).

    Parameters
    ----------
    experiment : str or Experiment, the experiment, or its registered name.
    steppers, problems : sequence of str, optional, registered names (None: every one).
    config : mapping, optional, overrides of the experiment's settings.
    options : RunOptions, optional
        Supplies `quick`, `jobs`, `scheduler`, `fresh`, `cache`, `cache_dir`, `plugins` and
        `cell_timeout` in place of those keywords.
    quick : bool, optional, start from the experiment's quick settings.
    jobs : int, optional, worker processes (None: all cores; 1: in this process).
    scheduler : str or distributed.Client, optional
        A Dask scheduler (``tcp://HOST:PORT``) or client, instead of local processes.
    fresh : bool, optional, recompute cached cells.
    cache : bool, optional, false: neither read nor write the cache.
    cache_dir : str or PathLike, optional, the cache root (default `harness.cache.cache_dir()`).
    plugins : sequence of paths, optional
        .py files loaded here and on every worker before names are looked up.
    cell_timeout : float, optional, seconds per cell.
    progress : Progress, bool or str, optional
        None/True (bar on a terminal, plain lines otherwise), False (silent), a mode ('bar',
        'lines', 'off') or a shared `Progress`.
    allow_empty : bool, optional, return an empty result instead of raising when no cell applies.
    _client, _counted, _listed, _versions
        Internal: what `run_experiments` shares between its experiments.

    Returns
    -------
    RunResult
        Rows, summary, failures, skips, per-cell records, counts and wall time.

    Raises `InputError` / `UnknownNameError` / `PluginError` (all `HarnessError`) for bad
    arguments before any cell runs, `NoApplicableCellsError` (with every skip reason) when no
    requested pair applies, `ExperimentError` when the experiment cannot list its
    cells, `CorruptResultsError` for a damaged cache file. Failures of single cells never raise:
    they are in `RunResult.failures`.
    """
    started = time.perf_counter()
    if options is not None:
        if not isinstance(options, RunOptions):
            raise InputError(f"`options` must be a RunOptions, got {type(options).__name__}")
        quick, jobs, scheduler, fresh = options.quick, options.jobs, options.scheduler, options.fresh
        cache, cache_dir, plugins = options.cache, options.cache_dir, options.plugins
        cell_timeout = options.cell_timeout
    exp = resolve_experiment(experiment)
    jobs_n = check_jobs(jobs)
    timeout = check_timeout(cell_timeout)
    sched = check_scheduler(scheduler)
    plugin_paths = check_plugins(plugins)
    for name, flag in (("quick", quick), ("fresh", fresh), ("cache", cache)):
        if not isinstance(flag, bool | np.bool_):
            raise InputError(f"`{name}` must be True or False, got {flag!r}")
    store = CellCache(cache_dir).check_writable() if cache else None  # unwritable: one line, 77

    for p in plugin_paths:
        load_plugin(p)
    plugin_specs = [plugin_spec(p) for p in plugin_paths]
    stepper_names = check_names("steppers", steppers)
    problem_names = check_names("problems", problems)
    cfg = resolve_config(exp, config, quick)

    try:
        listed = _listed if _listed is not None else exp.cells(stepper_names, problem_names, cfg)
        cells, skips = listed
        cells, skips = list(cells), list(skips)
    except HarnessError:
        raise
    except Exception as exc:
        raise ExperimentError(
            f"experiment {exp.name!r} could not list its cells: "
            f"{type(exc).__name__}: {one_line(str(exc), 300)}"
        ) from None
    bad = [c for c in cells if not isinstance(c, Cell)] + [s for s in skips if not isinstance(s, Skip)]
    if bad:
        raise ExperimentError(f"experiment {exp.name!r} listed {type(bad[0]).__name__} objects "
                              "where Cell and Skip objects belong")
    if not cells and not allow_empty:
        raise no_cells_error([exp.name], skips, stepper_names, problem_names)
    if sched is None and _client is None:
        guard_memory(exp, cells, cfg, jobs_n)
    own_client = None
    if sched is not None and _client is None:
        # connect before looking at the cache: a bad address is an error even when every cell
        # is cached
        _client, own_client = dask_client(sched)

    exp_version = experiment_fingerprint(exp)
    # each (stepper, problem) pair's code version, shared by the experiments of one run
    versions: dict[tuple[str, str], Any] = {} if _versions is None else _versions
    failures: dict[int, dict] = {}
    records: dict[int, dict] = {}
    frames: dict[int, pd.DataFrame] = {}
    tasks: list[Task] = []
    seen: dict[str, int] = {}
    cached = 0
    pack_key: str | None = None
    packed: tuple[pd.DataFrame, list[dict]] | None = None
    bar, own_bar = progress_display(progress, exp.name)
    if not _counted:
        bar.add_total(len(cells))
        if not own_bar:
            bar.set_description(exp.name)

    def record(i: int, cell: Cell, key: str, status: str, was_cached: bool, wall: float,
               n_rows: int, worker: str) -> None:
        records[i] = {"experiment": exp.name, "cell": cell.label, "stepper": cell.stepper,
                      "problem": cell.problem, "params": _params_json(cell), "key": key,
                      "status": status, "cached": was_cached, "wall_s": float(wall),
                      "n_rows": int(n_rows), "worker": worker}

    def fail(i: int, cell: Cell, key: str, kind: str, message: str, tb: str = "",
             wall: float = 0.0, worker: str = "") -> None:
        failures[i] = failed_record(cell, message, kind=kind, traceback=tb, key=key)
        record(i, cell, key, "failed", False, wall, 0, worker)

    try:
        keyed: list[tuple[int, Cell, str, str]] = []
        for i, cell in enumerate(cells):
            pair = (cell.stepper, cell.problem)
            if pair not in versions:
                try:
                    versions[pair] = code_version(*pair)
                except Exception as exc:  # unknown name, or a fingerprint() that raises
                    versions[pair] = exc
            v = versions[pair]
            if isinstance(v, Exception):
                fail(i, cell, "", "lookup", one_line(f"{type(v).__name__}: {v}"))
                bar.update(1, failed=1)
                continue
            key = cell_key(cell, cfg, exp_version, v)
            if key in seen:
                raise ExperimentError(
                    f"experiment {exp.name!r} lists cell {cell.label} twice"
                )
            seen[key] = i
            keyed.append((i, cell, key, v))
        # every cell keyed: the whole run may be one pack (one file read instead of one per cell)
        if store is not None and keyed and len(keyed) == len(cells):
            pack_key = store.pack_key(exp.name, [k for _, _, k, _ in keyed])
            packed = read_pack(store, pack_key, [k for _, _, k, _ in keyed]) if not fresh else None
        if packed is not None:
            for (i, cell, key, _), c in zip(keyed, packed[1], strict=True):
                record(i, cell, key, "ok", True, float(c["wall_s"]), int(c["n_rows"]), str(c["worker"]))
            cached = len(keyed)
            keyed = []
        shipped = None if jobs_n == 1 and _client is None else shipped_objects(  # for workers
            [c.stepper for _, c, _, _ in keyed], [c.problem for _, c, _, _ in keyed])
        for i, cell, key, v in keyed:
            hit = store.get_or_discard(key) if (store is not None and not fresh) else None
            if hit is not None:
                rows, info = hit
                frames[i] = rows
                record(i, cell, key, "ok", True, float(info.get("wall_s", 0.0)), len(rows),
                       str(info.get("worker", "")))
                cached += 1
                continue
            payload = {"key": key, "cell": cell, "config": cfg, "experiment": exp,
                       "plugins": plugin_specs, "timeout": timeout, "sp_version": v,
                       "objects": shipped, "submitter": os.getpid()}
            tasks.append(Task(i, cell, key, payload))
        if cached:
            bar.update(cached, cached=cached)

        def accept(t: Task, out: dict) -> None:
            if out["ok"]:
                try:
                    rows = _with_ids(out["rows"], t.cell)
                    info = {"key": t.key, "experiment": exp.name, "cell": t.cell.label,
                            "wall_s": out["wall_s"], "worker": out["worker"]}
                    rows, data = _roundtrip(t.key, rows, info)
                except CellOutputError as exc:
                    fail(t.index, t.cell, t.key, "invalid", str(exc), wall=out["wall_s"],
                         worker=out["worker"])
                    bar.update(1, failed=1)
                    return
                if store is not None:
                    store.put_encoded(t.key, data)  # atomic; OutputError names the file
                frames[t.index] = rows
                record(t.index, t.cell, t.key, "ok", False, out["wall_s"], len(rows), out["worker"])
                bar.update(1)
            else:
                fail(t.index, t.cell, t.key, out["kind"], out["message"], out["traceback"],
                     out["wall_s"], out["worker"])
                bar.update(1, failed=1)

        alone = bool(getattr(exp, "exclusive", False))  # timed cells: one at a time, nothing beside
        if tasks:
            if _client is not None and not alone:
                run_dask(interleaved(tasks), _client, accept)
            elif jobs_n == 1 or _client is not None:
                run_serial(tasks, accept)
            else:
                run_loky(interleaved(tasks), 1 if alone else jobs_n, accept)
    finally:
        if own_client:
            _client.close()
        if own_bar:
            bar.close()

    order = sorted(frames)
    rows_stored = packed is not None
    if packed is not None:
        rows_df = packed[0]
    elif order:
        with_rows = [frames[i] for i in order if len(frames[i].columns)]
        rows_df = pd.concat(with_rows, ignore_index=True) if with_rows else pd.DataFrame(columns=ID_COLUMNS)
        if pack_key is not None and not failures:  # continue with the rows as the pack reads back
            rows_df = write_pack(store, pack_key, exp.name, rows_df, [records[i] for i in sorted(records)])
            rows_stored = True
    else:
        rows_df = pd.DataFrame(columns=ID_COLUMNS)
    summary = pd.DataFrame()
    if order or packed is not None:
        try:
            if pack_key is not None and not failures:  # a whole run: its summary may be cached
                summary = summarize_packed(store, pack_key, exp, rows_df,
                                           lambda: exp.summarize(rows_df.copy(), cfg), fresh)
            else:
                summary = exp.summarize(rows_df.copy(), cfg)
            if not isinstance(summary, pd.DataFrame):
                raise CellOutputError(
                    f"summarize returned {type(summary).__name__}, expected a pandas DataFrame"
                )
            summary = summary.reset_index(drop=True)
        except Exception as exc:
            summary = pd.DataFrame()
            rec = failed_record(Cell(exp.name, "", ""), one_line(f"{type(exc).__name__}: {exc}"),
                                kind="summarize", traceback=short_traceback(exc))
            rec["cell"] = f"{exp.name}:summarize"
            failures[len(cells)] = rec
    fail_df = pd.DataFrame([failures[i] for i in sorted(failures)], columns=FAILURE_COLUMNS)
    skip_df = pd.DataFrame(_skip_records(skips), columns=SKIP_COLUMNS)
    cell_df = pd.DataFrame([records[i] for i in sorted(records)], columns=CELL_COLUMNS)
    return RunResult(
        experiment=exp.name,
        description=str(getattr(exp, "description", "")),
        config=cfg,
        rows=rows_df,
        summary=summary,
        failures=fail_df,
        skips=skip_df,
        cells=cell_df,
        wall_s=time.perf_counter() - started,
        cached_cells=cached,
        computed_cells=len(tasks),
        options={"jobs": jobs_n if sched is None and _client is None else None,
                 "scheduler": scheduler if isinstance(scheduler, str) else None,
                 "fresh": bool(fresh), "cache": bool(cache), "quick": bool(quick),
                 "cell_timeout": timeout, "plugins": plugin_paths,
                 "steppers": stepper_names, "problems": problem_names},
        rows_stored=rows_stored,
    )


def interleaved(tasks: list[Task]) -> list[Task]:
    """`tasks` in the order workers take them: the problems in turn (a cell of each problem,
    then the next of each, ...), every other problem's list started halfway through. Workers
    starting together then meet different problems and steppers half a registry apart (other
    families), so each compiles its own problem's functions and family kernel instead of
    waiting on the other's lock for the same one. Results keep the cell order (they are placed
    by cell index).

    Parameters
    ----------
    tasks : list of Task, the tasks in cell order.

    Returns
    -------
    list of Task
    """
    groups: dict[str, list[Task]] = {}
    for t in tasks:
        groups.setdefault(t.cell.problem, []).append(t)
    keyed = []
    for j, group in enumerate(groups.values()):
        shift = (j % 2) * (len(group) // 2)
        keyed += [(n, j, t) for n, t in enumerate(group[shift:] + group[:shift])]
    return [t for _, _, t in sorted(keyed, key=lambda item: item[:2])]

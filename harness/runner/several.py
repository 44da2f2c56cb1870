"""Several experiments in one run: their cells on one pool of workers, each experiment finished
(its pack written, its summary made) as soon as its last cell is in.

Run one after another, each experiment ended with its slowest cells running on fewer workers than
the run has, while the next experiment's cells waited: about 50 s of a cold report on two cores
(its experiments' wall times added up to 467 s against 416 s of cell time per worker). Here every
experiment is listed, keyed and taken from the cache first (`prepare_experiment`), then all the
cells still to run go to the workers as one list, experiment after experiment (each in its
interleaved order), so a worker that finishes the last cells of one experiment takes the first
of the next; and this process summarizes an experiment while the workers run the next one's cells.
Rows, summaries and failures are those of `run_experiment` run experiment by experiment: a cell's
outcome goes to its own experiment, whose rows keep the order of its cell list.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

import pandas as pd

from harness.errors import InputError, UnknownNameError
from harness.experiments.base import Experiment
from harness.progress import Progress
from harness.runner.checks import (
    check_names,
    check_plugins,
    check_scheduler,
    progress_display,
    resolve_config,
    resolve_experiment,
)
from harness.runner.executors import Task, dask_client
from harness.runner.orchestration import (
    ExperimentJob,
    RunOptions,
    execute_tasks,
    no_cells_error,
    prepare_experiment,
)
from harness.runner.result import RunResult

__all__ = ["run_experiments"]


def run_experiments(
    experiments: Sequence[str | Experiment] | None = None,
    steppers: Sequence[str] | None = None,
    problems: Sequence[str] | None = None,
    *,
    configs: Mapping[str, Mapping[str, Any]] | None = None,
    quick: bool = False,
    jobs: int | None = None,
    scheduler: str | Any | None = None,
    fresh: bool = False,
    cache: bool = True,
    cache_dir: str | os.PathLike | None = None,
    plugins: Sequence[str | os.PathLike] = (),
    cell_timeout: float | None = None,
    progress: Progress | bool | str | None = None,
) -> dict[str, RunResult]:
    """`run_experiment` for several experiments (None: every registered one), with one progress
    display, one Dask connection and one pool of workers for all their cells; `configs` maps
    experiment name -> overrides. Returns {experiment name: RunResult} in the order given; pass
    it to `harness.store.save_run`. An experiment's `wall_s` runs from its listing to its
    summary, so the experiments' wall times overlap."""
    from harness.experiments import EXPERIMENTS

    if experiments is None:
        experiments = list(EXPERIMENTS)
    if isinstance(experiments, str | Experiment):
        experiments = [experiments]
    exps = [resolve_experiment(e) for e in experiments]
    if configs is not None and not isinstance(configs, Mapping):
        raise InputError(f"`configs` must map experiment names to settings, got {type(configs).__name__}")
    unknown = [k for k in (configs or {}) if k not in {e.name for e in exps}]
    if unknown:
        raise UnknownNameError(f"`configs` names experiments not being run: {unknown}")
    sched = check_scheduler(scheduler)
    from harness.registry import load_plugin

    plugin_paths = check_plugins(plugins)
    for p in plugin_paths:
        load_plugin(p)
    options = RunOptions(quick=quick, jobs=jobs, scheduler=None, fresh=fresh, cache=cache,
                         cache_dir=cache_dir, plugins=tuple(plugin_paths), cell_timeout=cell_timeout)
    stepper_names = check_names("steppers", steppers)
    problem_names = check_names("problems", problems)
    bar, own_bar = progress_display(progress, "cells")
    # Every experiment's cells are listed once, here: the whole run's size first, so the
    # display's total does not grow; each experiment's job takes its list.
    listed: dict[str, tuple[list, list]] = {}
    versions: dict[tuple[str, str], Any] = {}
    for exp in exps:
        try:
            cfg = resolve_config(exp, (configs or {}).get(exp.name), quick)
            cells, skips = exp.cells(stepper_names, problem_names, cfg)
            listed[exp.name] = (list(cells), list(skips))
        except Exception:  # prepare_experiment lists it again and reports the failure properly
            break
    counted = len(listed) == len(exps)
    if counted:
        bar.add_total(sum(len(cells) for cells, _ in listed.values()))
    client = None
    own_client = False
    jobs_list: list[ExperimentJob] = []
    out: dict[str, RunResult] = {}
    try:
        if sched is not None:
            client, own_client = dask_client(sched)
        for exp in exps:
            jobs_list.append(prepare_experiment(
                exp, stepper_names, problem_names, config=(configs or {}).get(exp.name),
                options=options, progress=bar, _client=client, _counted=counted, allow_empty=True,
                _listed=listed.get(exp.name), _versions=versions,
            ))
        finished = _run_jobs(jobs_list, bar)
        for job in jobs_list:
            out[job.experiment] = finished[job.experiment]
            if sched is not None:
                out[job.experiment].options["scheduler"] = sched if isinstance(sched, str) else None
    finally:
        for job in jobs_list:
            job.close()
        if own_client and client is not None:
            client.close()
        if own_bar:
            bar.close()
    if out and not any(r.n_cells for r in out.values()):
        raise no_cells_error(list(out), pd.concat([r.skips for r in out.values()], ignore_index=True),
                             stepper_names, problem_names)
    return out


def _run_jobs(jobs_list: list[ExperimentJob], bar: Progress) -> dict[str, RunResult]:
    """Every job's tasks on one pool; each job finished the moment its last outcome is in."""
    owner: dict[int, int] = {}
    left = [len(job.tasks) for job in jobs_list]
    tasks: list[Task] = []
    finished: dict[str, RunResult] = {}
    n = len(jobs_list)

    def describe() -> None:
        current = next((k for k in range(n) if jobs_list[k].experiment not in finished), n - 1)
        bar.set_description(f"[{current + 1}/{n}] {jobs_list[current].experiment}")

    def finish(k: int) -> None:
        finished[jobs_list[k].experiment] = jobs_list[k].finish()
        describe()

    def accept(t: Task, outcome: dict) -> None:
        k = owner[id(t)]
        jobs_list[k].accept(t, outcome)
        left[k] -= 1
        if left[k] == 0:
            finish(k)

    for k, job in enumerate(jobs_list):
        for t in job.tasks:
            owner[id(t)] = k
        tasks += job.tasks
    describe()
    for k in range(n):  # nothing to run: finished now, in order
        if not left[k]:
            finish(k)
    if tasks:
        first = jobs_list[owner[id(tasks[0])]]
        execute_tasks(tasks, first.jobs, first.client, accept, groups=[job.tasks for job in jobs_list])
    return finished

"""Several experiments in one call: one listing of every cell (so the progress total does not
grow), one progress display and one Dask connection, each experiment run by `run_experiment`."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import pandas as pd

from harness.errors import InputError, UnknownNameError
from harness.experiments import EXPERIMENTS
from harness.experiments.base import Experiment
from harness.progress import Progress
from harness.registry import load_plugin
from harness.runner import checks
from harness.runner.executors import dask_client
from harness.runner.orchestration import RunOptions, no_cells_error, run_experiment
from harness.runner.result import RunResult

__all__ = ["run_experiments"]

#: The keywords `run_experiments` passes on to every `run_experiment`: the fields of `RunOptions`.
RUN_OPTION_NAMES = tuple(f.name for f in dataclasses.fields(RunOptions))


def run_experiments(
    experiments: Sequence[str | Experiment] | None = None,
    steppers: Sequence[str] | None = None,
    problems: Sequence[str] | None = None,
    *,
    configs: Mapping[str, Mapping[str, Any]] | None = None,
    progress: Progress | bool | str | None = None,
    **run_options: Any,
) -> dict[str, RunResult]:
    """`run_experiment` for several experiments (None: every registered one), in order, with one
    progress display and one Dask connection.

    Parameters
    ----------
    experiments : sequence of str or Experiment, optional, the experiments (None: every registered one).
    steppers, problems : sequence of str, optional, registered names (None: every one).
    configs : mapping, optional, experiment name -> overrides of its settings.
    progress : as in `run_experiment`.
    **run_options
        How to run the cells, the fields of `RunOptions` as keywords (quick, jobs, scheduler,
        fresh, cache, cache_dir, plugins, cell_timeout), as in `run_experiment`.

    Returns
    -------
    dict of str to RunResult: by experiment name; pass it to `harness.store.save_run`.
    """
    unknown_options = sorted(set(run_options) - set(RUN_OPTION_NAMES))
    if unknown_options:
        raise InputError(f"`run_experiments` takes the run options {', '.join(RUN_OPTION_NAMES)}; "
                         f"got unknown keyword(s) {', '.join(unknown_options)}")
    run_options.setdefault("plugins", ())
    if experiments is None:
        experiments = list(EXPERIMENTS)
    if isinstance(experiments, str | Experiment):
        experiments = [experiments]
    exps = [checks.resolve_experiment(e) for e in experiments]
    if configs is not None and not isinstance(configs, Mapping):
        raise InputError(f"`configs` must map experiment names to settings, got {type(configs).__name__}")
    unknown = [k for k in (configs or {}) if k not in {e.name for e in exps}]
    if unknown:
        raise UnknownNameError(f"`configs` names experiments not being run: {unknown}")
    sched = checks.check_scheduler(run_options.get("scheduler"))

    plugin_paths = checks.check_plugins(run_options["plugins"])
    for p in plugin_paths:
        load_plugin(p)
    options = RunOptions(**{**run_options, "scheduler": None, "plugins": tuple(plugin_paths)})
    quick = options.quick
    stepper_names = checks.check_names("steppers", steppers)
    problem_names = checks.check_names("problems", problems)
    bar, own_bar = checks.progress_display(progress, "cells")
    # Every experiment's cells are listed once, here: the whole run's size first, so the
    # display's total does not grow; each `run_experiment` takes its list.
    listed: dict[str, tuple[list, list]] = {}
    versions: dict[tuple[str, str], Any] = {}
    for exp in exps:
        try:
            cfg = checks.resolve_config(exp, (configs or {}).get(exp.name), quick)
            cells, skips = exp.cells(stepper_names, problem_names, cfg)
            listed[exp.name] = (list(cells), list(skips))
        except Exception:  # run_experiment lists it again and reports the failure properly
            break
    counted = len(listed) == len(exps)
    if counted:
        bar.add_total(sum(len(cells) for cells, _ in listed.values()))
    client = None
    own_client = False
    out: dict[str, RunResult] = {}
    try:
        if sched is not None:
            client, own_client = dask_client(sched)
        for i, exp in enumerate(exps, 1):
            bar.set_description(f"[{i}/{len(exps)}] {exp.name}")
            out[exp.name] = run_experiment(
                exp, stepper_names, problem_names, config=(configs or {}).get(exp.name),
                options=options, progress=bar, _client=client, _counted=counted, allow_empty=True,
                _listed=listed.get(exp.name), _versions=versions,
            )
            if sched is not None:
                out[exp.name].options["scheduler"] = sched if isinstance(sched, str) else None
    finally:
        if own_client and client is not None:
            client.close()
        if own_bar:
            bar.close()
    if out and not any(r.n_cells for r in out.values()):
        raise no_cells_error(list(out), pd.concat([r.skips for r in out.values()], ignore_index=True),
                             stepper_names, problem_names)
    return out

"""Argument checks of a run: jobs, scheduler, names, plugins, experiment, configuration,
progress display; each bad value is an `InputError` naming the argument and the rule."""

from __future__ import annotations

import os
import re
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from harness import registry
from harness.errors import (
    InputError,
)
from harness.experiments.base import Experiment, get_experiment
from harness.progress import Progress

# A local run uses at most this many worker processes per core.
MAX_JOBS_PER_CORE = 8


# -- argument checks --------------------------------------------------------------------------------
def default_jobs() -> int:
    """All cores this process may use.

    Returns
    -------
    int: the number of CPUs in this process's affinity mask (else `os.cpu_count()`), at least 1.
    """
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def check_jobs(jobs: Any) -> int:
    """`jobs` as a worker count (None: `default_jobs()`), or `InputError` naming `jobs`.

    Parameters
    ----------
    jobs : int or None, the requested worker count; None for the default.

    Returns
    -------
    int
    """
    if jobs is None:
        return default_jobs()
    if isinstance(jobs, bool) or not isinstance(jobs, int | np.integer):
        raise InputError(f"`jobs` must be a whole number >= 1, got {jobs!r}")
    limit = MAX_JOBS_PER_CORE * default_jobs()
    if jobs < 1 or jobs > limit:
        raise InputError(f"`jobs` must be between 1 and {limit} ({MAX_JOBS_PER_CORE} per core), got {jobs}")
    return int(jobs)


_SCHEDULER = re.compile(r"^(tcp|tls|ucx|ws|wss|inproc)://[^\s/]+$")


def check_scheduler(value: Any) -> Any:
    """`value` as a Dask scheduler address or client (None: run locally), or `InputError`.

    Parameters
    ----------
    value : any, none, a ``tcp://HOST:PORT`` address or a `distributed.Client`.

    Returns
    -------
    str, Client or None
    """
    if value is None:
        return None
    try:
        from distributed import Client
    except ImportError:  # pragma: no cover - dask is in the pinned requirements
        Client = ()  # type: ignore[assignment]
    if Client and isinstance(value, Client):
        return value
    if not isinstance(value, str) or not _SCHEDULER.match(value):
        raise InputError(
            f"`scheduler` must be a Dask scheduler address like tcp://HOST:PORT, got {str(value)[:80]!r}"
        )
    if not value.startswith("tcp://"):
        # tls:// needs certificates (a distributed.Security), ucx:// and ws:// extra libraries,
        # inproc:// a scheduler in this very process: none can be given as a bare address
        raise InputError(
            f"`scheduler` {value[:80]!r}: only tcp://HOST:PORT addresses are taken here; for "
            f"{value.split('://')[0]}:// pass a connected distributed.Client to the Python API "
            "(`scheduler=client`)"
        )
    return value


def check_names(kind: str, names: Any) -> list[str]:
    """The requested names of `kind` ('steppers' or 'problems'; None: every registered one),
    each checked against the registry (`UnknownNameError` with the closest names), duplicates
    dropped.

    Parameters
    ----------
    kind : str, 'steppers' or 'problems'.
    names : sequence of str or None, the requested names.

    Returns
    -------
    list of str
    """
    reg = registry.steppers if kind == "steppers" else registry.problems
    if names is None:
        return reg.names()
    if isinstance(names, str):
        names = [names]
    if not isinstance(names, Iterable):
        raise InputError(f"`{kind}` must be a list of names, got {type(names).__name__}")
    out = []
    for n in names:
        if not isinstance(n, str) or not n:
            raise InputError(f"`{kind}` must hold non-empty names (strings), got {n!r}")
        reg.get(n)  # UnknownNameError with the closest names
        out.append(n)
    return list(dict.fromkeys(out))


def check_plugins(plugins: Any) -> list[str]:
    """`plugins` (None, a path or a sequence of paths) as a list of path strings.

    Parameters
    ----------
    plugins : str, PathLike, sequence of them, or None, the plugin files.

    Returns
    -------
    list of str: `InputError` for anything else.
    """
    if plugins is None:
        return []
    if isinstance(plugins, str | os.PathLike):
        plugins = [plugins]
    if not isinstance(plugins, Iterable):
        raise InputError(f"`plugins` must be a list of .py file paths, got {type(plugins).__name__}")
    out = []
    for p in plugins:
        if not isinstance(p, str | os.PathLike) or not os.fspath(p):
            raise InputError(f"`plugins` must hold .py file paths, got {p!r}")
        out.append(os.fspath(p))
    return out


def resolve_experiment(experiment: Any) -> Experiment:
    """The experiment object for `experiment` (an `Experiment` or a registered name).

    Parameters
    ----------
    experiment : Experiment or str, the experiment or its name (`UnknownNameError` for an unknown name).

    Returns
    -------
    Experiment
    """
    if isinstance(experiment, Experiment):
        return experiment
    if not isinstance(experiment, str) or not experiment:
        raise InputError(f"`experiment` must be an experiment name, got {experiment!r}")
    return get_experiment(experiment)


def resolve_config(exp: Experiment, config: Any, quick: bool) -> dict:
    """The experiment's configuration: its defaults (quick ones when `quick`), updated with the
    known settings of `config` (`InputError` for an unknown one).

    Parameters
    ----------
    exp : Experiment, the experiment.
    config : mapping or None, overrides of its settings.
    quick : bool, start from the quick settings.

    Returns
    -------
    dict: the settings, checked by the experiment.
    """
    if config is not None and not isinstance(config, Mapping):
        raise InputError(f"`config` must be a mapping of settings, got {type(config).__name__}")
    if config and exp.default_config:
        unknown = [k for k in config if k not in exp.default_config]
        if unknown:
            raise InputError(
                f"`config` sets {', '.join(map(repr, unknown))}, not settings of experiment "
                f"{exp.name!r}; known: {', '.join(sorted(exp.default_config))}"
            )
    return exp.config(dict(config or {}), quick=bool(quick))


def progress_display(progress: Any, desc: str) -> tuple[Progress, bool]:
    """(progress display, whether this call owns and closes it).

    Parameters
    ----------
    progress : Progress, bool, str or None
        A shared display, None/True (default display), False (silent) or a mode.
    desc : str, the display's label.

    Returns
    -------
    (Progress, bool)
    """
    if isinstance(progress, Progress):
        return progress, False
    if progress is None or progress is True:
        return Progress(0, desc), True
    if progress is False:
        return Progress(0, desc, mode="off"), True
    if isinstance(progress, str):
        return Progress(0, desc, mode=progress), True
    raise InputError(f"`progress` must be None, a bool, a mode name or a Progress, got {progress!r}")




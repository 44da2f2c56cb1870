"""The memory guard: a run whose largest cells would not fit in memory is refused up front."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from harness.errors import (
    HarnessError,
    InputError,
)
from harness.experiments.base import Cell, Experiment
from harness.registry import get_problem
from harness.tolerances import MEMORY_HEADROOM

# Working arrays a stepper keeps per state (stages, carries, temporaries) in the default
# memory estimate: 16 covers an 8-stage Runge-Kutta method with its error estimate.
WORK_ARRAYS = 16


def estimate_bytes(*, dim: int, ensemble: int = 1, saved_states: int = 2,
                   work_arrays: int = WORK_ARRAYS) -> int:
    """Peak bytes of integrating an ensemble: float64 states of shape (dim, ensemble), times
    (saved states + working arrays).

    Parameters
    ----------
    dim : int, state dimension.
    ensemble : int, optional, ensemble size (default 1).
    saved_states : int, optional, states kept (default 2: start and end).
    work_arrays : int, optional, working arrays of the state's size (WORK_ARRAYS).

    Returns
    -------
    int: 8 dim ensemble (saved_states + work_arrays).
    """
    for name, v in (("dim", dim), ("ensemble", ensemble), ("saved_states", saved_states),
                    ("work_arrays", work_arrays)):
        if isinstance(v, bool) or not isinstance(v, int | np.integer):
            raise InputError(f"`{name}` must be a whole number, got {v!r}")
        if v < (1 if name in ("dim", "ensemble") else 0):
            raise InputError(f"`{name}` must be at least {1 if name in ('dim', 'ensemble') else 0}, got {v}")
    return 8 * int(dim) * int(ensemble) * (int(saved_states) + int(work_arrays))


def available_memory() -> int:
    """Bytes of memory available to new allocations now (psutil).

    Returns
    -------
    int
    """
    import psutil

    return int(psutil.virtual_memory().available)


def _fmt_bytes(n: float) -> str:
    for unit in ("B", "KB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1024 or unit == "PB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} PB"


def check_memory(needed: int, *, argument: str, detail: str = "",
                 available: int | None = None) -> None:
    """Raise `InputError` naming `argument` when `needed` bytes exceed MEMORY_HEADROOM of the
    available memory (`available`, default: measured now).

    Parameters
    ----------
    needed : int, bytes needed.
    argument : str, the argument named in the error.
    detail : str, optional, added to the message.
    available : int, optional, bytes available (default measured now).
    """
    avail = available_memory() if available is None else int(available)
    limit = int(MEMORY_HEADROOM * avail)
    if needed > limit:
        what = f"{detail}: " if detail else ""
        raise InputError(
            f"`{argument}`: {what}needs an estimated {_fmt_bytes(needed)}, more than the "
            f"{_fmt_bytes(limit)} available ({MEMORY_HEADROOM:.0%} of {_fmt_bytes(avail)} free); "
            f"lower `{argument}`"
        )


def _cell_estimate(experiment: Experiment, cell: Cell, config: Mapping[str, Any]) -> tuple[int, str]:
    hook = getattr(experiment, "estimate_bytes", None)
    if callable(hook):
        return int(hook(cell, config)), "config"
    size = config.get("ensemble")
    if isinstance(size, bool) or not isinstance(size, int | np.integer) or not cell.problem:
        return 0, "ensemble"

    try:
        dim = get_problem(cell.problem).dim
    except HarnessError:
        return 0, "ensemble"
    if size < 1:
        raise InputError(f"`ensemble` must be at least 1, got {size}")
    return estimate_bytes(dim=dim, ensemble=int(size)), "ensemble"


def guard_memory(experiment: Experiment, cells: Sequence[Cell], config: Mapping[str, Any],
                  jobs: int) -> None:
    """Refuse (`InputError`) a run whose `jobs` largest cells together would not fit in the
    available memory (see `estimate_bytes`).

    Parameters
    ----------
    experiment : Experiment, the experiment (its `estimate_bytes(cell, config)` hook when it has one).
    cells : sequence of Cell, the cells to run.
    config : mapping, the experiment's resolved configuration.
    jobs : int, number of workers running at once.
    """
    estimates = []
    for cell in cells:
        b, arg = _cell_estimate(experiment, cell, config)
        estimates.append((b, arg, cell))
    if not estimates:
        return
    estimates.sort(key=lambda e: e[0], reverse=True)
    top = estimates[: max(1, jobs)]
    needed = sum(e[0] for e in top)
    b, arg, cell = top[0]
    detail = f"{experiment.name} cell {cell.label} ({_fmt_bytes(b)} each"
    detail += f", {len(top)} at once)" if len(top) > 1 else ")"
    if arg == "ensemble":
        detail = f"{config.get('ensemble')}, " + detail
        argument = "ensemble"
    else:
        argument = "config"
    check_memory(needed, argument=argument, detail=detail)



"""The step counts a convergence sweep may visit, and the ground truth at every time its runs
read, asked for in one call.

A sweep (`harness.experiments.convergence`, items 1 and 4) runs n_first ratio^j steps while its
budget lasts, coarsens to n_first / 2^j down to its least count, and fills in between the counts
measured (the rounded geometric mean of neighbours, twice); its local sweep steps from exact
history at h_max 2^-i (`local_step_sizes`). A stepper whose start reads the ground truth
(`Stepper.reference_times`: an implicit multistep table started from the reference because its
explicit starter would be unstable, as on a stiff problem) needs the reference at a few new times
per step size. Where that reference is the stiff path's (`harness.ground_truth.stiff`: an implicit
solve per member, each costing about as much for a short span as for the whole horizon, which
keeps the values it computed), asking for every time any run may read, and the horizon, in one
call costs one solve per member instead of one per step size and one more for the horizon: the
same values, taken from the same solver's step end points, with the same stated error.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from harness.errors import ReferenceError_
from harness.ground_truth import reference
from harness.ground_truth.stiff import IMPLICIT_LEVEL

__all__ = ["LOCAL_HALVINGS", "least_count", "local_step_sizes", "planned_counts", "read_references_once"]

#: Step sizes of the local sweep: h_max and its halvings.
LOCAL_HALVINGS = 12


def least_count(stepper) -> int:
    """The fewest steps a sweep runs: twice a multistep method's history (fewer would measure its
    starter, often exact, not the method), one for a one-step method.

    Parameters
    ----------
    stepper : Stepper, its `history_length`.

    Returns
    -------
    int
    """
    history = int(getattr(stepper, "history_length", 1))
    return 2 * history if history > 1 else 1


def local_step_sizes(h_max: float, problem, k: int) -> np.ndarray:
    """The local sweep's step sizes: h_max, capped so k steps stay within the problem's
    convergence horizon, and its LOCAL_HALVINGS - 1 halvings.

    Parameters
    ----------
    h_max : float, the largest step in the global fit; problem : Problem; k : int, the history.

    Returns
    -------
    ndarray, decreasing.
    """
    h_max = min(h_max, (problem.convergence_t_end - problem.t0) / max(k, 1))
    return h_max * 0.5 ** np.arange(LOCAL_HALVINGS)


def planned_counts(n_first: int, n_min: int, ratio: float, budget: int) -> list[int]:
    """Every step count a sweep may run (a superset: the sweep stops earlier at its floor, its
    target or its budget).

    Parameters
    ----------
    n_first : int, the first count; n_min : int, the least; ratio : float, the refinement ratio;
    budget : int, the steps the sweep may spend.

    Returns
    -------
    list of int, increasing.
    """
    counts: set[int] = set()
    n = n_first
    while n > n_min:  # coarsening of a start already below the start error
        n = max(n_min, n // 2)
        counts.add(n)
    n = n_first
    while n <= budget:
        counts.add(n)
        n = int(math.ceil(n * ratio))
    for _ in range(2):  # the fill-ins, from neighbours of everything measured
        ordered = sorted(counts)
        counts |= {int(round(math.sqrt(x * y))) for x, y in zip(ordered, ordered[1:], strict=False)}
    return sorted(counts)


def read_references_once(runner, problem, y0: np.ndarray, T0: float, horizons, budget: int,
                         config: Mapping[str, Any]) -> None:
    """Have the stiff ground truth computed at once at every time a sweep from `y0` to any of
    `horizons` may read, the horizons included (module docstring). Nothing when its runs read no
    reference (or `horizons` is empty: already asked); where the reference is not the stiff
    path's (the first member, asked first, says which: the Taylor path is cheap per call and
    keeps no values between calls), the other members are not asked.

    Parameters
    ----------
    runner : Stepper, the implementation the sweep runs; problem : Problem; y0 : ndarray (dim, N);
    T0 : float, the start; horizons : sequence of float, the end times the sweep may use (a
    shrinking sweep's shorter horizons too); budget : int, the step budget; config : mapping, the
    sweep's `n_start` and `ratio`.
    """
    k = int(runner.history_length)
    n_min = least_count(runner)
    counts = planned_counts(max(int(config["n_start"]), n_min), n_min, float(config["ratio"]), budget)
    times: set[float] = set()
    for span in (float(T) - T0 for T in horizons):
        for n in counts:
            times.update(float(t) for t in runner.reference_times(problem, T0, y0, span / n))
    if not times:
        return
    for span in (float(T) - T0 for T in horizons):
        for n in counts:  # the local sweep, from any count the global fit may start at
            for h in local_step_sizes(span / n, problem, k):
                times.update(float(problem.t0 + h * j) for j in range(1, k + 1))
    times.update(float(T) for T in horizons)
    grid = np.array(sorted(times))
    try:
        if reference(problem, grid, y0[:, :1], t0=T0).precision == IMPLICIT_LEVEL:
            reference(problem, grid, y0, t0=T0)
    except ReferenceError_:
        return  # each run then asks for its own times and meets the same refusal there
